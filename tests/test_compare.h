// The scenes and the comparison that every engine is held to against the scalar reference:
// the OpenCL engine cell for cell (test_opencl.cpp), the Embree ray caster within the rounding
// of its floats (test_embree.cpp).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "formfactor/engine.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "scene/scene.h"

namespace hemirad::test {

// An axis-aligned block [lo, hi] standing on its base: the top and four sides, facing out.
void add_block(scene::Scene& s, glm::dvec3 lo, glm::dvec3 hi, std::uint32_t material, const std::string& name);

struct Case {
    std::string name;
    scene::Scene scene;
    mesh::Settings mesh;
};

// The scenes the engines are compared on: enclosures, a shared edge, one-sided occluders seen
// from behind (blockers), a doubleSided occluder (twins), a Cornell-like box with blocks.
std::vector<Case> comparison_cases();

struct Comparison {
    std::size_t mismatched_cells = 0, cells = 0, shots = 0;
    std::size_t hit_cells = 0, blocker_cells = 0;  // in the reference: the comparison is not vacuous
    double worst_f = 0.0;      // largest relative error among the F (and blocked) off by more than 1e-6
    double worst_total = 0.0;  // largest |(ΣF + blocked)_other − (ΣF + blocked)_ref|
    double worst_l1 = 0.0;     // largest Σ_k |F_other − F_ref| + |blocked_other − blocked_ref| of a shot
};

// Shoots `shots` patches spread over the mesh with both engines and compares everything (the
// other engine's id buffer from last_ids()).
Comparison compare(const mesh::Mesh& m, formfactor::ReferenceEngine& ref, formfactor::Engine& other, int shots);

}  // namespace hemirad::test
