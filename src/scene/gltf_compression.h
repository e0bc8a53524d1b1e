// Compressed glTF geometry, decoded before the loader reads any accessor: EXT_meshopt_compression
// with meshoptimizer (Debian's libmeshoptimizer-dev) into the buffers tinygltf loaded, and
// KHR_draco_mesh_compression with Draco (libdraco-dev) into buffers and accessors of its own.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace tinygltf {
class Model;
}

namespace hemirad::scene {

// EXT_meshopt_compression's fallback buffers: the buffers whose bytes exist only once the
// compressed bufferViews are decoded (no uri, `"fallback": true`), by index, with the byteLength
// the file declares for each.
using MeshoptFallbacks = std::map<int, std::uint64_t>;

// What tinygltf would refuse in a file (`bytes`: a .gltf's JSON text, or a whole .glb when
// `glb`) that uses compressed geometry, changed in its JSON so that tinygltf loads the rest:
// each EXT_meshopt_compression fallback buffer without a uri is given a one-byte data uri in
// its place (these buffers are returned, for decode_meshopt to fill), and each
// KHR_draco_mesh_compression primitive loses its indices accessor, which has no bufferView
// (decode_draco gives it the decoded indices). A file without either extension is left
// untouched. Throws InputError naming `name` for a fallback buffer whose byteLength is not a
// whole number of bytes.
MeshoptFallbacks stand_in_for_compressed_data(std::vector<unsigned char>& bytes, bool glb, const std::string& name);

// Decodes every bufferView of `model` that has EXT_meshopt_compression (modes ATTRIBUTES,
// TRIANGLES and INDICES; filters NONE, OCTAHEDRAL, QUATERNION and EXPONENTIAL) into the bytes
// the bufferView itself names, sizing the fallback buffers to what the views need. Every number
// of the extension is checked against the buffers before meshoptimizer sees it; a view whose
// data does not decode, or whose extension is malformed, throws InputError naming `name` and
// the bufferView.
void decode_meshopt(tinygltf::Model& model, const MeshoptFallbacks& fallbacks, const std::string& name);

// Decodes every primitive of `model` that has KHR_draco_mesh_compression: each attribute the
// extension lists becomes a new FLOAT accessor (Draco's dequantization and normalization
// applied) over a new buffer, and the indices a new UNSIGNED_INT accessor, which the primitive
// then names in place of the accessors the file gave it. Data that does not decode, or an
// extension that names what the data lacks, throws InputError naming `name`, the mesh and the
// primitive.
void decode_draco(tinygltf::Model& model, const std::string& name);

}  // namespace hemirad::scene
