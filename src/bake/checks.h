// The bake's checks of its input that need more than the loader knows: a scene with light, lamps
// the mesh can see, the memory a bake may use, and option values the CLI passes as text.
#pragma once

#include <optional>
#include <string>

#include <glm/glm.hpp>

#include "mesh/mesh.h"
#include "scene/effects.h"
#include "scene/scene.h"

namespace hemirad::bake {

// Whether a triangle's material emits.
bool emits(const scene::Scene& scene, const scene::Triangle& t);
// The punctual lights of a scene that shine (point, spot and directional ones).
std::size_t shining_lights(const scene::Scene& scene);

// "X,Y,Z": three finite numbers, or InputError naming the option.
glm::dvec3 parse_point(const std::string& text, const std::string& option);

// Triangles to bake and something that emits, or InputError saying what is missing.
void check_scene(const scene::Scene& scene);
// After the see_through decision: a scene whose only emitters were see-through (faint blended
// glows) has nothing left to light it, which the user can change.
void check_emitters_left(const scene::Scene& scene, const scene::EffectsPlan& plan);
// After meshing: a material that emits in the file but whose surfaces give the mesh no light
// (every texel cut away by alphaMode MASK, an emissive texture black where the surface is, or
// only triangles of no area) is a lamp the bake cannot see: a warning naming it (added to the
// scene's warnings). With no light left anywhere the bake would be black: InputError, saying why.
void check_lamps_seen(scene::Scene& scene, const mesh::Mesh& mesh);
// After meshing: emitter patches whose emissive texture changes across them but which shoot from
// their centres, the cap on splitting them (mesh::kMaxEmissionShooters) reached: a warning.
void warn_uneven_emitters(scene::Scene& scene, const mesh::Mesh& mesh);

// The memory a bake may use, and where that figure comes from (for messages and the report).
// The solver and refinement are planned by `bytes`, which does not change from run to run (so
// neither do the numbers a bake gives); without --max-memory, a bake that needs more than is
// `available` at the moment is also refused rather than swapped or killed part-way.
struct MemoryLimit {
    double bytes = 0.0;
    std::string source;
    std::optional<double> available;  // without --max-memory: what is free now
};
// --max-memory's value (empty: this machine's memory).
MemoryLimit memory_limit_of(const std::string& option);

// Whether the hemicube engine --device picks may be an OpenCL one (whose buffers, on a CPU device,
// are host memory).
bool may_use_opencl(const std::string& device);

}  // namespace hemirad::bake
