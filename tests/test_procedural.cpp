// Tests for the procedural benchmark scenes: triangle counts, closed and consistently oriented
// room and objects, closed shots, determinism, and parsing of "procedural:<count>" specs.
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <glm/gtc/constants.hpp>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "core/error.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "gen/procedural.h"
#include "test_scenes.h"

using glm::dvec3;
using hemirad::InputError;
using hemirad::gen::parse_procedural_spec;
using hemirad::gen::procedural_scene;
using hemirad::scene::Scene;
using hemirad::scene::Triangle;

namespace {

const dvec3 kRoomCentre(0.0, 2.0, 0.0);

dvec3 normal_of(const Triangle& t) {
    return glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]);
}

dvec3 centroid_of(const Triangle& t) {
    return (t.p[0] + t.p[1] + t.p[2]) / 3.0;
}

// Bitwise vertex keys: a closed surface must reuse identical coordinates, not nearly equal ones.
using Key = std::array<double, 3>;
Key key(const dvec3& p) {
    return {p.x, p.y, p.z};
}

// Empty when every directed edge a→b of the surface is matched by exactly one b→a and no edge
// is used twice in the same direction: closed, and oriented consistently. Else the first problem.
std::string closure_problem(const std::vector<const Triangle*>& surface) {
    std::map<std::pair<Key, Key>, int> directed;
    for (const Triangle* t : surface)
        for (int k = 0; k < 3; ++k) ++directed[{key(t->p[std::size_t(k)]), key(t->p[std::size_t((k + 1) % 3)])}];
    for (const auto& [edge, count] : directed) {
        if (count != 1) return "an edge is used " + std::to_string(count) + " times in one direction";
        const auto twin = directed.find({edge.second, edge.first});
        if (twin == directed.end()) return "an edge has no opposite (a hole or flipped triangle)";
    }
    return {};
}

std::size_t relative_error_percent(std::size_t got, std::size_t wanted) {
    const double e = std::abs(double(got) - double(wanted)) / double(wanted);
    return std::size_t(std::lround(100.0 * e));
}

// Checks every structural promise of one scene; used on several sizes.
void check_structure(const Scene& s) {
    INFO(s.path.string());
    REQUIRE(s.materials.size() >= 4);
    REQUIRE(s.nodes.size() >= 2);
    CHECK(s.nodes[0].name == "room");
    CHECK(s.nodes[1].name == "light");
    CHECK(s.cameras.size() == 1);

    std::vector<const Triangle*> room;
    std::map<std::uint32_t, std::vector<const Triangle*>> objects;  // by primitive
    std::map<std::uint32_t, std::uint32_t> node_of;                 // primitive → node
    std::set<std::uint32_t> finished;                               // primitives whose run has ended
    std::uint32_t previous = ~0u;
    bool contiguous = true, one_node = true, in_box = true, nondegenerate = true, rho_ok = true;
    for (const Triangle& t : s.triangles) {
        // Non-degenerate well beyond the mesher's 1e-12 × longest² cut.
        const double area = 0.5 * glm::length(normal_of(t));
        double longest = 0.0;
        for (int k = 0; k < 3; ++k)
            longest = std::max(longest, glm::length(t.p[std::size_t((k + 1) % 3)] - t.p[std::size_t(k)]));
        if (!(area > 1e-6 * longest * longest)) nondegenerate = false;
        for (const dvec3& p : t.p)
            if (glm::any(glm::lessThan(p, s.bbox_min)) || glm::any(glm::greaterThan(p, s.bbox_max))) in_box = false;
        REQUIRE(t.material < s.materials.size());
        REQUIRE(t.node < s.nodes.size());
        for (const dvec3& rho : t.rho)
            if (rho != s.materials[t.material].base_color) rho_ok = false;

        if (t.primitive != previous) {
            if (finished.count(t.primitive)) contiguous = false;
            if (previous != ~0u) finished.insert(previous);
            previous = t.primitive;
        }
        const auto [it, inserted] = node_of.emplace(t.primitive, t.node);
        if (!inserted && it->second != t.node) one_node = false;

        if (t.node == 0) {
            room.push_back(&t);
            // Walls face into the room.
            CHECK(glm::dot(normal_of(t), kRoomCentre - centroid_of(t)) > 0.0);
        } else if (t.node == 1) {
            CHECK(glm::normalize(normal_of(t)).y == Approx(-1.0));  // the light faces the floor
            CHECK(s.materials[t.material].emission.x > 0.0);
        } else {
            objects[t.primitive].push_back(&t);
            CHECK(s.materials[t.material].emission == dvec3(0.0));
        }
    }
    CHECK(nondegenerate);
    CHECK(in_box);
    CHECK(rho_ok);
    CHECK(contiguous);  // each primitive's triangles form one run
    CHECK(one_node);

    // The room: 6 walls, 2 triangles each, each its own primitive, closed.
    CHECK(room.size() == 12);
    std::set<std::uint32_t> wall_primitives;
    for (const Triangle* t : room) wall_primitives.insert(t->primitive);
    CHECK(wall_primitives.size() == 6);
    CHECK(closure_problem(room).empty());

    // Objects: one node each, named object_<row>_<col>; closed, facing out from an interior point.
    CHECK(objects.size() == s.nodes.size() - 2);
    std::set<std::uint32_t> object_nodes;
    bool closed = true, outward = true, on_floor = true;
    std::string problem;
    for (const auto& [primitive, tris] : objects) {
        object_nodes.insert(tris.front()->node);
        const std::string p = closure_problem(tris);
        if (!p.empty()) closed = false, problem = p;
        dvec3 mean(0.0);  // a positive mix of a convex solid's vertices lies inside it
        double lowest = 1e30;
        for (const Triangle* t : tris)
            for (const dvec3& v : t->p) mean += v, lowest = std::min(lowest, v.y);
        mean /= 3.0 * double(tris.size());
        for (const Triangle* t : tris) {
            if (!(glm::dot(normal_of(*t), centroid_of(*t) - mean) > 0.0)) outward = false;
            // A face in the floor's plane would see out of the room from its centroid.
            if (!(centroid_of(*t).y > 0.0)) on_floor = false;
        }
        // Ellipsoids touch the floor at their pole; boxes stand 1 mm above it, so that no face
        // lies in the floor's plane looking out of the room.
        if (!(lowest >= 0.0 && lowest <= 0.001)) on_floor = false;
    }
    INFO(problem);
    CHECK(closed);
    CHECK(outward);
    CHECK(on_floor);
    CHECK(object_nodes.size() == objects.size());
    for (std::size_t n = 2; n < s.nodes.size(); ++n) CHECK(s.nodes[n].name.rfind("object_", 0) == 0);
}

// The floor fraction under the objects: a closed convex object's outline seen from above has
// half the sum over its triangles of area × |n·y| (every vertical line crosses it twice).
double floor_coverage(const Scene& s) {
    double area = 0.0;
    for (const Triangle& t : s.triangles)
        if (t.node >= 2) area += 0.25 * std::abs(normal_of(t).y);  // |cross| is twice the area
    return area / ((s.bbox_max.x - s.bbox_min.x) * (s.bbox_max.z - s.bbox_min.z));
}

}  // namespace

TEST_CASE("procedural scenes have about the requested triangle count", "[procedural]") {
    CHECK(procedural_scene(100).triangles.size() >= 67);
    CHECK(procedural_scene(100).triangles.size() <= 150);
    for (const std::size_t n : {1'000u, 2'500u, 10'000u, 12'345u, 100'000u}) {
        INFO(n);
        CHECK(relative_error_percent(procedural_scene(n).triangles.size(), n) <= 10);
    }
    const Scene million = procedural_scene(1'000'000);
    CHECK(relative_error_percent(million.triangles.size(), 1'000'000) <= 10);
    CHECK(million.nodes.size() <= 10'002);
    CHECK(million.path.string() == "procedural:1M");
}

TEST_CASE("procedural scenes: closed room and objects, consistently oriented", "[procedural]") {
    for (const std::size_t n : {100u, 1'000u, 10'000u, 33'333u}) {
        const Scene s = procedural_scene(n, 7);
        check_structure(s);
    }
}

TEST_CASE("procedural scenes: bounding box, camera and materials", "[procedural]") {
    const Scene s = procedural_scene(10'000);
    CHECK(s.path.string() == "procedural:10k");
    CHECK(s.bbox_min == dvec3(-5.0, 0.0, -5.0));
    CHECK(s.bbox_max == dvec3(5.0, 4.0, 5.0));
    const dvec3 eye(s.cameras[0].camera_to_world[3]);
    CHECK(glm::all(glm::greaterThan(eye, s.bbox_min)));
    CHECK(glm::all(glm::lessThan(eye, s.bbox_max)));
    std::set<std::string> names;
    for (const auto& m : s.materials) names.insert(m.name);
    CHECK(names == std::set<std::string>{"grey", "red", "green", "light"});
}

TEST_CASE("procedural scenes are deterministic, the seed changes layout, not size", "[procedural]") {
    const Scene a = procedural_scene(20'000, 3), b = procedural_scene(20'000, 3), c = procedural_scene(20'000, 4);
    CHECK(hemirad::test::same_triangles(a, b));
    CHECK(c.triangles.size() == a.triangles.size());
    CHECK_FALSE(hemirad::test::same_triangles(a, c));
}

TEST_CASE("procedural scenes cover a similar floor fraction at every size", "[procedural]") {
    // Designed: a third boxes (0.36 cell²), the rest ellipsoids (0.09π cell²), over 64 of 100 m².
    const double designed = 0.64 * (0.36 + 2.0 * 0.09 * glm::pi<double>()) / 3.0;
    for (const std::size_t n : {100u, 1'000u, 10'000u, 100'000u}) {
        INFO(n);
        CHECK(floor_coverage(procedural_scene(n)) == Approx(designed).epsilon(0.05));
    }
}

TEST_CASE("procedural scenes mesh into paired quads with nothing dropped", "[procedural]") {
    const Scene s = procedural_scene(10'000);
    const double patch = s.diagonal() / 16.0;
    const hemirad::mesh::Mesh m = hemirad::mesh::build(s, {patch, patch / 3.0});
    CHECK(m.dropped_triangles == 0);
    // Nearly every triangle belongs to a quad (only the ellipsoids' polar fans stand alone).
    CHECK(double(2 * m.quads) > 0.8 * double(s.triangles.size()));
}

TEST_CASE("every shot in a procedural scene sees a closed surround", "[procedural]") {
    // Form factors plus blocked must be 1 from every patch: nothing can escape a closed room.
    // All patches of the smallest scene; at 1k the downward-facing ones (box bottoms, the lower
    // halves of ellipsoids, which sit nearest the floor) and a spread of the rest.
    for (const std::size_t n : {100u, 1'000u}) {
        const Scene s = procedural_scene(n);
        const double patch = s.diagonal() / 16.0;
        const hemirad::mesh::Mesh m = hemirad::mesh::build(s, {patch, patch / 3.0});
        hemirad::formfactor::ReferenceEngine engine(m, {32, 1});
        hemirad::formfactor::ShotResult shot;
        std::size_t shots = 0, open = 0;
        for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
            if (n > 100 && m.patches[p].normal.y > -0.5 && p % 10 != 0) continue;
            engine.shoot(p, p, shot);
            double sum = shot.blocked;
            for (const double f : shot.F) sum += f;
            ++shots;
            if (!(std::abs(sum - 1.0) < 1e-9)) ++open;
        }
        INFO(n << ": " << shots << " shots");
        CHECK(shots > 100);
        CHECK(open == 0);
    }
}

TEST_CASE("parse_procedural_spec", "[procedural]") {
    CHECK(parse_procedural_spec("procedural:100") == std::size_t(100));
    CHECK(parse_procedural_spec("procedural:100k") == std::size_t(100'000));
    CHECK(parse_procedural_spec("procedural:1M") == std::size_t(1'000'000));
    CHECK(parse_procedural_spec("procedural:2.5M") == std::size_t(2'500'000));
    CHECK(parse_procedural_spec("procedural:0010K") == std::size_t(10'000));
    CHECK(parse_procedural_spec("procedural:50M") == std::size_t(50'000'000));
    CHECK_FALSE(parse_procedural_spec("scenes/x.gltf"));
    CHECK_FALSE(parse_procedural_spec("procedural"));
    CHECK_FALSE(parse_procedural_spec(""));
    for (const char* bad : {"procedural:", "procedural:abc", "procedural:0", "procedural:0k", "procedural:51M",
                            "procedural:99999999999999999999999", "procedural:1.5", "procedural:1.0001k",
                            "procedural:-5", "procedural:10 k", "procedural:1kk", "procedural:1.k"}) {
        INFO(bad);
        CHECK_THROWS_AS(parse_procedural_spec(bad), InputError);
    }
    // One line, naming the spec.
    try {
        parse_procedural_spec("procedural:abc");
        FAIL("no exception");
    } catch (const InputError& e) {
        const std::string what = e.what();
        CHECK(what.rfind("procedural:abc: ", 0) == 0);
        CHECK(what.find('\n') == std::string::npos);
    }
}
