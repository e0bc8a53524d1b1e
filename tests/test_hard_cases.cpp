// Numerically hard cases (issue 6, part): each with a known answer, and no NaN or Inf anywhere.
// Solved with the matrix solver on the bake's engine stack (reference hemicube under the
// near-field correction), which has no early stop to hide a drift.
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "formfactor/analytic.h"
#include "formfactor/hemicube.h"
#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "output/output.h"
#include "solve/matrix.h"
#include "solve/progressive.h"
#include "backends.h"
#include "test_scenes.h"

using namespace hemirad;
using Catch::Matchers::WithinRel;

namespace {

bool finite(const std::vector<glm::dvec3>& values) {
    for (const glm::dvec3& v : values)
        if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) return false;
    return true;
}

// The bake's engine stack: the near-field correction over the reference hemicube.
std::unique_ptr<formfactor::Engine> bake_engine(const mesh::Mesh& m, int hemicube, std::uint64_t seed = 1) {
    return std::make_unique<formfactor::NearFieldEngine>(
        m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{hemicube, seed}));
}

// The same stack over any backend's hemicube engine (tests/backends.h).
std::unique_ptr<formfactor::Engine> bake_engine(const test::Backend& b, const mesh::Mesh& m, int hemicube,
                                                std::uint64_t seed = 1) {
    return std::make_unique<formfactor::NearFieldEngine>(m, b.make(m, formfactor::Settings{hemicube, seed}));
}

// Area-weighted radiosity (red) of node `node` for any per-element B.
double node_mean(const mesh::Mesh& m, const std::vector<glm::dvec3>& B, std::uint32_t node) {
    double sum = 0.0, area = 0.0;
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        if (m.elements[k].node != node) continue;
        sum += B[k].x * m.elements[k].area;
        area += m.elements[k].area;
    }
    return sum / area;
}

struct Result {
    mesh::Mesh mesh;
    std::vector<glm::dvec3> B;
    solve::Energy energy;
    bool converged = false;
};

// Meshes `s` with patches of `patch` (elements half that) and solves it to 1e-9.
Result solve_scene(const scene::Scene& s, double patch, int hemicube = 64) {
    Result r;
    r.mesh = mesh::build(s, {patch, patch / 2});
    const auto engine = bake_engine(r.mesh, hemicube);
    solve::MatrixSettings settings;
    settings.tolerance = 1e-9;
    settings.max_iterations = 100000;
    solve::Matrix solver(r.mesh, *engine, settings);
    solver.solve();
    r.B = solver.radiosity();
    r.energy = solver.energy();
    r.converged = solver.converged();
    REQUIRE(finite(r.B));
    REQUIRE(finite(solver.irradiance()));
    return r;
}

// Area-weighted radiosity (red) of node `node`.
double node_average(const Result& r, std::uint32_t node) {
    return node_mean(r.mesh, r.B, node);
}

void check_books(const solve::Energy& e) {
    CHECK(std::isfinite(e.emitted));
    CHECK_THAT(e.absorbed + e.escaped + e.unshot, WithinRel(e.emitted, 1e-9));
}

// A closed box of grey walls (ρ = `rho`, material 0) lit by its face 3 (ρ 0.5, E = 1, material 1).
struct LitBox {
    scene::Scene scene;
    std::uint32_t wall = 0, light = 0;
};
LitBox lit_box(const glm::dvec3& size, double rho) {
    LitBox box;
    box.wall = scene::add_material(box.scene, glm::dvec3(rho), glm::dvec3(0.0));
    box.light = scene::add_material(box.scene, glm::dvec3(0.5), glm::dvec3(1.0));
    box.scene = test::closed_box(
        size, [&](int face) { return face == 3 ? box.light : box.wall; }, box.scene);
    return box;
}

// Σ_k A_k B_k (red): the radiosity flux leaving every element.
double total_flux(const mesh::Mesh& m, const std::vector<glm::dvec3>& B) {
    double sum = 0.0;
    for (std::size_t k = 0; k < m.elements.size(); ++k) sum += B[k].x * m.elements[k].area;
    return sum;
}

// Σ_k A_k E_k (red): the emitted flux.
double emitted_flux(const mesh::Mesh& m) {
    double sum = 0.0;
    for (const mesh::Element& e : m.elements) sum += e.emission.x * e.area;
    return sum;
}

// The matrix solver on the bake's engine stack (N = 64, grey) to a residual of 1e-9, which must
// converge within 30000 Gauss–Seidel sweeps: the radiosity and the books.
std::pair<std::vector<glm::dvec3>, solve::Energy> gauss_seidel_in_bounded_sweeps(const mesh::Mesh& m) {
    auto engine = bake_engine(m, 64);
    solve::MatrixSettings settings;
    settings.tolerance = 1e-9;
    settings.grey = true;
    settings.max_iterations = 30000;
    solve::Matrix solver(m, *engine, settings);
    solver.solve();
    CAPTURE(solver.iterations(), solver.error_bound());
    CHECK(solver.converged());
    CHECK(solver.iterations() < settings.max_iterations);
    return {solver.radiosity(), solver.energy()};
}

// What every pass of a progressive run in a closed box of uniform reflectance ρ must keep:
//  - the books: emitted = absorbed + escaped + unshot (1e-9: each pass adds rounding ~1e-16);
//  - the unshot flux U falls by (1 − ρ) of every shot (a pass takes u·A from the pool and gives
//    back ρ·u·A·ΣF, ΣF = 1 to rounding), and the shooter holds the most, at least U / P of it:
//    U_after ≤ U_before · (1 − (1 − ρ) / P), P patches, to 1e-12 for rounding;
//  - Σ A B with the ambient term is Φ_E / (1 − ρ) exactly. Shot light: Σ A B = Φ_E + ρ Σ
//    received, and the books give Σ received = (Φ_E − U − escaped) / (1 − ρ) (what is absorbed
//    is (1 − ρ) of what is received). The ambient term spreads U as H_amb = h ū / (1 − ρ_eff)
//    over the area, h = 1 (closed) and ρ_eff = ρ (measured), adding ρ U / (1 − ρ): the sum is
//    (Φ_E − ρ escaped) / (1 − ρ), and escaped is rounding. Relative error ~1e-16 × 1/(1 − ρ)
//    per pass, so 1e-9 holds with a wide margin and fails on any real leak or drift.
struct PassChecker {
    const mesh::Mesh& m;
    double rho;
    double emitted = emitted_flux(m);
    double previous_unshot = emitted;
    long failures = 0;
    double worst_books = 0.0, worst_identity = 0.0;

    void check(const solve::Progressive& solver) {
        const solve::Energy e = solver.energy();
        const double want = emitted / (1.0 - rho);
        const double flux = total_flux(m, solver.radiosity(/*ambient=*/true));
        worst_books = std::max(worst_books, std::abs(e.absorbed + e.escaped + e.unshot - e.emitted) / e.emitted);
        worst_identity = std::max(worst_identity, std::abs(flux - want) / want);
        const bool books = std::abs(e.absorbed + e.escaped + e.unshot - e.emitted) <= 1e-9 * e.emitted;
        const double P = static_cast<double>(m.patches.size());
        const bool falls = e.unshot <= previous_unshot * (1.0 - (1.0 - rho) / P) * (1.0 + 1e-12);
        const bool identity = std::abs(flux - want) <= 1e-9 * want;
        if (!(books && falls && identity)) {
            // Report the first few failures only: the loops run thousands of passes.
            if (++failures <= 3) {
                CAPTURE(solver.passes(), e.emitted, e.absorbed, e.escaped, e.unshot, previous_unshot, flux, want);
                CHECK(books);
                CHECK(falls);
                CHECK(identity);
            }
        }
        previous_unshot = e.unshot;
    }
};

}  // namespace

TEST_CASE("hard cases: huge and tiny emission give the same light scaled exactly", "[hard]") {
    // A closed box whose six walls (ρ = 0.9) all emit E: B = E / (1 − ρ) = 10 E everywhere, at
    // E = 1, 1e6 and 1e-6 alike; the solve is linear in E, so the three agree to rounding.
    std::vector<double> averages;
    for (double E : {1.0, 1e6, 1e-6}) {
        scene::Scene s;
        const std::uint32_t wall = scene::add_material(s, glm::dvec3(0.9), glm::dvec3(E));
        s = test::closed_box(
            {1.0, 1.0, 1.0}, [&](int) { return wall; }, s);
        const Result r = solve_scene(s, 0.25);
        CHECK(r.converged);
        check_books(r.energy);
        for (std::uint32_t node = 0; node < 6; ++node) {
            CAPTURE(E, node);
            CHECK_THAT(node_average(r, node) / E, WithinRel(10.0, 0.01));
        }
        averages.push_back(node_average(r, 0));
    }
    CHECK_THAT(averages[1] / 1e6, WithinRel(averages[0], 1e-9));
    CHECK_THAT(averages[2] / 1e-6, WithinRel(averages[0], 1e-9));
}

TEST_CASE("hard cases: scenes scaled from 1e-4 to 1e4 give the same radiosity within 0.5%", "[hard]") {
    // A 1 × 0.8 × 1.2 box lit by its ceiling, meshed in proportion to its size (as a bake
    // meshes by the diagonal): every wall's radiosity must not depend on the unit.
    std::vector<std::vector<double>> per_scale;
    for (double scale : {1e-4, 1.0, 1e4}) {
        const Result r = solve_scene(lit_box(glm::dvec3(1.0, 0.8, 1.2) * scale, 0.6).scene, 0.2 * scale);
        check_books(r.energy);
        std::vector<double> walls;
        for (std::uint32_t node = 0; node < 6; ++node) walls.push_back(node_average(r, node));
        per_scale.push_back(walls);
    }
    for (std::size_t node = 0; node < 6; ++node) {
        CAPTURE(node, per_scale[0][node], per_scale[1][node], per_scale[2][node]);
        CHECK_THAT(per_scale[0][node], WithinRel(per_scale[1][node], 0.005));
        CHECK_THAT(per_scale[2][node], WithinRel(per_scale[1][node], 0.005));
    }
}

TEST_CASE("hard cases: a coplanar duplicate of a face changes nothing and fights no one", "[hard]") {
    // The floor of a lit box twice, in the same place (z-fighting in every hemicube): the depth
    // test gives each cell to one copy (ties to the lower element), so what the floor receives
    // is split, not doubled: every other wall and the books are as without the duplicate.
    const auto box = [](bool duplicate) {
        auto [s, wall, light] = lit_box({1.0, 1.0, 1.0}, 0.5);
        if (duplicate) {
            test::add_quad(s, {0, 0, 0}, {0, 0, 1}, {1, 0, 1}, {1, 0, 0}, wall, "floor copy");  // normal +y
            test::finish(s);
        }
        return s;
    };
    const Result plain = solve_scene(box(false), 0.25);
    const Result doubled = solve_scene(box(true), 0.25);
    check_books(doubled.energy);
    CHECK_THAT(doubled.energy.absorbed, WithinRel(plain.energy.absorbed, 1e-6));
    for (std::uint32_t node : {0u, 1u, 3u, 4u, 5u}) {  // all but the floor (node 2)
        CAPTURE(node);
        CHECK_THAT(node_average(doubled, node), WithinRel(node_average(plain, node), 0.01));
    }
}

TEST_CASE("hard cases: skinny triangles and a lamp inside the box keep the books and stay finite", "[hard]") {
    // A closed box whose floor is a fan of 200 needle triangles (1:100 to 1:140), lit by a
    // small two-sided lamp floating inside it: a shooter close to everything, seen edge-on by the
    // floor's slivers. Every emitted watt ends absorbed (the box is closed), nothing escapes.
    const scene::Scene s = test::needle_box(200);
    const Result r = solve_scene(s, 0.25, 128);
    CHECK(r.converged);
    check_books(r.energy);
    CHECK(r.energy.escaped < 1e-3 * r.energy.emitted);  // ΣF = 1 from every patch of a closed box
    CHECK(r.mesh.dropped_triangles == 0);
}

TEST_CASE("hard cases: rho = 0.999 in a closed room converges in bounded time and does not drift", "[hard]") {
    // Every wall of a closed unit box has ρ = 0.999 and emits E = 1: B = E / (1 − ρ) = 1000
    // everywhere. The hemicube's ΣF is exact to rounding (the delta table sums to 1) but its rows
    // are not exactly reciprocal, which moves single walls a little: measured within 0.09% at
    // N = 64, hence 0.5% on the wall averages (a leak of 1e-5 per shot would already be 1%).
    scene::Scene s;
    const double rho = 0.999;
    const std::uint32_t wall = scene::add_material(s, glm::dvec3(rho), glm::dvec3(1.0));
    s = test::closed_box(
        {1.0, 1.0, 1.0}, [&](int) { return wall; }, s);
    const mesh::Mesh m = mesh::build(s, {0.5, 0.25});
    REQUIRE(m.patches.size() == 24);
    const auto walls_at_1000 = [&](const std::vector<glm::dvec3>& B) {
        REQUIRE(finite(B));
        for (std::uint32_t node = 0; node < 6; ++node) {
            CAPTURE(node);
            CHECK_THAT(node_mean(m, B, node), WithinRel(1000.0, 0.005));
        }
    };

    SECTION("progressive shooting with the ambient term") {
        auto engine = bake_engine(m, 64);
        // Plain shooting would need ln(1e4) / (1 − ρ) ≈ 9200 rounds of 24 passes to bring the
        // unshot flux to 1e-4; with the measured ambient term the answer is there after the first
        // round (measured: 48 passes, two rounds). Four rounds at most; the cap of 5000 passes
        // only stops a runaway.
        solve::Progressive solver(m, *engine, {1e-4, 5000});
        PassChecker checker{m, rho};
        while (solver.step()) checker.check(solver);
        CAPTURE(solver.passes());
        CHECK(solver.converged());
        CHECK(solver.passes() <= 4 * 24);
        walls_at_1000(solver.radiosity(true));
    }
    SECTION("progressive shooting far past convergence: 3000 passes at threshold 0") {
        // 60 times the passes it needs: every pass keeps the books and Σ A B = 6000 (PassChecker),
        // the unshot flux falls at least geometrically (so U ≤ (1 − 0.001 / 24)^3000 Φ ≈ 0.88 Φ;
        // measured 0.78), and the answer is still 1000 on every wall.
        auto engine = bake_engine(m, 32);
        solve::Progressive solver(m, *engine, {0.0, 3000});
        PassChecker checker{m, rho};
        while (solver.step()) checker.check(solver);
        CHECK(solver.passes() == 3000);
        CHECK(solver.unshot_fraction() <= std::pow(1.0 - (1.0 - rho) / 24.0, 3000.0));
        walls_at_1000(solver.radiosity(true));
    }
    SECTION("Gauss-Seidel on the full matrix") {
        // Gauss–Seidel's slowest mode is the uniform one, shrinking by about ρ per sweep: from
        // B = E (relative residual ≈ ρ / 1) to 1e-9 × B_max ≈ 1e-6 takes about ln(1e-6) / ln(ρ)
        // ≈ 13800 sweeps at worst (measured: 7254); 30000 is the stated bound.
        const auto [B, e] = gauss_seidel_in_bounded_sweeps(m);
        walls_at_1000(B);
        // Σ A B = Φ_E / (1 − ρ) up to the residual's flux: Σ_p A_p r_p ≤ A · 1e-9 · B_max, which
        // relative to Φ_E = A · E is 1e-9 × 1000 ≈ 1e-6 (B_max ≈ 1000 E).
        CHECK(std::abs(e.unshot) <= 1.1e-6 * e.emitted);
        CHECK_THAT(total_flux(m, B), WithinRel(6000.0, 1.1e-6));
    }
}

TEST_CASE("hard cases: a closed room at rho = 0.999 lit by one wall holds sum(A B) = emitted / (1 - rho)", "[hard]") {
    // A 1 × 0.8 × 1.2 box, every face ρ = 0.999, its ceiling (1 × 1.2) emitting E = 1. Summing
    // B = E + ρ H over a closed enclosure of uniform ρ, with Σ_j F_ij = 1 for every shooter:
    // Σ A B = Φ_E + ρ Σ A B, so Σ A B = Φ_E / (1 − ρ) = 1.2 × 1000 exactly, whatever the
    // form factors' noise. Nothing else here has a closed form; this one is exact.
    scene::Scene s;
    const double rho = 0.999;
    const std::uint32_t wall = scene::add_material(s, glm::dvec3(rho), glm::dvec3(0.0));
    const std::uint32_t light = scene::add_material(s, glm::dvec3(rho), glm::dvec3(1.0));
    s = test::closed_box(
        {1.0, 0.8, 1.2}, [&](int face) { return face == 3 ? light : wall; }, s);
    const mesh::Mesh m = mesh::build(s, {0.4, 0.2});
    const double want = 1.2 / (1.0 - rho);
    REQUIRE_THAT(emitted_flux(m), WithinRel(1.2, 1e-12));

    SECTION("progressive shooting with the ambient term") {
        auto engine = bake_engine(m, 64);
        // The ambient term stands in for everything unshot: Σ A B = Φ_E / (1 − ρ) holds at every
        // pass (PassChecker, 1e-9), converged or not. Bounded: at most four rounds of passes.
        solve::Progressive solver(m, *engine, {1e-4, 20000});
        PassChecker checker{m, rho};
        while (solver.step()) checker.check(solver);
        const long round = static_cast<long>(m.patches.size());
        CAPTURE(solver.passes(), round);
        CHECK(solver.converged());
        CHECK(solver.passes() <= 4 * round);
        const auto B = solver.radiosity(true);
        REQUIRE(finite(B));
        CHECK_THAT(total_flux(m, B), WithinRel(want, 1e-9));
    }
    SECTION("Gauss-Seidel on the full matrix") {
        // Tolerance 1e-9 on the residual: Σ A B within 1e-9 × B_max × A / Φ_E ≈ 1e-9 × 204 × 5.92
        // / 1.2 ≈ 1e-6 of the answer (B_max ≈ E + the mean 1200 / 5.92); 2e-6 allows B_max to
        // be twice the mean. At most 30000 sweeps (see above).
        const auto [B, e] = gauss_seidel_in_bounded_sweeps(m);
        REQUIRE(finite(B));
        check_books(e);
        CHECK(std::abs(e.unshot) <= 2e-6 * e.emitted);
        CHECK_THAT(total_flux(m, B), WithinRel(want, 2e-6));
    }
}

TEST_CASE("hard cases: perpendicular squares sharing an edge and the right-angled corners of a box, on every backend", "[hard][backends]") {
    const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
    HEMIRAD_SKIP_ABSENT(b);
    INFO("backend " << b.name);
    scene::Scene base;
    const std::uint32_t grey = scene::add_material(base, glm::dvec3(0.5), glm::dvec3(0.0));

    SECTION("the squares' form factor both ways, and the patches along the shared edge") {
        // Unit floor (node 0, facing +z) and wall (node 1, facing +y) sharing the x axis:
        // F = 0.2000437761 both ways (equal areas, reciprocity). Patches of 1/4, elements of 1/8,
        // N = 64: what is left is the hemicube's and the near-field collocation's error
        // (measured: −0.25% floor to wall, −0.37% back, the edge patches' rows within 0.35%);
        // 1% on each. The correction's per-element accuracy is test_near_field.cpp's subject.
        const scene::Scene s = test::perpendicular_rectangles(1, 1, 1, grey, grey, base);
        const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
        auto engine = bake_engine(b, m, 64);
        const double exact = 0.2000437761;
        REQUIRE_THAT(test::perpendicular_rectangles_ff(1, 1, 1), WithinRel(exact, 1e-9));
        const double f_floor_wall = test::area_form_factor(m, *engine, 0, 1);
        const double f_wall_floor = test::area_form_factor(m, *engine, 1, 0, 1000);
        CHECK_THAT(f_floor_wall, WithinRel(exact, 0.01));
        CHECK_THAT(f_wall_floor, WithinRel(exact, 0.01));

        // Every shot: every F finite and non-negative, and every receiver along the shared edge
        // (the first row of elements on the other square) seen, F > 0: nothing hides it.
        // The shooters along the edge: their row to the other square against the exact
        // F(A_p → square) = (1/A_p) ∫_p F(x → square) dx, Lambert's point form factor averaged
        // by a 32 × 32 midpoint rule (bounded integrand, 1/2 at the edge: within 1e-6 of the
        // converged rule).
        mesh::Polygon floor, wall;
        floor.n = wall.n = 4;
        floor.v = {glm::dvec3(0, 0, 0), glm::dvec3(1, 0, 0), glm::dvec3(1, 1, 0), glm::dvec3(0, 1, 0)};
        wall.v = {glm::dvec3(0, 0, 0), glm::dvec3(0, 0, 1), glm::dvec3(1, 0, 1), glm::dvec3(1, 0, 0)};
        formfactor::ShotResult r;
        for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
            const mesh::Patch& shooter = m.patches[p];
            engine->shoot(p, 5000 + p, r);
            const std::uint32_t other = 1 - shooter.node;
            long bad = 0, unseen = 0, edge_receivers = 0;
            const std::vector<double> F = r.dense(m.elements.size());
            for (std::size_t k = 0; k < m.elements.size(); ++k) {
                const mesh::Element& e = m.elements[k];
                if (!(std::isfinite(F[k]) && F[k] >= 0.0)) ++bad;
                const double off_edge = e.node == 0 ? e.centroid.y : e.centroid.z;
                if (e.node == other && off_edge < 0.125) {
                    ++edge_receivers;
                    if (!(F[k] > 0.0)) ++unseen;
                }
            }
            CAPTURE(p, bad, unseen);
            CHECK(bad == 0);
            CHECK(edge_receivers == 8);
            CHECK(unseen == 0);
            const double shooter_off_edge = shooter.node == 0 ? shooter.centroid.y : shooter.centroid.z;
            if (shooter_off_edge > 0.25) continue;
            const mesh::Polygon& target = other == 0 ? floor : wall;
            const int q = 32;
            double exact_row = 0.0;
            for (int b = 0; b < q; ++b)
                for (int a = 0; a < q; ++a) {
                    const double u = (a + 0.5) / q, v = (b + 0.5) / q;
                    const auto& P = shooter.poly.v;
                    const glm::dvec3 x =
                        (1 - u) * (1 - v) * P[0] + u * (1 - v) * P[1] + u * v * P[2] + (1 - u) * v * P[3];
                    exact_row += formfactor::point_to_polygon(x, shooter.normal, target) / (q * q);
                }
            const double row = test::node_form_factor(m, r, other);
            CAPTURE(p, shooter.centroid.x, row, exact_row);
            CHECK_THAT(row, WithinRel(exact_row, 0.01));
        }
    }

    SECTION("a closed box: from every patch, sum F + blocked = 1, nothing leaks through a corner") {
        // Each wall meets four others at right angles along shared edges, three at each corner;
        // the hemicube's cells tile the hemisphere and the near-field correction keeps each shot's
        // total, so ΣF = Σ delta = 1 to rounding (measured 1.6e-15): 1e-12. blocked = 0: every
        // front faces in. A corner cell lost or counted twice would be ≥ 1e-6.
        const scene::Scene s = test::closed_box(
            {1.0, 0.7, 1.3}, [&](int) { return grey; }, base);
        const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
        auto engine = bake_engine(b, m, 64);
        formfactor::ShotResult r;
        for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
            engine->shoot(p, p, r);
            double sum = 0.0;
            long bad = 0;
            for (double f : r.F) {
                if (!(std::isfinite(f) && f >= 0.0)) ++bad;
                sum += f;
            }
            CAPTURE(p, sum, r.blocked, bad);
            CHECK(bad == 0);
            CHECK(r.blocked == 0.0);
            CHECK(std::abs(sum + r.blocked - 1.0) <= 1e-12);
        }
    }
}

TEST_CASE("hard cases: zero-area triangles are dropped, counted, and change nothing", "[hard]") {
    // A lit closed box, then the same box with five zero-area triangles: three collinear points
    // (exactly representable), three collinear in decimal only (0.1, 0.2, 0.3 + t (0.3, 0.3,
    // 0.3): their area is rounding, ~1e-17), a repeated vertex, three equal vertices (each in a
    // node of its own, two of them emitting), and a repeated-vertex sliver along the floor's edge
    // inside the floor's own node and primitive, put first so it is met before the floor's two
    // triangles pair into a quad.
    // Known answer: the five are dropped and counted, the mesh is the plain box's, so the
    // solve is the plain box's to the bit (1e-12 allows for nothing but rounding), and no area,
    // normal or radiosity anywhere is zero, NaN or infinite.
    const auto box = [](bool degenerate) {
        auto [s, wall, light] = lit_box({1.0, 1.0, 1.0}, 0.6);
        if (degenerate) {
            const glm::dvec3 rho(0.6);
            scene::Triangle sliver{{glm::dvec3(0, 0, 0), glm::dvec3(1, 0, 0), glm::dvec3(1, 0, 0)}, {rho, rho, rho}};
            sliver.material = wall;
            sliver.node = sliver.primitive = 2;  // the floor's node "y0" and primitive
            s.triangles.insert(s.triangles.begin(), sliver);
            test::add_triangle(s, {0.25, 0.25, 0.25}, {0.5, 0.5, 0.5}, {0.75, 0.75, 0.75}, light, "collinear");
            test::add_triangle(s, {0.1, 0.2, 0.3}, {0.4, 0.5, 0.6}, {0.7, 0.8, 0.9}, wall, "collinear in decimal");
            test::add_triangle(s, {0.2, 0.3, 0.4}, {0.6, 0.5, 0.4}, {0.2, 0.3, 0.4}, light, "repeated vertex");
            test::add_triangle(s, {0.5, 0.5, 0.5}, {0.5, 0.5, 0.5}, {0.5, 0.5, 0.5}, wall, "point");
            test::finish(s);
        }
        return s;
    };
    const scene::Scene plain_scene = box(false), degenerate_scene = box(true);
    const Result plain = solve_scene(plain_scene, 0.25);
    const Result r = solve_scene(degenerate_scene, 0.25);
    CHECK(plain.mesh.dropped_triangles == 0);
    CHECK(r.mesh.dropped_triangles == 5);
    CHECK(r.mesh.quads == plain.mesh.quads);
    REQUIRE(r.mesh.patches.size() == plain.mesh.patches.size());
    REQUIRE(r.mesh.elements.size() == plain.mesh.elements.size());

    const auto sound = [](const glm::dvec3& normal, double area) {
        return std::isfinite(area) && area > 0.0 && std::isfinite(glm::length(normal)) &&
               std::abs(glm::length(normal) - 1.0) < 1e-12;
    };
    for (const mesh::Patch& p : r.mesh.patches) CHECK(sound(p.normal, p.area));
    for (const mesh::Element& e : r.mesh.elements) CHECK(sound(e.normal, e.area));

    CHECK(r.converged);
    check_books(r.energy);
    CHECK_THAT(r.energy.emitted, WithinRel(1.0, 1e-12));  // the ceiling alone: the emitting slivers add nothing
    for (std::size_t k = 0; k < r.B.size(); ++k) {
        CAPTURE(k);
        REQUIRE(r.mesh.elements[k].node == plain.mesh.elements[k].node);
        CHECK_THAT(r.B[k].x, WithinRel(plain.B[k].x, 1e-12));
    }
    // The report's per-node averages: the four nodes that lost every triangle get zero area and
    // zero light, not 0 / 0.
    const std::vector<glm::dvec3> H(r.B.size(), glm::dvec3(0.0));
    const auto summary = output::summarize(degenerate_scene, r.mesh, r.B, H);
    REQUIRE(summary.size() == 10);
    for (std::size_t node = 0; node < summary.size(); ++node) {
        CAPTURE(node, summary[node].area, summary[node].radiosity.x);
        CHECK(std::isfinite(summary[node].radiosity.x));
        if (node < 6) {
            CHECK(summary[node].area > 0.0);
            CHECK(summary[node].radiosity.x > 0.0);
        } else {
            CHECK(summary[node].area == 0.0);
            CHECK(summary[node].radiosity.x == 0.0);
        }
    }
}

TEST_CASE("hard cases: geometry exactly on the hemicube's face boundaries is counted once", "[hard]") {
    // The hemicube of one shot, at the centroid of a small square on z = 0, has the frame
    // make_frame(patch, seed, shot): (u, v) turned about w = +z by a seeded angle. Built in that
    // frame (to the rounding of world coordinates, ~1e-16), the box [−a, a]² × [0, 1] around the
    // shooter lines up with the hemicube:
    //  - a = 1: the ceiling is exactly the top face (its edges on |x| = z, |y| = z: the top/side
    //    boundaries), each wall exactly one side face (upright edges on |x| = |y|, the side/side
    //    boundaries; top edge on a top/side boundary);
    //  - a = 2: the ceiling's inner 2 × 2 elements are exactly the top face (element edges inside
    //    the ceiling lie on the top/side boundaries), its outer ring exactly the upper half of
    //    the side faces, and the walls (corners on |x| = |y|) their lower half.
    // Cell centres lie half a cell from every one of these lines (N = 64: v/d = 1/2 is the row
    // boundary 16), so each surface owns exactly its cells, and its F is its exact form factor
    // from the point: Lambert's formula (in the frame). One boundary row or column counted
    // twice or lost changes some F by 1e-4 or more (at N = 64 even the smallest boundary cell,
    // at the foot of a side/side boundary, is ~1e-6): the tolerance 1e-10 allows rounding only.
    // Closed: ΣF = 1 to rounding (1e-12), blocked = 0.
    const int N = 64;
    const std::uint64_t seed = 3;
    for (double a : {1.0, 2.0}) {
        for (std::uint64_t shot : {0u, 1u, 2u, 17u, 1000u}) {
            mesh::Patch probe;
            probe.normal = {0.0, 0.0, 1.0};
            probe.centroid = {0.0, 0.0, 0.0};
            const formfactor::Frame frame = formfactor::make_frame(probe, seed, shot);
            const auto world = [&](const glm::dvec3& p) { return p.x * frame.u + p.y * frame.v + p.z * frame.w; };

            scene::Scene s;
            const std::uint32_t grey = scene::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
            test::add_quad(s, {-0.1, -0.1, 0}, {0.1, -0.1, 0}, {0.1, 0.1, 0}, {-0.1, 0.1, 0}, grey, "shooter");
            // Surfaces in frame coordinates, counter-clockwise seen from inside the box.
            const std::vector<std::array<glm::dvec3, 4>> faces = {
                {glm::dvec3(-a, -a, 1), glm::dvec3(-a, a, 1), glm::dvec3(a, a, 1), glm::dvec3(a, -a, 1)},    // ceiling
                {glm::dvec3(a, -a, 0), glm::dvec3(a, -a, 1), glm::dvec3(a, a, 1), glm::dvec3(a, a, 0)},      // +x
                {glm::dvec3(-a, -a, 0), glm::dvec3(-a, a, 0), glm::dvec3(-a, a, 1), glm::dvec3(-a, -a, 1)},  // −x
                {glm::dvec3(-a, a, 0), glm::dvec3(a, a, 0), glm::dvec3(a, a, 1), glm::dvec3(-a, a, 1)},      // +y
                {glm::dvec3(-a, -a, 0), glm::dvec3(-a, -a, 1), glm::dvec3(a, -a, 1), glm::dvec3(a, -a, 0)},  // −y
            };
            for (std::size_t f = 0; f < faces.size(); ++f) {
                const auto& q = faces[f];
                for (const glm::dvec3& corner : q) {
                    const glm::dvec3 back = frame.to_local(world(corner));  // on the boundary to rounding
                    REQUIRE(glm::length(back - corner) < 1e-14);
                }
                test::add_quad(s, world(q[0]), world(q[1]), world(q[2]), world(q[3]), grey, "face" + std::to_string(f));
            }
            test::finish(s);
            // One patch per surface; elements of 0.5, so the ceiling at a = 2 has edges at ±1.
            const mesh::Mesh m = mesh::build(s, {5.0, 0.5});
            REQUIRE(m.patches.size() == 6);
            REQUIRE(m.patches[0].node == 0);
            REQUIRE(m.patches[0].normal == probe.normal);
            REQUIRE(m.patches[0].centroid == probe.centroid);

            formfactor::ReferenceEngine engine(m, {N, seed});
            formfactor::ShotResult r;
            engine.shoot(0, shot, r);
            double sum = 0.0, inner = 0.0;
            for (std::size_t i = 0; i < r.size(); ++i) {
                const std::uint32_t k = r.element[i];
                sum += r.F[i];
                const glm::dvec3 c = frame.to_local(m.elements[k].centroid);
                if (m.elements[k].node == 1 && std::abs(c.x) < 1.0 && std::abs(c.y) < 1.0) inner += r.F[i];
            }
            CAPTURE(a, shot, sum, r.blocked);
            CHECK(r.blocked == 0.0);
            CHECK(std::abs(sum - 1.0) <= 1e-12);
            for (std::uint32_t f = 0; f < faces.size(); ++f) {
                const double exact = formfactor::point_to_polygon(glm::dvec3(0, 0, 1), faces[f].data(), 4);
                const double got = test::node_form_factor(m, r, f + 1);
                CAPTURE(f, got, exact);
                CHECK_THAT(got, WithinRel(exact, 1e-10));
            }
            const glm::dvec3 top[4] = {glm::dvec3(-1, -1, 1), glm::dvec3(-1, 1, 1), glm::dvec3(1, 1, 1),
                                       glm::dvec3(1, -1, 1)};
            const double top_exact = formfactor::point_to_polygon(glm::dvec3(0, 0, 1), top, 4);
            CAPTURE(inner, top_exact);
            CHECK_THAT(inner, WithinRel(top_exact, 1e-10));
        }
    }
}

TEST_CASE("hard cases: thousands of small shots keep the books and the closed-room answer", "[hard]") {
    // A closed unit box of 384 patches (1/8, one element each), all ρ = 0.9 and emitting E = 1,
    // shot 8000 times (21 rounds) at threshold 0: late shots carry ~4e-5 of the emitted flux
    // into irradiances ~10 E, and the books add up some 3 million terms. Known answers:
    //  - at every pass, PassChecker's identities to 1e-9: even if every one of the ~3e6 roundings
    //    of 2^-53 went the same way the books would be off by 3.4e-10 (measured: ~1e-13);
    //  - the unshot flux, falling at least geometrically at every pass (PassChecker): U ≤ Φ (1 −
    //    (1 − ρ) / P)^passes = e^{−2.08} Φ ≈ 0.125 Φ at the end (measured 0.014 Φ);
    //  - B = E / (1 − ρ) = 10: every wall's average within 0.2% (measured ≤ 0.01%), every element
    //    within 3% (measured ±1.1%: one N = 32 hemicube per shot, rows not exactly reciprocal).
    const double rho = 0.9;
    const long passes = 8000;
    scene::Scene s;
    const std::uint32_t wall = scene::add_material(s, glm::dvec3(rho), glm::dvec3(1.0));
    s = test::closed_box(
        {1.0, 1.0, 1.0}, [&](int) { return wall; }, s);
    const mesh::Mesh m = mesh::build(s, {0.125, 0.125});
    REQUIRE(m.patches.size() == 384);
    auto engine = bake_engine(m, 32);
    solve::Progressive solver(m, *engine, {0.0, passes});
    PassChecker checker{m, rho};
    while (solver.step()) checker.check(solver);
    CHECK(solver.passes() == passes);
    CAPTURE(checker.worst_books, checker.worst_identity);
    const double bound =
        std::pow(1.0 - (1.0 - rho) / static_cast<double>(m.patches.size()), static_cast<double>(passes));
    CAPTURE(solver.unshot_fraction(), bound);
    CHECK(solver.unshot_fraction() <= bound);
    const auto B = solver.radiosity(true);
    REQUIRE(finite(B));
    for (std::uint32_t node = 0; node < 6; ++node) {
        CAPTURE(node);
        CHECK_THAT(node_mean(m, B, node), WithinRel(10.0, 0.002));
    }
    for (std::size_t k = 0; k < B.size(); ++k) {
        CAPTURE(k);
        CHECK_THAT(B[k].x, WithinRel(10.0, 0.03));
    }
}
