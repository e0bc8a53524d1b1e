// The stages of a bake and what each makes (bake.cpp runs them in order; docs/architecture.md):
//
//   plan → load → set up → mesh → solve → refine → gather → write outputs → write report
//
// A stage is a function that takes what it reads and returns what it makes. Warnings go to a
// `Warnings` (the report lists them; the Progress shows them).
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "bake/budget.h"
#include "bake/checks.h"
#include "bake/options.h"
#include "bake/progress.h"
#include "core/quality.h"
#include "formfactor/row_cache.h"
#include "formfactor/verify.h"
#include "mesh/mesh.h"
#include "output/output.h"
#include "output/welded_mesh.h"
#include "scene/effects.h"
#include "scene/scene.h"
#include "scene/sky.h"
#include "solve/matrix.h"
#include "solve/progressive.h"
#include "solve/refinement.h"

namespace hemirad::bake {

// Convergence forced off: shoot until this little is left (progressive), or solve to rounding (matrix).
inline constexpr double kUnconvergedThreshold = 1e-6;
inline constexpr double kUnconvergedTolerance = 1e-12;

// The warnings of a bake, in order: each is shown (Progress::warning) and kept for report.json.
class Warnings {
public:
    explicit Warnings(Progress& progress) : progress_(progress) {}
    void add(const std::string& text, bool always = false) {
        progress_.warning(text, always);
        all_.push_back(text);
    }
    const std::vector<std::string>& all() const { return all_; }

private:
    Progress& progress_;
    std::vector<std::string> all_;
};

// Stage "plan": the options made whole (the quality's settings where none was given) and what
// they name, parsed and checked, before any file is read.
struct Plan {
    Options o;                      // the effective options
    bool gather_given = false;      // --gather was given (else the quality's gather may be left out)
    const QualityPreset* quality = nullptr;
    scene::EffectOverrides overrides;
    std::optional<std::pair<glm::dvec3, glm::dvec3>> look;  // --look-from, --look-at
    std::optional<scene::Sky> sky;
    std::optional<scene::PunctualLight> sun;
    MemoryLimit memory_limit;
};

// Stage "set up": what the loaded scene calls for, before any of the mesh is built.
struct Setup {
    scene::EffectsPlan effects;
    mesh::Settings mesh_settings;
    output::View view;
    int width = 0, height = 0;              // of the render
    solve::MatrixSettings matrix;           // the matrix solver's settings
    BakeShape shape;                        // what the memory estimate is made from (no counts yet)
    bool direct_only = false;               // interreflection off
    double threshold = 0.0;                 // the progressive solver stops below it
    std::vector<scene::Triangle> see_through;  // left out of the mesh (effect see_through): the render shows them
};

// Stage "mesh": the mesh, and the solver chosen by its counts within the memory limit.
struct Meshed {
    mesh::Mesh mesh;
    BakeShape shape;                        // with the mesh's counts
    std::string solver, solver_why;
    MemoryEstimate memory;
};

// What either solver leaves for the output and the report.
struct Solution {
    std::vector<glm::dvec3> radiosity, irradiance;  // per element, the ambient term included
    glm::dvec3 ambient{0.0};
    std::vector<glm::dvec3> shot;  // per patch, the radiosity it shot in all
    solve::Energy energy;
    long passes = 0;  // hemicubes shot by the solver
    // The progressive solver's steps in this run (from a --resume on): each one engine call of
    // the shooters it took together (Settings::batch_share), and the most one took.
    long steps = 0, largest_step = 0;
    bool converged = false;
    double error = 0.0;
    double unshot_fraction = 0.0;
    int iterations = 0;  // Gauss–Seidel sweeps (matrix)
    std::string convergence_rule;  // what "converged" rests on
    long resumed_from = -1;  // the passes or rows a --resume started from
};

// Stage "solve": the solution on the base mesh.
struct Solved {
    Solution solution;
    double formfactor_seconds = 0.0, solve_seconds = 0.0;
    // Shots a call the engine asked for (formfactor::Engine::preferred_batch): the matrix rows,
    // refinement's re-gathers and the gather's points go in batches of at least this.
    std::size_t preferred_batch = 0;
    std::optional<formfactor::VerifySummary> verified;      // what --verify compared
    std::optional<formfactor::RowCacheStats> row_cache;     // the progressive solve's
};

// Stage "gather": the light at every output vertex.
struct Gathered {
    output::VertexLight light;
    long points = 0;                 // vertices gathered (0: no gather)
    std::size_t contact_split = 0;   // elements split along contact lines for the gather
    std::size_t gather_split = 0;    // elements split where the gathered light changes fast
    // A sparse gather's (more vertices than --gather-points): its points and what it interpolated.
    long sparse_seeds = 0;           // 0: every vertex was gathered (or none)
    int sparse_levels = 0;
    long sparse_covered = 0;
    std::size_t sparse_vertices = 0, sparse_interpolated = 0, sparse_unreached = 0;
    bool sparse_capped = false;
    std::size_t sparse_budget = 0;   // the hemicubes it was allowed
};

// What solve, refine and gather leave: the final mesh and its light.
struct Lit {
    mesh::Mesh mesh;
    Solved solved;                            // the solution, refined and graded with the mesh
    std::vector<solve::RefineLevel> levels;   // refinement's
    Gathered gathered;
    // The weld of `mesh` (output/welded_mesh.h) where the gather made one: the outputs draw it.
    std::optional<output::WeldedMesh> welded;
    double refine_seconds = 0.0, gather_seconds = 0.0;
};

// The first stages (bake.cpp), public for callers that run a bake's stages on a scene of their
// own (bench --accuracy): plan, set up (the scene is changed as its effects say), mesh.
Plan make_plan(const Options& options);
Setup set_up(const Plan& plan, scene::Scene& scene);
Meshed build_mesh(const Plan& plan, const Setup& setup, scene::Scene& scene);

}  // namespace hemirad::bake
