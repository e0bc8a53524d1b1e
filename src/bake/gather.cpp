// Stages "refine" and "gather" (see gather.h).
#include "bake/gather.h"

#include <algorithm>
#include <functional>

#include <fmt/core.h>

#include "bake/stage_progress.h"
#include "core/cancel.h"
#include "core/memory.h"
#include "core/parallel.h"
#include "core/timing.h"
#include "mesh/texturing.h"
#include "output/welded_mesh.h"
#include "solve/final_gather.h"
#include "solve/lights.h"
#include "solve/sparse_gather.h"

namespace hemirad::bake {

namespace {

// Before a final gather, elements along contact lines longer than this fraction of the element size
// (those not yet refined) are split once. Measured on the Cornell box against the path tracer
// (per-pixel error, gather points): default 2.31% (10,370) → 2.16% (12,660); a uniformly finer
// element (0.015 for 0.02) costs more for less, 2.08% (16,661); split twice (0.3) 2.11% (17,382);
// high 1.74% → 1.67%, draft 5.76% → 5.58%.
constexpr double kContactGrading = 0.6;

// Gather refinement (--gather-refine, --gather-contrast; solve::gather_contrasts): elements whose
// vertices' gathered light spans more than the contrast and kGatherNoiseFloor of the mean are
// split, down to kGatherMinSize of the element size, and only their new vertices gathered. On the
// Cornell box (per-pixel error, gather points; four levels; bench --accuracy): at the default
// 1.76% (12,660) → contrast 0.5 1.48% (14,570), 0.3 1.36% (18,478), 0.2 1.31% (26,398); one
// level 1.61%, two 1.53%; down to 0.12 of the element instead of 0.06, contrast 0.2 gave 1.42%
// (19,935). At high (gather N 192) 1.46% → 0.4 1.14% (18,880), 0.3 1.10% (20,877), 0.2 1.07%
// (26,487). A uniformly finer element (0.01 for 0.02) gives 1.30% with 3× the gather.
constexpr double kGatherNoiseFloor = 0.02;
constexpr double kGatherMinSize = 0.06;


}  // namespace

std::size_t gather_budget(const Plan& plan) {
    if (plan.o.gather_points >= 0) return static_cast<std::size_t>(plan.o.gather_points);
    return plan.gather_given ? 0 : kMaxPlannedGather;
}

std::size_t gather_budget(const Plan& plan, const mesh::Mesh& mesh) {
    const std::size_t budget = gather_budget(plan);
    if (budget == 0 || plan.o.gather_points >= 0) return budget;
    return std::min(budget, static_cast<std::size_t>(timed_gather_budget(double(gather_drawn(mesh)), plan.o.gather)));
}

std::size_t gather_drawn(const mesh::Mesh& mesh) {
    std::vector<std::size_t> cells(mesh.patches.size());
    parallel::for_each(mesh.patches.size(), 64,
                       [&](std::size_t p) { cells[p] = solve::drawn_cells(mesh, mesh.patches[p]).size(); });
    std::size_t drawn = 0;
    for (const std::size_t c : cells) drawn += c;
    return drawn;
}

Lit refine(const LightContext& c, Lit lit, EngineStack& engines) {
    const Options& o = c.plan.o;
    const auto t0 = Clock::now();
    if (c.setup.effects.refinement.on && o.refine_levels > 0) {
        solve::RefineSettings rs;
        rs.contrast = o.contrast;
        rs.max_levels = o.refine_levels;
        rs.batch = std::max(o.batch, 64);
        rs.engine_batch = true;
        rs.max_elements = refinement_room(c.meshed.shape, c.meshed.solver, c.plan.memory_limit.bytes);
        rs.cancelled = [] { return cancel::requested(); };
        const mesh::Texturing texturing(c.scene);
        rs.texturing = &texturing;
        rs.lights = &c.scene.lights;
        c.progress.begin_stage("refine");
        rs.progress = [&](int level, long shots, long total) { c.progress.refining(level, shots, total); };
        Solution& s = lit.solved.solution;
        solve::RefineResult refined = solve::refine(
            std::move(lit.mesh), std::move(s.irradiance), s.shot,
            [&](const mesh::Mesh& m, int level) { return engines.level(m, level); }, rs);
        c.progress.end_stage();
        cancel::check();
        if (refined.stopped_for_memory.level > 0)
            c.warnings.add(fmt::format("refinement stopped before level {}: splitting {} more elements would pass the {} {}",
                                       refined.stopped_for_memory.level, refined.stopped_for_memory.split,
                                       format_bytes(c.plan.memory_limit.bytes), c.plan.memory_limit.source));
        lit.mesh = std::move(refined.mesh);
        c.progress.refined(lit.mesh.elements.size());
        s.irradiance = std::move(refined.irradiance);
        s.radiosity = std::move(refined.radiosity);
        lit.levels = std::move(refined.levels);
    }
    lit.refine_seconds = seconds_since(t0);
    return lit;
}

namespace {

// The output's nodes a gather takes: every one but the sky dome's (gather_mesh's cells hold them).
std::function<bool(std::size_t)> gathered_nodes(const scene::Scene& scene) {
    return [&scene](std::size_t n) { return !scene.nodes[n].synthetic; };
}

// The vertices of `w` in the nodes a gather takes.
std::size_t gathered_vertices(const scene::Scene& scene, const output::WeldedMesh& w) {
    const auto gathered = gathered_nodes(scene);
    std::size_t vertices = 0;
    for (std::size_t n = 0; n < w.nodes.size(); ++n)
        if (gathered(n)) vertices += w.nodes[n].positions.size();
    return vertices;
}

// A hemicube per vertex: on real content many times the solve's shots, each costing about as
// much (a 113k-vertex material ball at draft: the gather ran 15x the solve's time). Beyond the
// budget (gather_budget) a mesh is gathered sparsely.
bool too_many(std::size_t budget, std::size_t vertices) { return budget > 0 && vertices > budget; }

// The punctual and directional lights' light on `mesh`, shot on an engine of its own.
std::vector<glm::dvec3> direct_light_on(const LightContext& c, const mesh::Mesh& mesh, EngineStack& engines) {
    if (!solve::has_direct_light(mesh, c.scene.lights)) return {};
    std::unique_ptr<formfactor::Engine> lights_engine = engines.level(mesh, 0);
    return solve::direct_light(mesh, c.scene.lights, *lights_engine, c.plan.o.refine_levels + 1);
}

// Gather refinement: where the gathered light changes faster than the vertices follow, the
// elements are split and only their new vertices gathered, drawing the last pass's light.
void refine_gather(const LightContext& c, Lit& lit, std::vector<glm::dvec3>& direct, output::WeldedMesh& welded,
                   const solve::GatherSettings& gs, EngineStack& engines) {
    const Options& o = c.plan.o;
    const mesh::Texturing texturing(c.scene);
    solve::GatherRefinement r;
    r.levels = o.gather_refine;
    r.contrast = o.gather_contrast;
    r.noise_floor = kGatherNoiseFloor;
    r.min_size = kGatherMinSize * c.setup.mesh_settings.element_size;
    // At most half as many vertices again as the gather's (the jungle at draft with --gather 32:
    // 82,724 vertices in 161 s, and four levels went on past 500 s), and within the budget.
    const std::size_t base = static_cast<std::size_t>(lit.gathered.points);
    r.max_vertices = base + base / 2;
    const std::size_t budget = gather_budget(c.plan, lit.mesh);
    if (budget > 0) r.max_vertices = std::min(r.max_vertices, budget);
    r.texturing = &texturing;
    r.make_engine = [&](const mesh::Mesh& finer_drawn) { return engines.gather(finer_drawn, o.gather); };
    if (!direct.empty()) r.direct_light = [&](const mesh::Mesh& finer) { return direct_light_on(c, finer, engines); };
    Solution& s = lit.solved.solution;
    solve::GatheredMesh g{lit.mesh, s.radiosity, s.irradiance, direct, welded, lit.gathered.light};
    const solve::GatherRefined refined = solve::refine_gather(g, gathered_nodes(c.scene), gs, r);
    if (refined.cancelled) throw cancel::Interrupted();
    lit.gathered.points += refined.points;
    lit.gathered.gather_split = refined.split;
    if (refined.capped)
        c.warnings.add(fmt::format("gather refinement stopped at level {} of {}: more would gather at more than {} "
                                   "vertices (half again the gather's {}{}); that level split only its elements of "
                                   "the highest contrast",
                                   refined.levels, o.gather_refine, r.max_vertices, base,
                                   budget > 0 ? fmt::format(", and the gather's budget of {} hemicubes", budget) : ""));
}

// The gather proper, on `welded` (the output's vertices of lit.mesh): at every vertex, or (`sparse`
// > 0) at that many at most, where the light varies.
void gather_vertices(const LightContext& c, Lit& lit, output::WeldedMesh& welded, EngineStack& engines,
                     std::size_t sparse) {
    const Options& o = c.plan.o;
    std::vector<glm::dvec3> direct = direct_light_on(c, lit.mesh, engines);
    const std::function<bool(std::size_t)> gathered_node = gathered_nodes(c.scene);
    mesh::Mesh drawn = solve::gather_mesh(lit.mesh);
    drawn.gather_points = solve::gather_points(welded, gathered_node);
    std::unique_ptr<formfactor::Engine> gather_engine = engines.gather(drawn, o.gather);
    solve::GatherSettings gs;
    gs.batch = std::max(o.batch, 64);
    gs.engine_batch = true;
    gs.passes = o.gather_passes;
    // The later passes re-use the first's rows, within the progressive solve's row-cache budget
    // (its cache is gone by now).
    gs.kept_entries = static_cast<std::size_t>(row_cache_bytes(c.meshed.shape) / (sizeof(std::uint32_t) + sizeof(double)));
    gs.cancelled = [] { return cancel::requested(); };
    gs.progress = [&](long done, long total) { c.progress.gathering(done, total); };
    // Direct light only (interreflection off): the gather sees the emitters' light alone, or it
    // would add the bounce the plan leaves out.
    Solution& s = lit.solved.solution;
    std::vector<glm::dvec3> emitted;
    if (c.setup.direct_only) {
        emitted.resize(lit.mesh.elements.size());
        for (std::size_t k = 0; k < lit.mesh.elements.size(); ++k) emitted[k] = lit.mesh.elements[k].emission;
        gs.passes = 1;
    }
    if (sparse > 0) {
        solve::SparseGatherSettings ss;
        ss.budget = sparse;
        ss.progress = [&](long done, long budget) { c.progress.gathering_sparse(done, budget); };
        const solve::SparseGathered sg =
            solve::sparse_gather(lit.mesh, welded, gathered_node, c.setup.direct_only ? emitted : s.radiosity,
                                 s.irradiance, direct, drawn, *gather_engine, gs, ss, lit.gathered.light);
        if (sg.cancelled) throw cancel::Interrupted();
        Gathered& g = lit.gathered;
        g.points = sg.points;
        g.sparse_seeds = sg.seeds;
        g.sparse_levels = sg.levels;
        g.sparse_covered = sg.covered;
        g.sparse_vertices = sg.vertices;
        g.sparse_interpolated = sg.interpolated;
        g.sparse_unreached = sg.unreached;
        g.sparse_capped = sg.capped;
        g.sparse_budget = ss.budget;
        const std::string allowed =
            o.gather_points >= 0 ? std::string("--gather-points allows")
                                 : fmt::format(
                                       "the time model allows ({:.0f} s by constants fitted on one 2-core machine; "
                                       "report.json's estimate has the measured time)",
                                       kGatherSeconds);
        const std::string unreached =
            sg.unreached > 0 ? fmt::format(" ({} on surfaces with no point keep their elements' light)", sg.unreached)
                             : std::string();
        c.warnings.add(
            fmt::format(
                "final gather sparse: {} vertices, more than the {} hemicubes {}; shot at {} of them ({} seeds, {} "
                "levels where the light varies{}{}), one pass, no contact grading or gather refinement, the others "
                "interpolated{}; --gather-points 0 gathers at every vertex",
                sg.vertices, ss.budget, allowed, sg.points, sg.seeds, sg.levels,
                sg.capped ? ", cut short by the budget" : "",
                sg.covered > 0 ? fmt::format(", {} spread where the light looked smooth", sg.covered) : std::string(),
                unreached),
            true);  // what accuracy was given up: said under --quiet too
        return;
    }
    if (!solve::final_gather(lit.mesh, welded, gathered_node, c.setup.direct_only ? emitted : s.radiosity, s.irradiance,
                             direct, drawn, *gather_engine, gs, lit.gathered.light))
        throw cancel::Interrupted();
    lit.gathered.points = static_cast<long>(drawn.gather_points.size());
    gather_engine.reset();
    if (o.gather_refine > 0 && !c.setup.direct_only) refine_gather(c, lit, direct, welded, gs, engines);
}

}  // namespace

Lit gather(const LightContext& c, Lit lit, EngineStack& engines) {
    const auto t0 = Clock::now();
    lit.gathered = Gathered{};
    if (c.plan.o.gather > 0) {
        c.progress.begin_stage("gather");  // the weld and the grading too: the gather's time
        Solution& s = lit.solved.solution;
        output::WeldedMesh welded = output::weld(c.scene.nodes.size(), lit.mesh, s.radiosity);
        const std::size_t budget = gather_budget(c.plan, lit.mesh);
        if (too_many(budget, gathered_vertices(c.scene, welded))) {
            gather_vertices(c, lit, welded, engines, budget);
        } else {
            // Elements along contact lines halved once, so that the gather's vertices follow the
            // light's fall there (mesh/contact.h): on copies, kept if the gather goes ahead.
            const mesh::Texturing texturing(c.scene);
            mesh::Mesh graded = lit.mesh;
            std::vector<glm::dvec3> radiosity = s.radiosity, irradiance = s.irradiance;
            const std::size_t split = solve::grade_contacts(
                graded, radiosity, irradiance, kContactGrading * c.setup.mesh_settings.element_size, &texturing);
            if (split > 0) {
                // Graded past the budget: the gather goes ahead ungraded.
                output::WeldedMesh graded_welded = output::weld(c.scene.nodes.size(), graded, radiosity);
                if (!too_many(budget, gathered_vertices(c.scene, graded_welded))) {
                    lit.mesh = std::move(graded);
                    s.radiosity = std::move(radiosity);
                    s.irradiance = std::move(irradiance);
                    welded = std::move(graded_welded);
                    lit.gathered.contact_split = split;
                }
            }
            gather_vertices(c, lit, welded, engines, 0);
        }
        lit.welded = std::move(welded);  // of lit.mesh, as graded and refined by the gather
        c.progress.end_stage();
    }
    lit.gather_seconds = seconds_since(t0);
    return lit;
}

}  // namespace hemirad::bake
