// Scenes built in code (procedural scenes, benchmark configurations, tests): materials, quads
// as two triangles of one primitive, the bounding box, and the analytic rectangle pairs.
#pragma once

#include <glm/glm.hpp>
#include <string>

#include "scene/scene.h"

namespace hemirad::scene {

inline std::uint32_t add_material(Scene& s, glm::dvec3 rho, glm::dvec3 emission, bool double_sided = false) {
    Material m;
    m.name = "m" + std::to_string(s.materials.size());
    m.base_color = rho;
    m.emission = emission;
    m.double_sided = double_sided;
    s.materials.push_back(m);
    return static_cast<std::uint32_t>(s.materials.size() - 1);
}

// A planar quad p0..p3, counter-clockwise seen from its front, as two triangles sharing p0–p2
// (reflectance: the material's) of an existing node and primitive.
inline void add_quad_to(Scene& s, glm::dvec3 p0, glm::dvec3 p1, glm::dvec3 p2, glm::dvec3 p3, std::uint32_t material,
                        std::uint32_t node, std::uint32_t primitive) {
    const glm::dvec3 rho = s.materials[material].base_color;
    s.triangles.push_back({{p0, p1, p2}, {rho, rho, rho}, material, node, primitive});
    s.triangles.push_back({{p0, p2, p3}, {rho, rho, rho}, material, node, primitive});
}

// The same quad in a node (and primitive) of its own.
inline void add_quad(Scene& s, glm::dvec3 p0, glm::dvec3 p1, glm::dvec3 p2, glm::dvec3 p3, std::uint32_t material,
                     const std::string& node_name) {
    const auto node = static_cast<std::uint32_t>(s.nodes.size());
    s.nodes.push_back({node_name, static_cast<int>(node)});
    add_quad_to(s, p0, p1, p2, p3, material, node, node);
}

// Sets the bounding box from the triangles.
inline void finish(Scene& s) {
    s.bbox_min = glm::dvec3(1e300);
    s.bbox_max = glm::dvec3(-1e300);
    for (const auto& t : s.triangles)
        for (const auto& p : t.p) {
            s.bbox_min = glm::min(s.bbox_min, p);
            s.bbox_max = glm::max(s.bbox_max, p);
        }
}

// Two a×b rectangles facing each other at distance c: the lower (z = 0) faces +z, the upper
// (z = c) faces −z. Node 0 "lower", node 1 "upper".
inline Scene parallel_rectangles(double a, double b, double c, std::uint32_t lower_material,
                                 std::uint32_t upper_material, Scene s) {
    add_quad(s, {0, 0, 0}, {a, 0, 0}, {a, b, 0}, {0, b, 0}, lower_material, "lower");
    add_quad(s, {0, 0, c}, {0, b, c}, {a, b, c}, {a, 0, c}, upper_material, "upper");
    finish(s);
    return s;
}

// Rectangles sharing the edge x ∈ [0, l] on the x axis: "floor" w deep (y ∈ [0, w], facing +z)
// and "wall" h high (z ∈ [0, h], facing +y).
inline Scene perpendicular_rectangles(double l, double w, double h, std::uint32_t floor_material,
                                      std::uint32_t wall_material, Scene s) {
    add_quad(s, {0, 0, 0}, {l, 0, 0}, {l, w, 0}, {0, w, 0}, floor_material, "floor");
    add_quad(s, {0, 0, 0}, {0, 0, h}, {l, 0, h}, {l, 0, 0}, wall_material, "wall");
    finish(s);
    return s;
}

}  // namespace hemirad::scene
