// The image comparison that leaves got.exr, reference.exr and difference.exr behind when images
// differ (image_artifacts.h), and nothing when they are the same.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <optional>
#include <string>

#include "cli_support.h"
#include "image_artifacts.h"

using namespace hemirad::test;

namespace {

// Sets an environment variable for a scope, restoring what it was.
class ScopedEnvironment {
public:
    ScopedEnvironment(const char* name, const std::string& value) : name_(name) {
        if (const char* old = std::getenv(name)) old_ = old;
        setenv(name, value.c_str(), 1);
    }
    ~ScopedEnvironment() {
        if (old_)
            setenv(name_, old_->c_str(), 1);
        else
            unsetenv(name_);
    }

private:
    const char* name_;
    std::optional<std::string> old_;
};

ImageData ramp(int width, int height, int channels) {
    ImageData image;
    image.width = width;
    image.height = height;
    image.channels = channels;
    for (int p = 0; p < width * height; ++p)
        for (int c = 0; c < channels; ++c) image.pixels.push_back(c == 3 ? 1.0f : 0.25f * float(p % 7) + 0.5f * float(c));
    return image;
}

}  // namespace

TEST_CASE("image comparison: a mismatch leaves got, reference and difference images named in the message, a match nothing",
          "[images]") {
    const TempDir dir;
    const ScopedEnvironment artifacts("HEMIRAD_TEST_ARTIFACTS", (dir / "artifacts").string());
    const fs::path folder = artifact_dir();
    CHECK(folder.parent_path() == dir / "artifacts");
    CHECK(folder.filename().string().find("image_comparison") == 0);  // named after the test, spaces and ':' as '_'

    const ImageData want = ramp(8, 6, 4);  // RGBA, as a PNG reads back: alpha is not compared
    SECTION("the same images: same, no message, no files") {
        const ImageComparison c = compare_images(want, want);
        CHECK(c.same);
        CHECK(c.differing == 0);
        CHECK(c.message.empty());
        CHECK(c.files.empty());
        CHECK_FALSE(fs::exists(folder));
    }
    SECTION("within the tolerance: the same") {
        ImageData got = want;
        got.pixels[5] += 0.01f;
        const ImageComparison c = compare_images(got, want, 0.02);
        CHECK(c.same);
        CHECK_FALSE(fs::exists(folder));
    }
    SECTION("two pixels off: the three images, the difference exact") {
        ImageData got = want;
        got.pixels[(2 * 8 + 3) * 4 + 1] += 0.5f;  // pixel (3, 2), green
        got.pixels[(5 * 8 + 7) * 4 + 0] -= 2.0f;  // pixel (7, 5), red
        const ImageComparison c = compare_images(got, want);
        CHECK_FALSE(c.same);
        CHECK(c.differing == 2);
        CHECK(c.worst == Approx(2.0));
        REQUIRE(c.files.size() == 3);
        CHECK(c.files[0] == folder / "got.exr");
        CHECK(c.files[1] == folder / "reference.exr");
        CHECK(c.files[2] == folder / "difference.exr");
        for (const fs::path& f : c.files) {
            CHECK(fs::is_regular_file(f));
            CHECK(c.message.find(f.string()) != std::string::npos);
        }
        CHECK(c.message.find("2 of 48 pixels differ") != std::string::npos);
        const ImageData difference = read_image(folder / "difference.exr");
        REQUIRE(difference.width == 8);
        REQUIRE(difference.height == 6);
        REQUIRE(difference.channels >= 3);
        for (int p = 0; p < 48; ++p)
            for (int c3 = 0; c3 < 3; ++c3) {
                const float d = difference.pixels[std::size_t(p * difference.channels + c3)];
                const float expected = p == 2 * 8 + 3 && c3 == 1 ? 0.5f : p == 5 * 8 + 7 && c3 == 0 ? 2.0f : 0.0f;
                CAPTURE(p, c3);
                CHECK(d == Approx(expected).margin(1e-3));  // half float
            }
        const ImageData back = read_image(folder / "reference.exr");
        CHECK(back.width == 8);
        CHECK(back.pixels[std::size_t(back.channels) * 10 + 2] == Approx(want.pixels[4 * 10 + 2]).margin(1e-3));
    }
    SECTION("another size: different, and the images written") {
        const ImageComparison c = compare_images(ramp(8, 5, 3), want);
        CHECK_FALSE(c.same);
        CHECK(c.message.find("differ in size: got 8x5, reference 8x6") != std::string::npos);
        REQUIRE(c.files.size() == 3);
        for (const fs::path& f : c.files) CHECK(fs::is_regular_file(f));
        CHECK(read_image(folder / "got.exr").height == 5);
        CHECK(read_image(folder / "difference.exr").height == 5);
    }
}
