// EXT_meshopt_compression and KHR_draco_mesh_compression (see gltf_compression.h).
#include "scene/gltf_compression.h"

#include <draco/compression/decode.h>
#include <fmt/format.h>
#include <meshoptimizer.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <new>
#include <nlohmann/json.hpp>
#include <string_view>

#include "core/error.h"

namespace hemirad::scene {
namespace {

constexpr const char* kMeshopt = "EXT_meshopt_compression";
constexpr const char* kDraco = "KHR_draco_mesh_compression";
constexpr std::size_t kGlbHeader = 12, kChunkHeader = 8;
// The most a fallback buffer is made to hold: what any buffer file may (the loader's limit).
constexpr std::uint64_t kMaxFallbackBytes = std::uint64_t{1} << 32;

std::uint32_t read32(const unsigned char* p) {
    return std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[3]) << 24;
}
void write32(unsigned char* p, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}

bool mentions(const unsigned char* text, std::size_t size, std::string_view word) {
    return std::string_view(reinterpret_cast<const char*>(text), size).find(word) != std::string_view::npos;
}

// Whether the JSON of a buffer marks it as a meshopt fallback with no bytes of its own.
bool is_bare_fallback(const nlohmann::json& buffer) {
    if (!buffer.is_object() || buffer.contains("uri")) return false;
    const auto extensions = buffer.find("extensions");
    if (extensions == buffer.end() || !extensions->is_object()) return false;
    const auto meshopt = extensions->find(kMeshopt);
    if (meshopt == extensions->end() || !meshopt->is_object()) return false;
    const auto fallback = meshopt->find("fallback");
    return fallback != meshopt->end() && fallback->is_boolean() && fallback->get<bool>();
}

// A whole number in [0, 2^53] from a tinygltf value, or -1.
double whole_number(const tinygltf::Value& v) {
    if (!v.IsNumber()) return -1.0;
    const double x = v.GetNumberAsDouble();
    return x >= 0.0 && x <= 9007199254740992.0 && std::floor(x) == x ? x : -1.0;
}

}  // namespace

MeshoptFallbacks stand_in_for_compressed_data(std::vector<unsigned char>& bytes, bool glb, const std::string& name) {
    MeshoptFallbacks fallbacks;
    // A .glb as read_glb checked it: a header and a JSON chunk within the bytes.
    const std::size_t json_start = glb ? kGlbHeader + kChunkHeader : 0;
    const std::size_t json_length = glb ? read32(bytes.data() + kGlbHeader) : bytes.size();
    const bool meshopt = mentions(bytes.data() + json_start, json_length, kMeshopt);
    const bool draco = mentions(bytes.data() + json_start, json_length, kDraco);
    if (!meshopt && !draco) return fallbacks;

    nlohmann::json doc = nlohmann::json::parse(bytes.begin() + std::ptrdiff_t(json_start),
                                               bytes.begin() + std::ptrdiff_t(json_start + json_length), nullptr,
                                               /*allow_exceptions=*/false);
    if (doc.is_discarded() || !doc.is_object()) return fallbacks;  // tinygltf says what is wrong with it
    bool changed = false;
    const auto buffers = doc.find("buffers");
    for (std::size_t b = 0; meshopt && buffers != doc.end() && buffers->is_array() && b < buffers->size(); ++b) {
        nlohmann::json& buffer = (*buffers)[b];
        if (!is_bare_fallback(buffer) || (glb && b == 0)) continue;  // a .glb's first buffer is its BIN chunk
        const auto length = buffer.find("byteLength");
        if (length == buffer.end() || !length->is_number_unsigned())
            throw InputError(fmt::format("{}: buffer {} ({} fallback): byteLength must be a whole number of bytes",
                                         name, b, kMeshopt));
        fallbacks[int(b)] = length->get<std::uint64_t>();
        buffer["uri"] = "data:application/octet-stream;base64,AA==";  // one zero byte
        buffer["byteLength"] = 1;
        changed = true;
    }
    // A Draco primitive's indices accessor has no bufferView, which tinygltf refuses: the
    // primitive loses its indices here, and decode_draco gives it the decoded ones.
    const auto meshes = doc.find("meshes");
    for (std::size_t m = 0; draco && meshes != doc.end() && meshes->is_array() && m < meshes->size(); ++m) {
        const auto primitives = (*meshes)[m].is_object() ? (*meshes)[m].find("primitives") : (*meshes)[m].end();
        if (primitives == (*meshes)[m].end() || !primitives->is_array()) continue;
        for (nlohmann::json& primitive : *primitives) {
            if (!primitive.is_object() || !primitive.contains("extensions") || !primitive["extensions"].is_object() ||
                !primitive["extensions"].contains(kDraco))
                continue;
            changed = primitive.erase("indices") > 0 || changed;
        }
    }
    if (!changed) return fallbacks;

    std::string json = doc.dump();
    if (!glb) {
        bytes.assign(json.begin(), json.end());
        return fallbacks;
    }
    json.resize((json.size() + 3) / 4 * 4, ' ');  // chunks are 4-byte aligned, JSON padded with spaces
    const std::size_t rest = json_start + json_length;  // the chunks after the JSON
    std::vector<unsigned char> glb_bytes(kGlbHeader + kChunkHeader + json.size() + (bytes.size() - rest));
    std::memcpy(glb_bytes.data(), bytes.data(), kGlbHeader);
    write32(glb_bytes.data() + 8, static_cast<std::uint32_t>(glb_bytes.size()));
    write32(glb_bytes.data() + kGlbHeader, static_cast<std::uint32_t>(json.size()));
    std::memcpy(glb_bytes.data() + kGlbHeader + 4, bytes.data() + kGlbHeader + 4, 4);  // "JSON"
    std::memcpy(glb_bytes.data() + kGlbHeader + kChunkHeader, json.data(), json.size());
    std::copy(bytes.begin() + std::ptrdiff_t(rest), bytes.end(),
              glb_bytes.begin() + std::ptrdiff_t(kGlbHeader + kChunkHeader + json.size()));
    bytes = std::move(glb_bytes);
    return fallbacks;
}

void decode_meshopt(tinygltf::Model& model, const MeshoptFallbacks& fallbacks, const std::string& name) {
    // The fallback buffers hold only what the views decode into: sized to the farthest byte a
    // view with the extension names, within the byteLength the file declares.
    for (const auto& [index, declared] : fallbacks) {
        std::uint64_t needed = 0;
        for (const tinygltf::BufferView& view : model.bufferViews)
            if (view.buffer == index && view.extensions.count(kMeshopt) != 0)
                needed = std::max<std::uint64_t>(needed, std::uint64_t(view.byteOffset) + view.byteLength);
        needed = std::min(needed, declared);
        if (needed > kMaxFallbackBytes)
            throw InputError(fmt::format("{}: buffer {} ({} fallback): its bufferViews need {} bytes, above the limit "
                                         "of {}",
                                         name, index, kMeshopt, needed, kMaxFallbackBytes));
        model.buffers[std::size_t(index)].data.assign(std::size_t(needed), 0);
    }

    for (std::size_t v = 0; v < model.bufferViews.size(); ++v) {
        tinygltf::BufferView& view = model.bufferViews[v];
        const auto found = view.extensions.find(kMeshopt);
        if (found == view.extensions.end()) continue;
        const std::string what = fmt::format("{}: bufferView {} ({})", name, v, kMeshopt);
        const tinygltf::Value& ext = found->second;
        if (!ext.IsObject()) throw InputError(what + ": the extension is not an object");
        const auto number = [&](const char* key, bool required) -> std::uint64_t {
            if (!ext.Has(key)) {
                if (required) throw InputError(fmt::format("{}: {} is missing", what, key));
                return 0;
            }
            const double x = whole_number(ext.Get(key));
            if (x < 0.0) throw InputError(fmt::format("{}: {} must be a whole number", what, key));
            return static_cast<std::uint64_t>(x);
        };
        const auto text = [&](const char* key, const char* otherwise) {
            if (!ext.Has(key)) return std::string(otherwise);
            if (!ext.Get(key).IsString()) throw InputError(fmt::format("{}: {} must be a string", what, key));
            return ext.Get(key).Get<std::string>();
        };
        const std::uint64_t source_buffer = number("buffer", true);
        const std::uint64_t source_offset = number("byteOffset", false);
        const std::uint64_t source_length = number("byteLength", true);
        const std::uint64_t stride = number("byteStride", true);
        const std::uint64_t count = number("count", true);
        const std::string mode = text("mode", "");
        const std::string filter = text("filter", "NONE");

        if (source_buffer >= model.buffers.size())
            throw InputError(fmt::format("{}: buffer {} out of range ({} buffers)", what, source_buffer,
                                         model.buffers.size()));
        const std::vector<unsigned char>& source = model.buffers[std::size_t(source_buffer)].data;
        if (source_offset > source.size() || source_length > source.size() - source_offset)
            throw InputError(fmt::format("{}: {} bytes at offset {} run past the end of buffer {} ({} bytes)", what,
                                         source_length, source_offset, source_buffer, source.size()));
        if (view.buffer < 0 || std::size_t(view.buffer) >= model.buffers.size())
            throw InputError(fmt::format("{}: names buffer {}, out of range", what, view.buffer));
        if (source_buffer == std::uint64_t(view.buffer))
            throw InputError(what + ": decodes into the buffer it reads from");
        std::vector<unsigned char>& target = model.buffers[std::size_t(view.buffer)].data;
        if (count > 0 && stride > view.byteLength / count)
            throw InputError(fmt::format("{}: {} elements of {} bytes do not fit its byteLength ({})", what, count,
                                         stride, view.byteLength));
        const std::uint64_t decoded = stride * count;
        if (view.byteOffset > target.size() || decoded > target.size() - view.byteOffset)
            throw InputError(fmt::format("{}: {} decoded bytes at offset {} run past the end of buffer {} ({} bytes)",
                                         what, decoded, view.byteOffset, view.buffer, target.size()));

        unsigned char* out = target.data() + view.byteOffset;
        const unsigned char* in = source.data() + std::size_t(source_offset);
        const std::size_t n = std::size_t(count), size = std::size_t(stride), in_size = std::size_t(source_length);
        int status = 0;
        if (mode == "ATTRIBUTES") {
            if (size == 0 || size > 256 || size % 4 != 0)
                throw InputError(fmt::format("{}: ATTRIBUTES need a byteStride that is a multiple of 4 up to 256, "
                                             "not {}",
                                             what, size));
            if (filter != "NONE" && filter != "OCTAHEDRAL" && filter != "QUATERNION" && filter != "EXPONENTIAL")
                throw InputError(fmt::format("{}: unknown filter '{}'", what, filter));
            if (filter == "OCTAHEDRAL" && size != 4 && size != 8)
                throw InputError(what + ": the OCTAHEDRAL filter needs a byteStride of 4 or 8");
            if (filter == "QUATERNION" && size != 8)
                throw InputError(what + ": the QUATERNION filter needs a byteStride of 8");
            status = meshopt_decodeVertexBuffer(out, n, size, in, in_size);
            if (status == 0 && filter == "OCTAHEDRAL") meshopt_decodeFilterOct(out, n, size);
            if (status == 0 && filter == "QUATERNION") meshopt_decodeFilterQuat(out, n, size);
            if (status == 0 && filter == "EXPONENTIAL") meshopt_decodeFilterExp(out, n, size);
        } else if (mode == "TRIANGLES" || mode == "INDICES") {
            if (size != 2 && size != 4)
                throw InputError(fmt::format("{}: {} need a byteStride of 2 or 4, not {}", what, mode, size));
            if (filter != "NONE") throw InputError(fmt::format("{}: {} take no filter ('{}')", what, mode, filter));
            if (mode == "TRIANGLES") {
                if (n % 3 != 0) throw InputError(fmt::format("{}: TRIANGLES need a count divisible by 3, not {}", what, n));
                status = meshopt_decodeIndexBuffer(out, n, size, in, in_size);
            } else {
                status = meshopt_decodeIndexSequence(out, n, size, in, in_size);
            }
        } else {
            throw InputError(fmt::format("{}: unknown mode '{}' (expected ATTRIBUTES, TRIANGLES or INDICES)", what, mode));
        }
        if (status != 0)
            throw InputError(fmt::format("{}: the compressed {} do not decode (meshoptimizer error {})", what,
                                         mode == "ATTRIBUTES" ? "attributes" : "indices", status));
    }
}

void decode_draco(tinygltf::Model& model, const std::string& name) {
    for (std::size_t m = 0; m < model.meshes.size(); ++m) {
        for (std::size_t p = 0; p < model.meshes[m].primitives.size(); ++p) {
            tinygltf::Primitive& prim = model.meshes[m].primitives[p];
            const auto found = prim.extensions.find(kDraco);
            if (found == prim.extensions.end()) continue;
            const std::string mesh_name = model.meshes[m].name.empty() ? fmt::format("{}", m)
                                                                       : fmt::format("'{}'", model.meshes[m].name);
            const std::string what = fmt::format("{}: mesh {} primitive {} ({})", name, mesh_name, p, kDraco);
            const tinygltf::Value& ext = found->second;
            if (!ext.IsObject() || !ext.Has("bufferView") || !ext.Has("attributes") || !ext.Get("attributes").IsObject())
                throw InputError(what + ": needs a bufferView and an object of attributes");
            const double view_index = whole_number(ext.Get("bufferView"));
            if (view_index < 0.0 || view_index >= double(model.bufferViews.size()))
                throw InputError(fmt::format("{}: bufferView out of range ({} bufferViews)", what,
                                             model.bufferViews.size()));
            const tinygltf::BufferView& view = model.bufferViews[std::size_t(view_index)];
            if (view.buffer < 0 || std::size_t(view.buffer) >= model.buffers.size())
                throw InputError(fmt::format("{}: bufferView {} names buffer {}, out of range", what, view_index,
                                             view.buffer));
            const std::vector<unsigned char>& bytes = model.buffers[std::size_t(view.buffer)].data;
            if (view.byteOffset > bytes.size() || view.byteLength > bytes.size() - view.byteOffset)
                throw InputError(fmt::format("{}: bufferView {} (offset {}, length {}) runs past the end of buffer {} "
                                             "({} bytes)",
                                             what, view_index, view.byteOffset, view.byteLength, view.buffer,
                                             bytes.size()));

            draco::DecoderBuffer source;
            source.Init(reinterpret_cast<const char*>(bytes.data() + view.byteOffset), view.byteLength);
            draco::Decoder decoder;
            auto decoded = [&] {
                try {
                    return decoder.DecodeMeshFromBuffer(&source);
                } catch (const std::bad_alloc&) {  // counts in the data past what memory holds
                    throw InputError(what + ": the compressed mesh does not decode (it asks for more memory than "
                                            "this machine has)");
                }
            }();
            if (!decoded.ok())
                throw InputError(fmt::format("{}: the compressed mesh does not decode ({})", what,
                                             decoded.status().error_msg_string()));
            const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
            const std::size_t points = mesh->num_points();

            // One new buffer for the primitive: its indices, then each attribute in floats.
            tinygltf::Buffer out;
            const auto add_accessor = [&](std::size_t offset, int component_type, int type, std::size_t count) {
                tinygltf::BufferView v;
                v.buffer = int(model.buffers.size());
                v.byteOffset = offset;
                v.byteLength = out.data.size() - offset;
                model.bufferViews.push_back(v);
                tinygltf::Accessor a;
                a.bufferView = int(model.bufferViews.size()) - 1;
                a.componentType = component_type;
                a.type = type;
                a.count = count;
                model.accessors.push_back(a);
                return int(model.accessors.size()) - 1;
            };
            const auto put = [&](const void* value, std::size_t size) {
                const auto* b = static_cast<const unsigned char*>(value);
                out.data.insert(out.data.end(), b, b + size);
            };
            for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f)
                for (int c = 0; c < 3; ++c) {
                    const std::uint32_t index = mesh->face(f)[c].value();
                    put(&index, sizeof index);
                }
            const int indices = add_accessor(0, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR,
                                              std::size_t(mesh->num_faces()) * 3);
            std::map<std::string, int> attributes;
            for (const std::string& key : ext.Get("attributes").Keys()) {
                const double id = whole_number(ext.Get("attributes").Get(key));
                const draco::PointAttribute* attribute =
                    id < 0.0 || id > 4294967295.0 ? nullptr : mesh->GetAttributeByUniqueId(std::uint32_t(id));
                if (attribute == nullptr)
                    throw InputError(fmt::format("{}: attribute {} names an id the compressed mesh lacks", what, key));
                const int n = attribute->num_components();
                if (n < 1 || n > 4)
                    throw InputError(fmt::format("{}: attribute {} has {} components", what, key, n));
                // glTF normalizes an integer attribute the file marks so; Draco does when its own
                // data says so: where only the file does, as the file means it.
                double scale = 1.0;
                const auto file_accessor = prim.attributes.find(key);
                const bool file_normalized = file_accessor != prim.attributes.end() && file_accessor->second >= 0 &&
                                             std::size_t(file_accessor->second) < model.accessors.size() &&
                                             model.accessors[std::size_t(file_accessor->second)].normalized;
                if (file_normalized && !attribute->normalized()) {
                    switch (attribute->data_type()) {
                        case draco::DT_UINT8: scale = 1.0 / 255.0; break;
                        case draco::DT_UINT16: scale = 1.0 / 65535.0; break;
                        case draco::DT_INT8: scale = 1.0 / 127.0; break;
                        case draco::DT_INT16: scale = 1.0 / 32767.0; break;
                        default: break;
                    }
                }
                const std::size_t offset = out.data.size();
                float value[4] = {};
                for (draco::PointIndex i(0); i < std::uint32_t(points); ++i) {
                    if (!attribute->ConvertValue<float>(attribute->mapped_index(i), std::int8_t(n), value))
                        throw InputError(fmt::format("{}: attribute {} does not convert to floats", what, key));
                    for (int c = 0; c < n; ++c) value[c] = float(double(value[c]) * scale);
                    put(value, sizeof(float) * std::size_t(n));
                }
                const int types[4] = {TINYGLTF_TYPE_SCALAR, TINYGLTF_TYPE_VEC2, TINYGLTF_TYPE_VEC3, TINYGLTF_TYPE_VEC4};
                attributes[key] = add_accessor(offset, TINYGLTF_COMPONENT_TYPE_FLOAT, types[n - 1], points);
            }
            model.buffers.push_back(std::move(out));
            prim.indices = indices;
            prim.mode = TINYGLTF_MODE_TRIANGLES;  // what Draco decodes, from a list or a strip
            for (const auto& [key, accessor] : attributes) prim.attributes[key] = accessor;
        }
    }
}

}  // namespace hemirad::scene
