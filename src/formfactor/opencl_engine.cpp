// The OpenCL hemicube engine (see opencl_engine.h): uploads the mesh once, then per shot runs
// setup -> count -> scan -> scatter -> raster of kernels/hemicube.cl and reads back the
// fixed-point sums (one read; the shot itself goes as a kernel argument).
#include "formfactor/opencl_engine.h"

#include <fmt/core.h>
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <type_traits>
#include <vector>

#include "core/error.h"
#include "core/parallel.h"
#include "core/timing.h"
#include "hemicube_types.h"

namespace hemirad::formfactor {
namespace {

// The layout header is the contract with the kernel: pin it down.
static_assert(sizeof(HrElement) == 160 && offsetof(HrElement, normal) == 96 && offsetof(HrElement, centroid) == 120 &&
              offsetof(HrElement, n) == 144 && offsetof(HrElement, has_twin) == 148 &&
              offsetof(HrElement, patch) == 152);
static_assert(sizeof(HrElementLanes) == 1280 && offsetof(HrElementLanes, normal) == 768 &&
              offsetof(HrElementLanes, n) == 1152 && offsetof(HrElementLanes, patch) == 1216 &&
              offsetof(HrElementLanes, bound) == 1248);
static_assert(sizeof(HrPatch) == 104 && offsetof(HrPatch, n) == 96);
static_assert(sizeof(HrShot) == 168 && offsetof(HrShot, eps) == 96 && offsetof(HrShot, n) == 104 &&
              offsetof(HrShot, twin) == 112 && offsetof(HrShot, patches) == 120 && offsetof(HrShot, tiles_x) == 124 &&
              offsetof(HrShot, tile_base) == 128 && offsetof(HrShot, list_capacity) == 152 &&
              offsetof(HrShot, group_capacity) == 156 && offsetof(HrShot, group_rows) == 160);
static_assert(sizeof(HrEdge) == 24 && sizeof(HrBox) == 24);
static_assert(sizeof(HrRecord) == 256 && offsetof(HrRecord, element) == 24 && offsetof(HrRecord, edges) == 32 &&
              offsetof(HrRecord, spans) == 36 && offsetof(HrRecord, cover) == 40 &&
              sizeof(HrRecord{}.cover.span) == sizeof(HrRecord{}.cover));
static_assert(std::int64_t{1} << HR_SUBCELL_BITS == kSubcell);
static_assert(HR_FACES == kFaces);
static_assert(HR_EMPTY == OpenCLEngine::kEmpty && HR_BLOCKER == OpenCLEngine::kBlocker);

// Per-device knobs. First match wins; measure before changing an entry.
struct TuningEntry {
    std::string_view type;  // DeviceInfo::type
    OpenCLTuning tuning;
};
const TuningEntry kTuningTable[] = {
    // Not yet measured: 256-cell raster groups, 4 warps per 1D group.
    // Occlusion culling needs lanes setup and raster_records: off.
    {"gpu", {16, false, 4, 128, 256, 1, 4, false, "", 0, 0, 0, true, Occlusion::off, 16, {}, ""}},
    // PoCL, 2 cores (Cornell, N = 256): the per-record raster ~2.5x faster than per-cell;
    // with integer edges, tiles of 32 ~20% ahead of 16 (fewer record-tile pieces); with span
    // records, tiles of 64 ~4% ahead in batches of 8 but ~7% behind one shot at a time, and
    // 64x32 behind too; a raster group of 1 ahead of 4 and 16. Setup in double8 lanes ~1.6x
    // faster on one thread. Setup and scatter groups of 16 work-items (65 groups) ~5% ahead of
    // 64 (17 groups, unevenly shared by 2 cores) one shot at a time, in 4 of 5 pairs; 8 no better.
    // Occlusion culling, where it pays (measured per bake): city:1M (N = 256) 38.2 -> 31.4 ms a
    // shot with half the lane groups hidden, foliage:100k 17.8 -> 15.9 ms, but furniture:100k
    // 5.5 -> 7.9 ms (9% hidden); an occluder share of 4 hides more and costs as much more.
    {"cpu", {32, true, 1, 16, 256, 8, 8, true, "", 0, 0, 0, true, Occlusion::measured, 16, {}, ""}},
};

// The private memory of one raster_records work-item (kernels/hemicube.cl): a tile's winners
// (an int and a double per cell, LANES - 1 more), its table of pending sums (an int and a long per
// entry), its columns' and rows' coordinates, and a little for the rest. On PoCL with 8 MiB
// stacks, tiles of 32 (12.5 KB by this count) ran at 700 work-items a group and crashed at 850.
double raster_records_private_bytes(const OpenCLTuning& t) {
    constexpr double kSumTable = 64.0 * (4 + 8), kRest = 512.0;
    const double cells = double(t.tile) * t.tile + t.lanes - 1;
    return cells * (4 + 8) + kSumTable + (2.0 * t.tile + t.lanes - 1) * 8 + kRest;
}

// The private memory of a setup or scatter work-item on a CPU, measured: with 8 MiB stacks PoCL
// ran groups of 768 and crashed at 1024 (with 16 MiB stacks 1024 ran), so between 8.2 and 10.9 KB.
constexpr double kSetupPrivateBytes = 11.0 * 1024;

// The stack of a thread the OpenCL CPU runtime starts: glibc gives threads the soft stack limit
// (8 MiB by default), or 2 MiB where it is unlimited.
std::size_t worker_stack_bytes() {
    struct rlimit limit {};
    if (getrlimit(RLIMIT_STACK, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return std::size_t{2} << 20;
    return std::max<std::size_t>(std::size_t(limit.rlim_cur), std::size_t{1} << 20);
}

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

// The clusters (lanes setup) each shot must set up: those whose bounding sphere does not lie
// wholly below −eps along the shooter's normal, the test group_behind makes per lane group, so
// every element of a skipped one lies behind the base plane. Fills `per_shot` and `rows` (row i:
// shot i's clusters, then −1, a work-group with nothing to do) and returns the row length.
std::size_t select_clusters(const std::vector<std::array<double, 4>>& bounds, const std::vector<HrShot>& shots,
                            bool cull, std::vector<std::vector<std::uint32_t>>& per_shot,
                            std::vector<std::int32_t>& rows) {
    per_shot.assign(shots.size(), {});
    std::size_t most = 1;
    for (std::size_t i = 0; i < shots.size(); ++i) {
        const HrShot& shot = shots[i];
        for (std::size_t c = 0; c < bounds.size(); ++c) {
            const double z = (bounds[c][0] - shot.origin[0]) * shot.w[0] + (bounds[c][1] - shot.origin[1]) * shot.w[1] +
                             (bounds[c][2] - shot.origin[2]) * shot.w[2];
            if (!cull || !(z + bounds[c][3] < -shot.eps)) per_shot[i].push_back(static_cast<std::uint32_t>(c));
        }
        most = std::max(most, per_shot[i].size());
    }
    rows.assign(shots.size() * most, -1);
    for (std::size_t i = 0; i < shots.size(); ++i)
        std::copy(per_shot[i].begin(), per_shot[i].end(), rows.begin() + static_cast<std::ptrdiff_t>(i * most));
    return most;
}

// The occluder pass's clusters: per shot, the one in `share` of its clusters in front (at least
// one) whose bounding spheres come nearest the shooter, nearest first, those most likely to hide
// the rest. (Ranked by the angle they span instead, with those narrower than a depth block left
// out, they hid less of city:1M: 41% of its lane groups against 51% at N = 64, 8.7 against 7.7 ms
// a shot. Two passes, the nearest quarter first and the rest culled against its depths, cost
// city:1M more in the second raster than they saved: 7.8-9.7 against 6.2-7.2 ms at N = 64.)
// Fills `rows` as select_clusters does and returns the row length; and rewrites `final_rows`
// (select_clusters' rows, of length `final_length`) to start with the same clusters as -2 - c, at
// the same work-groups, so that the final pass keeps their records.
std::size_t select_occluders(const std::vector<std::array<double, 4>>& bounds, const std::vector<HrShot>& shots,
                             const std::vector<std::vector<std::uint32_t>>& per_shot, int share,
                             std::vector<std::int32_t>& rows, std::vector<std::int32_t>& final_rows,
                             std::size_t final_length) {
    std::vector<std::vector<std::uint32_t>> nearest(shots.size());
    std::size_t most = 1;
    std::vector<std::pair<double, std::uint32_t>> keyed;
    for (std::size_t i = 0; i < shots.size(); ++i) {
        const HrShot& shot = shots[i];
        keyed.clear();
        for (const std::uint32_t c : per_shot[i]) {
            const double dx = bounds[c][0] - shot.origin[0], dy = bounds[c][1] - shot.origin[1],
                         dz = bounds[c][2] - shot.origin[2];
            keyed.emplace_back(std::sqrt(dx * dx + dy * dy + dz * dz) - bounds[c][3], c);
        }
        const std::size_t take = std::min(keyed.size(), std::max<std::size_t>(1, keyed.size() / std::size_t(share)));
        std::partial_sort(keyed.begin(), keyed.begin() + static_cast<std::ptrdiff_t>(take), keyed.end());
        for (std::size_t k = 0; k < take; ++k) nearest[i].push_back(keyed[k].second);
        most = std::max(most, take);
    }
    rows.assign(shots.size() * most, -1);
    for (std::size_t i = 0; i < shots.size(); ++i) {
        std::copy(nearest[i].begin(), nearest[i].end(), rows.begin() + static_cast<std::ptrdiff_t>(i * most));
        std::int32_t* row = final_rows.data() + i * final_length;
        std::size_t k = 0;
        for (const std::uint32_t c : nearest[i]) row[k++] = -2 - static_cast<std::int32_t>(c);
        std::sort(nearest[i].begin(), nearest[i].end());
        for (const std::uint32_t c : per_shot[i])
            if (!std::binary_search(nearest[i].begin(), nearest[i].end(), c)) row[k++] = static_cast<std::int32_t>(c);
    }
    return most;
}

}  // namespace

namespace {

// The knobs of kernels/hemicube.cl the host must agree with: it sizes buffers and launches by
// them, so a kernel built with another tile or counter-copy count than the host's overruns its
// buffers. A -D override of one sets the host's value too, within what the kernels take: tiles of
// at least 4 cells and at most 64 copies keep the tile counters of N = 4096 (3 (N / tile)² copies
// times) within the kernels' 32-bit ints; the scan's work-group is a power of two; raster_records
// steps 4 or 8 cells a row. Device limits (work-items per group) are checked by the engine.
struct Knob {
    enum class Rule { range, power_of_two, either };  // lo..hi; a power of two in it; lo or hi
    std::string_view macro;
    int lo, hi;
    Rule rule;
    void (*set)(OpenCLTuning&, int);
};
const Knob kKnobs[] = {
    {"HEMIRAD_TILE", 4, 64, Knob::Rule::range, [](OpenCLTuning& t, int v) { t.tile = v; }},
    {"HEMIRAD_WG", 1, 1024, Knob::Rule::range, [](OpenCLTuning& t, int v) { t.work_group = v; }},
    {"HEMIRAD_SCAN_WG", 1, 1024, Knob::Rule::power_of_two, [](OpenCLTuning& t, int v) { t.scan_work_group = v; }},
    {"HEMIRAD_RASTER_WG", 1, 1024, Knob::Rule::range, [](OpenCLTuning& t, int v) { t.raster_work_group = v; }},
    {"HEMIRAD_COUNT_COPIES", 1, 64, Knob::Rule::range, [](OpenCLTuning& t, int v) { t.count_copies = v; }},
    {"HEMIRAD_LANES", 4, 8, Knob::Rule::either, [](OpenCLTuning& t, int v) { t.lanes = v; }},
    {"HEMIRAD_SETUP_LANES", 0, 1, Knob::Rule::either, [](OpenCLTuning& t, int v) { t.setup_lanes = v != 0; }},
    {"HEMIRAD_CULL", 0, 1, Knob::Rule::either, [](OpenCLTuning& t, int v) { t.cull = v != 0; }},
};

std::string knob_rule(const Knob& k) {
    if (k.rule == Knob::Rule::either) return fmt::format("{} or {}", k.lo, k.hi);
    return fmt::format("{}in [{}, {}]", k.rule == Knob::Rule::power_of_two ? "a power of two " : "", k.lo, k.hi);
}

bool knob_accepts(const Knob& k, long v) {
    if (k.rule == Knob::Rule::either) return v == k.lo || v == k.hi;
    return v >= k.lo && v <= k.hi && (k.rule != Knob::Rule::power_of_two || (v & (v - 1)) == 0);
}

}  // namespace

void apply_build_options(OpenCLTuning& tuning, const std::string& text) {
    std::istringstream words(text);
    std::vector<std::string> tokens;
    for (std::string word; words >> word;) tokens.push_back(word);
    std::string passed;  // what is not a knob goes to the compiler as it was
    for (std::size_t i = 0; i < tokens.size(); ++i) {
        std::string option = tokens[i], definition;
        if (option == "-D" || option == "-U") {  // "-D NAME=V", two words
            if (i + 1 < tokens.size()) definition = tokens[++i];
            option += " " + definition;
        } else if (option.rfind("-D", 0) == 0 || option.rfind("-U", 0) == 0) {
            definition = option.substr(2);
        } else {
            passed += " " + option;
            continue;
        }
        const std::string macro = definition.substr(0, definition.find('='));
        if (macro.rfind("HEMIRAD_", 0) != 0) {
            passed += " " + option;
            continue;
        }
        const Knob* knob = nullptr;
        std::string names;
        for (const Knob& k : kKnobs) {
            if (k.macro == macro) knob = &k;
            names += fmt::format("{}{}", names.empty() ? "" : ", ", k.macro);
        }
        if (!knob) throw std::invalid_argument(fmt::format("'{}': {} is no tuning knob of the kernels ({})", option, macro, names));
        if (option[1] == 'U')
            throw std::invalid_argument(fmt::format("'{}': the host sizes its buffers by {}; it can be set, not undefined", option, macro));
        // "-DNAME" alone defines it as 1, as the compiler reads it.
        const std::string value = definition.size() > macro.size() ? definition.substr(macro.size() + 1) : "1";
        const bool digits = !value.empty() && value.size() <= 9 && value.find_first_not_of("0123456789") == std::string::npos;
        if (!digits || !knob_accepts(*knob, std::stol(value)))
            throw std::invalid_argument(fmt::format("'{}': {} must be {}", option, macro, knob_rule(*knob)));
        knob->set(tuning, static_cast<int>(std::stol(value)));
        tuning.overrides += fmt::format("{}{}={}", tuning.overrides.empty() ? "" : " ", macro, value);
    }
    if (!passed.empty()) tuning.extra_options += (tuning.extra_options.empty() ? "" : " ") + passed.substr(1);
}

OpenCLTuning default_tuning(const ocl::DeviceInfo& device) {
    for (const auto& entry : kTuningTable)
        if (entry.type == device.type) return entry.tuning;
    return {};
}

OpenCLFault parse_fault(const std::string& text) {
    OpenCLFault fault;
    for (std::size_t start = 0, end = 0; end < text.size(); start = end + 1) {
        end = std::min(text.find(',', start), text.size());
        const std::string item = text.substr(start, end - start);
        const std::size_t colon = item.find(':');
        const std::string name = item.substr(0, colon),
                          count = colon == std::string::npos ? "" : item.substr(colon + 1);
        if (name == "device") {
            if (count.rfind("opencl:", 0) != 0)
                throw std::invalid_argument(fmt::format("'{}': expected device:opencl:P.D", item));
            fault.device = count;
            continue;
        }
        if (name == "stage") {
            if (count != "solve" && count != "refine" && count != "gather" && count != "output")
                throw std::invalid_argument(
                    fmt::format("'{}': expected stage:solve, stage:refine, stage:gather or stage:output", item));
            fault.stage = count;
            continue;
        }
        std::size_t* const field = name == "oom-above"     ? &fault.oom_above
                                   : name == "fail-after"  ? &fault.fail_after
                                   : name == "wrong-after" ? &fault.wrong_after
                                                           : nullptr;
        if (!field || count.empty() || count.size() > 9 || count.find_first_not_of("0123456789") != std::string::npos)
            throw std::invalid_argument(fmt::format("'{}': expected oom-above:K, fail-after:K, wrong-after:K, device:opencl:P.D or stage:NAME", item));
        *field = std::stoul(count);
    }
    return fault;
}

OpenCLFault fault_from_environment() {
    const char* text = std::getenv("HEMIRAD_FAULT");
    try {
        return parse_fault(text ? text : "");
    } catch (const std::invalid_argument& e) {
        throw InputError(fmt::format("HEMIRAD_FAULT={}: {}", text, e.what()));
    }
}

OpenCLTuning tuning_from_environment(const ocl::DeviceInfo& device) {
    OpenCLTuning tuning = default_tuning(device);
    if (const char* extra = std::getenv("HEMIRAD_OPENCL_OPTIONS"); extra && *extra) {
        try {
            apply_build_options(tuning, extra);
        } catch (const std::invalid_argument& e) {
            throw InputError(fmt::format("HEMIRAD_OPENCL_OPTIONS={}: {}", extra, e.what()));
        }
    }
    if (const char* cull = std::getenv("HEMIRAD_CULL"); cull && std::string_view(cull) == "0") tuning.cull = false;
    if (const char* occlusion = std::getenv("HEMIRAD_OCCLUSION"); occlusion && *occlusion) {
        const std::string_view value(occlusion);
        if (value != "0" && value != "1")
            throw InputError(fmt::format("HEMIRAD_OCCLUSION={}: must be 0 (off) or 1 (always on)", value));
        tuning.occlusion = value == "0" ? Occlusion::off : Occlusion::on;
    }
    if (const char* share = std::getenv("HEMIRAD_OCCLUDER_SHARE"); share && *share) {
        const std::string_view value(share);
        const bool digits = value.size() <= 4 && value.find_first_not_of("0123456789") == std::string_view::npos;
        tuning.occluder_share = digits ? std::atoi(share) : 0;
        if (tuning.occluder_share < 1)
            throw InputError(fmt::format("HEMIRAD_OCCLUDER_SHARE={}: must be a whole number from 1 to 9999", value));
    }
    return tuning;
}

OpenCLEngine::OpenCLEngine(const mesh::Mesh& mesh, ocl::Context& context, const Settings& settings)
    : OpenCLEngine(mesh, context, settings, default_tuning(context.info())) {}

OpenCLEngine::OpenCLEngine(const mesh::Mesh& mesh, ocl::Context& context, const Settings& settings,
                           const OpenCLTuning& tuning, const OpenCLFault& fault)
    : OpenCLEngine(mesh, nullptr, context, settings, tuning, fault) {}

OpenCLEngine::OpenCLEngine(const mesh::Mesh& mesh, const DeviceMesh& packed, ocl::Context& context,
                           const Settings& settings, const OpenCLTuning& tuning, const OpenCLFault& fault)
    : OpenCLEngine(mesh, &packed, context, settings, tuning, fault) {}

OpenCLEngine::OpenCLEngine(const mesh::Mesh& mesh, const DeviceMesh* packed, ocl::Context& context,
                           const Settings& settings, const OpenCLTuning& tuning, const OpenCLFault& fault)
    : mesh_(mesh),
      context_(context),
      settings_(settings),
      tuning_(tuning),
      fault_(fault) {
    const ocl::DeviceInfo& info = context.info();
    if (settings.hemicube < 8 || settings.hemicube % 2 != 0 || settings.hemicube > kMaxHemicube)
        throw InternalError("hemicube resolution must be even, at least 8 and at most 4096");
    if (!info.fp64)
        throw InternalError(
            fmt::format("{}: needs cl_khr_fp64 (double precision) for results that match the reference", info.name));
    if (!info.int64_atomics)
        throw InternalError(
            fmt::format("{}: needs cl_khr_int64_base_atomics for deterministic form-factor sums", info.name));
    if (tuning.tile < 1 || tuning.work_group < 1 || tuning.scan_work_group < 1 || tuning.raster_work_group < 1 ||
        tuning.count_copies < 1 || (tuning.lanes != 4 && tuning.lanes != 8) ||
        (tuning.scan_work_group & (tuning.scan_work_group - 1)) != 0)
        throw InternalError("OpenCL tuning: tile and work-group sizes must be positive, the scan's a power of two");

    const bool lanes = tuning.setup_lanes;  // the layout setup reads; the other is not uploaded
    if (packed && (!packed->has(lanes ? Packing::lanes : Packing::elements) ||
                   packed->patches.size() != mesh.patches.size() ||
                   (lanes ? packed->lanes.size() != lane_groups(mesh) : packed->elements.size() != mesh.elements.size())))
        throw InternalError("OpenCL engine: the packed mesh is not this mesh's, or lacks the layout this device reads");
    eps_ = packed ? packed->eps : base_plane_epsilon(mesh);  // exactly the reference's clip distance

    // Never -cl-fast-relaxed-math or -cl-mad-enable: the kernel must round like the reference.
    // -w: a compiler's warnings are not the user's (PoCL's clang, on a CPU without AVX-512,
    // warned about each double8 argument's ABI and printed "157 warnings generated." on stderr).
    options_ = fmt::format(
        "-cl-std=CL1.2 -w -DHEMIRAD_TILE={} -DHEMIRAD_WG={} -DHEMIRAD_SCAN_WG={} -DHEMIRAD_RASTER_WG={} "
        "-DHEMIRAD_COUNT_COPIES={} -DHEMIRAD_LANES={} -DHEMIRAD_SETUP_LANES={} -DHEMIRAD_CULL={}",
        tuning.tile, tuning.work_group, tuning.scan_work_group, tuning.raster_work_group, tuning.count_copies,
        tuning.lanes, tuning.setup_lanes ? 1 : 0, tuning.cull ? 1 : 0);
    if (!tuning.extra_options.empty()) options_ += " " + tuning.extra_options;
    cl::Program& program = context.program(std::string(ocl::kernel_source("hemicube.cl")), options_);
    setup_ = cl::Kernel(program, "setup");
    scan_ = cl::Kernel(program, "scan");
    scatter_ = cl::Kernel(program, "scatter");
    raster_ = cl::Kernel(program, tuning.raster_per_record ? "raster_records" : "raster");
    if (tuning.setup_lanes) cull_ = cl::Kernel(program, "cull_clusters");
    check_layout(context, program);
    const auto check_group = [&](cl::Kernel& kernel, const char* name, int size) {
        const cl::Device& device = context.device();
        std::size_t most = kernel.getWorkGroupInfo<CL_KERNEL_WORK_GROUP_SIZE>(device);
        // On a CPU a work-group's private memory lives on the stack of the thread that runs it:
        // at most half of that stack (PoCL reports a nominal 1 KB a work-item; raster_records'
        // per-cell winners are ours to count).
        if (info.type == "cpu") {
            const std::string_view kernel_name(name);
            const double counted = kernel_name == "raster" && tuning.raster_per_record ? raster_records_private_bytes(tuning)
                                   : kernel_name == "setup" || kernel_name == "scatter" ? kSetupPrivateBytes
                                                                                         : 0.0;
            const double per_item =
                std::max(double(kernel.getWorkGroupInfo<CL_KERNEL_PRIVATE_MEM_SIZE>(device)), counted);
            if (per_item > 0.0)
                most = std::min(most, std::max<std::size_t>(1, std::size_t(0.5 * double(worker_stack_bytes()) / per_item)));
        }
        // And the local memory it declares must fit the device's.
        const cl_ulong local = kernel.getWorkGroupInfo<CL_KERNEL_LOCAL_MEM_SIZE>(device);
        if (local > device.getInfo<CL_DEVICE_LOCAL_MEM_SIZE>())
            throw InternalError(fmt::format("{}: kernel {} needs {} bytes of local memory, the device has {}", info.name,
                                            name, local, device.getInfo<CL_DEVICE_LOCAL_MEM_SIZE>()));
        if (static_cast<std::size_t>(size) > most && !tuning.overrides.empty())
            throw InputError(fmt::format("HEMIRAD_OPENCL_OPTIONS ({}): on {} kernel {} runs at most {} work-items per "
                                         "group, these knobs ask for {}",
                                         tuning.overrides, info.name, name, most, size));
        if (static_cast<std::size_t>(size) > most)
            throw InternalError(
                fmt::format("{}: kernel {} runs at most {} work-items per group, the tuning asks for {}", info.name,
                            name, most, size));
    };
    check_group(setup_, "setup", tuning.work_group);
    check_group(scatter_, "scatter", tuning.work_group);
    check_group(scan_, "scan", tuning.scan_work_group);
    check_group(raster_, "raster", raster_group_size());

    // Tiles: face by face, row-major within a face.
    const int n = settings.hemicube;
    tiles_x_ = (n + tuning.tile - 1) / tuning.tile;
    tile_base_[0] = 0;
    for (int face = 0; face < kFaces; ++face) {
        const int tiles_y = (face_rows(face) + tuning.tile - 1) / tuning.tile;
        tile_base_[static_cast<std::size_t>(face) + 1] =
            tile_base_[static_cast<std::size_t>(face)] + tiles_x_ * tiles_y;
    }

    // Clusters, a setup work-group's elements each (lanes setup): their bounding spheres, for
    // select_clusters on the host. (Clusters of near lane groups, in the Morton order of their
    // spheres, were tried: at city:1M their spheres hid fewer groups, 37% against 40% at N = 64,
    // and setup, reading scattered groups, took 40% longer.)
    if (tuning.setup_lanes)
        for (std::size_t first = 0; first < mesh.elements.size(); first += cluster_elements())
            cluster_bounds_.push_back(bounding_sphere(mesh, first, cluster_elements()));
    // Fixed point: 2^62 per unit of form factor; the whole table sums to 1, far below 2^63. In
    // the order the raster reads it: tile by tile (the tiles' global order), each tile's T×T
    // cells row by row, zero where a tile overhangs its face, so that a tile's reads are one
    // block (row-major, a tile's rows at N = 1024 lay 8 KB apart and 41% of raster_records'
    // samples waited on them). Zero-padded: raster_records reads whole lane groups, up to 7
    // entries past the last cell.
    // Two tables, one after the other (HrShot::table picks): the form factors of patches' shots,
    // then, for a mesh with lights, the solid angles of lights' shots (Weights).
    const std::size_t tile = static_cast<std::size_t>(tuning.tile);
    const std::size_t table_cells = static_cast<std::size_t>(tile_base_[kFaces]) * tile * tile;
    const bool lights = !mesh.lights.empty();
    std::vector<hr_long> delta_fixed((lights ? 2 : 1) * table_cells + 8, 0);
    for (const Weights weights : {Weights::form_factor, Weights::solid_angle}) {
        if (weights == Weights::solid_angle && !lights) break;
        // the table in doubles only while it is converted (25 MB at N = 1024)
        const DeltaFormFactors delta(n, weights);
        const std::size_t base = weights == Weights::form_factor ? 0 : table_cells;
        for (int face = 0; face < kFaces; ++face)
            for (int j = 0; j < delta.rows(face); ++j)
                for (int i = 0; i < n; ++i) {
                    const std::size_t t = static_cast<std::size_t>(tile_base_[static_cast<std::size_t>(face)] +
                                                                   (j / tuning.tile) * tiles_x_ + i / tuning.tile);
                    const double f = delta.table()[delta.offset(face) + static_cast<std::size_t>(j) * n + i];
                    delta_fixed[base + t * tile * tile + static_cast<std::size_t>(j % tuning.tile) * tile +
                                static_cast<std::size_t>(i % tuning.tile)] =
                        static_cast<hr_long>(std::llround(std::ldexp(f, HR_FIXED_SHIFT)));
                }
    }

    cl::Context& cl_context = context.context();
    cl::CommandQueue& queue = context.queue();
    if (tuning.setup_lanes) {  // regions for two records an element, a quarter of the clusters: grown as shots need
        group_capacity_ = tuning.group_capacity > 0
                              ? tuning.group_capacity
                              : static_cast<std::uint32_t>(kInitialRecordsPerElement * cluster_elements());
        record_rows_ = std::max<std::size_t>(1, setup_groups() / 4);
    }
    list_capacity_ = tuning.list_capacity > 0
                         ? tuning.list_capacity
                         : static_cast<std::uint32_t>(initial_list_entries(double(record_slots())));
    try {
        // The layout setup reads (the other a buffer of one entry: it is still an argument). Without
        // a packing given, packed here piece by piece, so that the mesh is never held twice.
        const auto upload_packed = [&](auto* tag, std::size_t count, const auto* whole, auto pack) {
            using T = std::remove_pointer_t<decltype(tag)>;
            cl::Buffer buffer(cl_context, CL_MEM_READ_ONLY, std::max<std::size_t>(1, count) * sizeof(T));
            if (whole) {
                if (count > 0) queue.enqueueWriteBuffer(buffer, CL_TRUE, 0, count * sizeof(T), whole);
                return buffer;
            }
            const std::size_t piece = std::max<std::size_t>(1, (std::size_t{4} << 20) / sizeof(T));
            std::vector<T> staging(std::min(piece, count));
            for (std::size_t first = 0; first < count; first += piece) {
                const std::size_t n = std::min(piece, count - first);
                pack(mesh, first, n, staging.data());
                queue.enqueueWriteBuffer(buffer, CL_TRUE, first * sizeof(T), n * sizeof(T), staging.data());
            }
            return buffer;
        };
        elements_ = upload_packed(static_cast<HrElement*>(nullptr), lanes ? 0 : mesh.elements.size(),
                                  packed ? packed->elements.data() : nullptr, pack_elements);
        element_lanes_ = upload_packed(static_cast<HrElementLanes*>(nullptr), lanes ? lane_groups(mesh) : 0,
                                       packed ? packed->lanes.data() : nullptr, pack_lanes);
        patches_ = packed ? upload(cl_context, queue, packed->patches) : upload(cl_context, queue, pack_patches(mesh));
        std::vector<double> spheres;  // for setup's test of whole clusters
        for (const std::array<double, 4>& b : cluster_bounds_) spheres.insert(spheres.end(), b.begin(), b.end());
        cluster_spheres_ = upload(cl_context, queue, spheres);
        delta_fixed_ = upload(cl_context, queue, delta_fixed);
        allocate_batch(1);
    } catch (const cl::Error& e) {
        throw ocl::DeviceError(
            fmt::format("{}: cannot hold the mesh ({} elements) and one shot at N = {}: {} failed: {}", info.name,
                        mesh.elements.size(), settings.hemicube, e.what(), ocl::error_name(e.err())));
    }
}

void OpenCLEngine::allocate_batch(std::size_t shots) {
    if (shots > fault_.oom_above)
        throw cl::Error(CL_MEM_OBJECT_ALLOCATION_FAILURE, "clCreateBuffer (HEMIRAD_FAULT oom-above)");
    cl::Context& cl_context = context_.context();
    const std::size_t counters = counter_entries();
    const auto buffer = [&](std::size_t per_shot_bytes) {
        return cl::Buffer(cl_context, CL_MEM_READ_WRITE, shots * per_shot_bytes);
    };
    // The batch's shots but the first, which goes by value (batch_shot in the kernels).
    shots_ = cl::Buffer(cl_context, CL_MEM_READ_ONLY, std::max<std::size_t>(1, shots - 1) * sizeof(HrShot));
    allocate_records(shots);
    group_records_ = buffer(setup_groups() * sizeof(hr_uint));
    tile_counts_ = buffer(counters * sizeof(hr_uint));
    counts_zero_ = false;
    offsets_ = buffer((counters + 1) * sizeof(hr_uint));
    clusters_ = buffer(setup_groups() * sizeof(hr_int));
    occluders_ = buffer(setup_groups() * sizeof(hr_int));
    hidden_ = buffer(setup_groups() * sizeof(hr_int));
    hidden_host_.assign(shots * setup_groups(), 0);
    block_depth_ = buffer(depth_blocks() * sizeof(hr_double));
    cursors_ = buffer(counters * sizeof(hr_uint));
    lists_ = buffer(std::size_t{list_capacity_} * sizeof(hr_uint));
    ids_buffer_ = buffer(cells() * sizeof(hr_int));
    sums_ = buffer(sum_stride() * sizeof(hr_long));
    sums_host_.assign(shots * sum_stride(), 0);
    ids_.assign(shots, {});  // read back only when asked for (last_ids: tests and --verify)
    ids_stale_.assign(shots, false);
    batch_capacity_ = shots;
}

void OpenCLEngine::release_batch() {
    for (cl::Buffer* b : {&shots_, &records_, &boxes_, &group_records_, &tile_counts_, &offsets_, &clusters_,
                          &occluders_, &hidden_, &block_depth_, &cursors_, &lists_, &ids_buffer_, &sums_})
        *b = cl::Buffer();
    batch_capacity_ = 0;
    counts_zero_ = false;
    last_batch_ = 0;
}

std::size_t OpenCLEngine::raster_group_size() const {
    return static_cast<std::size_t>(tuning_.raster_per_record ? tuning_.raster_work_group
                                                              : tuning_.tile * tuning_.tile);
}

std::size_t OpenCLEngine::preferred_batch() const {
    constexpr std::size_t kShotsPerUnit = 8, kMostPreferred = 1024;
    // The host holds a batch's rows: at most an entry (12 bytes) per element each, kept within
    // 512 MiB (a 1M-element scene: the default 64).
    constexpr double kRowBytes = 512.0 * (1 << 20);
    std::size_t batch = kDefaultBatch;
    if (context_.info().type == "gpu") {
        batch = std::clamp<std::size_t>(kShotsPerUnit * std::size_t(std::max(0, context_.info().compute_units)),
                                        kDefaultBatch, kMostPreferred);
        const double rows = kRowBytes / (12.0 * std::max<double>(1.0, double(mesh_.elements.size())));
        batch = std::max(kDefaultBatch, std::min(batch, static_cast<std::size_t>(rows)));
    }
    return batch;  // (a batch past what the device's memory holds runs as several launches)
}

std::size_t OpenCLEngine::max_batch() const {
    return std::min(batch_limit_, memory_batch());
}

double OpenCLEngine::shot_bytes(double elements, int hemicube) {
    // As allocate_batch sizes them on a CPU (lanes setup): records and boxes, the regions of
    // every cluster at their initial capacity (a quarter of them at first, grown with the clusters
    // in front of a shot: half the scene for most shooters, all of it for some), the initial lists,
    // the ids (on the device; the host reads them back only when asked), the sums (device and host).
    const double records = std::max(1.0, elements * kInitialRecordsPerElement);
    const double lists = initial_list_entries(records);
    const double cells = 3.0 * double(hemicube) * double(hemicube);
    return records * double(sizeof(HrRecord) + sizeof(HrBox)) + lists * sizeof(hr_uint) +
           cells * sizeof(hr_int) + 2.0 * (elements + 5.0) * sizeof(hr_long);
}

std::size_t OpenCLEngine::memory_batch() const {
    const std::size_t per_shot = record_slots() * (sizeof(HrRecord) + sizeof(HrBox)) +
                                 std::size_t{list_capacity_} * sizeof(hr_uint) + cells() * sizeof(hr_int) +
                                 sum_stride() * sizeof(hr_long);
    const std::size_t budget =
        tuning_.batch_memory > 0 ? tuning_.batch_memory : launch_budget(context_.info().type == "cpu", context_.info().global_memory);
    return std::max<std::size_t>(1, budget / per_shot);
}

std::size_t OpenCLEngine::record_slots() const {
    if (tuning_.setup_lanes) return std::max<std::size_t>(1, record_rows_ * group_capacity_);
    return std::max<std::size_t>(1, mesh_.elements.size() * kFaces);  // a record per element and face at most
}

void OpenCLEngine::allocate_records(std::size_t shots) {
    records_ = cl::Buffer(context_.context(), CL_MEM_READ_WRITE, shots * record_slots() * sizeof(HrRecord));
    boxes_ = cl::Buffer(context_.context(), CL_MEM_READ_WRITE, shots * record_slots() * sizeof(HrBox));
}

std::size_t OpenCLEngine::setup_groups() const {
    const std::size_t wg = static_cast<std::size_t>(tuning_.work_group);
    const std::size_t items =
        tuning_.setup_lanes ? (mesh_.elements.size() + HR_SETUP_LANES - 1) / HR_SETUP_LANES : mesh_.elements.size();
    return std::max<std::size_t>(1, (items + wg - 1) / wg);
}

std::size_t OpenCLEngine::cluster_elements() const {
    return static_cast<std::size_t>(tuning_.work_group) * HR_SETUP_LANES;
}

std::size_t OpenCLEngine::counter_entries() const {
    return static_cast<std::size_t>(tile_base_[kFaces]) * static_cast<std::size_t>(tuning_.count_copies);
}

std::size_t OpenCLEngine::sum_stride() const {
    // Per element; the blocked share, the list entries needed, the lane groups tested for
    // occlusion and those hidden, the most records a setup work-group made.
    return mesh_.elements.size() + 5;
}

std::size_t OpenCLEngine::depth_blocks() const {
    const std::size_t n = static_cast<std::size_t>(settings_.hemicube), b = HR_DEPTH_BLOCK;
    const std::size_t across = (n + b - 1) / b;
    return across * across + 4 * across * ((n / 2 + b - 1) / b);
}

OpenCLEngine::LaunchNeeds OpenCLEngine::run_batch(const std::vector<ShotRequest>& requests) {
    if (++launches_ > fault_.fail_after)
        throw cl::Error(CL_INVALID_COMMAND_QUEUE, "clEnqueueNDRangeKernel (HEMIRAD_FAULT fail-after)");
    const std::size_t batch = requests.size();
    const auto launch_start = Clock::now();
    std::vector<HrShot> shots(batch);
    for (std::size_t i = 0; i < batch; ++i) {
        const Frame frame = make_frame(mesh_, requests[i].shooter, settings_.seed, requests[i].shot);
        HrShot& shot = shots[i];
        shot = {};
        copy3(frame.origin, shot.origin);
        copy3(frame.u, shot.u);
        copy3(frame.v, shot.v);
        copy3(frame.w, shot.w);
        shot.eps = eps_;
        shot.n = settings_.hemicube;
        // The patches a shot skips (shot_skips): a cell's own and its twin's, none for a cluster.
        const ShotSkips skips = shot_skips(mesh_, requests[i].shooter);
        shot.shooter = skips.own == mesh::kNoPatch ? -1 : static_cast<hr_int>(skips.own);
        shot.twin = skips.twin == mesh::kNoPatch ? -1 : static_cast<hr_int>(skips.twin);
        shot.elements = static_cast<hr_int>(mesh_.elements.size());
        shot.patches = static_cast<hr_int>(mesh_.patches.size());
        shot.tiles_x = tiles_x_;
        std::copy(tile_base_.begin(), tile_base_.end(), shot.tile_base);
        shot.list_capacity = list_capacity_;
        shot.group_capacity = group_capacity_;
        shot.group_rows = static_cast<hr_uint>(record_rows_);
        shot.table = weights_of(requests[i].shooter) == Weights::solid_angle ? 1 : 0;
    }
    // Every kernel's arguments, bound here only: the first shot by value, the rest of the batch
    // through shots_ (batch_shot in the kernels).
    const HrShot& first = shots[0];
    // Lanes setup: a work-group per cluster in front of the shooter (the most any shot has).
    std::size_t groups =
        tuning_.setup_lanes ? select_clusters(cluster_bounds_, shots, tuning_.cull, shot_clusters_, cluster_rows_)
                            : setup_groups();
    // Occlusion culling: where shots have enough clusters in front for some to hide others, an
    // occluder pass over the nearest of them first (the same kernels), whose depths setup then
    // culls by. It changes no cell: what it hides could not have won one.
    const bool can_cull = tuning_.occlusion != Occlusion::off && tuning_.setup_lanes && tuning_.raster_per_record &&
                          tuning_.tile % HR_DEPTH_BLOCK == 0 && groups >= kOcclusionMinClusters;
    const bool occlusion = can_cull && (tuning_.occlusion == Occlusion::on || occlusion_pays());
    const std::size_t occluder_groups =
        occlusion ? select_occluders(cluster_bounds_, shots, shot_clusters_, tuning_.occluder_share, occluder_rows_,
                                     cluster_rows_, groups)
                  : 0;
    if (tuning_.setup_lanes && groups > record_rows_) {  // more clusters in front than the regions hold: grow
        record_rows_ = std::min(setup_groups(), std::max(groups, record_rows_ + record_rows_ / 4));
        for (HrShot& shot : shots) shot.group_rows = static_cast<hr_uint>(record_rows_);
        allocate_records(batch_capacity_);
    }
    const auto write_clusters = [&] {  // cluster_rows_ as it stands
        context_.queue().enqueueWriteBuffer(clusters_, CL_TRUE, 0, cluster_rows_.size() * sizeof(std::int32_t),
                                            cluster_rows_.data());
    };
    if (tuning_.setup_lanes) write_clusters();
    if (occlusion)
        context_.queue().enqueueWriteBuffer(occluders_, CL_TRUE, 0, occluder_rows_.size() * sizeof(std::int32_t),
                                            occluder_rows_.data());
    // occluded: the occluder pass has drawn the depths, and setup tests each lane group by them.
    const auto bind_setup = [&](const cl::Buffer& rows, bool occluded) {
        bind(setup_, first, shots_, elements_, element_lanes_, patches_, records_, boxes_, group_records_,
             tile_counts_, sums_, rows, block_depth_, hr_int{occluded ? 1 : 0});
    };
    const auto bind_scan = [&](std::size_t launch_groups) {
        bind(scan_, first, shots_, tile_counts_, offsets_, cursors_, sums_, group_records_,
             static_cast<hr_int>(launch_groups));
    };
    bind(scatter_, first, shots_, boxes_, group_records_, cursors_, lists_);
    const auto bind_raster = [&](bool occluder_pass) {
        bind(raster_, first, shots_, records_, boxes_, offsets_, lists_, delta_fixed_, ids_buffer_, sums_, block_depth_,
             hr_int{occluder_pass ? 1 : 0});
    };

    // Dimension 1 of every kernel is the shot within the batch.
    cl::CommandQueue& queue = context_.queue();
    const std::size_t elements = mesh_.elements.size();
    const std::size_t tiles = static_cast<std::size_t>(tile_base_[kFaces]);
    const std::size_t wg = static_cast<std::size_t>(tuning_.work_group);
    const std::size_t scan_wg = static_cast<std::size_t>(tuning_.scan_work_group);
    const std::size_t raster_wg = raster_group_size();
    const std::size_t raster_items = tuning_.raster_per_record ? round_up(tiles, raster_wg) : tiles * raster_wg;
    // setup counts into the tile counts and scan leaves them at zero again, so they need
    // zeroing only when new, or when a launch before this one failed part-way.
    if (!counts_zero_)
        queue.enqueueFillBuffer(tile_counts_, hr_uint{0}, 0, batch_capacity_ * counter_entries() * sizeof(hr_uint));
    counts_zero_ = false;
    // Blocking: `shots` is local, and an exception thrown by a later enqueue would free it.
    if (batch > 1) queue.enqueueWriteBuffer(shots_, CL_TRUE, 0, (batch - 1) * sizeof(HrShot), shots.data() + 1);
    const auto run = [&](cl::Kernel& kernel, std::size_t items, std::size_t group, cl::Event* event) {
        queue.enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(items, batch), cl::NDRange(group, 1), nullptr,
                                   event);
    };
    const auto seconds = [](const cl::Event& e) {
        return 1e-9 * static_cast<double>(e.getProfilingInfo<CL_PROFILING_COMMAND_END>() -
                                          e.getProfilingInfo<CL_PROFILING_COMMAND_START>());
    };
    // scatter reads the records of setup's work-groups, one work-group each.
    std::array<cl::Event, 4> occluder_events;
    std::array<cl::Event, kStages> events;  // 0 and 6 unused (the occluder pass's, above; the reads', read_sums)
    if (occlusion) {  // its raster writes every tile's depth, but for lists that overflowed: zero, no culling
        queue.enqueueFillBuffer(block_depth_, hr_double{0.0}, 0, batch * depth_blocks() * sizeof(hr_double));
        bind_setup(occluders_, false);
        bind_scan(occluder_groups);
        run(setup_, occluder_groups * wg, wg, &occluder_events[0]);
        run(scan_, scan_wg, scan_wg, &occluder_events[1]);
        run(scatter_, occluder_groups * wg, wg, &occluder_events[2]);
        bind_raster(true);
        run(raster_, raster_items, raster_wg, &occluder_events[3]);
        // Whole clusters against those depths, then the final pass's rows without the hidden ones.
        bind(cull_, first, shots_, element_lanes_, clusters_, static_cast<hr_int>(groups),
             block_depth_, cluster_spheres_, hidden_);
        run(cull_, round_up(groups, wg), wg, &events[1]);
        queue.enqueueReadBuffer(hidden_, CL_TRUE, 0, batch * groups * sizeof(hr_int), hidden_host_.data());
        groups = drop_hidden_clusters(batch, groups);
        write_clusters();
    }
    bind_setup(clusters_, occlusion);
    bind_scan(groups);
    bind_raster(false);
    const std::size_t group_items = groups * wg;
    run(setup_, group_items, wg, &events[2]);
    run(scan_, scan_wg, scan_wg, &events[3]);
    run(scatter_, group_items, wg, &events[4]);
    run(raster_, raster_items, raster_wg, &events[5]);
    // The sums, then per shot the list entries it needed (from scan).
    const std::vector<cl::Event> reads = read_sums(batch);
    counts_zero_ = true;  // scan has run
    if (occlusion)
        for (const cl::Event& e : occluder_events) stage_seconds_[0] += seconds(e);
    for (std::size_t s = occlusion ? 1 : 2; s + 1 < kStages; ++s) stage_seconds_[s] += seconds(events[s]);
    for (const cl::Event& e : reads) stage_seconds_[kStages - 1] += seconds(e);
    // Wall time, not device time: occlusion culling's host work (the occluders' choice, the
    // verdicts read back and the rows cut between the passes) is part of its cost.
    if (can_cull && tuning_.occlusion == Occlusion::measured)
        record_occlusion_cost(occlusion, seconds_since(launch_start) / static_cast<double>(batch));
    LaunchNeeds needed;
    for (std::size_t i = 0; i < batch; ++i) {
        const hr_long* tail = sums_host_.data() + i * sum_stride() + elements;
        needed.list_entries = std::max(needed.list_entries, static_cast<std::uint32_t>(tail[1]));
        needed.group_records = std::max(needed.group_records, static_cast<std::uint32_t>(tail[4]));
    }
    if (occlusion)
        for (std::size_t i = 0; i < batch; ++i) {
            occlusion_tested_ += static_cast<std::uint64_t>(sums_host_[i * sum_stride() + elements + 2]);
            occlusion_hidden_ += static_cast<std::uint64_t>(sums_host_[i * sum_stride() + elements + 3]);
        }
    return needed;
}

std::vector<cl::Event> OpenCLEngine::read_sums(std::size_t batch) {
    cl::CommandQueue& queue = context_.queue();
    std::vector<cl::Event> reads;
    const auto read = [&](std::size_t first, std::size_t count) {
        reads.emplace_back();
        queue.enqueueReadBuffer(sums_, CL_FALSE, first * sizeof(hr_long), count * sizeof(hr_long),
                                sums_host_.data() + first, nullptr, &reads.back());
    };
    if (!tuning_.setup_lanes) {  // setup per patch clears and fills every element's sum
        read(0, batch * sum_stride());
    } else {
        // Only the clusters set up hold this shot's sums (the host reads no others), so a shot
        // that culled most of a large scene reads what it kept, not a sum per element: runs of
        // kept clusters, joined across gaps of up to kReadGap clusters (a read command costs
        // PoCL about as much as that many clusters' bytes), then the shot's tail.
        constexpr std::size_t kReadGap = 32;
        const std::size_t elements = mesh_.elements.size(), size = cluster_elements();
        for (std::size_t i = 0; i < batch; ++i) {
            const std::size_t base = i * sum_stride();
            const std::vector<std::uint32_t>& kept = shot_clusters_[i];  // ascending
            for (std::size_t k = 0; k < kept.size();) {
                std::size_t last = k;
                while (last + 1 < kept.size() && kept[last + 1] - kept[last] <= kReadGap) ++last;
                const std::size_t first = kept[k] * size, end = std::min(elements, (kept[last] + 1) * size);
                read(base + first, end - first);
                k = last + 1;
            }
            read(base + elements, sum_stride() - elements);
        }
    }
    reads.back().wait();  // an in-order queue: the reads before it are done too
    return reads;
}

std::size_t OpenCLEngine::drop_hidden_clusters(std::size_t batch, std::size_t length) {
    const auto kept = [&](std::size_t i, std::size_t g) {
        return cluster_rows_[i * length + g] != -1 && hidden_host_[i * length + g] == 0;
    };
    std::size_t most = 1;
    for (std::size_t i = 0; i < batch; ++i) {
        std::size_t count = 0;
        for (std::size_t g = 0; g < length; ++g) count += kept(i, g) ? 1 : 0;
        most = std::max(most, count);
    }
    // In place: row i moves from i * length to i * most <= it, each entry to an index <= its own,
    // so nothing is overwritten before it is read.
    std::vector<std::uint32_t> hidden;
    for (std::size_t i = 0; i < batch; ++i) {
        hidden.clear();
        std::size_t k = i * most;
        for (std::size_t g = 0; g < length; ++g) {
            const std::int32_t entry = cluster_rows_[i * length + g];
            if (kept(i, g)) {
                cluster_rows_[k++] = entry;
            } else if (entry >= 0) {
                hidden.push_back(static_cast<std::uint32_t>(entry));
                occlusion_tested_ += static_cast<std::uint64_t>(hidden_host_[i * length + g]);
                occlusion_hidden_ += static_cast<std::uint64_t>(hidden_host_[i * length + g]);
            }
        }
        std::fill(cluster_rows_.begin() + static_cast<std::ptrdiff_t>(k),
                  cluster_rows_.begin() + static_cast<std::ptrdiff_t>((i + 1) * most), -1);
        std::sort(hidden.begin(), hidden.end());
        std::vector<std::uint32_t>& in_front = shot_clusters_[i];
        in_front.erase(std::remove_if(in_front.begin(), in_front.end(),
                                      [&](std::uint32_t c) { return std::binary_search(hidden.begin(), hidden.end(), c); }),
                       in_front.end());
    }
    cluster_rows_.resize(batch * most);
    return most;
}

bool OpenCLEngine::occlusion_pays() {
    ++occlusion_launches_;
    if (occlusion_samples_[1] < kOcclusionWarm) return true;
    if (occlusion_samples_[0] < kOcclusionWarm) return false;
    const bool on_cheaper = occlusion_cost_[1] <= occlusion_cost_[0];
    return occlusion_launches_ % kOcclusionProbe == 0 ? !on_cheaper : on_cheaper;
}

void OpenCLEngine::record_occlusion_cost(bool on, double seconds_per_shot) {
    const std::size_t mode = on ? 1 : 0;
    const double n = static_cast<double>(++occlusion_samples_[mode]);
    const double weight = n <= kOcclusionWarm ? 1.0 / n : 0.125;
    occlusion_cost_[mode] += weight * (seconds_per_shot - occlusion_cost_[mode]);
}

void OpenCLEngine::shoot(const ShotRequest& request, ShotResult& out) {
    shoot_batch({request}, batch_results_);
    out = std::move(batch_results_[0]);
}

void OpenCLEngine::shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    // Directional lights' parallel shots on this device's raster (kernels/parallel.cl, the
    // host's bits), one at a time; the hemicubes together.
    if (!split_directional(shots, hemicubes_, place_)) {
        place_.clear();
        owner_ = {};  // up to 64 MiB: not kept past the lights
        shoot_hemicubes(shots, out);
        return;
    }
    out.resize(shots.size());
    if (!parallel_) parallel_ = std::make_unique<OpenCLParallelRaster>(context_);
    owner_shot_ = 0;
    for (std::size_t i = 0; i < shots.size(); ++i)
        if (place_[i] < 0) owner_shot_ = i;
    for (std::size_t i = 0; i < shots.size(); ++i)
        if (place_[i] < 0)
            shoot_directional(mesh_, shots[i], out[i], parallel_.get(), i == owner_shot_ ? &owner_ : nullptr);
    shoot_hemicubes(hemicubes_, rows_);
    for (std::size_t i = 0; i < shots.size(); ++i)
        if (place_[i] >= 0) out[i] = std::move(rows_[static_cast<std::size_t>(place_[i])]);
}

void OpenCLEngine::shoot_hemicubes(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    out.resize(shots.size());
    if (shots.empty()) return;
    // Per-shot buffers are large (records for every element and face): a batch beyond the
    // memory budget runs as several launches, with the same results.
    const std::size_t most = max_batch();
    if (shots.size() > most) {
        std::vector<ShotResult> part;
        std::size_t first = 0;
        for (; first + most < shots.size(); first += most) {
            shoot_hemicubes({shots.begin() + static_cast<std::ptrdiff_t>(first),
                         shots.begin() + static_cast<std::ptrdiff_t>(first + most)},
                        part);
            std::move(part.begin(), part.end(), out.begin() + static_cast<std::ptrdiff_t>(first));
        }
        shoot_hemicubes({shots.begin() + static_cast<std::ptrdiff_t>(first), shots.end()}, part);
        std::move(part.begin(), part.end(), out.begin() + static_cast<std::ptrdiff_t>(first));
        ids_first_ += first;  // the id buffers kept are the last part's
        return;
    }
    ids_first_ = 0;
    try {
        shoot_fitting(shots, out);
    } catch (const cl::Error& e) {
        const std::string& device = context_.info().name;
        if (!ocl::out_of_memory(e.err()))
            throw ocl::DeviceError(fmt::format("{}: {} failed: {}", device, e.what(), ocl::error_name(e.err())));
        if (shots.size() == 1)  // (CL_OUT_OF_RESOURCES may also mean a kernel that failed)
            throw ocl::DeviceError(fmt::format("{}: a single shot of {} elements at N = {} does not fit: {} failed: {}",
                                               device, mesh_.elements.size(), settings_.hemicube, e.what(),
                                               ocl::error_name(e.err())));
        // Whatever the failed launch left queued goes first; its buffers are freed for fewer.
        try {
            context_.queue().finish();
        } catch (const cl::Error&) {
        }
        release_batch();
        batch_limit_ = (shots.size() + 1) / 2;
        if (tuning_.on_shrink) tuning_.on_shrink(shots.size(), batch_limit_, ocl::error_name(e.err()));
        shoot_hemicubes(shots, out);
    }
}

void OpenCLEngine::shoot_fitting(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    if (shots.size() > batch_capacity_) allocate_batch(shots.size());
    for (;;) {
        const LaunchNeeds needed = run_batch(shots);
        const bool lists_full = needed.list_entries > list_capacity_;
        const bool regions_full = tuning_.setup_lanes && needed.group_records > group_capacity_;
        if (!lists_full && !regions_full) break;
        // The raster skipped the batch, or some records were only counted: grow what was short
        // with some headroom and run it again.
        if (lists_full) {
            list_capacity_ = static_cast<std::uint32_t>(
                std::min<std::uint64_t>(0xffffffffu, needed.list_entries + needed.list_entries / 4ull));
            lists_ = cl::Buffer(context_.context(), CL_MEM_READ_WRITE,
                                batch_capacity_ * std::size_t{list_capacity_} * sizeof(hr_uint));
        }
        if (regions_full) {  // at most a record per element and face
            group_capacity_ = static_cast<std::uint32_t>(std::min<std::size_t>(
                kFaces * cluster_elements(), needed.group_records + needed.group_records / 4u));
            allocate_records(batch_capacity_);
        }
    }
    last_batch_ = shots.size();
    std::fill(ids_stale_.begin(), ids_stale_.end(), true);

    const std::size_t elements = mesh_.elements.size();
    // A power of two: the product is exact, as ldexp would be, at a fraction of the cost (a shot
    // of a large scene converts a sum per element).
    const double unit = std::ldexp(1.0, -HR_FIXED_SHIFT);
    // Each shot's row on a host thread of its own: a GPU returns a batch of shots at once, and
    // one core scanning a sum per element of each (8 MB a shot at 1M elements) would hold it.
    parallel::for_each(shots.size(), 1, [&](std::size_t i) {
        const hr_long* sums = sums_host_.data() + i * sum_stride();
        const auto fixed_to_double = [unit](hr_long s) { return static_cast<double>(s) * unit; };
        if (tuning_.setup_lanes) {  // only the clusters set up hold sums (ascending); the rest see nothing
            out[i].clear();
            for (std::uint32_t c : shot_clusters_[i]) {
                const std::size_t first = c * cluster_elements();
                const std::size_t end = std::min(elements, first + cluster_elements());
                for (std::size_t k = first; k < end; ++k)
                    if (sums[k] != 0) out[i].push(static_cast<std::uint32_t>(k), fixed_to_double(sums[k]));
            }
        } else {
            out[i].assign_nonzero(sums, elements, fixed_to_double);
        }
        out[i].blocked = static_cast<double>(sums[elements]) * unit;
        if (launches_ > fault_.wrong_after && !out[i].F.empty())  // HEMIRAD_FAULT: what a broken device might return
            *std::max_element(out[i].F.begin(), out[i].F.end()) *= 1.25;
    });
}

const std::vector<std::int32_t>* OpenCLEngine::last_ids(std::size_t shot) const {
    if (!place_.empty()) {  // a batch with directional shots: the last one's grid, and the hemicubes' ids
        if (shot >= place_.size()) return nullptr;
        if (place_[shot] < 0) return shot == owner_shot_ ? &owner_ : nullptr;
        shot = static_cast<std::size_t>(place_[shot]);
    }
    if (shot < ids_first_ || shot - ids_first_ >= last_batch_) return nullptr;
    const std::size_t i = shot - ids_first_;
    if (ids_stale_[i] || ids_[i].empty()) {
        ids_[i].resize(cells());
        context_.queue().enqueueReadBuffer(ids_buffer_, CL_TRUE, i * cells() * sizeof(std::int32_t),
                                           cells() * sizeof(std::int32_t), ids_[i].data());
        ids_stale_[i] = false;
    }
    return &ids_[i];
}

}  // namespace hemirad::formfactor
