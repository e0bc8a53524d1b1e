// Alpha-blended and transmissive surfaces (glass, veils) through `hemirad bake`: by default they
// neither block nor receive light (the floor under a see-through slab gets what it gets without
// the slab), report.json says so and why, and `--effects see_through=off` bakes them as opaque
// surfaces; blended materials that are mostly opaque, or emit, stay opaque.
#include <OpenImageIO/imageio.h>

#include <catch2/catch.hpp>
#include <string>

#include "cli_support.h"
#include "scene/scene.h"

namespace {

using namespace hemirad::test;

// A floor (2 x 2 m at y = 0, facing up), a lamp (0.5 x 0.5 m at y = 1, facing down) and, when
// `slab` is given, a 1 x 1 m slab at y = 0.5 facing up with that material, its node last; the
// buffer in room.bin in `dir`.
json room(const TempDir& dir, const json& lamp_material, const json& slab = nullptr) {
    std::vector<float> p = {-1, 0, -1, -1, 0, 1, 1, 0, 1, 1, 0, -1,                      // floor
                            -0.25f, 1, -0.25f, 0.25f, 1, -0.25f, 0.25f, 1, 0.25f, -0.25f, 1, 0.25f,  // lamp
                            -0.5f, 0.5f, -0.5f, -0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, -0.5f};  // slab
    const std::vector<std::uint16_t> quad = {0, 1, 2, 0, 2, 3};
    std::string bytes(reinterpret_cast<const char*>(p.data()), p.size() * 4);
    bytes.append(reinterpret_cast<const char*>(quad.data()), quad.size() * 2);
    write_text(dir / "room.bin", bytes);
    json buffer = {{"byteLength", bytes.size()}, {"uri", "room.bin"}};
    json g = {{"asset", {{"version", "2.0"}}},
              {"scene", 0},
              {"scenes", {{{"nodes", slab.is_null() ? json{0, 1} : json{0, 1, 2}}}}},
              {"nodes", {{{"name", "floor"}, {"mesh", 0}}, {{"name", "lamp"}, {"mesh", 1}}}},
              {"meshes", json::array()},
              {"materials", {{{"name", "grey"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}},
                             lamp_material}},
              {"accessors", json::array()},
              {"bufferViews", {{{"buffer", 0}, {"byteLength", p.size() * 4}},
                               {{"buffer", 0}, {"byteOffset", p.size() * 4}, {"byteLength", 12}}}},
              {"buffers", {buffer}}};
    g["accessors"].push_back({{"bufferView", 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}});
    for (int q = 0; q < (slab.is_null() ? 2 : 3); ++q) {
        g["accessors"].push_back({{"bufferView", 0}, {"byteOffset", 48 * q}, {"componentType", 5126}, {"count", 4},
                                  {"type", "VEC3"}, {"min", {-1, 0, -1}}, {"max", {1, 1, 1}}});
        const json primitive = {{"attributes", {{"POSITION", q + 1}}}, {"indices", 0}, {"material", q}};
        g["meshes"].push_back({{"primitives", json::array({primitive})}});
    }
    if (!slab.is_null()) {
        g["materials"].push_back(slab);
        g["nodes"].push_back({{"name", "slab"}, {"mesh", 2}});
    }
    return g;
}

const json kLamp = {{"name", "lamp"}, {"emissiveFactor", {1.0, 1.0, 1.0}},
                    {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 0.0, 0.0, 1.0}}}}};

double floor_radiosity(const json& report) {
    for (const json& m : report["meshes"])
        if (m["name"] == "floor") return m["radiosity"][0].get<double>();
    FAIL("no floor in the report");
    return 0.0;
}

}  // namespace

TEST_CASE("see-through surfaces neither block nor receive by default, see_through=off makes them opaque",
          "[see_through][cli]") {
    TempDir dir;
    const json glass = {{"name", "glass"},
                        {"pbrMetallicRoughness", {{"baseColorFactor", {0.9, 0.9, 0.9, 1.0}}}},
                        {"extensions", {{"KHR_materials_transmission", {{"transmissionFactor", 0.9}}}}}};
    const json veil = {{"name", "veil"}, {"alphaMode", "BLEND"},
                       {"pbrMetallicRoughness", {{"baseColorFactor", {0.8, 0.8, 0.8, 0.2}}}}};
    write_json(dir / "bare.gltf", room(dir, kLamp));
    const json bare = bake_ok(dir, dir / "bare.gltf", dir / "bare");
    REQUIRE(floor_radiosity(bare) > 0.0);

    for (const json& slab : {glass, veil}) {
        const std::string name = slab["name"];
        DYNAMIC_SECTION(name) {
            write_json(dir / (name + ".gltf"), room(dir, kLamp, slab));
            const json seen = bake_ok(dir, dir / (name + ".gltf"), dir / (name + "-default"));
            const json& effect = seen["effects"]["see_through"];
            INFO(effect.dump());
            CHECK(effect["on"] == true);
            CHECK(effect["forced"] == false);
            CHECK(effect["why"].get<std::string>().find("'" + name + "'") != std::string::npos);
            CHECK(effect["why"].get<std::string>().find(name == "glass" ? "KHR_materials_transmission 0.9"
                                                                        : "alphaMode BLEND, mean opacity 0.20") !=
                  std::string::npos);
            // The slab is not there for the light: the floor gets exactly what it gets without it,
            // and the slab itself none.
            CHECK(floor_radiosity(seen) == Approx(floor_radiosity(bare)).epsilon(1e-12));
            CHECK(seen["meshes"][2]["name"] == "slab");
            CHECK(seen["meshes"][2]["area"] == 0.0);

            const json opaque = bake_ok(dir, dir / (name + ".gltf"), dir / (name + "-opaque"),
                                        concat(kFast, {"--effects", "see_through=off"}));
            CHECK(opaque["effects"]["see_through"]["on"] == false);
            CHECK(opaque["effects"]["see_through"]["forced"] == true);
            CHECK(opaque["meshes"][2]["area"].get<double>() == Approx(1.0));
            CHECK(floor_radiosity(opaque) < 0.8 * floor_radiosity(bare));  // an opaque slab shades the floor
        }
    }
}

TEST_CASE("blended materials that are mostly opaque, or that emit, stay opaque surfaces", "[see_through][cli]") {
    TempDir dir;
    // A lantern's glass at 90% opacity blocks like any surface.
    const json lantern = {{"name", "lantern"}, {"alphaMode", "BLEND"},
                          {"pbrMetallicRoughness", {{"baseColorFactor", {0.8, 0.8, 0.8, 0.9}}}}};
    write_json(dir / "lantern.gltf", room(dir, kLamp, lantern));
    const json kept = bake_ok(dir, dir / "lantern.gltf", dir / "lantern");
    CHECK(kept["effects"]["see_through"]["on"] == false);
    CHECK(kept["meshes"][2]["area"].get<double>() == Approx(1.0));
    // A lamp exported as a blended glow is still the scene's light, said in a warning.
    json glow = kLamp;
    glow["alphaMode"] = "BLEND";
    glow["pbrMetallicRoughness"]["baseColorFactor"] = {0.0, 0.0, 0.0, 0.3};
    write_json(dir / "glow.gltf", room(dir, glow));
    const json lit = bake_ok(dir, dir / "glow.gltf", dir / "glow");
    CHECK(lit["effects"]["see_through"]["on"] == false);
    CHECK(floor_radiosity(lit) > 0.0);
    bool warned = false;
    for (const json& w : lit["warnings"])
        warned = warned || w.get<std::string>().find("material 'lamp': see-through (alphaMode BLEND, mean opacity "
                                                     "0.30) but emitting, and denser than a fake light shaft: baked "
                                                     "as an opaque emitter") != std::string::npos;
    CHECK(warned);
}

TEST_CASE("a faint blended emitter (a fake light shaft) is left out, the scene's lamp still lights it",
          "[see_through][cli]") {
    TempDir dir;
    // A glowing slab at 10% opacity between the lamp and the floor: decoration, not a light.
    const json shaft = {{"name", "shaft"}, {"alphaMode", "BLEND"}, {"doubleSided", true},
                        {"emissiveFactor", {1.0, 0.8, 0.3}},
                        {"pbrMetallicRoughness", {{"baseColorFactor", {1.0, 1.0, 1.0, 0.1}}}}};
    write_json(dir / "bare.gltf", room(dir, kLamp));
    write_json(dir / "shaft.gltf", room(dir, kLamp, shaft));
    const json bare = bake_ok(dir, dir / "bare.gltf", dir / "bare");
    const json seen = bake_ok(dir, dir / "shaft.gltf", dir / "seen");
    CHECK(seen["effects"]["see_through"]["on"] == true);
    CHECK(floor_radiosity(seen) == Approx(floor_radiosity(bare)).epsilon(1e-12));
    CHECK(seen["energy"]["emitted"].get<double>() == Approx(bare["energy"]["emitted"].get<double>()).epsilon(1e-12));
    // Forced opaque, it lights the floor as the glowing slab the exporter's file describes.
    const json opaque = bake_ok(dir, dir / "shaft.gltf", dir / "opaque", concat(kFast, {"--effects", "see_through=off"}));
    CHECK(floor_radiosity(opaque) > 1.5 * floor_radiosity(bare));
    // Alone, it lights nothing: the scene has no light to bake, and the error says what to do.
    json dark = kLamp;
    dark.erase("emissiveFactor");
    write_json(dir / "alone.gltf", room(dir, dark, shaft));
    const RunResult r = run_hemirad(dir, bake_args(dir / "alone.gltf", dir / "out"));
    INFO(r.err);
    CHECK(r.code == 2);
    CHECK(r.err.find("alone.gltf: nothing emits light once see-through surfaces are left out") != std::string::npos);
    // First: add the light the glows stand beside (a sun, a sky), naming the glows; only then
    // bake the glows themselves.
    CHECK(r.err.find("1 glow material ('shaft')") != std::string::npos);
    const std::size_t sun = r.err.find("--sun "), sky = r.err.find("--sky "), off = r.err.find("--effects see_through=off");
    CHECK(sun != std::string::npos);
    CHECK(sky != std::string::npos);
    CHECK(off != std::string::npos);
    CHECK(sun < off);
    CHECK(sky < off);
    CHECK(!fs::exists(dir / "out"));
}

TEST_CASE("a scene with no emissive material and only dark lights is refused, counting them", "[see_through][cli]") {
    TempDir dir;
    json dark = kLamp;
    dark.erase("emissiveFactor");
    json g = room(dir, dark);
    g["extensionsUsed"] = {"KHR_lights_punctual"};
    g["extensions"]["KHR_lights_punctual"]["lights"] = {{{"type", "directional"}, {"intensity", 0.0}},
                                                         {{"type", "spot"}, {"intensity", 0.0}, {"spot", {{"outerConeAngle", 0.7}}}}};
    g["nodes"].push_back({{"name", "sun"}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
    g["nodes"].push_back({{"name", "spot"}, {"translation", {0, 0.8, 0}},
                          {"extensions", {{"KHR_lights_punctual", {{"light", 1}}}}}});
    g["scenes"][0]["nodes"] = {0, 1, 2, 3};
    write_json(dir / "bulbs.gltf", g);
    const RunResult r = run_hemirad(dir, bake_args(dir / "bulbs.gltf", dir / "out"));
    INFO(r.err);
    CHECK(r.code == 2);
    CHECK(r.err.find("bulbs.gltf: nothing emits light: 0 emissive triangles") != std::string::npos);
    CHECK(r.err.find("0 KHR_lights_punctual lights of intensity > 0 (of 2)") != std::string::npos);
    CHECK(r.err.find("--sun AZIMUTH,ELEVATION,LUX") != std::string::npos);
    CHECK(!fs::exists(dir / "out"));
}

TEST_CASE("a blended material's opacity is its alpha factor times its texture's mean alpha", "[see_through]") {
    TempDir dir;
    // 2 x 2 RGBA texels with alpha 0, 0, 1 and 0.2 (stored linear): a mean of 0.3, times 0.8.
    const unsigned char texels[16] = {200, 200, 200, 0, 200, 200, 200, 0, 200, 200, 200, 255, 200, 200, 200, 51};
    {
        auto out = OIIO::ImageOutput::create((dir / "leaf.png").string());
        REQUIRE(out);
        REQUIRE(out->open((dir / "leaf.png").string(), OIIO::ImageSpec(2, 2, 4, OIIO::TypeDesc::UINT8)));
        REQUIRE(out->write_image(OIIO::TypeDesc::UINT8, texels));
        REQUIRE(out->close());
    }
    const json leaf = {{"name", "leaf"}, {"alphaMode", "BLEND"},
                       {"pbrMetallicRoughness", {{"baseColorFactor", {1.0, 1.0, 1.0, 0.8}},
                                                 {"baseColorTexture", {{"index", 0}}}}}};
    json g = room(dir, kLamp, leaf);
    g["images"] = {{{"uri", "leaf.png"}}};
    g["textures"] = {{{"source", 0}}};
    write_json(dir / "leaf.gltf", g);
    const hemirad::scene::Scene scene = hemirad::scene::load(dir / "leaf.gltf");
    REQUIRE(scene.materials.size() == 3);
    CHECK(scene.materials[2].see_through == "alphaMode BLEND, mean opacity 0.24");
    CHECK(scene.materials[0].see_through.empty());
}
