// Adaptive refinement: splitting, contrast marking, the flux-preserving re-gather, and the gain
// against an exact reference at equal element count.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>

#include "formfactor/analytic.h"
#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "mesh/refine.h"
#include "solve/progressive.h"
#include "solve/refinement.h"
#include "test_scenes.h"

using namespace hemirad;
using Catch::WithinRel;

namespace {

// A square lamp (E = 1, facing down at height 2) over a black floor [−2, 2]², and between them a
// black square occluder [−0.3, 0.3]² at kOccluderHeight: a shadow with an umbra and a penumbra. Every ρ = 0, so the
// floor's irradiance is the lamp's direct light, known exactly (below).
// Near the floor, so the shadow is sharp: a penumbra 0.14 wide around an umbra 0.54 across.
constexpr double kOccluderHeight = 0.25;
scene::Scene shadow_scene() {
    scene::Scene s;
    const std::uint32_t lamp = scene::add_material(s, glm::dvec3(0.0), glm::dvec3(1.0));
    const std::uint32_t black = scene::add_material(s, glm::dvec3(0.0), glm::dvec3(0.0));
    scene::add_quad(s, {-2, -2, 0}, {2, -2, 0}, {2, 2, 0}, {-2, 2, 0}, black, "floor");
    const double h = kOccluderHeight;
    scene::add_quad(s, {-0.3, -0.3, h}, {0.3, -0.3, h}, {0.3, 0.3, h}, {-0.3, 0.3, h}, black, "occluder");
    // The lamp as 4 × 4 quads of one patch each (a hemicube sees the occluder from its patch's
    // centre, so 16 patches sample the penumbra).
    constexpr int lamp_cells = 4;
    for (int j = 0; j < lamp_cells; ++j) {
        for (int i = 0; i < lamp_cells; ++i) {
            const double x0 = -0.5 + double(i) / lamp_cells, x1 = -0.5 + double(i + 1) / lamp_cells;
            const double y0 = -0.5 + double(j) / lamp_cells, y1 = -0.5 + double(j + 1) / lamp_cells;
            scene::add_quad(s, {x0, y0, 2}, {x0, y1, 2}, {x1, y1, 2}, {x1, y0, 2}, lamp, "lamp");
        }
    }
    scene::finish(s);
    return s;
}

mesh::Polygon rect_at_2(double x0, double x1, double y0, double y1) {
    mesh::Polygon p;
    p.n = 4;
    p.v = {glm::dvec3(x0, y0, 2), glm::dvec3(x1, y0, 2), glm::dvec3(x1, y1, 2), glm::dvec3(x0, y1, 2)};
    return p;
}

// Exact irradiance at floor point (x, y): Lambert's factor to the part of the lamp the occluder
// leaves visible. Seen from (x, y, 0) the occluder [−0.3, 0.3]² at height 1 covers, on the lamp's
// plane at height 2, the square [−0.3k − (k − 1)x, 0.3k − (k − 1)x] × (the same in y), k = 2 / h
// for an occluder at height h; the lamp minus that square is at most four rectangles, whose
// factors add.
double exact_irradiance(double x, double y) {
    const double lx0 = -0.5, lx1 = 0.5, ly0 = -0.5, ly1 = 0.5;
    const double k = 2.0 / kOccluderHeight;  // a point at height h projects from (x, y, 0) to height 2 ×k
    const double px0 = -0.3 * k - (k - 1) * x, px1 = 0.3 * k - (k - 1) * x;
    const double py0 = -0.3 * k - (k - 1) * y, py1 = 0.3 * k - (k - 1) * y;
    std::vector<mesh::Polygon> pieces;
    if (px1 <= lx0 || px0 >= lx1 || py1 <= ly0 || py0 >= ly1) {
        pieces.push_back(rect_at_2(lx0, lx1, ly0, ly1));
    } else {
        const double mx0 = std::max(lx0, px0), mx1 = std::min(lx1, px1);
        if (mx0 > lx0) pieces.push_back(rect_at_2(lx0, mx0, ly0, ly1));
        if (mx1 < lx1) pieces.push_back(rect_at_2(mx1, lx1, ly0, ly1));
        if (py0 > ly0) pieces.push_back(rect_at_2(mx0, mx1, ly0, py0));
        if (py1 < ly1) pieces.push_back(rect_at_2(mx0, mx1, py1, ly1));
    }
    double f = 0.0;
    for (const auto& p : pieces) f += formfactor::point_to_polygon({x, y, 0}, {0, 0, 1}, p);
    return f;
}

struct FloorResult {
    std::size_t floor_elements = 0;
    double rms = 0.0;          // RMS of (element value − exact) over a fine grid of floor points, / mean
    double flux_before = 0.0;  // Σ H A over the floor, solved and after refinement
    double flux_after = 0.0;
    std::size_t fine_far = 0;   // floor elements smaller than the coarsest, away from the shadow
    std::size_t fine_near = 0;  // … within its reach (the penumbra ends 0.42 from the centre)
};

// As a bake does: the hemicube's resolution doubles with the refinement level.
std::unique_ptr<formfactor::Engine> engine_for(const mesh::Mesh& m, int level = 0) {
    return std::make_unique<formfactor::NearFieldEngine>(
        m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{solve::regather_hemicube(256, level), 7}));
}

// Solves the shadow scene with floor elements of `element_size`, refines `levels` times, and
// measures the piecewise-constant floor irradiance against the exact one at 200 × 200 points.
FloorResult bake_floor(double element_size, int levels) {
    const scene::Scene s = shadow_scene();
    mesh::Mesh m = mesh::build(s, {std::max(0.25, element_size), element_size});
    auto engine = engine_for(m);
    solve::Settings settings;
    settings.threshold = 0.0;
    solve::Progressive solver(m, *engine, settings);
    while (solver.step()) {
    }
    std::vector<glm::dvec3> H = solver.irradiance(true);
    FloorResult out;
    for (std::size_t k = 0; k < m.elements.size(); ++k)
        if (m.elements[k].node == 0) out.flux_before += H[k].x * m.elements[k].area;
    if (levels > 0) {
        solve::RefineSettings rs;
        rs.max_levels = levels;
        solve::RefineResult r = solve::refine(std::move(m), std::move(H), solver.shot(), engine_for, rs);
        m = std::move(r.mesh);
        H = std::move(r.irradiance);
    }
    constexpr int kSamples = 200;
    std::vector<double> value(kSamples * kSamples, -1.0);
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        const mesh::Element& e = m.elements[k];
        if (e.node != 0) continue;
        ++out.floor_elements;
        if (e.area < 0.25 * 0.25 * 0.99) {
            const double reach = std::max(std::abs(e.centroid.x), std::abs(e.centroid.y));
            ++(reach > 0.75 ? out.fine_far : out.fine_near);
        }
        out.flux_after += H[k].x * e.area;
        glm::dvec3 lo = e.poly.v[0], hi = e.poly.v[0];
        for (int i = 1; i < e.poly.n; ++i) {
            lo = glm::min(lo, e.poly.v[std::size_t(i)]);
            hi = glm::max(hi, e.poly.v[std::size_t(i)]);
        }
        for (int j = 0; j < kSamples; ++j) {
            const double y = -2.0 + 4.0 * (j + 0.5) / kSamples;
            if (y < lo.y || y >= hi.y) continue;
            for (int i = 0; i < kSamples; ++i) {
                const double x = -2.0 + 4.0 * (i + 0.5) / kSamples;
                if (x >= lo.x && x < hi.x) value[std::size_t(j) * kSamples + std::size_t(i)] = H[k].x;
            }
        }
    }
    double sq = 0.0, sum = 0.0;
    for (int j = 0; j < kSamples; ++j) {
        for (int i = 0; i < kSamples; ++i) {
            const double exact = exact_irradiance(-2.0 + 4.0 * (i + 0.5) / kSamples, -2.0 + 4.0 * (j + 0.5) / kSamples);
            const double got = value[std::size_t(j) * kSamples + std::size_t(i)];
            REQUIRE(got >= 0.0);  // every sample lies in exactly one floor element
            sq += (got - exact) * (got - exact);
            sum += exact;
        }
    }
    const double n = double(kSamples) * kSamples;
    out.rms = std::sqrt(sq / n) / (sum / n);
    return out;
}

mesh::Element element_of(const mesh::Polygon& poly) {
    mesh::Element e;
    e.poly = poly;
    const mesh::Shape shape = mesh::shape_of(poly);
    e.normal = shape.normal;
    e.centroid = shape.centroid;
    e.area = shape.area;
    return e;
}

}  // namespace

TEST_CASE("refinement: children tile their parent and patches stay whole", "[refinement]") {
    scene::Scene base;
    const std::uint32_t grey = scene::add_material(base, glm::dvec3(0.5), glm::dvec3(0.0));
    test::add_triangle(base, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, grey, "triangle");
    const scene::Scene s = test::parallel_rectangles(1, 1, 1, grey, grey, base);
    const mesh::Mesh m = mesh::build(s, {0.5, 0.25});
    std::vector<bool> split(m.elements.size(), false);
    for (std::size_t k = 0; k < split.size(); k += 3) split[k] = true;
    const mesh::Refined r = mesh::split_elements(m, split);
    const auto marked = static_cast<std::size_t>(std::count(split.begin(), split.end(), true));
    REQUIRE(r.mesh.elements.size() == m.elements.size() + 3 * marked);
    REQUIRE(r.mesh.patches.size() == m.patches.size());
    std::vector<double> area(m.elements.size(), 0.0);
    std::uint32_t next = 0;
    for (std::size_t p = 0; p < r.mesh.patches.size(); ++p) {
        const mesh::Patch& patch = r.mesh.patches[p];
        CHECK(patch.first_element == next);  // contiguous, in order
        next += patch.element_count;
        for (std::uint32_t k = patch.first_element; k < next; ++k) {
            CHECK(r.mesh.elements[k].patch == p);
            CHECK(m.elements[r.origin[k]].patch == p);
            area[r.origin[k]] += r.mesh.elements[k].area;
            // A child's centroid lies inside its parent: the same plane, within its bounds.
            const glm::dvec3 d = r.mesh.elements[k].centroid - m.elements[r.origin[k]].centroid;
            CHECK(std::abs(glm::dot(d, m.elements[r.origin[k]].normal)) < 1e-12);
        }
    }
    CHECK(next == r.mesh.elements.size());
    for (std::size_t k = 0; k < m.elements.size(); ++k) CHECK_THAT(area[k], WithinRel(m.elements[k].area, 1e-12));
    // Triangles split into four congruent triangles of a quarter of the area each.
    for (const mesh::Polygon& child : mesh::split_polygon(element_of(m.elements.back().poly).poly))
        CHECK_THAT(mesh::shape_of(child).area, WithinRel(m.elements.back().area / 4, 1e-12));
}

TEST_CASE("refinement: contrast marks both sides of a step and nothing on a smooth ramp", "[refinement]") {
    scene::Scene base;
    const std::uint32_t grey = scene::add_material(base, glm::dvec3(0.5), glm::dvec3(0.0));
    scene::add_quad(base, {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, grey, "floor");
    scene::finish(base);
    const mesh::Mesh m = mesh::build(base, {1.0, 0.1});  // 10 × 10 elements
    const std::vector<int> level(m.elements.size(), 0);
    solve::RefineSettings rs;
    std::vector<glm::dvec3> step(m.elements.size()), ramp(m.elements.size());
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        const double x = m.elements[k].centroid.x;
        step[k] = glm::dvec3(x < 0.5 ? 1.0 : 0.2);
        ramp[k] = glm::dvec3(1.0 + x);  // neighbours differ by < 10%
    }
    const std::vector<bool> at_step = solve::mark_contrast(m, step, level, rs);
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        const double x = m.elements[k].centroid.x;
        CAPTURE(x);
        CHECK(at_step[k] == (std::abs(x - 0.5) < 0.1));  // the columns either side of x = 0.5
    }
    const std::vector<bool> on_ramp = solve::mark_contrast(m, ramp, level, rs);
    CHECK(std::none_of(on_ramp.begin(), on_ramp.end(), [](bool b) { return b; }));
    // At the maximum level nothing more is split.
    const std::vector<int> deep(m.elements.size(), rs.max_levels);
    const std::vector<bool> none = solve::mark_contrast(m, step, deep, rs);
    CHECK(std::none_of(none.begin(), none.end(), [](bool b) { return b; }));
}

TEST_CASE("refinement: a shadow is refined and beats a uniform mesh of as many elements", "[refinement]") {
    // Adaptive: 0.25 elements refined up to three times where the irradiance contrasts. Uniform:
    // the smallest grid of whole elements per 0.25 patch with at least as many floor elements.
    // Measured (N = 256, doubled per level in the re-gather): 256 elements, RMS 0.159; adaptive
    // 976, 0.061; uniform 1024, 0.086 (uniform 4096: 0.045).
    const FloorResult adaptive = bake_floor(0.25, 3);
    const int per_patch = static_cast<int>(std::ceil(std::sqrt(double(adaptive.floor_elements)) / 16.0));
    const FloorResult uniform = bake_floor(0.25 / per_patch, 0);
    const FloorResult coarse = bake_floor(0.25, 0);

    INFO("coarse " << coarse.floor_elements << " elements, RMS " << coarse.rms << "; adaptive "
                   << adaptive.floor_elements << ", " << adaptive.rms << "; uniform " << uniform.floor_elements << ", "
                   << uniform.rms);
    CHECK(uniform.floor_elements >= adaptive.floor_elements);
    CHECK(adaptive.floor_elements > coarse.floor_elements);
    CHECK(adaptive.rms < coarse.rms);
    CHECK(adaptive.rms < 0.8 * uniform.rms);
    // The detail goes to the shadow: the lit floor around it stays coarse.
    INFO("fine elements near the shadow " << adaptive.fine_near << ", away from it " << adaptive.fine_far);
    CHECK(adaptive.fine_near > 500);
    CHECK(adaptive.fine_far == 0);
    // The re-gather shares each parent's flux out: the floor's total does not move.
    CHECK_THAT(adaptive.flux_after, WithinRel(adaptive.flux_before, 1e-12));
}
