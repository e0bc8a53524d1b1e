// Every image format glTF pipelines write (WebP under EXT_texture_webp, as a file, a data URI of
// any type and a bufferView; KHR_texture_basisu refused by name), textures whose image cannot be
// used (the material's factors, one warning, --strict-textures), and the warnings that would
// repeat per item, counted on one line. Images are made here with OpenImageIO; each WebP is
// checked against a PNG of the pixels it decodes to, and a uniform one against its known colour.
#include <OpenImageIO/imageio.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <string>
#include <vector>

#include "cli_support.h"
#include "core/error.h"
#include "scene/effects.h"
#include "scene/scene.h"

namespace {

using namespace hemirad::test;
using hemirad::scene::Scene;

struct Pixels {
    int width = 0, height = 0;
    std::vector<unsigned char> rgb;  // 8-bit, row by row
};

// 16 x 16 blocks of four colours, 4 pixels a side.
Pixels blocks() {
    const unsigned char colours[4][3] = {{200, 30, 40}, {20, 180, 60}, {40, 70, 220}, {250, 240, 10}};
    Pixels p{16, 16, {}};
    for (int y = 0; y < 16; ++y)
        for (int x = 0; x < 16; ++x)
            for (int c = 0; c < 3; ++c) p.rgb.push_back(colours[(x / 4 + y / 4) % 4][c]);
    return p;
}

Pixels uniform(unsigned char r, unsigned char g, unsigned char b) {
    Pixels p{8, 8, {}};
    for (int i = 0; i < 64; ++i) p.rgb.insert(p.rgb.end(), {r, g, b});
    return p;
}

// Writes `p` in the format the file's extension names; WebP losslessly (OpenImageIO's
// "compression" "lossless": a VP8L stream, though its colours pass through 4:2:0 chroma on the
// way, so edges between colours blur: the tests compare with the pixels it decodes to).
void write_image(const fs::path& file, const Pixels& p) {
    auto out = OIIO::ImageOutput::create(file.string());
    REQUIRE(out);
    OIIO::ImageSpec spec(p.width, p.height, 3, OIIO::TypeDesc::UINT8);
    if (file.extension() == ".webp") spec.attribute("compression", "lossless");
    if (file.extension() == ".jpg") spec.attribute("CompressionQuality", 90);
    REQUIRE(out->open(file.string(), spec));
    REQUIRE(out->write_image(OIIO::TypeDesc::UINT8, p.rgb.data()));
    REQUIRE(out->close());
}

Pixels read_pixels(const fs::path& file) {
    auto in = OIIO::ImageInput::open(file.string());
    REQUIRE(in);
    Pixels p{in->spec().width, in->spec().height, {}};
    p.rgb.resize(std::size_t(p.width) * std::size_t(p.height) * 3);
    REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, p.rgb.data()));
    return p;
}

std::string base64(const std::string& bytes) {
    static const char* kDigits = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    for (std::size_t i = 0; i < bytes.size(); i += 3) {
        const std::size_t n = std::min<std::size_t>(3, bytes.size() - i);
        std::uint32_t v = 0;
        for (std::size_t k = 0; k < 3; ++k) v = v << 8 | (k < n ? static_cast<unsigned char>(bytes[i + k]) : 0u);
        for (std::size_t k = 0; k < 4; ++k) out += k <= n ? kDigits[(v >> (18 - 6 * k)) & 63] : '=';
    }
    return out;
}

// closed_room.gltf with its wall material (0, baseColorFactor 0.7) and, when `also_cube`, the
// cube's (2, 0.5) reading texture 0 through `texture`, the file's images `images`.
json textured_room(const json& texture, const json& images, bool also_cube = false) {
    json g = read_json(kClosedRoom);
    g["images"] = images;
    g["textures"] = json::array({texture});
    g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    if (also_cube) g["materials"][2]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    return g;
}

json webp_texture(int webp, int fallback = -1) {
    json t = {{"extensions", {{"EXT_texture_webp", {{"source", webp}}}}}};
    if (fallback >= 0) t["source"] = fallback;
    return t;
}

void require_webp(json& g) {
    g["extensionsUsed"].push_back("EXT_texture_webp");
    g["extensionsRequired"] = {"EXT_texture_webp"};
}

Scene load_json(const TempDir& dir, const std::string& name, const json& g) {
    write_json(dir / name, g);
    return hemirad::scene::load(dir / name);
}

std::size_t count_warnings(const Scene& s, const std::string& needle) {
    return std::size_t(std::count_if(s.warnings.begin(), s.warnings.end(),
                                     [&](const std::string& w) { return w.find(needle) != std::string::npos; }));
}

std::size_t count_warnings(const json& report, const std::string& needle) {
    std::size_t n = 0;
    for (const json& w : report["warnings"]) n += w.get<std::string>().find(needle) != std::string::npos;
    return n;
}

// The texture as the mesher holds it, texel by texel, and the material's mean colour.
void check_same_texture(const Scene& got, const Scene& want) {
    REQUIRE(got.textures.size() == 1);
    REQUIRE(want.textures.size() == 1);
    CHECK(got.materials[0].base_color == want.materials[0].base_color);
    const auto& a = *got.textures[0];
    const auto& b = *want.textures[0];
    REQUIRE(a.width() == b.width());
    REQUIRE(a.height() == b.height());
    for (int y = 0; y < a.height(); ++y)
        for (int x = 0; x < a.width(); ++x) {
            const glm::dvec2 uv((x + 0.5) / a.width(), (y + 0.5) / a.height());
            const auto w = hemirad::scene::Wrap::clamp;
            CHECK(a.texel(uv, 0, w, w) == b.texel(uv, 0, w, w));
        }
}

double srgb_to_linear(double x) { return x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4); }

}  // namespace

TEST_CASE("a WebP texture reads as the PNG of its pixels: EXT_texture_webp, a file, a data URI, a bufferView",
          "[textures][image_formats]") {
    TempDir dir;
    write_image(dir / "blocks.webp", blocks());
    const std::string webp = read_text(dir / "blocks.webp");
    REQUIRE(webp.substr(12, 4) == "VP8L");  // lossless
    write_image(dir / "same.png", read_pixels(dir / "blocks.webp"));  // the pixels the WebP decodes to
    write_image(dir / "other.png", uniform(10, 200, 30));
    const Scene png = load_json(dir, "png.gltf", textured_room({{"source", 0}}, {{{"uri", "same.png"}}}));

    SECTION("EXT_texture_webp alone, the extension required") {
        json g = textured_room(webp_texture(0), {{{"uri", "blocks.webp"}}});
        require_webp(g);
        const Scene s = load_json(dir, "webp.gltf", g);
        check_same_texture(s, png);
        CHECK(count_warnings(s, "not supported") == 0);
        CHECK(count_warnings(s, "basisu") == 0);
    }
    SECTION("EXT_texture_webp with a fallback source: the WebP is read") {
        const Scene s = load_json(dir, "both.gltf", textured_room(webp_texture(0, 1), {{{"uri", "blocks.webp"}}, {{"uri", "other.png"}}}));
        check_same_texture(s, png);
    }
    SECTION("EXT_texture_webp whose WebP is missing: the fallback source is read") {
        const Scene s = load_json(dir, "fallback.gltf", textured_room(webp_texture(0, 1), {{{"uri", "gone.webp"}}, {{"uri", "same.png"}}}));
        check_same_texture(s, png);
    }
    SECTION("a WebP as the plain source") {
        check_same_texture(load_json(dir, "plain.gltf", textured_room({{"source", 0}}, {{{"uri", "blocks.webp"}}})), png);
    }
    SECTION("a WebP as a data URI (image/webp, a type tinygltf does not decode), with the extension and without") {
        const json images = {{{"uri", "data:image/webp;base64," + base64(webp)}}};
        json g = textured_room(webp_texture(0), images);
        require_webp(g);
        check_same_texture(load_json(dir, "uri.gltf", g), png);
        check_same_texture(load_json(dir, "uri_plain.gltf", textured_room({{"source", 0}}, images)), png);
    }
    SECTION("a WebP in a bufferView") {
        json g = textured_room(webp_texture(0), {{{"bufferView", 0}, {"mimeType", "image/webp"}}});
        write_text(dir / "image.bin", webp);
        const std::size_t buffer = g["buffers"].size();
        g["buffers"].push_back({{"uri", "image.bin"}, {"byteLength", webp.size()}});
        g["bufferViews"].push_back({{"buffer", buffer}, {"byteLength", webp.size()}});
        g["images"][0]["bufferView"] = g["bufferViews"].size() - 1;
        require_webp(g);
        check_same_texture(load_json(dir, "view.gltf", g), png);
    }
    SECTION("PNG and JPEG as data URIs of any image type, and the PNG's own") {
        const std::string png_bytes = read_text(dir / "same.png");
        for (const std::string type : {"image/png", "image/x-png", "application/octet-stream"}) {
            INFO(type);
            check_same_texture(load_json(dir, "png_uri.gltf", textured_room({{"source", 0}}, {{{"uri", "data:" + type + ";base64," + base64(png_bytes)}}})), png);
        }
        write_image(dir / "blocks.jpg", blocks());
        write_image(dir / "jpeg_pixels.png", read_pixels(dir / "blocks.jpg"));
        const Scene jpeg_png = load_json(dir, "jpeg_png.gltf", textured_room({{"source", 0}}, {{{"uri", "jpeg_pixels.png"}}}));
        for (const std::string type : {"image/jpeg", "image/jpg"}) {
            INFO(type);
            check_same_texture(load_json(dir, "jpeg_uri.gltf", textured_room({{"source", 0}}, {{{"uri", "data:" + type + ";base64," + base64(read_text(dir / "blocks.jpg"))}}})),
                               jpeg_png);
        }
    }
}

TEST_CASE("a uniform WebP texture gives its known colour, within WebP's rounding", "[textures][image_formats]") {
    TempDir dir;
    write_image(dir / "flat.webp", uniform(200, 100, 50));
    const Scene s = load_json(dir, "flat.gltf", textured_room(webp_texture(0), {{{"uri", "flat.webp"}}}));
    const unsigned char want[3] = {200, 100, 50};
    for (int c = 0; c < 3; ++c) {
        // A level either side in the encoded values (RGB through YUV and back).
        const double lo = 0.7 * srgb_to_linear((want[c] - 2) / 255.0), hi = 0.7 * srgb_to_linear((want[c] + 2) / 255.0);
        CHECK(s.materials[0].base_color[c] >= lo);
        CHECK(s.materials[0].base_color[c] <= hi);
    }
}

TEST_CASE("a baked WebP data URI texture equals the bake of its PNG, and baked.gltf keeps the WebP",
          "[textures][image_formats][cli]") {
    TempDir dir;
    write_image(dir / "blocks.webp", blocks());
    write_image(dir / "same.png", read_pixels(dir / "blocks.webp"));
    json g = textured_room(webp_texture(0), {{{"uri", "data:image/webp;base64," + base64(read_text(dir / "blocks.webp"))}}});
    require_webp(g);
    write_json(dir / "webp.gltf", g);
    write_json(dir / "png.gltf", textured_room({{"source", 0}}, {{{"uri", "same.png"}}}));
    const json webp = bake_ok(dir, dir / "webp.gltf", dir / "webp");
    const json png = bake_ok(dir, dir / "png.gltf", dir / "png");
    CHECK(webp["meshes"] == png["meshes"]);
    CHECK(count_warnings(webp, "not supported") == 0);
    const json baked = read_json(dir / "webp" / "baked.gltf");
    REQUIRE(baked["images"].size() == 1);
    CHECK(baked["images"][0]["mimeType"] == "image/webp");
    CHECK(baked["images"][0].contains("bufferView"));
    CHECK(!baked["images"][0].contains("uri"));
}

TEST_CASE("a texture only in KHR_texture_basisu is exit 2 naming that extension and with a PNG fallback it bakes",
          "[textures][image_formats][cli]") {
    TempDir dir;
    // The KTX2 file identifier, then nothing a decoder would want: hemirad must not try.
    write_text(dir / "t.ktx2", std::string("\xabKTX 20\xbb\r\n\x1a\n", 12) + std::string(64, '\0'));
    json g = textured_room({{"extensions", {{"KHR_texture_basisu", {{"source", 0}}}}}}, {{{"uri", "t.ktx2"}}});
    g["extensionsUsed"].push_back("KHR_texture_basisu");
    g["extensionsRequired"] = {"KHR_texture_basisu"};
    write_json(dir / "ktx2.gltf", g);
    try {
        hemirad::scene::load(dir / "ktx2.gltf");
        FAIL("a KTX2-only texture loaded");
    } catch (const hemirad::InputError& e) {
        const std::string what = e.what();
        CHECK(what.find("KHR_texture_basisu") != std::string::npos);
        CHECK(what.find("glTF-Transform") != std::string::npos);
        CHECK(what.find("EXT_texture_webp") == std::string::npos);
    }
    const RunResult r = run_hemirad(dir, bake_args(dir / "ktx2.gltf", dir / "never"));
    CHECK(r.code == 2);
    CHECK(r.err.find("KHR_texture_basisu") != std::string::npos);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
    CHECK(!fs::exists(dir / "never"));
    // The fallback `source` a basisu texture may carry is read instead.
    write_image(dir / "flat.png", uniform(100, 100, 100));
    json fallback = textured_room({{"source", 1}, {"extensions", {{"KHR_texture_basisu", {{"source", 0}}}}}},
                                  {{{"uri", "t.ktx2"}}, {{"uri", "flat.png"}}});
    const Scene s = load_json(dir, "fallback.gltf", fallback);
    CHECK(s.materials[0].base_color.x == Approx(0.7 * srgb_to_linear(100 / 255.0)).epsilon(1e-9));
    // A WebP-only texture whose image is missing is named as what it is, never as basisu.
    const Scene missing = load_json(dir, "webp_missing.gltf", textured_room(webp_texture(0), {{{"uri", "gone.webp"}}}));
    CHECK(count_warnings(missing, "gone.webp") == 1);
    CHECK(count_warnings(missing, "basisu") == 0);
}

TEST_CASE("a missing texture bakes with the material's factors and one warning and --strict-textures makes it exit 2",
          "[textures][image_formats][cli]") {
    TempDir dir;
    // Two materials read the one missing image: one warning, counting both.
    write_json(dir / "missing.gltf", textured_room({{"source", 0}}, {{{"uri", "missing.png"}}}, /*also_cube=*/true));
    const Scene s = hemirad::scene::load(dir / "missing.gltf");
    CHECK(count_warnings(s, "missing.png") == 1);
    CHECK(count_warnings(s, "2 materials ('wall_grey', 'cube_grey')") == 1);
    CHECK(s.materials[0].base_color == glm::dvec3(0.7));
    CHECK(s.materials[2].base_color == glm::dvec3(0.5));
    CHECK(!s.materials[0].base_texture);

    // The bake is the bake of the same scene without the texture, number for number.
    const json plain = bake_ok(dir, kClosedRoom, dir / "plain");
    const json missing = bake_ok(dir, dir / "missing.gltf", dir / "missing");
    CHECK(missing["meshes"] == plain["meshes"]);
    CHECK(missing["energy"] == plain["energy"]);
    CHECK(count_warnings(missing, "missing.png") == 1);

    // An image that does not decode, and a texture with no image at all, likewise.
    write_text(dir / "garbage.png", "not a picture\n");
    write_json(dir / "garbage.gltf", textured_room({{"source", 0}}, {{{"uri", "garbage.png"}}}));
    CHECK(bake_ok(dir, dir / "garbage.gltf", dir / "garbage")["meshes"] == plain["meshes"]);
    write_json(dir / "sourceless.gltf", textured_room(json::object(), json::array()));
    const Scene sourceless = hemirad::scene::load(dir / "sourceless.gltf");
    CHECK(count_warnings(sourceless, "texture 0: names no image") == 1);

    // --strict-textures: exit 2, one line naming the image, nothing written.
    for (const std::string file : {"missing", "garbage", "sourceless"}) {
        INFO(file);
        const RunResult r = run_hemirad(dir, bake_args(dir / (file + ".gltf"), dir / "never", concat(kFast, {"--strict-textures"})));
        CHECK(r.code == 2);
        CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
        CHECK(r.err.find(file + ".gltf: material 'wall_grey' baseColorTexture") != std::string::npos);
        CHECK(!fs::exists(dir / "never"));
    }
}

TEST_CASE("warnings that repeat per item are one line with the count", "[scene][image_formats]") {
    TempDir dir;
    SECTION("primitives of a mode other than triangles, many meshes") {
        json g = read_json(kClosedRoom);
        const int position = g["meshes"][0]["primitives"][0]["attributes"]["POSITION"];
        for (int i = 0; i < 1200; ++i) {
            g["meshes"].push_back({{"name", "line" + std::to_string(i)},
                                   {"primitives", {{{"attributes", {{"POSITION", position}}}, {"mode", 1}}}}});
            g["nodes"].push_back({{"mesh", g["meshes"].size() - 1}});
            g["scenes"][0]["nodes"].push_back(g["nodes"].size() - 1);
        }
        const Scene s = load_json(dir, "lines.gltf", g);
        CHECK(s.warnings.size() == 1);
        CHECK(count_warnings(s, "1,200 primitives of mode LINES are not triangles; skipped (mesh 'line0' primitive 0; "
                                "mesh 'line1' primitive 0; mesh 'line2' primitive 0; and 1,197 more)") == 1);
    }
    SECTION("many images missing: one warning each for the first, then one line") {
        json images = json::array(), textures = json::array();
        json g = read_json(kClosedRoom);
        for (int i = 0; i < 12; ++i) {
            images.push_back({{"uri", "gone" + std::to_string(i) + ".png"}});
            textures.push_back({{"source", i}});
            json m = g["materials"][0];
            m["name"] = "m" + std::to_string(i);
            m["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", i}};
            g["materials"].push_back(m);
        }
        g["images"] = images;
        g["textures"] = textures;
        const Scene s = load_json(dir, "gone.gltf", g);
        CHECK(s.warnings.size() == 9);
        CHECK(count_warnings(s, "4 more texture images cannot be used either (image 8 'gone8.png', image 9 "
                                "'gone9.png', image 10 'gone10.png', ...); the 4 materials reading them") == 1);
    }
}

TEST_CASE("many zero-area triangles are one warning line counting them", "[cli][image_formats]") {
    TempDir dir;
    json g = read_json(kClosedRoom);
    // 1,200 triangles whose three corners are one point.
    const std::vector<float> points(1200 * 9, 0.25f);
    write_text(dir / "points.bin", std::string(reinterpret_cast<const char*>(points.data()), points.size() * 4));
    const std::size_t buffer = g["buffers"].size(), view = g["bufferViews"].size(), accessor = g["accessors"].size();
    g["buffers"].push_back({{"uri", "points.bin"}, {"byteLength", points.size() * 4}});
    g["bufferViews"].push_back({{"buffer", buffer}, {"byteLength", points.size() * 4}});
    g["accessors"].push_back({{"bufferView", view}, {"componentType", 5126}, {"count", 3600}, {"type", "VEC3"},
                              {"min", {0.25, 0.25, 0.25}}, {"max", {0.25, 0.25, 0.25}}});
    g["meshes"].push_back({{"name", "dust"}, {"primitives", {{{"attributes", {{"POSITION", accessor}}}, {"material", 0}}}}});
    g["nodes"].push_back({{"name", "dust"}, {"mesh", g["meshes"].size() - 1}});
    g["scenes"][0]["nodes"].push_back(g["nodes"].size() - 1);
    write_json(dir / "dust.gltf", g);
    const json report = bake_ok(dir, dir / "dust.gltf", dir / "out");
    CHECK(report["counts"]["dropped_triangles"] == 1200);
    CHECK(count_warnings(report, "zero-area") == 1);
    CHECK(count_warnings(report, "1,200 zero-area triangles dropped (of ") == 1);
}

TEST_CASE("skinned and animated meshes: one warning that they bake in their rest pose", "[scene][image_formats]") {
    TempDir dir;
    json g = read_json(kClosedRoom);
    const int position = g["meshes"][7]["primitives"][0]["attributes"]["POSITION"];
    // A skinned copy of the cube (its joints and weights accessors are not read, so any will do).
    json arm = g["meshes"][7];
    arm["name"] = "arm";
    arm["primitives"][0]["attributes"]["JOINTS_0"] = position;
    arm["primitives"][0]["attributes"]["WEIGHTS_0"] = position;
    g["meshes"].push_back(arm);
    const std::size_t arm_node = g["nodes"].size();
    g["nodes"].push_back({{"name", "arm"}, {"mesh", g["meshes"].size() - 1}, {"skin", 0}});
    g["scenes"][0]["nodes"].push_back(arm_node);
    // One identity inverse bind matrix (tinygltf 2.7 asks for one, though glTF does not).
    const float identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    g["buffers"].push_back({{"byteLength", sizeof identity},
                            {"uri", "data:application/octet-stream;base64," +
                                        base64(std::string(reinterpret_cast<const char*>(identity), sizeof identity))}});
    g["bufferViews"].push_back({{"buffer", g["buffers"].size() - 1}, {"byteLength", sizeof identity}});
    g["accessors"].push_back({{"bufferView", g["bufferViews"].size() - 1}, {"componentType", 5126}, {"count", 1}, {"type", "MAT4"}});
    g["skins"] = {{{"joints", {arm_node}}, {"inverseBindMatrices", g["accessors"].size() - 1}}};
    const Scene still = hemirad::scene::load(kClosedRoom);
    CHECK(count_warnings(still, "rest pose") == 0);
    const Scene skinned = load_json(dir, "skinned.gltf", g);
    CHECK(count_warnings(skinned, "1 mesh (1 skinned: 'arm') is baked in its bind or rest pose") == 1);
    // An animation that moves the cube's node: two meshes now, in one line.
    int cube_node = -1;
    for (std::size_t i = 0; i < g["nodes"].size(); ++i)
        if (g["nodes"][i].value("mesh", -1) == 7) cube_node = int(i);
    REQUIRE(cube_node >= 0);
    const json sampler = {{"input", position}, {"output", position}};
    const json channel = {{"sampler", 0}, {"target", {{"node", cube_node}, {"path", "translation"}}}};
    json animation = json::object();
    animation["samplers"] = json::array({sampler});
    animation["channels"] = json::array({channel});
    g["animations"] = json::array({animation});
    const Scene animated = load_json(dir, "animated.gltf", g);
    CHECK(count_warnings(animated, "rest pose") == 1);
    CHECK(count_warnings(animated, "2 meshes (1 skinned, 1 moved by an animation: ") == 1);
    CHECK(count_warnings(animated, "light will not follow the animation") == 1);
}

TEST_CASE("bake --help lists every effect --effects takes", "[cli][image_formats]") {
    TempDir dir;
    const RunResult r = run_hemirad(dir, {"bake", "--help"});
    REQUIRE(r.code == 0);
    const std::size_t at = r.out.find("--effects");
    REQUIRE(at != std::string::npos);
    const std::string line = r.out.substr(at, r.out.find('\n', at) - at);
    for (const char* name : hemirad::scene::kEffectNames) {
        INFO(name);
        CHECK(line.find(name) != std::string::npos);
        CHECK_NOTHROW(hemirad::scene::parse_effect_overrides(std::string(name) + "=off"));
    }
    CHECK(line.find("see_through") != std::string::npos);
}
