// What both image back-ends share (see image.h).
#include "image/image.h"

#include <cstring>

namespace hemirad::image {

std::optional<Format> format_of(const unsigned char* bytes, std::size_t size) {
    static const unsigned char kPng[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    static const unsigned char kJpeg[] = {0xff, 0xd8, 0xff};
    if (size >= sizeof kPng && std::memcmp(bytes, kPng, sizeof kPng) == 0) return Format::png;
    if (size >= sizeof kJpeg && std::memcmp(bytes, kJpeg, sizeof kJpeg) == 0) return Format::jpeg;
    if (size >= 12 && std::memcmp(bytes, "RIFF", 4) == 0 && std::memcmp(bytes + 8, "WEBP", 4) == 0)
        return Format::webp;
    return std::nullopt;
}

const char* extension(Format format) {
    switch (format) {
        case Format::png: return "png";
        case Format::jpeg: return "jpg";
        case Format::webp: return "webp";
    }
    return "";
}

int FloatImage::channel(const std::string& name) const {
    for (std::size_t c = 0; c < channels.size(); ++c)
        if (channels[c] == name) return int(c);
    return -1;
}

}  // namespace hemirad::image
