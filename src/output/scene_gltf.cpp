// The user's scene back, with the light baked in (see write_scene_gltf in output.h).
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <set>
#include <unordered_map>

#include "core/error.h"
#include "output/gltf_write.h"
#include "output/output.h"
#include "output/welded_mesh.h"
#include "scene/gltf_source.h"
#include "scene/gltf_views.h"

namespace hemirad::output {
namespace {

namespace fs = std::filesystem;
using glm::dvec3;

// Extensions of the file that the output no longer uses: its geometry is written decoded, as floats.
const std::set<std::string> kDecoded = {"EXT_meshopt_compression", "KHR_draco_mesh_compression",
                                        "KHR_mesh_quantization"};

// Bytes an accessor without a bufferView may make (all zeros but its sparse values): 1 GiB.
constexpr std::size_t kMaxLooseBytes = std::size_t{1} << 30;

int component_size(int type) {
    switch (type) {
        case TINYGLTF_COMPONENT_TYPE_BYTE:
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
        case TINYGLTF_COMPONENT_TYPE_SHORT:
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
        case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
        default: return 0;
    }
}

int components(int type) {
    switch (type) {
        case TINYGLTF_TYPE_SCALAR: return 1;
        case TINYGLTF_TYPE_VEC2: return 2;
        case TINYGLTF_TYPE_VEC3: return 3;
        case TINYGLTF_TYPE_VEC4: return 4;
        case TINYGLTF_TYPE_MAT2: return 4;
        case TINYGLTF_TYPE_MAT3: return 9;
        case TINYGLTF_TYPE_MAT4: return 16;
        default: return 0;
    }
}

// An accessor's elements, tightly packed, sparse substitution applied; false (with why) for
// one whose numbers do not fit its buffers, which the loader did not need to check. Every span is
// checked against its bufferView and buffer before anything is allocated for it.
bool read_raw(const tinygltf::Model& m, int index, std::vector<unsigned char>& out, std::string& why) {
    if (index < 0 || std::size_t(index) >= m.accessors.size()) {
        why = fmt::format("accessor {} does not exist", index);
        return false;
    }
    const tinygltf::Accessor& a = m.accessors[std::size_t(index)];
    const std::size_t size = std::size_t(component_size(a.componentType)) * std::size_t(components(a.type));
    if (size == 0 || ((a.type == TINYGLTF_TYPE_MAT2 || a.type == TINYGLTF_TYPE_MAT3) && component_size(a.componentType) < 4)) {
        why = fmt::format("accessor {} has a layout hemirad does not copy", index);
        return false;
    }
    // glTF asks for at least one element; an empty one (a web export's empty primitive, whose
    // offset then ran past its empty bufferView) is said as what it is.
    if (a.count == 0) {
        why = fmt::format("accessor {} has no elements (count 0, which glTF does not allow)", index);
        return false;
    }
    // The first byte of `count` elements of `element` bytes, `stride` apart (0: packed), from
    // `offset` into a bufferView; null where the view, its buffer or the span does not exist.
    const auto span = [&](int view_index, std::size_t offset, std::size_t stride, std::size_t count,
                          std::size_t element) -> const unsigned char* {
        if (view_index < 0 || std::size_t(view_index) >= m.bufferViews.size()) return nullptr;
        const tinygltf::BufferView& v = m.bufferViews[std::size_t(view_index)];
        if (v.buffer < 0 || std::size_t(v.buffer) >= m.buffers.size()) return nullptr;
        const std::vector<unsigned char>& data = m.buffers[std::size_t(v.buffer)].data;
        if (v.byteOffset > data.size() || v.byteLength > data.size() - v.byteOffset || offset > v.byteLength)
            return nullptr;
        if (stride == 0) stride = element;
        if (count > 0 && (element > v.byteLength - offset || (count - 1) > (v.byteLength - offset - element) / stride))
            return nullptr;
        return data.data() + v.byteOffset + offset;
    };
    const auto copy = [](const unsigned char* from, std::size_t stride, std::size_t count, std::size_t element,
                         unsigned char* to) {
        if (stride == 0) stride = element;
        for (std::size_t i = 0; i < count; ++i) std::memcpy(to + i * element, from + i * stride, element);
    };
    const unsigned char* data = nullptr;
    const std::size_t stride =
        a.bufferView >= 0 && std::size_t(a.bufferView) < m.bufferViews.size() ? m.bufferViews[std::size_t(a.bufferView)].byteStride : 0;
    if (a.bufferView >= 0) {
        if (!(data = span(a.bufferView, a.byteOffset, stride, a.count, size))) {
            why = fmt::format("accessor {} runs past its bufferView", index);
            return false;
        }
    } else if (a.count > kMaxLooseBytes / size) {
        why = fmt::format("accessor {} has no bufferView and {} elements, too many to copy", index, a.count);
        return false;
    }
    out.assign(a.count * size, 0);
    if (data) copy(data, stride, a.count, size, out.data());
    if (a.sparse.isSparse && a.sparse.count > 0) {
        const std::size_t n = std::size_t(a.sparse.count);
        const int index_size = component_size(a.sparse.indices.componentType);
        const unsigned char* indices =
            index_size == 0 || (index_size == 4 && a.sparse.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
                ? nullptr
                : span(a.sparse.indices.bufferView, a.sparse.indices.byteOffset, 0, n, std::size_t(index_size));
        const unsigned char* values = span(a.sparse.values.bufferView, a.sparse.values.byteOffset, 0, n, size);
        if (!indices || !values) {
            why = fmt::format("accessor {}'s sparse data runs past its bufferViews", index);
            return false;
        }
        for (std::size_t i = 0; i < n; ++i) {
            std::uint32_t at = 0;
            if (index_size == 1) at = indices[i];
            if (index_size == 2) at = std::uint32_t(indices[2 * i]) | std::uint32_t(indices[2 * i + 1]) << 8;
            if (index_size == 4) std::memcpy(&at, &indices[4 * i], 4);
            if (at >= a.count) {
                why = fmt::format("accessor {}'s sparse index {} is out of range", index, at);
                return false;
            }
            std::memcpy(out.data() + std::size_t(at) * size, values + i * size, size);
        }
    }
    return true;
}

// An accessor's values as doubles, normalized integers mapped to [0, 1] or [−1, 1] as glTF
// defines (others as they are), `comps` per element.
bool read_doubles(const tinygltf::Model& m, int index, std::vector<double>& out, int& comps, std::string& why) {
    std::vector<unsigned char> raw;
    if (!read_raw(m, index, raw, why)) return false;
    const tinygltf::Accessor& a = m.accessors[std::size_t(index)];
    comps = components(a.type);
    const std::size_t n = a.count * std::size_t(comps);
    out.resize(n);
    const bool norm = a.normalized;
    for (std::size_t i = 0; i < n; ++i) {
        double v = 0.0;
        switch (a.componentType) {
            case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, &raw[4 * i], 4); v = f; break; }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { std::uint32_t u; std::memcpy(&u, &raw[4 * i], 4); v = u; break; }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { std::uint16_t u; std::memcpy(&u, &raw[2 * i], 2); v = norm ? u / 65535.0 : u; break; }
            case TINYGLTF_COMPONENT_TYPE_SHORT: { std::int16_t s; std::memcpy(&s, &raw[2 * i], 2); v = norm ? std::max(s / 32767.0, -1.0) : s; break; }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: v = norm ? raw[i] / 255.0 : raw[i]; break;
            case TINYGLTF_COMPONENT_TYPE_BYTE: { const auto s = static_cast<std::int8_t>(raw[i]); v = norm ? std::max(s / 127.0, -1.0) : s; break; }
            default: break;
        }
        if (!std::isfinite(v)) {
            why = fmt::format("accessor {} holds a value that is not finite", index);
            return false;
        }
        out[i] = v;
    }
    return true;
}

// The output model, built up: buffer 0 holds every byte it names.
class Writer {
public:
    Writer(const scene::Scene& scene, const mesh::Mesh& mesh, const WeldedMesh& light, const VertexValues& incident,
           double exposure, const fs::path& final_dir)
        : scene_(scene), src_(scene.source->model), mesh_(mesh), light_(light), incident_(incident),
          exposure_(exposure), final_dir_(final_dir) {}

    tinygltf::Model build() {
        out_.asset = src_.asset;
        out_.asset.generator = src_.asset.generator.empty() ? "hemirad" : "hemirad, from " + src_.asset.generator;
        tinygltf::Value::Object about;
        about["exposure"] = tinygltf::Value(exposure_);
        about["COLOR_0"] = tinygltf::Value(std::string(
            "display-range baked light for viewers: tone(exposure x irradiance) x the file's COLOR_0 under unlit materials "
            "(tone(exposure x radiosity) on emitters)"));
        about["_RADIOSITY"] = tinygltf::Value(std::string("linear radiosity (exitance), in emissiveFactor's units"));
        about["_IRRADIANCE"] = tinygltf::Value(std::string("linear irradiance (incident light), in the same units"));
        tinygltf::Value::Object extras = src_.asset.extras.IsObject() ? src_.asset.extras.Get<tinygltf::Value::Object>()
                                                                      : tinygltf::Value::Object{};
        extras["hemirad"] = tinygltf::Value(about);
        out_.asset.extras = tinygltf::Value(extras);
        out_.buffers.emplace_back();
        out_.scenes = src_.scenes;
        out_.defaultScene = src_.defaultScene;
        out_.cameras = src_.cameras;
        out_.lights = src_.lights;
        out_.samplers = src_.samplers;
        out_.textures = src_.textures;
        out_.materials = src_.materials;
        out_.extensions = src_.extensions;
        out_.extensions.erase("KHR_lights_punctual");  // written from out_.lights
        out_.extras = src_.extras;
        for (const std::string& e : src_.extensionsUsed)
            if (kDecoded.count(e) == 0) out_.extensionsUsed.push_back(e);
        for (const std::string& e : src_.extensionsRequired)
            if (kDecoded.count(e) == 0) out_.extensionsRequired.push_back(e);
        copy_images();

        // The baked mesh nodes, by glTF node.
        std::map<int, std::uint32_t> baked;
        for (std::uint32_t n = 0; n < scene_.nodes.size(); ++n)
            if (!scene_.nodes[n].synthetic && scene_.nodes[n].gltf_node >= 0) baked.emplace(scene_.nodes[n].gltf_node, n);
        out_.nodes = src_.nodes;
        for (std::size_t i = 0; i < out_.nodes.size(); ++i) {
            tinygltf::Node& node = out_.nodes[i];
            if (node.mesh < 0 || std::size_t(node.mesh) >= src_.meshes.size()) {
                node.mesh = -1;
                continue;
            }
            const auto b = baked.find(int(i));
            node.mesh = b == baked.end() ? copied_mesh(node.mesh) : baked_mesh(b->second, node.mesh);
        }
        out_.skins = src_.skins;
        for (tinygltf::Skin& skin : out_.skins)
            if (skin.inverseBindMatrices >= 0) skin.inverseBindMatrices = copied_accessor(skin.inverseBindMatrices);
        for (const tinygltf::Animation& a : src_.animations) {
            tinygltf::Animation copy = a;
            bool whole = true;
            for (tinygltf::AnimationSampler& s : copy.samplers) {
                s.input = copied_accessor(s.input);
                s.output = copied_accessor(s.output);
                whole = whole && s.input >= 0 && s.output >= 0;
            }
            if (whole) out_.animations.push_back(copy);
            else warn(fmt::format("animation '{}' left out: its data could not be read", a.name));
        }
        if (unlit_used_ && std::find(out_.extensionsUsed.begin(), out_.extensionsUsed.end(), "KHR_materials_unlit") ==
                               out_.extensionsUsed.end())
            out_.extensionsUsed.push_back("KHR_materials_unlit");
        if (out_.buffers[0].data.empty()) out_.buffers.clear();
        return std::move(out_);
    }

    std::vector<std::string> warnings() const { return warnings_; }

private:
    void warn(const std::string& line) {
        if (std::find(warnings_.begin(), warnings_.end(), line) == warnings_.end()) warnings_.push_back(line);
    }

    // Images: one the file names by a uri, referred to where it is; an embedded one (a data uri or
    // a bufferView) copied into the buffer.
    void copy_images() {
        const scene::GltfSource& source = *scene_.source;
        for (std::size_t i = 0; i < src_.images.size(); ++i) {
            tinygltf::Image image;
            const tinygltf::Image& in = src_.images[i];
            image.name = in.name;
            image.mimeType = in.mimeType;
            image.extras = in.extras;
            image.extensions = in.extensions;
            if (in.bufferView >= 0) {
                std::vector<unsigned char> bytes;
                const tinygltf::BufferView* v =
                    std::size_t(in.bufferView) < src_.bufferViews.size() ? &src_.bufferViews[std::size_t(in.bufferView)] : nullptr;
                const std::vector<unsigned char>* data =
                    v && v->buffer >= 0 && std::size_t(v->buffer) < src_.buffers.size() ? &src_.buffers[std::size_t(v->buffer)].data : nullptr;
                if (data && v->byteOffset <= data->size() && v->byteLength <= data->size() - v->byteOffset) {
                    image.bufferView = scene::append_view(out_, data->data() + v->byteOffset, v->byteLength, 0);
                } else {
                    warn(fmt::format("image {} left empty: its bufferView runs past its buffer", i));
                }
            } else if (const auto e = source.embedded_images.find(int(i)); e != source.embedded_images.end()) {
                image.bufferView = scene::append_view(out_, e->second.data(), e->second.size(), 0);
                if (image.mimeType.empty()) image.mimeType = "image/png";
            } else if (!in.uri.empty()) {
                image.uri = relative_uri(in.uri);
            }
            out_.images.push_back(image);
        }
    }

    // The uri of a file the input names, from the directory baked.gltf goes to: a relative
    // path where one exists, percent-encoded segment by segment.
    std::string relative_uri(const std::string& uri) const {
        const std::string decoded = scene::percent_decoded(uri);
        std::error_code ec;
        const fs::path base = scene_.source->base_dir.empty() ? fs::path(".") : fs::path(scene_.source->base_dir);
        fs::path target = fs::weakly_canonical(fs::absolute(base / decoded, ec), ec);
        if (ec || target.empty()) target = fs::absolute(base / decoded, ec).lexically_normal();
        const fs::path from = fs::weakly_canonical(fs::absolute(final_dir_, ec), ec);
        fs::path relative = from.empty() ? fs::path() : target.lexically_relative(from);
        if (relative.empty()) relative = target;
        std::string out = relative.is_absolute() ? "/" : "";
        bool first = true;
        for (const fs::path& part : relative.relative_path()) {
            if (!first) out += "/";
            out += percent_encode(part.string());
            first = false;
        }
        return out;
    }

    int copied_accessor(int index) {
        if (index < 0) return -1;
        if (const auto done = copied_accessors_.find(index); done != copied_accessors_.end()) return done->second;
        std::vector<unsigned char> raw;
        std::string why;
        int result = -1;
        if (read_raw(src_, index, raw, why)) {
            tinygltf::Accessor a = src_.accessors[std::size_t(index)];
            a.sparse = decltype(a.sparse)();
            a.byteOffset = 0;
            a.bufferView = a.count > 0 ? scene::append_view(out_, raw.data(), raw.size(), 0) : -1;
            out_.accessors.push_back(a);
            result = int(out_.accessors.size() - 1);
        } else {
            warn(why);
        }
        copied_accessors_[index] = result;
        return result;
    }

    // A primitive as the file has it, its data copied; false when some of it cannot be read.
    bool copy_primitive(const tinygltf::Primitive& in, tinygltf::Primitive& out) {
        out = in;
        out.extensions.erase("KHR_draco_mesh_compression");
        for (auto& [name, accessor] : out.attributes)
            if ((accessor = copied_accessor(accessor)) < 0) return false;
        if (in.indices >= 0 && (out.indices = copied_accessor(in.indices)) < 0) return false;
        for (auto& target : out.targets)
            for (auto& [name, accessor] : target)
                if ((accessor = copied_accessor(accessor)) < 0) return false;
        return true;
    }

    int copied_mesh(int index) {
        if (const auto done = copied_meshes_.find(index); done != copied_meshes_.end()) return done->second;
        const tinygltf::Mesh& in = src_.meshes[std::size_t(index)];
        tinygltf::Mesh mesh = in;
        mesh.primitives.clear();
        for (std::size_t p = 0; p < in.primitives.size(); ++p) {
            tinygltf::Primitive copy;
            if (copy_primitive(in.primitives[p], copy)) mesh.primitives.push_back(copy);
            else warn(fmt::format("mesh '{}' primitive {} left out: its data could not be read", in.name, p));
        }
        return copied_meshes_[index] = add_mesh(mesh);
    }

    // The unlit copy of material m (-1: the default material) that baked primitives use: for an
    // emitter, white without textures (COLOR_0 holds its whole light).
    int unlit_material(int m, bool emitter) {
        const auto key = std::make_pair(m, emitter);
        if (const auto done = unlit_.find(key); done != unlit_.end()) return done->second;
        tinygltf::Material mat = m >= 0 ? src_.materials[std::size_t(m)] : tinygltf::Material();
        if (m < 0) mat.name = "default";
        tinygltf::PbrMetallicRoughness& pbr = mat.pbrMetallicRoughness;
        if (emitter) {
            const double alpha = pbr.baseColorFactor.size() == 4 ? pbr.baseColorFactor[3] : 1.0;
            pbr.baseColorFactor = {1.0, 1.0, 1.0, alpha};
            pbr.baseColorTexture = tinygltf::TextureInfo();
        }
        // KHR_materials_unlit's fallback for readers without it: not metallic, fully rough.
        pbr.metallicFactor = 0.0;
        pbr.roughnessFactor = 1.0;
        pbr.metallicRoughnessTexture = tinygltf::TextureInfo();
        mat.normalTexture = tinygltf::NormalTextureInfo();
        mat.occlusionTexture = tinygltf::OcclusionTextureInfo();
        mat.emissiveTexture = tinygltf::TextureInfo();
        mat.emissiveFactor = {0.0, 0.0, 0.0};
        mat.doubleSided = false;  // each side of a doubleSided surface is its own primitive
        mat.extensions.clear();
        mat.extensions["KHR_materials_unlit"] = tinygltf::Value(tinygltf::Value::Object{});
        out_.materials.push_back(mat);
        unlit_used_ = true;
        return unlit_[key] = int(out_.materials.size() - 1);
    }

    // One scene node's mesh: each primitive the bake meshed becomes the welded element mesh of
    // its triangles, with the file's attributes interpolated; the rest are copied.
    int baked_mesh(std::uint32_t node, int mesh_index) {
        const tinygltf::Mesh& in = src_.meshes[std::size_t(mesh_index)];
        const WeldedNode& w = light_.nodes[node];
        const std::vector<glm::dvec3>& h = incident_[node];
        const scene::GltfSource& source = *scene_.source;
        // The welded triangles of each of the file's primitives (by index in the mesh).
        std::map<int, std::vector<std::size_t>> of_primitive;
        for (std::size_t t = 0; t < w.triangle_count(); ++t) {
            const mesh::Element& e = mesh_.elements[w.element[t]];
            const std::uint32_t tri = e.source[0];
            if (tri >= scene_.triangles.size()) continue;
            const std::uint32_t p = scene_.triangles[tri].primitive;
            if (p >= source.primitives.size() || source.primitives[p].mesh != mesh_index) continue;
            of_primitive[source.primitives[p].index].push_back(t);
        }
        tinygltf::Mesh mesh;
        mesh.name = in.name;
        mesh.extras = in.extras;
        mesh.weights = in.weights;
        for (std::size_t p = 0; p < in.primitives.size(); ++p) {
            const auto baked = of_primitive.find(int(p));
            tinygltf::Primitive prim;
            if (baked == of_primitive.end()) {
                if (copy_primitive(in.primitives[p], prim)) mesh.primitives.push_back(prim);
                else warn(fmt::format("mesh '{}' primitive {} left out: its data could not be read", in.name, p));
                continue;
            }
            for (const bool back : {false, true})
                if (bake_primitive(node, in.primitives[p], baked->second, w, h, back, prim)) mesh.primitives.push_back(prim);
        }
        return add_mesh(mesh);
    }

    // A mesh of the output, or −1 (its node holds none) where no primitive is left: glTF
    // requires at least one.
    int add_mesh(const tinygltf::Mesh& mesh) {
        if (mesh.primitives.empty()) return -1;
        out_.meshes.push_back(mesh);
        return int(out_.meshes.size() - 1);
    }

    // The welded triangles `triangles` of one side of a primitive, as a primitive in the node's
    // local space; false when that side has none.
    bool bake_primitive(std::uint32_t node, const tinygltf::Primitive& in, const std::vector<std::size_t>& triangles,
                        const WeldedNode& w, const std::vector<glm::dvec3>& h, bool back, tinygltf::Primitive& out) {
        std::vector<std::size_t> side;
        for (const std::size_t t : triangles)
            if (mesh_.elements[w.element[t]].back == back) side.push_back(t);
        if (side.empty()) return false;
        const scene::MeshNode& mesh_node = scene_.nodes[node];
        const glm::dmat4 to_local = glm::inverse(mesh_node.world);
        const bool mirrored = glm::determinant(glm::dmat3(mesh_node.world)) < 0.0;

        // The file's attributes, read once per primitive (the loader read POSITION already).
        struct Attribute {
            std::string name;
            std::vector<double> values;
            int comps = 0;
        };
        std::vector<Attribute> attributes;
        for (const auto& [name, accessor] : in.attributes) {
            if (name == "POSITION") continue;
            Attribute a{name, {}, 0};
            std::string why;
            if (!read_doubles(src_, accessor, a.values, a.comps, why)) {
                warn(fmt::format("{} of a primitive of node '{}' left out: {}", name, mesh_node.name, why));
                continue;
            }
            attributes.push_back(std::move(a));
        }
        if (!in.targets.empty())
            warn(fmt::format("node '{}': morph targets of baked primitives are left out", mesh_node.name));
        const int material = in.material >= 0 && std::size_t(in.material) < src_.materials.size() ? in.material : -1;
        const std::uint32_t scene_material = mesh_.elements[w.element[side[0]]].material;
        const scene::Material& mat = scene_.materials[scene_material];
        const bool emitter = mat.emission != dvec3(0.0);

        std::vector<glm::vec3> positions;
        std::vector<std::vector<float>> values(attributes.size());
        std::vector<glm::vec3> colour, radiosity, irradiance;
        std::vector<std::uint32_t> indices;
        std::unordered_map<std::string, std::uint32_t> vertex_of;
        std::string key;
        std::vector<float> corner_values;
        for (const std::size_t t : side) {
            const mesh::Element& e = mesh_.elements[w.element[t]];
            std::uint32_t corner[3];
            for (int c = 0; c < 3; ++c) {
                const std::uint32_t v = w.indices[3 * t + std::size_t(c)];
                const dvec3 world = w.positions[v];
                // The file triangle the vertex lies in (a quad element has two), and its barycentrics.
                std::uint32_t tri = e.source[0];
                glm::dvec3 bary = barycentric(tri, world);
                if (e.source[1] < scene_.triangles.size()) {
                    const glm::dvec3 other = barycentric(e.source[1], world);
                    if (std::min({other.x, other.y, other.z}) > std::min({bary.x, bary.y, bary.z})) {
                        tri = e.source[1];
                        bary = other;
                    }
                }
                bary = glm::max(bary, dvec3(0.0));
                bary /= std::max(bary.x + bary.y + bary.z, 1e-300);
                const scene::Triangle& st = scene_.triangles[tri];
                const int dominant = bary.x >= bary.y && bary.x >= bary.z ? 0 : bary.y >= bary.z ? 1 : 2;
                corner_values.clear();
                dvec3 vertex_colour(1.0);
                for (const Attribute& a : attributes) {
                    std::array<double, 16> mixed{};
                    const bool nearest = a.name.rfind("JOINTS_", 0) == 0;
                    for (int k = 0; k < a.comps; ++k) {
                        for (int i = 0; i < 3; ++i) {
                            const std::size_t at = std::size_t(st.corner[std::size_t(i)]) * std::size_t(a.comps) + std::size_t(k);
                            const double value = at < a.values.size() ? a.values[at] : 0.0;
                            if (nearest) {
                                if (i == dominant) mixed[std::size_t(k)] = value;
                            } else {
                                mixed[std::size_t(k)] += bary[i] * value;
                            }
                        }
                    }
                    if (a.name == "NORMAL" || a.name == "TANGENT") {
                        glm::dvec3 n(mixed[0], mixed[1], mixed[2]);
                        const double length = glm::length(n);
                        n = length > 0.0 ? n / length : n;
                        if (back) n = -n;  // the other face's side
                        mixed[0] = n.x, mixed[1] = n.y, mixed[2] = n.z;
                        if (a.name == "TANGENT" && a.comps == 4) {
                            const std::size_t at = std::size_t(st.corner[std::size_t(dominant)]) * 4 + 3;
                            mixed[3] = at < a.values.size() && a.values[at] < 0.0 ? -1.0 : 1.0;
                        }
                    }
                    if (a.name == "COLOR_0") {
                        vertex_colour = dvec3(mixed[0], mixed[1], mixed[2]);
                        continue;  // the baked light takes its place, times it
                    }
                    for (int k = 0; k < a.comps; ++k) corner_values.push_back(static_cast<float>(mixed[std::size_t(k)]));
                }
                const dvec3 light = emitter ? w.radiosity[v] : h[v];
                const glm::vec3 shown(vertex_colour * dvec3(tone(exposure_ * light.x), tone(exposure_ * light.y),
                                                            tone(exposure_ * light.z)));
                key.assign(reinterpret_cast<const char*>(&v), sizeof v);
                key.append(reinterpret_cast<const char*>(corner_values.data()), corner_values.size() * sizeof(float));
                key.append(reinterpret_cast<const char*>(&shown), sizeof shown);
                const auto [found, inserted] = vertex_of.emplace(key, static_cast<std::uint32_t>(positions.size()));
                if (inserted) {
                    positions.push_back(glm::vec3(dvec3(to_local * glm::dvec4(world, 1.0))));
                    std::size_t at = 0;
                    for (std::size_t a = 0, slot = 0; a < attributes.size(); ++a) {
                        if (attributes[a].name == "COLOR_0") continue;
                        for (int k = 0; k < attributes[a].comps; ++k) values[slot].push_back(corner_values[at++]);
                        ++slot;
                    }
                    colour.push_back(shown);
                    radiosity.push_back(glm::vec3(w.radiosity[v]));
                    irradiance.push_back(glm::vec3(h[v]));
                }
                corner[c] = found->second;
            }
            // Front counter-clockwise in world space; a mirroring node turns that over, which
            // readers undo (glTF: a negative determinant means clockwise fronts).
            indices.insert(indices.end(), {corner[0], mirrored ? corner[2] : corner[1], mirrored ? corner[1] : corner[2]});
        }

        out = tinygltf::Primitive();
        out.mode = TINYGLTF_MODE_TRIANGLES;
        out.material = unlit_material(material, emitter);
        out.extras = in.extras;
        out.attributes["POSITION"] = add_floats(reinterpret_cast<const float*>(positions.data()), positions.size(), 3, true);
        for (std::size_t a = 0, slot = 0; a < attributes.size(); ++a) {
            if (attributes[a].name == "COLOR_0") continue;
            const Attribute& at = attributes[a];
            if (at.name.rfind("JOINTS_", 0) == 0) {
                std::vector<std::uint16_t> joints(values[slot].size());
                for (std::size_t i = 0; i < joints.size(); ++i)
                    joints[i] = static_cast<std::uint16_t>(std::clamp(values[slot][i], 0.0f, 65535.0f));
                out.attributes[at.name] = add_accessor(joints.data(), joints.size() * 2, positions.size(), at.comps,
                                                       TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT);
            } else {
                out.attributes[at.name] = add_floats(values[slot].data(), positions.size(), at.comps, false);
            }
            ++slot;
        }
        out.attributes["COLOR_0"] = add_floats(reinterpret_cast<const float*>(colour.data()), colour.size(), 3, false);
        out.attributes["_RADIOSITY"] = add_floats(reinterpret_cast<const float*>(radiosity.data()), radiosity.size(), 3, false);
        out.attributes["_IRRADIANCE"] = add_floats(reinterpret_cast<const float*>(irradiance.data()), irradiance.size(), 3, false);
        out.indices = add_accessor(indices.data(), indices.size() * 4, indices.size(), 1, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                                   TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
        return true;
    }

    // Barycentric coordinates of p in scene triangle `tri`, in the plane of the triangle.
    glm::dvec3 barycentric(std::uint32_t tri, const dvec3& p) const {
        const scene::Triangle& t = scene_.triangles[tri];
        const dvec3 e1 = t.p[1] - t.p[0], e2 = t.p[2] - t.p[0], d = p - t.p[0];
        const double a = glm::dot(e1, e1), b = glm::dot(e1, e2), c = glm::dot(e2, e2);
        const double p1 = glm::dot(d, e1), p2 = glm::dot(d, e2);
        const double det = a * c - b * b;
        if (!(std::abs(det) > 0.0)) return dvec3(1.0, 0.0, 0.0);
        const double v = (c * p1 - b * p2) / det, w = (a * p2 - b * p1) / det;
        return dvec3(1.0 - v - w, v, w);
    }

    int add_accessor(const void* data, std::size_t bytes, std::size_t count, int comps, int component_type,
                     int target = TINYGLTF_TARGET_ARRAY_BUFFER) {
        tinygltf::Accessor a;
        a.bufferView = scene::append_view(out_, data, bytes, target);
        a.componentType = component_type;
        a.type = comps == 1 ? TINYGLTF_TYPE_SCALAR : comps == 2 ? TINYGLTF_TYPE_VEC2 : comps == 3 ? TINYGLTF_TYPE_VEC3
                                                                                                  : TINYGLTF_TYPE_VEC4;
        a.count = count;
        out_.accessors.push_back(a);
        return int(out_.accessors.size() - 1);
    }

    int add_floats(const float* data, std::size_t count, int comps, bool bounds) {
        const int index = add_accessor(data, count * std::size_t(comps) * sizeof(float), count, comps,
                                       TINYGLTF_COMPONENT_TYPE_FLOAT);
        if (bounds && count > 0) {
            tinygltf::Accessor& a = out_.accessors.back();
            a.minValues.assign(std::size_t(comps), HUGE_VAL);
            a.maxValues.assign(std::size_t(comps), -HUGE_VAL);
            for (std::size_t i = 0; i < count; ++i)
                for (int k = 0; k < comps; ++k) {
                    a.minValues[std::size_t(k)] = std::min<double>(a.minValues[std::size_t(k)], data[i * std::size_t(comps) + std::size_t(k)]);
                    a.maxValues[std::size_t(k)] = std::max<double>(a.maxValues[std::size_t(k)], data[i * std::size_t(comps) + std::size_t(k)]);
                }
        }
        return index;
    }

    const scene::Scene& scene_;
    const tinygltf::Model& src_;
    const mesh::Mesh& mesh_;
    const WeldedMesh& light_;
    const VertexValues& incident_;
    double exposure_;
    fs::path final_dir_;
    tinygltf::Model out_;
    std::map<int, int> copied_accessors_, copied_meshes_;
    std::map<std::pair<int, bool>, int> unlit_;
    bool unlit_used_ = false;
    std::vector<std::string> warnings_;
};

}  // namespace

std::vector<std::string> write_scene_gltf(const fs::path& file, const fs::path& final_dir, const scene::Scene& scene,
                                          const mesh::Mesh& mesh, const std::vector<glm::dvec3>& radiosity,
                                          const std::vector<glm::dvec3>& irradiance, double exposure,
                                          const VertexLight* gathered) {
    const WeldedMesh light = weld(scene.nodes.size(), mesh, radiosity, gathered ? &gathered->radiosity : nullptr);
    return write_scene_gltf(file, final_dir, scene, mesh, light,
                            gathered ? gathered->irradiance : vertex_values(light, mesh, irradiance), exposure);
}

std::vector<std::string> write_scene_gltf(const fs::path& file, const fs::path& final_dir, const scene::Scene& scene,
                                          const mesh::Mesh& mesh, const WeldedMesh& light, const VertexValues& incident,
                                          double exposure) {
    if (!scene.source) throw InternalError("write_scene_gltf: the scene has no source file");
    if (incident.size() != light.nodes.size()) throw InternalError("write_scene_gltf: irradiance for other nodes");
    Writer writer(scene, mesh, light, incident, exposure, final_dir);
    tinygltf::Model model = writer.build();
    const std::string bin_name = file.stem().string() + ".bin";
    if (!model.buffers.empty()) model.buffers[0].uri = percent_encode(bin_name);
    write_model(model, file, bin_name);
    return writer.warnings();
}

}  // namespace hemirad::output
