// The box-room radiosity reference against closed forms, conservation laws and its own finer grids.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include "bench/room_reference.h"
#include "test_scenes.h"

using namespace hemirad;
using bench::Room;
using bench::Surface;
using Catch::Matchers::WithinAbs;
using Catch::Matchers::WithinRel;

namespace {

// A cell (all that cell_form_factor reads: corners, counter-clockwise from the front, and the normal).
bench::Cell rectangle(glm::dvec3 origin, glm::dvec3 a, glm::dvec3 b) {
    bench::Cell c;
    c.v = {origin, origin + a, origin + a + b, origin + b};
    c.normal = glm::normalize(glm::cross(a, b));
    c.area = glm::length(glm::cross(a, b));
    return c;
}

// Area-weighted form factor from the cells of face `from` to those of face `to`.
double face_to_face(const bench::RoomFormFactors& ff, int from, int to) {
    double weighted = 0.0, area = 0.0;
    for (std::size_t i = 0; i < ff.size(); ++i) {
        if (ff.grid.cells[i].face != from) continue;
        area += ff.grid.cells[i].area;
        for (std::size_t j = 0; j < ff.size(); ++j)
            if (ff.grid.cells[j].face == to) weighted += ff.grid.cells[i].area * ff(i, j);
    }
    return weighted / area;
}

double largest(const glm::dvec3& v) {
    return std::max({v.x, v.y, v.z});
}

double max_relative_difference(const glm::dvec3& a, const glm::dvec3& b) {
    return largest(glm::abs(a - b) / glm::abs(b));
}

}  // namespace

TEST_CASE("room scene: a closed box of inward quads, one node and material per surface", "[room_reference]") {
    const Room room;
    const scene::Scene s = bench::make_room_scene(room);
    REQUIRE(s.nodes.size() == std::size_t(bench::kSurfaceCount));
    REQUIRE(s.materials.size() == std::size_t(bench::kSurfaceCount));
    for (int i = 0; i < bench::kSurfaceCount; ++i) {
        CHECK(s.nodes[i].name == bench::surface_name(Surface(i)));
        CHECK(s.materials[i].base_color == room.rho[i]);
        CHECK(s.materials[i].emission == room.emission[i]);
    }
    CHECK(s.bbox_min == glm::dvec3(0.0));
    CHECK(s.bbox_max == room.size);

    const glm::dvec3 centre = 0.5 * room.size;
    std::map<std::uint32_t, int> triangles_per_primitive;
    std::map<std::string, double> area;
    for (const auto& t : s.triangles) {
        const glm::dvec3 cross = glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]);
        const glm::dvec3 n = glm::normalize(cross);
        const glm::dvec3 centroid = (t.p[0] + t.p[1] + t.p[2]) / 3.0;
        CAPTURE(s.nodes[t.node].name, centroid);
        // Counter-clockwise from inside: the front normal is one of ±x, ±y, ±z and points into the room.
        CHECK(largest(glm::abs(n)) == Approx(1.0));
        CHECK(glm::dot(n, centre - centroid) > 0.0);
        // On the box: the coordinate along the normal is 0 or the box size.
        const int axis = std::abs(n.x) > 0.5 ? 0 : std::abs(n.y) > 0.5 ? 1 : 2;
        CHECK((centroid[axis] == 0.0 || centroid[axis] == room.size[axis]));
        CHECK(t.material == t.node);
        for (const auto& rho : t.rho) CHECK(rho == s.materials[t.material].base_color);
        ++triangles_per_primitive[t.primitive];
        area[s.nodes[t.node].name] += 0.5 * glm::length(cross);
    }
    // Every quad is its own primitive of two triangles: 6 faces, the ceiling as 8 rectangles around the light.
    CHECK(triangles_per_primitive.size() == 5 + 1 + 8);
    for (const auto& [primitive, count] : triangles_per_primitive) CHECK(count == 2);
    const double light = (room.light_max.x - room.light_min.x) * (room.light_max.y - room.light_min.y);
    CHECK_THAT(area["floor"], WithinRel(room.size.x * room.size.z, 1e-12));
    CHECK_THAT(area["light"], WithinRel(light, 1e-12));
    CHECK_THAT(area["ceiling"], WithinRel(room.size.x * room.size.z - light, 1e-12));
    CHECK_THAT(area["wall_north"], WithinRel(room.size.x * room.size.y, 1e-12));
    CHECK_THAT(area["wall_east"], WithinRel(room.size.z * room.size.y, 1e-12));

    // A light touching a wall leaves fewer ceiling rectangles, none empty.
    Room corner;
    corner.light_min = {0.0, 0.0};
    const scene::Scene c = bench::make_room_scene(corner);
    CHECK(c.triangles.size() == 2 * (5 + 1 + 3));
}

TEST_CASE("room reference: rectangle form factors match the closed forms", "[room_reference]") {
    const glm::dvec3 x(1, 0, 0), y(0, 1, 0), z(0, 0, 1);
    // REFERENCES.md. Observed errors: ≤ 1e-8 (the quadrature), so 5e-8 is the margin.
    const bench::Cell floor = rectangle({0, 0, 0}, z, x);  // faces +y
    CHECK_THAT(bench::cell_form_factor(floor, rectangle({0, 1, 0}, x, z)), WithinAbs(0.1998248957, 5e-8));
    CHECK_THAT(bench::cell_form_factor(floor, rectangle({0, 2, 0}, x, z)), WithinAbs(0.0685895888, 5e-8));
    CHECK_THAT(bench::cell_form_factor(rectangle({0, 0, 0}, 2.0 * z, 2.0 * x), rectangle({0, 1, 0}, 2.0 * x, 2.0 * z)),
               WithinAbs(0.4152532836, 5e-8));
    const bench::Cell wall = rectangle({0, 0, 0}, x, y);  // faces +z, shares the edge x ∈ [0, 1]
    const bench::Cell tall = rectangle({0, 0, 0}, x, 2.0 * y);
    CHECK_THAT(bench::cell_form_factor(floor, wall), WithinAbs(0.2000437761, 5e-8));
    CHECK_THAT(bench::cell_form_factor(floor, tall), WithinAbs(0.2328526028, 5e-8));
    CHECK_THAT(bench::cell_form_factor(tall, floor), WithinAbs(0.1164263014, 5e-8));
}

TEST_CASE("room reference: form-factor rows sum to 1, reciprocity, shared factors are the direct ones",
          "[room_reference]") {
    // 0.3 m does not divide the light's 1 m edges: the grid is uneven (0.3, 0.25, 0.2857 m cells), which
    // the sharing of factors between translated cell pairs must cope with.
    const bench::RoomFormFactors ff = bench::room_form_factors(Room{}, 0.3);
    const std::size_t n = ff.size();
    REQUIRE(n > 500);
    double worst_row = 0.0, worst_reciprocity = 0.0, worst_shared = 0.0;
    std::size_t coplanar_nonzero = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const bench::Cell& ci = ff.grid.cells[i];
        double row = 0.0;
        for (std::size_t j = 0; j < n; ++j) {
            const bench::Cell& cj = ff.grid.cells[j];
            row += ff(i, j);
            if (ci.face == cj.face) {
                coplanar_nonzero += ff(i, j) != 0.0;
                continue;
            }
            const double gij = ci.area * ff(i, j), gji = cj.area * ff(j, i);
            worst_reciprocity = std::max(worst_reciprocity, std::abs(gij - gji) / gij);
            if ((i * n + j) % 97 == 0) {  // a spread sample: the matrix entry is the pair's own integral
                const double direct = bench::cell_form_factor(ci, cj);
                worst_shared = std::max(worst_shared, std::abs(ff(i, j) - direct) / direct);
            }
        }
        worst_row = std::max(worst_row, std::abs(row - 1.0));
    }
    // Observed: rows 5e-8 (float storage and the quadrature), reciprocity 4e-7 relative (the two directions
    // are integrated independently; the worst pair is a tiny far factor), shared vs direct 6e-8 (float).
    CHECK(coplanar_nonzero == 0);
    CHECK(worst_row < 1e-6);
    CHECK(worst_reciprocity < 1e-5);
    CHECK(worst_shared < 1e-6);
}

TEST_CASE("room reference: whole-face form factors equal the rectangle formulas", "[room_reference]") {
    // An uneven box with the light off-centre, so no symmetry hides a misplaced cell.
    Room room;
    room.size = {2.0, 1.5, 3.0};
    room.light_min = {0.25, 1.0};
    room.light_max = {1.0, 2.5};
    const bench::RoomFormFactors ff = bench::room_form_factors(room, 0.25);
    // Observed differences ≤ 5e-9 (quadrature and float storage).
    // Faces: 0 floor, 1 ceiling (with the light), 2 north (z = 0), 4 west (x = 0).
    CHECK_THAT(face_to_face(ff, 0, 1), WithinAbs(test::parallel_rectangles_ff(2.0, 3.0, 1.5), 5e-8));
    // Floor → north wall share the 2 m edge along x; the floor is 3 m deep, the wall 1.5 m high.
    CHECK_THAT(face_to_face(ff, 0, 2), WithinAbs(test::perpendicular_rectangles_ff(2.0, 3.0, 1.5), 5e-8));
    // North → west walls share the 1.5 m vertical edge; north is 2 m wide, west 3 m.
    CHECK_THAT(face_to_face(ff, 2, 4), WithinAbs(test::perpendicular_rectangles_ff(1.5, 2.0, 3.0), 5e-8));
    CHECK_THAT(face_to_face(ff, 4, 2), WithinAbs(test::perpendicular_rectangles_ff(1.5, 3.0, 2.0), 5e-8));
}

TEST_CASE("room reference: a furnace room has B = E / (1 − ρ) everywhere", "[room_reference]") {
    for (double rho : {0.5, 0.9}) {
        Room room;
        room.light_min = {0.0, 0.0};  // in a corner: the grid drops the empty segments
        room.light_max = {1.0, 1.5};
        room.rho.fill(glm::dvec3(rho));
        room.emission.fill(glm::dvec3(1.0, 2.0, 0.5));
        const bench::RoomSolution sol = bench::solve_room(room, 0.5);
        CAPTURE(rho, sol.iterations, sol.residual);
        CHECK(sol.residual < 1e-12);
        const glm::dvec3 expected = glm::dvec3(1.0, 2.0, 0.5) / (1.0 - rho);
        double worst = 0.0;
        for (const glm::dvec3& b : sol.radiosity) worst = std::max(worst, max_relative_difference(b, expected));
        // Row sums are 1 to ~5e-8; the furnace amplifies that by ρ/(1 − ρ) ≤ 9. Observed 3e-8, 2e-7.
        CHECK(worst < 1e-6);
    }
}

TEST_CASE("room reference: emitted power equals absorbed power", "[room_reference]") {
    const bench::RoomFormFactors ff = bench::room_form_factors(Room{}, 0.5);
    const bench::RoomSolution sol = bench::solve_room(ff);
    const Room& room = ff.grid.room;
    glm::dvec3 emitted(0.0), absorbed(0.0), worst_residual(0.0);
    for (std::size_t i = 0; i < ff.size(); ++i) {
        const bench::Cell& c = ff.grid.cells[i];
        glm::dvec3 incident(0.0);  // from the matrix here, not the solver's own product
        for (std::size_t j = 0; j < ff.size(); ++j) incident += ff(i, j) * sol.radiosity[j];
        const glm::dvec3 rho = room.rho[int(c.surface)], e = room.emission[int(c.surface)];
        emitted += c.area * e;
        absorbed += c.area * (1.0 - rho) * incident;
        worst_residual = glm::max(worst_residual, glm::abs(e + rho * incident - sol.radiosity[i]));
    }
    CHECK(largest(worst_residual) < 1e-11 * largest(sol.average(Surface::light)));
    // A closed room loses nothing: equal to the form factors' row sums and reciprocity (observed 4e-8).
    CHECK(max_relative_difference(absorbed, emitted) < 1e-6);
    CHECK(emitted == glm::dvec3(10.0));  // 1 m² at 10 W/m²
}

TEST_CASE("room reference: converged with the grid", "[room_reference]") {
    // Default room: the largest relative difference (any surface, any channel) from the 0.1 m solution,
    // of the surface averages and of the gathered point values at 8 × 8 probes per surface:
    //   cells     averages   probes   solve_room time (2 cores)
    //   0.5  m    0.093 %    2.3 %    0.04 s
    //   0.25 m    0.024 %    0.31 %   0.08 s
    //   0.2  m    0.013 %    0.19 %   0.2 s
    //   0.125 m   0.003 %    0.044 %  0.5 s
    //   0.1  m    —          —        1.0 s (0.4 s form factors, 0.6 s solve)
    // Both fall like h² (Galerkin averages are superconvergent; the gather smooths the pointwise O(h)
    // error of the cells), so at 0.1 m the averages are within ~0.005 % and the probes within ~0.07 % of
    // the limit. The tolerances are 4× the observed 0.2 m differences: far below the errors of any bake
    // being measured, and loose enough not to trip on rounding.
    const Room room;
    const bench::RoomSolution coarse = bench::solve_room(room, 0.2);
    const bench::RoomSolution fine = bench::solve_room(room, 0.1);
    double averages = 0.0;
    for (int s = 0; s < bench::kSurfaceCount; ++s) {
        CHECK(coarse.surface_average[s].first == fine.surface_average[s].first);
        averages = std::max(averages,
                            max_relative_difference(coarse.surface_average[s].second, fine.surface_average[s].second));
    }
    double probes = 0.0;
    for (const bench::Probe& p : bench::room_probes(room, 8))
        probes = std::max(probes, max_relative_difference(coarse.radiosity_at(p.point, p.normal),
                                                          fine.radiosity_at(p.point, p.normal)));
    CAPTURE(averages, probes);
    CHECK(averages < 5e-4);
    CHECK(probes < 8e-3);
    // The light's average is E + ρ × its irradiance, so it sits a little above 10.
    CHECK(fine.average(Surface::light).x > 10.0);
}

TEST_CASE("room reference: the red wall bleeds onto the others", "[room_reference]") {
    Room grey;
    grey.rho[int(Surface::wall_west)] = glm::dvec3(0.7);
    const bench::RoomSolution red = bench::solve_room(Room{}, 0.5), plain = bench::solve_room(grey, 0.5);
    for (Surface s : {Surface::floor, Surface::ceiling, Surface::wall_east, Surface::wall_north}) {
        CAPTURE(bench::surface_name(s));
        const glm::dvec3 r = red.average(s), p = plain.average(s);
        CHECK(r.x / r.y > 1.02 * p.x / p.y);
    }
}

TEST_CASE("room reference: probes, point and element queries", "[room_reference]") {
    const Room room;
    const bench::RoomSolution sol = bench::solve_room(room, 0.25);
    // 3 × 3 per surface; the ceiling's centre point (2, 2.5) is on the light and is left out.
    const std::vector<bench::Probe> probes = bench::room_probes(room, 3);
    CHECK(probes.size() == 7 * 9 - 1);
    for (const bench::Probe& p : probes) {
        CAPTURE(p.surface, p.point);
        const std::size_t cell = sol.grid.cell_at(p.point, p.normal);
        CHECK(bench::surface_name(sol.grid.cells[cell].surface) == p.surface);
        CHECK(sol.grid.cells[cell].normal == p.normal);
        // The gather and the cell's own value agree to the in-cell variation (largest beside the light).
        const glm::dvec3 point = sol.radiosity_at(p.point, p.normal);
        CHECK(max_relative_difference(point, sol.radiosity[cell]) < 0.15);
    }
    // Averaged over a cell, the gather is that cell's value: B_i = E + ρ Σ_j F_ij B_j and F_ij is the
    // cell-average of the point factor. What is left is the 2 × 2 rule's error.
    double worst = 0.0;
    for (std::size_t i = 0; i < sol.grid.cells.size(); i += 7) {
        mesh::Polygon poly;
        poly.n = 4;
        std::copy(sol.grid.cells[i].v.begin(), sol.grid.cells[i].v.end(), poly.v.begin());
        worst = std::max(worst, max_relative_difference(sol.average_over(poly), sol.radiosity[i]));
    }
    CAPTURE(worst);
    CHECK(worst < 2e-3);  // observed 3e-4
    // A point between the light and the ceiling: the normal names the ceiling face, the light's edge
    // belongs to the cell with the larger coordinate.
    CHECK(sol.grid.cells[sol.grid.cell_at({1.5, 2.5, 2.5}, {0, -1, 0})].surface == Surface::light);
    CHECK(sol.grid.cells[sol.grid.cell_at({1.5, 2.5, 1.9}, {0, -1, 0})].surface == Surface::ceiling);
    CHECK_THROWS_AS(sol.grid.cell_at({1.0, 1.0, 1.0}, {0, 1, 0}), std::invalid_argument);
    CHECK_THROWS_AS(sol.grid.cell_at({5.0, 0.0, 1.0}, {0, 1, 0}), std::invalid_argument);
}

TEST_CASE("room reference: invalid rooms and grids are refused", "[room_reference]") {
    Room outside;
    outside.light_max = {4.5, 3.0};
    CHECK_THROWS_AS(bench::make_room_scene(outside), std::invalid_argument);
    Room white;
    white.rho[0] = glm::dvec3(1.0);
    CHECK_THROWS_AS(bench::make_room_grid(white, 0.5), std::invalid_argument);
    CHECK_THROWS_AS(bench::make_room_grid(Room{}, 0.0), std::invalid_argument);
    CHECK_THROWS_AS(bench::make_room_grid(Room{}, 0.05), std::invalid_argument);  // 34000 cells
    CHECK_THROWS_AS(bench::room_probes(Room{}, 0), std::invalid_argument);
}
