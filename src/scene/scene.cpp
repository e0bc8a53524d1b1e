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
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <memory>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "core/cancel.h"
#include "core/counted.h"
#include "core/error.h"
#include "core/memory.h"
#include "core/regular_file.h"
#include "scene/gltf_compression.h"
#include "scene/gltf_source.h"
#include "scene/image_mean.h"
#include "scene/load_estimate.h"

namespace hemirad::scene {
namespace {

namespace fs = std::filesystem;
using glm::dmat4;
using glm::dvec3;

// Used for primitives without a material. glTF's default is white, but reflectance 1 never
// converges; 0.8 is a typical bright diffuse surface.
constexpr double kDefaultBaseColor = 0.8;

// Which TEXCOORD_n set a texture reads, and the KHR_texture_transform applied to it.
struct UvSource {
    int set = 0;
    glm::dmat3 transform{1.0};
    bool used = false;  // the material has this texture
};

// Everything the load steps share: the parsed file, its name for messages, the scene being
// built, and which once-per-kind warnings have already been given.
struct Loader {
    const tinygltf::Model& model;
    GltfSource& source;  // holds model
    std::string file;  // as the caller named it; every message starts with it
    Scene& scene;
    std::set<std::string> warned;
    int default_material = -1;  // index in scene.materials once some primitive needs it
    std::string base_dir;                // where the file's uris are resolved
    std::map<int, EncodedImage> encoded;  // what tinygltf handed the image loader, by index
    std::map<int, ImageMean> images;     // decoded when a material's texture first needs one
    std::uint64_t decoded_pixels = 0;    // of every image decoded so far
    std::map<int, int> texture_of_image;  // glTF image -> Scene::textures index, once decoded
    // Per material: where its base colour and emissive textures' coordinates come from.
    std::vector<std::array<UvSource, 2>> uv_sources;
    std::map<int, std::size_t> light_of_node;  // glTF node -> its light in Scene::lights
    std::set<std::uint32_t> clamped;  // materials whose reflectance (× COLOR_0) reached 1 somewhere
    bool strict_textures = false;     // LoadOptions::strict_textures
    int material = -1;                // the material being converted, for the images' warnings
    // Texture images that could not be used (missing, undecodable), in the order first met: one
    // warning each at the end of the load, counting the materials that read them.
    struct UnusableImage {
        std::string label, problem;
        std::set<int> materials;
    };
    std::vector<UnusableImage> unusable{};
    std::map<std::string, std::size_t> unusable_at{};  // label -> index in unusable
    // Warnings that would repeat per item (a primitive, a material, a node): one line per kind at
    // the end of the load (warn_grouped), `one` for a single item, else `many`, where "{n}" is
    // the count and "{names}" the first items.
    struct Group {
        std::string one, many;
        std::vector<std::string> items;
    };
    std::vector<Group> groups{};
    std::map<std::string, std::size_t> group_at{};  // key -> index in groups

    [[noreturn]] void fail(const std::string& problem) const { throw InputError(file + ": " + problem); }
    void warn(const std::string& problem) { scene.warnings.push_back(file + ": " + problem); }
    void warn_once(const std::string& key, const std::string& problem) {
        if (warned.insert(key).second) warn(problem);
    }
    // `item` for the grouped warning `key` (each item once).
    void group(const std::string& key, const std::string& one, const std::string& many, const std::string& item) {
        auto [at, added] = group_at.emplace(key, groups.size());
        if (added) groups.push_back({one, many, {}});
        std::vector<std::string>& items = groups[at->second].items;
        if (std::find(items.begin(), items.end(), item) == items.end()) items.push_back(item);
    }
    void warn_grouped() {
        constexpr std::size_t kNamed = 3;
        for (const Group& g : groups) {
            std::string names;
            for (std::size_t i = 0; i < g.items.size() && i < kNamed; ++i) names += (i ? "; " : "") + g.items[i];
            if (g.items.size() > kNamed) names += fmt::format("; and {} more", grouped(g.items.size() - kNamed));
            std::string text = g.items.size() == 1 ? g.one : g.many;
            for (const auto& [field, value] : {std::pair<std::string, std::string>{"{n}", grouped(g.items.size())},
                                               {"{names}", names}})
                for (std::size_t at; (at = text.find(field)) != std::string::npos;) text.replace(at, field.size(), value);
            warn(text);
        }
        groups.clear();
        group_at.clear();
    }
};

// tinygltf's messages in plain words: without nlohmann's exception tags and the tail of the text
// it read off a JSON parse error, or tinygltf's repetition of a path read_file names,
// and a data URI's payload (it can be megabytes) cut to its first bytes.
std::string plain_words(std::string text) {
    // libstdc++'s regex recurses once per character matched: a parse error quoting 20 KB of the
    // file ("last read: '[[[[…") overflowed the stack. The message is cut to one short line
    // afterwards anyway, so every line is cut first.
    constexpr std::size_t kLongestLine = 1024;
    std::string clipped;
    for (std::size_t start = 0; start < text.size();) {
        const std::size_t end = std::min(text.find('\n', start), text.size());
        clipped.append(text, start, std::min(end - start, kLongestLine));
        if (end < text.size()) clipped += '\n';
        start = end + 1;
    }
    text = std::move(clipped);
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

// Limits on what the loader reads before it trusts a file. nlohmann (under tinygltf) parses JSON
// nesting with its own stack, but tinygltf converts `extras` and `extensions` recursively: a file
// nested thousands deep would overflow the call stack. No glTF needs more than a few dozen levels.
constexpr int kMaxJsonDepth = 512;
// A .gltf's JSON text (or a .glb's JSON chunk): parsed whole, at several times its size in memory.
constexpr std::uint64_t kMaxJsonBytes = std::uint64_t{1} << 30;
// A buffer or image file the scene names is read whole: at most this (a .glb's own length field is
// 32 bits, and tinygltf takes an image's size as an int), checked before reading.
constexpr std::uint64_t kMaxExternalFileBytes = std::uint64_t{1} << 32;
constexpr std::size_t kGlbHeader = 12, kChunkHeader = 8;
constexpr std::uint32_t kGlbMagic = 0x46546c67;  // "glTF", little-endian
constexpr std::uint32_t kChunkJson = 0x4e4f534a;  // "JSON"

std::uint32_t little_endian32(const unsigned char* p) {
    return std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[3]) << 24;
}

// Refuses JSON nested deeper than kMaxJsonDepth, before it is parsed: a scan that counts '{' and
// '[' outside strings (a backslash in a string escapes the byte after it).
void check_json_depth(const unsigned char* text, std::size_t size, const std::string& name) {
    int depth = 0;
    bool in_string = false;
    for (std::size_t i = 0; i < size; ++i) {
        const unsigned char c = text[i];
        if (in_string) {
            if (c == '\\') ++i;
            else if (c == '"') in_string = false;
        } else if (c == '"') {
            in_string = true;
        } else if (c == '{' || c == '[') {
            if (++depth > kMaxJsonDepth)
                throw InputError(fmt::format("{}: JSON nested more than {} levels deep (at byte {} of the JSON); refused", name,
                                             kMaxJsonDepth, i));
        } else if ((c == '}' || c == ']') && depth > 0) {
            --depth;
        }
    }
}

// A .gltf is JSON: its first byte past a UTF-8 byte-order mark and white space is '{'. Checked on
// the first bytes, so that a huge file of something else is refused without reading it.
void check_looks_like_json(const RegularFile& file, const std::string& name) {
    if (file.size() == 0) throw InputError(name + ": the file is empty (0 bytes)");
    unsigned char head[256];
    const std::size_t n = std::size_t(std::min<std::uint64_t>(file.size(), sizeof head));
    file.read_exactly(0, n, head);
    std::size_t i = n >= 3 && head[0] == 0xef && head[1] == 0xbb && head[2] == 0xbf ? 3 : 0;
    while (i < n && (head[i] == ' ' || head[i] == '\t' || head[i] == '\n' || head[i] == '\r')) ++i;
    if (i == n && n == file.size()) throw InputError(name + ": not JSON (only white space)");
    if (i < n && head[i] != '{') {
        const unsigned char c = head[i];
        throw InputError(fmt::format("{}: not JSON (a glTF file starts with '{{', this one with {})", name,
                                     std::isprint(c) ? fmt::format("'{}'", char(c)) : fmt::format("byte 0x{:02x}", c)));
    }
}

// The JSON text of a .gltf, checked before tinygltf sees it.
std::vector<unsigned char> read_gltf(const fs::path& path, const std::string& name) {
    const RegularFile file(path, name);
    check_looks_like_json(file, name);
    if (file.size() > kMaxJsonBytes)
        throw InputError(fmt::format("{}: {} bytes of JSON, above the limit of {} (keep large buffers in .bin files or "
                                     "a .glb)",
                                     name, file.size(), kMaxJsonBytes));
    std::vector<unsigned char> text(std::size_t(file.size()));
    file.read_exactly(0, text.size(), text.data());
    check_json_depth(text.data(), text.size(), name);
    return text;
}

// A .glb, its header and JSON chunk checked from the first bytes before the rest is read: a file
// that is no .glb, or is cut short, is refused without reading it whole.
std::vector<unsigned char> read_glb(const fs::path& path, const std::string& name) {
    const RegularFile file(path, name);
    if (file.size() == 0) throw InputError(name + ": the file is empty (0 bytes)");
    if (file.size() < kGlbHeader)
        throw InputError(fmt::format("{}: not a .glb: {} bytes, shorter than the 12-byte header", name, file.size()));
    unsigned char header[kGlbHeader + kChunkHeader] = {};
    file.read_exactly(0, std::size_t(std::min<std::uint64_t>(file.size(), sizeof header)), header);
    if (little_endian32(header) != kGlbMagic)
        throw InputError(name + ": not a .glb (its first 4 bytes are not the magic 'glTF')");
    if (const std::uint32_t version = little_endian32(header + 4); version != 2)
        throw InputError(fmt::format("{}: .glb container version {} is not supported (need 2)", name, version));
    const std::uint32_t length = little_endian32(header + 8);
    if (length > file.size())
        throw InputError(
            fmt::format("{}: truncated: its header declares {} bytes, the file holds {}", name, length, file.size()));
    if (length < sizeof header)
        throw InputError(fmt::format("{}: its header declares {} bytes, too few for a JSON chunk", name, length));
    const std::uint32_t json_length = little_endian32(header + kGlbHeader);
    if (little_endian32(header + kGlbHeader + 4) != kChunkJson)
        throw InputError(name + ": the first chunk of a .glb must be its JSON");
    if (json_length > length - sizeof header)
        throw InputError(fmt::format("{}: its JSON chunk ({} bytes) runs past the {} bytes the header declares", name,
                                     json_length, length));
    if (json_length > kMaxJsonBytes)
        throw InputError(
            fmt::format("{}: {} bytes of JSON, above the limit of {}", name, json_length, kMaxJsonBytes));
    std::vector<unsigned char> bytes(length);  // bytes past `length` are not part of the .glb
    file.read_exactly(0, bytes.size(), bytes.data());
    check_json_depth(bytes.data() + sizeof header, json_length, name);
    return bytes;
}

// tinygltf's file callbacks, given only regular files: its own FileExists opens the file (a FIFO
// would block there), and its reader sizes its buffer by seeking to the end, which for a directory
// (a buffer uri naming one) gives an absurd size and an out-of-memory crash.
bool file_exists(const std::string& path, void*) {
    std::error_code ec;
    return fs::exists(path, ec);  // stat only; read_file says what is wrong with it
}

bool read_file(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
    try {
        *out = read_regular_file(path, "'" + path + "' (a buffer or image the scene names)", kMaxExternalFileBytes);
        return true;
    } catch (const InputError& e) {
        if (err) *err += std::string(e.what()) + "\n";
        return false;
    }
}

// What tinygltf handed the image loader for each image of the file, by index, kept encoded: the
// loader needs only the mean colour of the images a material's texture uses, decodes each of
// those once, and says what is wrong only with them.
struct ImageDecoder {
    const tinygltf::Model* model = nullptr;  // being filled in by tinygltf: its buffers come before images
    std::map<int, EncodedImage> images;
};

// tinygltf's image callback: keeps the bytes (decoding waits until a texture needs the image, so
// images nothing uses, such as normal maps, cost no time) and never fails the load, so that an
// image no material uses cannot stop a bake.
bool keep_image(tinygltf::Image* image, const int index, std::string*, std::string*, int, int,
                const unsigned char* bytes, int size, void* user) {
    auto& decoder = *static_cast<ImageDecoder*>(user);
    EncodedImage& kept = decoder.images[index];
    if (image->bufferView >= 0) {  // tinygltf passes its bytes unchecked against the buffer
        const tinygltf::BufferView& view = decoder.model->bufferViews[std::size_t(image->bufferView)];
        const std::size_t buffer_size = decoder.model->buffers[std::size_t(view.buffer)].data.size();
        if (view.byteOffset > buffer_size || view.byteLength > buffer_size - view.byteOffset) {
            kept.problem = fmt::format("bufferView {} (offset {}, length {}) runs past the end of buffer {} ({} bytes)",
                                       image->bufferView, view.byteOffset, view.byteLength, view.buffer, buffer_size);
            kept.refused = true;
            return true;
        }
    }
    if (size > 0) kept.bytes.assign(bytes, bytes + size);
    return true;
}

// The bytes of a data URI ("data:[TYPE][;base64],DATA", RFC 2397) and its media type, for the
// image types tinygltf does not decode itself (it knows only PNG, JPEG, BMP and GIF ones and
// takes any other, such as image/webp, for a file name). Empty bytes and a problem when the
// payload does not decode.
struct DataUri {
    std::string type;
    std::vector<unsigned char> bytes;
    std::string problem;
};

DataUri decode_data_uri(const std::string& uri) {
    DataUri out;
    const std::size_t comma = uri.find(',');
    if (uri.rfind("data:", 0) != 0 || comma == std::string::npos) {
        out.problem = "a data URI without the ',' that starts its data";
        return out;
    }
    const std::string header = uri.substr(5, comma - 5);
    const bool base64 = header.size() >= 7 && lowercase(header.substr(header.size() - 7)) == ";base64";
    out.type = header.substr(0, header.find(';'));
    if (!base64) {
        const std::string text = percent_decoded(uri.substr(comma + 1));
        out.bytes.assign(text.begin(), text.end());
        return out;
    }
    std::uint32_t bits = 0;
    int held = 0, padding = 0;
    out.bytes.reserve((uri.size() - comma) / 4 * 3);
    for (std::size_t i = comma + 1; i < uri.size(); ++i) {
        const char c = uri[i];
        int v;
        if (c >= 'A' && c <= 'Z') v = c - 'A';
        else if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
        else if (c >= '0' && c <= '9') v = c - '0' + 52;
        else if (c == '+' || c == '-') v = 62;  // '-' and '_': the URL-safe alphabet
        else if (c == '/' || c == '_') v = 63;
        else if (c == '=') {
            ++padding;
            continue;
        } else {
            out.bytes.clear();
            out.problem = fmt::format("its data URI is not base64 (byte {} is {})", i - comma - 1,
                                      std::isprint(static_cast<unsigned char>(c)) ? fmt::format("'{}'", c)
                                                                                  : fmt::format("0x{:02x}", c & 0xff));
            return out;
        }
        if (padding > 0) {
            out.bytes.clear();
            out.problem = "its data URI has base64 data after the '=' padding";
            return out;
        }
        bits = bits << 6 | std::uint32_t(v);
        if ((held += 6) >= 8) {
            held -= 8;
            out.bytes.push_back(static_cast<unsigned char>(bits >> held & 0xffu));
        }
    }
    return out;
}

// The base directory tinygltf resolves uris against, as its LoadASCIIFromFile computes it.
std::string base_dir(const std::string& file) {
    const std::size_t slash = file.find_last_of('/');
    return slash == std::string::npos ? std::string() : file.substr(0, slash);
}

// Before tinygltf reads anything the JSON names: the extensions' integers (which it would cut to
// 32 bits), the files it will read (options.inputs), and what loading will ask for, against
// options.max_bytes. Returns the triangles the scene will hold. A file whose JSON does not parse
// is left to tinygltf, which says what is wrong with it.
double look_before_loading(const std::vector<unsigned char>& bytes, bool glb, const fs::path& file,
                           const std::string& name, const LoadOptions& options) {
    const std::size_t start = glb ? kGlbHeader + kChunkHeader : 0;
    const std::size_t length = glb ? little_endian32(bytes.data() + kGlbHeader) : bytes.size();
    const nlohmann::json doc = nlohmann::json::parse(bytes.begin() + std::ptrdiff_t(start),
                                                     bytes.begin() + std::ptrdiff_t(start + length), nullptr,
                                                     /*allow_exceptions=*/false);
    if (doc.is_discarded()) return 0.0;
    check_extension_integers(doc, name);
    if (options.inputs) {
        std::vector<fs::path> files = referenced_files(doc, base_dir(file.string()));
        files.insert(files.begin(), file);
        options.inputs(files);
    }
    const LoadEstimate e = estimate_load(doc);
    if (e.total() > options.max_bytes)
        throw InputError(fmt::format("{}: loading it would need about {} ({}), more than the {} {}", name,
                                     format_bytes(e.total()), e.describe(), format_bytes(options.max_bytes),
                                     options.limit_source));
    return e.triangles;
}

tinygltf::Model parse(const fs::path& file, const std::string& name, std::vector<std::string>& warnings,
                      std::map<int, EncodedImage>& images, const LoadOptions& options, double& triangles) {
    const std::string ext = lowercase(file.extension().string());
    if (ext != ".gltf" && ext != ".glb") {
        throw InputError(name + ": not a glTF file (expected a .gltf or .glb extension)");
    }
    std::vector<unsigned char> bytes = ext == ".glb" ? read_glb(file, name) : read_gltf(file, name);
    triangles = look_before_loading(bytes, ext == ".glb", file, name, options);
    const MeshoptFallbacks fallbacks = stand_in_for_compressed_data(bytes, ext == ".glb", name);

    tinygltf::TinyGLTF gltf;
    gltf.SetFsCallbacks({&file_exists, &tinygltf::ExpandFilePath, &read_file, &tinygltf::WriteWholeFile, nullptr});
    tinygltf::Model model;
    ImageDecoder decoder{&model, {}};
    gltf.SetImageLoader(&keep_image, &decoder);
    std::string err, warn;
    const bool ok = ext == ".glb"
                        ? gltf.LoadBinaryFromMemory(&model, &err, &warn, bytes.data(), unsigned(bytes.size()),
                                                    base_dir(file.string()))
                        : gltf.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(bytes.data()),
                                                   unsigned(bytes.size()), base_dir(file.string()));
    if (!ok || !err.empty()) {
        const std::string why = one_line(plain_words(err));
        throw InputError(name + ": " + (why.empty() ? "cannot parse glTF" : why));
    }
    images = std::move(decoder.images);
    // Data URIs of the image types tinygltf does not decode (image/webp above all): tinygltf kept
    // them as file names. Decoded here and kept like its own, the uri cleared (its bytes become
    // GltfSource::embedded_images, as an embedded PNG's do).
    for (std::size_t i = 0; i < model.images.size(); ++i) {
        tinygltf::Image& image = model.images[i];
        if (image.uri.rfind("data:", 0) != 0) continue;
        DataUri data = decode_data_uri(image.uri);
        EncodedImage& kept = images[int(i)];
        kept.bytes = std::move(data.bytes);
        kept.problem = std::move(data.problem);
        if (kept.problem.empty() && kept.bytes.empty()) kept.problem = "its data URI holds no data";
        image.mimeType = data.type;
        image.uri.clear();
    }
    // tinygltf only warns for an external image it cannot read; texture_image fails for one a
    // material uses, and one no material uses does not matter.
    const auto about_an_image = [](const std::string& line) {
        for (const char* start : {"File not found : ", "File read error : ", "File is empty : ",
                                  "Failed to load external 'uri' for image"})
            if (line.rfind(start, 0) == 0) return true;
        return false;
    };
    std::istringstream lines(warn);
    for (std::string line; std::getline(lines, line);) {
        if (about_an_image(line)) continue;
        if (!one_line(line).empty()) warnings.push_back(name + ": " + one_line(line));
    }

    if (model.asset.version.rfind("2.", 0) != 0) {
        throw InputError(name + ": glTF version '" + model.asset.version + "' is not supported (need 2.x)");
    }
    decode_meshopt(model, fallbacks, name);
    decode_draco(model, name);
    // A required extension the loader does not know may change what the file means: said, not
    // silently ignored (those that change geometry are all decoded above).
    static const std::set<std::string> kRead = {"KHR_mesh_quantization", "EXT_meshopt_compression",
                                                "KHR_draco_mesh_compression", "KHR_materials_emissive_strength",
                                                "KHR_lights_punctual", "KHR_texture_transform", "EXT_texture_webp"};
    for (const std::string& required : model.extensionsRequired)
        if (kRead.count(required) == 0)
            warnings.push_back(fmt::format("{}: required extension {} is not supported; the scene is read without it",
                                           name, required));
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
    bool normalized = false;
    std::string what;  // "mesh 'x' primitive 0 POSITION (accessor 3)", for messages
    // A sparse accessor's elements, or an accessor's without a bufferView, made here: `data`
    // points into it.
    std::shared_ptr<const std::vector<unsigned char>> owned;

    // The value an attribute means: an integer component of a normalized accessor mapped to
    // [0, 1] or [-1, 1] as glTF defines (KHR_mesh_quantization stores positions so), else the
    // stored value.
    double value(std::size_t element, int c) const {
        const double x = get(element, c);
        if (!normalized) return x;
        switch (component_type) {
            case TINYGLTF_COMPONENT_TYPE_BYTE:
                return std::max(x / 127.0, -1.0);
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
                return x / 255.0;
            case TINYGLTF_COMPONENT_TYPE_SHORT:
                return std::max(x / 32767.0, -1.0);
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
                return x / 65535.0;
            default:
                return x;
        }
    }

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

// The bytes [offset, offset + count elements at `stride`) of bufferView `index`, checked against
// its buffer and its byteLength: for an accessor's elements and a sparse accessor's indices and
// values.
const unsigned char* view_bytes(const Loader& L, int index, std::size_t offset, std::size_t count,
                                std::size_t element, std::size_t stride, const std::string& what) {
    const tinygltf::Model& m = L.model;
    if (index < 0 || std::size_t(index) >= m.bufferViews.size()) {
        L.fail(fmt::format("{}: bufferView {} out of range ({} bufferViews)", what, index, m.bufferViews.size()));
    }
    const tinygltf::BufferView& bv = m.bufferViews[std::size_t(index)];
    if (bv.buffer < 0 || std::size_t(bv.buffer) >= m.buffers.size()) {
        L.fail(fmt::format("{}: bufferView {} names buffer {}, out of range", what, index, bv.buffer));
    }
    const std::vector<unsigned char>& bytes = m.buffers[std::size_t(bv.buffer)].data;
    if (bv.byteOffset > bytes.size() || bv.byteLength > bytes.size() - bv.byteOffset) {
        L.fail(fmt::format("{}: bufferView {} (offset {}, length {}) runs past the end of buffer {} ({} bytes)", what,
                           index, bv.byteOffset, bv.byteLength, bv.buffer, bytes.size()));
    }
    // Written as divisions so a huge count in the file cannot overflow the check itself.
    if (count > 0 && (offset > bv.byteLength || element > bv.byteLength - offset ||
                      (count - 1) > (bv.byteLength - offset - element) / stride)) {
        L.fail(fmt::format("{}: {} elements at offset {} with stride {} run past the end of bufferView {} ({} bytes)",
                           what, count, offset, stride, index, bv.byteLength));
    }
    return bytes.data() + bv.byteOffset + offset;
}

// The bytes from one of an accessor's elements to the next in its bufferView (which must exist):
// its byteStride, or the element's size where it has none.
std::size_t element_stride(const Loader& L, const tinygltf::Accessor& a, std::size_t element, const std::string& what) {
    const std::size_t view_stride =
        std::size_t(a.bufferView) < L.model.bufferViews.size() ? L.model.bufferViews[std::size_t(a.bufferView)].byteStride : 0;
    const std::size_t stride = view_stride != 0 ? view_stride : element;
    if (stride < element) {
        L.fail(fmt::format("{}: byteStride {} is shorter than one element ({} bytes)", what, stride, element));
    }
    return stride;
}

// A sparse accessor, or one without a bufferView, as glTF defines it: the elements of its
// bufferView (zeros without one), then each of `sparse.count` values written over the element
// its index names.
std::shared_ptr<const std::vector<unsigned char>> materialize(const Loader& L, const tinygltf::Accessor& a,
                                                              std::size_t element, const std::string& what) {
    constexpr std::size_t kMaxBytes = std::size_t{1} << 32;  // what a bufferView may hold, at most
    if (a.count > kMaxBytes / element)
        L.fail(fmt::format("{}: {} elements of {} bytes are more than an accessor may hold", what, a.count, element));
    auto out = std::make_shared<std::vector<unsigned char>>(a.count * element, 0);
    if (a.bufferView >= 0) {
        const std::size_t stride = element_stride(L, a, element, what);
        const unsigned char* dense = view_bytes(L, a.bufferView, a.byteOffset, a.count, element, stride, what);
        for (std::size_t i = 0; i < a.count; ++i) std::memcpy(out->data() + i * element, dense + i * stride, element);
    }
    if (!a.sparse.isSparse) return out;
    const auto& sp = a.sparse;
    if (sp.count < 1 || std::size_t(sp.count) > a.count)
        L.fail(fmt::format("{}: sparse count {} must be from 1 to the accessor's count ({})", what, sp.count, a.count));
    if (sp.indices.byteOffset < 0 || sp.values.byteOffset < 0)
        L.fail(what + ": a sparse byteOffset is negative");
    const std::size_t n = std::size_t(sp.count);
    const std::size_t index_size = component_size(sp.indices.componentType);
    if (sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        sp.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        L.fail(fmt::format("{}: sparse indices must be unsigned byte, short or int (componentType {})", what,
                           sp.indices.componentType));
    const unsigned char* indices = view_bytes(L, sp.indices.bufferView, std::size_t(sp.indices.byteOffset), n,
                                              index_size, index_size, what + " sparse indices");
    const unsigned char* values = view_bytes(L, sp.values.bufferView, std::size_t(sp.values.byteOffset), n, element,
                                             element, what + " sparse values");
    const AccessorView index_view{indices, index_size, n, 1, sp.indices.componentType, false, what, nullptr};
    for (std::size_t i = 0; i < n; ++i) {
        const double target = index_view.get(i, 0);
        if (target >= double(a.count))
            L.fail(fmt::format("{}: sparse index {} is {}, past the accessor's {} elements", what, i, target, a.count));
        std::memcpy(out->data() + std::size_t(target) * element, values + i * element, element);
    }
    return out;
}

AccessorView view_accessor(const Loader& L, int index, const std::string& where) {
    const tinygltf::Model& m = L.model;
    if (index < 0 || std::size_t(index) >= m.accessors.size()) {
        L.fail(fmt::format("{}: accessor {} out of range ({} accessors)", where, index, m.accessors.size()));
    }
    const tinygltf::Accessor& a = m.accessors[std::size_t(index)];
    const std::string what = fmt::format("{} (accessor {})", where, index);
    const std::size_t csize = component_size(a.componentType);
    const int n = component_count(a.type);
    if (csize == 0 || n == 0) L.fail(fmt::format("{}: invalid componentType {} or type", what, a.componentType));
    const std::size_t element = csize * std::size_t(n);
    if (a.sparse.isSparse || a.bufferView < 0) {
        auto owned = materialize(L, a, element, what);
        return {owned->data(), element, a.count, n, a.componentType, a.normalized, what, owned};
    }
    const std::size_t stride = element_stride(L, a, element, what);
    const unsigned char* data = view_bytes(L, a.bufferView, a.byteOffset, a.count, element, stride, what);
    return {data, stride, a.count, n, a.componentType, a.normalized, what, nullptr};
}

std::vector<dvec3> read_positions(const Loader& L, int index, const std::string& where) {
    const AccessorView v = view_accessor(L, index, where);
    // FLOAT, or (KHR_mesh_quantization) signed or unsigned bytes or shorts, normalized or not:
    // the node's transform takes the values back to the model's units.
    if (v.components != 3 || v.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT) {
        L.fail(v.what + ": POSITION must be VEC3 of FLOAT, or of bytes or shorts (KHR_mesh_quantization)");
    }
    std::vector<dvec3> out(v.count);
    for (std::size_t i = 0; i < v.count; ++i) {
        out[i] = dvec3(v.value(i, 0), v.value(i, 1), v.value(i, 2));
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

// TEXCOORD_n: FLOAT, or normalized unsigned bytes or shorts (glTF), or (KHR_mesh_quantization)
// bytes or shorts of either sign, normalized or not.
std::vector<glm::dvec2> read_texcoords(const Loader& L, int index, const std::string& where) {
    const AccessorView v = view_accessor(L, index, where);
    if (v.components != 2 || v.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        L.fail(v.what + ": a TEXCOORD must be VEC2 of FLOAT, or of bytes or shorts");
    std::vector<glm::dvec2> out(v.count);
    for (std::size_t i = 0; i < v.count; ++i) {
        out[i] = glm::dvec2(v.value(i, 0), v.value(i, 1));
        if (!std::isfinite(out[i].x) || !std::isfinite(out[i].y))
            L.fail(fmt::format("{}: texture coordinate {} is not finite (NaN or Inf)", v.what, i));
    }
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


// What a texture image is called in messages: its uri, its bufferView, or its data URI's type.
std::string image_label(const tinygltf::Model& m, int index) {
    const tinygltf::Image& img = m.images[std::size_t(index)];
    if (!img.uri.empty()) return fmt::format("image {} '{}'", index, img.uri);
    if (img.bufferView >= 0) return fmt::format("image {} (bufferView {})", index, img.bufferView);
    if (!img.mimeType.empty()) return fmt::format("image {} (embedded, {})", index, img.mimeType);
    return fmt::format("image {}", index);
}

// The decoded means of image `index` (decoded once, when a texture first needs it); !ok with the
// problem when it is missing, cannot be read or does not decode.
const ImageMean& decoded_image(Loader& L, int index, const std::string& what) {
    if (const auto done = L.images.find(index); done != L.images.end()) return done->second;
    ImageMean mean;
    const auto kept = L.encoded.find(index);
    if (kept == L.encoded.end()) {
        // tinygltf could not read the file, so never gave its bytes to the decoder: say why.
        const tinygltf::Image& img = L.model.images[std::size_t(index)];
        mean.problem = img.uri.empty() ? std::string("no image data")
                                       : regular_file_problem(fs::path(L.base_dir) / percent_decoded(img.uri));
        if (mean.problem.empty()) mean.problem = "cannot be read";
    } else if (!kept->second.problem.empty()) {
        mean.problem = kept->second.problem;
        mean.refused = kept->second.refused;
    } else {
        Texels texels;
        mean = decode_image_mean(kept->second.bytes.data(), kept->second.bytes.size(), &texels);
        L.decoded_pixels += std::uint64_t(mean.width) * std::uint64_t(mean.height);
        if (L.decoded_pixels > kMaxScenePixels)
            L.fail(fmt::format("{}: {}: the textures the scene's materials use hold more than {} pixels in all", what,
                               image_label(L.model, index), kMaxScenePixels));
        if (mean.ok) {
            L.texture_of_image[index] = int(L.scene.textures.size());
            L.scene.textures.push_back(std::make_shared<const Texture>(texels, mean.mean));
        }
    }
    if (kept != L.encoded.end()) L.encoded.erase(kept);  // decoded once; the bytes are no longer needed
    return L.images.emplace(index, std::move(mean)).first->second;
}

// A texture image that cannot be used: with --strict-textures an error naming it; otherwise the
// material reads the texture as white and opaque (its factors alone), and the image is listed
// for one warning at the end of the load.
void unusable_image(Loader& L, const std::string& what, const std::string& label, const std::string& problem) {
    if (L.strict_textures) L.fail(fmt::format("{}: {}: {}", what, label, problem));
    auto [at, added] = L.unusable_at.emplace(label, L.unusable.size());
    if (added) L.unusable.push_back({label, problem, {}});
    if (L.material >= 0) L.unusable[at->second].materials.insert(L.material);
}

// The image a texture reads and its decoded means; image -1 and white, opaque means when it has
// no texture or its image cannot be used (see unusable_image).
struct TextureImage {
    const ImageMean* mean = nullptr;
    int image = -1;  // the glTF image decoded (a key of Loader::texture_of_image), or -1
};

// The `source` of a texture's extension `name`, or -1 without one; out-of-range or non-integer
// sources are refused as the plain `source` is.
int extension_source(const Loader& L, const tinygltf::Texture& tex, const char* name, int texture,
                     const std::string& what) {
    const auto it = tex.extensions.find(name);
    if (it == tex.extensions.end() || !it->second.IsObject() || !it->second.Has("source")) return -1;
    const tinygltf::Value& v = it->second.Get("source");
    const int source = v.IsInt() ? v.GetNumberAsInt() : -1;
    if (!v.IsInt() || source < 0 || std::size_t(source) >= L.model.images.size())
        L.fail(fmt::format("{}: texture {} {} source must be an image index (0 to {})", what, texture, name,
                           int(L.model.images.size()) - 1));
    return source;
}

// The decoded means (linear colour, alpha) of the image a material's texture names: white and
// opaque when it has none. Where a texture names its image twice, EXT_texture_webp's source
// comes first and the plain `source` (a PNG or JPEG fallback for viewers without WebP) second:
// the extension's image is the one its author meant viewers that read WebP to show, and the
// fallback is still read when the WebP is missing or does not decode. An image only in
// KHR_texture_basisu (KTX2) is refused: no Debian library decodes it, and baking every texture
// of such a file as white would be silently wrong. A texture index or image index out of range
// is refused; a missing or undecodable image goes to unusable_image.
TextureImage texture_image(Loader& L, const tinygltf::TextureInfo& info, const std::string& what) {
    static const ImageMean kWhite = [] {
        ImageMean white;
        white.ok = true;
        return white;
    }();
    if (info.index < 0) return {&kWhite, -1};
    const tinygltf::Model& m = L.model;
    if (std::size_t(info.index) >= m.textures.size()) {
        L.fail(fmt::format("{}: texture {} out of range ({} textures)", what, info.index, m.textures.size()));
    }
    const tinygltf::Texture& tex = m.textures[std::size_t(info.index)];
    if (tex.source >= 0 && std::size_t(tex.source) >= m.images.size()) {
        L.fail(fmt::format("{}: texture {} names image {}, out of range", what, info.index, tex.source));
    }
    std::vector<int> sources;
    if (const int webp = extension_source(L, tex, "EXT_texture_webp", info.index, what); webp >= 0)
        sources.push_back(webp);
    if (tex.source >= 0 && (sources.empty() || sources.front() != tex.source)) sources.push_back(tex.source);
    if (sources.empty()) {
        std::string others;  // extensions that name an image hemirad does not decode
        for (const auto& [name, value] : tex.extensions)
            if (value.IsObject() && value.Has("source")) others += (others.empty() ? "" : ", ") + name;
        if (tex.extensions.count("KHR_texture_basisu"))
            L.fail(fmt::format("{}: texture {} has its image only in KHR_texture_basisu (a KTX2 / Basis Universal "
                               "image), which hemirad cannot decode (no Debian library reads KTX2); re-encode the "
                               "textures as PNG or WebP, e.g. with glTF-Transform: gltf-transform png IN.glb OUT.glb",
                               what, info.index));
        if (!others.empty())
            L.fail(fmt::format("{}: texture {} has its image only in {}, which hemirad does not decode (it reads PNG, "
                               "JPEG and WebP: 'source' or EXT_texture_webp)",
                               what, info.index, others));
        unusable_image(L, what, fmt::format("texture {}", info.index), "names no image (it has no 'source')");
        return {&kWhite, -1};
    }
    for (const int image : sources) {
        const ImageMean& mean = decoded_image(L, image, what);
        if (mean.ok) return {&mean, image};
        if (mean.refused) L.fail(fmt::format("{}: {}: {}", what, image_label(m, image), mean.problem));
    }
    const int first = sources.front();
    unusable_image(L, what, image_label(m, first), L.images.at(first).problem);
    return {&kWhite, -1};
}

// One warning per texture image that could not be used, after the materials are read (the
// first kNamed images by name, the rest counted on one line).
void warn_unusable_images(Loader& L) {
    constexpr std::size_t kNamed = 8;
    const auto materials = [&](const Loader::UnusableImage& u) {
        std::string names;
        std::size_t named = 0;
        for (const int m : u.materials) {
            if (named++ == 3) break;
            names += fmt::format("{}'{}'", names.empty() ? "" : ", ", L.scene.materials[std::size_t(m)].name);
        }
        if (u.materials.size() > 3) names += fmt::format(" and {} more", grouped(u.materials.size() - 3));
        return fmt::format("{} ({})", counted(u.materials.size(), "material"), names);
    };
    for (std::size_t i = 0; i < L.unusable.size() && i < kNamed; ++i) {
        const Loader::UnusableImage& u = L.unusable[i];
        L.warn(fmt::format("{}: {}; the {} reading it bake{} with their factors alone, as under a white texture "
                           "(--strict-textures makes this an error)",
                           u.label, u.problem, materials(u), u.materials.size() == 1 ? "s" : ""));
    }
    if (L.unusable.size() > kNamed) {
        std::set<int> all;
        std::string labels;
        for (std::size_t i = kNamed; i < L.unusable.size(); ++i) {
            all.insert(L.unusable[i].materials.begin(), L.unusable[i].materials.end());
            if (i < kNamed + 3) labels += (labels.empty() ? "" : ", ") + L.unusable[i].label;
        }
        if (L.unusable.size() > kNamed + 3) labels += ", ...";
        L.warn(fmt::format("{} more texture images cannot be used either ({}); the {} reading them bake with their "
                           "factors alone (--strict-textures makes this an error)",
                           grouped(L.unusable.size() - kNamed), labels, counted(all.size(), "material")));
    }
}

Wrap wrap_mode(const Loader& L, int mode, const std::string& what) {
    switch (mode) {
        case TINYGLTF_TEXTURE_WRAP_REPEAT:
            return Wrap::repeat;
        case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE:
            return Wrap::clamp;
        case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT:
            return Wrap::mirror;
        default:
            L.fail(fmt::format("{}: wrap mode {} is not a glTF wrap mode", what, mode));
    }
}

// A number of a KHR_texture_transform object, or `fallback` where absent.
double transform_number(const Loader& L, const tinygltf::Value& ext, const char* key, int i, double fallback,
                        const std::string& what) {
    if (!ext.Has(key)) return fallback;
    const tinygltf::Value& v = ext.Get(key);
    const tinygltf::Value& n = i < 0 ? v : (v.IsArray() && v.ArrayLen() == 2 ? v.Get(i) : tinygltf::Value());
    if (!n.IsNumber() || !std::isfinite(n.GetNumberAsDouble()))
        L.fail(fmt::format("{}: KHR_texture_transform {} must be {}", what, key,
                           i < 0 ? "a finite number" : "two finite numbers"));
    return n.GetNumberAsDouble();
}

// The texture coordinate set and transform a texture is read through: texCoord, unless
// KHR_texture_transform names another, and the extension's offset . rotation . scale (its
// rotation turns the coordinates counter-clockwise, as the extension's GLSL reads).
UvSource uv_source(const Loader& L, const tinygltf::TextureInfo& info, const std::string& what) {
    UvSource src;
    src.used = info.index >= 0;
    src.set = info.texCoord;
    const auto it = info.extensions.find("KHR_texture_transform");
    if (it != info.extensions.end() && it->second.IsObject()) {
        const tinygltf::Value& ext = it->second;
        const double ox = transform_number(L, ext, "offset", 0, 0.0, what);
        const double oy = transform_number(L, ext, "offset", 1, 0.0, what);
        const double r = transform_number(L, ext, "rotation", -1, 0.0, what);
        const double sx = transform_number(L, ext, "scale", 0, 1.0, what);
        const double sy = transform_number(L, ext, "scale", 1, 1.0, what);
        if (ext.Has("texCoord")) src.set = int(transform_number(L, ext, "texCoord", -1, 0.0, what));
        const glm::dmat3 translation(1, 0, 0, 0, 1, 0, ox, oy, 1);  // column-major, as GLSL's mat3
        const glm::dmat3 rotation(std::cos(r), std::sin(r), 0, -std::sin(r), std::cos(r), 0, 0, 0, 1);
        const glm::dmat3 scale(sx, 0, 0, 0, sy, 0, 0, 0, 1);
        src.transform = translation * rotation * scale;
    }
    if (src.set < 0) L.fail(fmt::format("{}: texCoord {} is negative", what, src.set));
    return src;
}

// All a material reads of one of its textures: the image's means (white and opaque without a
// texture), the decoded texture with its sampler's wrap modes, and the coordinates it is read
// through. Decodes the image if no texture has yet; fails for a bad texture, image or sampler.
struct MaterialTexture {
    const ImageMean* image = nullptr;
    TextureSlot slot;
    UvSource uv;
};

MaterialTexture read_texture(Loader& L, const tinygltf::TextureInfo& info, const std::string& what) {
    const TextureImage image = texture_image(L, info, what);
    MaterialTexture out{image.mean, {}, {}};
    if (image.image < 0) return out;  // no texture, or one whose image cannot be used: its factors
    const tinygltf::Texture& tex = L.model.textures[std::size_t(info.index)];
    out.slot.texture = L.texture_of_image.at(image.image);
    if (tex.sampler >= 0) {
        if (std::size_t(tex.sampler) >= L.model.samplers.size())
            L.fail(fmt::format("{}: texture {} names sampler {}, out of range", what, info.index, tex.sampler));
        const tinygltf::Sampler& sampler = L.model.samplers[std::size_t(tex.sampler)];
        out.slot.wrap_s = wrap_mode(L, sampler.wrapS, fmt::format("{}: sampler {} wrapS", what, tex.sampler));
        out.slot.wrap_t = wrap_mode(L, sampler.wrapT, fmt::format("{}: sampler {} wrapT", what, tex.sampler));
    }
    out.uv = uv_source(L, info, what);
    return out;
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

// Whether light passes the material's surfaces (Material::see_through), by its opacity: for
// alphaMode BLEND, baseColorFactor alpha x the base colour texture's mean alpha; for
// KHR_materials_transmission, 1 - transmissionFactor. Exporters mark many opaque materials BLEND
// (an alpha channel in the texture is enough: lanterns, windows, decals at 95-100% opacity), so
// the opacity decides: below one half, see-through. An emitter must be fainter, below a quarter
// (a fake light shaft or glow sprite: botanists-study's light cone, 0.07); a denser one stays an
// opaque emitter, said in a warning (a lamp exported as a blended glow is still the scene's
// light: botanists-study's only lamp, 0.32), since a surface that emits without blocking needs a
// shooter the kernels do not yet have.
void see_through(Loader& L, const tinygltf::Material& mat, const std::string& label, Material& out) {
    double opacity = 1.0;
    std::string why;
    if (mat.alphaMode == "BLEND") {
        const std::vector<double>& base = mat.pbrMetallicRoughness.baseColorFactor;
        opacity = base[3] * texture_image(L, mat.pbrMetallicRoughness.baseColorTexture, label + " baseColorTexture").mean->alpha;
        why = fmt::format("alphaMode BLEND, mean opacity {:.2f}", opacity);
    }
    if (const auto it = mat.extensions.find("KHR_materials_transmission"); it != mat.extensions.end()) {
        // transmissionFactor defaults to 0: a texture alone transmits nothing.
        const tinygltf::Value& factor = it->second.IsObject() && it->second.Has("transmissionFactor")
                                            ? it->second.Get("transmissionFactor")
                                            : tinygltf::Value();
        if (factor.IsNumber() && 1.0 - factor.GetNumberAsDouble() < opacity) {
            opacity = 1.0 - factor.GetNumberAsDouble();
            why = fmt::format("KHR_materials_transmission {:g}", factor.GetNumberAsDouble());
        }
    }
    const bool emits = out.emission != dvec3(0.0);
    if (opacity >= (emits ? 0.25 : 0.5)) {
        if (emits && opacity < 0.5)
            L.group("dense glow", "{names} but emitting, and denser than a fake light shaft: baked as an opaque emitter",
                    "{n} materials are see-through but emitting, and denser than a fake light shaft: baked as opaque "
                    "emitters ({names})",
                    fmt::format("{}: see-through ({})", label, why));
        return;
    }
    out.see_through = why;
    out.opacity = opacity;
}

Material convert_material(Loader& L, int index) {
    const tinygltf::Material& mat = L.model.materials[std::size_t(index)];
    const std::string label = material_label(mat, index);
    L.material = index;
    Material out;
    out.name = mat.name.empty() ? fmt::format("material{}", index) : mat.name;
    out.double_sided = mat.doubleSided;

    const std::vector<double>& base = mat.pbrMetallicRoughness.baseColorFactor;
    if (base.size() != 4) L.fail(label + ": baseColorFactor must have 4 components");
    check_factor(L, base, label + ": baseColorFactor");
    const MaterialTexture base_texture =
        read_texture(L, mat.pbrMetallicRoughness.baseColorTexture, label + " baseColorTexture");
    out.base_color = dvec3(base[0], base[1], base[2]) * base_texture.image->mean;
    out.base_texture = base_texture.slot;
    out.coloured_texture = base_texture.image->coloured;
    out.alpha_factor = base[3];
    if (mat.alphaMode == "MASK") {
        out.alpha_cutoff = mat.alphaCutoff;
        if (!(out.alpha_cutoff >= 0.0) || !std::isfinite(out.alpha_cutoff))
            L.fail(fmt::format("{}: alphaCutoff {} must be finite and >= 0", label, mat.alphaCutoff));
    }
    std::array<UvSource, 2> uv{base_texture.uv, UvSource{}};

    const std::vector<double>& emissive = mat.emissiveFactor;
    if (!emissive.empty() && emissive.size() != 3) L.fail(label + ": emissiveFactor must have 3 components");
    check_factor(L, emissive, label + ": emissiveFactor");
    const double strength = emissive_strength(L, mat, label);
    if (!emissive.empty() && (emissive[0] > 0.0 || emissive[1] > 0.0 || emissive[2] > 0.0) && strength > 0.0) {
        const MaterialTexture emissive_texture = read_texture(L, mat.emissiveTexture, label + " emissiveTexture");
        out.emission = dvec3(emissive[0], emissive[1], emissive[2]) * strength * emissive_texture.image->mean;
        out.emissive_texture = emissive_texture.slot;
        out.coloured_texture = out.coloured_texture || emissive_texture.image->coloured;
        uv[1] = emissive_texture.uv;
    }
    if (L.uv_sources.size() <= std::size_t(index)) L.uv_sources.resize(std::size_t(index) + 1);
    L.uv_sources[std::size_t(index)] = uv;
    see_through(L, mat, label, out);
    for (int c = 0; c < 3; ++c) {
        if (!(out.emission[c] <= kMaxEmission)) {
            L.fail(fmt::format("{}: emission {:g} (emissiveFactor x emissiveStrength x texture) is above {:g}: the "
                               "outputs hold 32-bit floats, and reflection can multiply it 10^4 times; rescale the "
                               "scene's units",
                               label, out.emission[c], kMaxEmission));
        }
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
        L.group(fmt::format("mode {}", name), fmt::format("{{names}}: mode {} is not triangles; skipped", name),
                fmt::format("{{n}} primitives of mode {} are not triangles; skipped ({{names}})", name), where);
        return;
    }
    const auto position = prim.attributes.find("POSITION");
    if (position == prim.attributes.end()) {
        L.group("no position", "{names}: has no POSITION; skipped",
                "{n} primitives have no POSITION; skipped ({names})", where);
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

    // The texture coordinates of the material's base colour and emissive textures, transformed.
    std::array<std::vector<glm::dvec2>, 2> uvs;
    for (std::size_t slot = 0; slot < 2 && material < L.uv_sources.size(); ++slot) {
        const UvSource& src = L.uv_sources[material][slot];
        if (!src.used) continue;
        const std::string name = fmt::format("TEXCOORD_{}", src.set);
        const auto a = prim.attributes.find(name);
        if (a == prim.attributes.end()) {  // invalid glTF, but the texture's mean still stands for it
            if (L.warned.insert(fmt::format("notexcoord {} {}", material, slot)).second)
                L.group("no " + name,
                        fmt::format("{{names}} through {}, which the primitive lacks; the texture's mean colour is used",
                                    name),
                        fmt::format("{{n}} textures are read through {}, which their primitives lack; each texture's "
                                    "mean colour is used ({{names}})",
                                    name),
                        fmt::format("{}: material '{}' reads its {} texture", where, mat.name,
                                    slot == 0 ? "base colour" : "emissive"));
            continue;
        }
        uvs[slot] = read_texcoords(L, a->second, where + " " + name);
        if (uvs[slot].size() != positions.size())
            L.fail(fmt::format("{} {}: {} coordinates for {} positions", where, name, uvs[slot].size(), positions.size()));
        for (glm::dvec2& uv : uvs[slot]) uv = glm::dvec2(src.transform * glm::dvec3(uv, 1.0));
    }

    const dmat4& world = ref.instance->world;
    // A mirroring transform turns counter-clockwise into clockwise; swapping two vertices
    // keeps the side the file called front as the front.
    const bool mirrored = glm::determinant(glm::dmat3(world)) < 0.0;
    bool clamped = false;
    const std::uint32_t primitive = primitive_counter++;
    L.source.primitives.push_back({ref.mesh, ref.index});
    for (std::size_t k = 0; k < indices.size(); k += 3) {
        if (k % (3 << 16) == 0) cancel::check();
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
            if (!uvs[0].empty()) t.uv_base[std::size_t(v)] = glm::vec2(uvs[0][i]);
            if (!uvs[1].empty()) t.uv_emissive[std::size_t(v)] = glm::vec2(uvs[1][i]);
            t.corner[std::size_t(v)] = i;
        }
        if (mirrored) {
            std::swap(t.p[1], t.p[2]);
            std::swap(t.corner[1], t.corner[2]);
            std::swap(t.rho[1], t.rho[2]);
            std::swap(t.uv_base[1], t.uv_base[2]);
            std::swap(t.uv_emissive[1], t.uv_emissive[2]);
        }
        t.uv_slots = std::uint8_t((uvs[0].empty() ? 0 : 1) | (uvs[1].empty() ? 0 : 2));
        t.material = material;
        t.node = ref.scene_node;
        t.primitive = primitive;
        L.scene.triangles.push_back(t);
    }
    if (clamped) L.clamped.insert(material);
}

// A node's KHR_lights_punctual light: its type, colour and intensity from the file's list,
// placed at the node's origin and shining along its -Z axis.
void add_light(Loader& L, const Instance& inst, const tinygltf::Value& ext) {
    const std::string where = fmt::format("node {} KHR_lights_punctual", inst.node);
    if (!ext.IsObject() || !ext.Has("light") || !ext.Get("light").IsInt())
        L.fail(where + ": 'light' must be the index of a light");
    const int index = ext.Get("light").GetNumberAsInt();
    if (index < 0 || std::size_t(index) >= L.model.lights.size())
        L.fail(fmt::format("{}: light {} out of range ({} lights)", where, index, L.model.lights.size()));
    const tinygltf::Light& in = L.model.lights[std::size_t(index)];
    const std::string label =
        in.name.empty() ? fmt::format("light {}", index) : fmt::format("light {} '{}'", index, in.name);
    PunctualLight out;
    out.name = !in.name.empty() ? in.name : fmt::format("light{}", index);
    if (in.type == "point") {
        out.type = PunctualLight::Type::point;
    } else if (in.type == "spot") {
        out.type = PunctualLight::Type::spot;
    } else if (in.type == "directional") {
        out.type = PunctualLight::Type::directional;
    } else {
        L.fail(fmt::format("{}: type '{}' is not point, spot or directional", label, in.type));
    }
    dvec3 colour(1.0);
    if (!in.color.empty()) {
        if (in.color.size() != 3) L.fail(label + ": color must have 3 components");
        check_factor(L, in.color, label + ": color");
        colour = dvec3(in.color[0], in.color[1], in.color[2]);
    }
    if (!(in.intensity >= 0.0) || !std::isfinite(in.intensity))
        L.fail(fmt::format("{}: intensity {} must be finite and >= 0", label, in.intensity));
    out.intensity = colour * in.intensity;
    for (int c = 0; c < 3; ++c)
        if (!(out.intensity[c] <= kMaxEmission))
            L.fail(fmt::format("{}: intensity {:g} is above {:g}; rescale the scene's units", label, out.intensity[c],
                               kMaxEmission));
    if (!(in.range >= 0.0) || !std::isfinite(in.range))
        L.fail(fmt::format("{}: range {} must be finite and > 0", label, in.range));
    out.range = in.range;
    if (out.type == PunctualLight::Type::spot) {
        const double inner = in.spot.innerConeAngle, outer = in.spot.outerConeAngle;
        if (!(inner >= 0.0 && inner < outer && outer <= 0.5 * glm::pi<double>()))
            L.fail(fmt::format("{}: cone angles inner {} and outer {} must satisfy 0 <= inner < outer <= pi/2", label,
                               inner, outer));
        out.inner_cone = inner;
        out.outer_cone = outer;
    }
    out.position = dvec3(inst.world[3]);
    const dvec3 axis = -dvec3(inst.world[2]);
    const double length = glm::length(axis);
    if (!(length > 0.0) || !std::isfinite(length) || !std::isfinite(glm::length(out.position)))
        L.fail(fmt::format("{}: node {} places it with a degenerate transform", label, inst.node));
    out.direction = axis / length;
    L.light_of_node[inst.node] = L.scene.lights.size();
    L.scene.lights.push_back(out);
}

// Meshes placed under a point or spot light's node (or on it) that enclose the light are its
// bulb, a visible stand-in for the light (an exporter's sphere of the light's radius): they
// would hide the light they stand for, so they are left out, with a warning naming them.
void leave_out_bulbs(Loader& L) {
    if (L.light_of_node.empty()) return;
    const tinygltf::Model& m = L.model;
    std::vector<int> parent(m.nodes.size(), -1);
    for (std::size_t i = 0; i < m.nodes.size(); ++i)
        for (const int child : m.nodes[i].children)
            if (child >= 0 && std::size_t(child) < m.nodes.size()) parent[std::size_t(child)] = int(i);
    Scene& scene = L.scene;
    std::vector<char> bulb(scene.nodes.size(), 0);
    for (std::size_t n = 0; n < scene.nodes.size(); ++n) {
        int at = scene.nodes[n].gltf_node;
        for (int steps = 0; at >= 0 && steps <= int(m.nodes.size()); ++steps, at = parent[std::size_t(at)]) {
            const auto light = L.light_of_node.find(at);
            if (light == L.light_of_node.end()) continue;
            const PunctualLight& l = scene.lights[light->second];
            if (l.type == PunctualLight::Type::directional) break;
            dvec3 lo(HUGE_VAL), hi(-HUGE_VAL);
            for (const Triangle& t : scene.triangles)
                if (t.node == n)
                    for (const dvec3& p : t.p) {
                        lo = glm::min(lo, p);
                        hi = glm::max(hi, p);
                    }
            if (glm::all(glm::greaterThanEqual(l.position, lo)) && glm::all(glm::lessThanEqual(l.position, hi))) {
                bulb[n] = 1;
                L.group("bulb",
                        "{names} and encloses it: taken as the light's bulb and left out, since it would hide the "
                        "light it stands for",
                        "{n} nodes lie under a light and enclose it: taken as the lights' bulbs and left out, since "
                        "they would hide the lights they stand for ({names})",
                        fmt::format("node '{}' lies under light '{}'", scene.nodes[n].name, l.name));
            }
            break;
        }
    }
    scene.triangles.erase(std::remove_if(scene.triangles.begin(), scene.triangles.end(),
                                         [&](const Triangle& t) { return t.node < bulb.size() && bulb[t.node]; }),
                          scene.triangles.end());
}

// Skinned meshes (a node with a skin, or primitives with JOINTS_0 and WEIGHTS_0) and meshes that
// an animation moves (a channel targets their node or one above it) are baked as the file places
// them, in their bind or rest pose: one warning says so, counting them, since their light will not
// follow them when the file is played.
void warn_animated(Loader& L, const std::vector<Instance>& instances) {
    const tinygltf::Model& m = L.model;
    std::vector<char> targeted(m.nodes.size(), 0);
    for (const tinygltf::Animation& a : m.animations)
        for (const tinygltf::AnimationChannel& c : a.channels)
            if (c.target_node >= 0 && std::size_t(c.target_node) < m.nodes.size()) targeted[std::size_t(c.target_node)] = 1;
    std::vector<int> parent(m.nodes.size(), -1);
    for (std::size_t i = 0; i < m.nodes.size(); ++i)
        for (const int child : m.nodes[i].children)
            if (child >= 0 && std::size_t(child) < m.nodes.size()) parent[std::size_t(child)] = int(i);
    std::size_t meshes = 0, skinned = 0, animated = 0;
    std::string names;  // the first few
    for (const Instance& inst : instances) {
        const tinygltf::Node& node = m.nodes[std::size_t(inst.node)];
        if (node.mesh < 0 || std::size_t(node.mesh) >= m.meshes.size()) continue;
        bool skin = node.skin >= 0;
        for (const tinygltf::Primitive& p : m.meshes[std::size_t(node.mesh)].primitives)
            skin = skin || (p.attributes.count("JOINTS_0") && p.attributes.count("WEIGHTS_0"));
        bool moved = false;
        for (int at = inst.node, steps = 0; at >= 0 && !moved && steps <= int(m.nodes.size());
             at = parent[std::size_t(at)], ++steps)
            moved = targeted[std::size_t(at)] != 0;
        if (!skin && !moved) continue;
        skinned += skin ? 1 : 0;
        animated += moved ? 1 : 0;
        if (++meshes <= 3)
            names += fmt::format("{}'{}'", meshes > 1 ? ", " : "",
                                 !node.name.empty() ? node.name : m.meshes[std::size_t(node.mesh)].name);
    }
    if (meshes == 0) return;
    std::string what;
    if (skinned > 0) what = fmt::format("{} skinned", grouped(skinned));
    if (animated > 0) what += fmt::format("{}{} moved by an animation", what.empty() ? "" : ", ", grouped(animated));
    L.warn(fmt::format("{} ({}: {}{}) {} baked in {} bind or rest pose, as the file places {}; {} light will not "
                       "follow the animation",
                       counted(meshes, "mesh", "meshes"), what, names, meshes > 3 ? ", ..." : "",
                       meshes == 1 ? "is" : "are",
                       meshes == 1 ? "its" : "their", meshes == 1 ? "it" : "them", meshes == 1 ? "its" : "their"));
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
    // Invalid glTF is refused; legal values no image can be made with are clamped, with a warning.
    if (!(p.yfov > 0.0 && p.yfov < glm::pi<double>())) {
        L.fail(fmt::format("camera '{}': yfov {} must be in (0, pi)", name, p.yfov));
    }
    if (!(p.znear > 0.0) || !std::isfinite(p.znear)) {
        L.fail(fmt::format("camera '{}': znear {} must be > 0", name, p.znear));
    }
    // tinygltf reads an absent aspectRatio as 0 (the render is then square).
    if (!(p.aspectRatio >= 0.0) || !std::isfinite(p.aspectRatio)) {
        L.fail(fmt::format("camera '{}': aspectRatio {} must be > 0", name, p.aspectRatio));
    }
    Camera out;
    out.name = name;
    out.camera_to_world = rigid_frame(L, inst.world, inst.node);
    out.yfov = std::max(p.yfov, kMinYfov);
    if (out.yfov != p.yfov) {
        L.warn(fmt::format("camera '{}': yfov {:g} is too narrow to render; using {:g}", name, p.yfov, out.yfov));
    }
    out.aspect = p.aspectRatio > 0.0 ? std::clamp(p.aspectRatio, kMinAspect, kMaxAspect) : 0.0;
    if (out.aspect != p.aspectRatio) {
        L.warn(fmt::format("camera '{}': aspectRatio {:g} is outside [{:g}, {:g}]; using {:g}", name, p.aspectRatio,
                           kMinAspect, kMaxAspect, out.aspect));
    }
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

std::string percent_decoded(const std::string& uri) {
    std::string out;
    for (std::size_t i = 0; i < uri.size(); ++i) {
        if (uri[i] == '%' && i + 2 < uri.size() && std::isxdigit(static_cast<unsigned char>(uri[i + 1])) &&
            std::isxdigit(static_cast<unsigned char>(uri[i + 2]))) {
            out += static_cast<char>(std::stoi(uri.substr(i + 1, 2), nullptr, 16));
            i += 2;
        } else {
            out += uri[i];
        }
    }
    return out;
}

double PunctualLight::attenuation(const glm::dvec3& to_point) const {
    const double distance = glm::length(to_point);
    double a = 1.0;
    if (range > 0.0) {
        const double r = distance / range;
        const double window = std::clamp(1.0 - r * r * r * r, 0.0, 1.0);
        a *= window * window;
    }
    if (type == Type::spot) {
        const double cd = distance > 0.0 ? glm::dot(direction, to_point) / distance : 1.0;
        const double scale = 1.0 / std::max(1e-3, std::cos(inner_cone) - std::cos(outer_cone));
        const double t = std::clamp((cd - std::cos(outer_cone)) * scale, 0.0, 1.0);
        a *= t * t;
    }
    return a;
}

Scene load(const std::filesystem::path& file, const LoadOptions& options) {
    Scene scene;
    scene.path = file;
    const std::string name = file.string();
    std::map<int, EncodedImage> images;
    auto source = std::make_shared<GltfSource>();
    double triangles = 0.0;
    source->model = parse(file, name, scene.warnings, images, options, triangles);
    // As many as the file places, once they were held against a limit: the vector never doubles.
    if (std::isfinite(options.max_bytes)) scene.triangles.reserve(std::size_t(triangles));
    source->base_dir = base_dir(name);
    const tinygltf::Model& model = source->model;
    for (std::size_t i = 0; i < model.images.size(); ++i) {  // data uris: tinygltf keeps no uri for them
        const tinygltf::Image& image = model.images[i];
        const auto kept = images.find(int(i));
        if (image.uri.empty() && image.bufferView < 0 && kept != images.end() && !kept->second.bytes.empty())
            source->embedded_images[int(i)] = kept->second.bytes;
    }
    Loader L{model, *source, name, scene, {}, -1, base_dir(name), std::move(images), {}, 0, {}, {}, {}, {}};
    L.strict_textures = options.strict_textures;

    // Converted in file order so a primitive's material index is also its Scene index.
    for (std::size_t i = 0; i < model.materials.size(); ++i) scene.materials.push_back(convert_material(L, int(i)));
    warn_unusable_images(L);

    std::vector<Instance> instances = instantiate(L, root_nodes(L));
    // Scene::nodes is in glTF node order; triangles follow the same order.
    std::stable_sort(instances.begin(), instances.end(),
                     [](const Instance& a, const Instance& b) { return a.node < b.node; });

    std::uint32_t primitive_counter = 0;
    for (const Instance& inst : instances) {
        cancel::check();  // a signal while a large scene loads (core/cancel.h)
        const tinygltf::Node& node = model.nodes[std::size_t(inst.node)];
        if (node.camera >= 0) {
            if (std::size_t(node.camera) >= model.cameras.size()) {
                L.fail(fmt::format("node {}: camera {} out of range ({} cameras)", inst.node, node.camera,
                                   model.cameras.size()));
            }
            add_camera(L, inst);
        }
        if (const auto light = node.extensions.find("KHR_lights_punctual"); light != node.extensions.end())
            add_light(L, inst, light->second);
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
        mesh_node.world = inst.world;
        const auto scene_node = std::uint32_t(scene.nodes.size());
        scene.nodes.push_back(mesh_node);
        for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
            add_primitive(L, {&inst, scene_node, node.mesh, int(p)}, primitive_counter);
        }
    }
    leave_out_bulbs(L);
    L.warn_grouped();
    warn_animated(L, instances);
    if (!L.clamped.empty()) {  // one line for them all
        constexpr std::size_t kNamed = 5;
        std::string names;
        std::size_t named = 0;
        for (const std::uint32_t m : L.clamped) {
            if (named++ == kNamed) break;
            names += fmt::format("{}'{}'", names.empty() ? "" : ", ", scene.materials[m].name);
        }
        if (L.clamped.size() > kNamed) names += fmt::format(" and {} more", L.clamped.size() - kNamed);
        L.warn(fmt::format("{} material{} reflect{} 1, which cannot conserve energy; clamped to {}: {}", L.clamped.size(),
                           L.clamped.size() == 1 ? "" : "s", L.clamped.size() == 1 ? "s" : "", kMaxReflectance, names));
    }
    compute_bbox(scene);
    scene.source = std::move(source);
    return scene;
}

}  // namespace hemirad::scene
