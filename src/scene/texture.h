// Textures as the mesher samples them: a decoded image as a pyramid of box-filtered levels, and
// how a material reads it (which image, wrap modes). Per-element averages come from sampling
// it (mesh/texturing.h).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include <glm/glm.hpp>

#include "scene/image_mean.h"

namespace hemirad::scene {

// glTF sampler wrap modes (the GL enums glTF uses).
enum class Wrap : std::uint16_t { repeat = 10497, clamp = 33071, mirror = 33648 };

class Texture {
public:
    // Level 0 is the kept texels (see Texels); each next level halves both sides (rounding up),
    // each texel the mean of the up to 2 x 2 texels it covers, down to 1 x 1. Colours below 0
    // (possible in a float image) become 0, and alpha is held to [0, 1].
    explicit Texture(const Texels& texels, glm::dvec3 mean);

    int levels() const { return int(levels_.size()); }
    int width(int level = 0) const { return levels_[std::size_t(level)].width; }
    int height(int level = 0) const { return levels_[std::size_t(level)].height; }
    // The mean linear colour of the whole source image (its exact mean: ImageMean::mean).
    glm::dvec3 mean() const { return mean_; }

    // Bilinear lookup at texture coordinate uv (glTF: u right, v down from the top row) on one
    // level, with the sampler's wrap modes. Non-finite coordinates read texel (0, 0).
    glm::dvec4 sample(glm::dvec2 uv, int level, Wrap wrap_s, Wrap wrap_t) const;
    // The texel of one level that holds uv (nearest lookup), wrapped likewise: its value is the
    // exact mean of the level-0 texels it covers, and nothing beyond them.
    glm::dvec4 texel(glm::dvec2 uv, int level, Wrap wrap_s, Wrap wrap_t) const;

    // The same image in grey: each texel's colour replaced by its Rec. 709 luminance.
    std::shared_ptr<const Texture> grey() const;

private:
    struct Level {
        int width = 0, height = 0;
        std::vector<glm::vec4> texels;
    };
    Texture() = default;
    std::vector<Level> levels_;
    glm::dvec3 mean_{1.0};
};

// Where a material reads a texture: Scene::textures[texture] through the sampler's wrap modes,
// at the texture coordinates each triangle carries for it (TEXCOORD_n, KHR_texture_transform
// applied). texture < 0: none.
struct TextureSlot {
    int texture = -1;
    Wrap wrap_s = Wrap::repeat, wrap_t = Wrap::repeat;
    explicit operator bool() const { return texture >= 0; }
};

}  // namespace hemirad::scene
