// The bake pipeline behind `hemirad bake`: load, mesh, solve, write — all or nothing.
#pragma once

#include <atomic>
#include <cstdint>
#include <ostream>
#include <stdexcept>
#include <string>

namespace hemirad::cli {

struct BakeOptions {
    std::string scene;
    std::string output = "out";
    std::string device = "auto";
    std::string quality = "default";  // draft | default | high: the settings below not given
    int hemicube = 0;             // N: top face N×N, side faces N×N/2; even; 0: from the quality
    double patch_size = 0.0;      // 0: scene diagonal × the quality's patch fraction
    double element_size = 0.0;    // 0: patch size / the quality's elements per patch edge
    double threshold = -1.0;      // < 0: from the quality
    long max_passes = 100000;
    int batch = 1;                // shooters per engine call (the top-K unshot patches)
    std::uint64_t seed = 1;
    bool verify = false;
    long verify_every = 1;        // with --verify: check shots 0, K, 2K, …
    std::string camera;
    long preview_every = 0;
    int image_width = 640;
    bool quiet = false;
    bool progress = false;                       // draw a progress line (a TTY and not --quiet)
    const std::atomic<bool>* interrupted = nullptr;  // set by SIGINT/SIGTERM
};

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
const QualityPreset& quality_preset(const std::string& name);

// Thrown when the user interrupts a bake; nothing has been written (or it was removed).
struct Interrupted : std::runtime_error {
    Interrupted() : std::runtime_error("interrupted") {}
};

// Runs a bake. Throws InputError (exit 2), Interrupted, or other exceptions (exit 1). On any
// throw, whatever this run wrote under the output directory has been removed.
void run_bake(const BakeOptions& options);

void list_devices(std::ostream& out, bool json);

}  // namespace hemirad::cli
