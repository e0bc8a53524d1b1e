// `hemirad bench --scaling`: shot throughput and bake time against the number of MPI ranks and
// of devices sharing the batches, as ratios taken in one run. Run under mpirun to measure ranks
// (`mpirun -n 2 hemirad bench --scaling`): configuration k uses rank 0 and the first k − 1
// workers, so every count up to the world's is measured against one rank in the same run. With a
// device list (--device all, opencl:0.0,opencl:0.1) it also measures the first d devices of rank 0.
// Every configuration's rows are compared with the first one's, byte for byte. What it measures
// per shot (compute, the host's solver work, the bytes of requests and rows, the mesh's) is what
// bench/scaling_model.py predicts larger clusters from.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>

namespace hemirad::bench {

struct ScalingOptions {
    std::string scene = "city:100k";  // a glTF file or a generated scene (bench::load_bench_scene)
    std::string device = "auto";      // each rank's devices (choose_engine)
    int hemicube = 256;
    int shots = 96;    // shots per timed run
    int batch = 0;     // shots per engine call; 0: bake's plan for the most members measured
    int repeats = 3;   // timed runs per configuration (the median is reported)
    int passes = 0;    // progressive passes of the timed bake; 0: 2 × batch
    std::uint64_t seed = 1;
};

// Runs on rank 0 (the workers serve it); prints a Markdown table to `log` and returns
// {version, machine, settings, runs: [...], model_inputs}. Throws InputError for a bad scene and
// InternalError when a configuration's rows differ from the first one's.
nlohmann::ordered_json run_scaling_bench(const ScalingOptions& options, std::ostream& log);

}  // namespace hemirad::bench
