// baked.gltf as the user's own scene (--output-mode scene, the default): the file's node tree,
// names, transforms, cameras, materials and textures kept; each baked primitive refined, its
// vertices on the file's surfaces with the file's attributes interpolated (checked against the
// texture coordinates' closed form in position), its light in _RADIOSITY and _IRRADIANCE, and
// COLOR_0 what a viewer multiplies with the unlit material.
#include <catch2/catch.hpp>
#include <tiny_gltf.h>

#include <cmath>
#include <cstring>
#include <string>

#include <glm/gtc/matrix_transform.hpp>

#include "cli_support.h"
#include "output/output.h"
#include "rect_scenes.h"
#include "scene/scene.h"

namespace {

using namespace hemirad::test;
using glm::dvec3;

// Four quads, each its own mesh of two triangles (0 1 2, 0 2 3) with POSITION, NORMAL and
// TEXCOORD_0; a 2 x 2 PNG the floor's material reads; the buffer in dir/scene.bin.
json scene_with_tree(const TempDir& dir) {
    struct Q {
        std::array<glm::vec3, 4> p;
        glm::vec3 n;
        std::array<glm::vec2, 4> uv;
    };
    // Local coordinates. The floor: y = −1 under "room" (translated by +1 in y), uv = ((x + 1) / 2, (z + 1) / 2).
    const std::vector<Q> quads = {
        {{{{-1, -1, -1}, {-1, -1, 1}, {1, -1, 1}, {1, -1, -1}}}, {0, 1, 0}, {{{0, 0}, {0, 1}, {1, 1}, {1, 0}}}},
        {{{{-0.3f, 1, -0.3f}, {0.3f, 1, -0.3f}, {0.3f, 1, 0.3f}, {-0.3f, 1, 0.3f}}}, {0, -1, 0}, {}},  // the lamp, facing down
        {{{{0, 0.2f, 0}, {0.6f, 0.2f, 0}, {0.6f, 0.8f, 0}, {0, 0.8f, 0}}}, {0, 0, 1}, {}},              // the card, facing +z
        {{{{-0.5f, 0.1f, 0.5f}, {0.5f, 0.1f, 0.5f}, {0.5f, 0.9f, 0.5f}, {-0.5f, 0.9f, 0.5f}}}, {0, 0, 1}, {}}};  // the glass
    std::string bytes;
    const auto put = [&](const void* p, std::size_t n) { bytes.append(static_cast<const char*>(p), n); };
    json accessors = json::array(), views = json::array(), meshes = json::array();
    const std::uint16_t indices[6] = {0, 1, 2, 0, 2, 3};
    const int materials[4] = {1, 0, 2, 3};
    for (std::size_t q = 0; q < quads.size(); ++q) {
        const std::size_t at = bytes.size();
        put(quads[q].p.data(), 48);
        for (int i = 0; i < 4; ++i) put(&quads[q].n, 12);
        put(quads[q].uv.data(), 32);
        put(indices, 12);
        views.push_back({{"buffer", 0}, {"byteOffset", at}, {"byteLength", 48}});
        views.push_back({{"buffer", 0}, {"byteOffset", at + 48}, {"byteLength", 48}});
        views.push_back({{"buffer", 0}, {"byteOffset", at + 96}, {"byteLength", 32}});
        views.push_back({{"buffer", 0}, {"byteOffset", at + 128}, {"byteLength", 12}});
        const int v = int(4 * q), a = int(accessors.size());
        accessors.push_back({{"bufferView", v}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"},
                             {"min", {-1, -1, -1}}, {"max", {1, 1, 1}}});
        accessors.push_back({{"bufferView", v + 1}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}});
        accessors.push_back({{"bufferView", v + 2}, {"componentType", 5126}, {"count", 4}, {"type", "VEC2"}});
        accessors.push_back({{"bufferView", v + 3}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}});
        const json primitive = {{"attributes", {{"POSITION", a}, {"NORMAL", a + 1}, {"TEXCOORD_0", a + 2}}},
                                {"indices", a + 3},
                                {"material", materials[q]}};
        meshes.push_back({{"primitives", json::array({primitive})}});
    }
    write_text(dir / "scene.bin", bytes);
    // A 2 x 2 checker (opaque RGB, 8 bits): written as a PNG by OpenImageIO through hemirad's writer.
    hemirad::output::Image checks{2, 2, {0.9f, 0.9f, 0.9f, 0.1f, 0.1f, 0.1f, 0.1f, 0.1f, 0.1f, 0.9f, 0.9f, 0.9f}};
    hemirad::output::write_png(checks, dir / "checks.png", 1.0);
    json g;
    g["asset"] = {{"version", "2.0"}, {"extras", {{"author", "test"}}}};
    g["extensionsUsed"] = {"KHR_texture_transform", "KHR_materials_emissive_strength"};
    g["scene"] = 0;
    g["scenes"] = json::array({{{"nodes", {0, 5}}}});
    g["nodes"] = json::array();
    g["nodes"].push_back({{"name", "room"}, {"translation", {0, 1, 0}}, {"children", {1, 2, 3, 4}}, {"extras", {{"tag", 7}}}});
    g["nodes"].push_back({{"name", "floor"}, {"mesh", 0}});
    g["nodes"].push_back({{"name", "lamp"}, {"mesh", 1}});
    g["nodes"].push_back({{"name", "mirrored"}, {"mesh", 2}, {"translation", {0.5, -1, 0}}, {"scale", {-1, 1, 1}}});
    g["nodes"].push_back({{"name", "glass"}, {"mesh", 3}, {"translation", {0, -1, -0.2}}});
    g["nodes"].push_back({{"name", "eye"}, {"camera", 0}, {"translation", {0, 1, 3}}});
    g["cameras"] = json::array();
    g["cameras"].push_back({{"name", "view"}, {"type", "perspective"}, {"perspective", {{"yfov", 0.9}, {"znear", 0.01}}}});
    g["meshes"] = meshes;
    json lamp = {{"name", "lamp"}, {"emissiveFactor", {1, 1, 1}}};
    lamp["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] = 5.0;
    json floor_material = {{"name", "floor"}};
    floor_material["pbrMetallicRoughness"]["baseColorFactor"] = {0.8, 0.8, 0.8, 1};
    floor_material["pbrMetallicRoughness"]["baseColorTexture"]["index"] = 0;
    floor_material["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]["KHR_texture_transform"]["scale"] = {2, 2};
    json card = {{"name", "card"}, {"doubleSided", true}};
    card["pbrMetallicRoughness"]["baseColorFactor"] = {0.5, 0.6, 0.7, 1};
    json glass = {{"name", "glass"}, {"alphaMode", "BLEND"}};
    glass["pbrMetallicRoughness"]["baseColorFactor"] = {0.9, 0.9, 1, 0.2};
    g["materials"] = json::array({lamp, floor_material, card, glass});
    g["textures"] = json::array({{{"source", 0}, {"sampler", 0}}});
    g["samplers"] = json::array({{{"magFilter", 9728}}});
    g["images"] = json::array({{{"uri", "checks.png"}}});
    g["accessors"] = accessors;
    g["bufferViews"] = views;
    g["buffers"] = json::array({{{"byteLength", bytes.size()}, {"uri", "scene.bin"}}});
    return g;
}

tinygltf::Model load_model(const fs::path& file) {
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err, warn;
    const bool ok = loader.LoadASCIIFromFile(&model, &err, &warn, file.string());
    INFO(err << warn);
    REQUIRE(ok);
    return model;
}

// A float or unsigned-int accessor's values, `comps` per element.
template <class T>
std::vector<T> values(const tinygltf::Model& m, int index, int comps) {
    const tinygltf::Accessor& a = m.accessors.at(std::size_t(index));
    const tinygltf::BufferView& v = m.bufferViews.at(std::size_t(a.bufferView));
    std::vector<T> out(a.count * std::size_t(comps));
    REQUIRE(v.byteStride == 0);
    REQUIRE(v.byteOffset + a.byteOffset + out.size() * sizeof(T) <= m.buffers.at(std::size_t(v.buffer)).data.size());
    std::memcpy(out.data(), m.buffers[std::size_t(v.buffer)].data.data() + v.byteOffset + a.byteOffset, out.size() * sizeof(T));
    return out;
}

const tinygltf::Mesh& mesh_of(const tinygltf::Model& m, const std::string& node) {
    for (const tinygltf::Node& n : m.nodes)
        if (n.name == node) {
            REQUIRE(n.mesh >= 0);
            return m.meshes.at(std::size_t(n.mesh));
        }
    FAIL("no node " << node);
    return m.meshes.at(0);
}

}  // namespace

TEST_CASE("baked.gltf gives the user's scene back, refined, with the baked light in its vertices", "[output][cli]") {
    TempDir dir;
    write_json(dir / "tree.gltf", scene_with_tree(dir));
    const json report = bake_ok(dir, dir / "tree.gltf", dir / "out", {});
    CHECK(report["settings"]["output_mode"] == "scene");
    const tinygltf::Model m = load_model(dir / "out" / "baked.gltf");

    // The tree, names, transforms, extras and camera as they were.
    REQUIRE(m.nodes.size() == 6);
    CHECK(m.nodes[0].name == "room");
    CHECK(m.nodes[0].children == std::vector<int>{1, 2, 3, 4});
    CHECK(m.nodes[0].translation == std::vector<double>{0, 1, 0});
    CHECK(m.nodes[0].extras.Get("tag").GetNumberAsInt() == 7);
    CHECK(m.nodes[3].scale == std::vector<double>{-1, 1, 1});
    CHECK(m.nodes[5].camera == 0);
    REQUIRE(m.cameras.size() == 1);
    CHECK(m.cameras[0].name == "view");
    CHECK(m.asset.extras.Get("author").Get<std::string>() == "test");
    const double exposure = m.asset.extras.Get("hemirad").Get("exposure").GetNumberAsDouble();
    CHECK(exposure == Approx(report["settings"]["exposure"].get<double>()));

    // The file's materials at their indices; the image where it was, from the output directory.
    REQUIRE(m.materials.size() >= 4);
    CHECK(m.materials[1].name == "floor");
    REQUIRE(m.images.size() == 1);
    CHECK(fs::equivalent(dir / "out" / m.images[0].uri, dir / "checks.png"));
    CHECK(std::find(m.extensionsUsed.begin(), m.extensionsUsed.end(), "KHR_materials_unlit") != m.extensionsUsed.end());

    // The floor: refined, every vertex on the file's floor (world y = 0 under "room"), its
    // texture coordinates the file's, ((x + 1) / 2, (z + 1) / 2), under an unlit copy of its
    // material that keeps the texture and its transform.
    const tinygltf::Mesh& floor = mesh_of(m, "floor");
    REQUIRE(floor.primitives.size() == 1);
    const tinygltf::Primitive& fp = floor.primitives[0];
    const tinygltf::Material& unlit = m.materials.at(std::size_t(fp.material));
    CHECK(unlit.extensions.count("KHR_materials_unlit") == 1);
    CHECK(unlit.pbrMetallicRoughness.baseColorTexture.index == 0);
    CHECK(unlit.pbrMetallicRoughness.baseColorTexture.extensions.count("KHR_texture_transform") == 1);
    const std::vector<float> pos = values<float>(m, fp.attributes.at("POSITION"), 3);
    const std::vector<float> uv = values<float>(m, fp.attributes.at("TEXCOORD_0"), 2);
    const std::vector<float> colour = values<float>(m, fp.attributes.at("COLOR_0"), 3);
    const std::vector<float> b = values<float>(m, fp.attributes.at("_RADIOSITY"), 3);
    const std::vector<float> h = values<float>(m, fp.attributes.at("_IRRADIANCE"), 3);
    const std::vector<std::uint32_t> idx = values<std::uint32_t>(m, fp.indices, 1);
    const std::size_t n = pos.size() / 3;
    CHECK(n > 4);  // refined
    for (std::size_t i = 0; i < n; ++i) {
        INFO("vertex " << i);
        CHECK(pos[3 * i + 1] + 1.0 == Approx(0.0).margin(1e-6));
        CHECK(uv[2 * i] == Approx((pos[3 * i] + 1.0) / 2.0).margin(1e-5));
        CHECK(uv[2 * i + 1] == Approx((pos[3 * i + 2] + 1.0) / 2.0).margin(1e-5));
        CHECK(colour[3 * i] == Approx(hemirad::output::tone(exposure * h[3 * i])).epsilon(1e-5));
        CHECK(colour[3 * i] <= 1.0f);
        // Reflectance 0.8 × the checks' 0.1 to 0.867 (0.9 through render.png's tone curve).
        CHECK(b[3 * i] <= 0.8 * 0.87 * h[3 * i] + 1e-6);
        CHECK(b[3 * i] >= 0.8 * 0.099 * h[3 * i] - 1e-6);
    }
    // Its area-weighted light is the report's floor.
    double area = 0.0, light = 0.0;
    for (std::size_t t = 0; t < idx.size(); t += 3) {
        glm::dvec3 p[3];
        double mean = 0.0;
        for (int c = 0; c < 3; ++c) {
            const std::size_t v = idx[t + std::size_t(c)];
            p[c] = glm::dvec3(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]);
            mean += h[3 * v] / 3.0;
        }
        const glm::dvec3 normal = glm::cross(p[1] - p[0], p[2] - p[0]);
        CHECK(normal.y > 0.0);  // facing up, as the file's floor
        area += 0.5 * glm::length(normal);
        light += 0.5 * glm::length(normal) * mean;
    }
    CHECK(area == Approx(4.0).epsilon(1e-6));
    CHECK(light / area == Approx(irradiance(report, "floor")).epsilon(0.03));

    // The lamp emits: its COLOR_0 is its radiosity's, under a white unlit material.
    const tinygltf::Primitive& lp = mesh_of(m, "lamp").primitives.at(0);
    const std::vector<float> lamp_colour = values<float>(m, lp.attributes.at("COLOR_0"), 3);
    const std::vector<float> lamp_b = values<float>(m, lp.attributes.at("_RADIOSITY"), 3);
    CHECK(lamp_b[0] >= 5.0f);
    CHECK(lamp_colour[0] == Approx(hemirad::output::tone(exposure * lamp_b[0])).epsilon(1e-5));
    CHECK(m.materials.at(std::size_t(lp.material)).pbrMetallicRoughness.baseColorTexture.index == -1);

    // The double-sided card under a mirroring node: a primitive per side under a material that
    // is not doubleSided, each triangle's front (counter-clockwise after the node's transform,
    // clockwise as glTF reads a negative determinant) along its interpolated NORMAL.
    const tinygltf::Mesh& card = mesh_of(m, "mirrored");
    REQUIRE(card.primitives.size() == 2);
    const glm::dmat3 world = glm::dmat3(glm::scale(glm::dmat4(1.0), dvec3(-1, 1, 1)));
    for (const tinygltf::Primitive& p : card.primitives) {
        CHECK(!m.materials.at(std::size_t(p.material)).doubleSided);
        const std::vector<float> cp = values<float>(m, p.attributes.at("POSITION"), 3);
        const std::vector<float> cn = values<float>(m, p.attributes.at("NORMAL"), 3);
        const std::vector<std::uint32_t> ci = values<std::uint32_t>(m, p.indices, 1);
        for (std::size_t t = 0; t < ci.size(); t += 3) {
            dvec3 q[3];
            for (int c = 0; c < 3; ++c) {
                const std::size_t v = ci[t + std::size_t(c)];
                q[c] = world * dvec3(cp[3 * v], cp[3 * v + 1], cp[3 * v + 2]);
            }
            const dvec3 front = -glm::cross(q[1] - q[0], q[2] - q[0]);  // clockwise: determinant < 0
            const std::size_t v0 = ci[t];
            const dvec3 normal = glm::transpose(glm::inverse(world)) * dvec3(cn[3 * v0], cn[3 * v0 + 1], cn[3 * v0 + 2]);
            CHECK(glm::dot(front, normal) > 0.0);
        }
    }

    // The glass is see-through: not baked, copied as the file has it, under its own material.
    const tinygltf::Mesh& glass = mesh_of(m, "glass");
    REQUIRE(glass.primitives.size() == 1);
    CHECK(glass.primitives[0].material == 3);
    CHECK(glass.primitives[0].attributes.count("_RADIOSITY") == 0);
    CHECK(m.accessors.at(std::size_t(glass.primitives[0].attributes.at("POSITION"))).count == 4);

    // hemirad reads its own output (its unlit materials emit nothing: it is not a scene to bake again).
    const hemirad::scene::Scene again = hemirad::scene::load(dir / "out" / "baked.gltf");
    CHECK(again.nodes.size() == 4);
    CHECK(again.cameras.size() == 1);
}

TEST_CASE("the radiosity output mode (--output-mode radiosity) writes the element mesh alone", "[output][cli]") {
    TempDir dir;
    write_json(dir / "tree.gltf", scene_with_tree(dir));
    bake_ok(dir, dir / "tree.gltf", dir / "out", {"--output-mode", "radiosity"});
    const tinygltf::Model m = load_model(dir / "out" / "baked.gltf");
    CHECK(m.cameras.empty());
    CHECK(m.images.empty());
    for (const tinygltf::Node& node : m.nodes) {  // the scene's mesh nodes alone, flat
        CHECK(node.name != "room");
        CHECK(node.children.empty());
        if (node.mesh >= 0) CHECK(m.meshes.at(std::size_t(node.mesh)).primitives.at(0).attributes.count("COLOR_0") == 1);
    }
    const RunResult bad = run_hemirad(dir, bake_args(dir / "tree.gltf", dir / "bad", {"--output-mode", "both"}));
    CHECK(bad.code == 2);
}

TEST_CASE("attributes the loader does not read and that do not fit their buffers are left out of baked.gltf with a warning",
          "[output][cli]") {
    TempDir dir;
    json g = scene_with_tree(dir);
    g["accessors"][1]["bufferView"] = 99;           // the floor's NORMAL names no bufferView that exists
    g["accessors"][13]["count"] = 1000000000000000;  // the glass's NORMAL claims 10^15 elements of a 48-byte view
    g["accessors"][10]["count"] = 0;                 // the mirrored quad's TEXCOORD_0 is empty (glTF forbids it)
    g["accessors"][10]["byteOffset"] = 12;           // ... and starts past its view, as a web export's did
    write_json(dir / "broken.gltf", g);
    const json report = bake_ok(dir, dir / "broken.gltf", dir / "out", {});
    std::string warnings;
    for (const json& w : report["warnings"]) warnings += w.get<std::string>() + "\n";
    INFO(warnings);
    CHECK(warnings.find("baked.gltf: NORMAL of a primitive of node 'floor' left out: accessor 1 runs past its "
                        "bufferView") != std::string::npos);
    CHECK(warnings.find("baked.gltf: accessor 13 runs past its bufferView") != std::string::npos);
    CHECK(warnings.find("baked.gltf: TEXCOORD_0 of a primitive of node 'mirrored' left out: accessor 10 has no "
                        "elements (count 0, which glTF does not allow)") != std::string::npos);
    const tinygltf::Model m = load_model(dir / "out" / "baked.gltf");
    const tinygltf::Primitive& floor = mesh_of(m, "floor").primitives.at(0);
    CHECK(floor.attributes.count("NORMAL") == 0);
    CHECK(floor.attributes.count("TEXCOORD_0") == 1);
    for (const tinygltf::Node& node : m.nodes)  // its copy could not be read whole: no mesh (glTF forbids an empty one)
        if (node.name == "glass") CHECK(node.mesh == -1);
}
