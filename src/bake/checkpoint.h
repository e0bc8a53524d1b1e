// `hemirad bake --checkpoint FILE` / `--resume FILE`: the solver's state on disk (the
// progressive solver's, or the matrix solver's rows), so that a bake killed at any moment goes on
// from its last checkpoint and ends with exactly the numbers of an uninterrupted bake.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "mesh/mesh.h"
#include "solve/resumable.h"

namespace hemirad::bake {

// How far the bake a checkpoint holds had come: the solver's state part-way (what --checkpoint
// wrote before stages were kept), or the light after the solve, after refinement or after the
// gather (the state the outputs are drawn from). A resumed bake skips every stage done.
enum class Stage : std::uint8_t { solving = 0, solved = 1, refined = 2, gathered = 3 };
const char* stage_name(Stage stage);

// What decides a bake's numbers: the mesh (every patch's and element's geometry,
// reflectance and emission, so the scene file, its buffers and the effects applied to it) and
// `settings`, the solver and engine settings as text. A checkpoint resumes only the same bake.
std::string bake_fingerprint(const mesh::Mesh& mesh, const std::string& settings);

// Before a bake does any work: that --checkpoint FILE can be written, and is either new or a
// hemirad checkpoint (recognised by its magic) — never the scene or any other file, which writing
// would destroy. Throws InputError (exit 2) naming the file otherwise.
void check_checkpoint_target(const std::filesystem::path& file);

// Before a bake does any work: that --resume FILE is a readable hemirad checkpoint (a regular
// file with the magic; a directory or FIFO is refused, not waited on). Throws InputError.
void check_resume_source(const std::filesystem::path& file);

// Writes the solver's state to `file` atomically (a temporary file beside it, then a rename), so
// a bake killed while writing leaves the previous checkpoint whole. Throws InputError when the
// file cannot be written, or has become something other than a checkpoint since the bake began.
void write_checkpoint(const std::filesystem::path& file, const std::string& fingerprint,
                      const solve::Resumable& solver);

// Writes a later stage's state (bake/stage_checkpoint.h makes `state`) the same way.
void write_stage_checkpoint(const std::filesystem::path& file, const std::string& fingerprint, Stage stage,
                            const std::string& state);

// The stage of a state read_checkpoint returned, and that state without it.
Stage checkpoint_stage(const std::string& state);
std::string stage_state(const std::string& state);

// Reads `file` and returns the solver state it holds, before the bake writes anything. Throws
// InputError (exit 2, naming the file) when it cannot be read, is not a hemirad checkpoint, is
// cut short, or belongs to another scene or settings.
std::string read_checkpoint(const std::filesystem::path& file, const std::string& fingerprint);

// The batch a progressive bake's checkpoint was made with (its fingerprint says): `batch`
// shooters a step, or with share > 0 those holding that share of the largest unshot flux
// (Options::batch_share); nullopt for a matrix bake's or a file that is no readable checkpoint.
// A resumed bake that is not given --batch takes it, so that it may resume with another number
// of devices or ranks.
struct CheckpointBatch {
    int batch = 1;
    double share = 0.0;
};
std::optional<CheckpointBatch> checkpoint_batch(const std::filesystem::path& file);

// Loads a state from read_checkpoint (stage `solving`) into the solver; InputError naming `file`
// if it is damaged.
void restore(solve::Resumable& solver, const std::string& state, const std::filesystem::path& file);

// Automatic checkpoints (bakes expected to take longer than a minute, unless --no-checkpoint):
// kept in checkpoint_directory(), named by the bake's fingerprint, so that a rerun of the same
// command finds its own; removed once the bake's outputs are committed.
//
// The directory: $HEMIRAD_CACHE_DIR/checkpoints, else $XDG_CACHE_HOME/hemirad/checkpoints, else
// ~/.cache/hemirad/checkpoints (the OpenCL program cache's folder, cl/program_cache.h); nullopt
// where HEMIRAD_CACHE_DIR=off or no home is known.
std::optional<std::filesystem::path> checkpoint_directory();
std::filesystem::path automatic_checkpoint_file(const std::filesystem::path& dir, const std::string& fingerprint);

// Keeps the folder bounded: removes checkpoints (and temporary files of killed writes) older than
// `max_age_days`, then the oldest until those left hold at most `max_bytes`. `keep` (this bake's)
// is never removed. Failures are ignored: a cache owes nothing. Returns how many were removed.
inline constexpr double kCheckpointMaxAgeDays = 14.0;
inline constexpr std::uintmax_t kCheckpointMaxBytes = std::uintmax_t{8} << 30;  // 8 GiB
int prune_checkpoints(const std::filesystem::path& dir, const std::filesystem::path& keep,
                      double max_age_days = kCheckpointMaxAgeDays, std::uintmax_t max_bytes = kCheckpointMaxBytes);

}  // namespace hemirad::bake
