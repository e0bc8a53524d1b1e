// Scene → glTF 2.0: a .gltf (JSON) and one .bin of float32 positions and colours.
#include "scene/writer.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/error.h"

namespace hemirad::scene {
namespace {

using nlohmann::json;

void append_floats(std::vector<unsigned char>& bin, const std::vector<float>& values) {
    const std::size_t at = bin.size();
    bin.resize(at + values.size() * sizeof(float));
    std::memcpy(bin.data() + at, values.data(), values.size() * sizeof(float));
}

// Adds a float VEC3 accessor over `values` (3 per vertex) and returns its index.
int add_vec3_accessor(json& gltf, std::vector<unsigned char>& bin, const std::vector<float>& values, bool bounds) {
    const std::size_t offset = bin.size();
    append_floats(bin, values);
    gltf["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", values.size() * sizeof(float)}});
    json accessor = {{"bufferView", gltf["bufferViews"].size() - 1},
                     {"componentType", 5126},
                     {"count", values.size() / 3},
                     {"type", "VEC3"}};
    if (bounds) {
        std::vector<float> lo(3, 0.0f), hi(3, 0.0f);
        for (std::size_t i = 0; i < values.size(); ++i) {
            const std::size_t c = i % 3;
            lo[c] = i < 3 ? values[i] : std::min(lo[c], values[i]);
            hi[c] = i < 3 ? values[i] : std::max(hi[c], values[i]);
        }
        accessor["min"] = lo;
        accessor["max"] = hi;
    }
    gltf["accessors"].push_back(accessor);
    return static_cast<int>(gltf["accessors"].size() - 1);
}

json material_json(const Material& m, bool colour_from_vertices) {
    const glm::dvec3 base = colour_from_vertices ? glm::dvec3(1.0) : m.base_color;
    const double peak = std::max({m.emission.x, m.emission.y, m.emission.z});
    const double strength = peak > 1.0 ? peak : 1.0;
    json out = {{"name", m.name},
                {"doubleSided", m.double_sided},
                {"pbrMetallicRoughness", {{"baseColorFactor", {base.x, base.y, base.z, 1.0}}, {"metallicFactor", 0.0}}},
                {"emissiveFactor", {m.emission.x / strength, m.emission.y / strength, m.emission.z / strength}}};
    if (strength > 1.0) out["extensions"]["KHR_materials_emissive_strength"] = {{"emissiveStrength", strength}};
    return out;
}

// The binary container: a 12-byte header, the JSON chunk padded with spaces and the BIN chunk
// padded with zeros, each to 4 bytes, as glTF 2.0 requires.
void write_glb(json& gltf, std::vector<unsigned char>& bin, const std::filesystem::path& file) {
    bin.resize((bin.size() + 3) / 4 * 4, 0);
    gltf["buffers"] = json::array({json{{"byteLength", bin.size()}}});
    std::string text = gltf.dump();
    text.resize((text.size() + 3) / 4 * 4, ' ');
    const auto u32 = [](std::size_t v) { return static_cast<std::uint32_t>(v); };
    const std::uint32_t header[3] = {0x46546C67u, 2u, u32(12 + 8 + text.size() + 8 + bin.size())};  // "glTF"
    const std::uint32_t json_chunk[2] = {u32(text.size()), 0x4E4F534Au};                           // "JSON"
    const std::uint32_t bin_chunk[2] = {u32(bin.size()), 0x004E4942u};                             // "BIN\0"
    std::ofstream out(file, std::ios::binary);
    out.write(reinterpret_cast<const char*>(header), sizeof header);
    out.write(reinterpret_cast<const char*>(json_chunk), sizeof json_chunk);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    out.write(reinterpret_cast<const char*>(bin_chunk), sizeof bin_chunk);
    out.write(reinterpret_cast<const char*>(bin.data()), static_cast<std::streamsize>(bin.size()));
    out.flush();
    if (!out) throw InternalError(fmt::format("{}: could not write the scene", file.string()));
}

}  // namespace

void write_gltf(const Scene& scene, const std::filesystem::path& file) {
    // Which materials need per-vertex colour: some triangle's reflectance is not the base colour.
    std::vector<bool> vertex_colour(scene.materials.size(), false);
    for (const Triangle& t : scene.triangles)
        for (const glm::dvec3& rho : t.rho)
            if (rho != scene.materials.at(t.material).base_color) vertex_colour[t.material] = true;

    json gltf = {{"asset", {{"version", "2.0"}, {"generator", "hemirad scene::write_gltf"}}},
                 {"scene", 0},
                 {"scenes", json::array({json{{"nodes", json::array()}}})},
                 {"nodes", json::array()},
                 {"meshes", json::array()},
                 {"materials", json::array()},
                 {"accessors", json::array()},
                 {"bufferViews", json::array()}};
    bool uses_strength = false;
    for (std::size_t m = 0; m < scene.materials.size(); ++m) {
        gltf["materials"].push_back(material_json(scene.materials[m], vertex_colour[m]));
        uses_strength = uses_strength || gltf["materials"].back().contains("extensions");
    }
    if (uses_strength) gltf["extensionsUsed"] = {"KHR_materials_emissive_strength"};

    // Triangles by node, then material, in one pass: a scan per node would be quadratic in a
    // generated scene's thousands of objects.
    std::vector<std::map<std::uint32_t, std::vector<const Triangle*>>> by_node(scene.nodes.size());
    for (const Triangle& t : scene.triangles) by_node.at(t.node)[t.material].push_back(&t);
    std::vector<unsigned char> bin;
    for (std::size_t n = 0; n < scene.nodes.size(); ++n) {
        const std::map<std::uint32_t, std::vector<const Triangle*>>& by_material = by_node[n];
        json primitives = json::array();
        for (const auto& [material, triangles] : by_material) {
            std::vector<float> positions, colours;
            for (const Triangle* t : triangles)
                for (int k = 0; k < 3; ++k)
                    for (int c = 0; c < 3; ++c) {
                        positions.push_back(static_cast<float>(t->p[k][c]));
                        colours.push_back(static_cast<float>(t->rho[k][c]));
                    }
            json attributes = {{"POSITION", add_vec3_accessor(gltf, bin, positions, true)}};
            if (vertex_colour[material]) attributes["COLOR_0"] = add_vec3_accessor(gltf, bin, colours, false);
            primitives.push_back({{"attributes", attributes}, {"material", material}, {"mode", 4}});
        }
        if (primitives.empty()) continue;
        gltf["meshes"].push_back({{"name", scene.nodes[n].name}, {"primitives", primitives}});
        gltf["nodes"].push_back({{"name", scene.nodes[n].name}, {"mesh", gltf["meshes"].size() - 1}});
        gltf["scenes"][0]["nodes"].push_back(gltf["nodes"].size() - 1);
    }
    // Cameras as nodes of their own, so a bake of the file renders the view the scene was made with.
    for (const Camera& c : scene.cameras) {
        json perspective = {{"yfov", c.yfov}, {"znear", c.znear}};
        if (c.aspect > 0.0) perspective["aspectRatio"] = c.aspect;
        gltf["cameras"].push_back({{"name", c.name}, {"type", "perspective"}, {"perspective", perspective}});
        json matrix = json::array();  // column-major, as glm stores it
        for (int col = 0; col < 4; ++col)
            for (int row = 0; row < 4; ++row) matrix.push_back(c.camera_to_world[col][row]);
        gltf["nodes"].push_back({{"name", c.name}, {"camera", gltf["cameras"].size() - 1}, {"matrix", matrix}});
        gltf["scenes"][0]["nodes"].push_back(gltf["nodes"].size() - 1);
    }
    if (file.extension() == ".glb") return write_glb(gltf, bin, file);
    const std::filesystem::path bin_file = std::filesystem::path(file).replace_extension(".bin");
    gltf["buffers"] = json::array({json{{"uri", bin_file.filename().string()}, {"byteLength", bin.size()}}});

    std::ofstream out_bin(bin_file, std::ios::binary);
    out_bin.write(reinterpret_cast<const char*>(bin.data()), static_cast<std::streamsize>(bin.size()));
    std::ofstream out(file);
    out << gltf.dump(1);
    if (!out_bin || !out) throw InternalError(fmt::format("{}: could not write the scene", file.string()));
}

}  // namespace hemirad::scene
