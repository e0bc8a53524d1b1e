// `hemirad bench`: shot throughput of every form-factor engine (the scalar reference, the Embree
// ray-casting peer, each OpenCL device) over scenes and hemicube resolutions, as ratios taken in
// one run, each result checked against the reference and set against the machine's limit.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <vector>

#include "formfactor/engine.h"
#include "mesh/mesh.h"
#include "scene/scene.h"

namespace hemirad::bench {

struct ThroughputOptions {
    std::vector<std::string> scenes;   // glTF files or generated specs: procedural:, city:, furniture:, foliage:<triangles>
    std::vector<int> hemicubes{256};   // N of each run, even, 8..4096
    std::vector<std::string> engines;  // ref, embree, opencl (every device), opencl:P.D; empty: all
    int shots = 16;                    // shots per engine per repeat
    int repeats = 5;
    std::vector<int> batches{1};  // shots per shoot_batch call: each is a run (1..4096)
    double patch_size = 0.0;    // 0: as a bake at the default quality (core/quality.h)
    double element_size = 0.0;  // 0: as a bake at the default quality
    std::uint64_t seed = 1;
    bool calibrate = true;  // measure each OpenCL device's fill rate and bandwidth
};

// What each engine owes the reference per shot (worst |ΔF| of an element, Σ|ΔF| over the shot):
// the hemicube engines the same cells, any difference is rounding; the ray caster the same but
// for cell centres within a float's rounding of an edge and depth ties, a few cells in a million.
struct Tolerance {
    double max_abs, l1;
};
inline constexpr Tolerance kExact{0.0, 0.0}, kRasterizer{1e-6, 1e-6}, kRayCaster{1e-3, 1e-3};

// How far one shot is from the reference's: the largest |ΔF| of an element, and Σ|ΔF| over the
// elements and the blocked share.
struct ShotDifference {
    double max_abs = 0.0, l1 = 0.0;
    bool within(const Tolerance& t) const { return max_abs <= t.max_abs && l1 <= t.l1; }
};
ShotDifference shot_difference(const formfactor::ShotResult& got, const formfactor::ShotResult& want);

// Over a run's repeats: the fastest, the median (the upper one of an even count) and the standard
// deviation as a percentage of the mean. `values` must not be empty.
struct Stats {
    double min = 0.0, median = 0.0, sigma_percent = 0.0;
};
Stats stats(std::vector<double> values);

// A scene by name: a generated spec (procedural:<count>, city:, furniture:, foliage:<count>; see
// gen/content_scenes.h) is generated, anything else loaded as glTF. `closed` is true where every
// direction from every patch hits a surface by construction (every generated kind but the open
// city), so each shot's form factors and blocked share must sum to 1.
struct BenchScene {
    scene::Scene scene;
    bool closed = false;
};
BenchScene load_bench_scene(const std::string& spec);

// The mesh a benchmark shoots in: the patch and element sizes of `options`, or where they are 0
// those of a bake at the default quality (core/quality.h).
mesh::Settings mesh_settings_for(const ThroughputOptions& options, const scene::Scene& s);

// The shots every engine is timed on: `count` patches spread over the scene (mesh `m`, which has
// patches), shot i with shot counter i (the seed stream).
std::vector<formfactor::ShotRequest> bench_shots(const mesh::Mesh& m, int count);
// The most shots one benchmark call may hold (--batch): a GPU fills at hundreds to thousands.
inline constexpr int kMaxBenchBatch = 4096;
// A markdown table of shots/s with a column per batch size: a row per scene, N, engine and
// device of `results` (run_throughput's rows), in the order they first appear.
std::string batch_table(const nlohmann::ordered_json& results, const std::vector<int>& batches);
// shots[first, first + batch), cut at the end: one engine call of a timed run.
std::vector<formfactor::ShotRequest> shots_from(const std::vector<formfactor::ShotRequest>& shots, std::size_t first,
                                                int batch);

// The machine a benchmark ran on: {cpu, hardware_threads}.
nlohmann::ordered_json machine_info();

// Runs every engine on every scene at every N; prints a Markdown table per scene to `log` and
// returns the JSON document ({machine, calibration, settings, results}). Throws InputError for
// bad scenes or options and formfactor::VerifyError when an engine fails a check.
nlohmann::ordered_json run_throughput(const ThroughputOptions& options, std::ostream& log);

}  // namespace hemirad::bench
