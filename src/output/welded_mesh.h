// The element mesh as triangles with shared vertices and per-vertex radiosity: what both the
// baked glTF and the preview renderer draw, built once so the two always agree.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "mesh/mesh.h"

namespace hemirad::output {

// One scene mesh node's triangles, both sides (a doubleSided back face has its own vertices).
struct WeldedNode {
    std::vector<glm::dvec3> positions;
    // Per vertex (a hanging vertex of a T-junction takes its edge's ends' mean instead, see weld):
    std::vector<glm::dvec3> normals;     // unit, area-weighted mean of the elements' around it
    std::vector<glm::dvec3> radiosity;   // area-weighted mean of the elements around the vertex
    std::vector<std::uint32_t> indices;  // 3 per triangle, counter-clockwise seen from its front
    std::vector<std::uint32_t> element;  // per triangle: the element it is part of (mesh index)

    // How weld made each vertex's value of the elements', so that any other per-element values
    // reach the same vertices without welding again (vertex_values): vertex v's elements, in the
    // order weld summed them, are corner_element[corner_start[v] .. corner_start[v + 1]); then
    // each hanging vertex, in `halfway`'s order, took the mean of its edge's ends.
    std::vector<std::uint32_t> corner_start, corner_element;
    struct Halfway {
        std::uint32_t vertex, a, b;
    };
    std::vector<Halfway> halfway;

    std::size_t triangle_count() const { return indices.size() / 3; }
};

// Index = scene node index.
struct WeldedMesh {
    std::vector<WeldedNode> nodes;
};

// Values at the welded vertices, per node (scene node index), one per vertex in weld's order.
using VertexValues = std::vector<std::vector<glm::dvec3>>;

// The light at the output's vertices from a final gather (solve/final_gather.h), which the outputs
// show instead of the elements' averages.
struct VertexLight {
    VertexValues radiosity, irradiance;
};

// Welds within one node and one side: vertices at bit-identical positions whose element
// normals are within a crease angle (40°) become one vertex, so tessellated curves shade
// smoothly but nothing blurs across a crease such as a box edge. Quads become two triangles.
//
// Adaptive refinement leaves T-junctions: a vertex of finer elements at the midpoint
// 0.5·(a + b) of a coarser neighbour's edge a–b (found by its bit-exact position, at any depth
// of halving). Such an element is cut into triangles through those hanging vertices instead
// (ear clipping: no zero-area triangles, no centroid vertex), so neighbours share triangle
// edges, and each hanging vertex takes the mean of its edge's ends' radiosity (and their
// normalized mean normal), so the shading is continuous across the junction. Across a crease
// the coarse side's edge is split too, at a vertex of its own (its value interpolated the
// same way). An unrefined mesh, whose elements meet vertex to vertex, gets exactly its old
// vertices and triangles.
//
// `vertex_values`, when given, replaces every vertex's value (a final gather's light; the mesh must
// be the one it was gathered on).
//
// Throws InternalError when `radiosity` is not one value per element, an element names a node
// that does not exist, or `vertex_values` does not hold one value per welded vertex.
WeldedMesh weld(std::size_t node_count, const mesh::Mesh& mesh, const std::vector<glm::dvec3>& radiosity,
                const VertexValues* vertex_values = nullptr);

// Per vertex of `welded` (weld's of `mesh`), the value weld would give it from the per-element
// `values`, bit for bit: one weld of a mesh serves every quantity on it (light, irradiance,
// emission, reflectance). Throws InternalError when `values` is not one value per element.
VertexValues vertex_values(const WeldedMesh& welded, const mesh::Mesh& mesh, const std::vector<glm::dvec3>& values);

// `welded` with its vertices' values replaced by `values` (one per vertex per node, as
// vertex_values gives them); InternalError where the counts differ.
void set_vertex_values(WeldedMesh& welded, const VertexValues& values);

}  // namespace hemirad::output
