// The OpenCL hemicube engine: kernels/hemicube.cl on one device, giving the scalar reference's
// result cell for cell (double precision, the same operations in the same order).
#pragma once

#include <array>
#include <algorithm>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "cl/runtime.h"
#include "formfactor/device_mesh.h"
#include "formfactor/engine.h"
#include "formfactor/hemicube.h"
#include "formfactor/parallel_opencl.h"

namespace hemirad::formfactor {

// Occlusion culling: never; on every launch that can (to measure); or where it pays, as measured
// launch by launch (the default: an occluder pass costs more than it saves where a shot sees most
// of what is in front of it, as in a room).
enum class Occlusion { off, on, measured };

// The tuning knobs of kernels/hemicube.cl, passed to the build as -D options.
struct OpenCLTuning {
    int tile = 16;                    // raster tile edge in cells
    bool raster_per_record = false;   // raster_records (a work-item per tile, CPUs) instead of raster (a cell each)
    int raster_work_group = 4;        // work-group size of raster_records; raster's is tile×tile
    int work_group = 64;              // work-group size of the per-patch and per-record kernels
    int scan_work_group = 256;        // the one work-group of the tile-offset scan, a power of two
    int count_copies = 1;             // copies of the per-tile counters (work-group mod copies): less contention
    int lanes = 4;                    // cells per row step of raster_records: 4 or 8
    bool setup_lanes = false;         // setup takes 8 elements per work-item in double8 lanes (CPUs)
    std::string extra_options;        // appended to the build options (never a knob above: apply_build_options)
    std::uint32_t list_capacity = 0;  // initial per-tile list entries; 0: from the mesh size (grows as needed)
    std::uint32_t group_capacity = 0;  // lanes setup: initial record slots per setup work-group; 0: two an element (grows)
    std::size_t batch_memory = 0;     // per-shot buffer bytes one launch may use; 0: launch_budget
    bool cull = true;                 // lanes setup skips clusters and groups behind the shooter (off: to measure)
    // Occlusion culling (lanes setup with raster_records): an occluder pass draws each shot's
    // nearest clusters first, one in `occluder_share` of those in front (at least one), and setup
    // then drops the lane groups its depths hide (group_hidden in the kernels).
    Occlusion occlusion = Occlusion::measured;
    int occluder_share = 16;
    // Told each time the device had not the memory for a batch of `shots` and the engine retried
    // it in parts of at most `limit` (the results do not change); `why`: the OpenCL error.
    std::function<void(std::size_t shots, std::size_t limit, const std::string& why)> on_shrink;
    std::string overrides;  // the knobs HEMIRAD_OPENCL_OPTIONS set ("HEMIRAD_TILE=8 ..."), for messages
};

// Faults the engine can be told to simulate (HEMIRAD_FAULT), so that what a bake does about a
// failing device can be tested on any device. Launches count from the engine's construction.
struct OpenCLFault {
    static constexpr std::size_t kNever = std::numeric_limits<std::size_t>::max();
    std::size_t oom_above = kNever;    // buffers for more shots than this fail as out of memory
    std::size_t fail_after = kNever;   // launches after this many fail as the device lost
    std::size_t wrong_after = kNever;  // launches after this many return a wrong form factor
    std::string device;                // only the engines on this device (opencl:P.D); empty: every device
    std::string stage;                 // the bake kills itself as this stage begins (bake::fault_point)
};

// HEMIRAD_FAULT's value: comma-separated oom-above:K, fail-after:K, wrong-after:K (K >= 0) and
// device:opencl:P.D (the faults hit that device alone, as one of several sharing a bake), and
// stage:solve, stage:refine, stage:gather or stage:output (the bake is killed as that stage begins, as by
// SIGKILL, to test that a rerun resumes from its checkpoint).
// Throws std::invalid_argument for anything else; an empty text is no fault.
OpenCLFault parse_fault(const std::string& text);

// The knobs for a device, from a small hand-edited table.
OpenCLTuning default_tuning(const ocl::DeviceInfo& device);
// Build options for the kernels (HEMIRAD_OPENCL_OPTIONS' text): a -D of a knob the host sizes
// buffers and launches by (HEMIRAD_TILE, HEMIRAD_COUNT_COPIES, …) sets it in `tuning`, so that
// host and kernels agree, and only within what the kernels take; anything else is appended to
// extra_options as it is. Throws std::invalid_argument naming the option for a value the kernels
// cannot take, an unknown HEMIRAD_ knob, or -U of a knob.
void apply_build_options(OpenCLTuning& tuning, const std::string& text);
// default_tuning with HEMIRAD_OPENCL_OPTIONS applied (apply_build_options; InputError naming it
// when it cannot be), culling off where HEMIRAD_CULL=0, occlusion culling off or always on where
// HEMIRAD_OCCLUSION=0 or 1 and its occluder share from HEMIRAD_OCCLUDER_SHARE: what bakes and
// benchmarks use.
OpenCLTuning tuning_from_environment(const ocl::DeviceInfo& device);
// HEMIRAD_FAULT parsed (no fault where unset). Throws InputError naming it when malformed.
OpenCLFault fault_from_environment();

class OpenCLEngine final : public Engine {
public:
    // Builds the kernels (cached by the context) and uploads the mesh and the delta-form-factor
    // table. Throws InternalError when the device lacks cl_khr_fp64 or
    // cl_khr_int64_base_atomics, ocl::BuildError when the kernels do not build.
    OpenCLEngine(const mesh::Mesh& mesh, ocl::Context& context, const Settings& settings);
    OpenCLEngine(const mesh::Mesh& mesh, ocl::Context& context, const Settings& settings, const OpenCLTuning& tuning,
                 const OpenCLFault& fault = {});
    // With the mesh packed already (DeviceMesh(mesh), holding at least the layout this device's
    // setup reads), as several devices' engines share one packing; uploaded here and not kept.
    OpenCLEngine(const mesh::Mesh& mesh, const DeviceMesh& packed, ocl::Context& context, const Settings& settings,
                 const OpenCLTuning& tuning, const OpenCLFault& fault = {});

    std::string name() const override { return "opencl"; }
    using Engine::shoot;
    void shoot(const ShotRequest& request, ShotResult& out) override;

    // Runs a batch's shots together: each stage is one launch over every shot (dimension 1 of
    // the NDRange), so a GPU has enough work. A directional light's shot (Shooter::Kind::directional)
    // runs apart, a launch of its own on this device's parallel raster (kernels/parallel.cl, built
    // on first use), whose cells' owners are the host's; last_ids gives those of the batch's last. The buffers grow to the largest batch seen; a
    // batch beyond the memory budget (launch_budget) runs in parts,
    // and then only the last part's id buffers are kept. Should the device run out of memory
    // all the same, the batch runs again in halves, and every later batch in parts no larger
    // (tuning's on_shrink is told): the results are the same. Throws ocl::DeviceError when
    // one shot does not fit, or an OpenCL call fails otherwise.
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override;

    // The id buffer of shot i of the last batch with the reference's conventions: face by
    // face, cell (i, j) at DeltaFormFactors::offset(face) + j·N + i; the element index, kEmpty
    // where nothing was hit, kBlocker for the back of a one-sided surface. Read from the
    // device on first use.
    static constexpr std::int32_t kEmpty = -1;
    static constexpr std::int32_t kBlocker = -2;
    const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const override;
    const std::string& build_options() const { return options_; }
    // The most shots one launch runs: from the memory budget, lowered where the device ran out.
    std::size_t max_batch() const;
    // A GPU's: eight shots a compute unit (132 on an H200: 1,024, the cap), as long as their rows
    // fit 512 MiB of the host's memory; a CPU device's kDefaultBatch (PoCL gains nothing past it:
    // bench/results/throughput_batches.md).
    std::size_t preferred_batch() const override;

    // The per-shot buffers one launch may hold: on a CPU (host memory) 16 MiB, since a shot of a
    // few thousand elements already gives its cores hundreds of work-groups and more shots only
    // cost memory (the Cornell box's bake peaked at 1.2 GB with 1 GiB launches, 305 MB with 32 MiB
    // and 293-302 MB with 16 MiB, of which PoCL itself holds 70 MB and the libraries 126 MB, in
    // the same time); on a GPU 1 GiB or a quarter of its memory, for the parallelism a batch brings.
    static std::size_t launch_budget(bool cpu, std::size_t device_memory) {
        return cpu ? std::size_t{16} << 20 : std::min<std::size_t>(std::size_t{1} << 30, device_memory / 4);
    }
    // Memory each shot of a launch holds for a mesh of `elements` elements at resolution
    // `hemicube` (on the device, and the host's copies of its ids and sums), besides the uploaded
    // mesh (DeviceMesh::bytes). A launch holds as many shots as the batch asks, up to what fits
    // its budget (tuning's batch_memory, else launch_budget) and at least one. For planning a bake
    // before its mesh is built.
    static double shot_bytes(double elements, int hemicube);

    // Device time per stage, summed over every shot so far (OpenCL event profiling).
    // "occluders": the occluder pass's four kernels together; "cull": the test of whole clusters
    // against its depths (cull_clusters).
    static constexpr int kStages = 7;
    static constexpr std::array<const char*, kStages> kStageNames = {"occluders", "cull",   "setup", "scan",
                                                                     "scatter",   "raster", "read"};

    const std::array<double, kStages>& stage_seconds() const { return stage_seconds_; }
    // Occlusion culling so far: lane groups (HR_SETUP_LANES elements) in front of a shooter that
    // setup tested against the occluder pass's depths, and those it found hidden and skipped.
    std::uint64_t occlusion_tested() const { return occlusion_tested_; }
    std::uint64_t occlusion_hidden() const { return occlusion_hidden_; }

private:
    // packed: a packing to upload, or nullptr to pack the layout setup reads here, piece by piece.
    OpenCLEngine(const mesh::Mesh& mesh, const DeviceMesh* packed, ocl::Context& context, const Settings& settings,
                 const OpenCLTuning& tuning, const OpenCLFault& fault);

    const mesh::Mesh& mesh_;
    ocl::Context& context_;
    std::unique_ptr<OpenCLParallelRaster> parallel_;
    // A batch with directional shots: its hemicubes, per shot its place among them (−1: a
    // directional one), and their rows; the owners of the grid of its last directional shot
    // (owner_shot_). place_ is empty after a batch of hemicubes alone.
    std::vector<ShotRequest> hemicubes_;
    std::vector<long> place_;
    std::vector<std::int32_t> owner_;
    std::size_t owner_shot_ = 0;
    std::vector<ShotResult> rows_;
    // shoot_batch for hemicubes alone.
    void shoot_hemicubes(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out);
    Settings settings_;
    OpenCLTuning tuning_;
    std::string options_;
    // Of the hemicube: n² on the top face, n²/2 on each side; a face's rows of n cells.
    std::size_t cells() const { return 3 * std::size_t(settings_.hemicube) * std::size_t(settings_.hemicube); }
    int face_rows(int face) const { return face == 0 ? settings_.hemicube : settings_.hemicube / 2; }
    double eps_;                      // base-plane clip distance, as the reference computes it
    std::array<int, 6> tile_base_{};  // first tile of each face, then the tile count
    int tiles_x_ = 0;
    std::uint32_t list_capacity_ = 0;  // entries of the per-tile record lists; grows on overflow
    // Lanes setup: record slots per setup work-group, and work-groups the record buffers hold per
    // shot (grown as shots need: a shot makes ~1.3 records an element it sees, not five).
    static constexpr double kInitialRecordsPerElement = 2.0;
    std::uint32_t group_capacity_ = 0;
    std::size_t record_rows_ = 0;
    OpenCLFault fault_;
    std::size_t launches_ = 0;                                           // run_batch calls so far
    std::size_t batch_limit_ = std::numeric_limits<std::size_t>::max();  // lowered when the device ran out

    cl::Kernel setup_, scan_, scatter_, raster_;  // raster_: raster or raster_records
    cl::Kernel cull_;                             // cull_clusters (lanes setup only)
    cl::Buffer shots_, elements_, element_lanes_, patches_, records_, boxes_, group_records_, tile_counts_, offsets_,
        cursors_, lists_, delta_fixed_, ids_buffer_, sums_, cluster_spheres_;
    std::vector<std::int64_t> sums_host_;  // per shot: per element, blocked (fixed point), list entries needed
    std::size_t batch_capacity_ = 0;       // shots the per-shot buffers hold
    bool counts_zero_ = false;             // tile_counts_ all zero (as every completed launch leaves them)
    std::size_t last_batch_ = 0;           // shots of the last launch
    std::size_t ids_first_ = 0;            // their first index in the last shoot_batch
    std::vector<ShotResult> batch_results_;
    // Lanes setup (CPUs): each setup work-group's elements as a cluster with a bounding sphere
    // (centre, radius); per shot of the launch, the clusters not wholly behind its base plane,
    // which alone are set up, cleared and read.
    std::vector<std::array<double, 4>> cluster_bounds_;
    std::vector<std::vector<std::uint32_t>> shot_clusters_;
    std::vector<std::int32_t> cluster_rows_;  // the launch's table: per shot, its clusters then −1
    std::vector<std::int32_t> occluder_rows_;  // likewise, the occluder pass's: per shot, its nearest clusters
    cl::Buffer clusters_, occluders_;
    // Per entry of the final pass's rows, cull_clusters' verdict: the live lane groups of a cluster
    // the occluder pass hides, else 0. Read back, and the hidden clusters dropped from the rows.
    cl::Buffer hidden_;
    std::vector<std::int32_t> hidden_host_;
    cl::Buffer block_depth_;  // per shot and depth block: the least 1/depth the occluder pass drew (0: an empty cell)

    std::array<double, kStages> stage_seconds_{};
    std::uint64_t occlusion_tested_ = 0, occlusion_hidden_ = 0;
    mutable std::vector<std::vector<std::int32_t>> ids_;  // per shot of the last batch
    mutable std::vector<bool> ids_stale_;

    // Occlusion culling needs clusters in front enough for some to hide others (a room's few do
    // not pay for the occluder pass).
    static constexpr std::size_t kOcclusionMinClusters = 8;
    // Occlusion::measured: wall seconds per shot of launches with and without occlusion
    // culling (a mean over the first kOcclusionWarm, then a moving average), each mode measured
    // first; then the cheaper mode, and the other once every kOcclusionProbe launches, as scenes
    // and shooters change. Either mode gives the same results, so the choice never shows in them.
    static constexpr std::size_t kOcclusionWarm = 4, kOcclusionProbe = 16;
    std::array<double, 2> occlusion_cost_{};
    std::array<std::size_t, 2> occlusion_samples_{};
    std::size_t occlusion_launches_ = 0;
    bool occlusion_pays();
    void record_occlusion_cost(bool on, double seconds_per_shot);
    std::size_t raster_group_size() const;
    std::size_t record_slots() const;      // per shot
    // The per-tile list entries a shot starts with, for `records` record slots: most records cover
    // a tile or two (a shot that needs more grows the lists and reruns).
    static double initial_list_entries(double records) { return std::max(double(1u << 16), 4.0 * records); }
    std::size_t setup_groups() const;      // work-groups of setup and scatter: a work-item per patch or lane group
    std::size_t cluster_elements() const;  // elements per cluster (a setup work-group's, lanes setup)
    std::size_t counter_entries() const;   // per shot: tile counters of every copy
    std::size_t sum_stride() const;
    // Reads back the batch's sums the host looks at: all of them, or the kept clusters' and each
    // shot's tail (lanes setup); returns the read commands, done.
    std::vector<cl::Event> read_sums(std::size_t batch);
    std::size_t depth_blocks() const;  // per shot: occlusion culling's depth blocks (HR_DEPTH_BLOCK² cells)
    std::size_t memory_batch() const;  // shots per launch within the memory budget
    void allocate_batch(std::size_t shots);
    void release_batch();  // frees the per-shot buffers (to allocate fewer)
    void shoot_fitting(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out);
    // What a launch found it needed: list entries, and (lanes setup) the most records of one
    // setup work-group; more than the lists or regions hold, and it must run again.
    struct LaunchNeeds {
        std::uint32_t list_entries = 0, group_records = 0;
    };
    LaunchNeeds run_batch(const std::vector<ShotRequest>& shots);
    // After cull_clusters (hidden_host_ read back): each shot's row of cluster_rows_, `length`
    // entries a shot, without the clusters it hid, the rest in order (the occluder pass's at the
    // same work-groups), and shot_clusters_ without them, so that they are neither set up nor
    // read. Counts their lane groups as tested and hidden. Returns the new row length.
    std::size_t drop_hidden_clusters(std::size_t batch, std::size_t length);
    void allocate_records(std::size_t shots);  // records_ and boxes_, for `shots` shots of record_slots()
};

}  // namespace hemirad::formfactor
