// A parallel shot: what a directional light (a sun) lights. Its rays are parallel, so a
// hemicube, which looks out from a point, cannot take it; the elements are drawn instead onto a
// grid across the light's direction (an orthographic projection), with a depth test along it,
// and each element's share of the grid is the area of it the light reaches.
//
// Scalar and simple like the reference hemicube (reference.cpp), with the same exact inside
// test (covers_cell: vertices snapped to kSubcell units per cell, the top-left rule), so that
// elements sharing an edge share its cells exactly. Tiles of the grid are drawn on threads;
// each element's cell count is an integer, so the result does not depend on their order.
#pragma once

#include <cstdint>

#include <glm/glm.hpp>

#include "formfactor/engine.h"
#include "mesh/mesh.h"

namespace hemirad::formfactor {

struct ParallelSettings {
    // The grid's cell, as a fraction of the median element's edge (the square root of its
    // area): the median element, facing the light, covers about 1 / cell² cells.
    double cell = 1.0 / 16.0;
    int max_cells = 4096;  // per side of the grid: where the scene is wide, cells grow instead (16M cells)
    int threads = 0;       // 0: the machine's
};

// The grid one shot drew: its cell's side (scene units) and its size in cells.
struct ParallelGrid {
    double cell = 0.0;
    int width = 0, height = 0;
};

// Elements lit by parallel light travelling along unit `direction`: the row holds, per element,
// cos θ times its lit share (θ between its normal and the light). An element of a mesh lit by a directional light of E lux (lm/m²)
// receives E × that value. Fronts facing the light receive it; backs of one-sided surfaces
// block it (their share is `blocked`, in scene units²); a doubleSided surface's back is its twin's
// front. Coarse elements (the sky dome) neither block nor receive: the sun lies beyond them.
// `shot` turns the grid about the direction (seeded like a hemicube's frame) so that its cells'
// aliasing is not the same at every refinement level.
ParallelGrid shoot_parallel(const mesh::Mesh& mesh, const glm::dvec3& direction, std::uint64_t shot, ShotResult& out,
                            const ParallelSettings& settings = {});

}  // namespace hemirad::formfactor
