// Directional lights (KHR_lights_punctual "directional", and --sun): a parallel shot across the
// light's direction. Against closed forms: a surface facing a light of E lux at angle θ receives
// E cos θ; the shadow of an opaque square is the square moved along the light's direction, so a
// floor square inside it receives nothing and one half inside it half.
#include <catch2/catch.hpp>
#include <cmath>
#include <string>

#include <glm/gtc/quaternion.hpp>

#include "backends.h"
#include "cli_support.h"
#include "cl/runtime.h"
#include "formfactor/parallel.h"
#include "formfactor/parallel_opencl.h"
#include "mesh/mesh.h"
#include "rect_scenes.h"
#include "scene/builder.h"
#include "scene/scene.h"
#include "scene/sky.h"

namespace {

using namespace hemirad::test;
using glm::dvec3;

const json kMaterials = {{{"name", "grey"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}},
                         {{"name", "black"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}}};

constexpr double kTheta = M_PI / 6.0;  // the light's angle from the vertical: it travels along (sin θ, −cos θ, 0)

// A black square facing down at y = 0.5 over x ∈ [−0.7, −0.3], z ∈ [−0.2, 0.2]: its shadow on the
// floor lies 0.5 tan θ further along x, over x ∈ [−0.411, −0.011]. Floor squares: one in full
// light, one in the shadow, one with the shadow's edge (z = 0.2) through its middle.
std::vector<Rect> shadow_scene() {
    return {{"lit", 0.9, 1.1, -0.1, 0.1, 0.0, true, 0},
            {"shaded", -0.35, -0.15, -0.1, 0.1, 0.0, true, 0},
            {"half", -0.35, -0.15, 0.1, 0.3, 0.0, true, 0},
            {"occluder", -0.7, -0.3, -0.2, 0.2, 0.5, false, 1}};
}

void check_sun(const json& report, double E) {
    CHECK(irradiance(report, "lit") == Approx(E * std::cos(kTheta)).epsilon(0.01));
    CHECK(irradiance(report, "shaded") < 1e-3 * E);
    CHECK(irradiance(report, "half") == Approx(0.5 * E * std::cos(kTheta)).epsilon(0.02));
    CHECK(radiosity(report, "lit") == Approx(0.5 * irradiance(report, "lit")));
}

// A one-sided UV sphere of radius 1 (64 × 32 faces, node "ball") 1.2 m above an 8 m floor.
hemirad::scene::Scene ball_over_floor() {
    hemirad::scene::Scene s;
    const std::uint32_t grey = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0));
    hemirad::scene::add_quad(s, {-4, 0, -4}, {-4, 0, 4}, {4, 0, 4}, {4, 0, -4}, grey, "floor");
    s.nodes.push_back({"ball", 1});
    const int segments = 64, rings = 32;
    const dvec3 centre(0, 1.2, 0);
    const auto at = [&](int ring, int segment) {
        const double polar = M_PI * ring / rings, azimuth = 2 * M_PI * segment / segments;
        return centre + dvec3(std::sin(polar) * std::cos(azimuth), std::cos(polar), std::sin(polar) * std::sin(azimuth));
    };
    for (int r = 0; r < rings; ++r)
        for (int g = 0; g < segments; ++g) {
            const dvec3 a = at(r, g), b = at(r, g + 1), c = at(r + 1, g + 1), d = at(r + 1, g);
            // Counter-clockwise seen from outside.
            if (r > 0) s.triangles.push_back({{a, b, c}, {dvec3(0.5), dvec3(0.5), dvec3(0.5)}, grey, 1, 1});
            if (r < rings - 1) s.triangles.push_back({{a, c, d}, {dvec3(0.5), dvec3(0.5), dvec3(0.5)}, grey, 1, 1});
        }
    hemirad::scene::finish(s);
    return s;
}

}  // namespace

TEST_CASE("a directional light of E lux gives a floor E cos(theta), and the occluder's shadow nothing", "[sun][cli]") {
    TempDir dir;
    // Shining along the node's −Z: turned to straight down (−90° about x), then θ about z.
    const glm::dquat q = glm::angleAxis(kTheta, dvec3(0, 0, 1)) * glm::angleAxis(-M_PI / 2, dvec3(1, 0, 0));
    const json lights = {{{"type", "directional"}, {"intensity", 3.0}, {"name", "sun"}}};
    const json nodes = {{{"name", "sun"}, {"translation", {5, 5, 5}}, {"rotation", {q.x, q.y, q.z, q.w}},
                         {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}};
    json g = rect_scene(dir, shadow_scene(), kMaterials, lights, nodes);
    g["extensionsRequired"] = {"KHR_lights_punctual"};  // read: no warning that it is not
    write_json(dir / "sun.gltf", g);
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "sun.gltf");
    REQUIRE(scene.lights.size() == 1);
    CHECK(scene.lights[0].direction.x == Approx(std::sin(kTheta)));
    CHECK(scene.lights[0].direction.y == Approx(-std::cos(kTheta)));
    for (const std::string solver : {"progressive", "matrix"}) {
        DYNAMIC_SECTION(solver) {
            const json report = bake_ok(dir, dir / "sun.gltf", dir / solver, {"--solver", solver});
            for (const json& w : report["warnings"]) {
                CHECK(w.get<std::string>().find("directional") == std::string::npos);
                CHECK(w.get<std::string>().find("not supported") == std::string::npos);
            }
            check_sun(report, 3.0);
        }
    }
}

TEST_CASE("the --sun AZIMUTH,ELEVATION,LUX option lights a scene that has no light, from the compass direction it names",
          "[sun][cli]") {
    TempDir dir;
    write_json(dir / "floor.gltf", rect_scene(dir, shadow_scene(), kMaterials));
    // West (azimuth 270°, −X) at 60° above the horizon: its light travels towards +X and down, at 30°
    // from the vertical, as above.
    const json report = bake_ok(dir, dir / "floor.gltf", dir / "out", {"--sun", "270,60,2.5"});
    check_sun(report, 2.5);

    // North (−Z) at 90°: straight down, the shadow right under the occluder.
    const hemirad::scene::PunctualLight noon = hemirad::scene::parse_sun("0,90,1", "--sun");
    CHECK(noon.direction.y == Approx(-1.0));
    const hemirad::scene::PunctualLight north = hemirad::scene::parse_sun("0,45,1", "--sun");
    CHECK(north.direction.z == Approx(std::sqrt(0.5)));  // it shines from −Z towards +Z
    const hemirad::scene::PunctualLight east = hemirad::scene::parse_sun("90,45,1", "--sun");
    CHECK(east.direction.x == Approx(-std::sqrt(0.5)));

    for (const std::string bad : {"90,0,1", "90,-5,1", "90,91,1", "0,45,0", "0,45,-1", "0,45", "0,45,1,2", "a,45,1",
                                  "0,45,1,", "0,nan,1", "0,45,1e300"}) {
        DYNAMIC_SECTION("--sun " << bad) {
            const RunResult r = run_hemirad(dir, bake_args(dir / "floor.gltf", dir / "bad", {"--sun", bad}));
            INFO(r.err);
            CHECK(r.code == 2);
            CHECK(r.err.find("--sun '" + bad + "'") != std::string::npos);
            CHECK(!fs::exists(dir / "bad"));
        }
    }
}

TEST_CASE("a parallel shot gives each element cos(theta) times its lit share, on any number of threads", "[sun]") {
    // A floor of 2 × 2 m, a one-sided square of 1 × 1 m facing down 1 m above it (its back blocks),
    // and a double-sided square of 0.5 × 0.5 m facing up beside it (its front receives, its back
    // is its twin's front and does not block).
    hemirad::scene::Scene s;
    const std::uint32_t grey = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0));
    const std::uint32_t twin = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0), /*double_sided=*/true);
    hemirad::scene::add_quad(s, {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, grey, "floor");
    hemirad::scene::add_quad(s, {-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}, grey, "roof");
    hemirad::scene::add_quad(s, {2, 1, 0}, {2, 1, 0.5}, {2.5, 1, 0.5}, {2.5, 1, 0}, twin, "card");
    hemirad::scene::finish(s);
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(s, {0.25, 0.125});
    const auto node_sum = [&](const hemirad::formfactor::ShotResult& row, const std::string& name) {
        double lit = 0.0, area = 0.0;
        for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
            const hemirad::mesh::Element& e = mesh.elements[k];
            if (s.nodes[e.node].name != name || e.back) continue;
            area += e.area;
        }
        for (std::size_t i = 0; i < row.size(); ++i) {
            const hemirad::mesh::Element& e = mesh.elements[row.element[i]];
            if (s.nodes[e.node].name == name && !e.back) lit += row.F[i] * e.area;
        }
        return lit / area;
    };
    for (const double theta : {0.0, 0.3, 0.4}) {
        DYNAMIC_SECTION("theta " << theta) {
            const dvec3 d(std::sin(theta), -std::cos(theta), 0.0);
            hemirad::formfactor::ShotResult one, two;
            hemirad::formfactor::shoot_parallel(mesh, d, 3, one, {1.0 / 16.0, 8192, 1});
            hemirad::formfactor::shoot_parallel(mesh, d, 3, two, {1.0 / 16.0, 8192, 2});
            CHECK(one == two);
            // The roof's shadow, the unit square moved by tan θ < 0.5 along x, lies wholly on the
            // floor: the floor's lit share is (4 − 1) / 4.
            CHECK(node_sum(one, "floor") == Approx(0.75 * std::cos(theta)).epsilon(0.002));
            CHECK(node_sum(one, "card") == Approx(std::cos(theta)).epsilon(0.002));
            CHECK(node_sum(one, "roof") == 0.0);  // its back faces the light
            CHECK(one.blocked == Approx(std::cos(theta)).epsilon(0.002));  // the roof's projected area
            // No element receives more than the full light.
            for (const double f : one.F) CHECK(f <= std::cos(theta) + 1e-12);
        }
    }
}

TEST_CASE("the bundled atrium takes in the sun's flux through its roof's opening, E cos(theta) times its area",
          "[sun][cli]") {
    // 10 lux at 60° elevation through a 2 m × 2 m horizontal opening: 40 cos 30° lumens, all of it
    // landing on the floor, the north wall and the block (scenes/README.md).
    TempDir dir;
    const double flux = 40.0 * std::cos(M_PI / 6.0);
    const fs::path atrium = kSourceDir / "scenes" / "atrium.gltf";
    const json report = bake_ok(dir, atrium, dir / "out", {});
    const json& energy = report["energy"];
    CHECK(energy["emitted"].get<double>() == Approx(flux).epsilon(1e-3));
    CHECK(energy["absorbed"].get<double>() + energy["escaped"].get<double>() + energy["unshot"].get<double>() ==
          Approx(flux).epsilon(1e-3));
    CHECK(energy["escaped"].get<double>() > 0.0);  // some of the reflected light leaves through the opening

    // Direct light only: the irradiance of each mesh, summed over its area, is the flux landed.
    const json direct = bake_ok(dir, atrium, dir / "direct", {"--effects", "interreflection=off"});
    double landed = 0.0;
    for (const json& m : direct["meshes"]) {
        landed += m["irradiance"][0].get<double>() * m["area"].get<double>();
        if (m["name"] == "roof") CHECK(m["irradiance"][0].get<double>() == 0.0);  // its back faces the sun
    }
    CHECK(landed == Approx(flux).epsilon(1e-3));
}

TEST_CASE("a sun on a tessellated ball lights each front element by exactly cos(theta) and shades the floor by its outline",
          "[sun]") {
    // A one-sided UV sphere of radius 1 (64 × 32) 1.2 m above an 8 m floor. The ball is convex: no
    // front element can shade another, so each gets cos θ exactly, whether it holds cell centres
    // or (with cells twice the median element) is lit by its centroid's test against its
    // neighbours' planes, which must not shade a curved surface by itself. The floor loses the
    // ball's outline: E (A cos θ − P), P the sum over the ball's front elements of cos θ A.
    const hemirad::scene::Scene s = ball_over_floor();
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(s, {0.5, 0.25});
    const double theta = 0.5;
    const dvec3 d(std::sin(theta), -std::cos(theta), 0.0);
    for (const double cell : {1.0 / 16.0, 2.0}) {
        DYNAMIC_SECTION("cells of " << cell << " of the median element") {
            hemirad::formfactor::ShotResult row;
            hemirad::formfactor::shoot_parallel(mesh, d, 1, row, {cell, 4096, 0});
            const std::vector<double> F = row.dense(mesh.elements.size());
            double outline = 0.0, floor_lit = 0.0, floor_area = 0.0;
            std::size_t front = 0;
            for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
                const hemirad::mesh::Element& e = mesh.elements[k];
                const double cos_theta = -glm::dot(e.normal, d);
                if (e.node == 1) {
                    if (cos_theta > 0.0) {
                        ++front;
                        outline += cos_theta * e.area;
                        INFO("ball element " << k << " at " << e.centroid.x << ", " << e.centroid.y << ", " << e.centroid.z);
                        CHECK(F[k] == Approx(cos_theta).epsilon(1e-12));
                    } else {
                        CHECK(F[k] == 0.0);
                    }
                } else {
                    floor_lit += F[k] * e.area;
                    floor_area += e.area;
                }
            }
            CHECK(front > 1000);
            CHECK(outline == Approx(M_PI).epsilon(0.01));  // the polyhedron's outline, a little inside the circle's
            CHECK(floor_lit == Approx(floor_area * std::cos(theta) - outline).epsilon(0.005));
        }
    }
}

TEST_CASE("a parallel shot on every OpenCL device gives the host's owner for every cell, and the same rows",
          "[sun][opencl]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    const auto devices = hemirad::ocl::list_devices();
    // The ball over its floor, and a floor under a one-sided roof and beside a double-sided card,
    // at several angles and turns of the grid, with cells finer and coarser than the elements.
    hemirad::scene::Scene shadow;
    const std::uint32_t grey = hemirad::scene::add_material(shadow, dvec3(0.5), dvec3(0.0));
    const std::uint32_t twin = hemirad::scene::add_material(shadow, dvec3(0.5), dvec3(0.0), /*double_sided=*/true);
    hemirad::scene::add_quad(shadow, {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, grey, "floor");
    hemirad::scene::add_quad(shadow, {-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}, grey, "roof");
    hemirad::scene::add_quad(shadow, {2, 1, 0}, {2, 1, 0.5}, {2.5, 1, 0.5}, {2.5, 1, 0}, twin, "card");
    hemirad::scene::finish(shadow);
    const hemirad::scene::Scene ball = ball_over_floor();
    const std::vector<hemirad::mesh::Mesh> meshes = {hemirad::mesh::build(shadow, {0.25, 0.125}),
                                                     hemirad::mesh::build(ball, {0.5, 0.25})};
    for (const hemirad::ocl::DeviceInfo& info : devices) {
        if (!info.fp64) continue;
        hemirad::ocl::Context context(info);
        hemirad::formfactor::OpenCLParallelRaster device(context);
        hemirad::formfactor::VerifyingParallelRaster checked(device);
        for (std::size_t m = 0; m < meshes.size(); ++m)
            for (const double theta : {0.0, 0.4, 1.2})
                for (const double cell : {1.0 / 16.0, 2.0}) {
                    INFO(info.name << ", mesh " << m << ", theta " << theta << ", cell " << cell);
                    const dvec3 d(std::sin(theta) * 0.8, -std::cos(theta), std::sin(theta) * 0.6);
                    hemirad::formfactor::ShotResult host, on_device;
                    hemirad::formfactor::shoot_parallel(meshes[m], d, 5, host, {cell, 4096, 0});
                    // The checked raster throws (VerifyError) at the first cell or count that differs.
                    hemirad::formfactor::shoot_parallel(meshes[m], d, 5, on_device, {cell, 4096, 0}, &checked);
                    CHECK(host == on_device);
                    CHECK(host.size() > 0);
                }
        CHECK(checked.cells_compared() > 100000);
    }
}

TEST_CASE("a sunlit bake gives the same bytes on the reference and on OpenCL, and passes its verification",
          "[sun][opencl][cli]") {
    HEMIRAD_SKIP_ABSENT(hemirad::test::first_opencl());
    TempDir dir;
    const fs::path atrium = kSourceDir / "scenes" / "atrium.gltf";
    const std::vector<std::string> draft = {"--quality", "draft"};
    auto with = [&](std::vector<std::string> extra) {
        extra.insert(extra.end(), draft.begin(), draft.end());
        return extra;
    };
    bake_ok(dir, atrium, dir / "ref", with({"--device", "ref"}));
    const json verified = bake_ok(dir, atrium, dir / "cl", with({"--device", "opencl", "--verify"}));
    CHECK(read_text(dir / "ref" / "baked.bin") == read_text(dir / "cl" / "baked.bin"));
    CHECK(verified["device"]["backend"] == "opencl");
}

TEST_CASE("a sunlit bake counts its parallel shots' memory in its estimate", "[sun][cli]") {
    // Under 100 MB the atrium is refused, and the refusal lists the estimate's parts.
    TempDir dir;
    const fs::path atrium = kSourceDir / "scenes" / "atrium.gltf";
    const RunResult r = run_hemirad(dir, bake_args(atrium, dir / "out", {"--max-memory", "100M", "--device", "ref"}));
    INFO(r.err);
    CHECK(r.code == 2);
    CHECK(r.err.find("parallel shots") != std::string::npos);
    CHECK(!fs::exists(dir / "out"));
    // Without the sun (the lit room: point and spot lights) there is no such part.
    const RunResult lit = run_hemirad(dir, bake_args(kSourceDir / "scenes" / "lit_room.gltf", dir / "lit",
                                                     {"--max-memory", "100M", "--device", "ref"}));
    CHECK(lit.err.find("parallel shots") == std::string::npos);
}
