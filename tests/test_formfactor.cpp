// Every form-factor backend (tests/backends.h: the scalar reference hemicube, each OpenCL device,
// Embree's rays, a sharded pair) against closed-form form factors (shared/REFERENCES.md), and the
// reference's own hemicube table and rasterization rules.
#include <catch2/catch.hpp>

#include <cmath>
#include <memory>

#include "formfactor/analytic.h"
#include "formfactor/hemicube.h"
#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "solve/progressive.h"
#include "backends.h"
#include "test_scenes.h"

using namespace hemirad;
using Catch::Matchers::WithinAbs;
using Catch::Matchers::WithinRel;

namespace {


scene::Scene with_materials(std::uint32_t& grey) {
    scene::Scene s;
    grey = test::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    return s;
}

}  // namespace

TEST_CASE("delta form factors of the five faces sum to 1", "[formfactor]") {
    for (int n : {8, 16, 64, 256}) {
        const formfactor::DeltaFormFactors delta(n);
        CAPTURE(n);
        CHECK_THAT(delta.sum(), WithinAbs(1.0, 1e-12));
        // The centre of the top face sees straight up: its cells carry the largest values.
        const double centre = delta.at(0, n / 2, n / 2);
        CHECK(centre > delta.at(0, 0, 0));
        CHECK(centre > delta.at(1, n / 2, 0));
        // The pixel-centre approximation ΔA cos²/(π r⁴) must agree to second order.
        const double cell = 2.0 / n, s = -1.0 + (n / 2 + 0.5) * cell, t = s;
        const double approx = cell * cell / (M_PI * std::pow(s * s + t * t + 1.0, 2.0));
        CHECK_THAT(centre, WithinRel(approx, 2.0 / (n * n) + 1e-12));
    }
}

TEST_CASE("point-to-polygon form factor matches the tabulated values", "[formfactor]") {
    const glm::dvec3 up{0, 0, 1};
    const glm::dvec3 centred[4] = {{-0.5, -0.5, 1}, {0.5, -0.5, 1}, {0.5, 0.5, 1}, {-0.5, 0.5, 1}};
    CHECK_THAT(formfactor::point_to_polygon(up, centred, 4), WithinAbs(0.2394564705, 1e-9));
    const glm::dvec3 corner[4] = {{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    CHECK_THAT(formfactor::point_to_polygon(up, corner, 4), WithinAbs(0.1385316060, 1e-9));
}

TEST_CASE("closed-form references reproduce REFERENCES.md", "[formfactor]") {
    CHECK_THAT(test::parallel_rectangles_ff(1, 1, 1), WithinAbs(0.1998248957, 1e-9));
    CHECK_THAT(test::parallel_rectangles_ff(2, 2, 1), WithinAbs(0.4152532836, 1e-9));
    CHECK_THAT(test::parallel_rectangles_ff(1, 1, 2), WithinAbs(0.0685895888, 1e-9));
    CHECK_THAT(test::perpendicular_rectangles_ff(1, 1, 1), WithinAbs(0.2000437761, 1e-9));
    CHECK_THAT(test::perpendicular_rectangles_ff(1, 1, 2), WithinAbs(0.2328526028, 1e-9));
    CHECK_THAT(test::perpendicular_rectangles_ff(1, 2, 1), WithinAbs(0.1164263014, 1e-9));
}

TEST_CASE("every backend: point to a centred square converges with N and rotations average out", "[formfactor][backends]") {
    const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
    HEMIRAD_SKIP_ABSENT(b);
    INFO("backend " << b.name);
    // A tiny shooter at the origin under a unit square at height 1: F → 0.2394564705.
    std::uint32_t grey = 0;
    scene::Scene s = with_materials(grey);
    const double h = 1e-3;
    test::add_quad(s, {-h, -h, 0}, {h, -h, 0}, {h, h, 0}, {-h, h, 0}, grey, "shooter");
    test::add_quad(s, {-0.5, -0.5, 1}, {-0.5, 0.5, 1}, {0.5, 0.5, 1}, {0.5, -0.5, 1}, grey, "square");
    test::finish(s);
    const mesh::Mesh m = mesh::build(s, {1.0, 0.25});
    REQUIRE(m.patches.size() == 2);
    const double exact = 0.2394564705;

    double previous_error = 1.0, worst_at_32 = 0.0;
    for (int n : {32, 128, 512}) {
        const std::unique_ptr<formfactor::Engine> engine = b.make(m, {n, 7});
        // Worst case over rotations: the error of one shot is edge aliasing, ~ perimeter cells.
        double worst = 0.0;
        for (std::uint64_t shot = 0; shot < 8; ++shot) {
            formfactor::ShotResult r;
            engine->shoot(0, shot, r);
            worst = std::max(worst, std::abs(test::node_form_factor(m, r, 1) - exact));
        }
        CAPTURE(n, worst);
        CHECK(worst < 0.1 / n);  // edge aliasing shrinks at least like 1/N
        CHECK(worst < previous_error);
        previous_error = worst;
        if (n == 32) worst_at_32 = worst;
    }
    // The rotation turns aliasing into zero-mean noise: the mean of many shots beats one shot.
    const std::unique_ptr<formfactor::Engine> engine = b.make(m, {32, 11});
    double mean = 0.0;
    const int shots = 64;
    for (int shot = 0; shot < shots; ++shot) {
        formfactor::ShotResult r;
        engine->shoot(0, static_cast<std::uint64_t>(shot), r);
        for (std::size_t i = 0; i < r.size(); ++i)
            if (m.elements[r.element[i]].node == 1) mean += r.F[i] / shots;
    }
    CAPTURE(worst_at_32, mean);
    CHECK(std::abs(mean - exact) < 0.5 * worst_at_32);
}

// Patches of 1/8 (elements 1/16), N = 256: within 0.5% of REFERENCES.md's 0.1998248957 on every
// backend (before, test_opencl.cpp and test_embree.cpp each checked that last mesh alone).
TEST_CASE("every backend: parallel unit squares converge to the analytic form factor with subdivision", "[formfactor][backends]") {
    const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
    HEMIRAD_SKIP_ABSENT(b);
    INFO("backend " << b.name);
    std::uint32_t grey = 0;
    scene::Scene base = with_materials(grey);
    const scene::Scene s = test::parallel_rectangles(1, 1, 1, grey, grey, base);
    const double exact = 0.1998248957;
    double previous = 1.0;
    for (double patch : {0.5, 0.25, 0.125}) {
        const mesh::Mesh m = mesh::build(s, {patch, patch / 2});
        const std::unique_ptr<formfactor::Engine> engine = b.make(m, {256, 1});
        const double f = test::area_form_factor(m, *engine, 0, 1);
        const double err = std::abs(f - exact) / exact;
        CAPTURE(patch, f, err);
        CHECK(err < previous);
        previous = err;
    }
    CHECK(previous < 0.005);
    CHECK_THAT(test::parallel_rectangles_ff(1, 1, 1), WithinAbs(exact, 1e-9));
}

// (Before, test_embree.cpp checked the 1×1 floor to the 1×2 wall on Embree alone.)
TEST_CASE("every backend: perpendicular rectangles and reciprocity", "[formfactor][backends]") {
    const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
    HEMIRAD_SKIP_ABSENT(b);
    INFO("backend " << b.name);
    std::uint32_t grey = 0;
    scene::Scene base = with_materials(grey);
    SECTION("unit squares sharing an edge") {
        const scene::Scene s = test::perpendicular_rectangles(1, 1, 1, grey, grey, base);
        const mesh::Mesh m = mesh::build(s, {1.0 / 16, 1.0 / 32});
        const std::unique_ptr<formfactor::Engine> engine = b.make(m, {256, 3});
        const double f = test::area_form_factor(m, *engine, 0, 1);
        CHECK_THAT(f, WithinRel(0.2000437761, 0.005));
    }
    SECTION("1×1 floor, 1×2 wall: A_i F_ij = A_j F_ji and both match the closed form") {
        const scene::Scene s = test::perpendicular_rectangles(1, 1, 2, grey, grey, base);
        const mesh::Mesh m = mesh::build(s, {1.0 / 16, 1.0 / 32});
        const std::unique_ptr<formfactor::Engine> engine = b.make(m, {256, 5});
        const double f_floor_wall = test::area_form_factor(m, *engine, 0, 1);
        const double f_wall_floor = test::area_form_factor(m, *engine, 1, 0, 1000);
        CHECK_THAT(f_floor_wall, WithinRel(0.2328526028, 0.005));
        CHECK_THAT(f_wall_floor, WithinRel(0.1164263014, 0.005));
        CHECK_THAT(1.0 * f_floor_wall, WithinRel(2.0 * f_wall_floor, 0.005));
    }
}

TEST_CASE("every backend: a closed box sees everything exactly once", "[formfactor][backends]") {
    // No gaps and no double counting between elements that share edges: from inside a closed
    // box every cell is owned by exactly one element, so ΣF equals the table's sum.
    const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
    HEMIRAD_SKIP_ABSENT(b);
    INFO("backend " << b.name);
    std::uint32_t grey = 0;
    scene::Scene base = with_materials(grey);
    const scene::Scene s = test::closed_box({1.0, 0.7, 1.3}, [&](int) { return grey; }, base);
    const mesh::Mesh m = mesh::build(s, {0.3, 0.1});
    const std::unique_ptr<formfactor::Engine> engine = b.make(m, {64, 9});
    const formfactor::DeltaFormFactors delta(64);
    for (std::uint32_t p : {0u, 5u, static_cast<std::uint32_t>(m.patches.size() - 1)}) {
        formfactor::ShotResult r;
        engine->shoot(p, p, r);
        double sum = 0.0;
        for (double f : r.F) sum += f;
        CAPTURE(p);
        CHECK_THAT(sum, WithinAbs(delta.sum(), 1e-12));
        CHECK(r.blocked == 0.0);
        // Every cell owned: the id buffer, where the engine keeps one (a sharded engine keeps none).
        const std::vector<std::int32_t>* ids = engine->last_ids();
        if (b.name != "sharded") REQUIRE(ids != nullptr);
        if (ids) {
            REQUIRE(ids->size() == delta.cells());
            for (std::int32_t id : *ids) REQUIRE(id >= 0);
        }
    }
}

TEST_CASE("every backend: occluders hide and backs of one-sided surfaces block", "[formfactor][backends]") {
    const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
    HEMIRAD_SKIP_ABSENT(b);
    INFO("backend " << b.name);
    std::uint32_t grey = 0;
    scene::Scene s = with_materials(grey);
    // Shooter at z = 0 facing up, receiver at z = 2 facing down, a blocker at z = 1.
    test::add_quad(s, {-0.1, -0.1, 0}, {0.1, -0.1, 0}, {0.1, 0.1, 0}, {-0.1, 0.1, 0}, grey, "shooter");
    test::add_quad(s, {-1, -1, 2}, {-1, 1, 2}, {1, 1, 2}, {1, -1, 2}, grey, "receiver");
    SECTION("a blocker facing the shooter takes what it covers") {
        test::add_quad(s, {-5, -5, 1}, {-5, 5, 1}, {5, 5, 1}, {5, -5, 1}, grey, "blocker");
        test::finish(s);
        const mesh::Mesh m = mesh::build(s, {1.0, 0.5});
        const std::unique_ptr<formfactor::Engine> engine = b.make(m, {64, 1});
        formfactor::ShotResult r;
        engine->shoot(0, 0, r);
        const double to_receiver = test::node_form_factor(m, r, 1), to_blocker = test::node_form_factor(m, r, 2);
        CHECK(to_receiver == 0.0);
        // Point to a centred 10×10 square at height 1 (Lambert's formula).
        const glm::dvec3 sq[4] = {{-5, -5, 1}, {5, -5, 1}, {5, 5, 1}, {-5, 5, 1}};
        CHECK_THAT(to_blocker, WithinRel(formfactor::point_to_polygon({0, 0, 1}, sq, 4), 0.01));
    }
    SECTION("the back of a one-sided blocker is opaque and receives nothing") {
        test::add_quad(s, {-5, -5, 1}, {5, -5, 1}, {5, 5, 1}, {-5, 5, 1}, grey, "blocker");  // faces +z
        test::finish(s);
        const mesh::Mesh m = mesh::build(s, {1.0, 0.5});
        const std::unique_ptr<formfactor::Engine> engine = b.make(m, {64, 1});
        formfactor::ShotResult r;
        engine->shoot(0, 0, r);
        for (std::size_t i = 0; i < r.size(); ++i)
            if (m.elements[r.element[i]].node != 0) CHECK(r.F[i] == 0.0);
        const glm::dvec3 sq[4] = {{-5, -5, 1}, {5, -5, 1}, {5, 5, 1}, {-5, 5, 1}};
        CHECK_THAT(r.blocked, WithinRel(formfactor::point_to_polygon({0, 0, 1}, sq, 4), 0.01));
    }
}

TEST_CASE("every backend: the same seed and shot give the same bits", "[formfactor][backends]") {
    const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
    HEMIRAD_SKIP_ABSENT(b);
    INFO("backend " << b.name);
    std::uint32_t grey = 0;
    scene::Scene base = with_materials(grey);
    const scene::Scene s = test::perpendicular_rectangles(1, 1, 1, grey, grey, base);
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    const std::unique_ptr<formfactor::Engine> a = b.make(m, {64, 42}), b2 = b.make(m, {64, 42}), c = b.make(m, {64, 43});
    formfactor::ShotResult ra, rb, rc;
    a->shoot(3, 17, ra);
    b2->shoot(3, 17, rb);
    c->shoot(3, 17, rc);
    CHECK(ra == rb);
    CHECK(ra != rc);  // another seed rotates the hemicube differently
}

// A closed box of uniform ρ, all of it emitting: every shot's ΣF = 1, so B = E/(1 − ρ) everywhere,
// through the bake's near-field correction over each backend. (Before, test_opencl.cpp ran it
// on OpenCL alone.)
TEST_CASE("every backend: a uniform closed-box furnace reaches B = E/(1 - rho)", "[formfactor][backends][solver]") {
    const test::Backend& b = test::backend(GENERATE(from_range(test::backend_names())));
    HEMIRAD_SKIP_ABSENT(b);
    INFO("backend " << b.name);
    const double rho = 0.9;
    scene::Scene s;
    const auto mat = test::add_material(s, glm::dvec3(rho), glm::dvec3(1.0, 0.5, 0.25));
    s = test::closed_box(
        {1.0, 1.0, 1.0}, [&](int) { return mat; }, s);
    const mesh::Mesh m = mesh::build(s, {0.25, 0.125});
    std::unique_ptr<formfactor::Engine> inner = b.make(m, formfactor::Settings{64, 1});
    const std::string name = inner->name();
    formfactor::NearFieldEngine engine(m, std::move(inner));
    REQUIRE(engine.name() == name);
    solve::Progressive solver(m, engine, {1e-4, 200000});
    while (solver.step()) {
    }
    CAPTURE(solver.passes());
    REQUIRE(solver.converged());
    const glm::dvec3 expected = glm::dvec3(1.0, 0.5, 0.25) / (1.0 - rho);
    for (const auto& B : solver.radiosity(true))
        for (int c = 0; c < 3; ++c) REQUIRE_THAT(B[c], WithinRel(expected[c], 0.01));
}

namespace {

// A point in cells, as the reference's fixed point.
std::int64_t fixed(double cells) { return static_cast<std::int64_t>(cells * formfactor::kSubcell); }

struct Poly {
    std::vector<std::int64_t> x, y;
};

Poly poly(std::initializer_list<std::pair<double, double>> cells) {
    Poly p;
    for (const auto& [x, y] : cells) {
        p.x.push_back(fixed(x));
        p.y.push_back(fixed(y));
    }
    return p;
}

}  // namespace

TEST_CASE("hemicube: centres exactly on shared edges and vertices are taken exactly once (top-left rule)",
          "[formfactor]") {
    // A square with its corners on cell centres, so that its edges run through centres: by the
    // top-left rule it takes the centres on its bottom and left edges (counter-clockwise, y up),
    // not those on its top and right, so exactly the 6 x 6 cells with centres in [1.5, 7.5)^2.
    const Poly square = poly({{1.5, 1.5}, {7.5, 1.5}, {7.5, 7.5}, {1.5, 7.5}});
    // Partitions of it whose inner edges and vertices also lie on centres: the two triangles of
    // the diagonal (through the centres (k + 1/2, k + 1/2)), a fan of four triangles around the
    // centre (4.5, 4.5), four sub-squares, and a pair split along a slope-2 line.
    const std::vector<std::vector<Poly>> partitions = {
        {poly({{1.5, 1.5}, {7.5, 1.5}, {7.5, 7.5}}), poly({{1.5, 1.5}, {7.5, 7.5}, {1.5, 7.5}})},
        {poly({{1.5, 1.5}, {7.5, 1.5}, {4.5, 4.5}}), poly({{7.5, 1.5}, {7.5, 7.5}, {4.5, 4.5}}),
         poly({{7.5, 7.5}, {1.5, 7.5}, {4.5, 4.5}}), poly({{1.5, 7.5}, {1.5, 1.5}, {4.5, 4.5}})},
        {poly({{1.5, 1.5}, {4.5, 1.5}, {4.5, 4.5}, {1.5, 4.5}}), poly({{4.5, 1.5}, {7.5, 1.5}, {7.5, 4.5}, {4.5, 4.5}}),
         poly({{4.5, 4.5}, {7.5, 4.5}, {7.5, 7.5}, {4.5, 7.5}}),
         poly({{1.5, 4.5}, {4.5, 4.5}, {4.5, 7.5}, {1.5, 7.5}})},
        {poly({{1.5, 1.5}, {4.5, 1.5}, {7.5, 7.5}, {1.5, 7.5}}), poly({{4.5, 1.5}, {7.5, 1.5}, {7.5, 7.5}})},
    };
    const auto covers = [](const Poly& p, int i, int j) {
        return formfactor::covers_cell(p.x.data(), p.y.data(), static_cast<int>(p.x.size()), i, j);
    };
    for (int j = 0; j < 10; ++j) {
        for (int i = 0; i < 10; ++i) {
            const bool expected = i >= 1 && i <= 6 && j >= 1 && j <= 6;
            REQUIRE(covers(square, i, j) == expected);
            for (const auto& parts : partitions) {
                int takers = 0;
                for (const Poly& p : parts) takers += covers(p, i, j) ? 1 : 0;
                INFO("cell " << i << ", " << j);
                REQUIRE(takers == (expected ? 1 : 0));
            }
        }
    }
}
