// Inverted-hull toon outlines (the outlines effect) against rooms of one-sided walls: a box in its
// hull bakes exactly as the box without it, a room keeps the sun out, and the warning for light
// that lands on one-sided backs (scene/outlines.h).
#include <catch2/catch.hpp>

#include <string>

#include "cli_support.h"
#include "scene/builder.h"
#include "scene/effects.h"
#include "scene/outlines.h"
#include "scene/sky.h"
#include "scene/writer.h"

namespace {

using namespace hemirad::test;
using hemirad::scene::Scene;
using glm::dvec3;

std::uint32_t add_node(Scene& s, const std::string& name) {
    const auto node = static_cast<std::uint32_t>(s.nodes.size());
    s.nodes.push_back({name, static_cast<int>(node)});
    return node;
}

// The faces of the box [lo, hi] in node `node`, facing outwards or (`inward`) inwards; without
// its bottom (y = lo.y) face unless `bottom`.
void add_box(Scene& s, dvec3 lo, dvec3 hi, std::uint32_t material, std::uint32_t node, bool inward, bool bottom = true) {
    const double x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x, y1 = hi.y, z1 = hi.z;
    const auto quad = [&](dvec3 a, dvec3 b, dvec3 c, dvec3 d) {
        if (inward) hemirad::scene::add_quad_to(s, a, d, c, b, material, node, node);
        else hemirad::scene::add_quad_to(s, a, b, c, d, material, node, node);
    };
    quad({x0, y0, z0}, {x0, y0, z1}, {x0, y1, z1}, {x0, y1, z0});  // −x
    quad({x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1});  // +x
    if (bottom) quad({x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1});  // −y
    quad({x0, y1, z0}, {x0, y1, z1}, {x1, y1, z1}, {x1, y1, z0});  // +y
    quad({x0, y0, z0}, {x0, y1, z0}, {x1, y1, z0}, {x1, y0, z0});  // −z
    quad({x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1});  // +z
}

// The box [lo, hi] scaled by `scale` about its centre, faces turned inwards: its toon outline.
void add_hull(Scene& s, dvec3 lo, dvec3 hi, double scale, std::uint32_t material, std::uint32_t node) {
    const dvec3 c = 0.5 * (lo + hi), h = 0.5 * scale * (hi - lo);
    add_box(s, c - h, c + h, material, node, true);
}

// A grey 4 x 4 m floor facing up (node "floor"); `boxes` grey unit boxes floating 0.3 m over it
// (nodes "box", "box1" ...), each in its hull (the box scaled `scale` about its centre, black,
// one-sided, node "shell", "shell1" ...) where `hulls`. Materials: 0 grey, 1 black ink.
Scene boxes_on_floor(int boxes, bool hulls, double scale = 1.05, double floor_half = 2.0) {
    Scene s;
    const std::uint32_t grey = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0));
    const std::uint32_t ink = hemirad::scene::add_material(s, dvec3(0.0), dvec3(0.0));
    const double f = floor_half;
    hemirad::scene::add_quad(s, {-f, 0, -f}, {-f, 0, f}, {f, 0, f}, {f, 0, -f}, grey, "floor");
    for (int b = 0; b < boxes; ++b) {
        const std::string suffix = b == 0 ? "" : std::to_string(b);
        const dvec3 at(1.5 * (b % 3) - 1.5 * ((boxes > 1) ? 1 : 0), 0.0, 1.5 * (b / 3) - 1.5 * ((boxes > 3) ? 1 : 0));
        const dvec3 lo = at + dvec3(-0.5, 0.3, -0.5), hi = at + dvec3(0.5, 1.3, 0.5);
        add_box(s, lo, hi, grey, add_node(s, "box" + suffix), false);
        if (hulls) add_hull(s, lo, hi, scale, ink, add_node(s, "shell" + suffix));
    }
    hemirad::scene::finish(s);
    return s;
}

// A closed 4 x 3 x 5 m room of one-sided walls facing inwards (one mesh, node "room") with a
// table (1.2 x 0.8 x 0.7 m box, node "table") inside, on a 20 x 20 m ground (node "ground")
// 1 cm below it.
Scene room_with_table() {
    Scene s;
    const std::uint32_t grey = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0));
    hemirad::scene::add_quad(s, {-10, -0.01, -10}, {-10, -0.01, 10}, {10, -0.01, 10}, {10, -0.01, -10}, grey, "ground");
    add_box(s, {-2, 0, -2.5}, {2, 3, 2.5}, grey, add_node(s, "room"), true);
    add_box(s, {-0.6, 0, -0.4}, {0.6, 0.7, 0.4}, grey, add_node(s, "table"), false, false);
    hemirad::scene::finish(s);
    return s;
}

const json& mesh_named(const json& report, const std::string& name) {
    for (const json& m : report["meshes"])
        if (m["name"] == name) return m;
    FAIL("no mesh '" << name << "' in the report");
    return report;
}
double radiosity(const json& report, const std::string& name) { return mesh_named(report, name)["radiosity"][0].get<double>(); }

bool warned_back_light(const json& report) {
    for (const json& w : report["warnings"])
        if (w.get<std::string>().find("backs of one-sided surfaces") != std::string::npos) return true;
    return false;
}

const std::vector<std::string> kSun = concat(kFast, {"--sun", "30,60,3"});

}  // namespace

TEST_CASE("outlines: a box in its inverted hull is found, a room, a loose shell or an outward copy is not",
          "[outlines]") {
    using hemirad::scene::find_outline_hulls;
    SECTION("a hull 5% larger than its box") {
        const hemirad::scene::OutlineSearch found = find_outline_hulls(boxes_on_floor(1, true));
        REQUIRE(found.hulls.size() == 1);
        CHECK(found.triangles.size() == 12);
        CHECK(found.hulls[0].node == 2);
        // The widest gap: 2.5% of the box's side on every side, over the hull's diagonal.
        CHECK(found.hulls[0].gap == Approx(0.025 / (1.05 * std::sqrt(3.0))).epsilon(1e-9));
        for (std::size_t t : found.triangles) CHECK(t >= 14);  // floor 2 + box 12 come first
    }
    SECTION("nine boxes, nine hulls") {
        const hemirad::scene::OutlineSearch found = find_outline_hulls(boxes_on_floor(9, true, 1.05, 3.0));
        CHECK(found.hulls.size() == 9);
        CHECK(found.triangles.size() == 9 * 12);
    }
    SECTION("a shell twice the size of its box hugs nothing") {
        const hemirad::scene::OutlineSearch found = find_outline_hulls(boxes_on_floor(1, true, 2.0));
        CHECK(found.hulls.empty());
        CHECK(found.inward_shells == 1);
    }
    SECTION("a shell named as an outline may be twice as loose, and no looser") {
        // 1.3: gaps of 0.15 / (1.3 √3) = 6.7% of the diagonal on the sides, the corners 0.26 m
        // (11.5%) from the box's: past the tolerance of 10% for an unnamed shell, within 20%.
        Scene s = boxes_on_floor(1, true, 1.3);
        CHECK(find_outline_hulls(s).hulls.empty());
        s.nodes[2].name = "Box_Outline";
        CHECK(find_outline_hulls(s).hulls.size() == 1);
        s.nodes[2].name = "pink sink";  // "ink" only inside words
        CHECK(find_outline_hulls(s).hulls.empty());
        s.nodes[2].name = "Ink.001";
        CHECK(find_outline_hulls(s).hulls.size() == 1);
        // A name alone makes no hull.
        Scene loose = boxes_on_floor(1, true, 2.0);
        loose.nodes[2].name = "outline";
        CHECK(find_outline_hulls(loose).hulls.empty());
    }
    SECTION("a larger copy facing outwards, a double-sided hull, an empty hull") {
        Scene outward = boxes_on_floor(1, false);
        add_box(outward, {-0.525, 0.275, -0.525}, {0.525, 1.325, 0.525}, 1, add_node(outward, "shell"), false);
        CHECK(find_outline_hulls(outward).hulls.empty());
        CHECK(find_outline_hulls(outward).inward_shells == 0);
        Scene two_sided = boxes_on_floor(1, true);
        two_sided.materials[1].double_sided = true;
        CHECK(find_outline_hulls(two_sided).hulls.empty());
        Scene empty;
        hemirad::scene::add_material(empty, dvec3(0.5), dvec3(0.0));
        add_hull(empty, {0, 0, 0}, {1, 1, 1}, 1.05, 0, add_node(empty, "shell"));
        CHECK(find_outline_hulls(empty).hulls.empty());
    }
    SECTION("a room of one-sided walls facing inwards holds a table far smaller than itself") {
        const hemirad::scene::OutlineSearch found = find_outline_hulls(room_with_table());
        CHECK(found.hulls.empty());
        CHECK(found.inward_shells == 1);
        CHECK(found.example_shell == "room");
    }
    SECTION("an outline material's other inward pieces go with its hulls, a larger shell of it does not") {
        // Three hulls of ink (material 1), then a half-size ink shell that encloses nothing: no
        // hull by what it holds, one by its material (the hulls hold 19.8 m² of its 21.3 m²).
        Scene s = boxes_on_floor(3, true, 1.05, 3.0);
        add_hull(s, {2.0, 0.3, 2.0}, {2.5, 0.8, 2.5}, 1.0, 1, add_node(s, "piece"));
        const hemirad::scene::OutlineSearch found = find_outline_hulls(s);
        REQUIRE(found.hulls.size() == 4);
        CHECK(found.triangles.size() == 4 * 12);
        for (const auto& h : found.hulls) CHECK(h.sibling == (s.nodes[h.node].name == "piece"));
        // Nine hulls and an ink shell twice a box's size: most of the ink is hulls (59 of 83 m²),
        // but that shell is larger than any of them.
        Scene big = boxes_on_floor(9, true, 1.05, 3.0);
        add_hull(big, {5.0, 0.3, 5.0}, {6.0, 1.3, 6.0}, 2.0, 1, add_node(big, "big"));
        CHECK(find_outline_hulls(big).hulls.size() == 9);
        // The same piece in grey, the boxes' material, is no hull.
        Scene grey = boxes_on_floor(3, true, 1.05, 3.0);
        add_hull(grey, {2.0, 0.3, 2.0}, {2.5, 0.8, 2.5}, 1.0, 0, add_node(grey, "piece"));
        CHECK(find_outline_hulls(grey).hulls.size() == 3);
    }
    SECTION("a room filled wall to wall is still a room when a camera is inside it") {
        Scene s;
        const std::uint32_t grey = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0));
        add_box(s, {0, 0, 0}, {4, 3, 5}, grey, add_node(s, "room"), true);
        add_box(s, {0.1, 0.0, 0.1}, {3.9, 2.9, 4.9}, grey, add_node(s, "crate"), false);
        CHECK(find_outline_hulls(s).hulls.size() == 1);  // shaped like a hull...
        hemirad::scene::Camera camera;
        camera.camera_to_world[3] = glm::dvec4(2.0, 1.5, 2.5, 1.0);
        s.cameras.push_back(camera);
        CHECK(find_outline_hulls(s).hulls.empty());  // ...but seen from inside
    }
}

TEST_CASE("outlines: the effect's names and values", "[outlines][effects]") {
    using hemirad::scene::Force;
    using hemirad::scene::parse_effect_overrides;
    CHECK(parse_effect_overrides("outlines=on").outlines == Force::on);
    CHECK(parse_effect_overrides(" outlines = off ").outlines == Force::off);
    CHECK(parse_effect_overrides("see_through=off,outlines=auto").outlines == Force::automatic);
    CHECK(parse_effect_overrides("").outlines == Force::automatic);
    CHECK_THROWS_WITH(parse_effect_overrides("outlines=maybe"), Catch::Contains("bad value 'maybe'"));
    CHECK_THROWS_WITH(parse_effect_overrides("outlines=on,outlines=off"), Catch::Contains("'outlines' given twice"));
    CHECK_THROWS_WITH(parse_effect_overrides("outline=on"), Catch::Contains("see_through or outlines"));
}

TEST_CASE("outlines: the plan leaves the hulls out, and judges the other effects without them", "[outlines][effects]") {
    const Scene s = boxes_on_floor(1, true);
    hemirad::scene::EffectsPlan plan = hemirad::scene::plan_effects(s, {});
    CHECK(plan.outlines.on);
    CHECK_FALSE(plan.outlines.forced);
    CHECK(plan.outline_triangles.size() == 12);
    CHECK_THAT(plan.outlines.why, Catch::Contains("1 inverted-hull outline (12 triangles on 1 node, e.g. 'shell') hugs the object it encloses"));
    CHECK_THAT(plan.outlines.why, Catch::Contains("outlines=off keeps them"));
    // Without the hull the floor and box hold no black: the reflectances are all grey.
    Scene applied = s;
    hemirad::scene::apply_outlines(applied, plan);
    CHECK(applied.triangles.size() == 14);
    for (const hemirad::scene::Triangle& t : applied.triangles) CHECK(t.material == 0);

    hemirad::scene::EffectOverrides off;
    off.outlines = hemirad::scene::Force::off;
    plan = hemirad::scene::plan_effects(s, off);
    CHECK_FALSE(plan.outlines.on);
    CHECK(plan.outlines.forced);
    CHECK(plan.outline_triangles.empty());
    CHECK_THAT(plan.outlines.why, Catch::Contains("forced off"));
    applied = s;
    hemirad::scene::apply_outlines(applied, plan);
    CHECK(applied.triangles.size() == s.triangles.size());

    const hemirad::scene::EffectsPlan room = hemirad::scene::plan_effects(room_with_table(), {});
    CHECK_FALSE(room.outlines.on);
    CHECK_THAT(room.outlines.why, Catch::Contains("node 'room'"));
}

TEST_CASE("outlines: a box in its hull under the sun bakes as the box alone and outlines=off leaves it black",
          "[outlines][cli]") {
    TempDir dir;
    hemirad::scene::write_gltf(boxes_on_floor(1, false), dir / "bare.gltf");
    hemirad::scene::write_gltf(boxes_on_floor(1, true), dir / "hull.gltf");
    const json bare = bake_ok(dir, dir / "bare.gltf", dir / "bare", kSun);
    REQUIRE(radiosity(bare, "box") > 0.1);

    const json seen = bake_ok(dir, dir / "hull.gltf", dir / "auto", kSun);
    const json& effect = seen["effects"]["outlines"];
    INFO(effect.dump());
    CHECK(effect["on"] == true);
    CHECK(effect["forced"] == false);
    CHECK(mesh_named(seen, "shell")["area"] == 0.0);
    // The same mesh as without the hull: the same light, to rounding.
    CHECK(radiosity(seen, "box") == Approx(radiosity(bare, "box")).epsilon(1e-12));
    CHECK(radiosity(seen, "floor") == Approx(radiosity(bare, "floor")).epsilon(1e-12));
    CHECK_FALSE(warned_back_light(seen));

    const json kept = bake_ok(dir, dir / "hull.gltf", dir / "off", concat(kSun, {"--effects", "outlines=off"}));
    CHECK(kept["effects"]["outlines"]["on"] == false);
    CHECK(kept["effects"]["outlines"]["forced"] == true);
    CHECK(mesh_named(kept, "shell")["area"].get<double>() == Approx(6 * 1.05 * 1.05));
    // Inside its hull (black inside, its back blocking the sun) the box gets nothing.
    CHECK(radiosity(kept, "box") == 0.0);
}

TEST_CASE("outlines: a closed room of one-sided walls keeps the sun out and is not taken for a hull",
          "[outlines][cli]") {
    TempDir dir;
    hemirad::scene::write_gltf(room_with_table(), dir / "room.gltf");
    const json report = bake_ok(dir, dir / "room.gltf", dir / "room", kSun);
    INFO(report["effects"]["outlines"].dump());
    CHECK(report["effects"]["outlines"]["on"] == false);
    CHECK(radiosity(report, "ground") > 0.1);
    CHECK(radiosity(report, "room") == 0.0);
    CHECK(radiosity(report, "table") == 0.0);
    // The sun on the room's outer walls (their backs) is as meant: no warning.
    CHECK_FALSE(warned_back_light(report));
}

TEST_CASE("outlines: the share of the sun's light on one-sided backs", "[outlines]") {
    SECTION("a floor facing up, then facing down, under a sun straight overhead") {
        Scene s = boxes_on_floor(0, false);
        s.lights.push_back(hemirad::scene::parse_sun("0,90,2", "--sun"));
        auto b = hemirad::scene::back_light(s);
        REQUIRE(b);
        CHECK(b->share == 0.0);
        CHECK_FALSE(hemirad::scene::back_light_warning(s));
        for (hemirad::scene::Triangle& t : s.triangles) std::swap(t.p[1], t.p[2]);  // flipped normals
        b = hemirad::scene::back_light(s);
        REQUIRE(b);
        CHECK(b->share == 1.0);
        CHECK(b->triangles == 2);
        CHECK(b->example == "floor");
        const auto w = hemirad::scene::back_light_warning(s);
        REQUIRE(w);
        CHECK_THAT(*w, Catch::Contains("100% of the light"));
        CHECK_THAT(*w, Catch::Contains("--effects two_sided=on"));
    }
    SECTION("a hull's top over the floor, seen from the sun overhead") {
        Scene s = boxes_on_floor(1, true);
        s.lights.push_back(hemirad::scene::parse_sun("0,90,2", "--sun"));
        const auto b = hemirad::scene::back_light(s);
        REQUIRE(b);
        // The hull's top, 1.05 m square, of the 4 m floor (to the cells of a 256-cell grid).
        CHECK(b->share == Approx(1.05 * 1.05 / 16.0).margin(2.0 * 4.0 * 1.05 / 256.0 / 16.0 * 4.0));
        CHECK_FALSE(hemirad::scene::back_light_warning(s));
    }
    SECTION("counts grouped by thousands") {
        CHECK(hemirad::scene::grouped(0) == "0");
        CHECK(hemirad::scene::grouped(999) == "999");
        CHECK(hemirad::scene::grouped(52824) == "52,824");
        CHECK(hemirad::scene::grouped(1234567) == "1,234,567");
    }
    SECTION("no sun and no sky: nothing to say") {
        CHECK_FALSE(hemirad::scene::back_light(boxes_on_floor(1, true)));
    }
}

TEST_CASE("outlines: the warning for light on one-sided backs fires for kept hulls, not for a room", "[outlines][cli]") {
    TempDir dir;
    // Nine boxes in their hulls nearly cover a 5 x 5 m floor.
    hemirad::scene::write_gltf(boxes_on_floor(9, true, 1.05, 2.5), dir / "hulls.gltf");
    const json kept = bake_ok(dir, dir / "hulls.gltf", dir / "off", concat(kSun, {"--effects", "outlines=off"}));
    CHECK(warned_back_light(kept));
    bool says = false;
    for (const json& w : kept["warnings"])
        says = says || (w.get<std::string>().find("--effects outlines=on leaves them out") != std::string::npos &&
                        w.get<std::string>().find("most on node 'shell") != std::string::npos);
    CHECK(says);
    const json left_out = bake_ok(dir, dir / "hulls.gltf", dir / "auto", kSun);
    CHECK(left_out["effects"]["outlines"]["on"] == true);
    CHECK_THAT(left_out["effects"]["outlines"]["why"].get<std::string>(),
               Catch::Contains("9 inverted-hull outlines (108 triangles on 9 nodes, e.g. 'shell')"));
    CHECK_FALSE(warned_back_light(left_out));
    // The room under the sun and under a sky.
    hemirad::scene::write_gltf(room_with_table(), dir / "room.gltf");
    CHECK_FALSE(warned_back_light(bake_ok(dir, dir / "room.gltf", dir / "sky", concat(kFast, {"--sky", "1"}))));
}
