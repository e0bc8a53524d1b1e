// Image comparisons that leave got, reference and difference images (image_artifacts.h).
#include "image_artifacts.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <sstream>

#include "output/output.h"

namespace hemirad::test {
namespace {

std::vector<float> rgb_of(const ImageData& image) {
    std::vector<float> rgb(std::size_t(image.width) * std::size_t(image.height) * 3, 0.0f);
    for (std::size_t p = 0; p < rgb.size() / 3; ++p)
        for (int c = 0; c < 3 && c < image.channels; ++c) rgb[3 * p + std::size_t(c)] = image.pixels[p * std::size_t(image.channels) + std::size_t(c)];
    return rgb;
}

output::Image image_of(std::vector<float> rgb, int width, int height) {
    output::Image image;
    image.width = width;
    image.height = height;
    image.rgb = std::move(rgb);
    return image;
}

// The three files for images of sizes (gw, gh) and (rw, rh); the difference over the part they share.
std::vector<fs::path> write_three(const std::vector<float>& got, int gw, int gh, const std::vector<float>& ref, int rw,
                                  int rh) {
    const fs::path dir = artifact_dir();
    fs::create_directories(dir);
    const int w = std::min(gw, rw), h = std::min(gh, rh);
    std::vector<float> difference(std::size_t(w) * std::size_t(h) * 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c)
                difference[(std::size_t(y) * w + x) * 3 + c] =
                    std::abs(got[(std::size_t(y) * gw + x) * 3 + c] - ref[(std::size_t(y) * rw + x) * 3 + c]);
    const std::vector<fs::path> files = {dir / "got.exr", dir / "reference.exr", dir / "difference.exr"};
    output::write_exr(image_of(got, gw, gh), files[0]);
    output::write_exr(image_of(ref, rw, rh), files[1]);
    output::write_exr(image_of(std::move(difference), w, h), files[2]);
    return files;
}

std::string naming(const std::vector<fs::path>& files) {
    std::string out = "images written: ";
    for (std::size_t i = 0; i < files.size(); ++i) out += (i ? ", " : "") + files[i].string();
    return out;
}

}  // namespace

fs::path artifact_dir() {
    const char* env = std::getenv("HEMIRAD_TEST_ARTIFACTS");
    const fs::path base = env && *env ? fs::path(env) : fs::path(HEMIRAD_TEST_BINARY_DIR) / "artifacts";
    std::string name = Catch::getResultCapture().getCurrentTestName();
    for (char& c : name)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_')) c = '_';
    if (name.size() > 120) name.resize(120);
    if (name.empty() || name == "." || name == "..") name = "unnamed";
    return base / name;
}

ImageComparison compare_images(const ImageData& got, const ImageData& reference, double tolerance) {
    ImageComparison out;
    const std::vector<float> a = rgb_of(got), b = rgb_of(reference);
    const bool same_size = got.width == reference.width && got.height == reference.height;
    if (same_size) {
        for (std::size_t p = 0; p < a.size() / 3; ++p) {
            bool off = false;
            for (int c = 0; c < 3; ++c) {
                const double d = std::abs(double(a[3 * p + c]) - double(b[3 * p + c]));
                // A NaN on either side differs.
                if (!(d <= tolerance)) off = true;
                out.worst = std::isnan(d) ? INFINITY : std::max(out.worst, d);
            }
            if (off) ++out.differing;
        }
    }
    out.same = same_size && out.differing == 0;
    if (out.same) return out;
    out.files = write_three(a, got.width, got.height, b, reference.width, reference.height);
    std::ostringstream m;
    if (!same_size)
        m << "the images differ in size: got " << got.width << "x" << got.height << ", reference " << reference.width
          << "x" << reference.height;
    else
        m << out.differing << " of " << a.size() / 3 << " pixels differ by more than " << tolerance << " (worst "
          << out.worst << ")";
    m << "; " << naming(out.files);
    out.message = m.str();
    return out;
}

std::string write_image_artifacts(const std::vector<float>& got_rgb, const std::vector<float>& reference_rgb,
                                  int width, int height) {
    return naming(write_three(got_rgb, width, height, reference_rgb, width, height));
}

}  // namespace hemirad::test
