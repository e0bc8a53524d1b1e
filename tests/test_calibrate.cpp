// The machine-limit calibration (bench/calibrate.h): its kernels compute what they claim on every
// OpenCL device, checked against host models, and calibrate() returns usable rates. No timing
// assertions: machines are noisy. Every device test warns and skips without a device.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <vector>

#include "bench/calibrate.h"
#include "cl/runtime.h"

using namespace hemirad;

namespace {

// Every OpenCL device, or none after a visible warning.
std::vector<ocl::DeviceInfo> devices_or_warn() {
    const auto devices = ocl::list_devices();
    if (devices.empty()) WARN("no OpenCL device: skipped");
    return devices;
}

}  // namespace

TEST_CASE("calibrate: synthetic triangles are exact integers and about half the tests are inside", "[calibrate]") {
    const int tile = 64;
    const auto triangles = bench::fill_triangles(512, tile, 7);
    REQUIRE(triangles.size() == 512);
    CHECK(bench::fill_triangles(512, tile, 7)[100].edge[1][2] == triangles[100].edge[1][2]);  // seeded
    int not_integer = 0, too_large = 0, depth_out_of_range = 0;
    for (const bench::FillTriangle& t : triangles) {
        for (const auto& e : t.edge)
            for (float c : e) not_integer += c != std::floor(c);
        // Every evaluation stays an integer below 2^24 (so float is exact): bound it at the corners.
        for (int x : {0, tile - 1})
            for (int y : {0, tile - 1}) {
                for (const auto& e : t.edge)
                    too_large += std::fabs(e[0] * x) + std::fabs(e[1] * y) + std::fabs(e[2]) >= 16777216.0f;
                const float depth = t.depth[0] * x + t.depth[1] * y + t.depth[2];
                depth_out_of_range += depth <= 0.0f || depth >= bench::kFillFar;
            }
    }
    CHECK(not_integer == 0);
    CHECK(too_large == 0);
    CHECK(depth_out_of_range == 0);
    std::uint64_t inside = 0;
    const bench::FillImage image = bench::fill_reference(triangles, tile, tile, &inside);
    const double share = double(inside) / (double(tile) * tile * double(triangles.size()));
    CAPTURE(share);
    CHECK(share > 0.4);
    CHECK(share < 0.6);
    // Nearly every pixel is covered, and not by one triangle: the depth planes cross.
    std::vector<bool> won(triangles.size(), false);
    int uncovered = 0;
    for (std::int32_t id : image.id) {
        if (id < 0)
            ++uncovered;
        else
            won[std::size_t(id)] = true;
    }
    CHECK(uncovered < tile * tile / 100);
    CHECK(std::count(won.begin(), won.end(), true) > 10);
}

TEST_CASE("calibrate: the z-buffer kernel matches the host model pixel for pixel", "[calibrate][opencl]") {
    for (const ocl::DeviceInfo& info : devices_or_warn()) {
        ocl::Context context(info);
        // 48 x 80: strips that do not divide the tile into whole default work-groups.
        for (auto [width, height, count] : {std::tuple{64, 64, 300}, std::tuple{48, 80, 37}, std::tuple{16, 16, 1}}) {
            const auto triangles = bench::fill_triangles(std::size_t(count), std::max(width, height), 11);
            const bench::FillImage expected = bench::fill_reference(triangles, width, height);
            const auto images = bench::run_fill(context, triangles, width, height, 2);
            REQUIRE(images.size() == 2);
            for (const bench::FillImage& image : images) {
                std::size_t z_mismatch = 0, id_mismatch = 0;
                for (std::size_t p = 0; p < expected.z.size(); ++p) {
                    z_mismatch += image.z[p] != expected.z[p];
                    id_mismatch += image.id[p] != expected.id[p];
                }
                CAPTURE(info.name, width, height, count);
                CHECK(z_mismatch == 0);
                CHECK(id_mismatch == 0);
            }
        }
    }
}

TEST_CASE("calibrate: the copy kernel copies every word", "[calibrate][opencl]") {
    for (const ocl::DeviceInfo& info : devices_or_warn()) {
        ocl::Context context(info);
        for (std::size_t words : {std::size_t{1024}, std::size_t{3} << 12, std::size_t{1} << 20}) {
            std::vector<std::uint32_t> source(words);
            for (std::size_t i = 0; i < words; ++i) source[i] = static_cast<std::uint32_t>(i * 2654435761u + 1);
            CAPTURE(info.name, words);
            CHECK(bench::run_copy(context, source) == source);
        }
    }
}

TEST_CASE("calibrate: rates are positive and finite", "[calibrate][opencl]") {
    for (const ocl::DeviceInfo& info : devices_or_warn()) {
        ocl::Context context(info);
        const bench::Calibration c = bench::calibrate(context, 1.0);
        CHECK(c.device == info.name);
        CHECK(std::isfinite(c.fill_tests_per_s));
        CHECK(c.fill_tests_per_s > 0);
        CHECK(std::isfinite(c.bandwidth_bytes_per_s));
        CHECK(c.bandwidth_bytes_per_s > 0);
        CHECK(c.seconds > 0);
        WARN(info.name << ": " << c.fill_tests_per_s / 1e9 << " G z-buffer tests/s, " << c.bandwidth_bytes_per_s / 1e9
                       << " GB/s copy (read + write), " << c.seconds << " s");
    }
}
