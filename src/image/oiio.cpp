// The OpenImageIO image back-end (see image.h): PNG and JPEG textures decoded from memory, the EXR
// and PNG outputs written. WebP goes to libwebp (open_webp).
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <fmt/core.h>

#include <cctype>

#include "core/error.h"
#include "image/image.h"

namespace hemirad::image {
namespace {

class OiioDecoder final : public Decoder {
public:
    explicit OiioDecoder(const unsigned char* bytes, std::size_t size) : memory_(bytes, size) {}

    // OpenImageIO picks a reader by the file name's extension, and reading from memory there is no
    // file to probe: the format told by the bytes names it. False with error_ set.
    bool start(Format format) {
        const std::string name = std::string("image.") + extension(format);
        OIIO::ImageSpec config;
        void* proxy = &memory_;
        config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy);
        config.attribute("oiio:UnassociatedAlpha", 1);  // the file's colours, not multiplied by alpha
        in_ = OIIO::ImageInput::create(name, false, &config);
        if (!in_) return fail(OIIO::geterror());
        if (!in_->open(name, oiio_spec_, config)) return fail(in_->geterror());
        if (oiio_spec_.depth > 1) return fail(fmt::format("a volume image ({} deep)", oiio_spec_.depth));
        const std::size_t base = oiio_spec_.format.basetype;
        spec_.width = oiio_spec_.width;
        spec_.height = oiio_spec_.height;
        spec_.channels = oiio_spec_.nchannels;
        spec_.bits = base == OIIO::TypeDesc::UINT8 || base == OIIO::TypeDesc::INT8     ? 8
                     : base == OIIO::TypeDesc::UINT16 || base == OIIO::TypeDesc::INT16 ? 16
                                                                                        : 32;
        return true;
    }

    bool read_rows(int y0, int y1, int channels, void* out) override {
        const OIIO::TypeDesc type = spec_.bits == 8    ? OIIO::TypeDesc::UINT8
                                    : spec_.bits == 16 ? OIIO::TypeDesc::UINT16
                                                       : OIIO::TypeDesc::FLOAT;
        if (in_->read_scanlines(0, 0, oiio_spec_.y + y0, oiio_spec_.y + y1, 0, 0, channels, type, out)) return true;
        return fail(in_->geterror());
    }

private:
    // OpenImageIO's first line (the first thing that went wrong; what follows restates it),
    // without the made-up file name it was given or trailing blanks: one line (image.h).
    bool fail(std::string message) {
        message = message.substr(0, message.find('\n'));
        for (const char* ext : {"png", "jpg", "webp"})
            for (const std::string& name : {fmt::format(" (\"image.{}\")", ext), fmt::format("\"image.{}\"", ext)})
                for (std::size_t at; (at = message.find(name)) != std::string::npos;) message.erase(at, name.size());
        while (!message.empty() && std::isspace(static_cast<unsigned char>(message.back()))) message.pop_back();
        error_ = std::move(message);
        return false;
    }

    OIIO::Filesystem::IOMemReader memory_;
    std::unique_ptr<OIIO::ImageInput> in_;
    OIIO::ImageSpec oiio_spec_;
};

std::unique_ptr<Decoder> open_oiio(Format format, const unsigned char* bytes, std::size_t size, std::string& problem) {
    if (format == Format::webp) return open_webp(bytes, size, problem);
    auto decoder = std::make_unique<OiioDecoder>(bytes, size);
    if (decoder->start(format)) return decoder;
    problem = decoder->error();
    return nullptr;
}

// Opens `file` for writing in `format` (named, so a temporary file name's extension does not
// matter), writes `pixels` (3 channels of `pixel_type`), closes; throws with OIIO's message.
void write_image(const std::filesystem::path& file, const char* format, const OIIO::ImageSpec& spec,
                 OIIO::TypeDesc pixel_type, const void* pixels) {
    const std::string name = file.string();
    auto out = OIIO::ImageOutput::create(format);
    if (!out) throw InternalError(fmt::format("{}: cannot write {}: {}", name, format, OIIO::geterror()));
    const bool ok = out->open(name, spec) && out->write_image(pixel_type, pixels) && out->close();
    if (!ok) throw OutputError(fmt::format("{}: cannot write: {}", name, out->geterror()));
}

void write_exr_oiio(const std::filesystem::path& file, int width, int height, const float* rgb) {
    OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::FLOAT);
    spec.attribute("compression", "zip");
    write_image(file, "openexr", spec, OIIO::TypeDesc::FLOAT, rgb);
}

void write_png_oiio(const std::filesystem::path& file, int width, int height, const unsigned char* rgb) {
    const OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::UINT8);
    write_image(file, "png", spec, OIIO::TypeDesc::UINT8, rgb);
}

}  // namespace

const Backend& oiio_backend() {
    static const Backend backend{"OpenImageIO " OIIO_VERSION_STRING " (WebP through libwebp)", open_oiio, write_exr_oiio, write_png_oiio};
    return backend;
}

}  // namespace hemirad::image
