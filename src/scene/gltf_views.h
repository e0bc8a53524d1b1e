// Building a tinygltf::Model in memory: a buffer view over bytes appended to buffer 0.
#pragma once

#include <tiny_gltf.h>

#include <cstddef>
#include <cstring>
#include <vector>

namespace hemirad::scene {

// Appends `size` bytes to buffer 0 (after zero padding to a multiple of 4, so every view is
// aligned as glTF requires for any component type) and a bufferView over them with `target`;
// returns the view's index. Buffer 0 must exist.
inline int append_view(tinygltf::Model& model, const void* data, std::size_t size, int target) {
    std::vector<unsigned char>& bytes = model.buffers[0].data;
    while (bytes.size() % 4) bytes.push_back(0);
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = bytes.size();
    view.byteLength = size;
    view.target = target;
    bytes.resize(bytes.size() + size);
    if (size > 0) std::memcpy(bytes.data() + view.byteOffset, data, size);
    model.bufferViews.push_back(view);
    return static_cast<int>(model.bufferViews.size() - 1);
}

}  // namespace hemirad::scene
