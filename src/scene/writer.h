// Writes a Scene as a glTF 2.0 file, so scenes built in code (tests, generated scenes) reach a
// bake through the loader, exactly as a user's file does.
#pragma once

#include <filesystem>

#include "scene/scene.h"

namespace hemirad::scene {

// `file` (.gltf) and its buffer `<stem>.bin` beside it, or one binary `file` when it ends in
// .glb (little-endian hosts only, as the glTF container is). One glTF node per MeshNode, with the
// identity transform and the node's name; per node one triangle primitive per material, its
// vertices the triangles' world-space corners (as float32, the only position type glTF has).
// Each camera becomes a node of its own with its matrix. Materials keep base colour, emission
// (emissiveFactor, with KHR_materials_emissive_strength above 1) and doubleSided; a triangle whose
// reflectance differs from its material's base colour gets it as COLOR_0 under a white base
// colour. Throws InternalError when the file cannot be written.
void write_gltf(const Scene& scene, const std::filesystem::path& file);

}  // namespace hemirad::scene
