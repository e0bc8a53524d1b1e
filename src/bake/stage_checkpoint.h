// The light of a bake after its solve, refinement or gather as checkpoint bytes (bake/checkpoint.h,
// stages solved, refined and gathered), so that a rerun goes on from the stage it had reached.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "bake/checkpoint.h"
#include "bake/stages.h"
#include "core/timing.h"

namespace hemirad::bake {

// What a stage's checkpoint gives back: the lit mesh as the stage left it, and the warnings the
// lighting stages had added by then (the resumed bake's report lists them as the first did).
struct StageState {
    Lit lit;
    bool has_mesh = false;  // false: the stage `solved`, whose mesh is the bake's base mesh
    std::vector<std::string> warnings;
};

// Where a bake keeps its checkpoints and what it resumed (bake.cpp's plan_checkpoints makes it).
struct StageCheckpoints {
    std::filesystem::path file;        // written during the solve and after each stage; empty: none
    std::string fingerprint;           // the bake's (checkpoint.h)
    bool automatic = false;            // in the cache folder, removed after the outputs are committed
    std::string why;                   // why there is one ("--checkpoint", or the expected time)
    double every_seconds = 0.0;        // automatic: the solver's state at most this often
    Clock::time_point last = Clock::now();
    Warnings* warnings = nullptr;      // where an automatic checkpoint that cannot be written says so

    // What a rerun goes on from: the checkpoint, its stage and when it was written; the solver's
    // state (stage solving) or the stage's light, taken by the first lighting.
    std::filesystem::path resume_file;
    std::optional<Stage> resumed;
    std::string written;               // the checkpoint's time, UTC
    std::string solver_state;
    std::optional<StageState> light;

    bool writing() const { return !file.empty(); }
    // Runs `write` on `file` where it is due (`force`, or an automatic checkpoint's interval
    // passed). A checkpoint the user asked for that cannot be written stops the bake
    // (InputError); an automatic one is a warning, and the bake goes on without.
    bool save(const std::function<void(const std::filesystem::path&)>& write, bool force = false);
};

// The settings a stage's light depends on beyond the checkpoint's fingerprint (which holds the mesh
// and the solver's settings): where the solve stops, then refinement's, then the gather's. A stage
// is resumed only where they are the same.
std::string stage_settings(const Plan& plan, const Setup& setup, const Meshed& meshed, Stage stage);

// Raw bytes (doubles bit for bit). `with_mesh`: false for the stage solved.
std::string save_lit(const Lit& lit, bool with_mesh, const std::string& settings, const std::vector<std::string>& warnings);

// save_lit's bytes back; throws std::runtime_error saying why they cannot be used (damaged, or
// made with other `settings`).
StageState load_lit(const std::string& state, const std::string& settings);

// Before the bake writes anything: what --resume FILE holds, read and checked (InputError, one
// line naming the file, where it cannot be resumed), in a StageCheckpoints for the bake.
StageCheckpoints read_resume(const Plan& plan, const Setup& setup, const Meshed& meshed, const std::string& fingerprint);

// Then the checkpoint it writes: --checkpoint FILE; else, unless --no-checkpoint, the automatic
// one where the bake is expected to take longer than a minute (`expected_seconds`; the
// threshold is HEMIRAD_CHECKPOINT_ABOVE seconds where set). With no --resume, a checkpoint of
// this bake found there is resumed (a note says so); one that cannot be is ignored with a
// warning. Prunes the cache folder.
void plan_checkpoints(StageCheckpoints& cp, const Plan& plan, const Setup& setup, const Meshed& meshed,
                      double expected_seconds, Warnings& warnings, Progress& progress);
inline constexpr double kAutomaticCheckpointAbove = 60.0;  // seconds expected
inline constexpr double kAutomaticCheckpointEvery = 60.0;  // seconds between the solver's states

// After a lighting stage: its light, where the bake writes checkpoints. `warnings`: those the
// lighting stages added.
void save_stage(StageCheckpoints& cp, const Plan& plan, const Setup& setup, const Meshed& meshed, Stage stage,
                const Lit& lit, const std::vector<std::string>& warnings);

// Once the outputs are committed: the automatic checkpoint is removed.
void finish_checkpoints(const StageCheckpoints& cp, Progress& progress);

// HEMIRAD_FAULT=stage:NAME (solve, refine, gather or output): the process kills itself (SIGKILL) as
// the stage begins (output: once the images and baked.gltf are staged, before anything is
// committed), as a kill from outside would, for the tests of resuming.
void fault_point(const char* stage);

}  // namespace hemirad::bake
