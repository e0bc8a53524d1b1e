// `hemirad bench --effects`: what simulating only the effects a scene calls for saves. Bakes the
// bundled scenes with each effect as the planner decides it (scene/effects.h) and forced the
// other way, in-process through bake::run, and reports for each pair the time (median over
// repeats), the stages that changed, the effect decisions and how far every mesh's average
// radiosity moved.
#pragma once

#include <nlohmann/json.hpp>
#include <ostream>
#include <string>

namespace hemirad::bench {

struct EffectsBenchOptions {
    std::string device = "auto";        // the bakes' --device (auto, ref, opencl, opencl:P.D)
    bool quick = false;                 // --quality draft and one repeat: seconds in all
    int repeats = 0;                    // timed repeats of every bake; 0: 3, or 1 with quick
    std::string scenes_dir = "scenes";  // holds cornell_box.gltf and empty_room.gltf
};

// The largest relative difference of any mesh's average radiosity between two report.json
// `meshes` arrays (the same meshes in the same order), over meshes and channels:
// |a − b| / max(|a|, |b|, 1e-12). Returns {value, mesh, channel}. Throws InternalError when the
// two arrays do not list the same meshes.
nlohmann::ordered_json max_mesh_difference(const nlohmann::ordered_json& a, const nlohmann::ordered_json& b);

// Runs the cases, prints a Markdown table to `log` and returns
// {version, machine, device, settings, cases: [...]}; each case has its planned and forced bake
// (options, median total and stage times, passes, elements, effects), time_ratio (forced ÷
// planned total), saved_s, max_mesh_difference and a note. Every bake writes into one temporary
// directory under std::filesystem::temp_directory_path(), removed on return or throw. Throws
// InputError when a scene is missing.
nlohmann::ordered_json run_effects_bench(const EffectsBenchOptions& options, std::ostream& log);

}  // namespace hemirad::bench
