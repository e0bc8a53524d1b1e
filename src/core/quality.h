// The `--quality` presets of a bake, shared with the benchmark, whose default scene meshing is
// the default preset's.
#pragma once

#include <fmt/core.h>

#include <string>

#include "core/error.h"

namespace hemirad {

// `--quality`: settings read off the Pareto front of `hemirad bench --accuracy` (error against
// time on a room with an independent converged reference; bench/results/accuracy.json and the
// README). Options given on the command line override their part of the preset.
struct QualityPreset {
    const char* name;
    int hemicube;
    double patch_fraction;           // patch size = scene diagonal × this
    double elements_per_patch_edge;  // element size = patch size / this
    double threshold;
};
inline constexpr QualityPreset kQualityPresets[] = {
    // On the room: 0.18 s and 4.6% RMS error at the probes; the defaults (threshold 1e-3) 2.2 s, 2.3%.
    {"draft", 64, 1.0 / 8.0, 4.0, 1e-2},
    {"default", 256, 1.0 / 16.0, 3.0, 1e-2},  // 1.3 s, 2.2%
    {"high", 512, 1.0 / 24.0, 4.0, 1e-2},     // 8.8 s, 0.93%
};
// The preset of that name; throws InputError for another name.
inline const QualityPreset& quality_preset(const std::string& name) {
    for (const QualityPreset& p : kQualityPresets)
        if (name == p.name) return p;
    throw InputError(fmt::format("--quality {}: expected draft, default or high", name));
}

}  // namespace hemirad
