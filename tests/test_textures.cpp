// Textures per element: base colour, emission and alphaMode MASK coverage averaged over each
// element through its texture coordinates, KHR_texture_transform and the sampler's wrap modes,
// in linear light. Checked against closed forms through `hemirad bake` at default settings
// (parallel rectangles under a half-lit panel) and, on the mesh, against the textures' own
// areas.
#include <OpenImageIO/imageio.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <string>

#include "cli_support.h"
#include "core/colour.h"
#include "mesh/mesh.h"
#include "mesh/refine.h"
#include "mesh/texturing.h"
#include "scene/scene.h"
#include "solve/final_gather.h"
#include "rect_scenes.h"
#include "test_scenes.h"

namespace {

using namespace hemirad::test;
using glm::dvec3;

// Writes a `width` x `height` RGBA 8-bit PNG whose texel (x, y) is texel(x, y).
template <class Texel>
void write_png(const fs::path& file, int width, int height, Texel texel) {
    std::vector<unsigned char> bytes;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const std::array<unsigned char, 4> t = texel(x, y);
            bytes.insert(bytes.end(), t.begin(), t.end());
        }
    auto out = OIIO::ImageOutput::create(file.string());
    REQUIRE(out);
    REQUIRE(out->open(file.string(), OIIO::ImageSpec(width, height, 4, OIIO::TypeDesc::UINT8)));
    REQUIRE(out->write_image(OIIO::TypeDesc::UINT8, bytes.data()));
    REQUIRE(out->close());
}

// The left half of the image (x < width / 2) is `left`, the right half `right`.
// A 64 x 64 colour ramp: red rising along x, green along y (texel (x, y) = 4x, 4y, 128).
void write_ramp(const fs::path& file) {
    write_png(file, 64, 64, [](int x, int y) -> std::array<unsigned char, 4> {
        return {static_cast<unsigned char>(4 * x), static_cast<unsigned char>(4 * y), 128, 255};
    });
}

void write_halves(const fs::path& file, std::array<unsigned char, 4> left, std::array<unsigned char, 4> right) {
    write_png(file, 64, 4, [&](int x, int) { return x < 32 ? left : right; });
}

// A 2 x 1 m panel at y = 1 facing down (u = x / 2, v = z), and under it the floor's two 1 x 1 m
// halves at y = 0 facing up ("floor left", x in [0, 1], and "floor right", their u the panel's),
// then any extra quads: a glTF with its buffer in `dir`.
json panel_over_floor(const TempDir& dir, const json& panel, const json& floor, const std::vector<Quad>& extra = {},
                      const std::vector<json>& extra_materials = {}) {
    std::vector<Quad> quads = {
        {{dvec3(0, 1, 0), dvec3(2, 1, 0), dvec3(2, 1, 1), dvec3(0, 1, 1)}, {{0, 0}, {1, 0}, {1, 1}, {0, 1}}, "panel", 0},
        {{dvec3(0, 0, 0), dvec3(0, 0, 1), dvec3(1, 0, 1), dvec3(1, 0, 0)}, {{0, 0}, {0, 1}, {0.5, 1}, {0.5, 0}},
         "floor left", 1},
        {{dvec3(1, 0, 0), dvec3(1, 0, 1), dvec3(2, 0, 1), dvec3(2, 0, 0)}, {{0.5, 0}, {0.5, 1}, {1, 1}, {1, 0}},
         "floor right", 1},
    };
    quads.insert(quads.end(), extra.begin(), extra.end());
    json materials = {panel, floor};
    for (const json& m : extra_materials) materials.push_back(m);
    return quad_scene(dir, quads, materials);
}

const json kBlack = {{"name", "black"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}};
const json kGrey = {{"name", "grey"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}};
const json kGlow = {{"name", "glow"}, {"emissiveFactor", {1.0, 1.0, 1.0}},
                    {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}};

// The textures' images and samplers: image i is `images[i]`; texture i reads image i through
// sampler 0 (clamped: a half-lit texture must not bleed across its far edge) .
void add_textures(json& g, const std::vector<std::string>& images) {
    g["samplers"] = {{{"wrapS", 33071}, {"wrapT", 33071}}};
    g["images"] = json::array();
    g["textures"] = json::array();
    for (std::size_t i = 0; i < images.size(); ++i) {
        g["images"].push_back({{"uri", images[i]}});
        g["textures"].push_back({{"source", i}, {"sampler", 0}});
    }
}

// Form factors from a floor half to the panel above it (1 m up): the half straight below, and the
// other half beside it (the whole panel's, less the one straight below, by symmetry).
const double kBelow = parallel_rectangles_ff(1.0, 1.0, 1.0);
const double kBeside = parallel_rectangles_ff(2.0, 1.0, 1.0) - kBelow;

}  // namespace

TEST_CASE("an emissive texture half black, half white lights only from its white half", "[textures]") {
    TempDir dir;
    write_halves(dir / "glow.png", {255, 255, 255, 255}, {0, 0, 0, 255});
    json panel = kGlow;
    panel["emissiveTexture"] = {{"index", 0}};
    json g = panel_over_floor(dir, panel, kGrey);
    add_textures(g, {"glow.png"});
    write_json(dir / "half.gltf", g);

    // On the mesh: half the flux, and none of it from elements over the black half.
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "half.gltf");
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(scene, {0.25, 0.125});
    double flux = 0.0, dark = 0.0;
    for (const hemirad::mesh::Element& e : mesh.elements) {
        if (e.node != 0) continue;
        flux += e.area * e.emission.x;
        if (e.centroid.x > 1.125) dark += e.area * e.emission.x;  // an element clear of the blend at x = 1 ± 1/64
    }
    CHECK(flux == Approx(1.0).epsilon(1e-3));  // 2 m² x E 1 x half lit
    CHECK(dark == 0.0);

    // Through the bake: each floor half gets the light of the lit half above it, or beside it.
    const json report = bake_ok(dir, dir / "half.gltf", dir / "out", {});
    CHECK(radiosity(report, "floor left") == Approx(0.5 * kBelow).epsilon(0.02));
    CHECK(radiosity(report, "floor right") == Approx(0.5 * kBeside).epsilon(0.03));
}

TEST_CASE("a base colour texture half black, half white reflects from its white half alone", "[textures]") {
    TempDir dir;
    write_halves(dir / "paint.png", {0, 0, 0, 255}, {255, 255, 255, 255});
    json floor = {{"name", "painted"},
                  {"pbrMetallicRoughness", {{"baseColorFactor", {0.8, 0.8, 0.8, 1.0}}, {"baseColorTexture", {{"index", 0}}}}}};
    json g = panel_over_floor(dir, kGlow, floor);
    add_textures(g, {"paint.png"});
    write_json(dir / "paint.gltf", g);
    const json report = bake_ok(dir, dir / "paint.gltf", dir / "out", {});
    // Each half sees the whole panel (by symmetry, both halves the same form factor).
    const double F = kBelow + kBeside;
    CHECK(radiosity(report, "floor left") < 0.01 * F);
    CHECK(radiosity(report, "floor right") == Approx(0.8 * F).epsilon(0.02));
}

TEST_CASE("a MASK card with half its area cut away passes the light of that half", "[textures]") {
    TempDir dir;
    // Holes (alpha 0) on the left, covered (alpha 1) on the right.
    write_halves(dir / "leaf.png", {40, 90, 20, 0}, {40, 90, 20, 255});
    const json card = {{"name", "card"}, {"alphaMode", "MASK"},
                       {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}},
                                                 {"baseColorTexture", {{"index", 0}}}}}};
    // Just under the panel, facing down: it hides the right half of the panel from the floor.
    const Quad under{{dvec3(0, 0.99, 0), dvec3(2, 0.99, 0), dvec3(2, 0.99, 1), dvec3(0, 0.99, 1)},
                     {{0, 0}, {1, 0}, {1, 1}, {0, 1}}, "card", 2};
    json g = panel_over_floor(dir, kGlow, kGrey, {under}, {card});
    add_textures(g, {"leaf.png"});
    write_json(dir / "mask.gltf", g);

    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "mask.gltf");
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(scene, {0.3, 0.15});
    double covered = 0.0;
    for (const hemirad::mesh::Element& e : mesh.elements)
        if (e.node == 3) {
            covered += e.area;
            CHECK(e.centroid.x > 0.95);
        }
    CHECK(covered == Approx(1.0).epsilon(0.05));
    CHECK(mesh.holes > 0);

    const json report = bake_ok(dir, dir / "mask.gltf", dir / "out", {});
    CHECK(report["counts"]["mask_holes"].get<long>() > 0);
    CHECK(radiosity(report, "floor left") == Approx(0.5 * kBelow).epsilon(0.04));
    CHECK(radiosity(report, "floor right") == Approx(0.5 * kBeside).epsilon(0.05));
    // Without its texture the card is all covered: the floor sees only the strip at the gap.
    json solid = g;
    solid["materials"][2]["pbrMetallicRoughness"].erase("baseColorTexture");
    write_json(dir / "solid.gltf", solid);
    const json shaded = bake_ok(dir, dir / "solid.gltf", dir / "solid", {});
    CHECK(radiosity(shaded, "floor left") < 0.05 * radiosity(report, "floor left"));
}

TEST_CASE("an emissive atlas with 3% of its texels lit emits from those elements alone", "[textures]") {
    TempDir dir;
    // 64 x 64 texels; an 11 x 11 block lit (121 / 4096 = 2.95%), away from the edges.
    write_png(dir / "atlas.png", 64, 64, [](int x, int y) -> std::array<unsigned char, 4> {
        const bool lit = x >= 40 && x < 51 && y >= 20 && y < 31;
        return lit ? std::array<unsigned char, 4>{255, 200, 120, 255} : std::array<unsigned char, 4>{0, 0, 0, 255};
    });
    json panel = kGlow;
    panel["emissiveTexture"] = {{"index", 0}};
    json g = panel_over_floor(dir, panel, kGrey);
    add_textures(g, {"atlas.png"});
    write_json(dir / "atlas.gltf", g);
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "atlas.gltf");
    const double lit = 121.0 / 4096.0;
    // The material's mean is the lit share of the texel colour, decoded from sRGB.
    CHECK(scene.materials[0].emission.y == Approx(lit * std::pow((200 / 255.0 + 0.055) / 1.055, 2.4)).epsilon(1e-6));

    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(scene, {0.5, 0.25});
    double flux = 0.0, emitting = 0.0;
    for (const hemirad::mesh::Element& e : mesh.elements) {
        if (e.node != 0) continue;
        flux += e.area * e.emission.x;
        if (e.emission.x > 0.0) emitting += e.area;
    }
    CHECK(flux == Approx(2.0 * lit).epsilon(0.01));
    // 2 m² of panel, of which 3% is lit: the emitting elements are a few times that at most.
    CHECK(emitting < 2.0 * 0.12);
    CHECK(mesh.texture_splits > 0);
    // Only patches over the lit block shoot, and those its edges cross are split into their
    // elements (Mesh::emission_splits): the shooting area is the emitting elements' again.
    double shooting = 0.0;
    for (const hemirad::mesh::Patch& p : mesh.patches) shooting += hemirad::luminance(p.emission) > 0.0 ? p.area : 0.0;
    CHECK(shooting == Approx(emitting).epsilon(1e-9));
    CHECK(mesh.emission_splits > 0);
}

TEST_CASE("KHR_texture_transform offsets, rotates and scales texture coordinates as the extension's GLSL",
          "[textures]") {
    TempDir dir;
    write_halves(dir / "paint.png", {0, 0, 0, 255}, {255, 255, 255, 255});
    json floor = {{"name", "painted"},
                  {"pbrMetallicRoughness",
                   {{"baseColorFactor", {1.0, 1.0, 1.0, 1.0}},
                    {"baseColorTexture",
                     {{"index", 0},
                      {"extensions",
                       {{"KHR_texture_transform",
                         {{"offset", {0.5, 0.25}}, {"rotation", M_PI / 2}, {"scale", {2.0, 3.0}}}}}}}}}}};
    json g = panel_over_floor(dir, kGlow, floor);
    g["extensionsUsed"] = {"KHR_texture_transform"};
    add_textures(g, {"paint.png"});
    write_json(dir / "t.gltf", g);
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "t.gltf");
    // Scale (2u, 3v), rotate counter-clockwise by 90° (x, y) -> (-y, x), then offset:
    // (u, v) -> (0.5 - 3v, 0.25 + 2u). Floor left's third corner (0.5, 1) -> (-2.5, 1.25).
    const hemirad::scene::Triangle& t = scene.triangles.at(2);  // floor left's first triangle (0, 1, 2)
    CHECK(t.uv_base[0].x == Approx(0.5));
    CHECK(t.uv_base[0].y == Approx(0.25));
    CHECK(t.uv_base[2].x == Approx(-2.5));
    CHECK(t.uv_base[2].y == Approx(1.25));
    CHECK((t.uv_slots & 1) == 1);
}

TEST_CASE("texture lookups wrap, clamp and mirror as the sampler says, in linear light", "[textures]") {
    // Four texels in a row: sRGB 0, 128, 255, 64.
    hemirad::scene::Texels texels;
    texels.width = 4;
    texels.height = 1;
    const auto lin = [](double s) { return s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4); };
    for (double s : {0.0, 128.0, 255.0, 64.0}) texels.rgba.push_back(glm::vec4(float(lin(s / 255.0))));
    const hemirad::scene::Texture tex(texels, dvec3(0.5));
    using hemirad::scene::Wrap;
    const auto at = [&](double u, Wrap w) { return tex.sample({u, 0.5}, 0, w, Wrap::clamp).x; };
    // Texel centres at (i + 0.5) / 4.
    CHECK(at(0.375, Wrap::repeat) == Approx(lin(128 / 255.0)).epsilon(1e-6));
    CHECK(at(1.375, Wrap::repeat) == Approx(lin(128 / 255.0)).epsilon(1e-6));
    CHECK(at(-0.625, Wrap::repeat) == Approx(lin(128 / 255.0)).epsilon(1e-6));
    CHECK(at(1.375, Wrap::clamp) == Approx(lin(64 / 255.0)).epsilon(1e-6));
    CHECK(at(1.375, Wrap::mirror) == Approx(lin(255 / 255.0)).epsilon(1e-6));  // 1 + 3/8 mirrors to 5/8
    CHECK(at(-0.125, Wrap::mirror) == Approx(0.0).margin(1e-9));               // -1/8 mirrors to 1/8
    // Between texels 0 and 1: the mean of their linear values, not of their encodings.
    CHECK(at(0.25, Wrap::clamp) == Approx(0.5 * lin(128 / 255.0)).epsilon(1e-6));
    // Nearest lookups read the texel holding u, wrapped the same way.
    CHECK(tex.texel({0.3, 0.5}, 0, Wrap::repeat, Wrap::clamp).x == Approx(lin(128 / 255.0)).epsilon(1e-6));
    CHECK(tex.texel({1.3, 0.5}, 0, Wrap::mirror, Wrap::clamp).x == Approx(1.0).epsilon(1e-6));   // texel 5 -> 2
    CHECK(tex.texel({-0.1, 0.5}, 0, Wrap::repeat, Wrap::clamp).x == Approx(lin(64 / 255.0)).epsilon(1e-6));
    CHECK(tex.texel({7.9, 0.5}, 0, Wrap::clamp, Wrap::clamp).x == Approx(lin(64 / 255.0)).epsilon(1e-6));
    // The pyramid: level 1 is two texels, level 2 one, each the mean of those it covers.
    REQUIRE(tex.levels() == 3);
    CHECK(tex.sample({0.5, 0.5}, 2, Wrap::clamp, Wrap::clamp).x ==
          Approx((lin(128 / 255.0) + 1.0 + lin(64 / 255.0)) / 4).epsilon(1e-6));
}

TEST_CASE("a large image is kept box-filtered, each texel the mean of the pixels it covers", "[textures]") {
    TempDir dir;
    // 2500 x 2 pixels, alternating black and white columns: reduced by 3 to 834 texels a row.
    write_png(dir / "wide.png", 2500, 2, [](int x, int) -> std::array<unsigned char, 4> {
        const unsigned char v = x % 2 ? 255 : 0;
        return {v, v, v, 255};
    });
    const std::string bytes = read_text(dir / "wide.png");
    hemirad::scene::Texels texels;
    const hemirad::scene::ImageMean mean = hemirad::scene::decode_image_mean(
        reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), &texels);
    REQUIRE(mean.ok);
    CHECK_FALSE(mean.coloured);
    CHECK(texels.factor == 3);
    CHECK(texels.width == 834);
    CHECK(texels.height == 1);
    CHECK(texels.rgba[0].x == Approx(1.0 / 3.0));  // columns 0, 1, 2: black, white, black
    CHECK(texels.rgba[1].x == Approx(2.0 / 3.0));
    CHECK(texels.rgba[833].x == Approx(1.0));  // the last texel covers column 2499 alone: white
}

TEST_CASE("elements split by refinement take their own texture averages, which average to their parent's",
          "[textures]") {
    TempDir dir;
    write_ramp(dir / "ramp.png");
    json floor = {{"name", "ramp"},
                  {"pbrMetallicRoughness", {{"baseColorFactor", {0.9, 0.9, 0.9, 1.0}}, {"baseColorTexture", {{"index", 0}}}}}};
    json g = panel_over_floor(dir, kGlow, floor);
    add_textures(g, {"ramp.png"});
    write_json(dir / "ramp.gltf", g);
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "ramp.gltf");
    CHECK(scene.materials[1].coloured_texture);
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(scene, {0.5, 0.25});
    const hemirad::mesh::Texturing texturing(scene);
    const hemirad::mesh::Refined refined =
        hemirad::mesh::split_elements(mesh, std::vector<bool>(mesh.elements.size(), true), &texturing);
    std::size_t checked = 0;
    for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
        const hemirad::mesh::Element& parent = mesh.elements[k];
        if (parent.node != 1) continue;
        dvec3 sum(0.0), lo(1.0), hi(0.0);
        for (std::size_t c = 0; c < refined.mesh.elements.size(); ++c)
            if (refined.origin[c] == k) {
                const hemirad::mesh::Element& child = refined.mesh.elements[c];
                sum += child.area * child.rho;
                lo = glm::min(lo, child.rho);
                hi = glm::max(hi, child.rho);
            }
        INFO("element " << k);
        CHECK(sum.x / parent.area == Approx(parent.rho.x).epsilon(0.01).margin(1e-3));
        CHECK(sum.y / parent.area == Approx(parent.rho.y).epsilon(0.01).margin(1e-3));
        CHECK(hi.x > lo.x * 1.05);  // the ramp runs across every element
        ++checked;
    }
    CHECK(checked == 16);
}

TEST_CASE("contact grading under an emissive texture: each child's light is E + rho H with its own E and rho",
          "[textures][contact]") {
    // A floor glowing through a ramp texture, and a grey wall standing across it along x = 0.5:
    // the floor's elements along the wall's foot are split in four (solve::grade_contacts). Each
    // child keeps its parent's irradiance H and takes its own texture averages, so its radiosity
    // is its own E + ρH, and the node's flux stays the parent's to the texture averages' rounding.
    TempDir dir;
    write_ramp(dir / "ramp.png");
    json floor = {{"name", "glowing ramp"},
                  {"emissiveFactor", {1.0, 1.0, 1.0}},
                  {"emissiveTexture", {{"index", 0}}},
                  {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}};
    const Quad wall{{dvec3(0.5, 0, 0), dvec3(0.5, 0.5, 0), dvec3(0.5, 0.5, 1), dvec3(0.5, 0, 1)},
                    {{0, 0}, {1, 0}, {1, 1}, {0, 1}},
                    "wall",
                    2};
    json g = panel_over_floor(dir, kGlow, floor, {wall}, {kGrey});
    add_textures(g, {"ramp.png"});
    write_json(dir / "glow.gltf", g);
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "glow.gltf");
    hemirad::mesh::Mesh mesh = hemirad::mesh::build(scene, {0.5, 0.25});
    const hemirad::mesh::Texturing texturing(scene);
    const std::size_t before = mesh.elements.size();
    std::vector<dvec3> radiosity(before), irradiance(before);
    std::vector<dvec3> flux(scene.nodes.size(), dvec3(0.0));
    for (std::size_t k = 0; k < before; ++k) {
        const hemirad::mesh::Element& e = mesh.elements[k];
        irradiance[k] = dvec3(1.0 + e.centroid.x, 2.0 - e.centroid.z, 1.5);
        radiosity[k] = e.emission + e.rho * irradiance[k];
        flux[e.node] += e.area * radiosity[k];
    }
    const auto floor_elements = [&] {
        return std::count_if(mesh.elements.begin(), mesh.elements.end(),
                             [](const hemirad::mesh::Element& e) { return e.node == 1 || e.node == 2; });
    };
    const auto floor_before = floor_elements();
    // Elements down to 0.05 m: the ramp's emission already split the floor's to 0.0625 m when meshed.
    const std::size_t split = hemirad::solve::grade_contacts(mesh, radiosity, irradiance, 0.05, &texturing);
    REQUIRE(split > 0);
    REQUIRE(mesh.elements.size() == before + 3 * split);
    std::vector<dvec3> after(scene.nodes.size(), dvec3(0.0));
    for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
        const hemirad::mesh::Element& e = mesh.elements[k];
        after[e.node] += e.area * radiosity[k];
        const dvec3 own = e.emission + e.rho * irradiance[k];
        INFO("element " << k);
        for (int c = 0; c < 3; ++c) CHECK(radiosity[k][c] == Approx(own[c]).epsilon(1e-12));
    }
    for (std::size_t n = 0; n < scene.nodes.size(); ++n)
        for (int c = 0; c < 3; ++c) CHECK(after[n][c] == Approx(flux[n][c]).epsilon(0.01));
    // The floor's elements along the wall's foot were split (their children's emissions differ
    // along the ramp, so the E + ρH check above tells a child's own light from its parent's).
    CHECK(floor_elements() - floor_before >= 3 * 4);
}

TEST_CASE("a primitive without the texture coordinates its material reads uses the texture's mean, with a warning",
          "[textures]") {
    TempDir dir;
    write_halves(dir / "paint.png", {0, 0, 0, 255}, {255, 255, 255, 255});
    json floor = {{"name", "painted"},
                  {"pbrMetallicRoughness", {{"baseColorFactor", {0.8, 0.8, 0.8, 1.0}}, {"baseColorTexture", {{"index", 0}, {"texCoord", 1}}}}}};
    json g = panel_over_floor(dir, kGlow, floor);
    add_textures(g, {"paint.png"});
    write_json(dir / "no-uv.gltf", g);
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "no-uv.gltf");
    std::size_t warned = 0;
    for (const std::string& w : scene.warnings) warned += w.find("TEXCOORD_1, which the primitive lacks") != std::string::npos;
    CHECK(warned == 1);  // once per material and texture
    const hemirad::mesh::Mesh mesh = hemirad::mesh::build(scene, {0.5, 0.25});
    for (const hemirad::mesh::Element& e : mesh.elements)
        if (e.node == 1) CHECK(e.rho.x == Approx(0.4).epsilon(1e-6));
}
