// Image files in and out, behind one interface with two back-ends chosen when an executable is
// linked (cmake/ImageBackends.cmake):
//   OpenImageIO  the full build's default: PNG and JPEG textures, EXR and PNG output
//   codecs       the format libraries alone (libpng, libjpeg, OpenEXR), for the relocatable bundle:
//                OpenImageIO's library closure is ~350 MB, these are a few
// WebP textures are decoded by libwebp in both (OpenImageIO 2.4 multiplies a WebP's colours by its
// alpha whatever it is asked, and glTF's colours are not so multiplied). Both back-ends give the same
// values for every pixel of every texture they decode (tests/test_image_backends.cpp), and a bake
// with either gives the same bytes.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace hemirad::image {

// The formats of glTF's textures (WebP through EXT_texture_webp), told by the bytes' signature.
enum class Format { png, jpeg, webp };
std::optional<Format> format_of(const unsigned char* bytes, std::size_t size);
const char* extension(Format format);  // "png", "jpg", "webp"

struct Spec {
    int width = 0, height = 0;
    int channels = 0;  // 1 grey, 2 grey + alpha, 3 RGB, 4 RGBA
    int bits = 8;      // per stored value: 8 or 16 (unsigned integers), 32 (float)
};

// An image being decoded, a band of rows at a time, top to bottom.
class Decoder {
public:
    virtual ~Decoder() = default;
    const Spec& spec() const { return spec_; }
    // Rows [y0, y1) (y0 the row after the last one read), the first `channels` channels of each
    // pixel, spec().bits per value in the machine's byte order, into `out`. False with error() set
    // when the data ends or breaks before y1. error() and open's `problem` are one line, in
    // OpenImageIO's words in both back-ends ("PNG read error: …", "JPEG error: …"), naming no file.
    virtual bool read_rows(int y0, int y1, int channels, void* out) = 0;
    const std::string& error() const { return error_; }

protected:
    Spec spec_;
    std::string error_;
};

// What a back-end offers. `problem` gets the decoder's own reason when open gives null.
struct Backend {
    const char* name;
    std::unique_ptr<Decoder> (*open)(Format format, const unsigned char* bytes, std::size_t size,
                                      std::string& problem);
    // `rgb` holds width × height × 3 values, row 0 at the top. A failed write throws OutputError.
    void (*write_exr)(const std::filesystem::path& file, int width, int height, const float* rgb);
    void (*write_png)(const std::filesystem::path& file, int width, int height, const unsigned char* rgb);
};

// An image file read whole as floats (the benchmark reads EXR renders and references with it).
struct FloatImage {
    int width = 0, height = 0;
    std::vector<std::string> channels;  // the file's channel names, in the file's order
    std::vector<float> values;          // pixel by pixel, channels.size() values each
    int channel(const std::string& name) const;  // its index, or -1
};

// The back-end this executable links, and its readers and writers.
const Backend& backend();
inline std::unique_ptr<Decoder> open(Format format, const unsigned char* bytes, std::size_t size,
                                     std::string& problem) {
    return backend().open(format, bytes, size, problem);
}
inline void write_exr(const std::filesystem::path& file, int width, int height, const float* rgb) {
    backend().write_exr(file, width, height, rgb);
}
inline void write_png(const std::filesystem::path& file, int width, int height, const unsigned char* rgb) {
    backend().write_png(file, width, height, rgb);
}
// An EXR file's every channel; throws InputError naming the file when it cannot be read.
FloatImage read_exr(const std::filesystem::path& file);

// The two back-ends, each linked where it is built: `oiio` only where OpenImageIO is.
const Backend& oiio_backend();
const Backend& codecs_backend();

// The WebP decoder both back-ends use (libwebp).
std::unique_ptr<Decoder> open_webp(const unsigned char* bytes, std::size_t size, std::string& problem);

}  // namespace hemirad::image
