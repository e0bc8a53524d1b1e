// Texture pyramids and bilinear lookups (see texture.h).
#include "scene/texture.h"

#include <algorithm>
#include <cmath>

#include "core/colour.h"

namespace hemirad::scene {
namespace {

// A texel index along one side of `size` texels, wrapped as the sampler says.
int wrapped(double index, int size, Wrap wrap) {
    const double n = double(size);
    switch (wrap) {
        case Wrap::clamp:
            return int(std::clamp(index, 0.0, n - 1.0));
        case Wrap::mirror: {
            const double m = index - 2.0 * n * std::floor(index / (2.0 * n));  // in [0, 2n)
            return int(std::clamp(m < n ? m : 2.0 * n - 1.0 - m, 0.0, n - 1.0));
        }
        case Wrap::repeat:
        default: {
            const double m = index - n * std::floor(index / n);
            return int(std::clamp(m, 0.0, n - 1.0));
        }
    }
}

}  // namespace

Texture::Texture(const Texels& texels, glm::dvec3 mean) : mean_(mean) {
    Level base{texels.width, texels.height, texels.rgba};
    for (glm::vec4& t : base.texels) {
        for (int c = 0; c < 3; ++c) t[c] = std::isfinite(t[c]) ? std::max(t[c], 0.0f) : 0.0f;
        t.a = std::isfinite(t.a) ? std::clamp(t.a, 0.0f, 1.0f) : 1.0f;
    }
    levels_.push_back(std::move(base));
    while (levels_.back().width > 1 || levels_.back().height > 1) {
        const Level& up = levels_.back();
        Level down{(up.width + 1) / 2, (up.height + 1) / 2, {}};
        down.texels.resize(std::size_t(down.width) * std::size_t(down.height));
        for (int y = 0; y < down.height; ++y)
            for (int x = 0; x < down.width; ++x) {
                glm::vec4 sum(0.0f);
                float count = 0.0f;
                for (int dy = 0; dy < 2; ++dy)
                    for (int dx = 0; dx < 2; ++dx) {
                        const int sx = 2 * x + dx, sy = 2 * y + dy;
                        if (sx >= up.width || sy >= up.height) continue;
                        sum += up.texels[std::size_t(sy) * std::size_t(up.width) + std::size_t(sx)];
                        count += 1.0f;
                    }
                down.texels[std::size_t(y) * std::size_t(down.width) + std::size_t(x)] = sum / count;
            }
        levels_.push_back(std::move(down));
    }
}

glm::dvec4 Texture::sample(glm::dvec2 uv, int level, Wrap wrap_s, Wrap wrap_t) const {
    const Level& l = levels_[std::size_t(std::clamp(level, 0, levels() - 1))];
    if (!std::isfinite(uv.x) || !std::isfinite(uv.y)) uv = glm::dvec2(0.0);
    // Texel centres at (i + 0.5) / size; coordinates far outside [0, 1] keep their fraction.
    const double x = uv.x * l.width - 0.5, y = uv.y * l.height - 0.5;
    const double x0 = std::floor(x), y0 = std::floor(y);
    const double fx = x - x0, fy = y - y0;
    const int xa = wrapped(x0, l.width, wrap_s), xb = wrapped(x0 + 1.0, l.width, wrap_s);
    const int ya = wrapped(y0, l.height, wrap_t), yb = wrapped(y0 + 1.0, l.height, wrap_t);
    const auto at = [&l](int i, int j) { return glm::dvec4(l.texels[std::size_t(j) * std::size_t(l.width) + std::size_t(i)]); };
    return (1.0 - fy) * ((1.0 - fx) * at(xa, ya) + fx * at(xb, ya)) + fy * ((1.0 - fx) * at(xa, yb) + fx * at(xb, yb));
}

glm::dvec4 Texture::texel(glm::dvec2 uv, int level, Wrap wrap_s, Wrap wrap_t) const {
    const Level& l = levels_[std::size_t(std::clamp(level, 0, levels() - 1))];
    if (!std::isfinite(uv.x) || !std::isfinite(uv.y)) uv = glm::dvec2(0.0);
    const int x = wrapped(std::floor(uv.x * l.width), l.width, wrap_s);
    const int y = wrapped(std::floor(uv.y * l.height), l.height, wrap_t);
    return glm::dvec4(l.texels[std::size_t(y) * std::size_t(l.width) + std::size_t(x)]);
}

std::shared_ptr<const Texture> Texture::grey() const {
    auto out = std::shared_ptr<Texture>(new Texture());
    out->levels_ = levels_;
    for (Level& l : out->levels_)
        for (glm::vec4& t : l.texels) {
            const float y = float(luminance(glm::dvec3(t)));
            t = glm::vec4(y, y, y, t.a);
        }
    out->mean_ = glm::dvec3(luminance(mean_));
    return out;
}

}  // namespace hemirad::scene
