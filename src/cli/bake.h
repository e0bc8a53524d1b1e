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
    int hemicube = 256;           // N: top face N×N, side faces N×N/2; even
    double patch_size = 0.0;      // 0: scene diagonal × kDefaultPatchFraction
    double element_size = 0.0;    // 0: patch size / kDefaultElementsPerPatchEdge
    double threshold = 1e-3;
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

inline constexpr double kDefaultPatchFraction = 1.0 / 16.0;
inline constexpr double kDefaultElementsPerPatchEdge = 3.0;

// Thrown when the user interrupts a bake; nothing has been written (or it was removed).
struct Interrupted : std::runtime_error {
    Interrupted() : std::runtime_error("interrupted") {}
};

// Runs a bake. Throws InputError (exit 2), Interrupted, or other exceptions (exit 1). On any
// throw, whatever this run wrote under the output directory has been removed.
void run_bake(const BakeOptions& options);

void list_devices(std::ostream& out, bool json);

}  // namespace hemirad::cli
