// The glTF a scene was loaded from, kept so that baked.gltf can give the user their own scene
// back (output/scene_gltf.cpp): its nodes, meshes, materials, textures, cameras and lights, with
// compressed geometry already decoded.
#pragma once

#include <map>
#include <string>
#include <vector>

#include <tiny_gltf.h>

namespace hemirad::scene {

// "a.png" with %XX escapes decoded, as tinygltf decodes an image uri before it opens the file.
std::string percent_decoded(const std::string& uri);

struct GltfSource {
    tinygltf::Model model;  // as loaded: meshopt and Draco data decoded into its buffers and accessors
    std::string base_dir;   // where its relative uris are resolved
    // The bytes of images given as data uris (tinygltf keeps no uri for them), by image index.
    std::map<int, std::vector<unsigned char>> embedded_images;
    // Triangle::primitive -> the file's mesh and the primitive's index in it.
    struct Primitive {
        int mesh = -1, index = -1;
    };
    std::vector<Primitive> primitives;
};

}  // namespace hemirad::scene
