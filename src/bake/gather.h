// Stages "refine" and "gather": adaptive refinement of the solved mesh where the irradiance
// contrasts, then the final gather of the light at every output vertex.
#pragma once

#include "bake/engines.h"
#include "bake/solve.h"
#include "bake/stages.h"

namespace hemirad::bake {

// What refinement and the gather read of the bake besides the lit mesh.
struct LightContext {
    const Plan& plan;
    const Setup& setup;
    const scene::Scene& scene;
    const Meshed& meshed;      // the solver, the shape and the memory limit's room
    Progress& progress;
    Warnings& warnings;
};

// Splits elements whose neighbours' irradiance differs by more than --contrast, and re-gathers
// the children's light from the solution (solve::refine).
Lit refine(const LightContext& c, Lit lit, EngineStack& engines);

// A hemicube at every output vertex (but the sky dome's) from the converged solution: first the
// elements along contact lines are halved once, then the gather, then gather refinement where the
// gathered light changes faster than the vertices follow. Left out (a warning) beyond
// kMaxPlannedGather vertices unless --gather was given.
Lit gather(const LightContext& c, Lit lit, EngineStack& engines);

// Stages "solve", "refine" and "gather" on the engines `engines` makes (bake.cpp). `mesh` is the
// one the solve's engine was made for: it stays in place while that engine lives, then moves on.
Lit light(const LightContext& c, mesh::Mesh& mesh, EngineStack& engines, const SolveContext& sc);

// The most output vertices the quality's final gather takes on by itself.
inline constexpr std::size_t kMaxPlannedGather = 50000;

}  // namespace hemirad::bake
