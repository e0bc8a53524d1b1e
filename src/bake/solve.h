// Stage "solve": the punctual lights' direct light, then the matrix or the progressive solver on
// the base mesh, with checkpoints, --resume and preview frames.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "bake/engines.h"
#include "bake/stages.h"

namespace hemirad::bake {

struct StageCheckpoints;  // bake/stage_checkpoint.h

// What either solver needs of a bake besides the mesh and the engine.
struct SolveContext {
    const Options& o;                      // the effective options
    double threshold;                      // progressive: stop below it
    const solve::MatrixSettings& matrix;   // the matrix solver's settings
    const std::string& fingerprint;        // of the checkpoints written
    const std::string& resume_state;       // what --resume read, or empty
    Progress& progress;
    std::function<void(const solve::Progressive&)> preview;  // writes a preview frame of the passes so far
    // The bake's checkpoints (bake.cpp: --checkpoint or the automatic one, and what a rerun
    // resumes); null: o.checkpoint, o.resume and resume_state as they are.
    StageCheckpoints* checkpoints = nullptr;
};

// Either solver on `engine`, from the lights' irradiance per element `direct` (null: none).
Solution solve_with_matrix(const mesh::Mesh& mesh, formfactor::Engine& engine, const SolveContext& c,
                           const std::vector<glm::dvec3>* direct);
Solution solve_progressively(const mesh::Mesh& mesh, formfactor::Engine& engine, const SolveContext& c,
                             const std::vector<glm::dvec3>* direct);

// The stage: the engine from `engines` (a row cache for the progressive solver), the lights'
// direct light, then `solver` ("matrix" or "progressive"), timed.
Solved solve(const mesh::Mesh& mesh, const scene::Scene& scene, const std::string& solver, const BakeShape& shape,
             EngineStack& engines, const SolveContext& c);

}  // namespace hemirad::bake
