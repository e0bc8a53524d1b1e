// Small glTF scenes of axis-aligned rectangles and punctual lights, written as JSON with their
// buffer beside them, for tests through `hemirad bake`; and readers of report.json's meshes.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "cli_support.h"

namespace hemirad::test {

// An axis-aligned rectangle [x0, x1] × [z0, z1] at height y, facing up or down.
struct Rect {
    std::string name;
    double x0, x1, z0, z1, y;
    bool up;
    int material;
};

// A glTF of rectangles (each its own node and mesh) and KHR_lights_punctual lights placed by
// `light_nodes` (none: both empty), its buffer in `dir`.
inline json rect_scene(const TempDir& dir, const std::vector<Rect>& rects, const json& materials,
                       const json& lights = json::array(), const json& light_nodes = json::array()) {
    std::vector<float> data;
    for (const Rect& r : rects) {
        const std::array<glm::dvec3, 4> up = {glm::dvec3(r.x0, r.y, r.z0), glm::dvec3(r.x0, r.y, r.z1),
                                              glm::dvec3(r.x1, r.y, r.z1), glm::dvec3(r.x1, r.y, r.z0)};
        for (int i = 0; i < 4; ++i) {
            const glm::dvec3& p = up[std::size_t(r.up ? i : (4 - i) % 4)];
            data.insert(data.end(), {float(p.x), float(p.y), float(p.z)});
        }
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
              {"bufferViews", {{{"buffer", 0}, {"byteLength", index_offset}},
                               {{"buffer", 0}, {"byteOffset", index_offset}, {"byteLength", 12}}}},
              {"buffers", {{{"byteLength", bytes.size()}, {"uri", "scene.bin"}}}}};
    if (!lights.empty()) {
        g["extensionsUsed"] = {"KHR_lights_punctual"};
        g["extensions"] = {{"KHR_lights_punctual", {{"lights", lights}}}};
    }
    for (std::size_t q = 0; q < rects.size(); ++q) {
        g["accessors"].push_back({{"bufferView", 0}, {"byteOffset", 48 * q}, {"componentType", 5126}, {"count", 4},
                                  {"type", "VEC3"}, {"min", {-9, -9, -9}}, {"max", {9, 9, 9}}});
        const json primitive = {{"attributes", {{"POSITION", q + 1}}}, {"indices", 0}, {"material", rects[q].material}};
        g["meshes"].push_back({{"primitives", json::array({primitive})}});
        g["nodes"].push_back({{"name", rects[q].name}, {"mesh", q}});
        g["scenes"][0]["nodes"].push_back(q);
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
