// `hemirad bench --accuracy`: what accuracy costs in time. Sweeps the settings a user picks
// (hemicube N, patch and element size, threshold, batching) on analytic configurations and on a
// room with an independent converged reference (bench/room_reference.h), records error and time
// per run, and derives the Pareto front and the `--quality` presets from it. The room's "solver"
// sweep also bakes it the way a bake plans it for this convex room (exact unoccluded form
// factors, the matrix solver, adaptive refinement) and the combinations in between, to show
// what those choices cost and buy; those runs stay out of the front and the presets.
#pragma once

#include <cstddef>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <vector>

namespace hemirad::bench {

struct AccuracyOptions {
    std::string engine = "auto";  // auto (the first OpenCL GPU, else device, else ref), ref, opencl:P.D
    bool quick = false;           // a smoke test: a few coarse runs against a coarser reference
};

// Returns {version, machine, accuracy: {device, analytic: [...], room: {reference, runs, pareto,
// presets}}} and prints the tables to `log`.
nlohmann::ordered_json run_accuracy(const AccuracyOptions& options, std::ostream& log);

// Presets come only from runs with a threshold of at most this: in the convex, unoccluded room
// the ambient term stands in for unshot light almost exactly, which a scene with shadows does
// not grant, so the room would reward stopping far too early.
inline constexpr double kPresetMaxThreshold = 1e-2;

// Whether a run (with threshold and optionally solver, exact, refine_levels) may enter the front
// and the presets: only the original kind of run, the progressive solver on the hemicube engine
// stack without refinement (solver "progressive", exact false, refine_levels 0; an absent field
// counts as that), with a threshold of at most kPresetMaxThreshold. The presets set N, meshing
// and threshold for every bake, so they are read off runs that depend on all of them and stay
// comparable from one benchmark to the next; the matrix solver, exact form factors and
// refinement are a scene's plan (src/bake/bake.cpp), not a quality setting.
bool preset_eligible(const nlohmann::ordered_json& run);

// Of `runs` (each with seconds, rms_rel_error, threshold and the fields preset_eligible reads),
// the indices of the eligible runs that no other eligible run beats in both time and error,
// fastest first.
std::vector<std::size_t> pareto_front(const nlohmann::ordered_json& runs);

// The --quality presets read off `front` against run 0 (a bake's defaults, which must be
// eligible): draft, the fastest front run within twice run 0's error; default, the fastest at
// most as wrong as run 0; high, the most accurate within 8x run 0's time. Each is a copy of its
// run with "run": its index.
nlohmann::ordered_json derive_presets(const nlohmann::ordered_json& runs, const std::vector<std::size_t>& front);

}  // namespace hemirad::bench
