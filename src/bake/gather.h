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
// gathered light changes faster than the vertices follow. Beyond gather_budget vertices, a sparse
// gather instead (solve::sparse_gather, one pass, no grading or refinement; a warning says so).
Lit gather(const LightContext& c, Lit lit, EngineStack& engines);

// Stages "solve", "refine" and "gather" on the engines `engines` makes (bake.cpp). `mesh` is the
// one the solve's engine was made for: it stays in place while that engine lives, then moves on.
Lit light(const LightContext& c, mesh::Mesh& mesh, EngineStack& engines, const SolveContext& sc);

// The most gather hemicubes the quality's final gather shoots by itself: a mesh with more output
// vertices is gathered sparsely (solve/sparse_gather.h).
inline constexpr std::size_t kMaxPlannedGather = 50000;

// The most gather hemicubes of this bake (0: no limit): --gather-points, else kMaxPlannedGather,
// or no limit where --gather is given.
std::size_t gather_budget(const Plan& plan);
// ... for a bake of `mesh`: also, unless --gather-points is given, at most timed_gather_budget of the
// mesh the gather draws.
std::size_t gather_budget(const Plan& plan, const mesh::Mesh& mesh);
// The elements a gather of `mesh` draws (solve::gather_mesh, counted).
std::size_t gather_drawn(const mesh::Mesh& mesh);

}  // namespace hemirad::bake
