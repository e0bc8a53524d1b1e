// The `--quality` presets of a bake, shared with the benchmark, whose default scene meshing is
// the default preset's.
#pragma once

#include <fmt/core.h>

#include <string>

#include "core/error.h"

namespace hemirad {

// `--quality`: settings read off the Pareto front of per-pixel error against bake time on the
// Cornell box, against an independent converged path tracer (`hemirad bench --accuracy`,
// bench/results/accuracy.json and the README): each preset is a front point, draft the best within
// 1.5 s, default within 5 s, high the most accurate within about 3× the default's time. Options
// given on the command line override their part of the preset.
struct QualityPreset {
    const char* name;
    int hemicube;
    double patch_fraction;           // patch size = scene diagonal × this
    double elements_per_patch_edge;  // element size = patch size / this
    double threshold;
    double contrast;                 // adaptive refinement's --contrast
    int gather;                      // final gather hemicube N (solve/final_gather.h); 0: none
    int gather_passes;               // final gathers, each from the last one's light
    int gather_refine;               // gather refinement levels (solve::gather_contrasts); 0: none
    double gather_contrast;          // … splitting elements whose vertices' light spans more than this share
};
inline constexpr QualityPreset kQualityPresets[] = {
    // On the Cornell box (2 cores of an Intel Xeon, PoCL; `hemirad bench --accuracy`): per-pixel
    // RMS error and time. Before the final gather the defaults were 6.5% (draft 21%). A gather's
    // passes after the first re-use its rows (about 0.1 s each on the default): 2.16% with one,
    // 1.88% with two, 1.76% with three and four, where the fourth takes the worst face of the
    // blocks from -1.04% to -0.84%. Draft keeps one, for time: 5.58% in 1.2–1.3 s, 5.25% with two.
    // Gather refinement: draft 5.30% with two levels, 0.2 s more (over its 1.5 s on a busy machine).
    {"draft", 64, 1.0 / 8.0, 3.0, 1e-2, 0.5, 32, 1, 0, 0.5},
    // The default keeps N 256 for the solve: 1.76% against 1.84% at N 128 in about 1 s less, which
    // the Cornell box alone might pick, but which leaves small receivers of punctual lights (their
    // hemicubes are the solve's) 9% off and rows of elements along a crease 1.5% off. Gather
    // refinement takes it from 1.76% to 1.48% for 15% more gather points (see bake.cpp).
    {"default", 256, 1.0 / 16.0, 3.0, 1e-2, 0.5, 96, 4, 4, 0.5},
    // Gather N 192 and refinement at contrast 0.3: 1.03% (1.46% without the refinement and the
    // rim inset).
    {"high", 256, 1.0 / 16.0, 3.0, 1e-2, 0.25, 192, 4, 4, 0.3},
};
// The preset of that name; throws InputError for another name.
inline const QualityPreset& quality_preset(const std::string& name) {
    for (const QualityPreset& p : kQualityPresets)
        if (name == p.name) return p;
    throw InputError(fmt::format("--quality {}: expected draft, default or high", name));
}

}  // namespace hemirad
