// The default bake's render against an independent path-traced reference on a curved,
// double-sided emitter (bench/reference/double_sided_cylinder, bench/make_references.sh): where
// the final gather's points fell behind the cylinder's curved surface they gathered its inside,
// and the walls came out 63% too bright.
#include <catch2/catch.hpp>

#include <filesystem>

#include "bake/bake.h"
#include "bench/image.h"

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
    int width = 0, height = 0;
    const std::vector<float> rgb = bench::read_rgb(dir / "render.exr", width, height);
    REQUIRE(width == reference.width);
    REQUIRE(height == reference.height);
    const bench::PixelErrors e = bench::compare_pixels(rgb, width, height, reference);
    CAPTURE(e.rms, e.mean, e.worst_tile_light, e.noise_rms);
    // Measured 0.49% (1.33% without the gather; 63% with the points behind the curve).
    CHECK(e.rms < 0.01);
    CHECK(std::abs(e.mean) < 0.005);
    std::filesystem::remove_all(dir);
}
