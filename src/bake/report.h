// report.json: what a bake did, from its stages' results (see DESIGN.md for the contract).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bake/engine_select.h"
#include "bake/stage_progress.h"
#include "bake/stages.h"
#include "core/timing.h"

namespace hemirad::bake {

struct StageCheckpoints;  // bake/stage_checkpoint.h

// The stages' clocks that are not in their results.
struct Timings {
    Clock::time_point start;          // of the bake
    double load = 0.0, mesh = 0.0, output = 0.0;
};

// Everything the report is made from.
struct Record {
    const Plan& plan;
    const Setup& setup;
    const Meshed& meshed;
    const scene::Scene& scene;
    const Lit& lit;
    const EngineChoice& choice;
    const nlohmann::ordered_json& fallback;  // the device that failed and why (null: none)
    std::size_t elements_before;             // before refinement
    const TimeEstimate& expected;
    double exposure;                         // render.png's scale
    const std::vector<std::string>& warnings;
    Timings timings;
    const StageCheckpoints* checkpoints = nullptr;  // where the bake kept its checkpoint, what it resumed
    const StageProgress* progress = nullptr;  // the time model's record (`estimate`); none: not written
};

// report.json's `estimate`: the time model's prediction per stage against the measurement
// (`now`: seconds into the bake as the report is made).
nlohmann::ordered_json estimate_json(const Eta& eta, double now);

nlohmann::ordered_json make_report(const Record& r);

// Writes the report to `file`; InternalError where a value is not finite (it would be written as
// null) or the file cannot be written.
void write_report(const Record& r, const std::filesystem::path& file);

}  // namespace hemirad::bake
