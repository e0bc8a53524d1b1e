// Counting what a glTF file asks the loader for, from its JSON alone (see load_estimate.h).
#include "scene/load_estimate.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/error.h"
#include "core/memory.h"
#include "scene/gltf_source.h"
#include "scene/scene.h"

namespace hemirad::scene {
namespace {

using json = nlohmann::json;

// What the loader holds per vertex while it reads a primitive (scene.cpp add_primitive): the
// positions and colours as dvec3, texture coordinates as dvec2 (two sets at most), indices as
// 32-bit ints.
constexpr double kPositionBytes = 24.0, kColourBytes = 24.0, kTexcoordBytes = 16.0, kIndexBytes = 4.0;

// doc[key][index] when that is an object, else null.
const json* item(const json& doc, const char* key, double index) {
    if (!doc.is_object() || index < 0.0) return nullptr;
    const auto list = doc.find(key);
    if (list == doc.end() || !list->is_array() || index >= double(list->size())) return nullptr;
    const json& x = (*list)[std::size_t(index)];
    return x.is_object() ? &x : nullptr;
}

// A non-negative number under `key` of an object, else `otherwise`.
double number(const json* obj, const char* key, double otherwise = -1.0) {
    if (!obj || !obj->is_object()) return otherwise;
    const auto x = obj->find(key);
    if (x == obj->end() || !x->is_number()) return otherwise;
    const double v = x->get<double>();
    return v >= 0.0 ? v : otherwise;
}

double element_bytes(const json& accessor) {
    const double component = [&] {
        switch (int(number(&accessor, "componentType", 0.0))) {
            case 5120: case 5121: return 1.0;
            case 5122: case 5123: return 2.0;
            default: return 4.0;  // 5125, 5126, or invalid (the loader refuses it)
        }
    }();
    const auto type = accessor.find("type");
    const std::string t = type != accessor.end() && type->is_string() ? type->get<std::string>() : "VEC4";
    const double components = t == "SCALAR" ? 1 : t == "VEC2" ? 2 : t == "VEC3" ? 3 : t == "MAT3" ? 9 : t == "MAT4" ? 16 : 4;
    return component * components;
}

// The elements of accessor `index`, and the bytes the loader makes of it whole (a sparse accessor,
// or one without a bufferView: scene.cpp materialize).
struct AccessorCount {
    double count = 0.0, whole_bytes = 0.0;
};
AccessorCount accessor(const json& doc, double index) {
    const json* a = item(doc, "accessors", index);
    if (!a) return {};
    AccessorCount c;
    c.count = number(a, "count", 0.0);
    if (a->contains("sparse") || !a->contains("bufferView")) c.whole_bytes = c.count * element_bytes(*a);
    return c;
}

// A mesh's triangles, the bytes its Draco primitives decode into, and its largest primitive's
// working copies.
struct MeshCount {
    double triangles = 0.0, decoded = 0.0, working = 0.0, whole = 0.0;
};
MeshCount count_mesh(const json& doc, const json& mesh) {
    MeshCount m;
    const auto primitives = mesh.find("primitives");
    if (primitives == mesh.end() || !primitives->is_array()) return m;
    for (const json& p : *primitives) {
        if (!p.is_object()) continue;
        const double mode = number(&p, "mode", 4.0);
        const auto attributes = p.find("attributes");
        if (mode != 4.0 || attributes == p.end() || !attributes->is_object()) continue;
        const auto attribute = [&](const char* name) {
            const auto a = attributes->find(name);
            return a != attributes->end() && a->is_number() ? accessor(doc, a->get<double>()) : AccessorCount{};
        };
        const AccessorCount position = attribute("POSITION"), colour = attribute("COLOR_0");
        const AccessorCount indices = p.contains("indices") ? accessor(doc, number(&p, "indices")) : AccessorCount{};
        const bool indexed = p.contains("indices");
        const bool draco = p.contains("extensions") && p["extensions"].is_object() &&
                           p["extensions"].contains("KHR_draco_mesh_compression");
        // (A Draco primitive's indices accessor declares the count its decoded indices have.)
        const double triangle_corners = indexed ? indices.count : position.count;
        m.triangles += std::floor(triangle_corners / 3.0);
        double texcoords = 0.0;
        for (const char* set : {"TEXCOORD_0", "TEXCOORD_1"}) texcoords += attribute(set).count;
        const double working = position.count * kPositionBytes + colour.count * kColourBytes +
                               texcoords * kTexcoordBytes + triangle_corners * kIndexBytes;
        m.working = std::max(m.working, working);
        if (draco) {
            // Decoded into buffers of its own, kept: each attribute as floats, the indices as ints.
            double decoded = triangle_corners * kIndexBytes;
            for (const auto& [name, index] : attributes->items())
                if (index.is_number()) {
                    const json* a = item(doc, "accessors", index.get<double>());
                    if (a) decoded += number(a, "count", 0.0) * element_bytes(*a);
                }
            m.decoded += decoded;
        } else {
            double whole = position.whole_bytes + colour.whole_bytes + indices.whole_bytes;
            for (const char* set : {"TEXCOORD_0", "TEXCOORD_1"}) whole += attribute(set).whole_bytes;
            m.whole = std::max(m.whole, whole);  // made whole while the primitive is read, then freed
        }
    }
    return m;
}

// The nodes the loader places: those below the default scene's roots (every node nobody names as
// a child where the file has no scenes), each once.
std::vector<std::size_t> placed_nodes(const json& doc) {
    const auto nodes = doc.find("nodes");
    if (nodes == doc.end() || !nodes->is_array()) return {};
    const std::size_t n = nodes->size();
    std::vector<double> roots;
    if (const json* scene = item(doc, "scenes", number(&doc, "scene", 0.0))) {
        if (const auto r = scene->find("nodes"); r != scene->end() && r->is_array())
            for (const json& x : *r)
                if (x.is_number()) roots.push_back(x.get<double>());
    } else if (!doc.contains("scenes")) {
        std::vector<char> child(n, 0);
        for (const json& node : *nodes)
            if (node.is_object() && node.contains("children") && node["children"].is_array())
                for (const json& c : node["children"])
                    if (c.is_number() && c.get<double>() >= 0.0 && c.get<double>() < double(n)) child[c.get<std::size_t>()] = 1;
        for (std::size_t i = 0; i < n; ++i)
            if (!child[i]) roots.push_back(double(i));
    }
    std::vector<char> seen(n, 0);
    std::vector<std::size_t> out, stack;
    for (const double r : roots)
        if (r >= 0.0 && r < double(n)) stack.push_back(std::size_t(r));
    while (!stack.empty()) {
        const std::size_t i = stack.back();
        stack.pop_back();
        if (seen[i]) continue;  // a cycle or a second parent: the loader refuses the file
        seen[i] = 1;
        out.push_back(i);
        const json& node = (*nodes)[i];
        if (node.is_object() && node.contains("children") && node["children"].is_array())
            for (const json& c : node["children"])
                if (c.is_number() && c.get<double>() >= 0.0 && c.get<double>() < double(n)) stack.push_back(c.get<std::size_t>());
    }
    return out;
}

// EXT_meshopt_compression: a fallback buffer (no uri) is made as large as the views decoding
// into it reach, within its declared byteLength (gltf_compression.cpp decode_meshopt).
double meshopt_bytes(const json& doc) {
    const auto buffers = doc.find("buffers");
    const auto views = doc.find("bufferViews");
    if (buffers == doc.end() || !buffers->is_array() || views == doc.end() || !views->is_array()) return 0.0;
    std::vector<double> reach(buffers->size(), 0.0);
    for (const json& v : *views) {
        if (!v.is_object() || !v.contains("extensions") || !v["extensions"].is_object() ||
            !v["extensions"].contains("EXT_meshopt_compression"))
            continue;
        const double b = number(&v, "buffer");
        if (b >= 0.0 && b < double(reach.size()))
            reach[std::size_t(b)] = std::max(reach[std::size_t(b)], number(&v, "byteOffset", 0.0) + number(&v, "byteLength", 0.0));
    }
    double total = 0.0;
    for (std::size_t b = 0; b < buffers->size(); ++b) {
        const json& buffer = (*buffers)[b];
        if (!buffer.is_object() || buffer.contains("uri")) continue;
        total += std::min(reach[b], number(&buffer, "byteLength", 0.0));
    }
    return total;
}

void check_integers(const json& value, const std::string& path, const std::string& name) {
    if (value.is_number_integer()) {
        const bool fits = value.is_number_unsigned()
                              ? value.get<std::uint64_t>() <= std::uint64_t(std::numeric_limits<std::int32_t>::max())
                              : value.get<std::int64_t>() >= std::numeric_limits<std::int32_t>::min() &&
                                    value.get<std::int64_t>() <= std::numeric_limits<std::int32_t>::max();
        if (!fits)
            throw InputError(fmt::format("{}: {} is {}, too large (an extension's integers must fit in 32 bits)", name,
                                         path, value.dump()));
    } else if (value.is_object()) {
        for (const auto& [key, x] : value.items()) check_integers(x, path + "." + key, name);
    } else if (value.is_array()) {
        for (std::size_t i = 0; i < value.size(); ++i) check_integers(value[i], fmt::format("{}[{}]", path, i), name);
    }
}

// Every object of an extension hemirad reads, anywhere in `value`, checked whole. Others (and
// `extras`, an application's own data: 64-bit ids are common) are not read, so not refused.
void find_extensions(const json& value, const std::string& path, const std::string& name) {
    static const char* const kRead[] = {"EXT_meshopt_compression", "KHR_draco_mesh_compression",
                                        "KHR_texture_transform", "KHR_lights_punctual",
                                        "KHR_materials_emissive_strength", "KHR_mesh_quantization"};
    if (value.is_object()) {
        for (const auto& [key, x] : value.items()) {
            const std::string here = path.empty() ? key : path + "." + key;
            if (key == "extensions" && x.is_object()) {
                for (const auto& [extension, body] : x.items()) {
                    if (std::find(std::begin(kRead), std::end(kRead), extension) != std::end(kRead))
                        check_integers(body, here + "." + extension, name);
                    else
                        find_extensions(body, here + "." + extension, name);
                }
            } else if (key != "extras") {
                find_extensions(x, here, name);
            }
        }
    } else if (value.is_array()) {
        for (std::size_t i = 0; i < value.size(); ++i) find_extensions(value[i], fmt::format("{}[{}]", path, i), name);
    }
}

}  // namespace

std::string LoadEstimate::describe() const {
    std::string out = fmt::format("{:.3g} triangles after instancing {}", triangles, format_bytes(triangle_bytes));
    if (accessor_bytes > 0.0) out += ", sparse accessors made whole " + format_bytes(accessor_bytes);
    if (decoded_bytes > 0.0) out += ", decompressed buffers " + format_bytes(decoded_bytes);
    out += ", reading the largest primitive " + format_bytes(working_bytes);
    return out;
}

LoadEstimate estimate_load(const json& doc) {
    LoadEstimate e;
    if (!doc.is_object()) return e;
    const auto meshes = doc.find("meshes");
    std::vector<MeshCount> per_mesh;
    if (meshes != doc.end() && meshes->is_array())
        for (const json& m : *meshes) per_mesh.push_back(m.is_object() ? count_mesh(doc, m) : MeshCount{});
    std::vector<char> decoded(per_mesh.size(), 0);  // a mesh is decoded once, however often it is placed
    const auto nodes = doc.find("nodes");
    for (const std::size_t n : placed_nodes(doc)) {
        const double mesh = number(&(*nodes)[n], "mesh");
        if (mesh < 0.0 || mesh >= double(per_mesh.size())) continue;
        const MeshCount& m = per_mesh[std::size_t(mesh)];
        e.triangles += m.triangles;
        e.working_bytes = std::max(e.working_bytes, m.working);
        e.accessor_bytes = std::max(e.accessor_bytes, m.whole);
        if (!decoded[std::size_t(mesh)]) e.decoded_bytes += m.decoded;
        decoded[std::size_t(mesh)] = 1;
    }
    e.triangle_bytes = e.triangles * double(sizeof(Triangle));
    e.decoded_bytes += meshopt_bytes(doc);
    return e;
}

std::vector<std::filesystem::path> referenced_files(const json& doc, const std::filesystem::path& base_dir) {
    std::vector<std::filesystem::path> files;
    for (const char* list : {"buffers", "images"}) {
        const auto items = doc.is_object() ? doc.find(list) : doc.end();
        if (items == doc.end() || !items->is_array()) continue;
        for (const json& x : *items) {
            if (!x.is_object() || !x.contains("uri") || !x["uri"].is_string()) continue;
            const std::string uri = x["uri"].get<std::string>();
            if (uri.rfind("data:", 0) == 0 || uri.empty()) continue;
            files.push_back(base_dir / percent_decoded(uri));
        }
    }
    return files;
}

void check_extension_integers(const json& doc, const std::string& name) { find_extensions(doc, "", name); }

}  // namespace hemirad::scene
