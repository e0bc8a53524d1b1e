// The bake as named stages (see bake.h and stages.h). Final files are written to a staging
// directory and renamed into place only when all exist (outputs.h).
#include "bake/bake.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>
#include <vector>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "bake/checkpoint.h"
#include "bake/engine_select.h"
#include "bake/engines.h"
#include "bake/gather.h"
#include "bake/outputs.h"
#include "bake/report.h"
#include "bake/solve.h"
#include "bake/stage_progress.h"
#include "bake/stage_checkpoint.h"
#include "bake/stages.h"
#include "core/counted.h"
#include "core/error.h"
#include "core/memory.h"
#include "core/parallel.h"
#include "core/timing.h"
#include "formfactor/hemicube.h"
#include "formfactor/parallel.h"
#include "output/finite.h"
#include "scene/outlines.h"
#include "solve/final_gather.h"
#include "solve/progressive.h"

namespace hemirad::bake {

namespace {

// Gauss–Seidel sweeps at most (each costs P² per channel; --solver auto avoids the matrix where
// reflectances are high enough to need many).
constexpr int kMaxSweeps = 20000;

// A bake expected to take longer than this (seconds) says so before it starts.
constexpr double kSayTimeAbove = 60.0;

// The quality's settings where the options give none, and the options' own checks.
Options complete_options(const Options& options, const QualityPreset& quality) {
    Options o = options;
    if (o.hemicube == 0) o.hemicube = quality.hemicube;
    if (o.threshold < 0.0) o.threshold = quality.threshold;
    if (o.hemicube % 2 != 0) throw InputError(fmt::format("--hemicube {}: must be even", o.hemicube));
    // Without --batch, the progressive solver's steps take the shooters that hold about as much
    // as the first (kBatchShare), and the engine calls of the matrix rows, refinement and the
    // gather grow with the devices or ranks that share them (none of which changes a number).
    // A resumed bake keeps its checkpoint's batch, on any number of them.
    if (!o.batch_given) {
        const CheckpointBatch planned{planned_batch(device_count(o.device) + EngineChoice::remote_ranks()), kBatchShare};
        const CheckpointBatch b = o.resume.empty() ? planned : checkpoint_batch(o.resume).value_or(planned);
        o.batch = b.share > 0.0 ? planned.batch : b.batch;
        o.batch_share = b.share;
    }
    if (o.contrast < 0.0) o.contrast = quality.contrast;
    if (o.gather < 0) o.gather = quality.gather;
    if (o.gather_passes <= 0) o.gather_passes = quality.gather_passes;
    if (o.gather_refine < 0) o.gather_refine = quality.gather_refine;
    if (o.gather_contrast < 0.0) o.gather_contrast = quality.gather_contrast;
    if (o.gather % 2 != 0 || (o.gather != 0 && (o.gather < 8 || o.gather > formfactor::kMaxHemicube)))
        throw InputError(fmt::format("--gather: {} must be 0 (none) or an even resolution from 8 to {}", o.gather,
                                     formfactor::kMaxHemicube));
    if (o.solver != "auto" && o.solver != "matrix" && o.solver != "progressive")
        throw InputError(fmt::format("--solver {}: expected auto, matrix or progressive", o.solver));
    return o;
}

}  // namespace

// Stage "plan": before any file is read.
Plan make_plan(const Options& options) {
    Plan p;
    p.quality = &quality_preset(options.quality);
    p.o = complete_options(options, *p.quality);
    p.gather_given = options.gather >= 0;
    const Options& o = p.o;
    try {
        p.overrides = scene::parse_effect_overrides(o.effects);
    } catch (const std::invalid_argument& e) {
        throw InputError(fmt::format("--effects {}: {}", o.effects, e.what()));
    }
    if (o.look_from.empty() != o.look_at.empty())
        throw InputError(o.look_from.empty() ? "--look-at needs --look-from" : "--look-from needs --look-at");
    if (!o.look_from.empty() && !o.camera.empty()) throw InputError("--camera and --look-from name two views; give one");
    if (!o.look_from.empty())
        p.look = std::pair(parse_point(o.look_from, "--look-from"), parse_point(o.look_at, "--look-at"));
    if (!o.sky.empty()) p.sky = scene::parse_sky(o.sky, "--sky");
    if (!o.sun.empty()) p.sun = scene::parse_sun(o.sun, "--sun");
    // Files named by options, before any work: a wrong --resume fails at once, and a --checkpoint
    // naming the scene (or any file not a checkpoint) must not be overwritten.
    if (!o.checkpoint.empty()) check_checkpoint_target(o.checkpoint);
    if (!o.resume.empty()) check_resume_source(o.resume);
    check_output_names(o);
    p.memory_limit = memory_limit_of(o.max_memory);
    return p;
}

namespace {

// Stage "load": the scene, with the sky and sun the options add, that has something to bake.
scene::Scene load(const Plan& p) {
    scene::LoadOptions load_options;
    load_options.max_bytes = p.memory_limit.bytes;
    load_options.limit_source = p.memory_limit.source;
    load_options.inputs = [&](const std::vector<fs::path>& inputs) { check_inputs_kept(p.o, inputs); };
    load_options.strict_textures = p.o.strict_textures;
    scene::Scene scene = scene::load(p.o.scene, load_options);
    if (p.sky && !scene.triangles.empty()) scene::add_sky(scene, *p.sky);
    if (p.sun) scene.lights.push_back(*p.sun);
    check_scene(scene);
    cancel::check();  // a signal while loading a large scene
    return scene;
}

// Which effects the scene calls for (report.json `effects` says why), applied to the scene.
scene::EffectsPlan plan_effects(const Plan& p, scene::Scene& scene) {
    const Options& o = p.o;
    scene::EffectsPlan effects = scene::plan_effects(scene, p.overrides);
    scene::apply_see_through(scene, effects);
    scene::apply_outlines(scene, effects);
    check_emitters_left(scene, effects);
    scene::apply_two_sided(scene, effects, p.overrides);
    if (auto w = scene::back_light_warning(scene)) scene.warnings.push_back(*w);
    scene::apply_colour(scene, effects);
    if (o.verify && !effects.occlusion.on) {
        if (effects.occlusion.forced)
            throw InputError("--verify checks the hemicube engines, which --effects occlusion=off does not use");
        effects.occlusion = {true, false,
                             "kept on for --verify, which checks the hemicube engines (" + effects.occlusion.why + ")"};
    }
    if (p.overrides.interreflection == scene::Force::off && o.solver == "progressive")
        throw InputError("--solver progressive: direct light only (--effects interreflection=off) is solved by --solver matrix");
    return effects;
}

// The render's view and size.
void plan_view(const Plan& p, const scene::Scene& scene, Setup& s) {
    const Options& o = p.o;
    s.view = p.look ? output::look_view(p.look->first, p.look->second, 0.8)
                    : output::choose_view(scene, o.camera);  // fails early on a bad --camera
    if (o.fov > 0.0) s.view.yfov = o.fov * M_PI / 180.0;
    s.width = o.image_width;
    const double rows = std::max(1.0, std::round(s.width / s.view.aspect));  // the loader keeps aspects within [1/16, 16]
    if (!(rows <= kMaxImageSide))
        throw InputError(fmt::format("--image-width {}: camera '{}' (aspect ratio {:g}) makes the image {:g} pixels "
                                     "high, above {}; choose a smaller --image-width",
                                     s.width, s.view.name, s.view.aspect, rows, kMaxImageSide));
    s.height = static_cast<int>(rows);
}

// What the memory estimate is made from, before the mesh's counts are known.
BakeShape plan_shape(const Plan& p, const scene::Scene& scene, const Setup& s) {
    const Options& o = p.o;
    BakeShape shape;
    shape.hemicube = o.hemicube;
    shape.batch = progressive_batch(o);
    shape.matrix = s.matrix;
    shape.opencl = s.effects.occlusion.on && may_use_opencl(o.device);
    shape.fallback_copy = shape.opencl && o.device == "auto";
    for (const scene::Triangle& t : scene.triangles)
        for (const glm::dvec3& rho : t.rho) shape.max_reflectance = std::max({shape.max_reflectance, rho.x, rho.y, rho.z});
    shape.refine_levels = s.effects.refinement.on ? o.refine_levels : 0;
    shape.pixels = double(s.width) * double(s.height);
    // A parallel shot's grid follows the median element, which the counts do not give (clusters'
    // faces can be far smaller than the element size): counted at its cap.
    if (std::any_of(scene.lights.begin(), scene.lights.end(), [](const scene::PunctualLight& l) {
            return l.type == scene::PunctualLight::Type::directional && l.intensity != glm::dvec3(0.0);
        })) {
        const double side = formfactor::ParallelSettings().max_cells;
        shape.parallel_cells = side * side;
    }
    return shape;
}

}  // namespace

// Stage "set up": what the loaded scene calls for, before any of the mesh is built.
Setup set_up(const Plan& p, scene::Scene& scene) {
    const Options& o = p.o;
    Setup s;
    std::vector<scene::Triangle> see_through = output::see_through_triangles(scene);
    s.effects = plan_effects(p, scene);
    if (s.effects.see_through.on) s.see_through = std::move(see_through);
    const double diagonal = scene.diagonal();
    if (!(diagonal > 0.0) || !std::isfinite(diagonal))
        throw InputError(fmt::format("{}: the scene has no extent (all vertices coincide)", o.scene));
    s.mesh_settings.patch_size = o.patch_size > 0.0 ? o.patch_size : diagonal * p.quality->patch_fraction;
    s.mesh_settings.element_size =
        o.element_size > 0.0 ? o.element_size : s.mesh_settings.patch_size / p.quality->elements_per_patch_edge;
    // The exact unoccluded engine integrates over each patch's polygon: clusters only for the hemicube.
    s.mesh_settings.cluster = s.effects.occlusion.on;
    s.mesh_settings.cluster_apart = o.cluster_apart;
    if (s.mesh_settings.element_size > s.mesh_settings.patch_size)
        throw InputError(fmt::format("--element-size {} is larger than the patch size {}", s.mesh_settings.element_size,
                                     s.mesh_settings.patch_size));
    plan_view(p, scene, s);
    s.direct_only = !s.effects.interreflection.on;
    s.matrix = solve::matrix_settings(o.threshold, o.batch);
    if (!s.effects.convergence.on) s.matrix.tolerance = kUnconvergedTolerance;
    s.matrix.grey = !s.effects.colour.on;
    s.matrix.interreflection = !s.direct_only;
    s.matrix.max_iterations = kMaxSweeps;
    s.shape = plan_shape(p, scene, s);
    s.threshold = s.effects.convergence.on ? o.threshold : kUnconvergedThreshold;
    return s;
}

namespace {

// The solver for a mesh of `counts` (--solver auto: by memory and expected time), and the memory
// it needs; InputError where that is more than the bake may use.
void choose_solver_within_memory(const Plan& p, const Setup& s, const mesh::Counts& counts, Meshed& m) {
    const Options& o = p.o;
    const MemoryLimit& limit = p.memory_limit;
    m.shape.counts = counts;
    // Direct light only is a matrix of the emitters' rows; previews show the progressive solution
    // pass by pass, which a matrix solve does not have.
    m.solver = o.solver;
    m.solver_why = "--solver " + o.solver;
    if (m.solver == "auto") {
        if (p.overrides.interreflection == scene::Force::off) {
            m.solver = "matrix";
            m.solver_why = "--effects interreflection=off: direct light only is the emitters' rows";
        } else if (o.preview_every > 0) {
            m.solver = "progressive";
            m.solver_why = "--preview-every shows the progressive solver's passes";
        } else {
            const SolverChoice c = choose_solver(m.shape, limit.bytes);
            m.solver = c.solver;
            m.solver_why = c.why;
        }
    }
    m.memory = estimate_memory(m.shape, m.solver);
    const double needed = m.memory.needed();
    if (needed <= limit.bytes) {
        if (!limit.available || needed <= *limit.available) return;
        throw InputError(fmt::format("{}: the bake would need about {} ({}), more than the {} available on this "
                                     "machine now (of {} it has); free some, or give --max-memory to bake anyway",
                                     o.scene, format_bytes(needed), m.memory.describe(), format_bytes(*limit.available),
                                     format_bytes(limit.bytes)));
    }
    std::string hint = fmt::format("a larger --patch-size or --element-size (now {:.4g} and {:.4g}) needs less",
                                   s.mesh_settings.patch_size, s.mesh_settings.element_size);
    if (m.solver == "matrix") {
        const double progressive = estimate_memory(m.shape, "progressive").needed();
        if (progressive <= limit.bytes) hint = fmt::format("--solver progressive would need about {}", format_bytes(progressive));
    }
    throw InputError(fmt::format("{}: the bake would need about {} for {:.4g} patches and {:.4g} elements ({}), "
                                 "more than the {} {}; {}",
                                 o.scene, format_bytes(needed), counts.patches, counts.elements, m.memory.describe(),
                                 format_bytes(limit.bytes), limit.source, hint));
}

}  // namespace

// Stage "mesh": patches and elements, the solver chosen by their counts before they are built.
Meshed build_mesh(const Plan& p, const Setup& s, scene::Scene& scene) {
    Meshed m;
    m.shape = s.shape;
    m.solver = p.o.solver;
    m.solver_why = "--solver " + p.o.solver;
    m.mesh = mesh::build(scene, s.mesh_settings,
                         [&](const mesh::Counts& counts) { choose_solver_within_memory(p, s, counts, m); });
    const std::string& file = p.o.scene;
    if (m.mesh.patches.empty()) throw InputError(fmt::format("{}: every triangle has zero area; nothing to bake", file));
    if (m.mesh.dropped_triangles > 0)
        scene.warnings.push_back(fmt::format("{}: {} dropped (of {}; under 1e-12 of their longest edge squared); "
                                             "report.json counts them",
                                             file, counted(m.mesh.dropped_triangles, "zero-area triangle"),
                                             grouped(scene.triangles.size())));
    warn_uneven_emitters(scene, m.mesh);
    check_lamps_seen(scene, m.mesh);
    if (p.o.preview_every > 0 && m.solver == "matrix")
        throw InputError("--preview-every shows the passes of the progressive solver; the matrix solver has none");
    return m;
}

namespace {

// The form-factor engine: the device's hemicube, or exact unoccluded form factors where nothing
// hides anything.
EngineChoice choose_engines(const Plan& p, const Setup& s, const mesh::Mesh& mesh, const formfactor::Settings& ff) {
    if (s.effects.occlusion.on) return choose_engine(p.o.device, p.o.verify, p.o.verify_every, mesh, ff);
    EngineChoice choice;
    choice.backend = "analytic";
    choice.platform = "host";
    choice.name = "exact unoccluded form factors (Lambert, point to polygon)";
    choice.id = "analytic";
    return choice;
}

// A checkpoint resumes only the bake it was made by: the same mesh and the settings that decide
// its numbers (not the device: every engine gives the reference's bits). The matrix solver's
// holds its rows, which depend on neither the batch nor the threshold. The lights are not in
// the mesh: their placement and intensity go into the fingerprint too. Empty without checkpoints
// (--no-checkpoint and neither --checkpoint nor --resume).
std::string checkpoint_fingerprint(const Plan& p, const Setup& s, const Meshed& m, const scene::Scene& scene) {
    const Options& o = p.o;
    if (o.checkpoint.empty() && o.resume.empty() && o.no_checkpoint) return {};
    std::string lights;
    for (const scene::PunctualLight& l : scene.lights)
        lights += fmt::format("; light {} at {:.17g},{:.17g},{:.17g} along {:.17g},{:.17g},{:.17g} of {:.17g},{:.17g},{:.17g} "
                              "cones {:.17g},{:.17g} range {:.17g}",
                              static_cast<int>(l.type), l.position.x, l.position.y, l.position.z, l.direction.x,
                              l.direction.y, l.direction.z, l.intensity.x, l.intensity.y, l.intensity.z, l.inner_cone,
                              l.outer_cone, l.range);
    const std::string form_factors =
        fmt::format("{} form factors, N {}, seed {}{}", s.effects.occlusion.on ? "hemicube" : "exact", o.hemicube, o.seed, lights);
    if (m.solver == "matrix")
        return bake_fingerprint(m.mesh, fmt::format("{}, matrix rows of {}", form_factors,
                                                    s.direct_only ? "the emitters" : "every patch that holds light"));
    const std::string share = o.batch_share > 0.0 ? fmt::format(" within {:.17g} of the largest", o.batch_share) : "";
    return bake_fingerprint(m.mesh, fmt::format("{}, batch {}{}, threshold {:.17g}", form_factors, progressive_batch(o), share,
                                                s.threshold));
}

// Work that would take minutes is said before it starts (by the model of 2 CPU cores).
// `w`: work_counts of the bake, whose drawn mesh the gather's cost and budget are taken from.
TimeEstimate say_expected_time(const Plan& p, const Meshed& m, const WorkCounts& w, Warnings& warnings) {
    const BakeShape& shape = m.shape;
    const double refined = shape.counts.elements * (shape.refine_levels > 0 ? 2.0 : 1.0);
    const double budget = planned_gather_budget(w);
    const double gathered = p.o.gather > 0 ? (budget > 0.0 ? std::min(refined, budget) : refined) : 0.0;
    const TimeEstimate expected =
        expected_bake_time(shape, m.solver, double(m.mesh.lights.size()), gathered,
                           p.o.gather > 0 ? gather_point_seconds(gather_drawn(w), p.o.gather) : 0.0);
    // The progressive solve's passes are not counted (expected_bake_time): the time said is then
    // what the rest takes, and says so (the ww2 city's "about 61 s" took 6 min, 3 of them solving).
    const bool solve_counted = m.solver == "matrix";
    if (expected.total() > kSayTimeAbove)
        warnings.add(fmt::format(
            "this bake is expected to take {} {} ({}{}; modelled on 2 CPU cores through PoCL, a "
            "GPU is faster); --progress shows how far it is; Ctrl-C stops it leaving the output folder as "
            "it was, and its checkpoint lets the same command go on (unless --no-checkpoint)",
            solve_counted ? "about" : "more than", format_duration(expected.total()), expected.describe(),
            solve_counted ? "" : ", besides the progressive solve, whose passes are not known before it runs"));
    return expected;
}

}  // namespace

// Stages "solve", "refine" and "gather" on the engines `engines` makes. `mesh` is the one the
// engines were made for: it stays in place while the solve's engines live, then moves on.
Lit light(const LightContext& c, mesh::Mesh& mesh, EngineStack& engines, const SolveContext& sc) {
    const EngineChoice& choice = engines.choice();
    c.progress.note(fmt::format("form factors on {} ({}){}, {} solver", choice.id, choice.name,
                                EngineChoice::remote_ranks() > 0
                                    ? fmt::format(" and {} more MPI ranks", EngineChoice::remote_ranks())
                                    : std::string(),
                                c.meshed.solver));
    Lit lit;
    // A rerun goes on after the last stage its checkpoint holds (once: after a device fallback
    // the bake starts again from the solve); each stage done is kept.
    StageCheckpoints* cp = sc.checkpoints;
    const std::size_t warned = c.warnings.all().size();
    const auto keep = [&](Stage stage) {
        if (cp)
            save_stage(*cp, c.plan, c.setup, c.meshed, stage, lit,
                       std::vector<std::string>(c.warnings.all().begin() + long(warned), c.warnings.all().end()));
    };
    const Stage from = cp && cp->light ? *cp->resumed : Stage::solving;
    if (from != Stage::solving) {
        StageState resumed = std::move(*cp->light);
        cp->light.reset();
        for (const std::string& w : resumed.warnings) c.warnings.add(w);
        lit = std::move(resumed.lit);
        if (!resumed.has_mesh) lit.mesh = std::move(mesh);
    } else {
        fault_point("solve");
        lit.solved = solve(mesh, c.scene, c.meshed.solver, c.meshed.shape, engines, sc);
        lit.mesh = std::move(mesh);  // refinement makes engines of its own: the solve's are gone
        keep(Stage::solved);
    }
    if (from < Stage::refined) {
        fault_point("refine");
        lit = refine(c, std::move(lit), engines);
        keep(Stage::refined);
    }
    if (from < Stage::gathered) {
        fault_point("gather");
        lit = gather(c, std::move(lit), engines);
        keep(Stage::gathered);
    }
    return lit;
}

namespace {

// The device fallback around the lighting stages: should the automatically chosen device fail
// part-way, the bake starts again on the reference engine from the mesh as built. What was
// solved on the failed device is dropped, not mixed with the reference's: the bake is then
// exactly a reference bake. `fallback` says which device failed and why.
Lit light_with_fallback(const LightContext& c, mesh::Mesh& mesh, EngineChoice& choice, const formfactor::Settings& ff,
                        const SolveContext& sc, nlohmann::ordered_json& fallback) {
    const mesh::Mesh built = choice.automatic ? mesh : mesh::Mesh{};
    for (;;) {
        try {
            EngineStack engines(choice, ff, c.setup.effects.occlusion.on, c.plan.o.on_shot);
            return light(c, mesh, engines, sc);
        } catch (const std::exception& e) {
            const std::string why = device_failure(e);
            if (why.empty() || !choice.automatic) throw;
            c.progress.end_stage();
            fallback = {{"from", choice.id}, {"name", choice.name}, {"why", why}};
            c.warnings.add(fmt::format("{} failed part-way: {}; starting again on the reference engine", choice.id, why),
                           /*always=*/true);
            mesh = built;
            choice = choose_engine("ref", false, c.plan.o.verify_every, mesh, ff);
        }
    }
}

// Devices that left the bake, and batches cut for memory: said after the lighting stages.
void warn_engine_events(const EngineChoice& choice, Warnings& warnings) {
    if (choice.stats)
        for (const formfactor::ShardStats::Member& m : choice.stats->members)
            if (!m.dropped.empty())
                warnings.add(fmt::format("{} failed and left the bake: {}; its shots were redone by the others", m.id,
                                         m.dropped));
    if (const EngineChoice::Shrinks& shrinks = *choice.shrinks; shrinks.count > 0)
        warnings.add(fmt::format("{} ran out of memory {} times ({}): its batches were cut to as few as {} shots, with "
                                 "the same results",
                                 choice.id, shrinks.count, shrinks.why, shrinks.smallest));
}

// Stage "write outputs": render.exr, render.png and baked.gltf, staged. Returns the exposure of
// render.png.
double write_outputs(const Plan& p, const Setup& s, const scene::Scene& scene, Lit& lit, OutputTransaction& out,
                     Warnings& warnings, Progress& progress) {
    const Options& o = p.o;
    const auto& radiosity = lit.solved.solution.radiosity;
    const auto& irradiance = lit.solved.solution.irradiance;
    if (!output::all_finite(radiosity) || !output::all_finite(irradiance))
        throw InternalError("the solution has a non-finite value; nothing written");
    // One weld of the mesh for every output: the gather's where it made one, its values then the
    // light drawn (the gather's at the vertices, else the elements' means); else one made here.
    const bool gathered = lit.gathered.points > 0;
    progress.writing("weld");
    output::WeldedMesh welded;
    if (lit.welded) {
        welded = std::move(*lit.welded);
        output::set_vertex_values(welded, gathered ? lit.gathered.light.radiosity
                                                   : output::vertex_values(welded, lit.mesh, radiosity));
    } else {
        welded = output::weld(scene.nodes.size(), lit.mesh, radiosity);  // no gather: no gathered light
    }
    progress.writing("render");
    const output::Image image =
        output::render(scene, welded, s.view, s.width, s.height, output::Surroundings{s.see_through, p.sky});
    if (!output::all_finite(image)) throw InternalError("the rendered image has a non-finite pixel; nothing written");
    progress.writing("render.exr");
    output::write_exr(image, out.staged("render.exr"));
    const double exposure = std::isnan(o.exposure) ? output::auto_exposure(image) : std::exp2(o.exposure);
    progress.writing("render.png");
    output::write_png(image, out.staged("render.png"), exposure);
    // The user's scene with the light baked in; or (--output-mode radiosity, and scenes not read
    // from a file) the element mesh alone.
    progress.writing("baked.gltf");
    if (o.output_mode == "scene" && scene.source) {
        const output::VertexValues incident =
            gathered ? lit.gathered.light.irradiance : output::vertex_values(welded, lit.mesh, irradiance);
        for (const std::string& w :
             output::write_scene_gltf(out.staged("baked.gltf"), o.output, scene, lit.mesh, welded, incident, exposure))
            warnings.add("baked.gltf: " + w);
    } else {
        output::write_baked_gltf(out.staged("baked.gltf"), scene, welded);
    }
    return exposure;
}

// The line that ends a bake.
std::string summary_line(const Options& o, const Meshed& m, const Lit& lit) {
    const Solution& s = lit.solved.solution;
    return fmt::format("{}, {} elements, wrote {}/report.json, baked.gltf, render.exr, render.png",
                       m.solver == "matrix" ? fmt::format("{} form-factor rows, {} sweeps, error bound {:.2e}", s.passes,
                                                          s.iterations, s.error)
                                            : fmt::format("{} passes, error {:.2e}", s.passes, s.error),
                       lit.mesh.elements.size(), o.output);
}

// What the time model predicts the stages after meshing from (stage_progress.h): the counts
// say_expected_time's estimate is made from.
WorkCounts work_counts(const Plan& p, const Setup& s, const Meshed& m, const scene::Scene& scene) {
    WorkCounts w;
    w.shape = m.shape;
    w.solver = m.solver;
    w.triangles = double(scene.triangles.size());
    w.light_hemicubes = double(m.mesh.lights.size());
    w.refine = s.effects.refinement.on && p.o.refine_levels > 0;
    w.gather = p.o.gather;
    w.gather_budget = double(gather_budget(p));
    w.gather_points_given = p.o.gather_points >= 0;
    w.gather_passes = s.direct_only ? 1 : p.o.gather_passes;
    w.gather_refine = p.o.gather_refine > 0 && !s.direct_only;
    if (m.solver == "progressive") w.max_passes = double(max_passes_for(p.o, m.mesh.patches.size()));
    // The solve's passes as the progress line first predicts them (stage_progress.h).
    // And what a gather draws (solve::gather_mesh).
    std::vector<double> emitted;
    emitted.reserve(m.mesh.patches.size());
    for (const mesh::Patch& patch : m.mesh.patches) {
        emitted.push_back((patch.emission.x + patch.emission.y + patch.emission.z) * patch.area);
        if (!patch.cluster() && patch.element_count > 1) w.gather_planar_patches += 1.0;
    }
    w.gather_cluster_cells = double(gather_drawn(m.mesh)) - w.gather_planar_patches;
    w.emitting_holders = double(solve::flux_holders(std::move(emitted), s.threshold));
    w.sky = p.sky.has_value();
    double reflected = 0.0, area = 0.0;
    for (const mesh::Element& e : m.mesh.elements) {
        const glm::dvec3& emission = m.mesh.patches[e.patch].emission;
        if (emission.x + emission.y + emission.z > 0.0) continue;
        reflected += (e.rho.x + e.rho.y + e.rho.z) / 3.0 * e.area;
        area += e.area;
    }
    w.reflectance = area > 0.0 ? reflected / area : 0.0;
    return w;
}

}  // namespace

int planned_batch(std::size_t members) {
    return members <= 1 ? 1 : static_cast<int>(std::min<std::size_t>(256, kShotsPerMember * members));
}

// A fixed cap stopped scenes of many patches before one round: city:1M at draft (364,391 patches)
// converges after 150,795 passes, foliage:100k (95,553) after more than 100,000.
long max_passes_for(const Options& o, std::size_t patches) {
    return o.max_passes >= 0 ? o.max_passes : std::max<long>(100000, 2 * static_cast<long>(patches));
}

void run(const Options& options, Progress& shown) {
    // One progress line through every stage, with the bake's time left from a model of its
    // stages re-fitted as it runs (stage_progress.h); report.json's `estimate` records it.
    StageProgress progress(shown);
    // The host stages' threads (--threads): the bake's bytes are the same whatever their count.
    const parallel::ThreadLimit host_threads(options.threads);
    Timings timings;
    timings.start = Clock::now();
    const Plan plan = make_plan(options);
    const Options& o = plan.o;

    progress.plan_load(o.scene);
    progress.begin_stage("load");
    auto t0 = Clock::now();
    scene::Scene scene = load(plan);
    timings.load = seconds_since(t0);
    const Setup setup = set_up(plan, scene);

    progress.plan_mesh(double(scene.triangles.size()));
    progress.begin_stage("mesh");
    t0 = Clock::now();
    Meshed meshed = build_mesh(plan, setup, scene);
    timings.mesh = seconds_since(t0);
    const WorkCounts counts = work_counts(plan, setup, meshed, scene);
    progress.plan_rest(counts);
    progress.begin_stage("engines");  // until the solve begins: the device's set-up

    formfactor::Settings ff;
    ff.hemicube = o.hemicube;
    ff.seed = o.seed;
    EngineChoice choice = choose_engines(plan, setup, meshed.mesh, ff);
    const std::string fingerprint = checkpoint_fingerprint(plan, setup, meshed, scene);
    StageCheckpoints checkpoints = read_resume(plan, setup, meshed, fingerprint);

    OutputTransaction out(o.output);
    // Only now, so that bad input is always exactly one line on stderr.
    Warnings warnings(progress);
    for (const std::string& w : scene.warnings) warnings.add(w, /*always=*/true);
    if (!choice.warning.empty()) warnings.add(choice.warning, /*always=*/true);
    const TimeEstimate expected = say_expected_time(plan, meshed, counts, warnings);
    plan_checkpoints(checkpoints, plan, setup, meshed, expected.total(), warnings, progress);

    const std::size_t elements_before = meshed.mesh.elements.size();
    const LightContext context{plan, setup, scene, meshed, progress, warnings};
    const SolveContext solve_context{o, setup.threshold, setup.matrix, fingerprint, checkpoints.solver_state, progress,
                                     [&](const solve::Progressive& solver) {
                                         write_png_preview(scene, meshed.mesh, solver, setup.view, setup.width,
                                                           setup.height, out);
                                     },
                                     &checkpoints};
    nlohmann::ordered_json fallback;
    Lit lit = light_with_fallback(context, meshed.mesh, choice, ff, solve_context, fallback);
    warn_engine_events(choice, warnings);

    t0 = Clock::now();
    const double exposure = write_outputs(plan, setup, scene, lit, out, warnings, progress);
    fault_point("output");  // the images and baked.gltf staged, nothing committed
    timings.output = seconds_since(t0);
    progress.end_stage();

    write_report({plan, setup, meshed, scene, lit, choice, fallback, elements_before, expected, exposure, warnings.all(),
                  timings, &checkpoints, &progress},
                 out.staged("report.json"));
    cancel::check();  // a signal while writing: nothing is committed
    out.commit(kOutputNames);
    finish_checkpoints(checkpoints, progress);
    progress.note(summary_line(o, meshed, lit));
}

void run(const Options& options) {
    Progress silent;
    run(options, silent);
}

}  // namespace hemirad::bake
