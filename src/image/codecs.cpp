// The codecs image back-end (see image.h): libpng and libjpeg decode textures, libpng writes the
// tone-mapped PNG, OpenEXR's own library writes and reads EXR. Decoded as OpenImageIO decodes with
// the same libraries: a palette expanded to RGB, grey of 1, 2 or 4 bits to 8, a tRNS chunk to an
// alpha channel, 16-bit PNG values kept, no gamma applied, a CMYK JPEG turned to RGB.
#include <png.h>
#include <jpeglib.h>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>

#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <exception>

#include <fmt/core.h>

#include "core/error.h"
#include "image/image.h"

namespace hemirad::image {
namespace {

// --- PNG -------------------------------------------------------------------------------------

// libpng reports an error by calling this, which must not return: it keeps the message, in
// OpenImageIO's words ("PNG read error: …", "PNG write error: …"), and jumps back to the setjmp
// of the call that was running. Warnings (a bad ancillary chunk) are ignored, as libpng's own
// defaults and OpenImageIO's reader do.
struct PngErrors {
    const char* prefix;
    std::string message;
};
[[noreturn]] void png_on_error(png_structp png, png_const_charp message) {
    auto* errors = static_cast<PngErrors*>(png_get_error_ptr(png));
    errors->message = std::string(errors->prefix) + (message ? message : "no reason given");
    png_longjmp(png, 1);
}
void png_on_warning(png_structp, png_const_charp) {}

struct MemoryReader {
    const unsigned char* bytes;
    std::size_t size, at = 0;
};
// Bytes past the end are OpenImageIO's "Read error: hit end of file" (its reader's own message,
// not libpng's, so without the prefix).
void png_read_memory(png_structp png, png_bytep out, png_size_t n) {
    auto* in = static_cast<MemoryReader*>(png_get_io_ptr(png));
    if (n > in->size - in->at) {
        static_cast<PngErrors*>(png_get_error_ptr(png))->message = "Read error: hit end of file";
        png_longjmp(png, 1);
    }
    std::memcpy(out, in->bytes + in->at, n);
    in->at += n;
}

class PngDecoder final : public Decoder {
public:
    PngDecoder(const unsigned char* bytes, std::size_t size) : memory_{bytes, size} {}
    ~PngDecoder() override { png_destroy_read_struct(&png_, &info_, nullptr); }

    // The header and the transforms; false with error_ set.
    bool start() {
        png_ = png_create_read_struct(PNG_LIBPNG_VER_STRING, &errors_, png_on_error, png_on_warning);
        if (!png_) return fail("libpng could not start");
        info_ = png_create_info_struct(png_);
        if (!info_) return fail("libpng could not start");
        if (setjmp(png_jmpbuf(png_))) return fail(errors_.message);
        png_set_read_fn(png_, &memory_, png_read_memory);
        png_read_info(png_, info_);
        const int colour = png_get_color_type(png_, info_);
        const int depth = png_get_bit_depth(png_, info_);
        if (colour == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png_);
        if (colour == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png_);
        if (png_get_valid(png_, info_, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(png_);
        if (depth == 16) {
            const std::uint16_t one = 1;
            unsigned char first;
            std::memcpy(&first, &one, 1);
            if (first == 1) png_set_swap(png_);  // PNG stores big-endian; the machine is not
        }
        interlaced_ = png_set_interlace_handling(png_) > 1;
        png_read_update_info(png_, info_);
        spec_.width = int(png_get_image_width(png_, info_));
        spec_.height = int(png_get_image_height(png_, info_));
        spec_.channels = png_get_channels(png_, info_);
        spec_.bits = png_get_bit_depth(png_, info_) == 16 ? 16 : 8;
        row_bytes_ = png_get_rowbytes(png_, info_);
        return true;
    }

    bool read_rows(int y0, int y1, int channels, void* out) override {
        if (y0 != next_ || y1 > spec_.height || y0 > y1 || channels < 1 || channels > spec_.channels)
            return fail(fmt::format("rows {} to {} asked after row {}", y0, y1, next_));
        const std::size_t value_bytes = std::size_t(spec_.bits / 8);
        // Everything with a destructor is made before the setjmp: libpng's error jumps over the
        // frames between, and would skip destructors there.
        std::vector<unsigned char> row(interlaced_ ? 0 : row_bytes_);
        std::vector<png_bytep> rows(interlaced_ && whole_.empty() ? std::size_t(spec_.height) : 0);
        if (setjmp(png_jmpbuf(png_))) return fail(errors_.message);
        if (interlaced_ && whole_.empty()) {  // the passes fill every row: the whole image at once
            whole_.resize(row_bytes_ * std::size_t(spec_.height));
            for (int y = 0; y < spec_.height; ++y) rows[std::size_t(y)] = whole_.data() + row_bytes_ * std::size_t(y);
            png_read_image(png_, rows.data());
            png_read_end(png_, nullptr);  // as OpenImageIO does here: a broken chunk after the pixels fails it
        }
        auto* to = static_cast<unsigned char*>(out);
        const std::size_t pixel_out = std::size_t(channels) * value_bytes;
        const std::size_t pixel_in = std::size_t(spec_.channels) * value_bytes;
        for (int y = y0; y < y1; ++y) {
            const unsigned char* from;
            if (interlaced_) {
                from = whole_.data() + row_bytes_ * std::size_t(y);
            } else {
                png_read_row(png_, row.data(), nullptr);
                from = row.data();
            }
            for (int x = 0; x < spec_.width; ++x)
                std::memcpy(to + std::size_t(x) * pixel_out, from + std::size_t(x) * pixel_in, pixel_out);
            to += std::size_t(spec_.width) * pixel_out;
            next_ = y + 1;
        }
        return true;
    }

private:
    bool fail(std::string message) {
        error_ = std::move(message);
        return false;
    }

    MemoryReader memory_;
    PngErrors errors_{"PNG read error: ", {}};
    png_structp png_ = nullptr;
    png_infop info_ = nullptr;
    bool interlaced_ = false;
    std::size_t row_bytes_ = 0;
    int next_ = 0;
    std::vector<unsigned char> whole_;
};

// --- JPEG ------------------------------------------------------------------------------------

struct JpegErrors {
    jpeg_error_mgr manager;
    std::jmp_buf jump;
    std::string message;
};
// The first thing libjpeg said, in OpenImageIO's words ("JPEG error: …"): a warning that came
// before the error (a header cut short warns "Premature end of JPEG file", then fails) says more.
void jpeg_keep_message(j_common_ptr info) {
    auto* errors = reinterpret_cast<JpegErrors*>(info->err);
    if (!errors->message.empty()) return;
    char text[JMSG_LENGTH_MAX];
    (*info->err->format_message)(info, text);
    errors->message = std::string("JPEG error: ") + text;
}
[[noreturn]] void jpeg_on_error(j_common_ptr info) {
    jpeg_keep_message(info);
    std::longjmp(reinterpret_cast<JpegErrors*>(info->err)->jump, 1);
}

class JpegDecoder final : public Decoder {
public:
    JpegDecoder() {
        info_.err = jpeg_std_error(&errors_.manager);
        errors_.manager.error_exit = jpeg_on_error;
        errors_.manager.output_message = jpeg_keep_message;  // kept, not printed
    }
    ~JpegDecoder() override {
        if (created_) jpeg_destroy_decompress(&info_);
    }

    bool start(const unsigned char* bytes, std::size_t size) {
        if (setjmp(errors_.jump)) return fail(errors_.message);
        jpeg_create_decompress(&info_);
        created_ = true;
        jpeg_mem_src(&info_, bytes, static_cast<unsigned long>(size));
        jpeg_read_header(&info_, TRUE);
        cmyk_ = info_.jpeg_color_space == JCS_CMYK || info_.jpeg_color_space == JCS_YCCK;
        if (cmyk_) info_.out_color_space = JCS_CMYK;
        else if (info_.num_components >= 3) info_.out_color_space = JCS_RGB;
        else info_.out_color_space = JCS_GRAYSCALE;
        jpeg_start_decompress(&info_);
        spec_.width = int(info_.output_width);
        spec_.height = int(info_.output_height);
        spec_.channels = cmyk_ ? 3 : info_.output_components;
        spec_.bits = 8;
        return true;
    }

    bool read_rows(int y0, int y1, int channels, void* out) override {
        if (y0 != int(info_.output_scanline) || y1 > spec_.height || y0 > y1 || channels < 1 ||
            channels > spec_.channels)
            return fail(fmt::format("rows {} to {} asked after row {}", y0, y1, info_.output_scanline));
        std::vector<unsigned char> row(std::size_t(spec_.width) * std::size_t(info_.output_components));
        if (setjmp(errors_.jump)) return fail(errors_.message);
        auto* to = static_cast<unsigned char*>(out);
        for (int y = y0; y < y1; ++y) {
            JSAMPROW rows[1] = {row.data()};
            if (jpeg_read_scanlines(&info_, rows, 1) != 1) return fail("the JPEG data ends early");
            for (int x = 0; x < spec_.width; ++x) {
                const unsigned char* p = row.data() + std::size_t(x) * std::size_t(info_.output_components);
                unsigned char rgb[3];
                if (cmyk_) {  // Adobe's inverted CMYK, as OpenImageIO reads it
                    for (int c = 0; c < 3; ++c) rgb[c] = static_cast<unsigned char>(int(p[c]) * int(p[3]) / 255);
                    p = rgb;
                }
                std::memcpy(to, p, std::size_t(channels));
                to += channels;
            }
        }
        return true;
    }

private:
    bool fail(std::string message) {
        error_ = std::move(message);
        return false;
    }

    jpeg_decompress_struct info_{};
    JpegErrors errors_{};
    bool created_ = false;
    bool cmyk_ = false;
};

std::unique_ptr<Decoder> open_codecs(Format format, const unsigned char* bytes, std::size_t size,
                                     std::string& problem) {
    switch (format) {
        case Format::png: {
            auto png = std::make_unique<PngDecoder>(bytes, size);
            if (png->start()) return png;
            problem = png->error();
            return nullptr;
        }
        case Format::jpeg: {
            auto jpeg = std::make_unique<JpegDecoder>();
            if (jpeg->start(bytes, size)) return jpeg;
            problem = jpeg->error();
            return nullptr;
        }
        case Format::webp: return open_webp(bytes, size, problem);
    }
    problem = "an unknown format";
    return nullptr;
}

// --- writers ---------------------------------------------------------------------------------

void write_exr_codecs(const std::filesystem::path& file, int width, int height, const float* rgb) {
    try {
        Imf::Header header(width, height);
        header.compression() = Imf::ZIP_COMPRESSION;
        Imf::FrameBuffer frame;
        const char* names[3] = {"R", "G", "B"};
        for (int c = 0; c < 3; ++c) {
            header.channels().insert(names[c], Imf::Channel(Imf::FLOAT));
            frame.insert(names[c], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(rgb + c)),
                                              3 * sizeof(float), 3 * sizeof(float) * std::size_t(width)));
        }
        Imf::OutputFile out(file.string().c_str(), header);
        out.setFrameBuffer(frame);
        out.writePixels(height);
    } catch (const std::exception& e) {
        throw OutputError(fmt::format("{}: cannot write: {}", file.string(), e.what()));
    }
}

void write_png_codecs(const std::filesystem::path& file, int width, int height, const unsigned char* rgb) {
    const std::string name = file.string();
    std::FILE* out = std::fopen(name.c_str(), "wb");
    if (!out) throw OutputError(fmt::format("{}: cannot write: {}", name, std::strerror(errno)));
    PngErrors errors{"PNG write error: ", {}};
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &errors, png_on_error, png_on_warning);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!png || !info) {
        png_destroy_write_struct(&png, &info);
        std::fclose(out);
        throw OutputError(fmt::format("{}: cannot write: libpng could not start", name));
    }
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        std::fclose(out);
        throw OutputError(fmt::format("{}: cannot write: {}", name, errors.message));
    }
    png_init_io(png, out);
    png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (int y = 0; y < height; ++y)
        png_write_row(png, const_cast<png_bytep>(rgb + std::size_t(y) * std::size_t(width) * 3));
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    const bool flushed = std::fflush(out) == 0 && !std::ferror(out);
    if (std::fclose(out) != 0 || !flushed)
        throw OutputError(fmt::format("{}: cannot write: {}", name, std::strerror(errno)));
}

}  // namespace

const Backend& codecs_backend() {
    static const Backend backend{"codecs (libpng, libjpeg, libwebp, OpenEXR)", open_codecs, write_exr_codecs,
                                 write_png_codecs};
    return backend;
}

FloatImage read_exr(const std::filesystem::path& file) {
    FloatImage image;
    try {
        Imf::InputFile in(file.string().c_str());
        const Imath::Box2i window = in.header().dataWindow();
        image.width = window.max.x - window.min.x + 1;
        image.height = window.max.y - window.min.y + 1;
        for (auto c = in.header().channels().begin(); c != in.header().channels().end(); ++c)
            image.channels.emplace_back(c.name());
        const std::size_t n = image.channels.size();
        image.values.assign(std::size_t(image.width) * std::size_t(image.height) * n, 0.0f);
        Imf::FrameBuffer frame;
        const std::size_t x_stride = n * sizeof(float), y_stride = x_stride * std::size_t(image.width);
        // OpenEXR addresses a slice by the data window's coordinates: the base is offset so that
        // its (min.x, min.y) pixel lands on values[0].
        char* base = reinterpret_cast<char*>(image.values.data()) - std::ptrdiff_t(window.min.x) * std::ptrdiff_t(x_stride) -
                     std::ptrdiff_t(window.min.y) * std::ptrdiff_t(y_stride);
        for (std::size_t c = 0; c < n; ++c)
            frame.insert(image.channels[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float), x_stride, y_stride));
        in.setFrameBuffer(frame);
        in.readPixels(window.min.y, window.max.y);
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: cannot read the image: {}", file.string(), e.what()));
    }
    return image;
}

}  // namespace hemirad::image
