// Element subdivision for adaptive refinement: an element is replaced by its four children
// (edge midpoints 0.5·(a + b), and a quad's centre), its patch and attributes kept.
#pragma once

#include <cstdint>
#include <vector>

#include "mesh/mesh.h"

namespace hemirad::mesh {

// The four children of a convex quad or triangle, counter-clockwise like the parent. Midpoints
// are 0.5·(a + b) so that the neighbour sharing edge a–b computes the bit-identical point: the
// welder finds T-junctions by it.
std::array<Polygon, 4> split_polygon(const Polygon& poly);

struct Refined {
    Mesh mesh;
    // Per element of `mesh`: the element of the input mesh it is, or was cut from.
    std::vector<std::uint32_t> origin;
    // Per element of `mesh`: true for a child of a split element.
    std::vector<bool> is_new;
};

class Texturing;

// Splits every element with split[k] into four. Patches keep their order, polygons and areas;
// elements stay grouped by patch (each patch's range is renumbered). Children keep the parent's
// reflectance, emission, node, material and flags, so the reflected flux of a parent whose
// irradiance is shared out among its children (Σ H_c A_c = H A) is unchanged; with `texturing`,
// children of textured materials take their own textures' averages instead (which average to
// the parent's).
Refined split_elements(const Mesh& mesh, const std::vector<bool>& split, const Texturing* texturing = nullptr);

}  // namespace hemirad::mesh
