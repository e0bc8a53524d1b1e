// The mean linear colour of an encoded texture image (PNG, JPEG or WebP), decoded by the image
// back-end (src/image) a band of rows at a time: the loader needs only the mean, so a
// 20000 × 20000 PNG costs a few megabytes of memory, not gigabytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace hemirad::scene {

// Images with more pixels than this are refused (decoding one takes tens of seconds), and so
// are those wider or taller than kMaxImageEdge (a row of them is decoded at once).
inline constexpr std::uint64_t kMaxImagePixels = std::uint64_t{1} << 30;  // 32768 × 32768
inline constexpr int kMaxImageEdge = 65536;
// The pixels of all the images one scene's textures use, together (a file naming one large image
// in many textures decodes it once; one naming many large images is refused past this).
inline constexpr std::uint64_t kMaxScenePixels = std::uint64_t{1} << 32;

// An image as the file holds it, before decoding, or what is wrong with where it should be.
struct EncodedImage {
    std::vector<unsigned char> bytes;
    std::string problem;
    bool refused = false;  // the problem is a broken structure (see ImageMean::refused)
};

// An image kept for sampling: linear RGBA (sRGB decoded; alpha 1 without an alpha channel; a grey
// image's one channel in all three), box-filtered by a whole factor until no side exceeds
// kMaxTexelEdge. Per-element averages need no finer detail: an element spans many texels, and
// the box filter keeps every region's mean.
inline constexpr int kMaxTexelEdge = 1024;
struct Texels {
    int width = 0, height = 0;
    int factor = 1;                // source pixels per texel along each side
    std::vector<glm::vec4> rgba;   // row-major, row 0 = the image's top row (glTF's v = 0)
};

struct ImageMean {
    bool ok = false;
    std::string problem;    // when !ok: "not a .png image hemirad can decode (…)", …
    // When !ok: the image was refused for a limit (kMaxImagePixels, kMaxImageEdge) or a broken
    // structure (a bufferView past its buffer), not merely missing or undecodable: such a file is
    // refused whatever --strict-textures says, as every other hostile input is.
    bool refused = false;
    glm::dvec3 mean{1.0};   // linear RGB; a grey image's one channel in all three
    double alpha = 1.0;     // the mean alpha (linear, as glTF stores it); 1 without an alpha channel
    bool coloured = false;  // some pixel's red, green and blue differ
    int width = 0, height = 0, channels = 0, bits = 0;
};

// 8- and 16-bit values are sRGB-encoded and decoded to linear before averaging (averaging the
// encoded values would darken the result); float images are linear already. Alpha (a channel
// after the colour ones: grey + alpha, RGBA) is averaged as it is stored, linear.
// The format is the bytes' own (PNG, JPEG or WebP), whatever the uri or mime type says.
// With `keep`, the decoded texels are also kept there (see Texels).
ImageMean decode_image_mean(const unsigned char* bytes, std::size_t size, Texels* keep = nullptr);

}  // namespace hemirad::scene
