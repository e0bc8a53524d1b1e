// Writing a tinygltf::Model as a .gltf with its buffer beside it (both baked.gltf modes).
#pragma once

#include <filesystem>
#include <string>

#include <tiny_gltf.h>

namespace hemirad::output {

// A file name as a URI reference (RFC 3986): unreserved characters kept, the rest %XX.
std::string percent_encode(const std::string& name);

// Writes `model` to `file` (.gltf, pretty-printed) and buffer 0 to `bin_name` beside it, which
// buffer 0's uri must name (percent-encoded). Throws InternalError when either is not written whole.
void write_model(const tinygltf::Model& model, const std::filesystem::path& file, const std::string& bin_name);

}  // namespace hemirad::output
