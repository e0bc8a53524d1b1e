// KHR_lights_punctual point and spot lights through `hemirad bake` at default settings, against
// closed forms: a light of I candela gives a floor rectangle the mean irradiance I Ω / A, Ω the
// solid angle the rectangle subtends (I cos³θ / h² at a point); a spot light scales it by the
// extension's cone falloff; an occluder leaves its shadow dark.
#include <catch2/catch.hpp>
#include <cmath>
#include <string>

#include "cli_support.h"
#include "formfactor/reference.h"
#include "formfactor/unoccluded.h"
#include "scene/builder.h"
#include "mesh/mesh.h"
#include "scene/scene.h"
#include "solve/lights.h"
#include "rect_scenes.h"
#include "test_scenes.h"

namespace {

using namespace hemirad::test;
using glm::dvec3;

const json kMaterials = {{{"name", "floor"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}},
                         {{"name", "black"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}}};

// The solid angle of the rectangle [0, a] × [0, b] seen from height h above its corner (0, 0).
double corner_omega(double a, double b, double h) {
    if (a == 0.0 || b == 0.0) return 0.0;
    const double s = (a > 0) == (b > 0) ? 1.0 : -1.0;
    return s * std::atan(std::abs(a * b) / (h * std::sqrt(a * a + b * b + h * h)));
}
// ... of [x0, x1] × [z0, z1] from height h above the origin (inclusion-exclusion of corners).
double rect_omega(double x0, double x1, double z0, double z1, double h) {
    return corner_omega(x1, z1, h) - corner_omega(x0, z1, h) - corner_omega(x1, z0, h) + corner_omega(x0, z0, h);
}

// Floor squares 0.2 m a side at y = 0: under the light, at 45° beside it, and one an occluder
// (a black 0.4 m square at y = 0.5) shades from a light 1 m up.
std::vector<Rect> floor_squares() {
    return {{"centre", -0.1, 0.1, -0.1, 0.1, 0.0, true, 0},
            {"beside", 0.9, 1.1, -0.1, 0.1, 0.0, true, 0},
            {"shaded", -1.1, -0.9, -0.1, 0.1, 0.0, true, 0},
            {"occluder", -0.7, -0.3, -0.2, 0.2, 0.5, false, 1}};
}

}  // namespace

TEST_CASE("a point light of I candela gives each floor square I times its solid angle over its area", "[lights]") {
    TempDir dir;
    const json lights = {{{"type", "point"}, {"intensity", 10.0}, {"color", {1.0, 0.8, 0.6}}, {"name", "bulb"}}};
    const json nodes = {{{"name", "bulb"}, {"translation", {0, 1, 0}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}};
    write_json(dir / "point.gltf", rect_scene(dir, floor_squares(), kMaterials, lights, nodes));

    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "point.gltf");
    REQUIRE(scene.lights.size() == 1);
    CHECK(scene.lights[0].position == dvec3(0, 1, 0));
    CHECK(scene.lights[0].intensity == dvec3(10.0, 8.0, 6.0));

    for (const std::string solver : {"progressive", "matrix"}) {
        DYNAMIC_SECTION(solver) {
            const json report = bake_ok(dir, dir / "point.gltf", dir / solver, {"--solver", solver});
            const double I = 10.0;
            CHECK(irradiance(report, "centre") == Approx(I * rect_omega(-0.1, 0.1, -0.1, 0.1, 1.0) / 0.04).epsilon(0.02));
            CHECK(irradiance(report, "beside") == Approx(I * rect_omega(0.9, 1.1, -0.1, 0.1, 1.0) / 0.04).epsilon(0.02));
            // I cos³θ / h² at the squares' centres, to the squares' curvature of the field.
            CHECK(irradiance(report, "centre") == Approx(I).epsilon(0.03));
            CHECK(irradiance(report, "beside") == Approx(I * std::pow(std::sqrt(0.5), 3)).epsilon(0.03));
            CHECK(irradiance(report, "shaded") < 1e-3 * I);
            // Its colour, and the floor's reflectance 0.5.
            const json& centre = mesh_named(report, "centre");
            CHECK(centre["irradiance"][2].get<double>() / centre["irradiance"][0].get<double>() == Approx(0.6));
            CHECK(centre["radiosity"][0].get<double>() == Approx(0.5 * centre["irradiance"][0].get<double>()));
        }
    }
}

TEST_CASE("a spot light's cone falls off as the extension defines, placed and aimed by its node", "[lights]") {
    TempDir dir;
    // Aimed straight down by a rotation of -90° about x (its light shines along the node's -Z).
    const double inner = 0.3, outer = 0.5;
    const json lights = {{{"type", "spot"}, {"intensity", 20.0}, {"spot", {{"innerConeAngle", inner}, {"outerConeAngle", outer}}}}};
    const json nodes = {{{"name", "spot"}, {"translation", {0, 1, 0}},
                         {"rotation", {-std::sqrt(0.5), 0, 0, std::sqrt(0.5)}},
                         {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}};
    // A small square at 0.4 rad from the axis, between the cones.
    const double x = std::tan(0.4);
    std::vector<Rect> rects = floor_squares();
    rects.push_back({"rim", x - 0.02, x + 0.02, -0.02, 0.02, 0.0, true, 0});
    write_json(dir / "spot.gltf", rect_scene(dir, rects, kMaterials, lights, nodes));
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "spot.gltf");
    REQUIRE(scene.lights.size() == 1);
    CHECK(scene.lights[0].direction.y == Approx(-1.0));

    const json report = bake_ok(dir, dir / "spot.gltf", dir / "out", {});
    const double I = 20.0;
    CHECK(irradiance(report, "centre") == Approx(I * rect_omega(-0.1, 0.1, -0.1, 0.1, 1.0) / 0.04).epsilon(0.02));
    CHECK(irradiance(report, "beside") == 0.0);  // 45°: outside the outer cone
    const double t = (std::cos(0.4) - std::cos(outer)) / (std::cos(inner) - std::cos(outer));
    CHECK(irradiance(report, "rim") == Approx(I * t * t * std::pow(std::cos(0.4), 3)).epsilon(0.05));
}

TEST_CASE("a light's hemicubes give every engine the same solid angles, and the exact ones to the hemicube's error",
          "[lights]") {
    // Two facing squares around a point light, one above and one below: its two hemicubes.
    hemirad::scene::Scene s;
    const std::uint32_t grey = hemirad::scene::add_material(s, dvec3(0.5), dvec3(0.0));
    hemirad::scene::add_quad(s, {-1, -1, -1}, {-1, -1, 1}, {1, -1, 1}, {1, -1, -1}, grey, "below");  // faces up
    hemirad::scene::add_quad(s, {-1, 1, -1}, {1, 1, -1}, {1, 1, 1}, {-1, 1, 1}, grey, "above");      // faces down
    hemirad::scene::PunctualLight light;
    light.position = dvec3(0.1, 0.2, -0.1);
    s.lights.push_back(light);
    hemirad::scene::finish(s);
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(s, {0.5, 0.25});
    REQUIRE(mesh.lights.size() == 2);
    hemirad::formfactor::ReferenceEngine ref(mesh, {256, 1});
    hemirad::formfactor::UnoccludedEngine exact(mesh);
    for (std::uint32_t l = 0; l < 2; ++l) {
        hemirad::formfactor::ShotResult a, b;
        ref.shoot(hemirad::formfactor::ShotRequest::of_light(l, 7), a);
        exact.shoot(hemirad::formfactor::ShotRequest::of_light(l, 7), b);
        // The hemicube's half: its solid angles are a half-space, 2π over 4π.
        CHECK(b.sum() == Approx(a.sum()).epsilon(0.01));
        const std::vector<double> da = a.dense(mesh.elements.size()), db = b.dense(mesh.elements.size());
        for (std::size_t k = 0; k < da.size(); ++k) CHECK(da[k] == Approx(db[k]).epsilon(0.05).margin(1e-4));
    }
}

TEST_CASE("malformed punctual lights are refused with one line naming the light", "[lights][cli]") {
    TempDir dir;
    const auto refused = [&](const json& light, const std::string& problem) {
        const json nodes = {{{"name", "l"}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}};
        write_json(dir / "bad.gltf", rect_scene(dir, floor_squares(), kMaterials, json::array({light}), nodes));
        const std::string message = load_error(dir / "bad.gltf");
        INFO(message);
        CHECK(message.find(problem) != std::string::npos);
    };
    refused({{"type", "area"}}, "light 0: type 'area' is not point, spot or directional");
    refused({{"type", "point"}, {"intensity", -1.0}}, "intensity -1 must be finite and >= 0");
    refused({{"type", "spot"}, {"spot", {{"innerConeAngle", 0.6}, {"outerConeAngle", 0.5}}}},
            "cone angles inner 0.6 and outer 0.5");
    refused({{"type", "point"}, {"color", {1.0, 2.0, 0.5}}}, "color component 1 is 2, outside [0, 1]");
}
