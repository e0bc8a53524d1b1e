// `hemirad bench --accuracy`: what accuracy costs in time. Sweeps the settings a user picks
// (hemicube N, patch and element size, threshold, batching) on analytic configurations and on a
// room with an independent converged reference (bench/room_reference.h), records error and time
// per run, and derives the Pareto front and the `--quality` presets from it.
#pragma once

#include <nlohmann/json.hpp>
#include <ostream>
#include <string>

namespace hemirad::bench {

struct AccuracyOptions {
    std::string engine = "auto";  // auto (the first OpenCL GPU, else device, else ref), ref, opencl:P.D
    bool quick = false;           // a few runs per sweep instead of the full sweep
};

// Returns {"accuracy": {device, analytic: [...], room: {reference, runs, pareto, presets}}} and
// prints the tables to `log`.
nlohmann::ordered_json run_accuracy(const AccuracyOptions& options, std::ostream& log);

}  // namespace hemirad::bench
