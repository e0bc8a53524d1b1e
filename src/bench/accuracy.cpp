// The accuracy-against-time sweep (see accuracy.h). Every run uses the engine stack of a bake
// (the hemicube engine under the near-field correction) and the progressive solver; its time
// is the wall time of meshing and solving, kernel builds excluded (a context keeps them).
#include "bench/accuracy.h"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <set>

#include "bench/room_reference.h"
#include "bench/throughput.h"
#include "cl/runtime.h"
#include "core/error.h"
#include "core/timing.h"
#include "formfactor/near_field.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "output/output.h"
#include "scene/builder.h"
#include "solve/progressive.h"

namespace hemirad::bench {
namespace {

using ordered_json = nlohmann::ordered_json;

// Probes per surface edge: 8 × 8 points on each of the seven surfaces.
constexpr int kProbesPerEdge = 8;

// The engine every run uses: an OpenCL device (one context for the whole sweep, so kernels
// build once per N) or the reference.
class EngineFactory {
public:
    explicit EngineFactory(const std::string& spec) {
        const std::vector<ocl::DeviceInfo> devices =
            spec == "ref" ? std::vector<ocl::DeviceInfo>{} : ocl::list_devices();
        if (const ocl::DeviceInfo* chosen = ocl::resolve_device(spec, "--device " + spec, devices))
            context_ = std::make_unique<ocl::Context>(*chosen);
    }
    std::string device() const {
        return context_ ? context_->info().name + " (" + context_->info().id() + ")" : "ref (host, 1 thread)";
    }
    // The bake's stack: the hemicube engine under the near-field correction.
    std::unique_ptr<formfactor::Engine> make(const mesh::Mesh& m, const formfactor::Settings& settings) {
        std::unique_ptr<formfactor::Engine> inner;
        if (context_)
            inner = std::make_unique<formfactor::OpenCLEngine>(m, *context_, settings,
                                                               formfactor::tuning_from_environment(context_->info()));
        else
            inner = std::make_unique<formfactor::ReferenceEngine>(m, settings);
        return std::make_unique<formfactor::NearFieldEngine>(m, std::move(inner));
    }

private:
    std::unique_ptr<ocl::Context> context_;
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
        for (std::size_t k = 0; k < m.elements.size(); ++k)
            if (m.elements[k].node == 1) to_receiver += shot.F[k];
        weighted += m.patches[p].area * to_receiver;
        shooter_area += m.patches[p].area;
    }
    return weighted / shooter_area;
}

ordered_json analytic_sweep(EngineFactory& engines, bool quick, std::ostream& log) {
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
                auto engine = engines.make(m, {n, 1});
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
    std::string sweep;
};

double luminance(const glm::dvec3& c) {
    return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
}

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

ordered_json room_run(const scene::Scene& room, const RoomSolution& reference, const std::vector<Probe>& probes,
                      EngineFactory& engines, const RoomSettings& r) {
    const auto t0 = Clock::now();
    const double patch = room.diagonal() * r.patch_fraction;
    const mesh::Mesh m = mesh::build(room, {patch, patch / r.elements_per_edge});
    auto engine = engines.make(m, {r.hemicube, 1});
    solve::Settings settings;
    settings.threshold = r.threshold;
    settings.batch = r.batch;
    solve::Progressive solver(m, *engine, settings);
    while (solver.step()) {
    }
    const std::vector<glm::dvec3> radiosity = solver.radiosity(/*ambient=*/true);
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
    const std::vector<output::NodeSummary> summary =
        output::summarize(room, m, radiosity, solver.irradiance(/*ambient=*/true));
    for (const auto& [name, average] : reference.surface_average)
        for (const auto& s : summary)
            if (s.name == name)
                worst_surface =
                    std::max(worst_surface, std::abs(luminance(s.radiosity) - luminance(average)) / luminance(average));
    return {{"hemicube", r.hemicube},
            {"patch_size", patch},
            {"element_size", patch / r.elements_per_edge},
            {"patch_fraction", r.patch_fraction},
            {"elements_per_patch_edge", r.elements_per_edge},
            {"threshold", r.threshold},
            {"batch", r.batch},
            {"elements", m.elements.size()},
            {"passes", solver.passes()},
            {"seconds", seconds},
            {"rms_rel_error", std::sqrt(squares / static_cast<double>(probes.size()))},
            {"max_surface_error", worst_surface},
            {"sweep", r.sweep}};
}

std::vector<RoomSettings> room_sweep(bool quick) {
    std::vector<RoomSettings> runs;
    // From the settings that were a bake's defaults; --quick, from coarse ones (a smoke test).
    const RoomSettings base = quick ? RoomSettings{64, 1.0 / 6.0, 2.0, 1e-2, 1, ""} : RoomSettings{};
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
    return runs;
}

}  // namespace

std::vector<std::size_t> pareto_front(const ordered_json& runs) {
    std::vector<std::size_t> order;
    for (std::size_t i = 0; i < runs.size(); ++i)
        if (runs[i]["threshold"].get<double>() <= kPresetMaxThreshold) order.push_back(i);
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
    EngineFactory engines(o.engine);
    log << fmt::format("accuracy against time on {}\n", engines.device());
    ordered_json out;
    out["device"] = engines.device();
    out["analytic"] = analytic_sweep(engines, o.quick, log);

    const Room room_spec;
    const scene::Scene room = make_room_scene(room_spec);
    auto t0 = Clock::now();
    // --quick: a 0.25 m grid, within 0.03% (surface averages) and 0.3% (probes) of converged.
    const double cell_size = o.quick ? 0.25 : kDefaultCellSize;
    const RoomSolution reference = solve_room(room_spec, cell_size);
    const double reference_seconds = seconds_since(t0);
    const std::vector<Probe> probes = room_probes(room_spec, o.quick ? 4 : kProbesPerEdge);
    log << fmt::format("\nroom: independent reference ({} m cells, exact form factors) in {:.1f} s; {} probes\n\n",
                       cell_size, reference_seconds, probes.size());

    {  // warm-up: kernel builds for the N values of the sweep stay out of the timings
        std::set<int> hemicubes;
        for (const RoomSettings& r : room_sweep(o.quick)) hemicubes.insert(r.hemicube);
        const mesh::Mesh m = mesh::build(room, {room.diagonal() / 4.0, room.diagonal() / 4.0});
        formfactor::ShotResult shot;
        for (int n : hemicubes) engines.make(m, {n, 1})->shoot(0, 0, shot);
    }
    log << "| sweep | N | patch | element | threshold | batch | passes | s | rms error | worst surface |\n"
           "|---|---|---|---|---|---|---|---|---|---|\n";
    ordered_json runs = ordered_json::array();
    for (const RoomSettings& r : room_sweep(o.quick)) {
        ordered_json run = room_run(room, reference, probes, engines, r);
        log << fmt::format("| {} | {} | {:.3f} | {:.3f} | {:g} | {} | {} | {:.2f} | {:.2f}% | {:.2f}% |\n", r.sweep,
                           r.hemicube, run["patch_size"].get<double>(), run["element_size"].get<double>(), r.threshold,
                           r.batch, run["passes"].get<long>(), run["seconds"].get<double>(),
                           100.0 * run["rms_rel_error"].get<double>(), 100.0 * run["max_surface_error"].get<double>());
        runs.push_back(run);
    }
    const std::vector<std::size_t> front = pareto_front(runs);
    out["room"] = {{"reference", {{"cell_size", cell_size}, {"seconds", reference_seconds}, {"probes", probes.size()}}},
                   {"runs", runs},
                   {"pareto", front},
                   {"presets", derive_presets(runs, front)}};
    log << "\nPareto front of the runs with threshold <= 1e-2 (fastest first):";
    for (std::size_t i : front)
        log << fmt::format(" [{:.2f} s, {:.2f}%]", runs[i]["seconds"].get<double>(),
                           100.0 * runs[i]["rms_rel_error"].get<double>());
    log << "\n\npresets, from runs with threshold <= 1e-2 (draft: fastest within 2x the defaults' error; default:\n"
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
