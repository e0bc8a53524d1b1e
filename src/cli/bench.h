// `hemirad bench`: throughput of the form-factor engines (bench/throughput.h) or the
// accuracy-against-time sweep (bench/accuracy.h), printed as tables and written as JSON.
#pragma once

#include <ostream>
#include <string>

#include "bench/accuracy.h"
#include "bench/throughput.h"

namespace hemirad::cli {

struct BenchCommand {
    bench::ThroughputOptions throughput;
    bool accuracy = false;        // the accuracy-against-time sweep instead of throughput
    bool quick = false;           // with accuracy: a smaller sweep
    std::string device = "auto";  // with accuracy: the engine of every run
    std::string json;             // also write the JSON document here (atomically)
};

// Runs the benchmark. Throws InputError (exit 2) for bad options or scenes, before any output
// file exists; the JSON file appears only complete.
void run_bench(const BenchCommand& command, std::ostream& log);

}  // namespace hemirad::cli
