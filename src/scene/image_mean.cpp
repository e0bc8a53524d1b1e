// Texture means decoded from memory by the image back-end, a band of rows at a time (see
// image_mean.h).
#include "scene/image_mean.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <optional>
#include <vector>

#include <fmt/core.h>

#include "image/image.h"

namespace hemirad::scene {
namespace {

// Each band of rows decoded at once holds at most this many bytes.
constexpr std::size_t kBandBytes = std::size_t{16} << 20;

double srgb_to_linear(double x) {
    return x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4);
}

// A decoder's reason (one line already, image.h), or a word that there was none.
std::string reason(const std::string& text) {
    return text.empty() ? "no reason given" : text;
}

// Sends what the image libraries print to stderr (fd 2) to a scratch file while it lives:
// libpng's default handlers print "libpng error: …" and "libpng warning: …" themselves, which
// would be a second line beside the CLI's one line, or noise on a good bake.
class StderrCapture {
public:
    StderrCapture() {
        std::fflush(stderr);
        file_ = std::tmpfile();
        saved_ = file_ ? ::dup(2) : -1;
        if (saved_ >= 0 && ::dup2(::fileno(file_), 2) < 0) {
            ::close(saved_);
            saved_ = -1;
        }
    }
    ~StderrCapture() {
        if (saved_ >= 0) {
            std::fflush(stderr);
            ::dup2(saved_, 2);
            ::close(saved_);
        }
        if (file_) std::fclose(file_);
    }
    StderrCapture(const StderrCapture&) = delete;
    StderrCapture& operator=(const StderrCapture&) = delete;

private:
    std::FILE* file_ = nullptr;
    int saved_ = -1;
};

}  // namespace

ImageMean decode_image_mean(const unsigned char* bytes, std::size_t size, Texels* keep) {
    ImageMean out;
    const auto fail = [&out](std::string problem) {
        out.problem = std::move(problem);
        return out;
    };
    if (size == 0) return fail("the image is empty (0 bytes)");
    const std::optional<image::Format> format = image::format_of(bytes, size);
    if (!format) return fail("not a PNG, JPEG or WebP image (its first bytes are none of their signatures)");
    const char* ext = image::extension(*format);

    const StderrCapture quiet;  // the decoders' own complaints: the problem below says what went wrong
    std::string problem;
    const std::unique_ptr<image::Decoder> in = image::open(*format, bytes, size, problem);
    if (!in) return fail(fmt::format("not a .{} image hemirad can decode ({})", ext, reason(problem)));
    const image::Spec& spec = in->spec();
    const std::uint64_t pixels = std::uint64_t(std::max(spec.width, 0)) * std::uint64_t(std::max(spec.height, 0));
    if (spec.width < 1 || spec.height < 1 || spec.channels < 1)
        return fail(fmt::format("not a picture ({} × {} pixels, {} channels)", spec.width, spec.height, spec.channels));
    if (pixels > kMaxImagePixels || spec.width > kMaxImageEdge || spec.height > kMaxImageEdge) {
        out.refused = true;
        return fail(fmt::format("{} × {} pixels, above the limits of {} pixels and {} a side", spec.width,
                                spec.height, kMaxImagePixels, kMaxImageEdge));
    }

    // 8- and 16-bit values are counted per level, then decoded once per level (a histogram:
    // one pow() per distinct level, not per pixel); anything else is read as linear floats.
    const int bits = spec.bits;
    const int colour = spec.channels >= 3 ? 3 : 1;  // grey (+alpha): one channel for all three
    const bool has_alpha = spec.channels == colour + 1;
    const int channels = colour + (has_alpha ? 1 : 0);  // read: the colour, then alpha
    const std::size_t value_bytes = std::size_t(bits / 8);
    const std::size_t row_values = std::size_t(spec.width) * std::size_t(channels);
    const int band = int(std::clamp<std::size_t>(kBandBytes / (row_values * value_bytes), 1, std::size_t(spec.height)));
    std::vector<unsigned char> rows(std::size_t(band) * row_values * value_bytes);

    const std::size_t levels = bits == 8 ? 256 : bits == 16 ? 65536 : 0;
    std::vector<std::uint64_t> histogram(std::size_t(channels) * levels, 0);
    double sums[4] = {0.0, 0.0, 0.0, 0.0};  // per channel read

    // Texels kept (see Texels): linear sums per texel of the reduced grid, divided at the end by
    // the pixels each one covers (fewer along the right and bottom edges).
    const int factor = keep ? std::max(1, (std::max(spec.width, spec.height) + kMaxTexelEdge - 1) / kMaxTexelEdge) : 1;
    const int tw = (spec.width + factor - 1) / factor, th = (spec.height + factor - 1) / factor;
    std::vector<double> texel_sums(keep ? std::size_t(tw) * std::size_t(th) * 4 : 0, 0.0);
    std::vector<float> linear(levels);  // colour levels decoded from sRGB once each
    if (keep)
        for (std::size_t level = 0; level < levels; ++level)
            linear[level] = float(srgb_to_linear(double(level) / double(levels - 1)));
    const auto value_at = [&](std::size_t i, int c) -> double {  // channel c's i-th stored value, linear
        if (bits == 8) return c < colour ? double(linear[rows[i]]) : double(rows[i]) / 255.0;
        if (bits == 16) {
            std::uint16_t v;
            std::memcpy(&v, rows.data() + 2 * i, 2);
            return c < colour ? double(linear[v]) : double(v) / 65535.0;
        }
        float v;
        std::memcpy(&v, rows.data() + 4 * i, 4);
        return double(v);
    };
    const auto raw_at = [&](std::size_t i) -> std::uint32_t {  // the stored bits, to compare channels
        std::uint32_t v = 0;
        std::memcpy(&v, rows.data() + value_bytes * i, value_bytes);
        return v;
    };

    for (int y = 0; y < spec.height; y += band) {
        const int n = std::min(band, spec.height - y);
        if (!in->read_rows(y, y + n, channels, rows.data()))
            return fail(fmt::format("the image does not decode past row {} ({})", y, reason(in->error())));
        const std::size_t values = std::size_t(n) * row_values;
        if (bits == 8) {
            for (std::size_t i = 0; i < values; ++i) ++histogram[(i % std::size_t(channels)) * levels + rows[i]];
        } else if (bits == 16) {
            for (std::size_t i = 0; i < values; ++i) {
                std::uint16_t v;
                std::memcpy(&v, rows.data() + 2 * i, 2);
                ++histogram[(i % std::size_t(channels)) * levels + v];
            }
        } else {
            for (std::size_t i = 0; i < values; ++i) {
                float v;
                std::memcpy(&v, rows.data() + 4 * i, 4);
                sums[i % std::size_t(channels)] += double(v);
            }
        }
        if (colour == 3 && !out.coloured)
            for (std::size_t i = 0; i < values; i += std::size_t(channels))
                if (raw_at(i) != raw_at(i + 1) || raw_at(i + 1) != raw_at(i + 2)) {
                    out.coloured = true;
                    break;
                }
        if (!keep) continue;
        for (int r = 0; r < n; ++r) {
            double* texel_row = texel_sums.data() + std::size_t((y + r) / factor) * std::size_t(tw) * 4;
            for (int x = 0; x < spec.width; ++x) {
                const std::size_t i = std::size_t(r) * row_values + std::size_t(x) * std::size_t(channels);
                double* t = texel_row + std::size_t(x / factor) * 4;
                for (int c = 0; c < colour; ++c) t[c] += value_at(i + std::size_t(c), c);
                if (colour == 1) t[1] = t[2] = t[0];
                t[3] += has_alpha ? value_at(i + std::size_t(colour), colour) : 1.0;
            }
        }
    }
    for (int c = 0; c < channels && levels > 0; ++c)
        for (std::size_t level = 0; level < levels; ++level)
            if (const std::uint64_t count = histogram[std::size_t(c) * levels + level]; count != 0) {
                const double value = double(level) / double(levels - 1);
                sums[c] += double(count) * (c < colour ? srgb_to_linear(value) : value);  // alpha is linear
            }
    if (keep) {
        keep->width = tw;
        keep->height = th;
        keep->factor = factor;
        keep->rgba.assign(std::size_t(tw) * std::size_t(th), glm::vec4(0.0f));
        for (int ty = 0; ty < th; ++ty)
            for (int tx = 0; tx < tw; ++tx) {
                const double covered = double(std::min(factor, spec.width - tx * factor)) *
                                       double(std::min(factor, spec.height - ty * factor));
                const double* t = texel_sums.data() + (std::size_t(ty) * std::size_t(tw) + std::size_t(tx)) * 4;
                glm::vec4& out_texel = keep->rgba[std::size_t(ty) * std::size_t(tw) + std::size_t(tx)];
                for (int c = 0; c < 4; ++c) out_texel[c] = float(t[c] / covered);
            }
    }
    const glm::dvec3 sum = colour == 1 ? glm::dvec3(sums[0]) : glm::dvec3(sums[0], sums[1], sums[2]);
    out.mean = sum / double(pixels);
    if (has_alpha) out.alpha = std::clamp(sums[colour] / double(pixels), 0.0, 1.0);
    for (int c = 0; c < 3; ++c)
        if (!std::isfinite(out.mean[c]) || out.mean[c] < 0.0)
            return fail(fmt::format("its mean colour has channel {} = {}, not a finite value >= 0", c, out.mean[c]));
    out.ok = true;
    out.width = spec.width;
    out.height = spec.height;
    out.channels = spec.channels;
    out.bits = bits;
    return out;
}

}  // namespace hemirad::scene
