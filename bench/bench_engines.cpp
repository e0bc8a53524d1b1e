// Shot throughput of the hemicube engines on one scene, as ratios taken in one run: the engines
// alternate, repeat after repeat, over the same shots, after a warm-up (kernel builds excluded).
// Every timed shot of every engine is also compared with the reference, so a fast wrong engine
// cannot win. Usage: hemirad_bench_engines [SCENE] [--hemicube N] [--patch-size S]
//   [--element-size S] [--shots K] [--repeats R] [--batch K] [--json FILE]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "cl/runtime.h"
#include "core/error.h"
#include "formfactor/opencl_engine.h"
#if HEMIRAD_HAVE_EMBREE
#include "formfactor/embree_engine.h"
#endif
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "scene/scene.h"

using namespace hemirad;

namespace {

struct Stats {
    double min = 0.0, median = 0.0, sigma_percent = 0.0;
};

Stats stats(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    double mean = 0.0, var = 0.0;
    for (double x : v) mean += x / v.size();
    for (double x : v) var += (x - mean) * (x - mean) / v.size();
    return {v.front(), v[v.size() / 2], mean > 0.0 ? 100.0 * std::sqrt(var) / mean : 0.0};
}

int run_bench(const std::string& scene_file, const std::string& json_file, int hemicube, int shots, int repeats,
              int batch, double patch, double element);

}  // namespace

int main(int argc, char** argv) {
    std::string scene_file = std::string(HEMIRAD_SOURCE_DIR) + "/scenes/cornell_box.gltf", json_file;
    int hemicube = 256, shots = 20, repeats = 5, batch = 1;
    double patch = 0.06, element = 0.02;
    CLI::App app{"hemicube engine throughput, as ratios in one run"};
    app.add_option("scene", scene_file)->capture_default_str();
    app.add_option("--hemicube", hemicube)->capture_default_str();
    app.add_option("--patch-size", patch)->capture_default_str();
    app.add_option("--element-size", element)->capture_default_str();
    app.add_option("--shots", shots, "shots per engine per repeat")->capture_default_str();
    app.add_option("--repeats", repeats)->capture_default_str();
    app.add_option("--batch", batch, "shots per shoot_batch call (the reference runs them in turn)")
        ->capture_default_str()
        ->check(CLI::PositiveNumber);
    app.add_option("--json", json_file, "also write the results here");
    CLI11_PARSE(app, argc, argv);
    // One line for what stops a run, as the CLI does: a bad scene (2), anything else (1).
    try {
        return run_bench(scene_file, json_file, hemicube, shots, repeats, batch, patch, element);
    } catch (const InputError& e) {
        std::cerr << "bench: " << e.what() << "\n";
        return 2;
    } catch (const std::exception& e) {  // a kernel build failure (its log in what()) among them
        std::cerr << "bench: " << e.what() << "\n";
        return 1;
    }
}

namespace {

int run_bench(const std::string& scene_file, const std::string& json_file, int hemicube, int shots, int repeats,
              int batch, double patch, double element) {
    const scene::Scene s = scene::load(scene_file);
    const mesh::Mesh m = mesh::build(s, {patch, element});
    const formfactor::Settings settings{hemicube, 1};

    // What each engine owes the reference per shot: the hemicube engines the same cells (any
    // |ΔF| is rounding); the ray caster the same but for centres within a float's rounding of
    // an edge and depth ties, a few cells in a million (Σ|ΔF| over the elements).
    struct Entry {
        std::string engine, device;
        std::unique_ptr<ocl::Context> context;
        std::unique_ptr<formfactor::Engine> engine_ptr;
        double max_abs_tolerance = 1e-6, l1_tolerance = 1e-6;
        std::vector<double> ms_per_shot;  // one value per repeat
        double worst_abs = 0.0, worst_l1 = 0.0;
    };
    std::vector<Entry> entries;
    entries.push_back(
        {"ref", "host (1 thread)", nullptr, std::make_unique<formfactor::ReferenceEngine>(m, settings), 0.0, 0.0, {}});
#if HEMIRAD_HAVE_EMBREE
    {
        auto rays = std::make_unique<formfactor::EmbreeEngine>(m, settings);
        const std::string device = fmt::format("host ({}, {} threads)", formfactor::EmbreeEngine::version(), rays->threads());
        entries.push_back({"embree", device, nullptr, std::move(rays), 1e-3, 1e-3, {}});
    }
#endif
    for (const auto& d : ocl::list_devices()) {
        Entry e{"opencl", d.name + " (" + d.id() + ")", std::make_unique<ocl::Context>(d), nullptr, 1e-6, 1e-6, {}};
        e.engine_ptr = std::make_unique<formfactor::OpenCLEngine>(m, *e.context, settings);
        entries.push_back(std::move(e));
    }

    // The same shots for every engine: patches spread over the scene, shot index = seed stream.
    std::vector<std::uint32_t> patches;
    for (int i = 0; i < shots; ++i)
        patches.push_back(static_cast<std::uint32_t>((static_cast<std::size_t>(i) * 7919u) % m.patches.size()));
    std::vector<formfactor::ShotResult> expected(patches.size());
    for (std::size_t i = 0; i < patches.size(); ++i) entries[0].engine_ptr->shoot(patches[i], i, expected[i]);

    formfactor::ShotResult r;
    std::vector<formfactor::ShotResult> results;
    for (auto& e : entries) e.engine_ptr->shoot(patches[0], 0, r);  // warm-up: builds, first uploads
    for (int rep = 0; rep < repeats; ++rep) {
        for (auto& e : entries) {
            const auto t0 = std::chrono::steady_clock::now();
            for (std::size_t first = 0; first < patches.size(); first += static_cast<std::size_t>(batch)) {
                std::vector<formfactor::ShotRequest> requests;
                for (std::size_t i = first; i < std::min(patches.size(), first + static_cast<std::size_t>(batch)); ++i)
                    requests.push_back({patches[i], i});
                e.engine_ptr->shoot_batch(requests, results);
                for (std::size_t b = 0; b < requests.size(); ++b) {
                    const formfactor::ShotResult& want = expected[first + b];
                    double l1 = std::abs(results[b].blocked - want.blocked);
                    for (std::size_t k = 0; k < want.F.size(); ++k) {
                        const double d = std::abs(results[b].F[k] - want.F[k]);
                        e.worst_abs = std::max(e.worst_abs, d);
                        l1 += d;
                    }
                    e.worst_l1 = std::max(e.worst_l1, l1);
                }
            }
            const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
            e.ms_per_shot.push_back(ms / static_cast<double>(patches.size()));
        }
    }
    for (const auto& e : entries)
        if ((e.worst_abs > e.max_abs_tolerance || e.worst_l1 > e.l1_tolerance) && !std::getenv("BENCH_NOCHECK")) {
            std::cerr << fmt::format("bench: {} disagrees with the reference (|ΔF| up to {:.3g}, Σ|ΔF| {:.3g}); no result\n",
                                     e.engine, e.worst_abs, e.worst_l1);
            return 1;
        }

    const Stats ref = stats(entries[0].ms_per_shot);
    std::cout << fmt::format(
        "{}: {} patches, {} elements, N = {}, {} shots × {} repeats, batches of {}\n\n",
        scene_file, m.patches.size(), m.elements.size(), hemicube, shots, repeats, batch);
    std::cout << "| engine | device | ms/shot median (min, σ) | shots/s | hemicube samples/s | vs ref | worst Σ\\|ΔF\\| vs ref |\n";
    std::cout << "|---|---|---|---|---|---|---|\n";
    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    for (const auto& e : entries) {
        const Stats st = stats(e.ms_per_shot);
        const double shots_per_s = 1000.0 / st.median;
        const double samples = 3.0 * hemicube * hemicube * shots_per_s;
        std::cout << fmt::format("| {} | {} | {:.2f} ({:.2f}, ±{:.0f}%) | {:.0f} | {:.3g} | {:.2f}× | {:.1e} |\n",
                                 e.engine, e.device, st.median, st.min, st.sigma_percent, shots_per_s, samples,
                                 ref.median / st.median, e.worst_l1);
        rows.push_back({{"engine", e.engine},
                        {"device", e.device},
                        {"scene", scene_file},
                        {"triangles", s.triangles.size()},
                        {"patches", m.patches.size()},
                        {"elements", m.elements.size()},
                        {"hemicube", hemicube},
                        {"batch", batch},
                        {"shots_per_s", shots_per_s},
                        {"ms_per_shot", {{"min", st.min}, {"median", st.median}, {"sigma_percent", st.sigma_percent}}},
                        {"speedup_vs_ref", ref.median / st.median},
                        {"vs_ref", {{"worst_abs_dF", e.worst_abs}, {"worst_l1_dF", e.worst_l1}}}});
        // The OpenCL stages' device time per shot, from event profiling (the warm-up shot included).
        const auto* cl_engine = dynamic_cast<const formfactor::OpenCLEngine*>(e.engine_ptr.get());
        if (cl_engine == nullptr) continue;
        const double timed_shots = static_cast<double>(repeats) * static_cast<double>(patches.size()) + 1.0;
        nlohmann::ordered_json stages;
        for (std::size_t st = 0; st < formfactor::OpenCLEngine::kStages; ++st)
            stages[formfactor::OpenCLEngine::kStageNames[st]] = 1e3 * cl_engine->stage_seconds()[st] / timed_shots;
        rows.back()["device_ms_per_shot"] = stages;
    }
    for (const auto& row : rows) {
        if (!row.contains("device_ms_per_shot")) continue;
        std::cout << fmt::format("\n{} device time per shot (ms, event profiling, warm-up included):",
                                 row["device"].get<std::string>());
        for (const auto& [stage, ms] : row["device_ms_per_shot"].items())
            std::cout << fmt::format(" {} {:.3f}", stage, ms.get<double>());
        std::cout << "\n";
    }
    if (!json_file.empty()) {
        std::ofstream out(json_file);
        out << rows.dump(2) << "\n";
        if (!out.good()) {
            std::cerr << fmt::format("bench: {}: cannot write the results\n", json_file);
            return 2;
        }
    }
    return 0;
}

}  // namespace
