// report.json (see report.h).
#include "bake/report.h"

#include <algorithm>
#include <fstream>

#include <fmt/core.h>

#include "bake/gather.h"
#include "bake/stage_checkpoint.h"
#include "core/error.h"
#include "core/memory.h"
#include "core/parallel.h"
#include "dist/dist.h"
#include "formfactor/near_field.h"
#include "output/finite.h"

namespace hemirad::bake {

using ordered_json = nlohmann::ordered_json;

namespace {

ordered_json vec3(const glm::dvec3& v) { return ordered_json::array({v.x, v.y, v.z}); }

ordered_json effect_json(const scene::EffectDecision& d) {
    return {{"on", d.on}, {"forced", d.forced}, {"why", d.why}};
}

ordered_json device_json(const Record& r) {
    ordered_json out = {{"backend", r.choice.backend}, {"platform", r.choice.platform}, {"name", r.choice.name}, {"id", r.choice.id}};
    if (!r.fallback.is_null()) out["fallback"] = r.fallback;
    if (r.choice.stats && r.choice.stats->members.size() > 1) {
        ordered_json members = ordered_json::array();
        for (const formfactor::ShardStats::Member& m : r.choice.stats->members) {
            ordered_json member = {{"id", m.id}, {"shots", m.shots}, {"chunks", m.chunks}, {"seconds", m.seconds}};
            if (!m.dropped.empty()) member["dropped"] = m.dropped;
            members.push_back(member);
        }
        out["members"] = members;
    }
    out["ranks"] = dist::size();
    // The shots a call of the matrix rows, refinement and the gather: the engine's preferred batch
    // (a GPU's from its compute units) or --batch, whichever is more.
    out["batch"] = std::max({r.lit.solved.preferred_batch, formfactor::Engine::kDefaultBatch,
                             std::size_t(std::max(1, r.plan.o.batch))});
    return out;
}

ordered_json settings_json(const Record& r) {
    const Options& o = r.plan.o;
    const Setup& S = r.setup;
    const Meshed& M = r.meshed;
    const Lit& L = r.lit;
    ordered_json out = {
        {"quality", o.quality},
        {"hemicube", o.hemicube},
        {"patch_size", S.mesh_settings.patch_size},
        {"element_size", S.mesh_settings.element_size},
        {"threshold", S.threshold},
        {"max_passes", max_passes_for(o, L.mesh.patches.size())},
        {"batch", M.solver == "progressive" ? progressive_batch(o) : o.batch},
        {"batch_share", o.batch_share},
        {"threads", parallel::threads()},
        {"cluster_apart", S.mesh_settings.cluster && S.mesh_settings.cluster_apart},
        {"gather", o.gather},
        {"gather_passes", o.gather_passes},
        {"gather_refine", o.gather_refine},
        {"gather_contrast", o.gather_contrast},
        {"gather_points", gather_budget(r.plan)},
        {"seed", o.seed},
        {"device", o.device},
        {"verify", o.verify},
        {"verify_every", o.verify_every},
        {"solver", M.solver},
        {"effects", o.effects},
        {"refine_levels", o.refine_levels},
        {"contrast", o.contrast},
        {"camera", S.view.name},  // the file's camera; "look-from"; "framing" (outside) or "framing (inside)" (a closed room)
        {"exposure", r.exposure},
        {"output_mode", o.output_mode},
        {"image", {S.width, S.height}},
        {"preview_every", o.preview_every},
        {"checkpoint", o.checkpoint},
        {"checkpoint_every", o.checkpoint_every},
        {"resume", o.resume},
    };
    return out;
}

ordered_json plan_json(const Record& r) {
    const Plan& P = r.plan;
    const Meshed& M = r.meshed;
    ordered_json out = {{"solver", {{"name", M.solver}, {"why", M.solver_why}}},
                      {"memory", {{"limit", P.memory_limit.bytes},
                                  {"limit_from", P.memory_limit.source},
                                  {"estimate", M.memory.total()},
                                  {"needed", M.memory.needed()},
                                  {"parts", [&] {
                                       ordered_json parts = ordered_json::object();
                                       for (const MemoryPart& p : M.memory.parts) parts[p.what] = p.bytes;
                                       return parts;
                                   }()}}}};
    if (P.memory_limit.available) out["memory"]["available"] = *P.memory_limit.available;  // without --max-memory
    // Measured: the most this process held so far (resident), the outputs not yet written.
    out["memory"]["peak"] = peak_memory();
    out["expected_seconds"] = ordered_json::object();
    for (const auto& [what, seconds] : r.expected.parts) out["expected_seconds"][what] = seconds;
    return out;
}

ordered_json effects_json(const Record& r) {
    const Options& o = r.plan.o;
    const Setup& S = r.setup;
    const Meshed& M = r.meshed;
    const Lit& L = r.lit;
    ordered_json out;
    std::string refine_why = S.effects.refinement.why;
    if (S.effects.refinement.on && o.refine_levels == 0) {
        refine_why = "turned off by --refine-levels 0";
    } else if (S.effects.refinement.on) {
        std::size_t split = 0;
        for (const auto& l : L.levels) split += l.split;
        refine_why += L.levels.empty()
                          ? fmt::format("; no neighbours' irradiance differed by more than {:g}: nothing split", o.contrast)
                          : fmt::format("; {} elements split over {} levels ({} → {} elements)", split, L.levels.size(),
                                        r.elements_before, L.mesh.elements.size());
    }
    const bool hemicube = S.effects.occlusion.on;
    out = {
        {"occlusion", effect_json(S.effects.occlusion)},
        {"colour", effect_json(S.effects.colour)},
        {"interreflection", effect_json(S.effects.interreflection)},
        {"two_sided", effect_json(S.effects.two_sided)},
        {"see_through", effect_json(S.effects.see_through)},
        // Inverted-hull toon outlines, left out of the bake where on (scene/outlines.h).
        {"outlines", effect_json(S.effects.outlines)},
        {"refinement", effect_json({S.effects.refinement.on && !L.levels.empty(), S.effects.refinement.forced, refine_why})},
        {"convergence", effect_json({S.effects.convergence.on, S.effects.convergence.forced,
                                     S.effects.convergence.why + fmt::format(" (solver {}, threshold {:g})", M.solver, S.threshold)})},
        {"near_field", {{"on", hemicube}, {"forced", false},
                        {"why", hemicube ? fmt::format("receivers within {} shooter radii get the exact form factor at their centroid, scaled by the visible share the hemicube measured", formfactor::NearFieldEngine::kDefaultReach)
                                         : std::string("the form factors are exact: nothing to correct")}}},
        {"ambient", {{"on", M.solver == "progressive"}, {"forced", false},
                     {"why", M.solver == "progressive" ? "the unshot flux is added as an ambient term (Cohen et al. 1988) with the measured reflectance"
                                                          : "the matrix solve leaves no unshot light to stand in for"}}},
    };
    return out;
}

ordered_json meshes_json(const Record& r) {
    const Lit& L = r.lit;
    ordered_json out = ordered_json::array();
    const auto summaries = output::summarize(r.scene, L.mesh, L.solved.solution.radiosity, L.solved.solution.irradiance);
    for (std::size_t n = 0; n < summaries.size(); ++n) {
        if (r.scene.nodes[n].synthetic) continue;  // the sky dome: not one of the file's meshes
        const auto& s = summaries[n];
        out.push_back({{"name", s.name}, {"area", s.area}, {"radiosity", vec3(s.radiosity)}, {"irradiance", vec3(s.irradiance)}});
    }
    return out;
}

}  // namespace

ordered_json make_report(const Record& r) {
    const Options& o = r.plan.o;
    const Meshed& M = r.meshed;
    const Lit& L = r.lit;
    const solve::Energy& energy = L.solved.solution.energy;
    ordered_json report;
    report["version"] = HEMIRAD_VERSION;
    report["scene"] = o.scene;
    report["device"] = device_json(r);
    report["settings"] = settings_json(r);
    report["counts"] = {{"triangles", r.scene.triangles.size()},
                        {"patches", L.mesh.patches.size()},
                        {"elements", L.mesh.elements.size()},
                        {"elements_before_refinement", r.elements_before},
                        {"gather_points", L.gathered.points},
                        // The elements a gather hemicube draws (a planar patch as one).
                        {"gather_drawn", L.gathered.points > 0 ? gather_drawn(L.mesh) : 0},
                        {"contact_split", L.gathered.contact_split},
                        {"gather_split", L.gathered.gather_split},
                        {"quads", L.mesh.quads},
                        {"clusters", L.mesh.clusters},
                        {"split_clusters", L.mesh.split_clusters},
                        {"moved_clusters", L.mesh.moved_clusters},
                        {"joined_clusters", L.mesh.joined_clusters},
                        {"texture_splits", L.mesh.texture_splits},
                        {"mask_holes", L.mesh.holes},
                        // Emitter patches an emissive texture's edge crosses, split into a
                        // shooter per element / left whole over the cap (mesh::Mesh), per side.
                        {"emission_splits", L.mesh.emission_splits},
                        {"emission_unsplit", L.mesh.emission_unsplit},
                        {"dropped_triangles", L.mesh.dropped_triangles},
                        {"skipped_primitives", r.scene.skipped_primitives}};
    if (L.gathered.sparse_seeds > 0) {
        const Gathered& g = L.gathered;
        // A sparse gather (solve/sparse_gather.h): what it shot and what it interpolated.
        report["counts"]["sparse_gather"] = {{"vertices", g.sparse_vertices},
                                             {"budget", g.sparse_budget},
                                             {"points", g.points},
                                             {"seeds", g.sparse_seeds},
                                             {"levels", g.sparse_levels},
                                             {"covered", g.sparse_covered},
                                             {"interpolated", g.sparse_interpolated},
                                             {"unreached", g.sparse_unreached},
                                             {"capped", g.sparse_capped}};
    }
    report["plan"] = plan_json(r);
    report["passes"] = L.solved.solution.passes;
    // The progressive solver's steps (this run's, from a --resume on): engine calls, each of the
    // shooters taken together, and the most one took.
    if (L.solved.solution.steps > 0)
        report["steps"] = {{"count", L.solved.solution.steps}, {"largest", L.solved.solution.largest_step}};
    if (L.solved.solution.resumed_from >= 0) report["resumed_from_pass"] = L.solved.solution.resumed_from;
    // "checkpoint" (where the bake kept one): {"file", "automatic" (the cache folder's, removed
    // once the outputs are committed; false: --checkpoint FILE, kept), "why"}. "resumed" (where it
    // went on from a checkpoint, --resume or the automatic one): {"from": the stage it held,
    // "solving" (the solver's state part-way; resumed_from_pass says where), "solved", "refined"
    // or "gathered" (the stages after it were run, those up to it skipped), "file", "written":
    // when, UTC}. A resumed bake's other numbers are an uninterrupted bake's.
    if (r.checkpoints && !r.checkpoints->why.empty())
        report["checkpoint"] = {{"file", r.checkpoints->file.string()},
                                {"automatic", r.checkpoints->automatic},
                                {"why", r.checkpoints->why}};
    if (r.checkpoints && r.checkpoints->resumed)
        report["resumed"] = {{"from", stage_name(*r.checkpoints->resumed)},
                             {"file", r.checkpoints->resume_file.string()},
                             {"written", r.checkpoints->written}};
    report["converged"] = L.solved.solution.converged;
    if (L.solved.solution.converged) report["converged_by"] = L.solved.solution.convergence_rule;
    report["error"] = L.solved.solution.error;
    if (M.solver == "matrix") report["iterations"] = L.solved.solution.iterations;
    if (L.solved.row_cache) {
        const formfactor::RowCacheStats& rc = *L.solved.row_cache;
        report["row_cache"] = {{"requests", rc.requests},
                               {"reused", rc.hits},
                               {"shot", rc.shot},
                               {"kept", rc.kept},
                               {"dropped", rc.dropped},
                               {"peak_bytes", rc.peak_bytes},
                               {"budget_bytes", rc.budget_bytes}};
    }
    report["energy"] = {{"emitted", energy.emitted},
                        {"absorbed", energy.absorbed},
                        {"escaped", energy.escaped},
                        {"unshot", energy.unshot},
                        {"unshot_fraction", L.solved.solution.unshot_fraction},
                        {"ambient_irradiance", vec3(L.solved.solution.ambient)}};
    report["effects"] = effects_json(r);
    report["timings_s"] = ordered_json::object();  // keeps the contract's key order; filled last
    report["meshes"] = meshes_json(r);
    if (L.solved.verified) {
        const formfactor::VerifySummary& v = *L.solved.verified;
        report["verify"] = {{"shots_checked", v.shots_checked},
                            {"cells_compared", v.cells_compared},
                            {"cells_mismatched", v.cells_mismatched},
                            {"max_abs_error", v.max_abs_error},
                            {"max_rel_error", v.max_rel_error},
                            {"tolerance", {{"absolute", formfactor::VerifyingEngine::kAbsoluteTolerance},
                                           {"relative", formfactor::VerifyingEngine::kRelativeTolerance}}}};
    }
    report["warnings"] = r.warnings;
    report["timings_s"] = {{"load", r.timings.load},
                           {"mesh", r.timings.mesh},
                           {"formfactors", L.solved.formfactor_seconds},
                           {"solve", L.solved.solve_seconds},
                           {"refine", L.refine_seconds},
                           {"gather", L.gather_seconds},
                           {"output", r.timings.output},
                           {"total", seconds_since(r.timings.start)}};
    if (r.progress) report["estimate"] = estimate_json(r.progress->eta(), r.progress->now());
    return report;
}

// `estimate`, beside timings_s: how the progress line's time left (bake/eta.h) fared.
//   "stages": [{"name", "predicted_s": the model's first prediction, from the work counts before
//              the stage ran (load, mesh: before each; the rest: once the mesh's counts were
//              known, before the solve), "refit_s": its prediction as it began, corrected by the
//              stages before it (the solve's measured/predicted ratio scales refinement's and
//              the gather's), "measured_s"}] — every stage that ran, in order ("lights": the
//              punctual lights' hemicubes at the solve's start; "output": the weld, render,
//              images and baked glTF; report.json itself is not in it);
//   "total_predicted_s": the sum of the predicted_s, "total_measured_s": seconds from the
//   bake's start to this report;
//   "at_10_percent": {"elapsed_s", "predicted_total_s", "ratio"}: the bake's total as the
//   progress line predicted it (elapsed + left) when 10% of total_measured_s had passed (or
//   first after, where the mesh's counts were not known yet), and predicted/measured.
nlohmann::ordered_json estimate_json(const Eta& eta, double now) {
    ordered_json stages = ordered_json::array();
    double predicted = 0.0;
    for (const Eta::Stage& s : eta.stages()) {
        if (s.state != Eta::Stage::State::done) continue;
        stages.push_back({{"name", s.plan.name},
                          {"predicted_s", s.first_predicted},
                          {"refit_s", std::max(0.0, s.predicted_at_begin)},
                          {"measured_s", s.measured}});
        predicted += s.first_predicted;
    }
    const Eta::Prediction at = eta.prediction_at(0.1, now);
    ordered_json out = {{"stages", stages}, {"total_predicted_s", predicted}, {"total_measured_s", now}};
    if (at.total >= 0.0 && now > 0.0)
        out["at_10_percent"] = {{"elapsed_s", at.at}, {"predicted_total_s", at.total}, {"ratio", at.total / now}};
    return out;
}

void write_report(const Record& r, const std::filesystem::path& file) {
    const ordered_json report = make_report(r);
    // NaN and Inf would be written as null: refuse the whole bake rather than a report that lies.
    if (const std::string where = output::first_non_finite(report); !where.empty())
        throw InternalError(fmt::format("report.json: {} is not finite; nothing written", where));
    std::ofstream f(file);
    f << report.dump(2) << "\n";
    if (!f) throw InternalError("cannot write report.json");
}

}  // namespace hemirad::bake
