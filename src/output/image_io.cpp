// Image files: linear 32-bit float EXR, tone-mapped sRGB PNG, and the exposure that suits them.
#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <cstring>
#include <cmath>
#include <cstdint>

#include "core/error.h"
#include "image/image.h"
#include "output/output.h"

namespace hemirad::output {
namespace {

// Exposure puts this luminance percentile at 1: bright walls, not the few emitter pixels.
constexpr double kExposurePercentile = 0.9;
// Where that percentile lands on the display, linear: ~0.8 after sRGB, so lit walls keep detail.
constexpr double kExposureTarget = 0.6;
// Tone curve: identity up to the knee, then a Reinhard shoulder that approaches 1 smoothly
// (continuous slope), so mid-tones keep their ratios and emitters roll off instead of clipping.
constexpr double kKnee = 0.8;

double luminance(const float* rgb) {  // Rec. 709 / sRGB primaries
    return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
}


double srgb_oetf(double linear) {  // IEC 61966-2-1
    return linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
}

// OpenImageIO's PNG writer does not see libpng's failed writes: on a full disk it left 0-byte
// frames and said nothing (checked for either back-end). A whole PNG ends with its IEND chunk, the last bytes written.
void check_png_written(const std::filesystem::path& file) {
    static constexpr unsigned char kEnd[8] = {'I', 'E', 'N', 'D', 0xAE, 0x42, 0x60, 0x82};
    std::error_code ec;
    const std::uintmax_t size = std::filesystem::file_size(file, ec);
    unsigned char tail[8] = {};
    std::ifstream in(file, std::ios::binary);
    if (!ec && size >= sizeof tail) {
        in.seekg(std::streamoff(size - sizeof tail));
        in.read(reinterpret_cast<char*>(tail), sizeof tail);
    }
    if (ec || size < sizeof tail || !in || std::memcmp(tail, kEnd, sizeof tail) != 0)
        throw OutputError(fmt::format("{}: written incompletely ({} bytes, no end chunk): is the disk full?",
                                      file.string(), ec ? 0 : size));
}

void check_size(const Image& image, const std::filesystem::path& file) {
    const std::size_t expected = std::size_t(std::max(image.width, 0)) * std::max(image.height, 0) * 3;
    if (image.width <= 0 || image.height <= 0 || image.rgb.size() != expected) {
        throw InternalError(fmt::format("{}: invalid {}x{} image with {} values", file.string(), image.width,
                                        image.height, image.rgb.size()));
    }
}

}  // namespace

double tone(double x) {
    if (!(x > 0.0)) return 0.0;  // NaN too: a broken pixel shows black, not garbage
    if (x <= kKnee) return x;
    if (std::isinf(x)) return 1.0;
    const double t = (x - kKnee) / (1.0 - kKnee);
    return kKnee + (1.0 - kKnee) * t / (1.0 + t);
}

double auto_exposure(const Image& image) {
    std::vector<double> lit;
    lit.reserve(image.rgb.size() / 3);
    for (std::size_t i = 0; i + 2 < image.rgb.size(); i += 3) {
        const double y = luminance(&image.rgb[i]);
        if (y > 0.0 && std::isfinite(y)) lit.push_back(y);  // background does not count
    }
    if (lit.empty()) return 1.0;
    const auto nth = lit.begin() + std::ptrdiff_t(kExposurePercentile * double(lit.size() - 1));
    std::nth_element(lit.begin(), nth, lit.end());
    return kExposureTarget / *nth;
}

void write_exr(const Image& image, const std::filesystem::path& file) {
    check_size(image, file);
    // 32-bit floats: half floats end at 65504, and a scene's units may put radiosity far above
    // (the loader allows emission up to 1e30): every pixel became inf.
    image::write_exr(file, image.width, image.height, image.rgb.data());
}

void write_png(const Image& image, const std::filesystem::path& file, double exposure) {
    check_size(image, file);
    // Per channel, so a saturated emitter rolls off towards white as film and eyes do.
    std::vector<std::uint8_t> bytes(image.rgb.size());
    for (std::size_t i = 0; i < bytes.size(); ++i) {
        const double display = srgb_oetf(tone(exposure * double(image.rgb[i])));
        bytes[i] = static_cast<std::uint8_t>(std::lround(std::clamp(display, 0.0, 1.0) * 255.0));
    }
    image::write_png(file, image.width, image.height, bytes.data());
    check_png_written(file);
}

}  // namespace hemirad::output
