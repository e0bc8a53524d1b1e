// Stage "solve" (see solve.h).
#include "bake/solve.h"

#include <algorithm>
#include <fmt/core.h>

#include "bake/checkpoint.h"
#include "bake/stage_checkpoint.h"
#include "core/cancel.h"
#include "core/timing.h"
#include "formfactor/row_cache.h"
#include "formfactor/timed.h"
#include "solve/lights.h"

namespace hemirad::bake {

namespace {

// Whether the solver's state is written to a checkpoint, and where from it resumes.
bool checkpointing(const SolveContext& c) {
    return c.checkpoints ? c.checkpoints->writing() : !c.o.checkpoint.empty();
}
std::filesystem::path resume_file(const SolveContext& c) {
    return c.checkpoints ? c.checkpoints->resume_file : std::filesystem::path(c.o.resume);
}

// A checkpoint of the solver's state; an automatic one only once its interval has passed, or
// `last` (the solve's end, or a stop asked for). Whether it was written.
bool save_solver(const SolveContext& c, const solve::Resumable& solver, bool last = false) {
    if (!c.checkpoints) {
        write_checkpoint(c.o.checkpoint, c.fingerprint, solver);
        return true;
    }
    return c.checkpoints->save(
        [&](const std::filesystem::path& file) { write_checkpoint(file, c.fingerprint, solver); }, last);
}

// Ctrl-C or SIGTERM while solving: the state after the last whole pass or row, kept before the
// bake stops (a write the watchdog cuts short leaves the previous checkpoint whole).
void save_if_stopping(const SolveContext& c, const solve::Resumable& solver, long done, long& checkpointed) {
    if (!cancel::requested() || !checkpointing(c) || done == checkpointed) return;
    try {
        if (save_solver(c, solver, /*last=*/true)) checkpointed = done;
    } catch (const std::exception&) {
        // Stopping anyway: the interruption is what the user is told.
    }
}

}  // namespace

Solution solve_with_matrix(const mesh::Mesh& mesh, formfactor::Engine& engine, const SolveContext& c,
                           const std::vector<glm::dvec3>* direct) {
    const Options& o = c.o;
    solve::Matrix solver(mesh, engine, c.matrix, direct);
    Solution solution;
    if (!c.resume_state.empty()) {
        restore(solver, c.resume_state, resume_file(c));
        solution.resumed_from = solver.rows();
    }
    long checkpointed = solver.rows();  // the rows of the last checkpoint written or resumed
    solver.solve([&](long done, long total) {
        save_if_stopping(c, solver, done, checkpointed);
        cancel::check();
        c.progress.rows(done, total);
        // Every K rows, and all of them: a bake killed while solving or refining then resumes
        // without shooting a row again.
        if (checkpointing(c) && done != checkpointed &&
            (done / o.checkpoint_every > checkpointed / o.checkpoint_every || done == total) &&
            save_solver(c, solver, done == total))
            checkpointed = done;
    });
    solution.radiosity = solver.radiosity();
    solution.irradiance = solver.irradiance();
    solution.shot = solver.patch_radiosity();
    solution.energy = solver.energy();
    solution.passes = solver.rows();
    solution.converged = solver.converged();
    solution.error = solver.error_bound();
    solution.unshot_fraction = solution.energy.emitted > 0.0 ? solution.energy.unshot / solution.energy.emitted : 0.0;
    solution.iterations = solver.iterations();
    if (solution.converged) solution.convergence_rule = "error bound";
    return solution;
}

Solution solve_progressively(const mesh::Mesh& mesh, formfactor::Engine& engine, const SolveContext& c,
                             const std::vector<glm::dvec3>* direct) {
    const Options& o = c.o;
    solve::Settings settings;
    settings.threshold = c.threshold;
    settings.max_passes = max_passes_for(o, mesh.patches.size());
    settings.batch = progressive_batch(o);
    settings.batch_share = o.batch_share;
    solve::Progressive solver(mesh, engine, settings, direct);
    Solution solution;
    if (!c.resume_state.empty()) {
        restore(solver, c.resume_state, resume_file(c));
        solution.resumed_from = solver.passes();
    }
    // Preview frames and checkpoints: one each time the passes cross a multiple of K.
    long previews = o.preview_every > 0 ? solver.passes() / o.preview_every : 0;
    long checkpointed = solver.passes();  // the passes of the last checkpoint written or resumed
    for (long before = solver.passes(); solver.step(); before = solver.passes()) {
        ++solution.steps;
        solution.largest_step = std::max(solution.largest_step, solver.passes() - before);
        save_if_stopping(c, solver, solver.passes(), checkpointed);
        cancel::check();
        c.progress.passes(solver, c.threshold);
        if (checkpointing(c) && solver.passes() / o.checkpoint_every > checkpointed / o.checkpoint_every &&
            save_solver(c, solver))
            checkpointed = solver.passes();
        if (o.preview_every > 0 && solver.passes() / o.preview_every > previews) {
            previews = solver.passes() / o.preview_every;
            c.preview(solver);
        }
    }
    // The finished solve too: a bake killed while refining resumes straight to refinement. (A bake
    // with stage checkpoints keeps its solved light instead, bake.cpp.)
    if (!c.checkpoints && checkpointing(c) && solver.passes() != checkpointed) save_solver(c, solver);
    c.progress.passes(solver, c.threshold);
    solution.radiosity = solver.radiosity(/*ambient=*/true);
    solution.irradiance = solver.irradiance(/*ambient=*/true);
    solution.ambient = solver.ambient();
    solution.shot = solver.shot();
    solution.energy = solver.energy();
    solution.passes = solver.passes();
    solution.converged = solver.converged();
    solution.error = solver.error();
    solution.unshot_fraction = solver.unshot_fraction();
    solution.convergence_rule = solver.convergence_rule();
    return solution;
}


Solved solve(const mesh::Mesh& mesh, const scene::Scene& scene, const std::string& solver, const BakeShape& shape,
             EngineStack& engines, const SolveContext& c) {
    std::unique_ptr<formfactor::Engine> base = engines.solve(mesh);
    // Progressive shooting asks for a patch's row again each time it shoots: keep them.
    formfactor::RowCacheEngine* row_cache = nullptr;
    if (solver == "progressive") {
        auto cached = std::make_unique<formfactor::RowCacheEngine>(std::move(base), row_cache_bytes(shape));
        row_cache = cached.get();
        base = std::move(cached);
    }
    formfactor::TimedEngine engine(*base);
    const auto t0 = Clock::now();
    c.progress.begin_stage("solve");
    // The punctual lights shoot first: the solvers start from their direct light.
    std::vector<glm::dvec3> direct;
    if (solve::has_direct_light(mesh, scene.lights))
        direct = solve::direct_light(mesh, scene.lights, engine, 0, nullptr,
                                     [&](std::size_t done, std::size_t total) { c.progress.lights(done, total); });
    const std::vector<glm::dvec3>* lit = direct.empty() ? nullptr : &direct;
    Solved out;
    out.solution = solver == "matrix" ? solve_with_matrix(mesh, engine, c, lit) : solve_progressively(mesh, engine, c, lit);
    c.progress.end_stage();
    const Solution& s = out.solution;
    // Shown, not reported: report.json's `converged` and `error` say it.
    if (!s.converged)
        c.progress.warning(solver == "matrix"
                         ? fmt::format("Gauss-Seidel stopped after {} sweeps with an error bound of {:.3g}", s.iterations, s.error)
                         : fmt::format("stopped at --max-passes {} before the threshold {} was reached (error {:.3g})",
                                       max_passes_for(c.o, mesh.patches.size()), c.threshold, s.error),
                           false);
    out.formfactor_seconds = engine.seconds();
    out.preferred_batch = engine.preferred_batch();
    if (engines.choice().verifier) out.verified = engines.choice().verifier->summary();  // the engine ends with this call
    if (row_cache) out.row_cache = row_cache->stats();
    out.solve_seconds = seconds_since(t0) - engine.seconds();
    return out;
}

}  // namespace hemirad::bake
