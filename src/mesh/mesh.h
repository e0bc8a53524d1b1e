// Patches (shooters) and elements (receivers, children of patches) built from the scene's
// triangles. Coplanar triangle pairs that form a convex quad are meshed as one grid.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "scene/scene.h"

namespace hemirad::mesh {

// A planar convex triangle or quad, counter-clockwise seen from its front.
struct Polygon {
    std::array<glm::dvec3, 4> v{};
    int n = 3;  // 3 or 4
};

struct Element {
    Polygon poly;
    glm::dvec3 normal{0.0};    // unit, front side
    glm::dvec3 centroid{0.0};  // area centroid
    double area = 0.0;
    glm::dvec3 rho{0.0};       // reflectance (COLOR_0 interpolated at the centroid)
    glm::dvec3 emission{0.0};
    std::uint32_t patch = 0;   // parent patch
    std::uint32_t node = 0;    // scene mesh node
    std::uint32_t material = 0;
    // True when the same surface also exists facing the other way (a doubleSided material):
    // then this element's back is the twin's front, so the back need not be drawn as a blocker.
    bool has_twin = false;
    // True for the reversed copy of a doubleSided triangle (its glTF back face). Per-node
    // averages in the report use front faces only.
    bool back = false;
};

struct Patch {
    Polygon poly;
    glm::dvec3 normal{0.0};
    glm::dvec3 centroid{0.0};
    double area = 0.0;
    glm::dvec3 emission{0.0};  // area-weighted over its elements
    std::uint32_t first_element = 0;
    std::uint32_t element_count = 0;
    std::uint32_t node = 0;
};

struct Settings {
    double patch_size = 0.0;    // maximum patch edge length, scene units (> 0)
    double element_size = 0.0;  // maximum element edge length, scene units (> 0, <= patch_size)
};

struct Mesh {
    std::vector<Patch> patches;
    std::vector<Element> elements;  // elements of patch p are [first_element, first_element + element_count)
    std::size_t dropped_triangles = 0;  // zero or near-zero area
    std::size_t quads = 0;              // triangle pairs meshed as quads
};

Mesh build(const scene::Scene& scene, const Settings& settings);

// An upper bound on the elements build makes of `scene` with elements of `element_size`: each
// triangle cut into (longest edge / size)² (build's count for a lone triangle; up to 4 times its
// count for a quad's two), twice if double-sided. Counting stops once past `limit`.
double element_bound(const scene::Scene& scene, double element_size, double limit);

// The largest element_bound a bake or a benchmark builds: some 16 million elements. A tiny size
// (1e-300, or 1e-4 on a room) would otherwise exhaust the memory, or fail in build, long after the
// run began.
inline constexpr double kMaxElementBound = double(1 << 26);

// Throws InputError("<what>: elements of S would be over N for this scene, …") where
// element_bound passes kMaxElementBound; `what` names the setting ("--element-size 1e-05").
void check_element_bound(const scene::Scene& scene, double element_size, const std::string& what);

// Normal (unit, front side), area centroid and area of a planar convex polygon.
struct Shape {
    glm::dvec3 normal{0.0};
    glm::dvec3 centroid{0.0};
    double area = 0.0;
};
Shape shape_of(const Polygon& poly);

// The longest edge of a polygon.
double longest_edge(const Polygon& poly);

}  // namespace hemirad::mesh
