// Machine-limit calibration of an OpenCL device (see calibrate.h): builds kernels/calibrate.cl,
// warms each kernel up, then takes the median of repeated launches timed by profiling events.
#include "bench/calibrate.h"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <string_view>

#include "core/error.h"
#include "core/rng.h"
#include "core/timing.h"

namespace hemirad::bench {
namespace {

// The kernel reads a triangle as four float4s.
static_assert(sizeof(FillTriangle) == 4 * sizeof(cl_float4));

// Per-device knobs. First match wins; measure before changing an entry.
struct CalibrationTuning {
    std::string_view type;     // DeviceInfo::type
    int width = 8;             // HEMIRAD_CALIB_WIDTH: pixels per strip row, 4, 8 or 16
    int rows = 2;              // HEMIRAD_CALIB_ROWS: strip rows a work-item keeps in registers
    int fill_group = 64;       // zbuffer_fill work-group size (strips)
    int copy_group = 64;       // bandwidth_copy work-group size, a power of two up to 256
    bool copy_runs = false;    // HEMIRAD_CALIB_COPY_RUNS: a contiguous run per work-item, not per group
    int groups_per_unit = 16;  // work-groups to launch per compute unit, at least
};
const CalibrationTuning kTuningTable[] = {
    // Not yet measured: two float4 rows per work-item keep the strip in few registers.
    {"gpu", 4, 2, 64, 256, false, 16},
    // PoCL, 2 cores, AVX-512: float16 rows, stepped, ~3 tests a cycle a core (4 rows as fast as 8),
    // ~1.7x float8 and ~1.4x evaluating each row in full; the copy in runs per work-item at about
    // memcpy's ~25 GB/s, groups of interleaved items at half that (a tenth in groups of 256).
    {"cpu", 16, 4, 16, 16, true, 32},
};
const CalibrationTuning kDefaultTuning{};

constexpr int kTile = 256;                      // calibration tile edge, pixels
constexpr std::size_t kMaxTriangles = 4096;     // 256 KiB of triangles: cache-resident on a CPU
constexpr std::size_t kProbeTriangles = 64;     // the warm-up and rate-probe launches
constexpr std::size_t kCopyBytes = 128u << 20;  // each of source and destination: past the caches
constexpr int kMinRepeats = 3, kMaxRepeats = 15;
constexpr std::uint64_t kSeed = 1;

// Binds a kernel's arguments in order: the one place each kernel's signature is spelled out.
template <class... Args>
void bind(cl::Kernel& kernel, const Args&... args) {
    cl_uint index = 0;
    (kernel.setArg(index++, args), ...);
}

const CalibrationTuning& tuning_for(const ocl::DeviceInfo& device) {
    for (const auto& entry : kTuningTable)
        if (entry.type == device.type) return entry;
    return kDefaultTuning;
}

struct Kernels {
    CalibrationTuning tuning;
    cl::Kernel fill, copy;
};

Kernels build(ocl::Context& context) {
    const CalibrationTuning& tuning = tuning_for(context.info());
    // Plain options: the fill kernel is exact by construction, and fast math would not speed it up.
    const std::string options =
        fmt::format("-cl-std=CL1.2 -DHEMIRAD_CALIB_WIDTH={} -DHEMIRAD_CALIB_ROWS={} -DHEMIRAD_CALIB_COPY_RUNS={}",
                    tuning.width, tuning.rows, tuning.copy_runs ? 1 : 0);
    cl::Program& program = context.program(std::string(ocl::kernel_source("calibrate.cl")), options);
    return {tuning, cl::Kernel(program, "zbuffer_fill"), cl::Kernel(program, "bandwidth_copy")};
}

double event_seconds(const cl::Event& event) {
    const cl_ulong start = event.getProfilingInfo<CL_PROFILING_COMMAND_START>();
    const cl_ulong end = event.getProfilingInfo<CL_PROFILING_COMMAND_END>();
    return static_cast<double>(end - start) * 1e-9;
}

double median(std::vector<double> values) {
    std::sort(values.begin(), values.end());
    const std::size_t n = values.size();
    return n % 2 == 1 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

// Repeats of a launch of `launch_seconds` that fit `seconds`, within [kMinRepeats, kMaxRepeats].
int repeats_within(double seconds, double launch_seconds) {
    const double fit = launch_seconds > 0 ? seconds / launch_seconds : kMaxRepeats;
    return static_cast<int>(std::clamp(fit, double{kMinRepeats}, double{kMaxRepeats}));
}

// The zbuffer_fill launch over `tiles` width x height tiles.
struct FillShape {
    int width, height, tiles;
    std::size_t strips_per_tile, group;
    std::size_t pixels() const { return std::size_t(width) * std::size_t(height) * std::size_t(tiles); }
};

FillShape fill_shape(const CalibrationTuning& tuning, int width, int height, int tiles) {
    if (width < 16 || height < 16 || width % 16 != 0 || height % 16 != 0 || tiles < 1)
        throw InternalError(fmt::format("z-buffer calibration: a {}x{} tile ({} of them) is not a multiple of 16",
                                        width, height, tiles));
    FillShape shape{width, height, tiles, 0, 0};
    shape.strips_per_tile = std::size_t(width / tuning.width) * std::size_t(height / tuning.rows);
    // A tile that is not a whole number of groups (a small test tile) gets the largest group that fits.
    shape.group = std::gcd(shape.strips_per_tile, std::size_t(tuning.fill_group));
    return shape;
}

cl::Event enqueue_fill(ocl::Context& context, Kernels& kernels, const FillShape& shape, const cl::Buffer& triangles,
                       std::size_t count, const cl::Buffer& z, const cl::Buffer& id) {
    bind(kernels.fill, triangles, static_cast<cl_int>(count), static_cast<cl_int>(shape.width),
         static_cast<cl_int>(shape.height), z, id);
    cl::Event event;
    context.queue().enqueueNDRangeKernel(kernels.fill, cl::NullRange,
                                         cl::NDRange(shape.strips_per_tile, std::size_t(shape.tiles)),
                                         cl::NDRange(shape.group, 1), nullptr, &event);
    return event;
}

// bandwidth_copy over `words` uint4s: group size from the tuning, and as many uint4s per
// work-item as leave at least `min_groups` groups.
struct CopyShape {
    std::size_t group, groups;
    cl_uint per_item;
};

CopyShape copy_shape(const CalibrationTuning& tuning, std::size_t words, std::size_t min_groups) {
    const std::size_t group = std::size_t(tuning.copy_group);
    if (words == 0 || words % group != 0)
        throw InternalError(fmt::format("copy calibration: {} uint4s is not a multiple of {}", words, group));
    const std::size_t runs = words / group;  // one uint4 per work-item each
    cl_uint per_item = 1;
    while (runs % (2 * std::size_t{per_item}) == 0 && runs / (2 * std::size_t{per_item}) >= min_groups) per_item *= 2;
    return {group, runs / per_item, per_item};
}

cl::Event enqueue_copy(ocl::Context& context, Kernels& kernels, const CopyShape& shape, const cl::Buffer& source,
                       const cl::Buffer& destination) {
    bind(kernels.copy, source, destination, shape.per_item);
    cl::Event event;
    context.queue().enqueueNDRangeKernel(kernels.copy, cl::NullRange, cl::NDRange(shape.groups * shape.group),
                                         cl::NDRange(shape.group), nullptr, &event);
    return event;
}

std::size_t min_groups(const ocl::Context& context, const CalibrationTuning& tuning) {
    return std::size_t(std::max(1, context.info().compute_units)) * std::size_t(tuning.groups_per_unit);
}

// Median seconds of `repeats` launches, enqueued back to back and timed on the device.
template <class Launch>
double median_seconds(ocl::Context& context, int repeats, Launch launch) {
    std::vector<cl::Event> events;
    for (int r = 0; r < repeats; ++r) events.push_back(launch());
    context.queue().finish();
    std::vector<double> seconds;
    for (const cl::Event& event : events) seconds.push_back(event_seconds(event));
    return median(seconds);
}

}  // namespace

std::vector<FillTriangle> fill_triangles(std::size_t count, int tile, std::uint64_t seed) {
    if (tile < 16 || tile > 512 || tile % 16 != 0)
        throw InternalError(fmt::format("z-buffer calibration: tile {} is not a multiple of 16 in 16..512", tile));
    const double size = tile;
    std::vector<FillTriangle> triangles(count);
    for (std::size_t i = 0; i < count; ++i) {
        std::uint64_t counter = 0;
        const auto uniform = [&] { return uniform01(seed, i, counter++); };
        // Roughly equilateral around a point of the tile, radius 0.5..1.2 tiles: on average about
        // half the tile inside (0.51 measured; the test checks). Vertices clamped to [-tile, 2 tile].
        const double cx = size * uniform(), cy = size * uniform();
        const double radius = size * (0.5 + 0.7 * uniform());
        const double angle = 6.283185307179586 * uniform();
        long vx[3], vy[3];
        for (int k = 0; k < 3; ++k) {
            const double a = angle + k * 2.0943951023931953 + 0.5 * (uniform() - 0.5);
            vx[k] = std::lround(std::clamp(cx + radius * std::cos(a), -size, 2 * size));
            vy[k] = std::lround(std::clamp(cy + radius * std::sin(a), -size, 2 * size));
        }
        // Counter-clockwise (the angles increase), but rounding or clamping may have flattened it.
        const long area = (vx[1] - vx[0]) * (vy[2] - vy[0]) - (vy[1] - vy[0]) * (vx[2] - vx[0]);
        if (area < 0) {
            std::swap(vx[1], vx[2]);
            std::swap(vy[1], vy[2]);
        } else if (area == 0) {
            vx[1] = vx[0] + 1;  // a sliver rather than a line: still a valid triangle
            vy[1] = vy[0];
            vx[2] = vx[0];
            vy[2] = vy[0] + 1;
        }
        FillTriangle& t = triangles[i];
        for (int k = 0; k < 3; ++k) {
            // Edge from vertex k to k + 1, >= 0 on its left: the inside of a counter-clockwise triangle.
            const long x0 = vx[k], y0 = vy[k], x1 = vx[(k + 1) % 3], y1 = vy[(k + 1) % 3];
            t.edge[k][0] = static_cast<float>(y0 - y1);
            t.edge[k][1] = static_cast<float>(x1 - x0);
            t.edge[k][2] = static_cast<float>((y1 - y0) * x0 - (x1 - x0) * y0);
            t.edge[k][3] = 0.0f;
        }
        // Depth 2^22..2^23 at the tile's centre, sloped by up to 2^21 / tile per pixel: 2^21..2^23 +
        // 2^21 over the tile, so steep planes cross and the winners vary.
        const long slope = (1l << 21) / tile;
        const long dx = std::lround(2 * slope * uniform()) - slope, dy = std::lround(2 * slope * uniform()) - slope;
        const long centre = (1l << 22) + std::lround(double(1l << 22) * uniform());
        t.depth[0] = static_cast<float>(dx);
        t.depth[1] = static_cast<float>(dy);
        t.depth[2] = static_cast<float>(centre - dx * (tile / 2) - dy * (tile / 2));
        t.depth[3] = 0.0f;
    }
    return triangles;
}

FillImage fill_reference(const std::vector<FillTriangle>& triangles, int width, int height,
                         std::uint64_t* inside_tests) {
    FillImage image{width, height, {}, {}};
    image.z.assign(std::size_t(width) * std::size_t(height), kFillFar);
    image.id.assign(image.z.size(), -1);
    // Integer copies of the (integer) coefficients: exact whatever the kernel's float order.
    std::vector<std::int64_t> c(triangles.size() * 12);
    for (std::size_t t = 0; t < triangles.size(); ++t)
        for (int k = 0; k < 3; ++k) {
            for (int j = 0; j < 3; ++j) c[12 * t + 3 * k + j] = std::int64_t(triangles[t].edge[k][j]);
            c[12 * t + 9 + std::size_t(k)] = std::int64_t(triangles[t].depth[k]);
        }
    std::uint64_t inside = 0;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const std::size_t pixel = std::size_t(y) * std::size_t(width) + std::size_t(x);
            std::int64_t best = std::int64_t(kFillFar);
            std::int32_t best_id = -1;
            for (std::size_t t = 0; t < triangles.size(); ++t) {
                const std::int64_t* p = &c[12 * t];
                if (p[0] * x + p[1] * y + p[2] < 0 || p[3] * x + p[4] * y + p[5] < 0 || p[6] * x + p[7] * y + p[8] < 0)
                    continue;
                ++inside;
                const std::int64_t depth = p[9] * x + p[10] * y + p[11];
                if (depth < best) {  // strict: the earlier triangle keeps a tie
                    best = depth;
                    best_id = static_cast<std::int32_t>(t);
                }
            }
            image.z[pixel] = static_cast<float>(best);
            image.id[pixel] = best_id;
        }
    if (inside_tests) *inside_tests = inside;
    return image;
}

std::vector<FillImage> run_fill(ocl::Context& context, const std::vector<FillTriangle>& triangles, int width,
                                int height, int tiles) {
    Kernels kernels = build(context);
    const FillShape shape = fill_shape(kernels.tuning, width, height, tiles);
    cl::Context& cl_context = context.context();
    cl::CommandQueue& queue = context.queue();
    cl::Buffer triangle_buffer(cl_context, CL_MEM_READ_ONLY,
                               std::max<std::size_t>(1, triangles.size()) * sizeof(FillTriangle));
    if (!triangles.empty())
        queue.enqueueWriteBuffer(triangle_buffer, CL_TRUE, 0, triangles.size() * sizeof(FillTriangle),
                                 triangles.data());
    cl::Buffer z(cl_context, CL_MEM_WRITE_ONLY, shape.pixels() * sizeof(float));
    cl::Buffer id(cl_context, CL_MEM_WRITE_ONLY, shape.pixels() * sizeof(cl_int));
    enqueue_fill(context, kernels, shape, triangle_buffer, triangles.size(), z, id);
    std::vector<float> z_host(shape.pixels());
    std::vector<std::int32_t> id_host(shape.pixels());
    queue.enqueueReadBuffer(z, CL_FALSE, 0, z_host.size() * sizeof(float), z_host.data());
    queue.enqueueReadBuffer(id, CL_TRUE, 0, id_host.size() * sizeof(cl_int), id_host.data());
    std::vector<FillImage> images;
    const std::size_t per_tile = std::size_t(width) * std::size_t(height);
    for (std::size_t first = 0; first < shape.pixels(); first += per_tile) {
        const float* z_tile = z_host.data() + first;
        const std::int32_t* id_tile = id_host.data() + first;
        images.push_back({width, height, {z_tile, z_tile + per_tile}, {id_tile, id_tile + per_tile}});
    }
    return images;
}

std::vector<std::uint32_t> run_copy(ocl::Context& context, const std::vector<std::uint32_t>& source) {
    Kernels kernels = build(context);
    if (source.size() % 1024 != 0)
        throw InternalError(fmt::format("copy calibration: {} words is not a multiple of 1024", source.size()));
    const CopyShape shape = copy_shape(kernels.tuning, source.size() / 4, min_groups(context, kernels.tuning));
    const std::size_t bytes = source.size() * sizeof(std::uint32_t);
    cl::Buffer from(context.context(), CL_MEM_READ_ONLY, bytes);
    cl::Buffer to(context.context(), CL_MEM_WRITE_ONLY, bytes);
    context.queue().enqueueWriteBuffer(from, CL_FALSE, 0, bytes, source.data());
    enqueue_copy(context, kernels, shape, from, to);
    std::vector<std::uint32_t> copied(source.size());
    context.queue().enqueueReadBuffer(to, CL_TRUE, 0, bytes, copied.data());
    return copied;
}

Calibration calibrate(ocl::Context& context, double budget_seconds) {
    const Clock::time_point start = Clock::now();
    Calibration result;
    result.device = context.info().name;
    Kernels kernels = build(context);
    cl::Context& cl_context = context.context();
    const std::size_t groups = min_groups(context, kernels.tuning);

    // Fill: enough tiles for the device's work-groups; the triangle count sized from a probe.
    FillShape shape = fill_shape(kernels.tuning, kTile, kTile, 1);
    const std::size_t groups_per_tile = shape.strips_per_tile / shape.group;
    shape.tiles = static_cast<int>((groups + groups_per_tile - 1) / groups_per_tile);
    const std::vector<FillTriangle> triangles = fill_triangles(kMaxTriangles, kTile, kSeed);
    cl::Buffer triangle_buffer(cl_context, CL_MEM_READ_ONLY, triangles.size() * sizeof(FillTriangle));
    context.queue().enqueueWriteBuffer(triangle_buffer, CL_TRUE, 0, triangles.size() * sizeof(FillTriangle),
                                       triangles.data());
    cl::Buffer z(cl_context, CL_MEM_WRITE_ONLY, shape.pixels() * sizeof(float));
    cl::Buffer id(cl_context, CL_MEM_WRITE_ONLY, shape.pixels() * sizeof(cl_int));
    // The first launch pays for PoCL's per-group-size compile and first touches; the second probes the rate.
    enqueue_fill(context, kernels, shape, triangle_buffer, kProbeTriangles, z, id).wait();
    cl::Event probe = enqueue_fill(context, kernels, shape, triangle_buffer, kProbeTriangles, z, id);
    probe.wait();
    const double per_triangle = event_seconds(probe) / double(kProbeTriangles);
    // Half of what is left for the fill, in launches of about a tenth of that.
    const double fill_budget = 0.5 * std::max(0.0, budget_seconds - seconds_since(start));
    const std::size_t count = std::clamp<std::size_t>(
        static_cast<std::size_t>(fill_budget / 10.0 / std::max(per_triangle, 1e-12)), kProbeTriangles, kMaxTriangles);
    const int fill_repeats = repeats_within(fill_budget, per_triangle * double(count));
    const double fill_seconds = median_seconds(
        context, fill_repeats, [&] { return enqueue_fill(context, kernels, shape, triangle_buffer, count, z, id); });
    result.fill_tests_per_s = double(shape.pixels()) * double(count) / fill_seconds;

    // Copy: a source and destination past the caches, as the device allows.
    const std::size_t most = std::min<std::size_t>(context.device().getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>(),
                                                   context.info().global_memory / 4);
    const std::size_t bytes = std::min(kCopyBytes, most) / (1u << 20) * (1u << 20);
    if (bytes == 0) throw InternalError(fmt::format("{}: too little memory for the copy calibration", result.device));
    const CopyShape copy = copy_shape(kernels.tuning, bytes / sizeof(cl_uint4), groups);
    cl::Buffer source(cl_context, CL_MEM_READ_ONLY, bytes);
    cl::Buffer destination(cl_context, CL_MEM_WRITE_ONLY, bytes);
    // Written, so that reads cannot all come from one shared zero page.
    context.queue().enqueueFillBuffer(source, cl_uint{0x5a5a5a5a}, 0, bytes);
    enqueue_copy(context, kernels, copy, source, destination).wait();  // first touch of the destination
    cl::Event copy_probe = enqueue_copy(context, kernels, copy, source, destination);
    copy_probe.wait();
    const int copy_repeats =
        repeats_within(std::max(0.0, budget_seconds - seconds_since(start)), event_seconds(copy_probe));
    const double copy_seconds = median_seconds(
        context, copy_repeats, [&] { return enqueue_copy(context, kernels, copy, source, destination); });
    result.bandwidth_bytes_per_s = 2.0 * double(bytes) / copy_seconds;

    result.seconds = seconds_since(start);
    return result;
}

}  // namespace hemirad::bench
