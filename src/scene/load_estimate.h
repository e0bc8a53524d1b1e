// What loading a glTF file will ask for, counted from its JSON before anything is materialized:
// the triangles after instancing (a mesh's triangles once per node that places it), the
// accessors made whole (sparse ones, those without a bufferView), the buffers compressed data
// decodes into, and the largest primitive's working copies. A 2 KB file can declare a billion
// triangles; this is what lets the loader refuse it against --max-memory instead of trying.
//
// The count is lenient: whatever the file gets wrong (an index out of range, a missing key) is
// skipped here and reported by the loader, which checks every number it reads.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

namespace hemirad::scene {

struct LoadEstimate {
    double triangles = 0.0;        // after instancing: what Scene::triangles will hold
    double triangle_bytes = 0.0;   // Scene::triangles
    double accessor_bytes = 0.0;   // sparse accessors and accessors without a bufferView, made whole
    double decoded_bytes = 0.0;    // EXT_meshopt_compression fallback buffers, Draco's decoded buffers
    double working_bytes = 0.0;    // the largest primitive's positions, indices and attributes as the loader reads them
    double total() const { return triangle_bytes + accessor_bytes + decoded_bytes + working_bytes; }
    std::string describe() const;  // "1.08e+09 triangles after instancing 242 GB, sparse accessors 3.6 GB, ..."
};

// `doc`: the file's JSON (a .gltf's text, a .glb's JSON chunk), parsed.
LoadEstimate estimate_load(const nlohmann::json& doc);

// The files a scene names (buffers' and images' uris that are not data: URIs), percent-decoded
// and resolved against `base_dir`, the scene's directory.
std::vector<std::filesystem::path> referenced_files(const nlohmann::json& doc, const std::filesystem::path& base_dir);

// tinygltf reads every integer inside an `extensions` object as a 32-bit int, so 2^32 + 12 would
// silently become 12 (a meshopt byteStride, a count). Throws InputError naming `name` and the
// value's JSON path for an integer outside [-2^31, 2^31) in an extension hemirad reads (meshopt,
// Draco, texture transforms, lights, emissive strength, quantization).
void check_extension_integers(const nlohmann::json& doc, const std::string& name);

}  // namespace hemirad::scene
