// Memory and time estimates for planning a bake before its mesh is built.
#include "bake/budget.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/memory.h"
#include "formfactor/opencl_engine.h"
#include "solve/matrix.h"
#include "solve/refinement.h"

namespace hemirad::bake {
namespace {

// Refinement is taken to double the elements (the Cornell box: 8316 → 15204).
constexpr double kRefinedGrowth = 2.0;
// Per element of the progressive solver: incident light, the round's snapshot, and the two
// per-element vectors its queries return (dvec3 each).
constexpr double kProgressivePerElement = 4 * 24.0;
// unshot, shot; hit share, round's unshot; shots, the counters of the first few (Settings::rotations)
const double kProgressivePerPatch = 2 * 24.0 + 2 * 8.0 + 4.0 + solve::Settings{}.rotations * 8.0;
// The progressive solve's row memo (formfactor::RowCacheEngine): this much per element, within
// [kRowCacheMin, kRowCacheMax].
constexpr double kRowCachePerElement = 256.0;
constexpr double kRowCacheMin = 64.0 * (1 << 20), kRowCacheMax = 512.0 * (1 << 20);
// Output: the welded mesh (about four vertices per element: position, normal, radiosity, index)
// and the render: the image (RGB floats, 12 B a pixel) and the automatic exposure's luminances
// (a double a pixel, reserved whole), then the PNG's bytes (3 B) once those are gone; the
// renderer's supersampled strip is a few rows (output/render.cpp). Measured: 14.5 B a pixel at
// 4096² and 8192² (peak resident less a 256² bake's; the closed room). It was 320 B, counting
// the strip for every row: --image-width 16384 "needed 86 GB".
constexpr double kWeldedPerElement = 4 * 40.0;
// A parallel shot's bytes per element: its projection (the element's corners and plane, ~130 B),
// its record (corners in fixed point, box and plane, ~116 B) and a few bin entries.
constexpr double kParallelPerElement = 260.0;
constexpr double kRenderPerPixel = 12.0 + 8.0;

// The model's constants, fitted on 2 EPYC cores through PoCL after clusters, sparse rows and
// occlusion culling (ratios matter): an OpenCL shot at N = 256 over ~8k elements, which grows
// about as the square root of the elements (2.5 ms at 8k, 6.0 ms at 59k, 23.5 ms at 508k: culling
// and clusters) and linearly with N (4.2× from 256 to 1024 on the Cornell box, 1.8× on the 1M
// city); the reference's, which grows as N²; host work per element per progressive pass (a pass
// walks only the elements its shot reached); one Gauss–Seidel multiply-add; a row's
// sparsification per element.
constexpr double kShotSeconds = 2.5e-3;
constexpr double kReferenceShotSeconds = 6.8e-3;
constexpr double kPassSecondsPerElement = 1e-9;
constexpr double kSweepSecondsPerEntry = 1e-9;
constexpr double kRowSecondsPerElement = 3e-9;
// Progressive shots to converge: about 3 rounds of the patches on the Cornell box (2787 passes,
// 924 patches), fewer rounds as scenes grow, whose patches mostly hold little light: 0.69 rounds
// for a 15k-patch room, 0.35–0.62 for 28k–34k-patch cities and furniture. About 3·√(924·P).
constexpr double kProgressiveRounds = 3.0;
constexpr double kRoundsPatches = 924.0;
constexpr double kOpenCLRuntimeBytes = 200e6;

bool direct_only(const BakeShape& s) { return !s.matrix.interreflection; }

double expected_sweeps(const BakeShape& s) { return solve::Matrix::expected_sweeps(s.max_reflectance, s.matrix.tolerance); }

double engine_bytes(const BakeShape& s, double elements, int hemicube, double shots) {
    if (!s.opencl) return 3.0 * hemicube * hemicube * 17.0 + elements * sizeof(double);  // reference: cells, one F
    const double per_shot = formfactor::OpenCLEngine::shot_bytes(elements, hemicube);
    // A launch's budget, one shot at least: a CPU's, whose buffers are the host memory planned for.
    const double budget = std::max(per_shot, double(formfactor::OpenCLEngine::launch_budget(true, 0)));
    return formfactor::DeviceMesh::bytes(elements, s.counts.patches) + std::min(shots * per_shot, budget);
}

}  // namespace

double MemoryEstimate::total() const {
    double sum = 0.0;
    for (const MemoryPart& p : parts) sum += p.bytes;
    return sum;
}

double MemoryEstimate::needed() const {
    double sum = 0.0;
    for (const MemoryPart& p : parts)
        if (p.what != "refinement") sum += p.bytes;
    return sum;
}

std::string MemoryEstimate::describe() const {
    std::string out;
    for (const MemoryPart& p : parts) {
        if (!out.empty()) out += ", ";
        out += p.what + " " + format_bytes(p.bytes);
    }
    return out;
}

MemoryEstimate estimate_memory(const BakeShape& s, const std::string& solver) {
    const double E = s.counts.elements, P = s.counts.patches;
    const double mesh = E * sizeof(mesh::Element) + P * sizeof(mesh::Patch);
    MemoryEstimate m;
    m.parts.push_back({"mesh", mesh * (s.fallback_copy ? 2.0 : 1.0)});
    const bool matrix = solver == "matrix";
    m.parts.push_back({"engine", engine_bytes(s, E, s.hemicube, matrix ? s.matrix.batch : s.batch)});
    // PoCL and its LLVM, resident once loaded (195 MB measured on `hemirad devices`, 2 EPYC cores).
    if (s.opencl) m.parts.push_back({"opencl runtime", kOpenCLRuntimeBytes});
    if (matrix) {
        m.parts.push_back({"matrix", solve::Matrix::estimate_bytes(P, E, s.matrix)});
    } else {
        // A step's rows, up to s.batch of them, each sparse: an element index and an F for at
        // most every element, or every cell of the hemicube (3N²).
        const double row_entries = std::min(E, 3.0 * s.hemicube * s.hemicube);
        m.parts.push_back({"solver", E * kProgressivePerElement + P * kProgressivePerPatch +
                                         std::max(1, s.batch) * row_entries * (sizeof(std::uint32_t) + sizeof(double))});
        m.parts.push_back({"row cache", row_cache_bytes(s)});
    }
    if (s.refine_levels > 0) {
        const double refined = E * kRefinedGrowth;
        const int top = solve::regather_hemicube(s.hemicube, s.refine_levels);
        m.parts.push_back({"refinement", refined * sizeof(mesh::Element) + engine_bytes(s, refined, top, 64) +
                                             refined * 2 * 24.0});
    }
    m.parts.push_back({"output", E * (s.refine_levels > 0 ? kRefinedGrowth : 1.0) * kWeldedPerElement +
                                     s.pixels * kRenderPerPixel});
    // A parallel shot, while it runs: per element its projection, record and bin entries, and per
    // cell its owner twice (the raster's and, on a device, its copy).
    if (s.parallel_cells > 0.0)
        m.parts.push_back({"parallel shots", E * (s.refine_levels > 0 ? kRefinedGrowth : 1.0) * kParallelPerElement +
                                                 2.0 * s.parallel_cells * sizeof(std::int32_t)});
    return m;
}

double row_cache_bytes(const BakeShape& s) {
    return std::clamp(s.counts.elements * kRowCachePerElement, kRowCacheMin, kRowCacheMax);
}

double refinement_room(const BakeShape& s, const std::string& solver, double limit) {
    // Bytes per refined element: itself, its engine share, its re-gathered light and its output.
    const double per_element = sizeof(mesh::Element) + 2 * 24.0 + kWeldedPerElement +
                               (s.opencl ? formfactor::DeviceMesh::bytes(1.0, 0.0) : sizeof(double));
    const double spent = estimate_memory(s, solver).needed();
    return std::max(s.counts.elements, (limit - spent) / per_element);
}

namespace {

// A hemicube of a batch (the lights'; the final gather has its own model, stage_progress.h) on
// OpenCL, per unit of the element scale below: its cells' cost at N = 256, or its elements' setup
// where N is small. Measured on 2 PoCL cores: 200,000 point lights in the closed room (N = 256)
// 0.71 ms a hemicube, the Cornell box's gather (N = 96) 0.25 ms a point; --gather 32 on a
// 300k-element jungle about 2 ms a point.
constexpr double kBatchedCellSeconds = 1.42e-3, kBatchedSetupSeconds = 1.9e-4;

}  // namespace

double batched_shot_seconds(const BakeShape& s, int hemicube) {
    const double scale = std::max(0.5, std::sqrt(s.counts.elements / 8316.0));
    const double n = double(hemicube) / 256.0;
    if (!s.opencl) return kReferenceShotSeconds * scale * n * n;
    return scale * std::max(kBatchedSetupSeconds, kBatchedCellSeconds * n * n);
}

// A hemicube's seconds: it grows with the elements it sets up and the cells it draws.
double shot_seconds(const BakeShape& s, int hemicube) {
    const double scale = std::max(0.5, std::sqrt(s.counts.elements / 8316.0));
    const double n = double(hemicube) / 256.0;
    return s.opencl ? kShotSeconds * scale * std::max(1.0, n) : kReferenceShotSeconds * scale * std::max(1.0, n * n);
}

double expected_passes(const BakeShape& s) {
    const double P = s.counts.patches;
    return kProgressiveRounds * std::sqrt(std::min(P, kRoundsPatches) * P);
}

std::string format_duration(double seconds) {
    if (seconds < 90.0) return fmt::format("{:.0f} s", seconds);
    if (seconds < 5400.0) return fmt::format("{:.0f} min", seconds / 60.0);
    return fmt::format("{:.1f} h", seconds / 3600.0);
}

double TimeEstimate::total() const {
    double sum = 0.0;
    for (const auto& p : parts) sum += p.second;
    return sum;
}

std::string TimeEstimate::describe() const {
    std::string out;
    for (const auto& [what, seconds] : parts)
        if (seconds >= 1.0) out += (out.empty() ? "" : ", ") + what + " " + format_duration(seconds);
    return out;
}

TimeEstimate expected_bake_time(const BakeShape& s, const std::string& solver, double light_hemicubes,
                                double gather_points, double gather_point_seconds) {
    TimeEstimate e;
    // The matrix solve is counted work (a row per patch, then sweeps); progressive shooting's
    // passes depend on how the light spreads, and the model of them, made for choosing a solver,
    // was 5-15x long on real scenes (web, stylized and apartment exports): not said.
    if (solver == "matrix") e.parts.emplace_back("solve", expected_times(s).matrix);
    if (light_hemicubes > 0.0)
        e.parts.emplace_back("lights' hemicubes", light_hemicubes * batched_shot_seconds(s, s.hemicube));
    if (gather_points > 0.0) e.parts.emplace_back("final gather", gather_points * gather_point_seconds);
    return e;
}

SolverTimes expected_times(const BakeShape& s) {
    const double E = s.counts.elements, P = s.counts.patches;
    const double channels = s.matrix.grey ? 1.0 : 3.0;
    const double shot = shot_seconds(s, s.hemicube);
    const double passes = expected_passes(s);
    SolverTimes t;
    const double sweeps = direct_only(s) ? 0.0 : expected_sweeps(s);
    t.matrix = P * (shot + E * kRowSecondsPerElement) + sweeps * channels * P * P * kSweepSecondsPerEntry;
    t.progressive = passes * (shot + E * kPassSecondsPerElement);
    return t;
}

SolverChoice choose_solver(const BakeShape& s, double limit) {
    const double with_matrix = estimate_memory(s, "matrix").needed();
    if (with_matrix > 0.5 * limit)
        return {"progressive", fmt::format("the matrix solver would need about {} ({} patches), more than half of the "
                                           "{} the bake may use",
                                           format_bytes(with_matrix), s.counts.patches, format_bytes(limit))};
    if (direct_only(s)) return {"matrix", "direct light only is the emitters' rows"};
    // Timed as on OpenCL whatever the engine: the reference engine's slower, N²-scaling shots
    // tipped a tiny room at reflectance 0.999 to the matrix on `--device ref` and to progressive
    // shooting on OpenCL (0.72 s against 1.18 s, 0.435 s against 0.47 s), so the two engines
    // baked different bytes (the bake fuzzer's finding). The choice must not depend on the device.
    BakeShape timed = s;
    timed.opencl = true;
    const SolverTimes t = expected_times(timed);
    if (t.matrix <= t.progressive)
        return {"matrix", fmt::format("expected faster than progressive shooting ({:.3g} s against {:.3g} s: {} rows, "
                                      "{:.0f} Gauss-Seidel sweeps at reflectance up to {:.3g}) and it fits in memory "
                                      "({} of {})",
                                      t.matrix, t.progressive, s.counts.patches,
                                      expected_sweeps(s),
                                      s.max_reflectance, format_bytes(with_matrix), format_bytes(limit))};
    return {"progressive", fmt::format("expected faster than the matrix solver ({:.3g} s against {:.3g} s: "
                                       "{:.3g} Gauss-Seidel sweeps at reflectance up to {:.3g})",
                                       t.progressive, t.matrix,
                                       expected_sweeps(s),
                                       s.max_reflectance)};
}

}  // namespace hemirad::bake
