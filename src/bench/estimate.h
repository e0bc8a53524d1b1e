// `hemirad bench --estimate`: how good the progress line's time left is. Bakes generated scenes
// of a few sizes (and, given, glTF files) in-process through bake::run and reports each stage's
// predicted, re-fitted and measured seconds (report.json's `estimate`) and the bake's total as
// predicted at 10% of it, against the measured total.
#pragma once

#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <vector>

namespace hemirad::bench {

struct EstimateBenchOptions {
    std::string device = "auto";     // the bakes' --device
    bool quick = false;              // two small scenes at --quality draft: under a minute
    std::vector<std::string> scenes; // glTF files or generated specs; none: the default set
};

// The specs baked without scenes given: (spec, quality).
std::vector<std::pair<std::string, std::string>> estimate_bench_scenes(bool quick);

// Bakes them, prints a Markdown table to `log` and returns {version, device, bakes: [{scene,
// quality, triangles, elements, solver, estimate (report.json's), ratio_at_10_percent,
// ratio_at_end}]}. InputError for a scene that is neither a file nor a generated spec.
nlohmann::ordered_json run_estimate_bench(const EstimateBenchOptions& options, std::ostream& log);

}  // namespace hemirad::bench
