// `hemirad bench`: shot throughput of every form-factor engine (the scalar reference, the Embree
// ray-casting peer, each OpenCL device) over scenes and hemicube resolutions, as ratios taken in
// one run, each result checked against the reference and set against the machine's limit.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace hemirad::bench {

struct ThroughputOptions {
    std::vector<std::string> scenes;   // glTF files or procedural:<triangles> (see scene/procedural.h)
    std::vector<int> hemicubes{256};   // N of each run, even, 8..4096
    std::vector<std::string> engines;  // ref, embree, opencl (every device), opencl:P.D; empty: all
    int shots = 16;                    // shots per engine per repeat
    int repeats = 5;
    int batch = 1;              // shots per shoot_batch call
    double patch_size = 0.0;    // 0: scene diagonal / 16, as a bake
    double element_size = 0.0;  // 0: patch size / 3
    std::uint64_t seed = 1;
    bool calibrate = true;  // measure each OpenCL device's fill rate and bandwidth
};

// A scene by name: procedural:<count> is generated, anything else loaded as glTF. `closed` is
// true where every direction from every patch hits a surface by construction (procedural
// scenes), so each shot's form factors and blocked share must sum to 1.
struct BenchScene {
    scene::Scene scene;
    bool closed = false;
};
BenchScene load_bench_scene(const std::string& spec);

// The machine a benchmark ran on: {cpu, hardware_threads}.
nlohmann::ordered_json machine_info();

// Runs every engine on every scene at every N; prints a Markdown table per scene to `log` and
// returns the JSON document ({machine, calibration, settings, results}). Throws InputError for
// bad scenes or options and formfactor::VerifyError when an engine fails a check.
nlohmann::ordered_json run_throughput(const ThroughputOptions& options, std::ostream& log);

}  // namespace hemirad::bench
