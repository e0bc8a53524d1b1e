// Progressive shooting against analytic answers: furnaces, flux balance, parallel squares.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <utility>
#include <vector>

#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "solve/max_tree.h"
#include "solve/progressive.h"
#include "test_scenes.h"

using namespace hemirad;
using Catch::Matchers::WithinAbs;
using Catch::Matchers::WithinRel;

namespace {

struct Solved {
    std::vector<glm::dvec3> B, H;
    long passes = 0;
    bool converged = false;
    solve::Energy energy;
};

Solved solve_scene(const scene::Scene& s, mesh::Settings ms, int hemicube, double threshold, std::uint64_t seed = 1) {
    const mesh::Mesh m = mesh::build(s, ms);
    formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{hemicube, seed}));
    solve::Progressive solver(m, engine, {threshold, 200000});
    while (solver.step()) {
    }
    return {solver.radiosity(true), solver.irradiance(true), solver.passes(), solver.converged(), solver.energy()};
}

}  // namespace

TEST_CASE("furnace: a closed box with uniform rho and E reaches B = E/(1 - rho)", "[solver]") {
    for (double rho : {0.5, 0.9, 0.99, 0.999}) {
        scene::Scene s;
        const auto mat = test::add_material(s, glm::dvec3(rho), glm::dvec3(1.0, 0.5, 0.25));
        s = test::closed_box({1.0, 1.0, 1.0}, [&](int) { return mat; }, s);
        const Solved r = solve_scene(s, {0.25, 0.125}, 64, 1e-4);
        CAPTURE(rho, r.passes);
        REQUIRE(r.converged);
        const glm::dvec3 expected = glm::dvec3(1.0, 0.5, 0.25) / (1.0 - rho);
        for (const auto& b : r.B)
            for (int c = 0; c < 3; ++c) REQUIRE_THAT(b[c], WithinRel(expected[c], 0.01));
    }
}

TEST_CASE("furnace lit by one wall: total radiosity flux is emitted/(1 - rho) even at rho = 0.999", "[solver]") {
    // In a closed box every unit of light bounces until absorbed: Σ B A = Φ_E / (1 − ρ).
    for (double rho : {0.9, 0.999}) {
        scene::Scene s;
        const auto wall = test::add_material(s, glm::dvec3(rho), glm::dvec3(0.0));
        const auto light = test::add_material(s, glm::dvec3(rho), glm::dvec3(2.0));
        s = test::closed_box({1.0, 0.8, 1.2}, [&](int face) { return face == 3 ? light : wall; }, s);
        const mesh::Mesh m = mesh::build(s, {0.2, 0.1});
        formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{64, 1}));
        solve::Progressive solver(m, engine, {1e-3, 200000});
        while (solver.step()) {
        }
        CAPTURE(rho, solver.passes());
        REQUIRE(solver.converged());
        CHECK(solver.passes() < 5000);  // not the ~7000 rounds plain shooting would need
        const auto B = solver.radiosity(true);
        double flux = 0.0, light_flux = 0.0;
        for (std::size_t k = 0; k < B.size(); ++k) {
            flux += B[k].x * m.elements[k].area;
            light_flux += m.elements[k].emission.x * m.elements[k].area;
        }
        CHECK_THAT(flux, WithinRel(light_flux / (1.0 - rho), 0.01));
    }
}

TEST_CASE("energy: emitted = absorbed + escaped + unshot at every pass", "[solver]") {
    scene::Scene s;
    const auto white = test::add_material(s, glm::dvec3(0.8, 0.7, 0.6), glm::dvec3(0.0));
    const auto light = test::add_material(s, glm::dvec3(0.5), glm::dvec3(3.0, 2.0, 1.0));
    // An open box: five walls, one lit, the sixth side missing so light escapes.
    s = test::closed_box({1.0, 1.0, 1.0}, [&](int face) { return face == 3 ? light : white; }, s);
    s.triangles.resize(s.triangles.size() - 2);
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{64, 1}));
    solve::Progressive solver(m, engine, {1e-4, 0});
    int checked = 0;
    while (solver.step()) {
        const solve::Energy e = solver.energy();
        REQUIRE_THAT(e.absorbed + e.escaped + e.unshot, WithinRel(e.emitted, 1e-6));
        ++checked;
    }
    const solve::Energy e = solver.energy();
    CHECK(checked > 50);
    CHECK(e.escaped > 0.05 * e.emitted);  // the open side lets light out
    CHECK(e.absorbed > 0.05 * e.emitted);
    CHECK(e.unshot < 1e-3 * e.emitted);
}

TEST_CASE("parallel squares: received light matches the analytic form factor", "[solver]") {
    // Emitter (E = 1, ρ = 0) under a grey receiver 1 apart: mean irradiance on the receiver is
    // F(receiver → emitter) · E = 0.1998248957 (unit squares, reciprocity).
    for (double scale : {1e-3, 1.0, 1e3}) {
        scene::Scene s;
        const auto emitter = test::add_material(s, glm::dvec3(0.0), glm::dvec3(1.0));
        const auto grey = test::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
        s = test::parallel_rectangles(scale, scale, scale, emitter, grey, s);
        const double patch = s.diagonal() / 24.0;
        const Solved r = solve_scene(s, {patch, patch / 3}, 256, 1e-3);
        const mesh::Mesh m = mesh::build(s, {patch, patch / 3});
        double h = 0.0, area = 0.0;
        for (std::size_t k = 0; k < m.elements.size(); ++k)
            if (m.elements[k].node == 1) {
                h += r.H[k].x * m.elements[k].area;
                area += m.elements[k].area;
            }
        CAPTURE(scale);
        CHECK_THAT(h / area, WithinRel(0.1998248957, 0.01));
    }
}

TEST_CASE("solver: the same scene and seed give identical radiosity", "[solver]") {
    scene::Scene s;
    const auto white = test::add_material(s, glm::dvec3(0.7), glm::dvec3(0.0));
    const auto light = test::add_material(s, glm::dvec3(0.5), glm::dvec3(1.0));
    s = test::closed_box({1.0, 1.0, 1.0}, [&](int face) { return face == 3 ? light : white; }, s);
    const Solved a = solve_scene(s, {0.25, 0.125}, 64, 1e-3, 5);
    const Solved b = solve_scene(s, {0.25, 0.125}, 64, 1e-3, 5);
    CHECK(a.passes == b.passes);
    CHECK(a.B == b.B);
}

TEST_CASE("progressive: a lamp whose brighter side faces the open sky does not end the bake unlit", "[solver]") {
    // A lamp 1 above a unit floor, open to the sky: its upper side (E = 2) faces away, its lower
    // side (E = 1, 1e-3 below it) faces the floor; neither reflects. The upper side holds the
    // most flux and shoots first, and all of it escapes. Measuring the scene's hit share from that
    // shot alone said the rest would escape too: converged after one pass, the floor black. The
    // floor's irradiance is E F(floor → lamp) = 0.1998248957 (REFERENCES.md, unit squares 1
    // apart); what the floor reflects escapes or is absorbed by the lamp.
    scene::Scene s;
    const auto floor = test::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    const auto upper = test::add_material(s, glm::dvec3(0.0), glm::dvec3(2.0));
    const auto lower = test::add_material(s, glm::dvec3(0.0), glm::dvec3(1.0));
    test::add_quad(s, {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, floor, "floor");              // faces +z
    test::add_quad(s, {0, 0, 1.001}, {1, 0, 1.001}, {1, 1, 1.001}, {0, 1, 1.001}, upper, "up");  // faces +z
    test::add_quad(s, {0, 0, 1}, {0, 1, 1}, {1, 1, 1}, {1, 0, 1}, lower, "down");                // faces −z
    test::finish(s);
    const mesh::Mesh m = mesh::build(s, {0.125, 0.0625});
    for (const double threshold : {1e-2, 1e-6}) {  // the default, and convergence forced off
        formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{64, 1}));
        solve::Progressive solver(m, engine, {threshold, 100000});
        while (solver.step()) {
        }
        const std::vector<glm::dvec3> H = solver.irradiance(true);
        double floor_flux = 0.0, floor_area = 0.0;
        for (std::size_t k = 0; k < m.elements.size(); ++k) {
            if (m.elements[k].node != 0) continue;
            floor_flux += H[k].x * m.elements[k].area;
            floor_area += m.elements[k].area;
        }
        const solve::Energy e = solver.energy();
        CAPTURE(threshold, solver.passes(), solver.unshot_fraction(), solver.error(), e.emitted, e.escaped);
        CHECK(solver.converged());
        CHECK(solver.passes() > 1);
        CHECK_THAT(floor_flux / floor_area, WithinRel(0.1998248957, 0.02));
        CHECK_THAT(e.absorbed + e.escaped + e.unshot, WithinRel(e.emitted, 1e-9));
        // Converged means what is unshot can no longer move the answer by the threshold: the lamp's
        // lower side has shot (else a third of the emitted flux would be unshot), and of the 0.1
        // the floor reflects (a thirtieth of the 3 emitted) little is left.
        CHECK(solver.unshot_fraction() <= 0.01);
    }
}

TEST_CASE("the max-tree picks what a scan of every key picks, ties to the lower index, through updates") {
    std::uint64_t state = 12345;
    const auto next = [&state] {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return state >> 33;
    };
    for (const std::size_t n : {1u, 2u, 3u, 7u, 64u, 1000u}) {
        std::vector<double> keys(n);
        for (double& k : keys) k = double(next() % 8);  // few distinct values: many ties
        solve::MaxTree tree(keys);
        for (int step = 0; step < 3000; ++step) {
            const std::size_t want = std::size_t(std::max_element(keys.begin(), keys.end()) - keys.begin());
            REQUIRE(tree.top() == want);
            const std::size_t i = next() % n;
            keys[i] = step % 5 == 0 ? -1.0 : double(next() % 8);
            tree.set(i, keys[i]);
        }
    }
    CHECK(solve::MaxTree{}.top() == 0);  // empty: size()
}

TEST_CASE("the solver's running sums match the ambient share and unshot flux recomputed from its state") {
    scene::Scene s;
    const std::uint32_t wall = test::add_material(s, {0.6, 0.5, 0.4}, {0, 0, 0});
    const std::uint32_t light = test::add_material(s, {0.2, 0.2, 0.2}, {5, 4, 3});
    s = test::closed_box({1.0, 0.8, 1.2}, [&](int face) { return face == 3 ? light : wall; }, s);
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    formfactor::ReferenceEngine engine(m, {32, 3});
    solve::Settings settings;
    settings.threshold = 1e-9;
    settings.batch = 3;
    solve::Progressive solver(m, engine, settings);
    for (int pass = 0; pass < 40 && solver.step(); ++pass) {
        const std::vector<glm::dvec3> H = solver.irradiance(/*ambient=*/false);
        const glm::dvec3 amb = solver.ambient();
        glm::dvec3 ambient_flux{0.0}, total{0.0};
        for (std::size_t k = 0; k < H.size(); ++k) {
            ambient_flux += amb * m.elements[k].area;
            total += (H[k] + amb) * m.elements[k].area;
        }
        double share = 0.0;
        for (int c = 0; c < 3; ++c) share = std::max(share, ambient_flux[c] / total[c]);
        REQUIRE_THAT(solver.ambient_share(), WithinRel(share, 1e-12));
        const solve::Energy e = solver.energy();
        REQUIRE_THAT(e.emitted, WithinRel(e.absorbed + e.escaped + e.unshot, 1e-12));
    }
}

TEST_CASE("holders: the largest fluxes that hold all but a share of the sum", "[solver]") {
    CHECK(solve::flux_holders({1.0, 4.0, 2.0, 3.0}, 0.0) == 4);
    CHECK(solve::flux_holders({1.0, 4.0, 2.0, 3.0}, 0.1) == 3);   // 4 + 3 + 2 = 9 of 10
    CHECK(solve::flux_holders({1.0, 4.0, 2.0, 3.0}, 0.11) == 3);  // 7 of 10 is not 8.9
    CHECK(solve::flux_holders({1.0, 4.0, 2.0, 3.0}, 0.3) == 2);   // 4 + 3 = 7
    CHECK(solve::flux_holders({0.0, 0.0, 5.0}, 0.01) == 1);
    CHECK(solve::flux_holders({0.0, 0.0}, 0.01) == 0);
    CHECK(solve::flux_holders({}, 0.01) == 0);
}

TEST_CASE("holders: before the first pass a lit wall's patches hold the light, then the walls it lit too", "[solver]") {
    scene::Scene s;
    const auto wall = test::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    const auto light = test::add_material(s, glm::dvec3(0.5), glm::dvec3(2.0));
    s = test::closed_box({1.0, 0.8, 1.2}, [&](int face) { return face == 3 ? light : wall; }, s);
    const mesh::Mesh m = mesh::build(s, {0.2, 0.1});
    std::vector<double> emitted;
    for (const mesh::Patch& p : m.patches)
        if (p.emission.x > 0.0) emitted.push_back(p.area);
    const double total = [&] { double t = 0.0; for (double a : emitted) t += a; return t; }();
    const double smallest = *std::min_element(emitted.begin(), emitted.end());
    REQUIRE(emitted.size() > 4);
    REQUIRE(smallest > 0.01 * total);  // each lit patch holds more than the share left over
    formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{64, 1}));
    solve::Progressive solver(m, engine, {1e-3, 200000});
    CHECK(solver.holders(0.01) == long(emitted.size()));
    CHECK(solver.holders(0.0) == long(emitted.size()));
    REQUIRE(solver.step());
    // The first shot takes a lit patch's light and sends half of what lands back unshot, spread
    // over the walls it reached: more patches hold light now.
    CHECK(solver.holders(0.0) > long(emitted.size()));
}

namespace {

// Passes batches on to an engine and keeps each batch's shooters, in order.
class BatchRecorder final : public formfactor::Engine {
public:
    explicit BatchRecorder(formfactor::Engine& inner) : inner_(inner) {}
    std::string name() const override { return "recorder"; }
    void shoot(const formfactor::ShotRequest& request, formfactor::ShotResult& out) override { inner_.shoot(request, out); }
    void shoot_batch(const std::vector<formfactor::ShotRequest>& shots, std::vector<formfactor::ShotResult>& out) override {
        batches.emplace_back();
        for (const formfactor::ShotRequest& r : shots) batches.back().push_back(r.shooter.patch);
        inner_.shoot_batch(shots, out);
    }
    std::vector<std::vector<std::uint32_t>> batches;

private:
    formfactor::Engine& inner_;
};

}  // namespace

TEST_CASE("batch share: a step shoots the patches holding about as much as the most, alone the one that holds most",
          "[solver]") {
    // A unit box of grey walls, its ceiling a lamp (E 2) cut into equal patches; in the second
    // scene also a wall ten times as bright (E 20).
    scene::Scene s;
    const auto wall = test::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    const auto lamp = test::add_material(s, glm::dvec3(0.5), glm::dvec3(2.0));
    const auto bright = test::add_material(s, glm::dvec3(0.5), glm::dvec3(20.0));
    const mesh::Settings ms{0.25, 0.125};
    const auto solve_first_steps = [&](const scene::Scene& scene, double share, int batch) {
        const mesh::Mesh m = mesh::build(scene, ms);
        formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{32, 1}));
        BatchRecorder recorder(engine);
        solve::Settings settings{1e-3, 200000};
        settings.batch = batch;
        settings.batch_share = share;
        solve::Progressive solver(m, recorder, settings);
        for (int i = 0; i < 2; ++i) REQUIRE(solver.step());
        std::vector<std::uint32_t> lit;  // the patches that emit, in order
        for (std::uint32_t p = 0; p < m.patches.size(); ++p)
            if (m.patches[p].emission.x > 0.0) lit.push_back(p);
        return std::make_pair(recorder.batches, lit);
    };
    {
        // Every lamp patch holds the same flux and nothing else holds any: the first step shoots
        // them all, in index order (ties to the lower index).
        const scene::Scene one = test::closed_box({1, 1, 1}, [&](int face) { return face == 5 ? lamp : wall; }, s);
        const auto [batches, lit] = solve_first_steps(one, 0.5, 256);
        REQUIRE(lit.size() == 16);
        CHECK(batches.front() == lit);
        // ... but no more than the batch's cap.
        const auto [capped, lit_again] = solve_first_steps(one, 0.5, 5);
        CHECK(capped.front() == std::vector<std::uint32_t>(lit_again.begin(), lit_again.begin() + 5));
    }
    {
        // A wall ten times as bright: its patches go first, together, and the lamp's, holding a
        // tenth of their flux, wait (a fixed batch of 32 would have taken them along).
        const scene::Scene two = test::closed_box(
            {1, 1, 1}, [&](int face) { return face == 5 ? lamp : face == 0 ? bright : wall; }, s);
        const auto [batches, lit] = solve_first_steps(two, 0.5, 256);
        REQUIRE(lit.size() == 32);
        const std::vector<std::uint32_t> bright_patches(lit.begin(), lit.begin() + 16);  // x0 comes first
        CHECK(batches.front() == bright_patches);
        const auto [fixed, lit_fixed] = solve_first_steps(two, 0.0, 32);
        CHECK(fixed.front().size() == 32);
    }
}

TEST_CASE("batch share: the solve converges to Southwell's answer, within what a change of seed moves it", "[solver]") {
    scene::Scene s;
    const auto wall = test::add_material(s, glm::dvec3(0.6, 0.5, 0.4), glm::dvec3(0.0));
    const auto lamp = test::add_material(s, glm::dvec3(0.5), glm::dvec3(4.0, 3.0, 2.0));
    s = test::closed_box({1.0, 0.8, 1.2}, [&](int face) { return face == 3 ? lamp : wall; }, s);
    const mesh::Mesh m = mesh::build(s, {0.2, 0.1});
    const auto solve_with = [&](double share, int batch, std::uint64_t seed) {
        formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{64, seed}));
        solve::Settings settings{1e-3, 200000};
        settings.batch = batch;
        settings.batch_share = share;
        solve::Progressive solver(m, engine, settings);
        long steps = 0;
        while (solver.step()) ++steps;
        REQUIRE(solver.converged());
        return std::make_tuple(solver.irradiance(true), solver.passes(), steps);
    };
    // Flux-weighted relative difference of two irradiance solutions.
    const auto apart = [&](const std::vector<glm::dvec3>& a, const std::vector<glm::dvec3>& b) {
        double diff = 0.0, total = 0.0;
        for (std::size_t k = 0; k < a.size(); ++k) {
            const double area = m.elements[k].area;
            for (int c = 0; c < 3; ++c) {
                diff += std::abs(a[k][c] - b[k][c]) * area;
                total += b[k][c] * area;
            }
        }
        return diff / total;
    };
    const auto [southwell, southwell_passes, southwell_steps] = solve_with(0.0, 1, 1);
    const auto [shared, shared_passes, shared_steps] = solve_with(0.5, 256, 1);
    const auto [reseeded, reseeded_passes, reseeded_steps] = solve_with(0.0, 1, 2);
    CAPTURE(southwell_passes, shared_passes, shared_steps, apart(shared, southwell), apart(reseeded, southwell));
    CHECK(southwell_steps == southwell_passes);
    CHECK(shared_steps * 4 < shared_passes);                    // several shooters a step
    CHECK(shared_passes < southwell_passes + southwell_passes / 4);  // and not many more shots
    CHECK(apart(shared, southwell) < apart(reseeded, southwell));
}
