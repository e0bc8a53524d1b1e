// Small glTF scenes of axis-aligned rectangles and punctual lights, written as JSON with their
// buffer beside them, for tests through `hemirad bake`; and readers of report.json's meshes.
#pragma once

#include <algorithm>
#include <array>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "cli_support.h"

namespace hemirad::test {

// One quad of a test scene: its corners (counter-clockwise seen from its front), texture
// coordinates (written as TEXCOORD_0 when any quad of the scene has them), node name and
// material index.
struct Quad {
    std::array<glm::dvec3, 4> p;
    std::vector<glm::dvec2> uv;  // 4, or none
    std::string name;
    int material;
};

// A glTF of quads, each its own node and mesh (two triangles, 0 1 2 and 0 2 3), its buffer
// in dir/scene.bin.
inline json quad_scene(const TempDir& dir, const std::vector<Quad>& quads, const json& materials) {
    const bool uvs = std::any_of(quads.begin(), quads.end(), [](const Quad& q) { return !q.uv.empty(); });
    std::vector<float> data;
    for (const Quad& q : quads)
        for (const glm::dvec3& p : q.p) data.insert(data.end(), {float(p.x), float(p.y), float(p.z)});
    const std::size_t uv_offset = data.size() * 4;
    for (const Quad& q : quads) {
        REQUIRE(q.uv.size() == (uvs ? 4u : 0u));
        for (const glm::dvec2& uv : q.uv) data.insert(data.end(), {float(uv.x), float(uv.y)});
    }
    const std::vector<std::uint16_t> indices = {0, 1, 2, 0, 2, 3};
    std::string bytes(reinterpret_cast<const char*>(data.data()), data.size() * 4);
    const std::size_t index_offset = bytes.size();
    bytes.append(reinterpret_cast<const char*>(indices.data()), indices.size() * 2);
    write_text(dir / "scene.bin", bytes);
    json g = {{"asset", {{"version", "2.0"}}},
              {"scene", 0},
              {"scenes", {{{"nodes", json::array()}}}},
              {"nodes", json::array()},
              {"meshes", json::array()},
              {"materials", materials},
              {"accessors", {{{"bufferView", 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}}},
              {"bufferViews", {{{"buffer", 0}, {"byteLength", uv_offset}},
                               {{"buffer", 0}, {"byteOffset", index_offset}, {"byteLength", 12}}}},
              {"buffers", {{{"byteLength", bytes.size()}, {"uri", "scene.bin"}}}}};
    if (uvs)
        g["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", uv_offset}, {"byteLength", index_offset - uv_offset}});
    for (std::size_t q = 0; q < quads.size(); ++q) {
        const int position = int(g["accessors"].size());
        g["accessors"].push_back({{"bufferView", 0}, {"byteOffset", 48 * q}, {"componentType", 5126}, {"count", 4},
                                  {"type", "VEC3"}, {"min", {-9, -9, -9}}, {"max", {9, 9, 9}}});
        json attributes = {{"POSITION", position}};
        if (uvs) {
            g["accessors"].push_back({{"bufferView", 2}, {"byteOffset", 32 * q}, {"componentType", 5126}, {"count", 4},
                                      {"type", "VEC2"}});
            attributes["TEXCOORD_0"] = position + 1;
        }
        const json primitive = {{"attributes", attributes}, {"indices", 0}, {"material", quads[q].material}};
        g["meshes"].push_back({{"primitives", json::array({primitive})}});
        g["nodes"].push_back({{"name", quads[q].name}, {"mesh", q}});
        g["scenes"][0]["nodes"].push_back(q);
    }
    return g;
}

// An axis-aligned rectangle [x0, x1] × [z0, z1] at height y, facing up or down.
struct Rect {
    std::string name;
    double x0, x1, z0, z1, y;
    bool up;
    int material;
};

// A glTF of rectangles (quad_scene) and KHR_lights_punctual lights placed by `light_nodes`
// (none: both empty), its buffer in `dir`.
inline json rect_scene(const TempDir& dir, const std::vector<Rect>& rects, const json& materials,
                       const json& lights = json::array(), const json& light_nodes = json::array()) {
    std::vector<Quad> quads;
    for (const Rect& r : rects) {
        const std::array<glm::dvec3, 4> up = {glm::dvec3(r.x0, r.y, r.z0), glm::dvec3(r.x0, r.y, r.z1),
                                              glm::dvec3(r.x1, r.y, r.z1), glm::dvec3(r.x1, r.y, r.z0)};
        Quad q{{}, {}, r.name, r.material};
        for (std::size_t i = 0; i < 4; ++i) q.p[i] = up[r.up ? i : (4 - i) % 4];
        quads.push_back(q);
    }
    json g = quad_scene(dir, quads, materials);
    if (!lights.empty()) {
        g["extensionsUsed"] = {"KHR_lights_punctual"};
        g["extensions"] = {{"KHR_lights_punctual", {{"lights", lights}}}};
    }
    for (const json& n : light_nodes) {
        g["scenes"][0]["nodes"].push_back(g["nodes"].size());
        g["nodes"].push_back(n);
    }
    return g;
}

inline const json& mesh_named(const json& report, const std::string& name) {
    for (const json& m : report["meshes"])
        if (m["name"] == name) return m;
    FAIL("no mesh '" << name << "' in the report");
    return report;
}
inline double irradiance(const json& report, const std::string& name) {
    return mesh_named(report, name)["irradiance"][0].get<double>();
}
inline double radiosity(const json& report, const std::string& name) {
    return mesh_named(report, name)["radiosity"][0].get<double>();
}

}  // namespace hemirad::test
