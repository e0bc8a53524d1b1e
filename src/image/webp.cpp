// WebP textures (EXT_texture_webp), decoded by libwebp whole: RGB, or RGBA with alpha as stored
// (not multiplied into the colours).
#include <webp/decode.h>

#include <cstring>

#include <fmt/core.h>

#include "image/image.h"

namespace hemirad::image {
namespace {

const char* status_text(VP8StatusCode status) {
    switch (status) {
        case VP8_STATUS_OK: return "no error";
        case VP8_STATUS_OUT_OF_MEMORY: return "out of memory";
        case VP8_STATUS_INVALID_PARAM: return "invalid parameter";
        case VP8_STATUS_BITSTREAM_ERROR: return "broken bitstream";
        case VP8_STATUS_UNSUPPORTED_FEATURE: return "unsupported feature";
        case VP8_STATUS_SUSPENDED: return "suspended";
        case VP8_STATUS_USER_ABORT: return "aborted";
        case VP8_STATUS_NOT_ENOUGH_DATA: return "the data ends early";
    }
    return "unknown error";
}

class WebpDecoder final : public Decoder {
public:
    WebpDecoder(const unsigned char* bytes, std::size_t size, int width, int height, bool alpha)
        : bytes_(bytes), size_(size) {
        spec_.width = width;
        spec_.height = height;
        spec_.channels = alpha ? 4 : 3;
        spec_.bits = 8;
    }

    bool read_rows(int y0, int y1, int channels, void* out) override {
        if (!decoded_ && !decode()) return false;
        if (y0 < 0 || y1 > spec_.height || y0 > y1 || channels < 1 || channels > spec_.channels) {
            error_ = fmt::format("rows {} to {} of {} channels asked of a {} × {} image of {}", y0, y1, channels,
                                 spec_.width, spec_.height, spec_.channels);
            return false;
        }
        auto* to = static_cast<unsigned char*>(out);
        const std::size_t n = std::size_t(y1 - y0) * std::size_t(spec_.width);
        const unsigned char* from = pixels_.data() + std::size_t(y0) * std::size_t(spec_.width) * std::size_t(spec_.channels);
        for (std::size_t p = 0; p < n; ++p)
            std::memcpy(to + p * std::size_t(channels), from + p * std::size_t(spec_.channels), std::size_t(channels));
        return true;
    }

private:
    bool decode() {
        pixels_.resize(std::size_t(spec_.width) * std::size_t(spec_.height) * std::size_t(spec_.channels));
        const int stride = spec_.width * spec_.channels;
        const bool ok = spec_.channels == 4
                            ? WebPDecodeRGBAInto(bytes_, size_, pixels_.data(), pixels_.size(), stride) != nullptr
                            : WebPDecodeRGBInto(bytes_, size_, pixels_.data(), pixels_.size(), stride) != nullptr;
        if (!ok) {
            WebPBitstreamFeatures features;
            const VP8StatusCode status = WebPGetFeatures(bytes_, size_, &features);
            error_ = status == VP8_STATUS_OK ? "the WebP data does not decode" : status_text(status);
            pixels_.clear();
            return false;
        }
        decoded_ = true;
        return true;
    }

    const unsigned char* bytes_;
    std::size_t size_;
    bool decoded_ = false;
    std::vector<unsigned char> pixels_;
};

}  // namespace

std::unique_ptr<Decoder> open_webp(const unsigned char* bytes, std::size_t size, std::string& problem) {
    WebPBitstreamFeatures features;
    const VP8StatusCode status = WebPGetFeatures(bytes, size, &features);
    if (status != VP8_STATUS_OK) {
        problem = fmt::format("not a WebP image libwebp reads: {}", status_text(status));
        return nullptr;
    }
    if (features.has_animation) {
        problem = "an animated WebP (a texture is one picture)";
        return nullptr;
    }
    return std::make_unique<WebpDecoder>(bytes, size, features.width, features.height, features.has_alpha != 0);
}

}  // namespace hemirad::image
