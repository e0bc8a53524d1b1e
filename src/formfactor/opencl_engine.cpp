// The OpenCL hemicube engine (see opencl_engine.h): uploads the mesh once, then per shot runs
// setup -> count -> scan -> scatter -> raster of kernels/hemicube.cl and reads back the
// fixed-point sums (one read; the shot itself goes as a kernel argument).
#include "formfactor/opencl_engine.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string_view>

#include <fmt/core.h>

#include "core/error.h"
#include "hemicube_types.h"

namespace hemirad::formfactor {
namespace {

// The layout header is the contract with the kernel: pin it down.
static_assert(sizeof(HrElement) == 160 && offsetof(HrElement, normal) == 96 && offsetof(HrElement, centroid) == 120 &&
              offsetof(HrElement, n) == 144 && offsetof(HrElement, has_twin) == 152);
static_assert(sizeof(HrPatch) == 112 && offsetof(HrPatch, n) == 96);
static_assert(sizeof(HrShot) == 152 && offsetof(HrShot, eps) == 96 && offsetof(HrShot, n) == 104 &&
              offsetof(HrShot, tiles_x) == 116 && offsetof(HrShot, tile_base) == 120 &&
              offsetof(HrShot, list_capacity) == 144);
static_assert(sizeof(HrEdge) == 32 && sizeof(HrBox) == 16);
static_assert(sizeof(HrRecord) == 344 && offsetof(HrRecord, c) == 24 && offsetof(HrRecord, element) == 32 &&
              offsetof(HrRecord, owns) == 44 && offsetof(HrRecord, edge) == 56);
static_assert(HR_FACES == kFaces);
static_assert(HR_EMPTY == OpenCLEngine::kEmpty && HR_BLOCKER == OpenCLEngine::kBlocker);

// Per-device knobs. First match wins; measure before changing an entry.
struct TuningEntry {
    std::string_view type;  // DeviceInfo::type
    OpenCLTuning tuning;
};
const TuningEntry kTuningTable[] = {
    // Not yet measured: 256-cell raster groups, 4 warps per 1D group.
    {"gpu", {16, false, 4, 128, 256, 1, 4, "", 0}},
    // PoCL, 2 cores (Cornell, N = 256): the per-record raster ~2.5x faster than per-cell;
    // tiles 16 a little ahead of 8 and 32; a raster group of 1 ahead of 4 and 16.
    {"cpu", {16, true, 1, 64, 256, 8, 8, "", 0}},
};

// Binds a kernel's arguments in order: the one place each kernel's signature is spelled out.
template <class... Args>
void bind(cl::Kernel& kernel, const Args&... args) {
    cl_uint index = 0;
    (kernel.setArg(index++, args), ...);
}

std::size_t round_up(std::size_t x, std::size_t multiple) {
    return (x + multiple - 1) / multiple * multiple;
}

template <class T>
cl::Buffer upload(cl::Context& context, cl::CommandQueue& queue, const std::vector<T>& data) {
    cl::Buffer buffer(context, CL_MEM_READ_ONLY, std::max<std::size_t>(1, data.size()) * sizeof(T));
    if (!data.empty()) queue.enqueueWriteBuffer(buffer, CL_TRUE, 0, data.size() * sizeof(T), data.data());
    return buffer;
}

void copy_polygon(const mesh::Polygon& poly, hr_double (&v)[12]) {
    for (int i = 0; i < 4; ++i)
        for (int c = 0; c < 3; ++c) v[3 * i + c] = i < poly.n ? poly.v[static_cast<std::size_t>(i)][c] : 0.0;
}

void copy3(const glm::dvec3& from, hr_double (&to)[3]) {
    for (int c = 0; c < 3; ++c) to[c] = from[c];
}

// The device compiler must lay the shared structs out as the host does (it would on any
// conforming device; this catches a header edited on one side only).
void check_layout(ocl::Context& context, cl::Program& program) {
    cl::Kernel layout(program, "layout");
    cl::Buffer sizes_buffer(context.context(), CL_MEM_WRITE_ONLY, 4 * sizeof(hr_int));
    bind(layout, sizes_buffer);
    context.queue().enqueueNDRangeKernel(layout, cl::NullRange, cl::NDRange(1), cl::NDRange(1));
    hr_int sizes[4] = {};
    context.queue().enqueueReadBuffer(sizes_buffer, CL_TRUE, 0, sizeof(sizes), sizes);
    const hr_int expected[4] = {sizeof(HrElement), sizeof(HrPatch), sizeof(HrShot), sizeof(HrRecord)};
    if (!std::equal(sizes, sizes + 4, expected))
        throw InternalError(fmt::format(
            "{}: kernels/hemicube_types.h lays out differently on the device (sizes {} {} {} {}, host {} {} {} {})",
            context.info().name, sizes[0], sizes[1], sizes[2], sizes[3], expected[0], expected[1], expected[2],
            expected[3]));
}

}  // namespace

OpenCLTuning default_tuning(const ocl::DeviceInfo& device) {
    for (const auto& entry : kTuningTable)
        if (entry.type == device.type) return entry.tuning;
    return {};
}

OpenCLEngine::OpenCLEngine(const mesh::Mesh& mesh, ocl::Context& context, const Settings& settings)
    : OpenCLEngine(mesh, context, settings, default_tuning(context.info())) {}

OpenCLEngine::OpenCLEngine(const mesh::Mesh& mesh, ocl::Context& context, const Settings& settings,
                           const OpenCLTuning& tuning)
    : mesh_(mesh), context_(context), settings_(settings), tuning_(tuning), delta_(std::max(settings.hemicube, 2)) {
    const ocl::DeviceInfo& info = context.info();
    if (settings.hemicube < 8 || settings.hemicube % 2 != 0)
        throw InternalError("hemicube resolution must be even and at least 8");
    if (!info.fp64)
        throw InternalError(
            fmt::format("{}: needs cl_khr_fp64 (double precision) for results that match the reference", info.name));
    if (!info.int64_atomics)
        throw InternalError(
            fmt::format("{}: needs cl_khr_int64_base_atomics for deterministic form-factor sums", info.name));
    if (tuning.tile < 1 || tuning.work_group < 1 || tuning.scan_work_group < 1 || tuning.raster_work_group < 1 ||
        tuning.count_copies < 1 || (tuning.lanes != 4 && tuning.lanes != 8) || (tuning.scan_work_group & (tuning.scan_work_group - 1)) != 0)
        throw InternalError("OpenCL tuning: tile and work-group sizes must be positive, the scan's a power of two");

    eps_ = base_plane_epsilon(mesh);  // exactly the reference's clip distance

    // Never -cl-fast-relaxed-math or -cl-mad-enable: the kernel must round like the reference.
    options_ = fmt::format(
        "-cl-std=CL1.2 -DHEMIRAD_TILE={} -DHEMIRAD_WG={} -DHEMIRAD_SCAN_WG={} -DHEMIRAD_RASTER_WG={} "
        "-DHEMIRAD_COUNT_COPIES={} -DHEMIRAD_LANES={}",
        tuning.tile, tuning.work_group, tuning.scan_work_group, tuning.raster_work_group, tuning.count_copies,
        tuning.lanes);
    if (!tuning.extra_options.empty()) options_ += " " + tuning.extra_options;
    cl::Program& program = context.program(std::string(ocl::kernel_source("hemicube.cl")), options_);
    setup_ = cl::Kernel(program, "setup");
    count_ = cl::Kernel(program, "count");
    scan_ = cl::Kernel(program, "scan");
    scatter_ = cl::Kernel(program, "scatter");
    raster_ = cl::Kernel(program, tuning.raster_per_record ? "raster_records" : "raster");
    check_layout(context, program);
    const auto check_group = [&](cl::Kernel& kernel, const char* name, int size) {
        const std::size_t most = kernel.getWorkGroupInfo<CL_KERNEL_WORK_GROUP_SIZE>(context.device());
        if (static_cast<std::size_t>(size) > most)
            throw InternalError(
                fmt::format("{}: kernel {} runs at most {} work-items per group, the tuning asks for {}", info.name,
                            name, most, size));
    };
    check_group(setup_, "setup", tuning.work_group);
    check_group(count_, "count", tuning.work_group);
    check_group(scatter_, "scatter", tuning.work_group);
    check_group(scan_, "scan", tuning.scan_work_group);
    check_group(raster_, "raster", raster_group_size());

    // Tiles: face by face, row-major within a face.
    const int n = settings.hemicube;
    tiles_x_ = (n + tuning.tile - 1) / tuning.tile;
    tile_base_[0] = 0;
    for (int face = 0; face < kFaces; ++face) {
        const int tiles_y = (delta_.rows(face) + tuning.tile - 1) / tuning.tile;
        tile_base_[static_cast<std::size_t>(face) + 1] =
            tile_base_[static_cast<std::size_t>(face)] + tiles_x_ * tiles_y;
    }
    const std::size_t tiles = static_cast<std::size_t>(tile_base_[kFaces]);

    std::vector<HrElement> elements(mesh.elements.size());
    for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
        const mesh::Element& e = mesh.elements[k];
        HrElement& h = elements[k];
        h = {};
        copy_polygon(e.poly, h.v);
        copy3(e.normal, h.normal);
        copy3(e.centroid, h.centroid);
        h.n = e.poly.n;
        h.patch = static_cast<hr_int>(e.patch);
        h.has_twin = e.has_twin ? 1 : 0;
    }
    std::vector<HrPatch> patches(mesh.patches.size());
    for (std::size_t p = 0; p < mesh.patches.size(); ++p) {
        patches[p] = {};
        copy_polygon(mesh.patches[p].poly, patches[p].v);
        patches[p].n = mesh.patches[p].poly.n;
    }
    // Fixed point: 2^62 per unit of form factor; the whole table sums to 1, far below 2^63.
    // Zero-padded: raster_records reads whole lane groups, up to 7 entries past the last cell.
    std::vector<hr_long> delta_fixed(delta_.cells() + 8, 0);
    for (std::size_t c = 0; c < delta_.cells(); ++c)
        delta_fixed[c] = static_cast<hr_long>(std::llround(std::ldexp(delta_.table()[c], HR_FIXED_SHIFT)));

    cl::Context& cl_context = context.context();
    cl::CommandQueue& queue = context.queue();
    const std::size_t record_slots = std::max<std::size_t>(1, mesh.elements.size() * kFaces);
    elements_ = upload(cl_context, queue, elements);
    patches_ = upload(cl_context, queue, patches);
    delta_fixed_ = upload(cl_context, queue, delta_fixed);
    records_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, record_slots * sizeof(HrRecord));
    const std::size_t counters = tiles * static_cast<std::size_t>(tuning.count_copies);
    boxes_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, record_slots * sizeof(HrBox));
    record_count_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, sizeof(hr_uint));
    tile_counts_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, counters * sizeof(hr_uint));
    offsets_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, (counters + 1) * sizeof(hr_uint));
    cursors_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, counters * sizeof(hr_uint));
    // Most records cover a tile or two; a shot that needs more grows the lists and reruns.
    list_capacity_ = tuning.list_capacity > 0
                         ? tuning.list_capacity
                         : static_cast<std::uint32_t>(std::max<std::size_t>(1u << 16, 4 * record_slots));
    lists_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, list_capacity_ * sizeof(hr_uint));
    ids_buffer_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, delta_.cells() * sizeof(hr_int));
    sums_ = cl::Buffer(cl_context, CL_MEM_READ_WRITE, (mesh.elements.size() + 2) * sizeof(hr_long));
    sums_host_.assign(mesh.elements.size() + 2, 0);
    ids_.assign(delta_.cells(), kEmpty);
}

std::size_t OpenCLEngine::raster_group_size() const {
    return static_cast<std::size_t>(tuning_.raster_per_record ? tuning_.raster_work_group
                                                              : tuning_.tile * tuning_.tile);
}

std::uint32_t OpenCLEngine::run_shot(std::uint32_t patch, const Frame& frame) {
    HrShot shot{};
    copy3(frame.origin, shot.origin);
    copy3(frame.u, shot.u);
    copy3(frame.v, shot.v);
    copy3(frame.w, shot.w);
    shot.eps = eps_;
    shot.n = settings_.hemicube;
    shot.shooter = static_cast<hr_int>(patch);
    shot.elements = static_cast<hr_int>(mesh_.elements.size());
    shot.tiles_x = tiles_x_;
    std::copy(tile_base_.begin(), tile_base_.end(), shot.tile_base);
    shot.list_capacity = list_capacity_;
    // Every kernel's arguments, bound here only; the shot goes by value: no upload to wait for.
    bind(setup_, shot, elements_, patches_, records_, boxes_, record_count_, tile_counts_, sums_);
    bind(count_, shot, records_, boxes_, record_count_, tile_counts_);
    bind(scan_, shot, tile_counts_, offsets_, cursors_, sums_);
    bind(scatter_, shot, records_, boxes_, record_count_, cursors_, lists_);
    bind(raster_, shot, records_, boxes_, offsets_, lists_, delta_fixed_, ids_buffer_, sums_);

    cl::CommandQueue& queue = context_.queue();
    const std::size_t elements = mesh_.elements.size();
    const std::size_t tiles = static_cast<std::size_t>(tile_base_[kFaces]);
    const std::size_t wg = static_cast<std::size_t>(tuning_.work_group);
    const std::size_t scan_wg = static_cast<std::size_t>(tuning_.scan_work_group);
    const std::size_t raster_wg = raster_group_size();
    const std::size_t raster_items = tuning_.raster_per_record ? round_up(tiles, raster_wg) : tiles * raster_wg;
    std::array<cl::Event, kStages> events;
    queue.enqueueFillBuffer(record_count_, hr_uint{0}, 0, sizeof(hr_uint));
    queue.enqueueNDRangeKernel(setup_, cl::NullRange, cl::NDRange(round_up(elements, wg)), cl::NDRange(wg), nullptr,
                               &events[0]);
    queue.enqueueNDRangeKernel(count_, cl::NullRange, cl::NDRange(round_up(elements, wg)), cl::NDRange(wg), nullptr,
                               &events[1]);
    queue.enqueueNDRangeKernel(scan_, cl::NullRange, cl::NDRange(scan_wg), cl::NDRange(scan_wg), nullptr, &events[2]);
    queue.enqueueNDRangeKernel(scatter_, cl::NullRange, cl::NDRange(round_up(elements, wg)), cl::NDRange(wg), nullptr,
                               &events[3]);
    queue.enqueueNDRangeKernel(raster_, cl::NullRange, cl::NDRange(raster_items), cl::NDRange(raster_wg), nullptr,
                               &events[4]);
    // The sums, then the list entries the shot needed (from scan).
    queue.enqueueReadBuffer(sums_, CL_TRUE, 0, sums_host_.size() * sizeof(hr_long), sums_host_.data(), nullptr,
                            &events[5]);
    for (int s = 0; s < kStages; ++s)
        stage_seconds_[static_cast<std::size_t>(s)] +=
            1e-9 * static_cast<double>(events[static_cast<std::size_t>(s)].getProfilingInfo<CL_PROFILING_COMMAND_END>() -
                                       events[static_cast<std::size_t>(s)].getProfilingInfo<CL_PROFILING_COMMAND_START>());
    return static_cast<std::uint32_t>(sums_host_[elements + 1]);
}

void OpenCLEngine::shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) {
    const mesh::Patch& shooter = mesh_.patches.at(patch);
    const Frame frame = make_frame(shooter, settings_.seed, shot);
    for (;;) {
        const std::uint32_t needed = run_shot(patch, frame);
        if (needed <= list_capacity_) break;
        // The raster skipped this shot: grow the lists with some headroom and run it again.
        list_capacity_ = static_cast<std::uint32_t>(std::min<std::uint64_t>(0xffffffffu, needed + needed / 4ull));
        lists_ = cl::Buffer(context_.context(), CL_MEM_READ_WRITE,
                            static_cast<std::size_t>(list_capacity_) * sizeof(hr_uint));
    }
    ids_stale_ = true;

    const std::size_t elements = mesh_.elements.size();
    out.F.assign(elements, 0.0);
    for (std::size_t k = 0; k < elements; ++k)
        out.F[k] = std::ldexp(static_cast<double>(sums_host_[k]), -HR_FIXED_SHIFT);
    out.blocked = std::ldexp(static_cast<double>(sums_host_[elements]), -HR_FIXED_SHIFT);
}

const std::vector<std::int32_t>& OpenCLEngine::ids() const {
    if (ids_stale_) {
        context_.queue().enqueueReadBuffer(ids_buffer_, CL_TRUE, 0, ids_.size() * sizeof(std::int32_t), ids_.data());
        ids_stale_ = false;
    }
    return ids_;
}

}  // namespace hemirad::formfactor
