// Analytic test scenes built in code: quads, parallel and perpendicular rectangles, closed boxes.
#pragma once

#include <catch2/catch.hpp>
#include <filesystem>
#include <glm/glm.hpp>
#include <string>

#include "core/error.h"
#include "formfactor/engine.h"
#include "mesh/mesh.h"
#include "scene/builder.h"
#include "scene/scene.h"

namespace hemirad::test {

using scene::add_material;
using scene::add_quad;
using scene::finish;

// Loads a file that must be rejected; returns the message.
inline std::string load_error(const std::filesystem::path& file) {
    try {
        scene::load(file);
    } catch (const InputError& e) {
        return e.what();
    }
    FAIL("no InputError for " << file);
    return {};
}

// A lone triangle p0 p1 p2, counter-clockwise seen from its front: meshed as triangles.
inline void add_triangle(scene::Scene& s, glm::dvec3 p0, glm::dvec3 p1, glm::dvec3 p2, std::uint32_t material,
                         const std::string& node_name) {
    const std::uint32_t node = static_cast<std::uint32_t>(s.nodes.size());
    s.nodes.push_back({node_name, static_cast<int>(node)});
    const glm::dvec3 rho = s.materials[material].base_color;
    s.triangles.push_back({{p0, p1, p2}, {rho, rho, rho}, material, node, node});
}

using scene::parallel_rectangles;
using scene::perpendicular_rectangles;

// An axis-aligned closed box [0, size]³ whose six faces look inwards, node per face.
// `material_of(face)` gives each face's material (faces: −x, +x, −y, +y, −z, +z walls).
template <class MaterialOf>
scene::Scene closed_box(glm::dvec3 size, MaterialOf material_of, scene::Scene s) {
    const double X = size.x, Y = size.y, Z = size.z;
    add_quad(s, {0, 0, 0}, {0, Y, 0}, {0, Y, Z}, {0, 0, Z}, material_of(0), "x0");  // normal +x
    add_quad(s, {X, 0, 0}, {X, 0, Z}, {X, Y, Z}, {X, Y, 0}, material_of(1), "x1");  // normal −x
    add_quad(s, {0, 0, 0}, {0, 0, Z}, {X, 0, Z}, {X, 0, 0}, material_of(2), "y0");  // normal +y
    add_quad(s, {0, Y, 0}, {X, Y, 0}, {X, Y, Z}, {0, Y, Z}, material_of(3), "y1");  // normal −y
    add_quad(s, {0, 0, 0}, {X, 0, 0}, {X, Y, 0}, {0, Y, 0}, material_of(4), "z0");  // normal +z
    add_quad(s, {0, 0, Z}, {0, Y, Z}, {X, Y, Z}, {X, 0, Z}, material_of(5), "z1");  // normal −z
    finish(s);
    return s;
}

// A closed unit box of grey walls (ρ 0.7) whose floor is a fan of `needles` triangles from the
// corner (0, 0, 0) to the far edges (node "floor needle", 1:needles/2 to 1:needles·0.7), lit by a
// small two-sided lamp (E = 5, ρ 0, node "lamp") floating at its centre: a shooter close to
// everything, seen edge-on by the floor's slivers.
scene::Scene needle_box(int needles);

// Σ F of one shot over the elements of node `node`: the form factor to that surface.
double node_form_factor(const mesh::Mesh& m, const formfactor::ShotResult& r, std::uint32_t node);

// Area-weighted form factor from every patch of node `from` to all elements of node `to`:
// F(A_from → A_to) = Σ_p A_p F(p → A_to) / A_from, one hemicube per patch, shots counted from
// `first_shot`.
double area_form_factor(const mesh::Mesh& m, formfactor::Engine& engine, std::uint32_t from, std::uint32_t to,
                        std::uint64_t first_shot = 0);

// Analytic form factors of ../shared/REFERENCES.md.
double parallel_rectangles_ff(double a, double b, double c);
double perpendicular_rectangles_ff(double l, double w, double h);

// The floor of the lamp scenes: 4 × 4 at z = 0 facing up (node 0), reflectance 0.5; the lamp,
// [1.5, 2.5]² at z = 1 facing down, emitting 1 (node 1); with `occluder`, a black plate
// [1, 2] × [1, 3] at z = 0.5 facing down (node 2), whose shadow's penumbra on the floor is
// x ∈ [1.5, 2.5] (for 0.5 < y < 3.5).
scene::Scene lamp_scene(bool occluder);

// The rectangle [x0, x1] × [y0, y1] at height z, as a polygon.
mesh::Polygon rectangle_at(double x0, double x1, double y0, double y1, double z);

// The same triangles in the same order: corners, reflectance, material, node and primitive.
bool same_triangles(const scene::Scene& a, const scene::Scene& b);

}  // namespace hemirad::test
