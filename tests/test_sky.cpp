// --sky: a dome of emitting patches around the scene, shot like any emitter. Against closed
// forms through `hemirad bake` at default settings: an open floor under a sky of radiance L
// receives π L (a uniform sky) or π L_h + 2π/3 (L_z − L_h) (one graded by the sine of the
// elevation); a floor square under a roof misses the sky the roof hides, π L (1 − F), F the
// form factor from the square's centre to the roof.
#include <catch2/catch.hpp>
#include <cmath>
#include <string>

#include "cli_support.h"
#include "core/error.h"
#include "rect_scenes.h"
#include "scene/sky.h"

namespace {

using namespace hemirad::test;

const json kMaterials = {{{"name", "grey"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}},
                         {{"name", "black"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}}};

// The form factor from a point to a parallel rectangle a × b at height h with one corner straight
// above it (Howell's catalogue, C-11).
double corner_form_factor(double a, double b, double h) {
    const double A = a / h, B = b / h;
    return (A / std::sqrt(1 + A * A) * std::atan(B / std::sqrt(1 + A * A)) +
            B / std::sqrt(1 + B * B) * std::atan(A / std::sqrt(1 + B * B))) /
           (2 * M_PI);
}

}  // namespace

TEST_CASE("an open floor under --sky receives pi times the sky's radiance", "[sky][cli]") {
    TempDir dir;
    write_json(dir / "floor.gltf", rect_scene(dir, {{"floor", -1, 1, -1, 1, 0.0, true, 0}}, kMaterials));
    // No emitter, no light: refused, naming the option that would light it.
    const RunResult dark = run_hemirad(dir, bake_args(dir / "floor.gltf", dir / "dark"));
    CHECK(dark.code == 2);
    CHECK(dark.err.find("--sky RADIANCE[,ZENITH_RADIANCE] adds a sky") != std::string::npos);

    const json uniform = bake_ok(dir, dir / "floor.gltf", dir / "uniform", {"--sky", "2"});
    CHECK(irradiance(uniform, "floor") == Approx(2 * M_PI).epsilon(0.03));
    CHECK(radiosity(uniform, "floor") == Approx(M_PI).epsilon(0.03));
    // The dome is not one of the file's meshes: neither the report nor baked.gltf holds it.
    CHECK(uniform["meshes"].size() == 1);
    CHECK(read_text(dir / "uniform" / "baked.gltf").find("\"sky\"") == std::string::npos);

    const json graded = bake_ok(dir, dir / "floor.gltf", dir / "graded", {"--sky", "0.5,2"});
    CHECK(irradiance(graded, "floor") == Approx(M_PI * 0.5 + 2 * M_PI / 3 * 1.5).epsilon(0.03));
}

TEST_CASE("a roof hides its share of the sky from the floor under it", "[sky][cli]") {
    TempDir dir;
    // A 0.2 m floor square under a black 2 m roof, 0.5 m up and facing down.
    write_json(dir / "roof.gltf", rect_scene(dir, {{"floor", -0.1, 0.1, -0.1, 0.1, 0.0, true, 0},
                                                   {"roof", -1, 1, -1, 1, 0.5, false, 1}},
                                             kMaterials));
    const json report = bake_ok(dir, dir / "roof.gltf", dir / "out", {"--sky", "1"});
    const double F = 4 * corner_form_factor(1.0, 1.0, 0.5);  // from the square's centre
    CHECK(irradiance(report, "floor") == Approx(M_PI * (1 - F)).epsilon(0.05));
}

TEST_CASE("sky radiances that are not numbers >= 0 are refused with one line", "[sky][cli]") {
    for (const std::string bad : {"", "-1", "1,2,3", "x", "1,", "0", "inf", "1,nan"}) {
        INFO("--sky '" << bad << "'");
        CHECK_THROWS_AS(hemirad::scene::parse_sky(bad, "--sky"), hemirad::InputError);
    }
    const hemirad::scene::Sky s = hemirad::scene::parse_sky("0.5,2", "--sky");
    CHECK(s.horizon == 0.5);
    CHECK(s.zenith == 2.0);
}
