// The accuracy-against-time sweep (see accuracy.h). Each run of the room is a bake's own stages
// (src/bake: plan, set up, mesh, solve, refine; no gather) with the run's settings as options:
// most use the hemicube engine stack and the progressive solver; the "solver" sweep also bakes
// the room as a bake plans it (exact unoccluded form factors, the matrix solver, adaptive
// refinement) and the combinations in between. A run's time is the wall time of those stages,
// kernel builds excluded (one engine choice, so one context, for the whole sweep).
#include "bench/accuracy.h"

#include "bake/gather.h"
#include "bake/stages.h"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <set>

#include "bench/room_reference.h"
#include "bench/throughput.h"
#include "cl/runtime.h"
#include "core/colour.h"
#include "core/error.h"
#include "core/quality.h"
#include "core/timing.h"
#include "formfactor/near_field.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "formfactor/unoccluded.h"
#include "mesh/mesh.h"
#include "output/output.h"
#include "scene/builder.h"
#include "scene/effects.h"
#include "solve/matrix.h"
#include "solve/progressive.h"
#include "solve/refinement.h"

namespace hemirad::bench {
namespace {

using ordered_json = nlohmann::ordered_json;

// Probes per surface edge: 8 × 8 points on each of the seven surfaces.
constexpr int kProbesPerEdge = 8;

// The engines every run uses, made by a bake's builder (bake::EngineStack) on one engine choice
// for the whole sweep: an OpenCL device (one context, so kernels build once per N) or the
// reference. `any` is a mesh to choose on (an automatic device's first shot is checked on it).
class Engines {
public:
    Engines(const std::string& spec, const mesh::Mesh& any)
        : choice_(bake::choose_engine(spec, false, 1, any, {32, 1})) {
        choice_.engine.reset();  // every run's engines are made like it, for its own mesh
    }
    std::string device() const {
        return choice_.id == "ref" ? "ref (host, 1 thread)" : choice_.name + " (" + choice_.id + ")";
    }
    const std::string& id() const { return choice_.id; }
    // A bake's engine stack at `settings`: the hemicube under the near-field correction, or
    // (occlusion off) exact unoccluded form factors.
    bake::EngineStack stack(const formfactor::Settings& settings, bool occlusion) {
        return bake::EngineStack(choice_, settings, occlusion, {});
    }

private:
    bake::EngineChoice choice_;
};

// --- Analytic configurations: the area form factor from one square to another -------------

struct AnalyticCase {
    std::string name;
    double exact;  // REFERENCES.md
    scene::Scene scene;
};

std::vector<AnalyticCase> analytic_cases() {
    scene::Scene s;
    const auto light = scene::add_material(s, glm::dvec3(0.0), glm::dvec3(1.0));
    const auto grey = scene::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    std::vector<AnalyticCase> cases;
    cases.push_back(
        {"parallel unit squares 1 apart", 0.1998248957, scene::parallel_rectangles(1, 1, 1, light, grey, s)});
    cases.push_back({"perpendicular unit squares sharing an edge", 0.2000437761,
                     scene::perpendicular_rectangles(1, 1, 1, light, grey, s)});
    return cases;
}

// F from node 0 to node 1: every patch of the shooter shoots once, its form factors to the
// receiver's elements weighted by its share of the shooter's area.
double area_form_factor(const mesh::Mesh& m, formfactor::Engine& engine) {
    double shooter_area = 0.0, weighted = 0.0;
    formfactor::ShotResult shot;
    for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
        if (m.patches[p].node != 0) continue;
        engine.shoot(p, p, shot);
        double to_receiver = 0.0;
        for (std::size_t i = 0; i < shot.size(); ++i)
            if (m.elements[shot.element[i]].node == 1) to_receiver += shot.F[i];
        weighted += m.patches[p].area * to_receiver;
        shooter_area += m.patches[p].area;
    }
    return weighted / shooter_area;
}

ordered_json analytic_sweep(Engines& engines, bool quick, std::ostream& log) {
    const std::vector<int> hemicubes =
        quick ? std::vector<int>{32, 128, 512} : std::vector<int>{16, 32, 64, 128, 256, 512, 1024};
    const std::vector<double> patch_sizes =
        quick ? std::vector<double>{1.0, 0.25} : std::vector<double>{1.0, 0.5, 0.25, 0.125};
    ordered_json rows = ordered_json::array();
    log << "\nanalytic form factors (near-field correction on, as in a bake)\n\n"
           "| case | exact | N | patch | F | error | ms |\n|---|---|---|---|---|---|---|\n";
    for (const AnalyticCase& c : analytic_cases())
        for (double patch : patch_sizes) {
            const mesh::Mesh m = mesh::build(c.scene, {patch, patch / 3.0});
            for (int n : hemicubes) {
                auto engine = engines.stack({n, 1}, true).level(m, 0);
                formfactor::ShotResult warm;
                engine->shoot(0, 0, warm);  // first uploads
                const auto t0 = Clock::now();
                const double value = area_form_factor(m, *engine);
                const double seconds = seconds_since(t0);
                const double error = std::abs(value - c.exact) / c.exact;
                rows.push_back({{"case", c.name},
                                {"exact", c.exact},
                                {"hemicube", n},
                                {"patch_size", patch},
                                {"value", value},
                                {"rel_error", error},
                                {"seconds", seconds}});
                log << fmt::format("| {} | {:.6f} | {} | {} | {:.6f} | {:.2e} | {:.2f} |\n", c.name, c.exact, n, patch,
                                   value, error, 1e3 * seconds);
            }
        }
    return rows;
}

// --- The room ------------------------------------------------------------------------------

struct RoomSettings {
    int hemicube = 256;
    double patch_fraction = 1.0 / 16.0;  // of the scene's diagonal, as --patch-size defaults
    double elements_per_edge = 3.0;      // element size = patch size / this
    double threshold = 1e-3;
    int batch = 1;
    std::string solver = "progressive";  // progressive | matrix (tolerance and batch as a bake sets them)
    bool exact = false;                  // formfactor::UnoccludedEngine instead of the hemicube stack
    int refine_levels = 0;               // adaptive refinement after the solve, as a bake does it
    std::string sweep;
    std::string note;  // printed beside the sweep, e.g. "as a bake plans it"
};

// The element of node `node` whose polygon holds `point` (in its plane), or the nearest centroid.
std::size_t element_at(const mesh::Mesh& m, std::uint32_t node, const glm::dvec3& point) {
    std::size_t best = m.elements.size();
    double best_distance = 1e300;
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        const mesh::Element& e = m.elements[k];
        if (e.node != node || e.back) continue;
        bool inside = true;
        for (int i = 0; i < e.poly.n && inside; ++i) {
            const glm::dvec3& a = e.poly.v[static_cast<std::size_t>(i)];
            const glm::dvec3& b = e.poly.v[static_cast<std::size_t>((i + 1) % e.poly.n)];
            inside = glm::dot(glm::cross(b - a, point - a), e.normal) >= 0.0;
        }
        if (inside) return k;
        const double d = glm::length(e.centroid - point);
        if (d < best_distance) {
            best_distance = d;
            best = k;
        }
    }
    return best;
}

// A run's settings as a bake's options: the sweep's own refinement contrast (solve::RefineSettings')
// and no cap on passes, no gather.
bake::Options room_options(const scene::Scene& room, const std::string& device, const RoomSettings& r) {
    bake::Options o;
    o.scene = "the accuracy benchmark's room";
    o.device = device;
    o.hemicube = r.hemicube;
    o.patch_size = room.diagonal() * r.patch_fraction;
    o.element_size = o.patch_size / r.elements_per_edge;
    o.threshold = r.threshold;
    o.batch = r.batch;
    o.batch_given = true;
    o.max_passes = 0;
    o.solver = r.solver;
    o.effects = r.exact ? "occlusion=off" : "occlusion=on";
    o.refine_levels = r.refine_levels;
    o.contrast = solve::RefineSettings().contrast;
    o.gather = 0;
    o.quiet = true;
    return o;
}

ordered_json room_run(const scene::Scene& room, const RoomSolution& reference, const std::vector<Probe>& probes,
                      Engines& engines, const RoomSettings& r) {
    if (r.solver != "progressive" && r.solver != "matrix") throw InternalError("accuracy: unknown solver " + r.solver);
    const auto t0 = Clock::now();
    const bake::Plan plan = bake::make_plan(room_options(room, engines.id(), r));
    scene::Scene scene = room;  // as the bake's set-up leaves it
    const bake::Setup setup = bake::set_up(plan, scene);
    bake::Meshed meshed = bake::build_mesh(plan, setup, scene);
    const std::size_t elements_before = meshed.mesh.elements.size();
    bake::EngineStack stack = engines.stack({r.hemicube, 1}, setup.effects.occlusion.on);
    bake::Progress silent;
    bake::Warnings warnings(silent);
    const bake::LightContext context{plan, setup, scene, meshed, silent, warnings};
    const std::string no_checkpoint;
    const bake::SolveContext solve_context{plan.o, setup.threshold, setup.matrix, no_checkpoint, no_checkpoint, silent, {}};
    const bake::Lit lit = bake::light(context, meshed.mesh, stack, solve_context);
    const bake::Solution& solution = lit.solved.solution;
    if (r.solver == "matrix" && !solution.converged) throw InternalError("accuracy: the matrix solve did not converge");
    const mesh::Mesh& m = lit.mesh;
    const std::vector<glm::dvec3>& radiosity = solution.radiosity;
    const std::vector<glm::dvec3>& irradiance = solution.irradiance;
    const long passes = solution.passes;        // hemicubes (rows, or passes) the solver shot
    const int iterations = solution.iterations;  // Gauss–Seidel sweeps (matrix)
    long regather_shots = 0;
    for (const solve::RefineLevel& level : lit.levels) regather_shots += level.shots;
    const double seconds = seconds_since(t0);

    // The error a user sees: radiosity (luminance) at probe points over every surface.
    double squares = 0.0;
    for (const Probe& probe : probes) {
        std::uint32_t node = 0;
        while (node < room.nodes.size() && room.nodes[node].name != probe.surface) ++node;
        const std::size_t k = element_at(m, node, probe.point);
        if (k >= m.elements.size()) throw InternalError("accuracy: no element on surface " + probe.surface);
        const double want = luminance(reference.radiosity_at(probe.point, probe.normal));
        const double got = luminance(radiosity[k]);
        squares += (got - want) * (got - want) / (want * want);
    }
    double worst_surface = 0.0;
    const std::vector<output::NodeSummary> summary = output::summarize(room, m, radiosity, irradiance);
    for (const auto& [name, average] : reference.surface_average)
        for (const auto& s : summary)
            if (s.name == name)
                worst_surface =
                    std::max(worst_surface, std::abs(luminance(s.radiosity) - luminance(average)) / luminance(average));
    ordered_json run = {{"hemicube", r.hemicube},
                        {"patch_size", plan.o.patch_size},
                        {"element_size", plan.o.element_size},
                        {"patch_fraction", r.patch_fraction},
                        {"elements_per_patch_edge", r.elements_per_edge},
                        {"threshold", r.threshold},
                        {"batch", r.batch},
                        {"solver", r.solver},
                        {"exact", r.exact},
                        {"refine_levels", r.refine_levels},
                        {"elements", m.elements.size()},
                        {"elements_before_refinement", elements_before},
                        {"passes", passes},
                        {"regather_shots", regather_shots},
                        {"seconds", seconds},
                        {"rms_rel_error", std::sqrt(squares / static_cast<double>(probes.size()))},
                        {"max_surface_error", worst_surface},
                        {"sweep", r.sweep}};
    if (r.solver == "matrix") run["iterations"] = iterations;
    if (!r.note.empty()) run["note"] = r.note;
    return run;
}

// `bake_plan`: a bake of the room plans occlusion off and refinement on (scene::plan_effects),
// so that exact form factors, the matrix solver and refinement are what `hemirad bake` does.
std::vector<RoomSettings> room_sweep(bool quick, bool bake_plan) {
    std::vector<RoomSettings> runs;
    // From the settings that were a bake's defaults; --quick, from coarse ones (a smoke test).
    RoomSettings base;
    if (quick) {
        base.hemicube = 64;
        base.patch_fraction = 1.0 / 6.0;
        base.elements_per_edge = 2.0;
        base.threshold = 1e-2;
    }
    runs.push_back(base);
    runs.back().sweep = "default";
    const auto add = [&](const std::string& sweep, auto change) {
        RoomSettings r = base;
        change(r);
        r.sweep = sweep;
        runs.push_back(r);
    };
    const auto pick = [quick](std::vector<double> full, std::vector<double> few) { return quick ? few : full; };
    for (double n : pick({32, 64, 128, 512, 1024}, {128}))
        add("hemicube", [n](RoomSettings& r) { r.hemicube = static_cast<int>(n); });
    for (double f : pick({6, 8, 12, 24, 32}, {8}))
        add("patch_size", [f](RoomSettings& r) { r.patch_fraction = 1.0 / f; });
    for (double e : pick({1, 2, 4, 6}, {3})) add("element_size", [e](RoomSettings& r) { r.elements_per_edge = e; });
    for (double t : pick({1e-1, 3e-2, 1e-2, 3e-3, 3e-4, 1e-4}, {3e-3}))
        add("threshold", [t](RoomSettings& r) { r.threshold = t; });
    for (double b : pick({4, 16}, {4})) add("batch", [b](RoomSettings& r) { r.batch = static_cast<int>(b); });
    if (!quick)  // the settings that matter most, together
        for (int n : {64, 128, 512})
            for (double f : {8.0, 12.0, 24.0})
                for (double e : {2.0, 4.0})
                    add("grid", [=](RoomSettings& r) {
                        r.hemicube = n;
                        r.patch_fraction = 1.0 / f;
                        r.elements_per_edge = e;
                        r.threshold = 1e-2;
                    });
    // What a bake's plan for this room costs and buys: the matrix solver, exact unoccluded form
    // factors and refinement, one by one and together (the last is the bake's plan). At the
    // base settings, and (full mode) at the default preset's, which a bake uses.
    struct Kind {
        const char* solver;
        bool exact;
        int refine_levels;
    };
    const Kind kinds[] = {
        {"matrix", false, 0}, {"matrix", true, 0}, {"progressive", true, 0}, {"matrix", false, 2}, {"matrix", true, 2}};
    const QualityPreset& preset = quality_preset("default");
    RoomSettings at_preset = base;
    at_preset.hemicube = preset.hemicube;
    at_preset.patch_fraction = preset.patch_fraction;
    at_preset.elements_per_edge = preset.elements_per_patch_edge;
    at_preset.threshold = preset.threshold;
    const bool preset_differs =
        base.hemicube != at_preset.hemicube || base.patch_fraction != at_preset.patch_fraction ||
        base.elements_per_edge != at_preset.elements_per_edge || base.threshold != at_preset.threshold;
    for (int at_default_preset = 0; at_default_preset < (quick || !preset_differs ? 1 : 2); ++at_default_preset)
        for (const Kind& kind : kinds) {
            RoomSettings r = at_default_preset ? at_preset : base;
            r.solver = kind.solver;
            r.exact = kind.exact;
            r.refine_levels = kind.refine_levels;
            r.sweep = "solver";
            const bool planned = bake_plan && r.solver == "matrix" && r.exact && r.refine_levels == 2;
            if (at_default_preset)
                r.note = planned ? "as `hemirad bake` plans it (--quality default)" : "at --quality default";
            else if (planned)
                r.note = "as a bake plans it";
            runs.push_back(r);
        }
    return runs;
}

}  // namespace

bool preset_eligible(const ordered_json& run) {
    // A field that is absent has the value of the original kind of run.
    return run["threshold"].get<double>() <= kPresetMaxThreshold &&
           run.value("solver", "progressive") == "progressive" && !run.value("exact", false) &&
           run.value("refine_levels", 0) == 0;
}

std::vector<std::size_t> pareto_front(const ordered_json& runs) {
    std::vector<std::size_t> order;
    for (std::size_t i = 0; i < runs.size(); ++i)
        if (preset_eligible(runs[i])) order.push_back(i);
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return runs[a]["seconds"].get<double>() < runs[b]["seconds"].get<double>();
    });
    std::vector<std::size_t> front;
    double best = 1e300;
    for (std::size_t i : order)
        if (runs[i]["rms_rel_error"].get<double>() < best) {
            best = runs[i]["rms_rel_error"].get<double>();
            front.push_back(i);
        }
    return front;
}

ordered_json derive_presets(const ordered_json& runs, const std::vector<std::size_t>& front) {
    const double base_error = runs[0]["rms_rel_error"].get<double>(), base_time = runs[0]["seconds"].get<double>();
    const auto error = [&](std::size_t i) { return runs[i]["rms_rel_error"].get<double>(); };
    const auto seconds = [&](std::size_t i) { return runs[i]["seconds"].get<double>(); };
    // The front is fastest first and each run more accurate than the one before.
    const auto first = [&](auto accept) { return *std::find_if(front.begin(), front.end(), accept); };
    const auto last = [&](auto accept) { return *std::find_if(front.rbegin(), front.rend(), accept); };
    ordered_json presets;
    // Run 0 (the defaults) is eligible and on the front or beaten by a run that is, so each
    // search finds a run.
    const std::pair<const char*, std::size_t> picks[] = {
        {"draft", first([&](std::size_t i) { return error(i) <= 2.0 * base_error; })},
        {"default", first([&](std::size_t i) { return error(i) <= base_error; })},
        {"high", last([&](std::size_t i) { return seconds(i) <= 8.0 * base_time; })},
    };
    for (const auto& [name, i] : picks) {
        presets[name] = runs[i];
        presets[name]["run"] = i;
    }
    return presets;
}

ordered_json run_accuracy(const AccuracyOptions& o, std::ostream& log) {
    const Room room_spec;
    const scene::Scene room = make_room_scene(room_spec);
    const mesh::Mesh coarse = mesh::build(room, {room.diagonal() / 4.0, room.diagonal() / 4.0});
    Engines engines(o.engine, coarse);
    log << fmt::format("accuracy against time on {}\n", engines.device());
    ordered_json out;
    out["device"] = engines.device();
    out["analytic"] = analytic_sweep(engines, o.quick, log);

    auto t0 = Clock::now();
    // --quick: a 0.25 m grid, within 0.03% (surface averages) and 0.3% (probes) of converged.
    const double cell_size = o.quick ? 0.25 : kDefaultCellSize;
    const RoomSolution reference = solve_room(room_spec, cell_size);
    const double reference_seconds = seconds_since(t0);
    const std::vector<Probe> probes = room_probes(room_spec, o.quick ? 4 : kProbesPerEdge);
    log << fmt::format("\nroom: independent reference ({} m cells, exact form factors) in {:.1f} s; {} probes\n\n",
                       cell_size, reference_seconds, probes.size());

    // What a bake plans for the room: the "solver" sweep's combination of exact form factors,
    // the matrix solver and refinement is a bake's only if the planner turns occlusion off and
    // refinement on (and leaves colour and interreflection on, as the runs assume).
    const scene::EffectsPlan plan = scene::plan_effects(room, {});
    const bool bake_plan =
        !plan.occlusion.on && plan.refinement.on && plan.colour.on && plan.interreflection.on && plan.convergence.on;
    log << fmt::format("a bake plans for the room: occlusion {} ({}); refinement {}; colour {}\n\n",
                       plan.occlusion.on ? "on" : "off", plan.occlusion.why, plan.refinement.on ? "on" : "off",
                       plan.colour.on ? "on" : "off");
    const std::vector<RoomSettings> sweep = room_sweep(o.quick, bake_plan);

    {  // warm-up: kernel builds for the N values of the sweep (re-gathers' too) stay out of the timings
        std::set<int> hemicubes;
        for (const RoomSettings& r : sweep)
            if (!r.exact)
                for (int level = 0; level <= r.refine_levels; ++level)
                    hemicubes.insert(solve::regather_hemicube(r.hemicube, level));
        formfactor::ShotResult shot;
        for (int n : hemicubes) engines.stack({n, 1}, true).level(coarse, 0)->shoot(0, 0, shot);
    }
    log << "| sweep | solver | form factors | refine | N | patch | element | threshold | batch | passes | elements "
           "| s | rms error | worst surface |\n"
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    ordered_json runs = ordered_json::array();
    for (const RoomSettings& r : sweep) {
        ordered_json run = room_run(room, reference, probes, engines, r);
        log << fmt::format(
            "| {} | {} | {} | {} | {} | {:.3f} | {:.3f} | {:g} | {} | {} | {} | {:.2f} | {:.2f}% | {:.2f}% |\n",
            r.note.empty() ? r.sweep : r.sweep + ": " + r.note, r.solver, r.exact ? "exact" : "hemicube",
            r.refine_levels, r.exact ? "-" : std::to_string(r.hemicube), run["patch_size"].get<double>(),
            run["element_size"].get<double>(), r.threshold, r.batch, run["passes"].get<long>(),
            run["elements"].get<long>(), run["seconds"].get<double>(), 100.0 * run["rms_rel_error"].get<double>(),
            100.0 * run["max_surface_error"].get<double>());
        runs.push_back(run);
    }
    const std::vector<std::size_t> front = pareto_front(runs);
    out["room"] = {{"reference", {{"cell_size", cell_size}, {"seconds", reference_seconds}, {"probes", probes.size()}}},
                   {"bake_plan",
                    {{"occlusion", plan.occlusion.on}, {"refinement", plan.refinement.on}, {"colour", plan.colour.on}}},
                   {"runs", runs},
                   {"pareto", front},
                   {"presets", derive_presets(runs, front)}};
    log << "\nPareto front of the progressive hemicube runs without refinement with threshold <= 1e-2 (fastest "
           "first):";
    for (std::size_t i : front)
        log << fmt::format(" [{:.2f} s, {:.2f}%]", runs[i]["seconds"].get<double>(),
                           100.0 * runs[i]["rms_rel_error"].get<double>());
    log << "\n\npresets, from those runs (draft: fastest within 2x the defaults' error; default:\n"
           "fastest at most as wrong as the defaults; high: most accurate within 8x their time)\n\n| preset | N | "
           "patch / diagonal | elements per "
           "patch edge | threshold | batch | s | rms error |\n|---|---|---|---|---|---|---|---|\n";
    for (const auto& [name, p] : out["room"]["presets"].items())
        log << fmt::format("| {} | {} | 1/{:.0f} | {:g} | {:g} | {} | {:.2f} | {:.2f}% |\n", name,
                           p["hemicube"].get<int>(), 1.0 / p["patch_fraction"].get<double>(),
                           p["elements_per_patch_edge"].get<double>(), p["threshold"].get<double>(),
                           p["batch"].get<int>(), p["seconds"].get<double>(), 100.0 * p["rms_rel_error"].get<double>());
    return {{"version", HEMIRAD_VERSION}, {"machine", machine_info()}, {"accuracy", out}};
}

}  // namespace hemirad::bench
