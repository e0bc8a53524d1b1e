// Previews that look like the scene (issue 44, item 5), through `hemirad bake`: the sky where the
// view escapes (π × its radiance, radiosity's units), see-through surfaces blended over what lies
// behind them, a closed room without a camera seen from inside, and sun patterns finer than the
// elements (blinds) kept by refining where the sun's shadow edge crosses an element.
#include <catch2/catch.hpp>
#include <cmath>
#include <string>
#include <vector>

#include "cli_support.h"
#include "rect_scenes.h"

namespace {

using namespace hemirad::test;

const json kGrey = {{"name", "grey"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}};
const json kBlack = {{"name", "black"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}};

glm::vec3 pixel(const ImageData& image, int x, int y) {
    const float* p = &image.pixels[(std::size_t(y) * std::size_t(image.width) + std::size_t(x)) * std::size_t(image.channels)];
    return {p[0], p[1], p[2]};
}

// A vertical quad in the plane z = `z`, [x0, x1] × [y0, y1], facing +Z.
Quad wall(const std::string& name, double x0, double x1, double y0, double y1, double z, int material) {
    return {{glm::dvec3(x0, y0, z), glm::dvec3(x1, y0, z), glm::dvec3(x1, y1, z), glm::dvec3(x0, y1, z)}, {}, name, material};
}
Quad floor_quad(const std::string& name, double x0, double x1, double z0, double z1, double y, int material) {
    return {{glm::dvec3(x0, y, z0), glm::dvec3(x0, y, z1), glm::dvec3(x1, y, z1), glm::dvec3(x1, y, z0)}, {}, name, material};
}

}  // namespace

TEST_CASE("a render under --sky shows pi times the sky's radiance where the view escapes, black without a sky",
          "[previews][sky][cli]") {
    TempDir dir;
    write_json(dir / "floor.gltf", rect_scene(dir, {{"floor", -1, 1, -1, 1, 0.0, true, 0}}, json::array({kGrey})));
    const std::vector<std::string> view = {"--look-from", "0,0.5,3", "--look-at", "0,0.5,0"};
    bake_ok(dir, dir / "floor.gltf", dir / "sky", concat(concat(kFast, view), {"--sky", "1.5"}));
    const ImageData sky = read_image(dir / "sky" / "render.exr");
    // The upper half looks above the floor's far edge, out of the scene, into the dome.
    for (const int x : {0, sky.width / 2, sky.width - 1}) {
        INFO("column " << x);
        CHECK(pixel(sky, x, 0).x == Approx(1.5 * M_PI).epsilon(1e-5));
        CHECK(pixel(sky, x, sky.height / 4).y == Approx(1.5 * M_PI).epsilon(1e-5));
    }
    // Lit by a sun instead: nothing there.
    bake_ok(dir, dir / "floor.gltf", dir / "sun", concat(concat(kFast, view), {"--sun", "0,45,100"}));
    const ImageData sun = read_image(dir / "sun" / "render.exr");
    CHECK(pixel(sun, sun.width / 2, 0).x == 0.0f);
    // The floor, seen from 0.5 above and 2 to 4 away: rows 0.65 to 0.8 of the way down.
    CHECK(pixel(sun, sun.width / 2, int(0.72 * sun.height)).x > 0.0f);
}

TEST_CASE("a red glass pane of opacity a in front of a wall blends (1 - a) of the wall with a times its colour",
          "[previews][see_through][cli]") {
    // The pane (alphaMode BLEND, baseColorFactor (1, 0, 0, 0.3)) is left out of the bake, so the
    // wall's light is the same with it and without it (the floor keeps the bounds the same):
    // behind it the green channel is 0.7 of the bare wall's and red gains 0.3 × 0.9999 × H.
    const json red = {{"name", "red glass"},
                      {"alphaMode", "BLEND"},
                      {"pbrMetallicRoughness", {{"baseColorFactor", {1.0, 0.0, 0.0, 0.3}}}}};
    const std::vector<std::string> view = {"--look-from", "0,0,3", "--look-at", "0,0,0", "--sky", "1"};
    TempDir bare_dir, glass_dir;
    const Quad w = wall("wall", -1, 1, -1, 1, 0.0, 0), f = floor_quad("floor", -1, 1, 0, 1, -1, 0);
    write_json(bare_dir / "bare.gltf", quad_scene(bare_dir, {w, f}, json::array({kGrey, red})));
    write_json(glass_dir / "glass.gltf",
               quad_scene(glass_dir, {w, f, wall("pane", -0.6, 0, -0.4, 0.4, 0.5, 1)}, json::array({kGrey, red})));
    bake_ok(bare_dir, bare_dir / "bare.gltf", bare_dir / "out", concat(kFast, view));
    const json report = bake_ok(glass_dir, glass_dir / "glass.gltf", glass_dir / "out", concat(kFast, view));
    CHECK(report["effects"]["see_through"]["on"] == true);
    const ImageData bare = read_image(bare_dir / "out" / "render.exr");
    const ImageData glass = read_image(glass_dir / "out" / "render.exr");
    // The pane's middle, (−0.3, 0, 0.5), seen from (0, 0, 3): left of the image's centre.
    const int x = bare.width / 2 - int(0.3 / 2.5 / std::tan(0.4) / (4.0 / 3.0) * bare.width / 2), y = bare.height / 2;
    const glm::vec3 behind = pixel(glass, x, y), wall_only = pixel(bare, x, y);
    INFO("behind the pane " << behind.x << " " << behind.y << " " << behind.z << ", bare wall " << wall_only.x);
    REQUIRE(wall_only.y > 0.0f);
    CHECK(behind.y == Approx(0.7 * wall_only.y).epsilon(1e-4));
    CHECK(behind.z == Approx(0.7 * wall_only.z).epsilon(1e-4));
    CHECK(behind.x > 0.7 * wall_only.x + 0.05 * wall_only.x);  // tinted red by the pane's own light
    // Beside the pane the wall is as it was.
    const glm::vec3 beside = pixel(glass, bare.width - 4, y), beside_bare = pixel(bare, bare.width - 4, y);
    CHECK(beside.x == beside_bare.x);
}

TEST_CASE("a closed room without a camera is framed from inside it, showing its walls' fronts",
          "[previews][view][cli]") {
    TempDir dir;
    // A 4 × 3 × 5 room of one-sided walls facing in, lit by its emitting ceiling.
    const json lamp = {{"name", "lamp"}, {"emissiveFactor", {1.0, 1.0, 1.0}},
                       {"pbrMetallicRoughness", {{"baseColorFactor", {0.8, 0.8, 0.8, 1.0}}}}};
    const double x0 = -2, x1 = 2, y0 = 0, y1 = 3, z0 = -2.5, z1 = 2.5;
    const auto q = [](const std::string& name, glm::dvec3 a, glm::dvec3 b, glm::dvec3 c, glm::dvec3 d, int m) {
        return Quad{{a, b, c, d}, {}, name, m};
    };
    const std::vector<Quad> room = {
        q("floor", {x0, y0, z0}, {x0, y0, z1}, {x1, y0, z1}, {x1, y0, z0}, 0),
        q("ceiling", {x0, y1, z0}, {x1, y1, z0}, {x1, y1, z1}, {x0, y1, z1}, 1),
        q("north", {x0, y0, z0}, {x1, y0, z0}, {x1, y1, z0}, {x0, y1, z0}, 0),
        q("south", {x0, y0, z1}, {x0, y1, z1}, {x1, y1, z1}, {x1, y0, z1}, 0),
        q("west", {x0, y0, z0}, {x0, y1, z0}, {x0, y1, z1}, {x0, y0, z1}, 0),
        q("east", {x1, y0, z0}, {x1, y0, z1}, {x1, y1, z1}, {x1, y1, z0}, 0)};
    write_json(dir / "room.gltf", quad_scene(dir, room, json::array({kGrey, lamp})));
    const json report = bake_ok(dir, dir / "room.gltf", dir / "out");
    CHECK(report["settings"]["camera"] == "framing (inside)");
    // Every wall is lit and seen from its front: hardly a black pixel (a back would be culled,
    // showing the dark beyond).
    const ImageData image = read_image(dir / "out" / "render.exr");
    int black = 0;
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x) black += pixel(image, x, y).x <= 0.0f;
    CHECK(black <= image.width * image.height / 50);
}

TEST_CASE("a diorama whose middle lies inside one of its buildings is framed from outside", "[previews][view][cli]") {
    TempDir dir;
    // A 40 × 40 ground, a closed double-sided 6 × 12 × 6 tower on it and a 12-high post in one
    // corner, under a sky: the bounds' centre (0, 6, 0) is inside the tower, whose double-sided
    // walls show from within, as a room's would; but the rays meet them at 0.15 of the way to the
    // bounds sideways (3 of 20), far short of the walls of a room.
    const json ds = {{"name", "grey"}, {"doubleSided", true}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}};
    const auto q = [](const std::string& name, glm::dvec3 a, glm::dvec3 b, glm::dvec3 c, glm::dvec3 d) {
        return Quad{{a, b, c, d}, {}, name, 0};
    };
    const double a = 3, h = 12;
    const std::vector<Quad> quads = {
        floor_quad("ground", -20, 20, -20, 20, 0.0, 0),
        q("roof", {-a, h, -a}, {-a, h, a}, {a, h, a}, {a, h, -a}),
        q("tower floor", {-a, 0.01, -a}, {a, 0.01, -a}, {a, 0.01, a}, {-a, 0.01, a}),
        wall("north", -a, a, 0, h, -a, 0), wall("south", -a, a, 0, h, a, 0),
        q("west", {-a, 0, -a}, {-a, 0, a}, {-a, h, a}, {-a, h, -a}),
        q("east", {a, 0, -a}, {a, h, -a}, {a, h, a}, {a, 0, a}),
        wall("post", 19, 19.5, 0, h, 19, 0)};
    write_json(dir / "diorama.gltf", quad_scene(dir, quads, json::array({ds})));
    std::vector<std::string> args = kFast;
    args.insert(args.end(), {"--sky", "1"});
    const json report = bake_ok(dir, dir / "diorama.gltf", dir / "out", args);
    CHECK(report["settings"]["camera"] == "framing");
}

namespace {

// Blinds: a grey floor [−1, 1]², black slats 0.5 above it, each `slat` wide along x every
// `period` from x = `start`, along the whole floor in z; the sun straight overhead. Baked at
// patches of 0.4 and elements of 0.2, seen from straight above (below the slats), the render's lit share of the
// floor within |x|, |z| < 0.9 and the lit stripes along its middle row are compared with the
// slats' geometry. Without a final gather: its own refinement is another matter (see the report).
void check_blinds(double slat, double period, double start) {
    TempDir dir;
    std::vector<Quad> quads = {floor_quad("floor", -1, 1, -1, 1, 0.0, 0)};
    double lit = 0.0;  // of the window |x| < 0.9, the length between slats
    int stripes = 0;   // gaps that meet the window
    double previous_end = -10.0;
    for (int k = 0; start + k * period < 1.3; ++k) {
        const double a = start + k * period, b = a + slat;
        quads.push_back(floor_quad("slat" + std::to_string(k), a, b, -1.5, 1.5, 0.5, 1));
        const double gap0 = std::max(previous_end, -0.9), gap1 = std::min(a, 0.9);
        if (gap1 > gap0) {
            lit += gap1 - gap0;
            ++stripes;
        }
        previous_end = b;
    }
    const double expected = lit / 1.8;
    write_json(dir / "blinds.gltf", quad_scene(dir, quads, json::array({kGrey, kBlack})));
    const std::vector<std::string> args = {"--hemicube", "32", "--patch-size", "0.4", "--element-size", "0.2",
                                           "--max-passes", "200", "--image-width", "320", "--quiet",
                                           "--sun", "0,90,1000", "--look-from", "0,0.45,0", "--look-at", "0,0,0",
                                           "--fov", "150", "--gather", "0"};
    bake_ok(dir, dir / "blinds.gltf", dir / "out", args);
    const ImageData image = read_image(dir / "out" / "render.exr");
    // Straight down from under the slats, 0.45 above the floor, 150° high: the floor is parallel
    // to the image, u (right) = −x, v (up) = z.
    const double half_v = 0.45 * std::tan(75.0 * M_PI / 180.0), half_u = half_v * image.width / image.height;
    const auto world_x = [&](int i) { return -((i + 0.5) / image.width * 2.0 - 1.0) * half_u; };
    const auto world_z = [&](int j) { return (1.0 - (j + 0.5) / image.height * 2.0) * half_v; };
    const float full = 0.5f * 1000.0f, threshold = 0.5f * full;
    long inside = 0, bright = 0;
    for (int j = 0; j < image.height; ++j) {
        if (std::abs(world_z(j)) >= 0.9) continue;
        for (int i = 0; i < image.width; ++i) {
            if (std::abs(world_x(i)) >= 0.9) continue;
            ++inside;
            bright += pixel(image, i, j).x > threshold;
        }
    }
    int runs = 0;
    bool was = false;
    for (int i = 0; i < image.width; ++i) {
        if (std::abs(world_x(i)) >= 0.9) continue;
        const bool is = pixel(image, i, image.height / 2).x > threshold;
        runs += is && !was;
        was = is;
    }
    const double measured = double(bright) / double(inside);
    INFO("slat " << slat << ", period " << period << ": lit share " << measured << " (geometry " << expected << "), "
                 << runs << " stripes (" << stripes << ")");
    CHECK(measured == Approx(expected).margin(0.03));
    CHECK(runs == stripes);
}

}  // namespace

TEST_CASE("blinds' stripes finer than the elements keep their lit share and their count: refinement follows the sun's "
          "shadow edges",
          "[previews][sun][refinement][cli]") {
    SECTION("slats 0.12 every 0.2: gaps of 0.4 elements") { check_blinds(0.12, 0.2, -1.17); }
    // Each with the window's edges (x = ±0.9) on slats.
    SECTION("slats 0.25 every 0.45: gaps of an element") { check_blinds(0.25, 0.45, -1.45); }
    SECTION("slats 0.8 every 1.6: two patches") { check_blinds(0.8, 1.6, -1.45); }
}
