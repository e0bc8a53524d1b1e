// A short machine-limit calibration per OpenCL device: the fill rate of a tight vectorized z-buffer
// loop and the streaming copy bandwidth, so the benchmark can show each engine's throughput as a
// share of what the device can do (kernels/calibrate.cl).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "cl/runtime.h"

namespace hemirad::bench {

struct Calibration {
    std::string device;                // the device name as ocl::DeviceInfo::name
    double fill_tests_per_s = 0;       // pixel-triangle z-buffer tests per second (median of repeats)
    double bandwidth_bytes_per_s = 0;  // bytes read + written per second (median of repeats)
    double seconds = 0;                // wall time the calibration took, kernel build included
};

// Builds kernels/calibrate.cl (cached by the context), launches each kernel once to warm up, then
// times repeated launches from the queue's profiling events and keeps the medians. The repeats are
// fitted to budget_seconds (at least 3 per kernel, so a slow device may overrun it): 0.6..0.9 s on
// PoCL with 2 cores, whatever the budget from 1 s up. The copy moves 2 x 128 MiB a launch (less
// where the device allows less). Throws ocl::BuildError or cl::Error from the device.
Calibration calibrate(ocl::Context& context, double budget_seconds = 2.0);

// One synthetic triangle as zbuffer_fill reads it (four float4s): three edge functions and a depth
// plane, each {a, b, c, 0} for a*x + b*y + c at integer pixel (x, y); inside where all three edges
// are >= 0. Every coefficient is an integer.
struct FillTriangle {
    float edge[3][4];
    float depth[4];
};

// `count` triangles over a tile x tile image (tile a multiple of 16 in 16..512), a pure function of
// the seed. Each lies around a random point of the tile and covers about half of it on average,
// so about half the pixel-triangle tests are inside; depths are random planes, so the depth test
// passes less and less often as the z-buffer fills. The coefficients keep every partial sum of
// every evaluation an integer below 2^24: exact in float, whatever the order or FMA.
std::vector<FillTriangle> fill_triangles(std::size_t count, int tile, std::uint64_t seed);

// A z-buffer, row-major: the nearest inside triangle's depth and index per pixel, the earlier
// triangle on a tie; kFillFar and -1 where none covers the pixel.
struct FillImage {
    int width = 0, height = 0;
    std::vector<float> z;
    std::vector<std::int32_t> id;
};
constexpr float kFillFar = 16777216.0f;  // 2^24, HEMIRAD_CALIB_FAR: beyond every synthetic depth

// The host model of zbuffer_fill, a pixel at a time in exact integer arithmetic (not the kernel's
// float vectors: it checks them). `inside_tests`, when given, receives how many pixel-triangle
// tests found the pixel inside.
FillImage fill_reference(const std::vector<FillTriangle>& triangles, int width, int height,
                         std::uint64_t* inside_tests = nullptr);

// One launch of zbuffer_fill over `tiles` copies of a width x height tile (multiples of 16), read
// back one image per tile; for tests. Throws InternalError on bad sizes.
std::vector<FillImage> run_fill(ocl::Context& context, const std::vector<FillTriangle>& triangles, int width,
                                int height, int tiles);

// One launch of bandwidth_copy, read back; for tests. The size must be a multiple of 4 * 256 words.
std::vector<std::uint32_t> run_copy(ocl::Context& context, const std::vector<std::uint32_t>& source);

}  // namespace hemirad::bench
