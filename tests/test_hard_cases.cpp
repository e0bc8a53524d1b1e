// Numerically hard cases (issue 6, part): each with a known answer, and no NaN or Inf anywhere.
// Solved with the matrix solver on the bake's engine stack (reference hemicube under the
// near-field correction), which has no early stop to hide a drift.
#include <catch2/catch.hpp>
#include <cmath>

#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "solve/matrix.h"
#include "test_scenes.h"

using namespace hemirad;
using Catch::Matchers::WithinRel;

namespace {

bool finite(const std::vector<glm::dvec3>& values) {
    for (const glm::dvec3& v : values)
        if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) return false;
    return true;
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
    formfactor::NearFieldEngine engine(
        r.mesh, std::make_unique<formfactor::ReferenceEngine>(r.mesh, formfactor::Settings{hemicube, 1}));
    solve::MatrixSettings settings;
    settings.tolerance = 1e-9;
    settings.max_iterations = 100000;
    solve::Matrix solver(r.mesh, engine, settings);
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
    double sum = 0.0, area = 0.0;
    for (std::size_t k = 0; k < r.mesh.elements.size(); ++k) {
        if (r.mesh.elements[k].node != node) continue;
        sum += r.B[k].x * r.mesh.elements[k].area;
        area += r.mesh.elements[k].area;
    }
    return sum / area;
}

void check_books(const solve::Energy& e) {
    CHECK(std::isfinite(e.emitted));
    CHECK_THAT(e.absorbed + e.escaped + e.unshot, WithinRel(e.emitted, 1e-9));
}

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
        scene::Scene s;
        const std::uint32_t wall = scene::add_material(s, glm::dvec3(0.6), glm::dvec3(0.0));
        const std::uint32_t light = scene::add_material(s, glm::dvec3(0.5), glm::dvec3(1.0));
        s = test::closed_box(
            glm::dvec3(1.0, 0.8, 1.2) * scale, [&](int face) { return face == 3 ? light : wall; }, s);
        const Result r = solve_scene(s, 0.2 * scale);
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
        scene::Scene s;
        const std::uint32_t wall = scene::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
        const std::uint32_t light = scene::add_material(s, glm::dvec3(0.5), glm::dvec3(1.0));
        s = test::closed_box(
            {1.0, 1.0, 1.0}, [&](int face) { return face == 3 ? light : wall; }, s);
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
    scene::Scene s;
    const std::uint32_t wall = scene::add_material(s, glm::dvec3(0.7), glm::dvec3(0.0));
    const std::uint32_t lamp = scene::add_material(s, glm::dvec3(0.0), glm::dvec3(5.0), /*double_sided=*/true);
    s = test::closed_box(
        {1.0, 1.0, 1.0}, [&](int face) { return face == 2 ? lamp : wall; }, s);
    // Replace the floor (face 2) by needles from the corner (0, 0, 0).
    s.triangles.erase(std::remove_if(s.triangles.begin(), s.triangles.end(),
                                     [&](const scene::Triangle& t) { return t.material == lamp; }),
                      s.triangles.end());
    const int needles = 200;
    for (int i = 0; i < needles; ++i) {
        const auto edge = [&](int k) {
            const double t = double(k) / needles;  // along the far edges x = 1 then z = 1
            return t <= 0.5 ? glm::dvec3(1.0, 0.0, 2.0 * t) : glm::dvec3(2.0 - 2.0 * t, 0.0, 1.0);
        };
        test::add_triangle(s, {0, 0, 0}, edge(i + 1), edge(i), wall, "floor needle");  // normal +y
    }
    test::add_quad(s, {0.45, 0.5, 0.45}, {0.55, 0.5, 0.45}, {0.55, 0.5, 0.55}, {0.45, 0.5, 0.55}, lamp, "lamp");
    test::finish(s);
    const Result r = solve_scene(s, 0.25, 128);
    CHECK(r.converged);
    check_books(r.energy);
    CHECK(r.energy.escaped < 1e-3 * r.energy.emitted);  // ΣF = 1 from every patch of a closed box
    CHECK(r.mesh.dropped_triangles == 0);
}
