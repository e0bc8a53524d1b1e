// Contact lines (mesh/contact.h) and the gather's grading toward them (solve::grade_contacts):
// polygon distances against closed forms, which elements of a box standing on a floor touch it,
// and that grading leaves every element average as it was.
#include <catch2/catch.hpp>

#include <cmath>

#include "mesh/contact.h"
#include "mesh/mesh.h"
#include "scene/builder.h"
#include "solve/final_gather.h"

using namespace hemirad;
using namespace hemirad::scene;

namespace {

mesh::Polygon quad(glm::dvec3 a, glm::dvec3 b, glm::dvec3 c, glm::dvec3 d) {
    mesh::Polygon p;
    p.n = 4;
    p.v = {a, b, c, d};
    return p;
}

// A 4 × 4 floor (z = 0, facing +z) and the sides and top of the unit box [1, 2]² × [lift, lift + 1]
// (no bottom), meshed in 0.25 elements.
mesh::Mesh box_on_floor(double lift) {
    Scene s;
    const std::uint32_t grey = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    add_quad(s, {0, 0, 0}, {4, 0, 0}, {4, 4, 0}, {0, 4, 0}, grey, "floor");
    const double z0 = lift, z1 = lift + 1.0;
    add_quad(s, {1, 1, z0}, {2, 1, z0}, {2, 1, z1}, {1, 1, z1}, grey, "front");  // facing −y
    add_quad(s, {2, 1, z0}, {2, 2, z0}, {2, 2, z1}, {2, 1, z1}, grey, "right");  // +x
    add_quad(s, {2, 2, z0}, {1, 2, z0}, {1, 2, z1}, {2, 2, z1}, grey, "back");   // +y
    add_quad(s, {1, 2, z0}, {1, 1, z0}, {1, 1, z1}, {1, 2, z1}, grey, "left");   // −x
    add_quad(s, {1, 1, z1}, {2, 1, z1}, {2, 2, z1}, {1, 2, z1}, grey, "top");    // +z
    finish(s);
    mesh::Settings ms;
    ms.patch_size = 0.5;
    ms.element_size = 0.25;
    return mesh::build(s, ms);
}

glm::dvec3 lowest(const mesh::Polygon& p) {
    glm::dvec3 lo = p.v[0];
    for (int i = 1; i < p.n; ++i) lo = glm::min(lo, p.v[std::size_t(i)]);
    return lo;
}

glm::dvec3 highest(const mesh::Polygon& p) {
    glm::dvec3 hi = p.v[0];
    for (int i = 1; i < p.n; ++i) hi = glm::max(hi, p.v[std::size_t(i)]);
    return hi;
}

}  // namespace

TEST_CASE("contact: distances between convex polygons", "[contact]") {
    const mesh::Polygon floor = quad({0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0});
    // Parallel, one above the other: the gap.
    CHECK(mesh::polygon_distance(floor, quad({0.2, 0.2, 0.3}, {0.8, 0.2, 0.3}, {0.8, 0.8, 0.3}, {0.2, 0.8, 0.3})) ==
          Approx(0.3).epsilon(1e-12));
    // A wall beside it, raised: from the floor's edge x = 1 to the wall's bottom edge (x 1.5, z 0.2).
    CHECK(mesh::polygon_distance(floor, quad({1.5, 0, 0.2}, {1.5, 1, 0.2}, {1.5, 1, 1.2}, {1.5, 0, 1.2})) ==
          Approx(std::sqrt(0.5 * 0.5 + 0.2 * 0.2)).epsilon(1e-12));
    // Standing on it, and passing through it.
    CHECK(mesh::polygon_distance(floor, quad({0.5, 0, 0}, {0.5, 1, 0}, {0.5, 1, 1}, {0.5, 0, 1})) == 0.0);
    CHECK(mesh::polygon_distance(floor, quad({0.5, 0.2, -0.5}, {0.5, 0.8, -0.5}, {0.5, 0.8, 0.5}, {0.5, 0.2, 0.5})) == 0.0);
    // Skew edges: the floor's edge y = 0 and a stick's edge above it along y, at height 0.4.
    mesh::Polygon stick;
    stick.v = {glm::dvec3(0.5, -1, 0.4), glm::dvec3(0.5, -0.5, 0.4), glm::dvec3(0.5, -1, 1.4)};
    CHECK(mesh::polygon_distance(floor, stick) == Approx(std::sqrt(0.5 * 0.5 + 0.4 * 0.4)).epsilon(1e-12));
}

TEST_CASE("contact: a box standing on a floor touches it along its foot, and only there", "[contact]") {
    const mesh::Mesh m = box_on_floor(0.0);
    const std::vector<bool> marked = mesh::contact_elements(m, 0.1);
    REQUIRE(marked.size() == m.elements.size());
    int floor_marked = 0, sides_marked = 0;
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        const mesh::Element& e = m.elements[k];
        const glm::dvec3 lo = lowest(e.poly), hi = highest(e.poly);
        bool expected = false;
        if (e.node == 0) {
            // Floor: outside the footprint, with its closed box meeting the footprint's.
            const bool inside = lo.x >= 1 && hi.x <= 2 && lo.y >= 1 && hi.y <= 2;
            const bool meets = hi.x >= 1 && lo.x <= 2 && hi.y >= 1 && lo.y <= 2;
            expected = !inside && meets;
            floor_marked += marked[k];
        } else if (e.node <= 4) {
            expected = lo.z == 0.0;  // a side: its bottom row
            sides_marked += marked[k];
        }  // the top: its rim is convex
        CAPTURE(e.node, lo.x, lo.y, lo.z, hi.x, hi.y, hi.z);
        CHECK(marked[k] == expected);
    }
    CHECK(floor_marked == 4 * 4 + 4);  // four along each side, one at each corner
    CHECK(sides_marked == 4 * 4);

    SECTION("nothing is split below the size asked for") {
        const std::vector<bool> none = mesh::contact_elements(m, 0.3);
        CHECK(std::count(none.begin(), none.end(), true) == 0);
    }
}

TEST_CASE("contact: a box hovering above the floor touches nothing", "[contact]") {
    const mesh::Mesh m = box_on_floor(0.1);
    const std::vector<bool> marked = mesh::contact_elements(m, 0.1);
    CHECK(std::count(marked.begin(), marked.end(), true) == 0);
}

TEST_CASE("contact: grading splits the contact elements and keeps every element average", "[contact][gather]") {
    mesh::Mesh m = box_on_floor(0.0);
    const std::size_t before = m.elements.size();
    std::vector<glm::dvec3> radiosity(before), irradiance(before);
    std::vector<glm::dvec3> flux(6, glm::dvec3(0.0));  // per node: Σ area × B
    for (std::size_t k = 0; k < before; ++k) {
        const glm::dvec3 c = m.elements[k].centroid;
        irradiance[k] = glm::dvec3(1.0 + c.x, 2.0 + c.y, 3.0 + c.z);
        radiosity[k] = m.elements[k].emission + m.elements[k].rho * irradiance[k];
        flux[m.elements[k].node] += m.elements[k].area * radiosity[k];
    }
    const std::vector<bool> contact = mesh::contact_elements(m, 0.1);
    const std::size_t split = solve::grade_contacts(m, radiosity, irradiance, 0.1, nullptr);
    CHECK(split == static_cast<std::size_t>(std::count(contact.begin(), contact.end(), true)));
    CHECK(split == 4 * 4 + 4 + 4 * 4);
    REQUIRE(m.elements.size() == before + 3 * split);
    REQUIRE(radiosity.size() == m.elements.size());
    std::vector<glm::dvec3> after(6, glm::dvec3(0.0));
    for (std::size_t k = 0; k < m.elements.size(); ++k) after[m.elements[k].node] += m.elements[k].area * radiosity[k];
    for (std::size_t n = 0; n < 6; ++n)
        for (int c = 0; c < 3; ++c) CHECK(after[n][c] == Approx(flux[n][c]).epsilon(1e-12));
    // Graded once, the children are a quarter the size: a second pass finds nothing above 0.15.
    const std::vector<bool> again = mesh::contact_elements(m, 0.15);
    CHECK(std::count(again.begin(), again.end(), true) == 0);
}

TEST_CASE("contact: a sharp concave fold is a contact line, a gentle one is not", "[contact]") {
    // Two 1 × 1 quads sharing the edge x ∈ [0, 1] on the x axis, their normals `angle` apart: a
    // floor (facing +z) and a second face folded up about the shared edge, concave side up.
    const auto folded = [](double degrees) {
        const double a = degrees * 3.14159265358979323846 / 180.0;
        Scene s;
        const std::uint32_t grey = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
        add_quad(s, {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, grey, "floor");
        const glm::dvec3 out(0.0, -std::cos(a), std::sin(a));  // from the shared edge, away from the floor
        add_quad(s, {0, 0, 0}, glm::dvec3(0, 0, 0) + out, glm::dvec3(1, 0, 0) + out, {1, 0, 0}, grey, "fold");
        finish(s);
        mesh::Settings ms;
        ms.patch_size = 0.5;
        ms.element_size = 0.25;
        const mesh::Mesh m = mesh::build(s, ms);
        const std::vector<bool> marked = mesh::contact_elements(m, 0.1);
        return std::count(marked.begin(), marked.end(), true);
    };
    CHECK(folded(20.0) == 0);       // a smooth surface's gentle fold
    CHECK(folded(90.0) == 4 + 4);   // a wall on a floor: the row on each side of the line
    CHECK(folded(150.0) == 4 + 4);  // an acute wedge
}
