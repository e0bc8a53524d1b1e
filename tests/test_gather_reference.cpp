// The default bake's render against an independent path-traced reference on a curved,
// double-sided emitter (bench/reference/double_sided_cylinder, bench/make_references.sh): where
// the final gather's points fell behind the cylinder's curved surface they gathered its inside,
// and the walls came out 63% too bright.
#include <catch2/catch.hpp>

#include <filesystem>

#include "bake/bake.h"
#include "bench/image.h"
#include "image/image.h"

using namespace hemirad;

TEST_CASE("final gather: the double-sided cylinder lamp's default bake against its path-traced reference",
          "[gather][bake]") {
    const std::filesystem::path root(HEMIRAD_SOURCE_DIR);
    const bench::ImageReference reference =
        bench::load_image_reference((root / "bench/reference/double_sided_cylinder").string());
    const std::filesystem::path dir = std::filesystem::temp_directory_path() / "hemirad-test-gather-reference";
    std::filesystem::remove_all(dir);
    bake::Options o;
    o.scene = (root / "scenes/double_sided_cylinder.gltf").string();
    o.output = dir.string();
    o.image_width = reference.width;
    o.quiet = true;
    o.no_checkpoint = true;
    bake::run(o);
    const image::FloatImage exr = image::read_exr(dir / "render.exr");
    REQUIRE(exr.width == reference.width);
    REQUIRE(exr.height == reference.height);
    std::vector<float> rgb(std::size_t(exr.width) * exr.height * 3);
    const std::size_t n = exr.channels.size();
    const int r = exr.channel("R"), g = exr.channel("G"), b = exr.channel("B");
    for (std::size_t p = 0; p < std::size_t(exr.width) * exr.height; ++p) {
        rgb[3 * p + 0] = exr.values[p * n + std::size_t(r)];
        rgb[3 * p + 1] = exr.values[p * n + std::size_t(g)];
        rgb[3 * p + 2] = exr.values[p * n + std::size_t(b)];
    }
    const bench::PixelErrors e = bench::compare_pixels(rgb, exr.width, exr.height, reference);
    CAPTURE(e.rms, e.mean, e.worst_tile_light, e.noise_rms);
    // Measured 0.49% (1.33% without the gather; 63% with the points behind the curve).
    CHECK(e.rms < 0.01);
    CHECK(std::abs(e.mean) < 0.005);
    std::filesystem::remove_all(dir);
}
