// Emitters whose emissive texture changes across a patch shoot from where they glow: a lamp
// lit on one side of a split lights the floor as the lit rectangle alone does, checked against
// the closed form of a differential area under a parallel rectangle and against the same lamp cut
// into a lit and an unlit rectangle.
#include <OpenImageIO/imageio.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <string>

#include "cli_support.h"
#include "mesh/mesh.h"
#include "rect_scenes.h"
#include "scene/scene.h"

namespace {

using namespace hemirad::test;
using glm::dvec3;

constexpr double kPi = 3.14159265358979323846;

// A `width` x 4 RGBA PNG, white for x < lit and black beyond.
void write_split(const fs::path& file, int width, int lit) {
    std::vector<unsigned char> bytes;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < width; ++x) {
            const unsigned char v = x < lit ? 255 : 0;
            bytes.insert(bytes.end(), {v, v, v, 255});
        }
    auto out = OIIO::ImageOutput::create(file.string());
    REQUIRE(out);
    REQUIRE(out->open(file.string(), OIIO::ImageSpec(width, 4, 4, OIIO::TypeDesc::UINT8)));
    REQUIRE(out->write_image(OIIO::TypeDesc::UINT8, bytes.data()));
    REQUIRE(out->close());
}

// Form factor from a differential area to a parallel rectangle a x b at distance c, the area
// under one of its corners (Howell's catalogue C-11). Odd in a and in b, so signed sizes add up.
double corner_ff(double a, double b, double c) {
    const double A = a / c, B = b / c;
    const double sa = std::sqrt(1.0 + A * A), sb = std::sqrt(1.0 + B * B);
    return (A / sa * std::atan(B / sa) + B / sb * std::atan(A / sb)) / (2.0 * kPi);
}

// From a differential area at (x, 0, z) facing up to the rectangle [x0, x1] x [z0, z1] at height h.
double point_ff(double x, double z, double x0, double x1, double z0, double z1, double h) {
    return corner_ff(x1 - x, z1 - z, h) - corner_ff(x0 - x, z1 - z, h) - corner_ff(x1 - x, z0 - z, h) +
           corner_ff(x0 - x, z0 - z, h);
}

// The lamp: 1 x 1 m at y = 1 facing down, u = x, v = z. The floor is probed by 0.1 m squares at
// y = 0 (black: only direct light), centred at z = 0.5 and these x: under the lit part, at the
// split, under the dark part and beyond the lamp.
constexpr double kProbe = 0.1;
const std::vector<double> kProbeX = {-0.25, 0.1, 0.25, 0.37, 0.5, 0.65, 0.9, 1.25};

std::string probe_name(std::size_t i) { return "probe " + std::to_string(i); }

// Mean of E x F over a probe, the lamp lit (E = 1) on x < split: 16 x 16 midpoints (the form
// factor is smooth over 0.1 m at 1 m: the rule's error is far below the tolerance).
double expected_irradiance(double px, double split) {
    double sum = 0.0;
    const int n = 16;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            const double x = px - kProbe / 2 + (i + 0.5) * kProbe / n, z = 0.5 - kProbe / 2 + (j + 0.5) * kProbe / n;
            sum += point_ff(x, z, 0.0, split, 0.0, 1.0, 1.0);
        }
    return sum / (n * n);
}

const json kBlack = {{"name", "black"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}};
const json kGlow = {{"name", "glow"}, {"emissiveFactor", {1.0, 1.0, 1.0}},
                    {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}};

Quad lamp_quad(double x0, double x1, const std::string& name, int material) {
    return {{dvec3(x0, 1, 0), dvec3(x1, 1, 0), dvec3(x1, 1, 1), dvec3(x0, 1, 1)},
            {{x0, 0}, {x1, 0}, {x1, 1}, {x0, 1}}, name, material};
}

std::vector<Quad> probes(int material) {
    std::vector<Quad> out;
    for (std::size_t i = 0; i < kProbeX.size(); ++i) {
        const double x0 = kProbeX[i] - kProbe / 2, x1 = x0 + kProbe, z0 = 0.5 - kProbe / 2, z1 = z0 + kProbe;
        out.push_back({{dvec3(x0, 0, z0), dvec3(x0, 0, z1), dvec3(x1, 0, z1), dvec3(x1, 0, z0)},
                       {{0, 0}, {0, 0}, {0, 0}, {0, 0}}, probe_name(i), material});
    }
    return out;
}

// The lamp of one quad, its emissive texture `width` texels wide and white on the first `lit`.
fs::path textured_lamp(const TempDir& dir, int width, int lit) {
    write_split(dir / "split.png", width, lit);
    json glow = kGlow;
    glow["emissiveTexture"] = {{"index", 0}};
    std::vector<Quad> quads = {lamp_quad(0.0, 1.0, "lamp", 0)};
    for (const Quad& q : probes(1)) quads.push_back(q);
    json g = quad_scene(dir, quads, {glow, kBlack});
    g["samplers"] = {{{"wrapS", 33071}, {"wrapT", 33071}}};
    g["images"] = {{{"uri", "split.png"}}};
    g["textures"] = {{{"source", 0}, {"sampler", 0}}};
    write_json(dir / "textured.gltf", g);
    return dir / "textured.gltf";
}

// The same lamp cut in two: a lit rectangle of plain emission 1 and an unlit one.
fs::path cut_lamp(const TempDir& dir, double split) {
    std::vector<Quad> quads = {lamp_quad(0.0, split, "lamp lit", 0), lamp_quad(split, 1.0, "lamp dark", 1)};
    for (const Quad& q : probes(1)) quads.push_back(q);
    write_json(dir / "cut.gltf", quad_scene(dir, quads, {kGlow, kBlack}));
    return dir / "cut.gltf";
}

// Checks each probe's irradiance in the textured bake against the closed form and (with `cut`)
// against the cut lamp's bake, each within 1%.
void check_split(int width, int lit, const std::vector<std::string>& extra, bool cut = true) {
    const double split = double(lit) / width;
    TempDir dir, cut_dir;  // each scene's buffer is scene.bin in its folder
    const json textured = bake_ok(dir, textured_lamp(dir, width, lit), dir / "textured", extra);
    json reference;
    if (cut) reference = bake_ok(cut_dir, cut_lamp(cut_dir, split), cut_dir / "cut", extra);
    CHECK(textured["counts"]["emission_unsplit"].get<long>() == 0);
    for (std::size_t i = 0; i < kProbeX.size(); ++i) {
        const double expected = expected_irradiance(kProbeX[i], split);
        const double got = irradiance(textured, probe_name(i));
        INFO("split " << split << ", probe at x = " << kProbeX[i] << ": closed form " << expected << ", textured "
                      << got << " (" << 100.0 * (got / expected - 1.0) << "%)");
        CHECK(got == Approx(expected).epsilon(0.01));
        if (cut) CHECK(got == Approx(irradiance(reference, probe_name(i))).epsilon(0.01));
    }
}

const std::vector<std::string> kQuick = {"--image-width", "32", "--quiet"};
// Patches of 0.5 m: the split at 0.37 crosses the lamp's first column of patches, the floor 1 m
// below. Whole, those patches put the light up to 17% off; split into their elements, within 1%.
const std::vector<std::string> kCoarse = {"--patch-size", "0.5", "--element-size", "0.125", "--image-width", "32",
                                          "--quiet"};

}  // namespace

TEST_CASE("a lamp lit on one side of a split across its patches lights the floor as its lit part alone",
          "[emission_atlas][textures]") {
    SECTION("split at 0.37 of the width, off the patch grid") { check_split(100, 37, kQuick); }
    SECTION("split at 0.5") { check_split(64, 32, kQuick); }
    SECTION("coarse patches, split at 0.37") { check_split(100, 37, kCoarse); }
    SECTION("coarse patches, split at 0.5 (on the patch grid)") { check_split(64, 32, kCoarse); }
    SECTION("the matrix solver, coarse patches") { check_split(100, 37, concat(kCoarse, {"--solver", "matrix"})); }
    // The hemicube, though nothing occludes: against the closed form only (the cut lamp's own
    // hemicube bake is up to 26% off under its unlit half at these patch sizes, split or not).
    SECTION("the hemicube, coarse patches") {
        check_split(100, 37, concat(kCoarse, {"--effects", "occlusion=on"}), /*cut=*/false);
    }
}

TEST_CASE("emitter patches follow their emission: each shoots a near-uniform emission", "[emission_atlas][mesh]") {
    TempDir dir;
    const hemirad::scene::Scene scene = hemirad::scene::load(textured_lamp(dir, 100, 37));
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(scene, {0.25, 0.125});
    CHECK(mesh.emission_splits > 0);
    CHECK(mesh.emission_unsplit == 0);
    double flux = 0.0, patch_flux = 0.0;
    for (std::size_t p = 0; p < mesh.patches.size(); ++p) {
        const hemirad::mesh::Patch& patch = mesh.patches[p];
        if (patch.node != 0) continue;
        patch_flux += patch.area * patch.emission.x;
        double lo = HUGE_VAL, hi = 0.0;
        for (std::uint32_t k = patch.first_element; k < patch.first_element + patch.element_count; ++k) {
            const hemirad::mesh::Element& e = mesh.elements[k];
            CHECK(e.patch == p);
            flux += e.area * e.emission.x;
            lo = std::min(lo, e.emission.x);
            hi = std::max(hi, e.emission.x);
        }
        CHECK(hi - lo <= 0.02 * hi);
        // A patch made of one element is that element: it shoots from its centroid.
        if (patch.element_count == 1) {
            const hemirad::mesh::Element& e = mesh.elements[patch.first_element];
            CHECK(glm::length(patch.centroid - e.centroid) < 1e-12);
            CHECK(patch.area == Approx(e.area).epsilon(1e-12));
        }
    }
    // The lit share of 1 m²: texel 36 ends at u = 0.37 (elements along the split are 1.6 texels wide).
    CHECK(flux == Approx(0.37).epsilon(0.005));
    CHECK(patch_flux == Approx(flux).epsilon(1e-12));

    // A lamp without texture is not split at all.
    const hemirad::scene::Scene plain = hemirad::scene::load(cut_lamp(dir, 0.37));
    const hemirad::mesh::Mesh plain_mesh = hemirad::mesh::build(plain, {0.25, 0.125});
    CHECK(plain_mesh.emission_splits == 0);
}

TEST_CASE("a large emissive atlas adds a bounded number of shooters and says how many it left whole",
          "[emission_atlas][mesh]") {
    TempDir dir;
    // A 256-texel-wide checkerboard of 2-texel squares, over a lamp of fine patches: every patch
    // has elements of different emission.
    std::vector<unsigned char> bytes;
    for (int y = 0; y < 256; ++y)
        for (int x = 0; x < 256; ++x) {
            const unsigned char v = ((x / 2 + y / 2) % 2) ? 255 : 0;
            bytes.insert(bytes.end(), {v, v, v, 255});
        }
    auto out = OIIO::ImageOutput::create((dir / "checker.png").string());
    REQUIRE(out);
    REQUIRE(out->open((dir / "checker.png").string(), OIIO::ImageSpec(256, 256, 4, OIIO::TypeDesc::UINT8)));
    REQUIRE(out->write_image(OIIO::TypeDesc::UINT8, bytes.data()));
    REQUIRE(out->close());
    json glow = kGlow;
    glow["emissiveTexture"] = {{"index", 0}};
    json g = quad_scene(dir, {lamp_quad(0.0, 1.0, "lamp", 0)}, json::array({glow}));
    g["images"] = {{{"uri", "checker.png"}}};
    g["textures"] = {{{"source", 0}}};
    write_json(dir / "checker.gltf", g);
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "checker.gltf");
    std::size_t counted = 0;
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(
        scene, {0.02, 0.01}, [&](const hemirad::mesh::Counts& c) { counted = std::size_t(c.patches); });
    CHECK(counted == 2500);
    CHECK(mesh.emission_splits > 0);
    CHECK(mesh.emission_unsplit > 0);
    CHECK(double(mesh.patches.size()) <= counted + hemirad::mesh::kMaxEmissionShooters + counted / 16.0);

    // Through a bake: the cap is a warning in report.json.
    const json report = bake_ok(dir, dir / "checker.gltf", dir / "out",
                                {"--patch-size", "0.02", "--element-size", "0.01", "--max-passes", "50",
                                 "--image-width", "16", "--quiet"});
    CHECK(report["counts"]["emission_unsplit"].get<long>() > 0);
    bool warned = false;
    for (const json& w : report["warnings"]) warned = warned || w.get<std::string>().find("shoot from their centres") != std::string::npos;
    CHECK(warned);
}
