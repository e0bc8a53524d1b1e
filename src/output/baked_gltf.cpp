// The baked glTF: the welded element mesh with per-vertex radiosity (COLOR_0) under unlit materials.
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <system_error>

#include "core/error.h"
#include "output/output.h"
#include "output/gltf_write.h"
#include "output/welded_mesh.h"
#include "scene/gltf_views.h"

namespace hemirad::output {
namespace fs = std::filesystem;

namespace {

// A float VEC3 accessor over `values`; POSITION must carry min/max (glTF 2.0 §5.1.1).
int add_vec3(tinygltf::Model& model, const std::vector<glm::dvec3>& values, bool unit_length, bool with_bounds) {
    std::vector<glm::vec3> floats(values.size());
    for (std::size_t i = 0; i < values.size(); ++i) {
        floats[i] = glm::vec3(values[i]);
        if (unit_length) floats[i] = glm::normalize(floats[i]);  // unit in float, as readers check
    }
    tinygltf::Accessor accessor;
    accessor.bufferView =
        scene::append_view(model, floats.data(), floats.size() * sizeof(glm::vec3), TINYGLTF_TARGET_ARRAY_BUFFER);
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    accessor.type = TINYGLTF_TYPE_VEC3;
    accessor.count = floats.size();
    if (with_bounds) {
        glm::vec3 lo = floats[0], hi = floats[0];
        for (const glm::vec3& f : floats) {
            lo = glm::min(lo, f);
            hi = glm::max(hi, f);
        }
        accessor.minValues = {lo.x, lo.y, lo.z};
        accessor.maxValues = {hi.x, hi.y, hi.z};
    }
    model.accessors.push_back(accessor);
    return static_cast<int>(model.accessors.size() - 1);
}

int add_indices(tinygltf::Model& model, const std::vector<std::uint32_t>& indices) {
    tinygltf::Accessor accessor;
    accessor.bufferView =
        scene::append_view(model, indices.data(), indices.size() * sizeof(std::uint32_t), TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    accessor.type = TINYGLTF_TYPE_SCALAR;
    accessor.count = indices.size();
    model.accessors.push_back(accessor);
    return static_cast<int>(model.accessors.size() - 1);
}

// Unlit, so viewers show COLOR_0 (the baked light) as is. Readers without the extension fall
// back to PBR; the extension's recommended fallback (non-metallic, rough) keeps them sensible.
int add_unlit_material(tinygltf::Model& model) {
    tinygltf::Material material;
    material.name = "baked";
    material.pbrMetallicRoughness.baseColorFactor = {1.0, 1.0, 1.0, 1.0};
    material.pbrMetallicRoughness.metallicFactor = 0.0;
    material.pbrMetallicRoughness.roughnessFactor = 0.9;
    material.doubleSided = false;  // back faces of doubleSided surfaces are their own triangles
    material.extensions["KHR_materials_unlit"] = tinygltf::Value(tinygltf::Value::Object{});
    model.materials.push_back(material);
    model.extensionsUsed.push_back("KHR_materials_unlit");
    return static_cast<int>(model.materials.size() - 1);
}

// One glTF node (and mesh, when it has triangles) for one scene node.
void add_node(tinygltf::Model& model, const std::string& name, const WeldedNode& welded, int material) {
    tinygltf::Node node;
    node.name = name;
    if (welded.triangle_count() > 0) {
        tinygltf::Primitive primitive;
        primitive.mode = TINYGLTF_MODE_TRIANGLES;
        primitive.material = material;
        primitive.attributes["POSITION"] = add_vec3(model, welded.positions, false, true);
        primitive.attributes["NORMAL"] = add_vec3(model, welded.normals, true, false);
        primitive.attributes["COLOR_0"] = add_vec3(model, welded.radiosity, false, false);
        primitive.indices = add_indices(model, welded.indices);
        tinygltf::Mesh mesh;
        mesh.name = name;
        mesh.primitives.push_back(primitive);
        model.meshes.push_back(mesh);
        node.mesh = static_cast<int>(model.meshes.size() - 1);
    }
    model.nodes.push_back(node);
    model.scenes[0].nodes.push_back(static_cast<int>(model.nodes.size() - 1));
}

tinygltf::Model build_model(const scene::Scene& scene, const WeldedMesh& welded) {
    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "hemirad";
    model.buffers.emplace_back();
    model.scenes.emplace_back();
    model.defaultScene = 0;
    const int material = add_unlit_material(model);
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        if (scene.nodes[n].synthetic) continue;  // the sky dome: not the user's
        add_node(model, scene.nodes[n].name, welded.nodes[n], material);
    }
    if (model.buffers[0].data.empty()) model.buffers.clear();  // glTF forbids empty buffers
    return model;
}

}  // namespace

// A file name as a URI reference (RFC 3986): unreserved characters kept, the rest %XX.
std::string percent_encode(const std::string& name) {
    std::string uri;
    for (const unsigned char c : name) {
        const bool unreserved = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                                c == '-' || c == '.' || c == '_' || c == '~';
        if (unreserved) {
            uri += static_cast<char>(c);
        } else {
            uri += fmt::format("%{:02X}", c);
        }
    }
    return uri;
}

// tinygltf 2.7 saves an external buffer to <directory of file>/<buffer.uri> verbatim, while
// readers decode the URI; so a name that needed escaping is renamed to its decoded form.
void write_model(const tinygltf::Model& model, const fs::path& file, const std::string& bin_name) {
    tinygltf::TinyGLTF gltf;
    const bool written = gltf.WriteGltfSceneToFile(&model, file.string(), /*embedImages=*/false,
                                                   /*embedBuffers=*/false, /*prettyPrint=*/true,
                                                   /*writeBinary=*/false);
    if (!written) throw InternalError(fmt::format("{}: could not write the baked glTF", file.string()));
    if (model.buffers.empty()) return;

    const fs::path bin = file.parent_path() / bin_name;
    std::error_code error;
    if (model.buffers[0].uri != bin_name) {
        fs::rename(file.parent_path() / model.buffers[0].uri, bin, error);
    }
    // tinygltf checks only that its streams opened; a short write (a full disk) shows here.
    // file_size reports an error as size −1.
    if (error || fs::file_size(bin, error) != model.buffers[0].data.size()) {
        throw InternalError(fmt::format("{}: could not write the baked glTF buffer {}", file.string(), bin.string()));
    }
}


void write_baked_gltf(const std::filesystem::path& file, const scene::Scene& scene, const mesh::Mesh& mesh,
                      const std::vector<glm::dvec3>& radiosity, const VertexLight* gathered) {
    write_baked_gltf(file, scene, weld(scene.nodes.size(), mesh, radiosity, gathered ? &gathered->radiosity : nullptr));
}

void write_baked_gltf(const std::filesystem::path& file, const scene::Scene& scene, const WeldedMesh& welded) {
    tinygltf::Model model = build_model(scene, welded);
    const std::string bin_name = file.stem().string() + ".bin";
    if (!model.buffers.empty()) model.buffers[0].uri = percent_encode(bin_name);
    write_model(model, file, bin_name);
}

}  // namespace hemirad::output
