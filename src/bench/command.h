// `hemirad bench`: throughput of the form-factor engines (bench/throughput.h), the
// accuracy-against-time sweep (bench/accuracy.h) or what planning the effects saves
// (bench/effects.h), printed as tables and written as JSON.
#pragma once

#include <ostream>
#include <string>

#include "bench/accuracy.h"
#include "bench/throughput.h"
#include "bench/scaling.h"

namespace hemirad::bench {

struct BenchCommand {
    bench::ThroughputOptions throughput;
    bool accuracy = false;        // the accuracy-against-time sweep instead of throughput
    bool effects = false;         // each effect as planned against forced, instead of throughput
    bool estimate = false;        // the progress line's estimate against the bakes' times (bench/estimate.h)
    bool scaling = false;         // throughput and bake time against ranks and devices (bench_scaling.h)
    ScalingOptions scaling_options;
    bool quick = false;           // with accuracy, effects or estimate: a smaller sweep
    std::string device = "auto";  // with accuracy or effects: the engine of every run
    std::string json;             // also write the JSON document here (atomically)
};

// Runs the benchmark. Throws InputError (exit 2) for bad options or scenes, before any output
// file exists; the JSON file appears only complete.
void run_bench(const BenchCommand& command, std::ostream& log);

}  // namespace hemirad::bench
