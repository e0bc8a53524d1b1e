// What a bake is asked for: the settings of `hemirad bake`, as the CLI parses them and tests and
// benchmarks give them.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>

namespace hemirad::formfactor {
struct ShotResult;
}

namespace hemirad::bake {

// The largest render, in pixels a side (--image-width, and the height its camera's aspect gives).
inline constexpr int kMaxImageSide = 16384;

struct Options {
    std::string scene;
    std::string output = "out";
    std::string device = "auto";
    std::string quality = "default";  // draft | default | high: the settings below not given
    int hemicube = 0;             // N: top face N×N, side faces N×N/2; even; 0: from the quality
    double patch_size = 0.0;      // 0: scene diagonal × the quality's patch fraction
    double element_size = 0.0;    // 0: patch size / the quality's elements per patch edge
    double threshold = -1.0;      // < 0: from the quality
    long max_passes = -1;         // < 0: kDefaultMaxPasses or twice the patches, whichever is more (max_passes_for)
    int batch = 1;                // shooters per engine call (the top-K unshot patches)
    // > 0: the progressive solver's steps take the patches that hold at least this share of the
    // largest unshot flux, up to kSharedBatch (solve::Settings::batch_share), not the top `batch`:
    // kBatchShare without --batch, 0 with it.
    double batch_share = 0.0;
    int threads = 0;              // host threads of the host stages (core/parallel.h); 0: every core
    bool batch_given = false;     // --batch was given; else several devices or ranks raise it (planned_batch)
    int gather = -1;              // final gather hemicube N (0: none); < 0: from the quality
    int gather_passes = 0;        // final gathers, each from the last one's light; 0: from the quality
    int gather_refine = -1;       // gather refinement levels (solve::gather_contrasts); < 0: from the quality
    double gather_contrast = -1.0;  // … splitting elements whose vertices' light spans more than this share; < 0: the quality's
    // Gather hemicubes at most: a mesh with more output vertices is gathered sparsely (where the
    // light varies, interpolated between; solve/sparse_gather.h). 0: no limit, every vertex; < 0:
    // kMaxPlannedGather, or no limit where --gather is given.
    long gather_points = -1;
    std::string solver = "auto";  // auto | matrix | progressive
    std::string effects;          // overrides: "occlusion=off,colour=on,…" (scene::parse_effect_overrides)
    std::string output_mode = "scene";  // --output-mode scene|radiosity (output.h)
    std::string sun;              // --sun AZIMUTH,ELEVATION,LUX (scene::parse_sun); empty: none
    std::string sky;              // --sky RADIANCE[,ZENITH_RADIANCE] (scene::parse_sky); empty: none
    int refine_levels = 2;        // adaptive refinement: splits of one element at most
    double contrast = -1.0;       // … of neighbours whose irradiance differs by more than this share; < 0: the quality's
    std::uint64_t seed = 1;
    std::string checkpoint;       // progressive: write the solver's state here every checkpoint_every passes
    long checkpoint_every = 500;
    std::string resume;           // progressive: go on from this checkpoint
    // Clusters also join across gaps (mesh::Settings::cluster_apart); --no-cluster-apart: connected
    // faces only.
    bool cluster_apart = true;
    bool no_checkpoint = false;   // --no-checkpoint: no automatic checkpoint (bake/stage_checkpoint.h)
    bool verify = false;
    long verify_every = 1;        // with --verify: check shots 0, K, 2K, …
    std::string camera;
    // --look-from X,Y,Z --look-at X,Y,Z: a view the file lacks (both, or neither); --fov its
    // vertical field of view in degrees (0: the camera's, else 45.8°).
    std::string look_from, look_at;
    double fov = 0.0;
    // --exposure EV: render.png's linear radiance is scaled by 2^EV; NaN: automatic (the 90th
    // percentile of lit pixels at 0.6 linear).
    double exposure = std::numeric_limits<double>::quiet_NaN();
    long preview_every = 0;
    int image_width = 640;
    std::string max_memory;       // --max-memory SIZE; empty: the memory available (core/memory.h)
    bool strict_textures = false; // --strict-textures: a texture image missing or undecodable is exit 2, not a warning
    bool quiet = false;
    bool progress = false;                       // report progress (a TTY or --progress, and not --quiet)
    bool progress_tty = false;                   // ... as one line redrawn in place (a TTY), else a line every few seconds
    // Called with every shot the solve and refinement's re-gather take, as the solver sees it
    // (near-field corrected), so tests and the fuzzer can check what the engines return.
    std::function<void(const formfactor::ShotResult&)> on_shot;
};

// The batch a bake plans when --batch is not given: 1 on one device, else kShotsPerMember shots
// for each device and rank that shares it (at most 256), so that every member takes several
// chunks of each batch (formfactor::ShardedEngine). The rows do not depend on it; the order of
// shooting does, so a bake matches another with the same batch byte for byte.
inline constexpr std::size_t kShotsPerMember = 16;
int planned_batch(std::size_t members);

// Without --batch, a progressive step shoots every patch that holds at least kBatchShare of the
// largest unshot flux, up to kSharedBatch of them (solve::Settings::batch_share), whatever the
// devices or ranks: the bytes are the same on any number of them. Measured in the README's
// "Shooters that hold about as much go together" (bake timings, not a bench/ run).
inline constexpr double kBatchShare = 0.5;
inline constexpr int kSharedBatch = 256;
// The progressive solver's batch and share for `options` (batch_share > 0: kSharedBatch).
inline int progressive_batch(const Options& options) {
    return options.batch_share > 0.0 ? kSharedBatch : options.batch;
}

// The progressive solver's cap on passes for a mesh of `patches` patches: options.max_passes, or
// where it is < 0 (not given), 100,000 or twice the patches, whichever is more.
long max_passes_for(const Options& options, std::size_t patches);

}  // namespace hemirad::bake
