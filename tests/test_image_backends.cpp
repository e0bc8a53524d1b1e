// The two image back-ends (src/image/image.h) against each other and against the pixels a test
// encoded itself with the format libraries: every PNG colour type and depth, JPEGs of each kind,
// WebP with alpha, broken files, and the EXR and PNG writers read back by the other back-end.
#include <catch2/catch.hpp>

#include <png.h>
#include <jpeglib.h>
#include <webp/encode.h>

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "image/image.h"
#include "scene/image_mean.h"

namespace fs = std::filesystem;
using hemirad::image::Decoder;
using hemirad::image::Format;

namespace {

using Bytes = std::vector<unsigned char>;

// --- encoders, written here with the libraries themselves --------------------------------------

void png_append(png_structp png, png_bytep data, png_size_t n) {
    auto* out = static_cast<Bytes*>(png_get_io_ptr(png));
    out->insert(out->end(), data, data + n);
}
void png_no_flush(png_structp) {}

struct PngCase {
    std::string name;
    int colour_type;  // PNG_COLOR_TYPE_*
    int depth;
    bool interlaced = false;
    bool transparent_key = false;  // a tRNS chunk (palette alpha, or one grey/RGB key colour)
    bool gamma = false;            // a gAMA chunk (neither back-end applies it)
};

int png_channels(int colour_type) {
    switch (colour_type) {
        case PNG_COLOR_TYPE_GRAY: return 1;
        case PNG_COLOR_TYPE_GRAY_ALPHA: return 2;
        case PNG_COLOR_TYPE_RGB: return 3;
        case PNG_COLOR_TYPE_RGB_ALPHA: return 4;
        default: return 1;  // palette: one index
    }
}

// A w × h PNG of seeded random samples; `samples` gets them as stored (indices for a palette,
// big-endian pairs for 16 bits, packed for depths below 8 before packing: one sample a byte).
Bytes encode_png(const PngCase& c, int w, int h, std::uint32_t seed) {
    std::mt19937 rng(seed);
    Bytes out;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png_create_info_struct(png);
    REQUIRE(png);
    REQUIRE(info);
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        FAIL("libpng could not write the test image");
    }
    png_set_write_fn(png, &out, png_append, png_no_flush);
    png_set_IHDR(png, info, png_uint_32(w), png_uint_32(h), c.depth, c.colour_type,
                 c.interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    const int levels = 1 << c.depth;
    if (c.colour_type == PNG_COLOR_TYPE_PALETTE) {
        std::vector<png_color> palette(static_cast<std::size_t>(levels));
        for (auto& p : palette) p = {png_byte(rng()), png_byte(rng()), png_byte(rng())};
        png_set_PLTE(png, info, palette.data(), levels);
        if (c.transparent_key) {
            std::vector<png_byte> alpha(static_cast<std::size_t>(levels));
            for (auto& a : alpha) a = png_byte(rng());
            png_set_tRNS(png, info, alpha.data(), levels, nullptr);
        }
    } else if (c.transparent_key) {
        png_color_16 key{};
        key.gray = png_uint_16(1);
        key.red = 1, key.green = 2, key.blue = 3;
        png_set_tRNS(png, info, nullptr, 0, &key);
    }
    if (c.gamma) png_set_gAMA(png, info, 1.0);
    png_write_info(png, info);
    const int channels = png_channels(c.colour_type);
    const std::size_t row_bytes = (std::size_t(w) * std::size_t(channels) * std::size_t(c.depth) + 7) / 8;
    std::vector<Bytes> rows(static_cast<std::size_t>(h), Bytes(row_bytes));
    for (int y = 0; y < h; ++y)
        for (auto& b : rows[std::size_t(y)]) b = png_byte(rng());
    // A few pixels equal to the tRNS key colour, so that some come out transparent.
    if (c.transparent_key && c.colour_type != PNG_COLOR_TYPE_PALETTE && c.depth == 8) {
        const Bytes key = c.colour_type == PNG_COLOR_TYPE_GRAY ? Bytes{1} : Bytes{1, 2, 3};
        for (int y = 0; y < h; y += 2) std::memcpy(rows[std::size_t(y)].data(), key.data(), key.size());
    }
    std::vector<png_bytep> pointers;
    for (auto& r : rows) pointers.push_back(r.data());
    png_write_image(png, pointers.data());
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    return out;
}

// A w × h JPEG of smooth seeded colour; `components` 1 (grey) or 3, optional progressive and
// 4:4:4 sampling (4:2:0 otherwise).
Bytes encode_jpeg(int w, int h, int components, bool progressive, bool full_chroma, std::uint32_t seed) {
    std::mt19937 rng(seed);
    jpeg_compress_struct info{};
    jpeg_error_mgr errors{};
    info.err = jpeg_std_error(&errors);
    jpeg_create_compress(&info);
    unsigned char* buffer = nullptr;
    unsigned long size = 0;
    jpeg_mem_dest(&info, &buffer, &size);
    info.image_width = JDIMENSION(w);
    info.image_height = JDIMENSION(h);
    info.input_components = components;
    info.in_color_space = components == 1 ? JCS_GRAYSCALE : JCS_RGB;
    jpeg_set_defaults(&info);
    jpeg_set_quality(&info, 85, TRUE);
    if (progressive) jpeg_simple_progression(&info);
    if (full_chroma && components == 3) info.comp_info[0].h_samp_factor = info.comp_info[0].v_samp_factor = 1;
    jpeg_start_compress(&info, TRUE);
    Bytes row(std::size_t(w) * std::size_t(components));
    const int base = int(rng() % 128);
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x)
            for (int k = 0; k < components; ++k)
                row[std::size_t(x * components + k)] = static_cast<unsigned char>((base + x * (k + 1) + y * 3 + int(rng() % 16)) & 255);
        JSAMPROW rows[1] = {row.data()};
        jpeg_write_scanlines(&info, rows, 1);
    }
    jpeg_finish_compress(&info);
    Bytes out(buffer, buffer + size);
    jpeg_destroy_compress(&info);
    std::free(buffer);
    return out;
}

// Every value an image decodes to, read in bands of 3 rows; empty when it does not open, and
// `problem` says why (open's or read_rows's reason).
struct Decoded {
    hemirad::image::Spec spec;
    Bytes values;
    bool opened = false, read = false;
    std::string problem;
};
Decoded decode(const hemirad::image::Backend& backend, const Bytes& bytes) {
    Decoded d;
    const auto format = hemirad::image::format_of(bytes.data(), bytes.size());
    REQUIRE(format);
    std::unique_ptr<Decoder> in = backend.open(*format, bytes.data(), bytes.size(), d.problem);
    if (!in) return d;
    d.opened = true;
    d.spec = in->spec();
    const std::size_t row = std::size_t(d.spec.width) * std::size_t(d.spec.channels) * std::size_t(d.spec.bits / 8);
    d.values.resize(row * std::size_t(d.spec.height));
    for (int y = 0; y < d.spec.height; y += 3) {
        const int end = std::min(y + 3, d.spec.height);
        if (!in->read_rows(y, end, d.spec.channels, d.values.data() + row * std::size_t(y))) {
            d.problem = in->error();
            return d;
        }
    }
    d.read = true;
    return d;
}

void check_same(const Decoded& a, const Decoded& b) {
    REQUIRE(a.opened == b.opened);
    REQUIRE(a.read == b.read);
    CHECK(a.spec.width == b.spec.width);
    CHECK(a.spec.height == b.spec.height);
    CHECK(a.spec.channels == b.spec.channels);
    CHECK(a.spec.bits == b.spec.bits);
    REQUIRE(a.values.size() == b.values.size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < a.values.size(); ++i) differ += a.values[i] != b.values[i] ? 1 : 0;
    CHECK(differ == 0);
}

const hemirad::image::Backend& oiio = hemirad::image::oiio_backend();
const hemirad::image::Backend& codecs = hemirad::image::codecs_backend();

}  // namespace

TEST_CASE("image back-ends: PNGs of every colour type and depth decode to the same values in both, "
          "and those they were written with",
          "[image][backends]") {
    const std::vector<PngCase> cases = {
        {"grey 1 bit", PNG_COLOR_TYPE_GRAY, 1},        {"grey 2 bits", PNG_COLOR_TYPE_GRAY, 2},
        {"grey 4 bits", PNG_COLOR_TYPE_GRAY, 4},       {"grey 8 bits", PNG_COLOR_TYPE_GRAY, 8},
        {"grey 16 bits", PNG_COLOR_TYPE_GRAY, 16},     {"grey + alpha 8", PNG_COLOR_TYPE_GRAY_ALPHA, 8},
        {"grey + alpha 16", PNG_COLOR_TYPE_GRAY_ALPHA, 16}, {"RGB 8", PNG_COLOR_TYPE_RGB, 8},
        {"RGB 16", PNG_COLOR_TYPE_RGB, 16},            {"RGBA 8", PNG_COLOR_TYPE_RGB_ALPHA, 8},
        {"RGBA 16", PNG_COLOR_TYPE_RGB_ALPHA, 16},     {"palette 2 bits", PNG_COLOR_TYPE_PALETTE, 2},
        {"palette 8 bits", PNG_COLOR_TYPE_PALETTE, 8}, {"palette + tRNS", PNG_COLOR_TYPE_PALETTE, 8, false, true},
        {"grey + tRNS key", PNG_COLOR_TYPE_GRAY, 8, false, true},
        {"RGB + tRNS key", PNG_COLOR_TYPE_RGB, 8, false, true},
        {"RGBA 8 interlaced", PNG_COLOR_TYPE_RGB_ALPHA, 8, true},
        {"grey 16 interlaced", PNG_COLOR_TYPE_GRAY, 16, true},
        {"RGB 8 with gAMA 1.0", PNG_COLOR_TYPE_RGB, 8, false, false, true},
    };
    std::uint32_t seed = 7;
    for (const PngCase& c : cases) {
        INFO(c.name);
        const int w = 37, h = 23;  // odd sizes: partial bytes at depths below 8, partial bands
        const Bytes png = encode_png(c, w, h, seed++);
        const Decoded a = decode(oiio, png), b = decode(codecs, png);
        INFO("OpenImageIO: " << a.problem << " | codecs: " << b.problem);
        REQUIRE(a.read);
        check_same(a, b);
        const bool alpha_added = c.transparent_key;
        const int stored = png_channels(c.colour_type);
        const int expected = c.colour_type == PNG_COLOR_TYPE_PALETTE ? 3 + (alpha_added ? 1 : 0)
                                                                      : stored + (alpha_added ? 1 : 0);
        CHECK(b.spec.channels == expected);
        CHECK(b.spec.bits == (c.depth == 16 ? 16 : 8));
        // Where nothing is expanded, the values are the stored samples themselves.
        if (c.colour_type != PNG_COLOR_TYPE_PALETTE && c.depth >= 8 && !alpha_added && !c.interlaced) {
            // Re-encode the same seed's rows to know them: the encoder's rng runs in the same order.
            std::mt19937 rng(seed - 1);
            const std::size_t row_bytes = std::size_t(w) * std::size_t(stored) * std::size_t(c.depth / 8);
            std::size_t differ = 0;
            for (int y = 0; y < h; ++y)
                for (std::size_t i = 0; i < row_bytes; ++i) {
                    const unsigned char written = static_cast<unsigned char>(rng());
                    // 16-bit samples are stored big-endian and decoded to the machine's order.
                    std::size_t at = std::size_t(y) * row_bytes + i;
                    if (c.depth == 16) at ^= 1;
                    differ += b.values[at] != written ? 1 : 0;
                }
            CHECK(differ == 0);
        }
    }
}

TEST_CASE("image back-ends: JPEGs (grey, 4:2:0, 4:4:4, progressive) decode to the same values in both",
          "[image][backends]") {
    struct Case {
        const char* name;
        int components;
        bool progressive, full_chroma;
    };
    std::uint32_t seed = 100;
    for (const Case c : {Case{"grey", 1, false, false}, Case{"RGB 4:2:0", 3, false, false},
                         Case{"RGB 4:4:4", 3, false, true}, Case{"RGB progressive", 3, true, false}}) {
        INFO(c.name);
        const Bytes jpeg = encode_jpeg(45, 31, c.components, c.progressive, c.full_chroma, seed++);
        const Decoded a = decode(oiio, jpeg), b = decode(codecs, jpeg);
        INFO("OpenImageIO: " << a.problem << " | codecs: " << b.problem);
        REQUIRE(a.read);
        check_same(a, b);
        CHECK(b.spec.channels == c.components);
        CHECK(b.spec.width == 45);
        CHECK(b.spec.height == 31);
    }
}

TEST_CASE("image back-ends: a WebP with alpha decodes to the colours and alpha it was written with, "
          "not multiplied",
          "[image][backends]") {
    const int w = 19, h = 11;
    std::mt19937 rng(3);
    Bytes rgba(std::size_t(w) * h * 4);
    for (auto& v : rgba) v = static_cast<unsigned char>(rng());
    uint8_t* encoded = nullptr;
    const std::size_t size = WebPEncodeLosslessRGBA(rgba.data(), w, h, w * 4, &encoded);
    REQUIRE(size > 0);
    // Lossless WebP may change the colour of fully transparent pixels ("exact" off): compare the rest.
    const Bytes webp(encoded, encoded + size);
    WebPFree(encoded);
    for (const auto* backend : {&oiio, &codecs}) {
        INFO(backend->name);
        const Decoded d = decode(*backend, webp);
        REQUIRE(d.read);
        CHECK(d.spec.channels == 4);
        std::size_t differ = 0;
        for (std::size_t p = 0; p < rgba.size(); p += 4)
            if (rgba[p + 3] != 0)
                differ += std::memcmp(&rgba[p], &d.values[p], 4) != 0 ? 1 : 0;
        CHECK(differ == 0);
    }
}

TEST_CASE("image back-ends: broken files fail alike in both, and a cut JPEG decodes alike",
          "[image][backends]") {
    const Bytes png = encode_png({"RGB 8", PNG_COLOR_TYPE_RGB, 8}, 64, 64, 11);
    SECTION("a PNG cut in its pixel data opens and then fails part way") {
        const Bytes cut(png.begin(), png.begin() + std::ptrdiff_t(png.size() / 2));
        const Decoded a = decode(oiio, cut), b = decode(codecs, cut);
        CHECK(a.opened);
        CHECK(b.opened);
        CHECK_FALSE(a.read);
        CHECK_FALSE(b.read);
        CHECK_FALSE(b.problem.empty());
    }
    SECTION("a PNG signature followed by noise does not open") {
        Bytes noise(png.begin(), png.begin() + 8);
        for (int i = 0; i < 200; ++i) noise.push_back(static_cast<unsigned char>(i * 37));
        const Decoded a = decode(oiio, noise), b = decode(codecs, noise);
        CHECK_FALSE(a.opened);
        CHECK_FALSE(b.opened);
        CHECK_FALSE(b.problem.empty());
    }
    SECTION("a JPEG cut in half decodes its first half, the rest filled alike") {
        const Bytes jpeg = encode_jpeg(64, 64, 3, false, false, 5);
        const Bytes cut(jpeg.begin(), jpeg.begin() + std::ptrdiff_t(jpeg.size() / 2));
        check_same(decode(oiio, cut), decode(codecs, cut));
    }
    SECTION("a JPEG header alone does not open") {
        const Bytes jpeg = encode_jpeg(16, 16, 3, false, false, 5);
        const Bytes head(jpeg.begin(), jpeg.begin() + 20);
        const Decoded a = decode(oiio, head), b = decode(codecs, head);
        CHECK(a.read == b.read);
        CHECK_FALSE(b.read);
    }
    SECTION("the texture means of one broken PNG are the same problem's") {
        const Bytes cut(png.begin(), png.begin() + std::ptrdiff_t(png.size() / 2));
        const hemirad::scene::ImageMean mean = hemirad::scene::decode_image_mean(cut.data(), cut.size());
        CHECK_FALSE(mean.ok);
        CHECK_THAT(mean.problem, Catch::StartsWith("the image does not decode past row"));
    }
}

// A copy of `file` damaged one of four ways, its signature kept (so the format is still told):
// cut short, one byte changed, a run of bytes overwritten with noise, or noise inserted.
Bytes damage(const Bytes& file, std::mt19937& rng) {
    Bytes out = file;
    const std::size_t keep = 8;  // the signature
    const auto at = [&](std::size_t size) { return keep + rng() % (size - keep); };
    switch (rng() % 4) {
        case 0: out.resize(at(out.size())); break;
        case 1: out[at(out.size())] ^= static_cast<unsigned char>(1 + rng() % 255); break;
        case 2: {
            const std::size_t from = at(out.size()), n = std::min<std::size_t>(1 + rng() % 64, out.size() - from);
            for (std::size_t i = 0; i < n; ++i) out[from + i] = static_cast<unsigned char>(rng());
            break;
        }
        default: {
            Bytes noise(1 + rng() % 32);
            for (auto& b : noise) b = static_cast<unsigned char>(rng());
            out.insert(out.begin() + std::ptrdiff_t(at(out.size())), noise.begin(), noise.end());
            break;
        }
    }
    return out;
}

TEST_CASE("image back-ends: damaged PNGs and JPEGs open, fail or decode alike in both, for the same reason",
          "[image][backends]") {
    const std::vector<Bytes> files = {
        encode_png({"RGB 8", PNG_COLOR_TYPE_RGB, 8}, 24, 20, 1),
        encode_png({"RGBA 16", PNG_COLOR_TYPE_RGB_ALPHA, 16}, 17, 9, 2),
        encode_png({"palette 4 + tRNS", PNG_COLOR_TYPE_PALETTE, 4, false, true}, 21, 13, 3),
        encode_png({"grey 8 interlaced", PNG_COLOR_TYPE_GRAY, 8, true}, 19, 23, 4),
        encode_jpeg(40, 24, 3, false, false, 5),
        encode_jpeg(24, 40, 3, true, true, 6),
        encode_jpeg(32, 16, 1, false, false, 7),
    };
    std::mt19937 rng(45);
    const int trials = 3000;
    int opened = 0, decoded = 0;
    for (int trial = 0; trial < trials; ++trial) {
        const Bytes& file = files[std::size_t(trial) % files.size()];
        const Bytes bad = damage(file, rng);
        INFO("trial " << trial << " (" << bad.size() << " bytes, from " << file.size() << ")");
        const Decoded a = decode(oiio, bad), b = decode(codecs, bad);
        REQUIRE(a.opened == b.opened);
        REQUIRE(a.read == b.read);
        CHECK(a.problem == b.problem);
        if (a.read) check_same(a, b);
        opened += a.opened ? 1 : 0;
        decoded += a.read ? 1 : 0;
        if (!a.read) CHECK_FALSE(b.problem.empty());
    }
    // Damage of every kind was met: files that did not open, files that failed part way, and
    // files that decoded (a changed byte in a JPEG's data, an ancillary chunk).
    CHECK(opened < trials);
    CHECK(opened - decoded > trials / 50);
    CHECK(decoded > trials / 50);
    CHECK(trials - decoded > trials / 10);  // failed, to open or part way
}

TEST_CASE("image back-ends: each one's EXR and PNG, read back by the other, hold the pixels written",
          "[image][backends]") {
    const fs::path dir = fs::temp_directory_path() / "hemirad_test_image_backends";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const int w = 29, h = 13;
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> radiance(0.0f, 1e6f);
    std::vector<float> rgb(std::size_t(w) * h * 3);
    for (auto& v : rgb) v = radiance(rng);
    Bytes bytes(rgb.size());
    for (auto& b : bytes) b = static_cast<unsigned char>(rng());

    for (const auto* writer : {&oiio, &codecs}) {
        INFO("written by " << writer->name);
        const fs::path exr = dir / "out.exr", png = dir / "out.png";
        writer->write_exr(exr, w, h, rgb.data());
        writer->write_png(png, w, h, bytes.data());

        // EXR through OpenEXR (read_exr) and through OpenImageIO.
        const hemirad::image::FloatImage back = hemirad::image::read_exr(exr);
        REQUIRE(back.width == w);
        REQUIRE(back.height == h);
        REQUIRE(back.channels.size() == 3);
        std::size_t differ = 0;
        for (std::size_t p = 0; p < std::size_t(w) * h; ++p)
            for (int c = 0; c < 3; ++c)
                differ += back.values[p * 3 + std::size_t(back.channel(std::string(1, "RGB"[c])))] != rgb[p * 3 + std::size_t(c)];
        CHECK(differ == 0);
        auto in = OIIO::ImageInput::open(exr.string());
        REQUIRE(in);
        std::vector<float> oiio_back(rgb.size());
        REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, oiio_back.data()));
        CHECK(oiio_back == rgb);

        // PNG through both decoders.
        std::ifstream file(png, std::ios::binary);
        const Bytes encoded((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
        for (const auto* reader : {&oiio, &codecs}) {
            const Decoded d = decode(*reader, encoded);
            REQUIRE(d.read);
            CHECK(d.spec.channels == 3);
            CHECK(d.values == bytes);
        }
    }
    SECTION("a write into a folder that does not exist is an OutputError naming the file") {
        for (const auto* writer : {&oiio, &codecs}) {
            INFO(writer->name);
            CHECK_THROWS_WITH(writer->write_exr(dir / "missing" / "a.exr", w, h, rgb.data()),
                              Catch::Contains((dir / "missing" / "a.exr").string()));
            CHECK_THROWS_WITH(writer->write_png(dir / "missing" / "a.png", w, h, bytes.data()),
                              Catch::Contains((dir / "missing" / "a.png").string()));
        }
    }
    fs::remove_all(dir);
}

TEST_CASE("image back-ends: the committed path-traced reference reads the same through OpenEXR and OpenImageIO",
          "[image][backends]") {
    const fs::path exr = fs::path(HEMIRAD_SOURCE_DIR) / "bench/reference/cornell_box/reference.exr";
    const hemirad::image::FloatImage a = hemirad::image::read_exr(exr);
    auto in = OIIO::ImageInput::open(exr.string());
    REQUIRE(in);
    const OIIO::ImageSpec& spec = in->spec();
    REQUIRE(a.width == spec.width);
    REQUIRE(a.height == spec.height);
    REQUIRE(int(a.channels.size()) == spec.nchannels);
    std::vector<float> b(std::size_t(spec.width) * spec.height * spec.nchannels);
    REQUIRE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, b.data()));
    for (int c = 0; c < spec.nchannels; ++c) {
        const std::string name = spec.channelnames[std::size_t(c)];
        INFO("channel " << name);
        const int k = a.channel(name);
        REQUIRE(k >= 0);
        std::size_t differ = 0;
        for (std::size_t p = 0; p < std::size_t(a.width) * a.height; ++p)
            differ += a.values[p * a.channels.size() + std::size_t(k)] != b[p * std::size_t(spec.nchannels) + std::size_t(c)];
        CHECK(differ == 0);
    }
    CHECK_THROWS_WITH(hemirad::image::read_exr(exr.parent_path() / "missing.exr"), Catch::Contains("missing.exr"));
}
