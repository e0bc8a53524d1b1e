// Property tests of the fixed-size polygon buffers (issue 20): random, near-degenerate and
// rounding-noise polygons against random planes, through the clip, Lambert's point-to-polygon
// factor, the reference hemicube, the near-field correction and the exact unoccluded engine.
// Built with AddressSanitizer and UBSan (tests/CMakeLists.txt): an overrun fails here even where
// it would not crash.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <memory>
#include <glm/gtc/matrix_transform.hpp>
#include <vector>

#include "core/rng.h"
#include "formfactor/analytic.h"
#include "formfactor/clip.h"
#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "formfactor/unoccluded.h"
#include "mesh/mesh.h"
#include "scene/builder.h"

using namespace hemirad;
using glm::dvec3;

namespace {

// Seeded uniform numbers in [lo, hi): stream `stream`, one counter per draw.
struct Draws {
    std::uint64_t stream;
    std::uint64_t counter = 0;
    double operator()(double lo, double hi) { return lo + (hi - lo) * uniform01(7, stream, counter++); }
    dvec3 unit() {
        for (;;) {
            const dvec3 v((*this)(-1, 1), (*this)(-1, 1), (*this)(-1, 1));
            const double len = glm::length(v);
            if (len > 0.1 && len <= 1.0) return v / len;
        }
    }
};

// The textbook Sutherland–Hodgman, with room for any number of vertices and the crossing taken
// from the lexicographically smaller end (as clip_convex takes it): the algorithm before the
// bound, written independently.
std::vector<dvec3> textbook_clip(const std::vector<dvec3>& in, const dvec3& n, double d) {
    std::vector<dvec3> out;
    for (std::size_t i = 0; i < in.size(); ++i) {
        const dvec3& a = in[i];
        const dvec3& b = in[(i + 1) % in.size()];
        const double fa = glm::dot(n, a) - d, fb = glm::dot(n, b) - d;
        if (fa >= 0.0) out.push_back(a);
        if ((fa >= 0.0) != (fb >= 0.0)) {
            const bool a_first = formfactor::lexicographically_less(a, b);
            const dvec3& p = a_first ? a : b;
            const dvec3& q = a_first ? b : a;
            const double fp = a_first ? fa : fb, fq = a_first ? fb : fa;
            out.push_back(p + (q - p) * (fp / (fp - fq)));
        }
    }
    return out;
}

// clip_convex into a buffer with guard cells on both sides, so a write past n + 1 shows even
// without a sanitizer.
std::vector<dvec3> bounded_clip(const std::vector<dvec3>& in, const dvec3& n, double d) {
    constexpr int kGuard = 8;
    const dvec3 sentinel(-12345.0);
    std::vector<dvec3> buffer(in.size() + 1 + 2 * kGuard, sentinel);
    const int m = formfactor::clip_convex(
        in.data(), static_cast<int>(in.size()), [&](const dvec3& p) { return glm::dot(n, p) - d; },
        buffer.data() + kGuard);
    REQUIRE(m <= static_cast<int>(in.size()) + 1);
    for (int i = 0; i < kGuard; ++i) {
        REQUIRE(buffer[static_cast<std::size_t>(i)] == sentinel);
        REQUIRE(buffer[buffer.size() - 1 - static_cast<std::size_t>(i)] == sentinel);
    }
    return {buffer.begin() + kGuard, buffer.begin() + kGuard + m};
}

// A random convex quad (or triangle) in the plane through `origin` spanned by u, v: corners at
// increasing angles on an ellipse-ish rim, so it is convex and counter-clockwise.
std::vector<dvec3> convex_polygon(Draws& draw, int n, const dvec3& origin, const dvec3& u, const dvec3& v,
                                  double size) {
    std::vector<double> angles;
    for (int i = 0; i < n; ++i) angles.push_back(draw(0.0, 2.0 * M_PI));
    std::sort(angles.begin(), angles.end());
    std::vector<dvec3> out;
    for (double a : angles) out.push_back(origin + size * (std::cos(a) * u + std::sin(a) * v));
    return out;
}

int sign_changes(const std::vector<dvec3>& poly, const dvec3& n, double d) {
    int changes = 0;
    for (std::size_t i = 0; i < poly.size(); ++i)
        changes += (glm::dot(n, poly[i]) - d >= 0.0) != (glm::dot(n, poly[(i + 1) % poly.size()]) - d >= 0.0);
    return changes;
}

// A frame with w = the normal: u, v span the plane.
void basis(const dvec3& w, dvec3& u, dvec3& v) {
    u = glm::normalize(glm::cross(std::abs(w.x) < 0.9 ? dvec3(1, 0, 0) : dvec3(0, 1, 0), w));
    v = glm::cross(w, u);
}

}  // namespace

TEST_CASE("clip: a convex polygon against a random plane is textbook Sutherland-Hodgman", "[polygons]") {
    Draws draw{1};
    int clipped = 0;
    for (int trial = 0; trial < 20000; ++trial) {
        const int n = trial % 2 == 0 ? 3 : 4;
        const dvec3 w = draw.unit();
        dvec3 u, v;
        basis(w, u, v);
        const std::vector<dvec3> poly = convex_polygon(draw, n, dvec3(draw(-2, 2), draw(-2, 2), draw(-2, 2)), u, v, 1.0);
        const dvec3 normal = draw.unit();
        const double d = draw(-1.5, 1.5);
        if (sign_changes(poly, normal, d) > 2) continue;  // rounding made it non-convex: the next test
        const std::vector<dvec3> want = textbook_clip(poly, normal, d);
        const std::vector<dvec3> got = bounded_clip(poly, normal, d);
        REQUIRE(got == want);  // vertex for vertex, bit for bit
        clipped += static_cast<int>(got.size() != poly.size());
    }
    CHECK(clipped > 5000);  // the planes did cut most of them
}

TEST_CASE("clip: polygons lying in the plane up to rounding gain at most one vertex", "[polygons]") {
    Draws draw{2};
    int textbook_overruns = 0;
    for (int trial = 0; trial < 20000; ++trial) {
        const int n = trial % 3 == 0 ? 3 : 4;
        const dvec3 normal = draw.unit();
        dvec3 u, v;
        basis(normal, u, v);
        const double scale = std::pow(10.0, draw(-4, 4));
        const dvec3 origin = scale * dvec3(draw(-3, 3), draw(-3, 3), draw(-3, 3));
        const double d = glm::dot(normal, origin);
        std::vector<dvec3> poly = convex_polygon(draw, n, origin, u, v, scale * draw(0.01, 2.0));
        // Off the plane by noise of a few ulps of the coordinates, alternating in sign half the
        // time (the worst pattern: +, −, +, − changes sign four times).
        for (int i = 0; i < n; ++i) {
            const double ulps = (trial % 2 == 0 ? (i % 2 == 0 ? 1.0 : -1.0) : draw(-1, 1)) * draw(0.0, 4.0);
            poly[static_cast<std::size_t>(i)] += normal * (ulps * 2.2e-16 * scale);
        }
        const std::vector<dvec3> textbook = textbook_clip(poly, normal, d);
        textbook_overruns += textbook.size() > poly.size() + 1;
        const std::vector<dvec3> got = bounded_clip(poly, normal, d);
        for (const dvec3& p : got) {
            REQUIRE(std::isfinite(p.x));
            REQUIRE(std::isfinite(p.y));
            REQUIRE(std::isfinite(p.z));
            REQUIRE(std::abs(glm::dot(normal, p) - d) <= 1e-12 * scale);  // still in the plane
        }
    }
    // The cases that overran the old buffers do occur: the textbook clip gains two vertices.
    CHECK(textbook_overruns > 100);
}

TEST_CASE("clip: quads through a hemicube face's five planes stay within 4 + 5 vertices", "[polygons]") {
    // The reference's frustum planes of the top face: z >= eps, |x| <= z, |y| <= z. Quads through
    // the eye's corner rays and along the planes, with rounding noise, are the worst inputs.
    Draws draw{3};
    const double eps = 1e-9;
    const std::vector<std::pair<dvec3, double>> planes = {
        {{0, 0, 1}, eps}, {{-1, 0, 1}, 0.0}, {{1, 0, 1}, 0.0}, {{0, -1, 1}, 0.0}, {{0, 1, 1}, 0.0}};
    int worst = 0;
    for (int trial = 0; trial < 20000; ++trial) {
        const dvec3 corner = glm::normalize(dvec3(trial % 2 == 0 ? 1 : -1, trial % 3 == 0 ? 1 : -1, 1));
        const dvec3 normal = trial % 4 == 0 ? planes[std::size_t(1 + trial / 4 % 4)].first / std::sqrt(2.0) : draw.unit();
        dvec3 u, v;
        basis(glm::normalize(normal), u, v);
        const dvec3 origin = corner * draw(0.0, 3.0) + 1e-15 * draw.unit();
        std::vector<dvec3> poly = convex_polygon(draw, 4, origin, u, v, draw(1e-6, 2.0));
        for (const auto& [n, d] : planes) {
            poly = bounded_clip(poly, n, d);
            if (poly.size() < 3) break;
        }
        REQUIRE(poly.size() <= 9u);
        worst = std::max(worst, static_cast<int>(poly.size()));
    }
    CHECK(worst >= 7);  // the clips did cut corners
}

TEST_CASE("point_to_polygon: near-coplanar polygons give a finite factor in [0, 1]", "[polygons]") {
    Draws draw{4};
    for (int trial = 0; trial < 20000; ++trial) {
        const dvec3 normal = draw.unit();
        dvec3 u, v;
        basis(normal, u, v);
        const double scale = std::pow(10.0, draw(-4, 4));
        const dvec3 point = scale * dvec3(draw(-1, 1), draw(-1, 1), draw(-1, 1));
        // Corners on a circle of radius `scale`, its centre 0 to 3 radii from the point: beside the
        // point the polygon is seen edge-on (next to nothing); over it, a lid at a height of
        // rounding noise that may cover the whole hemisphere.
        const double offset = draw(0.0, 3.0);
        mesh::Polygon poly;
        poly.n = trial % 2 == 0 ? 4 : 3;
        const std::vector<dvec3> corners = convex_polygon(draw, poly.n, point + scale * offset * u, u, v, scale);
        for (int i = 0; i < poly.n; ++i) {
            const double ulps = (i % 2 == 0 ? 1.0 : -1.0) * draw(0.0, 4.0);
            poly.v[std::size_t(i)] = corners[std::size_t(i)] + normal * (ulps * 2.2e-16 * scale);
        }
        const double f = formfactor::point_to_polygon(point, normal, poly);
        REQUIRE(std::isfinite(f));
        REQUIRE(f >= 0.0);
        REQUIRE(f <= 1.0 + 1e-12);
        if (offset > 1.1) REQUIRE(f <= 1e-6);
    }
    // And the closed form of REFERENCES.md still holds: a unit square centred 1 above the point.
    mesh::Polygon square;
    square.n = 4;
    square.v = {dvec3(-0.5, -0.5, 1), dvec3(0.5, -0.5, 1), dvec3(0.5, 0.5, 1), dvec3(-0.5, 0.5, 1)};
    CHECK_THAT(formfactor::point_to_polygon(dvec3(0), dvec3(0, 0, 1), square), Catch::Matchers::WithinAbs(0.2394564705, 1e-10));
}

namespace {

// A double-sided emissive cylinder of `segments` sides (side quads as two triangles, fan caps)
// under a rotated, scaled, shifted transform, above a floor: every element of a curved,
// double-sided surface is near-coplanar with its neighbours, the shape that overran the clip.
scene::Scene cylinder_scene(int segments, const glm::dmat3& transform) {
    scene::Scene s;
    const std::uint32_t lamp = scene::add_material(s, dvec3(0.7), dvec3(2.0), /*double_sided=*/true);
    const std::uint32_t floor = scene::add_material(s, dvec3(0.5), dvec3(0.0));
    s.nodes.push_back({"cylinder", 0});
    const dvec3 offset(0.2, 2.0, -0.1);
    const auto at = [&](double angle, double y) { return transform * dvec3(std::cos(angle), y, std::sin(angle)) + offset; };
    const dvec3 bottom = transform * dvec3(0, -1, 0) + offset, top = transform * dvec3(0, 1, 0) + offset;
    for (int i = 0; i < segments; ++i) {
        const double a0 = 2.0 * M_PI * i / segments, a1 = 2.0 * M_PI * (i + 1) / segments;
        const dvec3 p00 = at(a0, -1), p10 = at(a1, -1), p01 = at(a0, 1), p11 = at(a1, 1);
        const dvec3 rho(0.7);
        s.triangles.push_back({{p00, p01, p11}, {rho, rho, rho}, lamp, 0, 0});
        s.triangles.push_back({{p00, p11, p10}, {rho, rho, rho}, lamp, 0, 0});
        s.triangles.push_back({{bottom, p00, p10}, {rho, rho, rho}, lamp, 0, 0});
        s.triangles.push_back({{top, p11, p01}, {rho, rho, rho}, lamp, 0, 0});
    }
    scene::add_quad(s, {-4, 0, -4}, {-4, 0, 4}, {4, 0, 4}, {4, 0, -4}, floor, "floor");
    scene::finish(s);
    return s;
}

// Every shot's factors are finite and non-negative and, with `blocked`, cover at most the
// hemisphere.
void check_shots(const mesh::Mesh& m, formfactor::Engine& engine) {
    formfactor::ShotResult r;
    for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
        engine.shoot(p, p, r);
        double sum = r.blocked;
        for (const double f : r.F) {
            REQUIRE(std::isfinite(f));
            REQUIRE(f >= 0.0);
            sum += f;
        }
        REQUIRE(sum <= 1.0 + 1e-9);
    }
}

}  // namespace

TEST_CASE("a double-sided cylinder under a rotated, scaled node: every engine stays in its buffers", "[polygons]") {
    const glm::dmat3 rotate = glm::dmat3(glm::rotate(glm::dmat4(1.0), 0.7, glm::normalize(dvec3(1, 2, 3))));
    const glm::dmat3 transform = rotate * glm::dmat3(0.3, 0, 0, 0, 1.7, 0, 0, 0, 0.3);
    const scene::Scene s = cylinder_scene(28, transform);
    REQUIRE(s.triangles.size() == 4 * 28 + 2);
    const mesh::Mesh cells = mesh::build(s, {0.5, 0.25, /*cluster=*/false});  // the exact engine's mesh
    formfactor::UnoccludedEngine exact(cells);
    check_shots(cells, exact);
    for (const bool cluster : {false, true}) {
        const mesh::Mesh m = mesh::build(s, {0.5, 0.25, cluster});
        REQUIRE((m.clusters > 0) == cluster);
        formfactor::NearFieldEngine hemicube(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{32, 1}));
        check_shots(m, hemicube);
    }
}
