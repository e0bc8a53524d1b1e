// Tests for mesh::build: quad pairing, patch and element grids, attributes, against hand-computed values.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <map>
#include <set>

#include "core/error.h"
#include "mesh/mesh.h"
#include "scene/builder.h"

using glm::dvec3;
using hemirad::mesh::build;
using hemirad::mesh::Element;
using hemirad::mesh::Mesh;
using hemirad::mesh::Patch;
using hemirad::mesh::Polygon;
using hemirad::mesh::Settings;
using hemirad::scene::Material;
using hemirad::scene::Scene;
using hemirad::scene::Triangle;

namespace {

Triangle tri(dvec3 a, dvec3 b, dvec3 c, std::uint32_t primitive = 0, std::uint32_t material = 0) {
    Triangle t;
    t.p = {a, b, c};
    t.rho = {dvec3(0.5), dvec3(0.5), dvec3(0.5)};
    t.material = material;
    t.primitive = primitive;
    return t;
}

Scene scene_of(std::vector<Triangle> tris, std::vector<Material> materials = {Material{}}) {
    Scene s;
    s.materials = std::move(materials);
    s.triangles = std::move(tris);
    s.nodes.push_back({"node0", 0});
    return s;
}

// The quad (a, b, c, d), CCW, split along a–c the way glTF exporters do.
std::vector<Triangle> split_quad(dvec3 a, dvec3 b, dvec3 c, dvec3 d) {
    return {tri(a, b, c), tri(a, c, d)};
}

std::vector<double> edge_lengths(const Polygon& p) {
    std::vector<double> e;
    for (int k = 0; k < p.n; ++k) e.push_back(glm::length(p.v[std::size_t((k + 1) % p.n)] - p.v[std::size_t(k)]));
    return e;
}

bool on_grid(double x, double step) {
    return std::abs(x / step - std::round(x / step)) < 1e-12;
}

// Exact (bitwise) vertex key: welding and the rasterizer need neighbours' vertices identical.
using Key = std::array<double, 3>;
Key key(const dvec3& p) {
    return {p.x, p.y, p.z};
}

// Euler characteristic V − E + F of the elements, counting vertices and edges by exact position.
// A face tiled without cracks or T-junctions is a disk: 1.
long euler_characteristic(const std::vector<Element>& elements) {
    std::set<Key> vertices;
    std::set<std::pair<Key, Key>> edges;
    for (const Element& e : elements) {
        for (int k = 0; k < e.poly.n; ++k) {
            Key a = key(e.poly.v[std::size_t(k)]), b = key(e.poly.v[std::size_t((k + 1) % e.poly.n)]);
            vertices.insert(a);
            edges.insert(std::minmax(a, b));
        }
    }
    return long(vertices.size()) - long(edges.size()) + long(elements.size());
}

// Normal of the polygon from its winding (front side for CCW).
dvec3 winding_normal(const Polygon& p) {
    dvec3 n{0.0};
    for (int k = 1; k + 1 < p.n; ++k) n += glm::cross(p.v[std::size_t(k)] - p.v[0], p.v[std::size_t(k + 1)] - p.v[0]);
    return glm::normalize(n);
}

bool inside_triangle(const Polygon& t, const dvec3& p) {
    const dvec3 n = winding_normal(t);
    for (int k = 0; k < 3; ++k) {
        const dvec3 a = t.v[std::size_t(k)], b = t.v[std::size_t((k + 1) % 3)];
        if (glm::dot(glm::cross(b - a, p - a), n) < -1e-12) return false;
    }
    return true;
}

void check_ranges(const Mesh& m) {
    std::uint32_t next = 0;
    for (std::size_t p = 0; p < m.patches.size(); ++p) {
        const Patch& patch = m.patches[p];
        REQUIRE(patch.first_element == next);
        REQUIRE(patch.element_count > 0);
        double area = 0.0;
        for (std::uint32_t e = patch.first_element; e < patch.first_element + patch.element_count; ++e) {
            REQUIRE(m.elements[e].patch == p);
            REQUIRE(m.elements[e].node == patch.node);
            area += m.elements[e].area;
        }
        REQUIRE(area == Approx(patch.area).epsilon(1e-12));
        next += patch.element_count;
    }
    REQUIRE(next == m.elements.size());
}

}  // namespace

TEST_CASE("unit square from two triangles meshes as an exact grid", "[mesh]") {
    const Scene s = scene_of(split_quad({0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}));
    const Mesh m = build(s, {0.25, 0.125});

    REQUIRE(m.quads == 1);
    REQUIRE(m.dropped_triangles == 0);
    REQUIRE(m.patches.size() == 16);
    REQUIRE(m.elements.size() == 64);
    for (const Patch& p : m.patches) {
        CHECK(p.poly.n == 4);
        CHECK(p.area == Approx(1.0 / 16).epsilon(1e-14));
        CHECK(p.element_count == 4);
        CHECK(glm::length(p.normal - dvec3(0, 0, 1)) < 1e-14);
    }
    double total = 0.0;
    for (const Element& e : m.elements) {
        REQUIRE(e.poly.n == 4);
        total += e.area;
        for (int k = 0; k < 4; ++k) {
            const dvec3 v = e.poly.v[std::size_t(k)], w = e.poly.v[std::size_t((k + 1) % 4)];
            CHECK(on_grid(v.x, 0.125));
            CHECK(on_grid(v.y, 0.125));
            CHECK(v.z == 0.0);
            // Axis aligned: each side moves along exactly one axis, by one grid step.
            CHECK(((v.x == w.x) != (v.y == w.y)));
            CHECK(glm::length(w - v) == Approx(0.125).epsilon(1e-12));
        }
        const auto len = edge_lengths(e.poly);
        CHECK(*std::max_element(len.begin(), len.end()) / *std::min_element(len.begin(), len.end()) <= 1.0001);
        CHECK(glm::dot(winding_normal(e.poly), dvec3(0, 0, 1)) > 0.999999);
    }
    CHECK(std::abs(total - 1.0) <= 1e-12);
    check_ranges(m);
    CHECK(euler_characteristic(m.elements) == 1);
}

TEST_CASE("a 2x1 rectangle with patch size 0.5 gives a 4x2 patch grid", "[mesh]") {
    const Scene s = scene_of(split_quad({0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {0, 1, 0}));
    const Mesh m = build(s, {0.5, 0.5});

    REQUIRE(m.quads == 1);
    REQUIRE(m.patches.size() == 8);
    std::set<std::pair<double, double>> centres;
    for (const Patch& p : m.patches) {
        CHECK(p.area == Approx(0.25).epsilon(1e-14));
        CHECK(p.element_count == 1);
        for (double l : edge_lengths(p.poly)) CHECK(l == Approx(0.5).epsilon(1e-14));
        centres.insert({p.centroid.x, p.centroid.y});
    }
    std::set<std::pair<double, double>> expected;
    for (double x : {0.25, 0.75, 1.25, 1.75})
        for (double y : {0.25, 0.75}) expected.insert({x, y});
    CHECK(centres == expected);
}

TEST_CASE("a lone right triangle splits into n^2 congruent cells, paired into parallelogram patches", "[mesh]") {
    const Scene s = scene_of({tri({0, 0, 0}, {1, 0, 0}, {0, 1, 0})});
    // n = ceil(sqrt2 / 0.5) = 3; cell hypotenuse sqrt2/3 = 0.471 → m = ceil(0.471 / 0.25) = 2.
    // Of the 9 cells, the 3 downward ones each pair with the upward one beside them: 3
    // parallelograms and the 3 upward cells along the hypotenuse, n(n + 1)/2 = 6 patches.
    const Mesh m = build(s, {0.5, 0.25});

    REQUIRE(m.quads == 0);
    REQUIRE(m.patches.size() == 6);
    REQUIRE(m.elements.size() == 9 * 4);
    int parallelograms = 0;
    double area = 0.0;
    for (const Patch& p : m.patches) {
        REQUIRE((p.poly.n == 3 || p.poly.n == 4));
        const bool pair = p.poly.n == 4;
        parallelograms += pair;
        area += p.area;
        CHECK(p.area == Approx(pair ? 1.0 / 9 : 1.0 / 18).epsilon(1e-13));
        CHECK(p.element_count == (pair ? 8u : 4u));
        auto len = edge_lengths(p.poly);
        std::sort(len.begin(), len.end());
        // A parallelogram's sides are two legs of a cell, each 1/3 (no longer than the patch size).
        CHECK(len[0] == Approx(1.0 / 3).epsilon(1e-13));
        CHECK(len[1] == Approx(1.0 / 3).epsilon(1e-13));
        CHECK(len.back() == Approx(pair ? 1.0 / 3 : std::sqrt(2.0) / 3).epsilon(1e-13));
        CHECK(glm::dot(winding_normal(p.poly), dvec3(0, 0, 1)) > 0.999999);
        if (pair) {  // its corners in order: opposite sides parallel and equal
            CHECK(glm::length(p.poly.v[1] - p.poly.v[0] - (p.poly.v[2] - p.poly.v[3])) < 1e-15);
        }
        for (std::uint32_t e = p.first_element; e < p.first_element + p.element_count; ++e) {
            CHECK(m.elements[e].area == Approx(1.0 / 72).epsilon(1e-13));
            const dvec3 c = m.elements[e].centroid;
            Polygon first = p.poly, second = p.poly;  // a parallelogram as two triangles
            first.n = second.n = 3;
            second.v[1] = p.poly.v[2];
            second.v[2] = p.poly.v[3];
            CHECK((inside_triangle(first, c) || (pair && inside_triangle(second, c))));
        }
    }
    CHECK(parallelograms == 3);
    CHECK(area == Approx(0.5).epsilon(1e-13));
    check_ranges(m);
    CHECK(euler_characteristic(m.elements) == 1);
}

TEST_CASE("a needle triangle is cut into strips across it, not n^2 slivers", "[mesh]") {
    // Sides of 1.0000125 and 0.01: n² cells from its longest side would be 121 slivers of its own
    // shape; strips across it are 11 patches (10 trapezoids and the tip), each within the patch
    // size and cut in two along the needle, tiling it exactly.
    const Scene s = scene_of({tri({0, 0.005, 0}, {0, -0.005, 0}, {1, 0, 0})});
    const Mesh m = build(s, {0.1, 0.05});
    REQUIRE(m.patches.size() == 11);
    REQUIRE(m.elements.size() == 22);
    double area = 0.0;
    for (const Patch& p : m.patches) {
        for (double l : edge_lengths(p.poly)) CHECK(l <= 0.1 + 1e-12);
        CHECK(glm::dot(winding_normal(p.poly), dvec3(0, 0, 1)) > 0.999999);
        area += p.area;
    }
    CHECK(area == Approx(0.005).epsilon(1e-12));
    CHECK(std::count_if(m.patches.begin(), m.patches.end(), [](const Patch& p) { return p.poly.n == 3; }) == 1);
    check_ranges(m);
    CHECK(euler_characteristic(m.elements) == 1);
}

TEST_CASE("folded or non-convex triangle pairs are not merged into quads", "[mesh]") {
    const Settings big{100.0, 100.0, /*cluster=*/false};  // a patch per face: the pairing alone
    SECTION("flat pair: control, is paired") {
        const Mesh m =
            build(scene_of({tri({0, 0, 0}, {1, 0, 0}, {1, 1, 0}), tri({0, 0, 0}, {1, 1, 0}, {0, 1, 0})}), big);
        CHECK(m.quads == 1);
        CHECK(m.patches.size() == 1);
    }
    SECTION("folded along the shared diagonal") {
        const Mesh m =
            build(scene_of({tri({0, 0, 0}, {1, 0, 0}, {1, 1, 0}), tri({0, 0, 0}, {1, 1, 0}, {0, 1, 1})}), big);
        CHECK(m.quads == 0);
        CHECK(m.patches.size() == 2);
    }
    SECTION("coplanar dart: A(0,0) B(2,1) C(4,0) D(2,3), reflex at B, split along B-D") {
        const Mesh m =
            build(scene_of({tri({0, 0, 0}, {2, 1, 0}, {2, 3, 0}), tri({2, 1, 0}, {4, 0, 0}, {2, 3, 0})}), big);
        CHECK(m.quads == 0);
        CHECK(m.patches.size() == 2);
        // Clustered, the two faces are one shooter of two elements.
        const Mesh c =
            build(scene_of({tri({0, 0, 0}, {2, 1, 0}, {2, 3, 0}), tri({2, 1, 0}, {4, 0, 0}, {2, 3, 0})}), {100.0, 100.0});
        REQUIRE(c.patches.size() == 1);
        CHECK(c.patches[0].cluster());
        CHECK(c.patches[0].element_count == 2);
        CHECK(c.patches[0].area == Approx(4.0));
    }
    SECTION("different primitives are never paired") {
        const Mesh m =
            build(scene_of({tri({0, 0, 0}, {1, 0, 0}, {1, 1, 0}, 0), tri({0, 0, 0}, {1, 1, 0}, {0, 1, 0}, 1)}), big);
        CHECK(m.quads == 0);
    }
}

TEST_CASE("pairing prefers the longest edge, the diagonal of a split quad", "[mesh]") {
    // Two unit squares side by side in one primitive. A1 also shares its short edge x = 1 with
    // B2, and that union (0,0) (1,0) (2,1) (1,1) is a convex parallelogram: a wrong pairing.
    const Scene s = scene_of({
        tri({0, 0, 0}, {1, 0, 0}, {1, 1, 0}),  // A1
        tri({1, 0, 0}, {2, 1, 0}, {1, 1, 0}),  // B2
        tri({0, 0, 0}, {1, 1, 0}, {0, 1, 0}),  // A2
        tri({1, 0, 0}, {2, 0, 0}, {2, 1, 0}),  // B1
    });
    const Mesh m = build(s, {1.0, 1.0});
    CHECK(m.quads == 2);
    REQUIRE(m.patches.size() == 2);
    for (const Patch& p : m.patches) {
        REQUIRE(p.poly.n == 4);
        for (double l : edge_lengths(p.poly)) CHECK(l == Approx(1.0).epsilon(1e-14));
    }
    CHECK(m.patches[0].centroid == dvec3(0.5, 0.5, 0.0));
    CHECK(m.patches[1].centroid == dvec3(1.5, 0.5, 0.0));
}

TEST_CASE("zero-area triangles are dropped and counted", "[mesh]") {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const Scene s = scene_of({
        tri({0, 0, 0}, {1, 0, 0}, {2, 0, 0}),      // collinear
        tri({0, 0, 0}, {1, 0, 0}, {0, 1, 0}),      // fine
        tri({0, 0, 0}, {2, 0, 0}, {1, 1e-13, 0}),  // area 1e-13 <= 1e-12 × 2²
        tri({0, 0, 0}, {1, nan, 0}, {0, 1, 0}),    // NaN
        tri({0, 0, 0}, {2, 0, 0}, {1, 1e-6, 0}),   // thin but real: kept
    });
    const Mesh m = build(s, {10.0, 10.0});
    CHECK(m.dropped_triangles == 3);
    REQUIRE(m.patches.size() == 2);
    CHECK(m.patches[0].area == Approx(0.5));
    CHECK(m.patches[1].area == Approx(1e-6));
}

TEST_CASE("doubleSided materials get a reversed twin of every patch and element", "[mesh]") {
    const auto quad = split_quad({0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0});
    const Settings settings{0.5, 0.25};

    Material one_sided;
    const Mesh single = build(scene_of(quad, {one_sided}), settings);
    REQUIRE(single.patches.size() == 4);
    REQUIRE(single.elements.size() == 16);
    for (const Element& e : single.elements) {
        CHECK_FALSE(e.has_twin);
        CHECK_FALSE(e.back);
    }

    Material two_sided;
    two_sided.double_sided = true;
    const Mesh both = build(scene_of(quad, {two_sided}), settings);
    REQUIRE(both.patches.size() == 8);
    REQUIRE(both.elements.size() == 32);
    check_ranges(both);
    for (std::size_t i = 0; i < 16; ++i) {
        const Element& front = both.elements[i];
        const Element& rev = both.elements[i + 16];
        CHECK(front.has_twin);
        CHECK(rev.has_twin);
        CHECK_FALSE(front.back);
        CHECK(rev.back);
        CHECK(front.normal == dvec3(0, 0, 1));
        CHECK(rev.normal == -front.normal);
        CHECK(rev.centroid == front.centroid);
        CHECK(rev.area == front.area);
        // The reverse copy is wound CCW seen from its own (negated) normal.
        CHECK(glm::dot(winding_normal(rev.poly), rev.normal) > 0.999999);
        CHECK(rev.patch == front.patch + 4);
    }
    for (std::size_t p = 0; p < 4; ++p) {
        CHECK(both.patches[p + 4].normal == -both.patches[p].normal);
        CHECK(glm::dot(winding_normal(both.patches[p + 4].poly), both.patches[p + 4].normal) > 0.999999);
    }
}

TEST_CASE("every front comes before every back, each back its front's twin", "[mesh]") {
    // One-sided and doubleSided faces in turn, large (several patches) and small (a cluster each):
    // setup's lane groups take the elements in mesh order, so fronts and backs must not mix.
    Scene s;
    const std::uint32_t one = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0), false);
    const std::uint32_t two = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0), true);
    for (int i = 0; i < 6; ++i) {
        const double x = 2.0 * i;
        hemirad::scene::add_quad(s, {x, 0, 0}, {x + 1.5, 0, 0}, {x + 1.5, 1.5, 0}, {x, 1.5, 0}, i % 2 ? one : two,
                                 "large");
        hemirad::scene::add_quad(s, {x, 3, 0}, {x + 0.2, 3, 0}, {x + 0.2, 3.2, 0}, {x, 3.2, 0}, i % 3 ? two : one,
                                 "small");
    }
    hemirad::scene::finish(s);
    const Mesh m = build(s, Settings{0.5, 0.25});
    std::size_t last_front = 0, first_back = m.elements.size(), backs = 0, twinned_fronts = 0;
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        const Element& e = m.elements[k];
        if (e.back) {
            first_back = std::min(first_back, k);
            ++backs;
        } else if (e.has_twin) {
            last_front = std::max(last_front, k);
            ++twinned_fronts;
        }
    }
    REQUIRE(backs > 0);
    CHECK(backs == twinned_fronts);
    CHECK(last_front < first_back);
    for (std::size_t p = 0; p < m.patches.size(); ++p) {
        const Patch& patch = m.patches[p];
        const bool back = m.elements[patch.first_element].back;
        if (patch.twin == hemirad::mesh::kNoPatch) {
            CHECK_FALSE(m.elements[patch.first_element].has_twin);
            continue;
        }
        const Patch& twin = m.patches[patch.twin];
        REQUIRE(twin.twin == p);
        CHECK(m.elements[twin.first_element].back != back);
        CHECK(twin.element_count == patch.element_count);
        CHECK(twin.normal == -patch.normal);
        for (std::uint32_t i = 0; i < patch.element_count; ++i)
            CHECK(m.elements[twin.first_element + i].centroid == m.elements[patch.first_element + i].centroid);
    }
}

TEST_CASE("element reflectance interpolates the source triangle's vertex colours", "[mesh]") {
    SECTION("lone triangle, red/green/blue corners") {
        Triangle t = tri({0, 0, 0}, {1, 0, 0}, {0, 1, 0});
        t.rho = {dvec3(1, 0, 0), dvec3(0, 1, 0), dvec3(0, 0, 1)};
        const Mesh m = build(scene_of({t}), {0.5, 0.25});

        dvec3 mean{0.0};
        double area = 0.0;
        const Element* nearest = nullptr;
        for (const Element& e : m.elements) {
            mean += e.area * e.rho;
            area += e.area;
            // Linear in position: at centroid (x, y) the weights are (1 − x − y, x, y).
            const dvec3 c = e.centroid;
            CHECK(glm::length(e.rho - dvec3(1 - c.x - c.y, c.x, c.y)) < 1e-12);
            if (!nearest || glm::length(c) < glm::length(nearest->centroid)) nearest = &e;
        }
        mean /= area;
        CHECK(glm::length(mean - dvec3(1.0 / 3)) < 1e-12);
        REQUIRE(nearest);
        for (const Element& e : m.elements) CHECK(nearest->rho.x >= e.rho.x);
        CHECK(nearest->rho.x > nearest->rho.y);
        CHECK(nearest->rho.x > nearest->rho.z);
    }
    SECTION("quad: each element takes the colour of the source triangle holding its centroid") {
        auto q = split_quad({0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0});
        q[0].rho = {dvec3(0.8, 0, 0), dvec3(0.8, 0, 0), dvec3(0.8, 0, 0)};  // below the diagonal x = y
        q[1].rho = {dvec3(0, 0, 0.8), dvec3(0, 0, 0.8), dvec3(0, 0, 0.8)};  // above it
        const Mesh m = build(scene_of(q), {0.5, 0.125});
        REQUIRE(m.quads == 1);
        int red = 0, blue = 0;
        for (const Element& e : m.elements) {
            const double side = e.centroid.x - e.centroid.y;
            if (std::abs(side) < 1e-9) continue;  // centred on the diagonal: either is right
            const dvec3 want = side > 0 ? dvec3(0.8, 0, 0) : dvec3(0, 0, 0.8);
            CHECK(glm::length(e.rho - want) < 1e-15);
            (side > 0 ? red : blue)++;
        }
        CHECK(red == 28);
        CHECK(blue == 28);
    }
}

TEST_CASE("a needle triangle a billionth as wide as it is long keeps a finite reflectance", "[mesh]") {
    // Kept by the mesher (its area is 5e-10 of its longest edge squared, above the 1e-12 cut), a
    // needle used to get NaN barycentric weights, a NaN reflectance, and a bake that failed with
    // "the solution has a non-finite value" (found by the random-scene fuzzer). Its elements'
    // reflectance must interpolate its corners': within their range, and red at the red end.
    for (const double width : {1e-9, 1e-7, 1e-11}) {
        CAPTURE(width);
        Triangle t = tri({0, 0, 0}, {1, 0, 0}, {1, width, 0});
        t.rho = {dvec3(0.9, 0.1, 0.1), dvec3(0.1, 0.9, 0.1), dvec3(0.1, 0.1, 0.9)};
        const Mesh m = build(scene_of({t}), {0.25, 0.125});
        REQUIRE(m.dropped_triangles == 0);
        REQUIRE(!m.elements.empty());
        const Element* nearest = nullptr;
        for (const Element& e : m.elements) {
            for (int c = 0; c < 3; ++c) {
                CHECK(std::isfinite(e.rho[c]));
                CHECK(e.rho[c] >= 0.1 - 1e-12);
                CHECK(e.rho[c] <= 0.9 + 1e-12);
            }
            if (!nearest || e.centroid.x < nearest->centroid.x) nearest = &e;
        }
        // The element at the red corner (x = 0) is redder than green or blue.
        CHECK(nearest->rho.x > nearest->rho.y);
        CHECK(nearest->rho.x > nearest->rho.z);
    }
}

TEST_CASE("attributes: emission, indices, node and material, trapezoid area centroid", "[mesh]") {
    Material dark;
    Material lamp;
    lamp.emission = {2, 3, 4};
    Triangle t = tri({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 0, 1);
    t.node = 1;
    Scene s = scene_of({t}, {dark, lamp});
    s.nodes.push_back({"lamp", 1});
    const Mesh m = build(s, {0.5, 0.25});

    REQUIRE(!m.patches.empty());
    check_ranges(m);
    for (const Patch& p : m.patches) {
        CHECK(p.node == 1);
        CHECK(glm::length(p.emission - dvec3(2, 3, 4)) < 1e-12);
    }
    for (const Element& e : m.elements) {
        CHECK(e.emission == dvec3(2, 3, 4));
        CHECK(e.material == 1);
        CHECK(e.node == 1);
    }

    // Trapezoid (0,0) (4,0) (3,2) (1,2): parallel sides a = 4, b = 2, height h = 2.
    // Area (a + b) h / 2 = 6; centroid height h (a + 2b) / (3 (a + b)) = 8/9 (vertex mean: 1).
    const Mesh trap = build(scene_of(split_quad({0, 0, 0}, {4, 0, 0}, {3, 2, 0}, {1, 2, 0})), {10.0, 10.0});
    REQUIRE(trap.quads == 1);
    REQUIRE(trap.patches.size() == 1);
    REQUIRE(trap.elements.size() == 1);
    CHECK(trap.patches[0].area == Approx(6.0).epsilon(1e-14));
    CHECK(glm::length(trap.patches[0].centroid - dvec3(2.0, 8.0 / 9.0, 0.0)) < 1e-14);
    CHECK(glm::length(trap.elements[0].centroid - dvec3(2.0, 8.0 / 9.0, 0.0)) < 1e-14);
}

TEST_CASE("neighbouring elements share bit-identical vertices on skewed 3D faces", "[mesh]") {
    // A trapezoid on a tilted plane with awkward coordinates, so rounding would show.
    const dvec3 o(0.1, 0.2, 0.3), u = glm::normalize(dvec3(1.0, 0.3, 0.7)),
                                  w = glm::normalize(glm::cross(dvec3(0.2, 1.0, -0.4), u));
    auto at = [&](double a, double b) { return o + a * u + b * w; };
    const Mesh quad = build(scene_of(split_quad(at(0, 0), at(3.1, 0), at(2.3, 1.7), at(0.4, 1.7))), {0.7, 0.3});
    REQUIRE(quad.quads == 1);
    CHECK(quad.patches.size() > 10);
    CHECK(euler_characteristic(quad.elements) == 1);
    check_ranges(quad);

    const Mesh lone = build(scene_of({tri(at(0, 0), at(3.1, 0.2), at(0.9, 2.4))}), {0.7, 0.3});
    CHECK(lone.patches.size() > 10);
    CHECK(euler_characteristic(lone.elements) == 1);
    check_ranges(lone);

    // Two faces meshed separately that share an edge, walked in opposite directions, divided
    // equally: their points on it must still match bit for bit (one disk, Euler 1).
    const dvec3 up = glm::cross(u, w);
    const Mesh quads = build(scene_of({
                                 tri(at(0, 0), at(1.3, 0), at(1.3, 1.7), 0),
                                 tri(at(0, 0), at(1.3, 1.7), at(0, 1.7), 0),
                                 // the second quad starts at its far corner, so it walks x = 1.3 downwards
                                 tri(at(2.9, 1.7), at(1.3, 1.7), at(1.3, 0), 1),
                                 tri(at(2.9, 1.7), at(1.3, 0), at(2.9, 0), 1),
                             }),
                             {0.7, 0.3});
    REQUIRE(quads.quads == 2);
    CHECK(euler_characteristic(quads.elements) == 1);

    const Mesh folded =
        build(scene_of({tri(at(0, 0), at(2, 0), at(0, 2)), tri(at(2, 0), at(2, 2) + 0.5 * up, at(0, 2))}), {0.7, 0.3});
    REQUIRE(folded.quads == 0);
    CHECK(euler_characteristic(folded.elements) == 1);
}

TEST_CASE("invalid sizes are an internal error", "[mesh]") {
    const Scene s = scene_of({tri({0, 0, 0}, {1, 0, 0}, {0, 1, 0})});
    CHECK_THROWS_AS(build(s, {0.0, 0.0}), hemirad::InternalError);
    CHECK_THROWS_AS(build(s, {0.1, 0.2}), hemirad::InternalError);
    CHECK_THROWS_AS(build(s, {0.1, -1.0}), hemirad::InternalError);
    CHECK_NOTHROW(build(s, {0.2, 0.2}));
}

TEST_CASE("two builds of the same scene are identical", "[mesh]") {
    Material two_sided;
    two_sided.double_sided = true;
    two_sided.emission = {1, 0.5, 0.25};
    std::vector<Triangle> tris = split_quad({0, 0, 0}, {1.3, 0, 0}, {1.1, 0.9, 0.18}, {0, 1, 0.2});
    Triangle lone = tri({2, 0, 0}, {3, 0.1, 0}, {2.2, 1.7, 0.4}, 1, 1);
    lone.rho = {dvec3(0.1, 0.2, 0.3), dvec3(0.9, 0.1, 0.4), dvec3(0.3, 0.8, 0.7)};
    tris.push_back(lone);
    const Scene s = scene_of(tris, {Material{}, two_sided});

    const Mesh a = build(s, {0.3, 0.1});
    const Mesh b = build(s, {0.3, 0.1});
    REQUIRE(a.patches.size() == b.patches.size());
    REQUIRE(a.elements.size() == b.elements.size());
    REQUIRE(a.quads == 1);
    for (std::size_t i = 0; i < a.patches.size(); ++i) {
        const Patch &p = a.patches[i], &q = b.patches[i];
        REQUIRE(p.poly.v == q.poly.v);
        REQUIRE(p.poly.n == q.poly.n);
        REQUIRE(p.normal == q.normal);
        REQUIRE(p.centroid == q.centroid);
        REQUIRE(p.area == q.area);
        REQUIRE(p.emission == q.emission);
        REQUIRE(p.first_element == q.first_element);
        REQUIRE(p.element_count == q.element_count);
        REQUIRE(p.node == q.node);
    }
    for (std::size_t i = 0; i < a.elements.size(); ++i) {
        const Element &e = a.elements[i], &f = b.elements[i];
        REQUIRE(e.poly.v == f.poly.v);
        REQUIRE(e.poly.n == f.poly.n);
        REQUIRE(e.normal == f.normal);
        REQUIRE(e.centroid == f.centroid);
        REQUIRE(e.area == f.area);
        REQUIRE(e.rho == f.rho);
        REQUIRE(e.emission == f.emission);
        REQUIRE(e.patch == f.patch);
        REQUIRE(e.node == f.node);
        REQUIRE(e.material == f.material);
        REQUIRE(e.has_twin == f.has_twin);
        REQUIRE(e.back == f.back);
    }
}
