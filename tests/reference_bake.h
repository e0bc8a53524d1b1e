// A bake of a bundled scene compared with its independent path-traced reference
// (bench/make_references.sh, bench/reference/<name>): shared by the tests that hold a bake's
// render to one.
#pragma once

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bake/bake.h"
#include "bench/image.h"

namespace hemirad::test {

struct Against {
    bench::PixelErrors errors;
    nlohmann::json report;
};

// A bake of bundled scene `name` (scenes/<name>.gltf) at the defaults (what `adjust` changes
// aside), at the width of its reference in bench/reference/<name>: its render's errors against
// the reference, and its report.
template <class Adjust>
Against bake_against_reference(const std::string& name, Adjust adjust) {
    const std::filesystem::path root(HEMIRAD_SOURCE_DIR);
    const bench::ImageReference reference = bench::load_image_reference((root / "bench/reference" / name).string());
    const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("hemirad-test-reference-" + name);
    std::filesystem::remove_all(dir);
    bake::Options o;
    o.scene = (root / "scenes" / (name + ".gltf")).string();
    o.output = dir.string();
    o.image_width = reference.width;
    o.quiet = true;
    o.no_checkpoint = true;
    adjust(o);
    bake::run(o);
    int width = 0, height = 0;
    const std::vector<float> rgb = bench::read_rgb(dir / "render.exr", width, height);
    REQUIRE(width == reference.width);
    REQUIRE(height == reference.height);
    std::ifstream in(dir / "report.json");
    Against out{bench::compare_pixels(rgb, width, height, reference), nlohmann::json::parse(in)};
    std::filesystem::remove_all(dir);
    return out;
}

}  // namespace hemirad::test
