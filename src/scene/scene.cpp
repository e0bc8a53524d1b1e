// Loads a glTF 2.0 file (.gltf or .glb) into world-space triangles with reflectance and
// emission, checking every index and byte range the file states before it is trusted.
#include "scene/scene.h"

#include <fmt/format.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "core/error.h"

namespace hemirad::scene {
namespace {

namespace fs = std::filesystem;
using glm::dmat4;
using glm::dvec3;

// Used for primitives without a material. glTF's default is white, but reflectance 1 never
// converges; 0.8 is a typical bright diffuse surface.
constexpr double kDefaultBaseColor = 0.8;

// Everything the load steps share: the parsed file, its name for messages, the scene being
// built, and which once-per-kind warnings have already been given.
struct Loader {
    const tinygltf::Model& model;
    std::string file;  // as the caller named it; every message starts with it
    Scene& scene;
    std::set<std::string> warned;
    int default_material = -1;  // index in scene.materials once some primitive needs it

    [[noreturn]] void fail(const std::string& problem) const { throw InputError(file + ": " + problem); }
    void warn(const std::string& problem) { scene.warnings.push_back(file + ": " + problem); }
    void warn_once(const std::string& key, const std::string& problem) {
        if (warned.insert(key).second) warn(problem);
    }
};

// tinygltf's messages in plain words: without nlohmann's exception tags and the tail of the text
// it read off a JSON parse error, or tinygltf's repetition of a path read_regular_file names,
// and a data URI's payload (it can be megabytes) cut to its first bytes.
std::string plain_words(std::string text) {
    static const std::regex json_tag(R"(\[json\.exception\.[a-z_]+\.[0-9]+\] )");
    static const std::regex last_read(R"(; last read: '[^\n]*)");
    static const std::regex decode(R"(Failed to decode 'uri' : (.*) in Buffer)");
    static const std::regex payload(R"((data:[^,\s]*,)([^\s]{24})[^\s]+)");
    if (std::regex_search(text, json_tag)) {
        text = std::regex_replace(text, json_tag, "not valid JSON: ");
        text = std::regex_replace(text, last_read, "");
    }
    static const std::regex not_found(R"(File not found : ([^\n]*))");
    static const std::regex read_error(R"(File read error : [^\n]* : )");
    text = std::regex_replace(text, not_found, "file not found: $1 (a buffer or image the scene names)");
    text = std::regex_replace(text, read_error, "");
    text = std::regex_replace(text, decode,
                              "a buffer's data URI does not decode to the byteLength the buffer declares ($1)");
    return std::regex_replace(text, payload, "$1$2...");
}

// tinygltf reports several '\n'-terminated lines; the CLI prints exactly one.
std::string one_line(const std::string& text) {
    constexpr std::size_t kMaxLength = 240;
    std::istringstream lines(text);
    std::string line, out;
    while (std::getline(lines, line)) {
        while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.pop_back();
        if (line.empty()) continue;
        if (!out.empty()) out += "; ";
        out += line;
    }
    if (out.size() > kMaxLength) out = out.substr(0, kMaxLength - 3) + "...";
    return out;
}

std::string lowercase(std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

// Checks the file is there ourselves: tinygltf's own message for a missing file is vaguer.
void check_readable(const fs::path& file, const std::string& name) {
    std::error_code ec;
    const fs::file_status st = fs::status(file, ec);
    if (ec && st.type() != fs::file_type::not_found) throw InputError(name + ": cannot open: " + ec.message());
    if (!fs::exists(st)) throw InputError(name + ": cannot open: No such file or directory");
    if (fs::is_directory(st)) throw InputError(name + ": cannot open: Is a directory");
    errno = 0;
    std::ifstream probe(file, std::ios::binary);
    if (!probe) {
        throw InputError(name + ": cannot open: " + (errno != 0 ? std::strerror(errno) : "unknown error"));
    }
}

// tinygltf's own reader sizes its buffer by seeking to the end, which for a directory (a buffer
// uri naming one) gives an absurd size and an out-of-memory crash: only regular files are read.
bool read_regular_file(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) {
        if (err) *err += "'" + path + "' (a buffer or image the scene names) is not a readable file\n";
        return false;
    }
    const std::uintmax_t size = fs::file_size(path, ec);
    std::ifstream in(path, std::ios::binary);
    if (ec || !in) {
        if (err) *err += "cannot read '" + path + "'\n";
        return false;
    }
    out->resize(static_cast<std::size_t>(size));
    if (size > 0 && !in.read(reinterpret_cast<char*>(out->data()), static_cast<std::streamsize>(size))) {
        if (err) *err += "cannot read '" + path + "'\n";
        return false;
    }
    return true;
}

tinygltf::Model parse(const fs::path& file, const std::string& name, std::vector<std::string>& warnings) {
    const std::string ext = lowercase(file.extension().string());
    if (ext != ".gltf" && ext != ".glb") {
        throw InputError(name + ": not a glTF file (expected a .gltf or .glb extension)");
    }
    check_readable(file, name);

    tinygltf::TinyGLTF gltf;
    gltf.SetFsCallbacks({&tinygltf::FileExists, &tinygltf::ExpandFilePath, &read_regular_file, &tinygltf::WriteWholeFile,
                         nullptr});
    tinygltf::Model model;
    std::string err, warn;
    const bool ok = ext == ".glb" ? gltf.LoadBinaryFromFile(&model, &err, &warn, file.string())
                                  : gltf.LoadASCIIFromFile(&model, &err, &warn, file.string());
    if (!ok || !err.empty()) {
        const std::string why = one_line(plain_words(err));
        throw InputError(name + ": " + (why.empty() ? "cannot parse glTF" : why));
    }
    std::istringstream lines(warn);
    for (std::string line; std::getline(lines, line);) {
        if (!one_line(line).empty()) warnings.push_back(name + ": " + one_line(line));
    }

    if (model.asset.version.rfind("2.", 0) != 0) {
        throw InputError(name + ": glTF version '" + model.asset.version + "' is not supported (need 2.x)");
    }
    // These change what accessors mean; reading the raw buffers anyway would give garbage.
    for (const std::string& required : model.extensionsRequired) {
        if (required == "KHR_draco_mesh_compression" || required == "EXT_meshopt_compression") {
            throw InputError(fmt::format("{}: required extension {} is not supported", name, required));
        }
    }
    return model;
}

// ---------------------------------------------------------------------------------------
// Accessors

std::size_t component_size(int component_type) {
    switch (component_type) {
        case TINYGLTF_COMPONENT_TYPE_BYTE:
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            return 1;
        case TINYGLTF_COMPONENT_TYPE_SHORT:
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
            return 2;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
            return 4;
        default:
            return 0;  // INT and DOUBLE are not valid in glTF 2.0 accessors
    }
}

int component_count(int type) {
    switch (type) {
        case TINYGLTF_TYPE_SCALAR:
            return 1;
        case TINYGLTF_TYPE_VEC2:
            return 2;
        case TINYGLTF_TYPE_VEC3:
            return 3;
        case TINYGLTF_TYPE_VEC4:
        case TINYGLTF_TYPE_MAT2:
            return 4;
        case TINYGLTF_TYPE_MAT3:
            return 9;
        case TINYGLTF_TYPE_MAT4:
            return 16;
        default:
            return 0;
    }
}

// A window onto one accessor's elements whose byte range has been checked against its buffer.
struct AccessorView {
    const unsigned char* data = nullptr;  // first element
    std::size_t stride = 0;               // bytes from one element to the next
    std::size_t count = 0;
    int components = 0;
    int component_type = 0;
    std::string what;  // "mesh 'x' primitive 0 POSITION (accessor 3)", for messages

    // The stored value, not normalised. memcpy because glTF data need not be aligned in memory.
    double get(std::size_t element, int c) const {
        const unsigned char* p = data + element * stride + std::size_t(c) * component_size(component_type);
        switch (component_type) {
            case TINYGLTF_COMPONENT_TYPE_BYTE:
                return double(static_cast<signed char>(*p));
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
                return double(*p);
            case TINYGLTF_COMPONENT_TYPE_SHORT: {
                std::int16_t v;
                std::memcpy(&v, p, 2);
                return v;
            }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
                std::uint16_t v;
                std::memcpy(&v, p, 2);
                return v;
            }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
                std::uint32_t v;
                std::memcpy(&v, p, 4);
                return v;
            }
            default: {
                float v;
                std::memcpy(&v, p, 4);
                return v;
            }
        }
    }
};

AccessorView view_accessor(const Loader& L, int index, const std::string& where) {
    const tinygltf::Model& m = L.model;
    if (index < 0 || std::size_t(index) >= m.accessors.size()) {
        L.fail(fmt::format("{}: accessor {} out of range ({} accessors)", where, index, m.accessors.size()));
    }
    const tinygltf::Accessor& a = m.accessors[std::size_t(index)];
    const std::string what = fmt::format("{} (accessor {})", where, index);
    if (a.sparse.isSparse) L.fail(what + ": sparse accessors are not supported");
    if (a.bufferView < 0) L.fail(what + ": accessors without a bufferView are not supported");
    if (std::size_t(a.bufferView) >= m.bufferViews.size()) {
        L.fail(
            fmt::format("{}: bufferView {} out of range ({} bufferViews)", what, a.bufferView, m.bufferViews.size()));
    }
    const tinygltf::BufferView& bv = m.bufferViews[std::size_t(a.bufferView)];
    if (bv.buffer < 0 || std::size_t(bv.buffer) >= m.buffers.size()) {
        L.fail(fmt::format("{}: bufferView {} names buffer {}, out of range", what, a.bufferView, bv.buffer));
    }
    const std::vector<unsigned char>& bytes = m.buffers[std::size_t(bv.buffer)].data;
    if (bv.byteOffset > bytes.size() || bv.byteLength > bytes.size() - bv.byteOffset) {
        L.fail(fmt::format("{}: bufferView {} (offset {}, length {}) runs past the end of buffer {} ({} bytes)", what,
                           a.bufferView, bv.byteOffset, bv.byteLength, bv.buffer, bytes.size()));
    }

    const std::size_t csize = component_size(a.componentType);
    const int n = component_count(a.type);
    if (csize == 0 || n == 0) L.fail(fmt::format("{}: invalid componentType {} or type", what, a.componentType));
    const std::size_t element = csize * std::size_t(n);
    const std::size_t stride = bv.byteStride != 0 ? bv.byteStride : element;
    if (stride < element) {
        L.fail(fmt::format("{}: byteStride {} is shorter than one element ({} bytes)", what, stride, element));
    }
    // Written as divisions so a huge count in the file cannot overflow the check itself.
    if (a.count > 0 && (a.byteOffset > bv.byteLength || element > bv.byteLength - a.byteOffset ||
                        (a.count - 1) > (bv.byteLength - a.byteOffset - element) / stride)) {
        L.fail(fmt::format("{}: {} elements at offset {} with stride {} run past the end of bufferView {} ({} bytes)",
                           what, a.count, a.byteOffset, stride, a.bufferView, bv.byteLength));
    }
    return {bytes.data() + bv.byteOffset + a.byteOffset, stride, a.count, n, a.componentType, what};
}

std::vector<dvec3> read_positions(const Loader& L, int index, const std::string& where) {
    const AccessorView v = view_accessor(L, index, where);
    if (v.components != 3 || v.component_type != TINYGLTF_COMPONENT_TYPE_FLOAT) {
        L.fail(v.what + ": POSITION must be VEC3 FLOAT");
    }
    std::vector<dvec3> out(v.count);
    for (std::size_t i = 0; i < v.count; ++i) {
        out[i] = dvec3(v.get(i, 0), v.get(i, 1), v.get(i, 2));
        if (!std::isfinite(out[i].x) || !std::isfinite(out[i].y) || !std::isfinite(out[i].z)) {
            L.fail(fmt::format("{}: position {} is not finite (NaN or Inf)", v.what, i));
        }
    }
    return out;
}

std::vector<std::uint32_t> read_indices(const Loader& L, int index, const std::string& where) {
    const AccessorView v = view_accessor(L, index, where);
    if (v.components != 1 || (v.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
                              v.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
                              v.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)) {
        L.fail(v.what + ": indices must be SCALAR unsigned byte, short or int");
    }
    std::vector<std::uint32_t> out(v.count);
    for (std::size_t i = 0; i < v.count; ++i) out[i] = static_cast<std::uint32_t>(v.get(i, 0));
    return out;
}

// COLOR_0 as linear RGB (glTF vertex colours are linear; alpha does not matter to radiosity).
std::vector<dvec3> read_colors(const Loader& L, int index, const std::string& where) {
    const AccessorView v = view_accessor(L, index, where);
    double scale = 1.0;
    switch (v.component_type) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            scale = 1.0 / 255.0;
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
            scale = 1.0 / 65535.0;
            break;
        default:
            L.fail(v.what + ": COLOR_0 must be FLOAT or normalized unsigned byte/short");
    }
    if (v.components != 3 && v.components != 4) L.fail(v.what + ": COLOR_0 must be VEC3 or VEC4");
    std::vector<dvec3> out(v.count);
    for (std::size_t i = 0; i < v.count; ++i) {
        out[i] = scale * dvec3(v.get(i, 0), v.get(i, 1), v.get(i, 2));
        for (int c = 0; c < 3; ++c) {
            if (!(out[i][c] >= 0.0) || !std::isfinite(out[i][c])) {
                L.fail(fmt::format("{}: colour {} component {} is {}, not a reflectance", v.what, i, c, out[i][c]));
            }
        }
    }
    return out;
}

// ---------------------------------------------------------------------------------------
// Materials

double srgb_to_linear(double x) {
    return x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4);
}

// Mean linear RGB of a decoded image. Colour textures are sRGB-encoded, and averaging the
// encoded values would darken the result, so each value is decoded first. A histogram per
// channel keeps that to one pow() per distinct level instead of one per pixel.
dvec3 average_linear(const tinygltf::Image& img) {
    const std::size_t pixels = std::size_t(img.width) * std::size_t(img.height);
    const std::size_t comps = std::size_t(img.component);
    const int colour_channels = comps >= 3 ? 3 : 1;  // grey (+alpha) images: one channel for all three
    dvec3 sum(0.0);
    if (img.bits == 8 || img.bits == 16) {
        const std::size_t levels = img.bits == 8 ? 256 : 65536;
        const std::size_t bytes = std::size_t(img.bits / 8);
        std::vector<std::uint64_t> histogram(3 * levels, 0);
        for (std::size_t p = 0; p < pixels; ++p) {
            for (int c = 0; c < colour_channels; ++c) {
                const unsigned char* src = img.image.data() + (p * comps + std::size_t(c)) * bytes;
                std::uint16_t value = *src;
                if (bytes == 2) std::memcpy(&value, src, 2);
                ++histogram[std::size_t(c) * levels + value];
            }
        }
        for (int c = 0; c < colour_channels; ++c) {
            for (std::size_t level = 0; level < levels; ++level) {
                const std::uint64_t n = histogram[std::size_t(c) * levels + level];
                if (n != 0) sum[c] += double(n) * srgb_to_linear(double(level) / double(levels - 1));
            }
        }
    } else {  // 32-bit float images are already linear
        for (std::size_t p = 0; p < pixels; ++p) {
            for (int c = 0; c < colour_channels; ++c) {
                float value;
                std::memcpy(&value, img.image.data() + (p * comps + std::size_t(c)) * 4, 4);
                sum[c] += double(value);
            }
        }
    }
    if (colour_channels == 1) sum = dvec3(sum[0]);
    return sum / double(pixels);
}

// 1 when the material has no such texture or its image could not be decoded (with a warning).
dvec3 texture_average(Loader& L, const tinygltf::TextureInfo& info, const std::string& what) {
    if (info.index < 0) return dvec3(1.0);
    const tinygltf::Model& m = L.model;
    if (std::size_t(info.index) >= m.textures.size()) {
        L.fail(fmt::format("{}: texture {} out of range ({} textures)", what, info.index, m.textures.size()));
    }
    const tinygltf::Texture& tex = m.textures[std::size_t(info.index)];
    if (tex.source < 0) {
        L.warn(fmt::format("{}: texture {} has no image this loader can decode; using 1", what, info.index));
        return dvec3(1.0);
    }
    if (std::size_t(tex.source) >= m.images.size()) {
        L.fail(fmt::format("{}: texture {} names image {}, out of range", what, info.index, tex.source));
    }
    const tinygltf::Image& img = m.images[std::size_t(tex.source)];
    const bool known_format =
        img.bits == 8 || img.bits == 16 || (img.bits == 32 && img.pixel_type == TINYGLTF_COMPONENT_TYPE_FLOAT);
    const bool complete = img.width > 0 && img.height > 0 && img.component > 0 && known_format &&
                          img.image.size() >= std::size_t(img.width) * std::size_t(img.height) *
                                                  std::size_t(img.component) * std::size_t(img.bits / 8);
    if (!complete) {
        L.warn(fmt::format("{}: image {} could not be decoded; using 1", what, tex.source));
        return dvec3(1.0);
    }
    return average_linear(img);
}

std::string material_label(const tinygltf::Material& mat, int index) {
    return mat.name.empty() ? fmt::format("material {}", index) : fmt::format("material '{}'", mat.name);
}

// glTF factors live in [0, 1]; anything else is an invalid file, not something to clamp.
void check_factor(const Loader& L, const std::vector<double>& factor, const std::string& what) {
    for (std::size_t i = 0; i < factor.size(); ++i) {
        if (!(factor[i] >= 0.0 && factor[i] <= 1.0)) {
            L.fail(fmt::format("{} component {} is {}, outside [0, 1]", what, i, factor[i]));
        }
    }
}

double emissive_strength(const Loader& L, const tinygltf::Material& mat, const std::string& label) {
    const auto it = mat.extensions.find("KHR_materials_emissive_strength");
    if (it == mat.extensions.end() || !it->second.Has("emissiveStrength")) return 1.0;
    const tinygltf::Value& value = it->second.Get("emissiveStrength");
    if (!value.IsNumber()) L.fail(label + ": emissiveStrength is not a number");
    const double strength = value.GetNumberAsDouble();
    if (!(strength >= 0.0) || !std::isfinite(strength)) {
        L.fail(fmt::format("{}: emissiveStrength {} must be finite and >= 0", label, strength));
    }
    return strength;
}

Material convert_material(Loader& L, int index) {
    const tinygltf::Material& mat = L.model.materials[std::size_t(index)];
    const std::string label = material_label(mat, index);
    Material out;
    out.name = mat.name.empty() ? fmt::format("material{}", index) : mat.name;
    out.double_sided = mat.doubleSided;

    const std::vector<double>& base = mat.pbrMetallicRoughness.baseColorFactor;
    if (base.size() != 4) L.fail(label + ": baseColorFactor must have 4 components");
    check_factor(L, base, label + ": baseColorFactor");
    out.base_color = dvec3(base[0], base[1], base[2]) *
                     texture_average(L, mat.pbrMetallicRoughness.baseColorTexture, label + " baseColorTexture");

    const std::vector<double>& emissive = mat.emissiveFactor;
    if (!emissive.empty() && emissive.size() != 3) L.fail(label + ": emissiveFactor must have 3 components");
    check_factor(L, emissive, label + ": emissiveFactor");
    const double strength = emissive_strength(L, mat, label);
    if (!emissive.empty() && (emissive[0] > 0.0 || emissive[1] > 0.0 || emissive[2] > 0.0) && strength > 0.0) {
        out.emission = dvec3(emissive[0], emissive[1], emissive[2]) * strength *
                       texture_average(L, mat.emissiveTexture, label + " emissiveTexture");
    }
    return out;
}

std::uint32_t default_material(Loader& L) {
    if (L.default_material < 0) {
        Material m;
        m.name = "default";
        m.base_color = dvec3(kDefaultBaseColor);
        L.default_material = int(L.scene.materials.size());
        L.scene.materials.push_back(m);
    }
    return std::uint32_t(L.default_material);
}

// ---------------------------------------------------------------------------------------
// Node hierarchy

bool all_finite(const dmat4& m) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
            if (!std::isfinite(m[c][r])) return false;
    return true;
}

// The node's local transform: its matrix when it has one, else T·R·S (glTF 2.0, 3.5.3).
dmat4 local_transform(const Loader& L, const tinygltf::Node& node, int index) {
    const auto bad = [&](const char* what) { L.fail(fmt::format("node {}: {}", index, what)); };
    if (!node.matrix.empty()) {
        if (node.matrix.size() != 16) bad("matrix must have 16 numbers");
        return glm::make_mat4(node.matrix.data());  // both column-major
    }
    dmat4 t(1.0), r(1.0), s(1.0);
    if (!node.translation.empty()) {
        if (node.translation.size() != 3) bad("translation must have 3 numbers");
        t = glm::translate(dmat4(1.0), dvec3(node.translation[0], node.translation[1], node.translation[2]));
    }
    if (!node.rotation.empty()) {
        if (node.rotation.size() != 4) bad("rotation must have 4 numbers");
        const auto& q = node.rotation;  // x, y, z, w in the file; glm's constructor takes w first
        const glm::dquat rotation(q[3], q[0], q[1], q[2]);
        const double length = glm::length(rotation);
        if (!(length > 0.0) || !std::isfinite(length)) bad("rotation is not a unit quaternion");
        r = glm::mat4_cast(rotation / length);  // exporters round; renormalise rather than shear
    }
    if (!node.scale.empty()) {
        if (node.scale.size() != 3) bad("scale must have 3 numbers");
        s = glm::scale(dmat4(1.0), dvec3(node.scale[0], node.scale[1], node.scale[2]));
    }
    return t * r * s;
}

struct Instance {
    int node = -1;
    dmat4 world{1.0};
};

// Depth-first through the trees below roots, composing transforms. An explicit stack so a
// deep hierarchy cannot overflow the call stack; glTF node hierarchies are disjoint trees,
// so a node reached twice is a cycle or a second parent and the file is invalid.
std::vector<Instance> instantiate(const Loader& L, const std::vector<int>& roots) {
    const std::vector<tinygltf::Node>& nodes = L.model.nodes;
    std::vector<char> on_path(nodes.size(), 0), seen(nodes.size(), 0);
    struct Frame {
        int node;
        dmat4 world;
        std::size_t next_child;
    };
    std::vector<Frame> stack;
    std::vector<Instance> out;

    const auto enter = [&](int index, const dmat4& parent, const std::string& referrer) {
        if (index < 0 || std::size_t(index) >= nodes.size()) {
            L.fail(fmt::format("{} names node {}, out of range ({} nodes)", referrer, index, nodes.size()));
        }
        if (on_path[std::size_t(index)]) L.fail(fmt::format("node {} is its own ancestor (a cycle)", index));
        if (seen[std::size_t(index)]) L.fail(fmt::format("node {} has more than one parent", index));
        const dmat4 world = parent * local_transform(L, nodes[std::size_t(index)], index);
        if (!all_finite(world)) L.fail(fmt::format("node {}: transform is not finite", index));
        on_path[std::size_t(index)] = seen[std::size_t(index)] = 1;
        stack.push_back({index, world, 0});
        out.push_back({index, world});
    };

    for (const int root : roots) {
        enter(root, dmat4(1.0), "scene");
        while (!stack.empty()) {
            Frame& top = stack.back();
            const std::vector<int>& children = nodes[std::size_t(top.node)].children;
            if (top.next_child < children.size()) {
                const int child = children[top.next_child++];
                const dmat4 parent = top.world;  // copied: enter() may reallocate the stack
                enter(child, parent, fmt::format("node {}", top.node));
            } else {
                on_path[std::size_t(top.node)] = 0;
                stack.pop_back();
            }
        }
    }
    return out;
}

std::vector<int> root_nodes(const Loader& L) {
    const tinygltf::Model& m = L.model;
    if (!m.scenes.empty()) {
        const int index = m.defaultScene >= 0 ? m.defaultScene : 0;
        if (std::size_t(index) >= m.scenes.size()) {
            L.fail(fmt::format("default scene {} out of range ({} scenes)", index, m.scenes.size()));
        }
        return m.scenes[std::size_t(index)].nodes;
    }
    // No scenes: every node that is nobody's child is a root.
    std::vector<char> is_child(m.nodes.size(), 0);
    for (const tinygltf::Node& node : m.nodes)
        for (const int child : node.children)
            if (child >= 0 && std::size_t(child) < m.nodes.size()) is_child[std::size_t(child)] = 1;
    std::vector<int> roots;
    for (std::size_t i = 0; i < m.nodes.size(); ++i)
        if (!is_child[i]) roots.push_back(int(i));
    return roots;
}

// ---------------------------------------------------------------------------------------
// Geometry and cameras

const char* mode_name(int mode) {
    switch (mode) {
        case TINYGLTF_MODE_POINTS:
            return "POINTS";
        case TINYGLTF_MODE_LINE:
            return "LINES";
        case TINYGLTF_MODE_LINE_LOOP:
            return "LINE_LOOP";
        case TINYGLTF_MODE_LINE_STRIP:
            return "LINE_STRIP";
        case TINYGLTF_MODE_TRIANGLE_STRIP:
            return "TRIANGLE_STRIP";
        case TINYGLTF_MODE_TRIANGLE_FAN:
            return "TRIANGLE_FAN";
        default:
            return nullptr;
    }
}

struct PrimitiveRef {
    const Instance* instance;
    std::uint32_t scene_node;  // index into Scene::nodes
    int mesh;
    int index;  // within the mesh
};

void add_primitive(Loader& L, const PrimitiveRef& ref, std::uint32_t& primitive_counter) {
    const tinygltf::Mesh& mesh = L.model.meshes[std::size_t(ref.mesh)];
    const tinygltf::Primitive& prim = mesh.primitives[std::size_t(ref.index)];
    const std::string mesh_label =
        mesh.name.empty() ? fmt::format("mesh {}", ref.mesh) : fmt::format("mesh '{}'", mesh.name);
    const std::string where = fmt::format("{} primitive {}", mesh_label, ref.index);

    // -1: tinygltf's "mode absent", which glTF defines as TRIANGLES.
    if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) {
        const char* name = mode_name(prim.mode);
        if (name == nullptr) L.fail(fmt::format("{}: mode {} is not a glTF primitive mode", where, prim.mode));
        ++L.scene.skipped_primitives;
        L.warn_once(fmt::format("mode {} {}", ref.mesh, prim.mode),
                    fmt::format("{}: mode {} is not triangles; skipped", where, name));
        return;
    }
    const auto position = prim.attributes.find("POSITION");
    if (position == prim.attributes.end()) {
        L.warn_once(fmt::format("noposition {} {}", ref.mesh, ref.index),
                    fmt::format("{}: has no POSITION; skipped", where));
        return;
    }
    const std::vector<dvec3> positions = read_positions(L, position->second, where + " POSITION");

    std::vector<std::uint32_t> indices;
    if (prim.indices >= 0) {
        indices = read_indices(L, prim.indices, where + " indices");
        for (const std::uint32_t i : indices) {
            if (i >= positions.size()) {
                L.fail(fmt::format("{} (accessor {}): index {} out of range ({} vertices)", where + " indices",
                                   prim.indices, i, positions.size()));
            }
        }
    } else {
        indices.resize(positions.size());
        for (std::size_t i = 0; i < indices.size(); ++i) indices[i] = std::uint32_t(i);
    }
    if (indices.size() % 3 != 0) {
        L.fail(fmt::format("{}: {} {} is not a multiple of 3", where,
                           prim.indices >= 0 ? "index count" : "vertex count", indices.size()));
    }

    std::vector<dvec3> colors;
    if (const auto c = prim.attributes.find("COLOR_0"); c != prim.attributes.end()) {
        colors = read_colors(L, c->second, where + " COLOR_0");
        if (colors.size() != positions.size()) {
            L.fail(fmt::format("{} COLOR_0: {} colours for {} positions", where, colors.size(), positions.size()));
        }
    }

    std::uint32_t material;
    if (prim.material < 0) {
        material = default_material(L);
    } else if (std::size_t(prim.material) < L.model.materials.size()) {
        material = std::uint32_t(prim.material);  // scene.materials mirrors the file's order
    } else {
        L.fail(
            fmt::format("{}: material {} out of range ({} materials)", where, prim.material, L.model.materials.size()));
    }
    const Material& mat = L.scene.materials[material];

    const dmat4& world = ref.instance->world;
    // A mirroring transform turns counter-clockwise into clockwise; swapping two vertices
    // keeps the side the file called front as the front.
    const bool mirrored = glm::determinant(glm::dmat3(world)) < 0.0;
    bool clamped = false;
    const std::uint32_t primitive = primitive_counter++;
    for (std::size_t k = 0; k < indices.size(); k += 3) {
        Triangle t;
        for (int v = 0; v < 3; ++v) {
            const std::uint32_t i = indices[k + std::size_t(v)];
            t.p[std::size_t(v)] = dvec3(world * glm::dvec4(positions[i], 1.0));
            dvec3 rho = mat.base_color * (colors.empty() ? dvec3(1.0) : colors[i]);
            for (int c = 0; c < 3; ++c) {
                if (rho[c] > kMaxReflectance) {
                    rho[c] = kMaxReflectance;
                    clamped = true;
                }
            }
            t.rho[std::size_t(v)] = rho;
        }
        if (mirrored) {
            std::swap(t.p[1], t.p[2]);
            std::swap(t.rho[1], t.rho[2]);
        }
        t.material = material;
        t.node = ref.scene_node;
        t.primitive = primitive;
        L.scene.triangles.push_back(t);
    }
    if (clamped) {
        L.warn_once(fmt::format("clamp {}", material),
                    fmt::format("material '{}': reflectance 1 cannot conserve energy; clamped to {}", mat.name,
                                kMaxReflectance));
    }
}

// Cameras carry no scale: keep the position and viewing direction, rebuild orthonormal axes.
dmat4 rigid_frame(const Loader& L, const dmat4& m, int node) {
    const dvec3 z_axis(m[2]), x_axis(m[0]);
    const double z_length = glm::length(z_axis);
    if (!(z_length > 0.0)) L.fail(fmt::format("node {}: camera transform is degenerate", node));
    const dvec3 z = z_axis / z_length;
    const dvec3 x_perpendicular = x_axis - glm::dot(x_axis, z) * z;  // removes any shear
    const double x_length = glm::length(x_perpendicular);
    if (!(x_length > 0.0)) L.fail(fmt::format("node {}: camera transform is degenerate", node));
    const dvec3 x = x_perpendicular / x_length;
    dmat4 out(1.0);
    out[0] = glm::dvec4(x, 0.0);
    out[1] = glm::dvec4(glm::cross(z, x), 0.0);  // right-handed even if the node mirrors
    out[2] = glm::dvec4(z, 0.0);
    out[3] = m[3];
    return out;
}

void add_camera(Loader& L, const Instance& inst) {
    const tinygltf::Node& node = L.model.nodes[std::size_t(inst.node)];
    const tinygltf::Camera& cam = L.model.cameras[std::size_t(node.camera)];
    const std::string name = !cam.name.empty()    ? cam.name
                             : !node.name.empty() ? node.name
                                                  : fmt::format("camera{}", node.camera);
    if (cam.type != "perspective") {
        L.warn_once(fmt::format("camera {}", node.camera),
                    fmt::format("camera '{}' is {}, not perspective; skipped", name, cam.type));
        return;
    }
    const tinygltf::PerspectiveCamera& p = cam.perspective;
    if (!(p.yfov > 0.0 && p.yfov < glm::pi<double>())) {
        L.fail(fmt::format("camera '{}': yfov {} must be in (0, pi)", name, p.yfov));
    }
    if (!(p.znear > 0.0) || !std::isfinite(p.znear)) {
        L.fail(fmt::format("camera '{}': znear {} must be > 0", name, p.znear));
    }
    Camera out;
    out.name = name;
    out.camera_to_world = rigid_frame(L, inst.world, inst.node);
    out.yfov = p.yfov;
    out.aspect = p.aspectRatio > 0.0 && std::isfinite(p.aspectRatio) ? p.aspectRatio : 0.0;
    out.znear = p.znear;
    L.scene.cameras.push_back(out);
}

void compute_bbox(Scene& scene) {
    if (scene.triangles.empty()) return;
    scene.bbox_min = scene.bbox_max = scene.triangles.front().p[0];
    for (const Triangle& t : scene.triangles) {
        for (const dvec3& p : t.p) {
            scene.bbox_min = glm::min(scene.bbox_min, p);
            scene.bbox_max = glm::max(scene.bbox_max, p);
        }
    }
}

}  // namespace

Scene load(const std::filesystem::path& file) {
    Scene scene;
    scene.path = file;
    const std::string name = file.string();
    const tinygltf::Model model = parse(file, name, scene.warnings);
    Loader L{model, name, scene, {}, -1};

    // Converted in file order so a primitive's material index is also its Scene index.
    for (std::size_t i = 0; i < model.materials.size(); ++i) scene.materials.push_back(convert_material(L, int(i)));

    std::vector<Instance> instances = instantiate(L, root_nodes(L));
    // Scene::nodes is in glTF node order; triangles follow the same order.
    std::stable_sort(instances.begin(), instances.end(),
                     [](const Instance& a, const Instance& b) { return a.node < b.node; });

    std::uint32_t primitive_counter = 0;
    for (const Instance& inst : instances) {
        const tinygltf::Node& node = model.nodes[std::size_t(inst.node)];
        if (node.camera >= 0) {
            if (std::size_t(node.camera) >= model.cameras.size()) {
                L.fail(fmt::format("node {}: camera {} out of range ({} cameras)", inst.node, node.camera,
                                   model.cameras.size()));
            }
            add_camera(L, inst);
        }
        if (node.mesh < 0) continue;
        if (std::size_t(node.mesh) >= model.meshes.size()) {
            L.fail(fmt::format("node {}: mesh {} out of range ({} meshes)", inst.node, node.mesh, model.meshes.size()));
        }
        const tinygltf::Mesh& mesh = model.meshes[std::size_t(node.mesh)];
        MeshNode mesh_node;
        mesh_node.name = !node.name.empty()   ? node.name
                         : !mesh.name.empty() ? mesh.name
                                              : fmt::format("node{}", inst.node);
        mesh_node.gltf_node = inst.node;
        const auto scene_node = std::uint32_t(scene.nodes.size());
        scene.nodes.push_back(mesh_node);
        for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
            add_primitive(L, {&inst, scene_node, node.mesh, int(p)}, primitive_counter);
        }
    }
    compute_bbox(scene);
    return scene;
}

}  // namespace hemirad::scene
