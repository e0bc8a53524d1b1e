// Shot throughput of the form-factor engines (see throughput.h). The engines alternate, repeat
// after repeat, over the same shots after a warm-up (kernel builds and first uploads excluded);
// only the engines' own calls are timed. Every shot of every engine is checked: its form factors
// and blocked share may not exceed 1 (and in a closed scene must reach it), and on a sample of
// shots it must agree with the scalar reference, so that a fast wrong engine cannot win.
#include "bench/throughput.h"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <thread>
#include <utility>

#include "bench/calibrate.h"
#include "cl/runtime.h"
#include "core/error.h"
#include "core/quality.h"
#include "core/timing.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "formfactor/verify.h"
#include "mesh/mesh.h"
#include "gen/content_scenes.h"
#if HEMIRAD_HAVE_EMBREE
#include "formfactor/embree_engine.h"
constexpr bool kHaveEmbree = true;
#else
constexpr bool kHaveEmbree = false;
#endif

namespace hemirad::bench {
namespace {

using ordered_json = nlohmann::ordered_json;

// Shots compared cell for cell with the reference, per repeat: the reference is the slowest
// engine, and one shot already exercises every kernel.
constexpr std::size_t kSampleShots = 4;

// Form factors plus the blocked share of one shot: at most 1 (the delta table sums to 1 in
// fixed point); in a closed scene every cell hits something, so exactly 1 to rounding.
constexpr double kSumSlack = 1e-9;

std::string cpu_model() {
    std::ifstream in("/proc/cpuinfo");
    for (std::string line; std::getline(in, line);)
        if (line.rfind("model name", 0) == 0) {
            const auto colon = line.find(':');
            return colon == std::string::npos ? line : line.substr(colon + 2);
        }
    return "unknown CPU";
}

struct Runner {
    std::string engine, device;       // "opencl", "PoCL … (opencl:0.0)"
    ocl::Context* context = nullptr;  // OpenCL engines: their device
    std::unique_ptr<formfactor::Engine> impl;
    Tolerance tolerance = kRasterizer;
    std::vector<double> ms_per_shot;  // per repeat
    ShotDifference worst{};           // over the shots compared
    double sum_min = 2.0, sum_max = 0.0;
};

// The engines a run asks for: ref, embree, opencl (every device) or opencl:P.D.
struct EngineSelection {
    bool ref = false, embree = false;
    std::vector<ocl::DeviceInfo> devices;
};

EngineSelection select_engines(const std::vector<std::string>& names) {
    const std::vector<ocl::DeviceInfo> all = ocl::list_devices();
    EngineSelection out;
    if (names.empty()) {
        out.ref = true;
        out.embree = kHaveEmbree;
        out.devices = all;
        return out;
    }
    for (const std::string& name : names) {
        if (name == "ref") {
            out.ref = true;
        } else if (name == "embree") {
            if (!kHaveEmbree)
                throw InputError("--engines embree: this build has no Embree peer (Embree 3 was not found)");
            out.embree = true;
        } else if (name == "opencl") {
            if (all.empty()) throw InputError("--engines opencl: no OpenCL device found (see hemirad devices)");
            out.devices = all;
        } else {
            const auto it = std::find_if(all.begin(), all.end(), [&](const auto& d) { return d.id() == name; });
            if (it == all.end())
                throw InputError(
                    fmt::format("--engines {}: expected ref, embree, opencl or one of hemirad devices", name));
            if (std::none_of(out.devices.begin(), out.devices.end(), [&](const auto& d) { return d.id() == name; }))
                out.devices.push_back(*it);
        }
    }
    return out;
}

// The least time a shot can take on a device with calibration `c`: one z-buffer test per
// hemicube sample at the peak fill rate, or the bytes every shot must move at the peak
// bandwidth (each element's vertices read once as three floats each, its sum written, and
// each cell's id), whichever is longer.
double limit_ms_per_shot(const Calibration& c, int n, std::size_t elements) {
    const double samples = 3.0 * n * n;
    const double bytes = (36.0 + 8.0) * static_cast<double>(elements) + 4.0 * samples;
    return 1e3 * std::max(samples / c.fill_tests_per_s, bytes / c.bandwidth_bytes_per_s);
}

}  // namespace

Stats stats(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    double mean = 0.0, var = 0.0;
    for (double x : v) mean += x / static_cast<double>(v.size());
    for (double x : v) var += (x - mean) * (x - mean) / static_cast<double>(v.size());
    return {v.front(), v[v.size() / 2], mean > 0.0 ? 100.0 * std::sqrt(var) / mean : 0.0};
}

ShotDifference shot_difference(const formfactor::ShotResult& got, const formfactor::ShotResult& want) {
    ShotDifference d;
    d.l1 = std::abs(got.blocked - want.blocked);
    formfactor::for_each_in_union(got, want, [&d](std::uint32_t, double g, double w) {
        const double diff = std::abs(g - w);
        d.max_abs = std::max(d.max_abs, diff);
        d.l1 += diff;
    });
    return d;
}

ordered_json machine_info() {
    return {{"cpu", cpu_model()}, {"hardware_threads", std::thread::hardware_concurrency()}};
}

BenchScene load_bench_scene(const std::string& spec) {
    bool closed = false;
    if (std::optional<scene::Scene> generated = gen::generated_scene(spec, &closed))
        return {std::move(*generated), closed};
    return {scene::load(spec), false};
}

mesh::Settings mesh_settings_for(const ThroughputOptions& o, const scene::Scene& s) {
    const QualityPreset& quality = quality_preset("default");
    mesh::Settings settings;
    settings.patch_size = o.patch_size > 0.0 ? o.patch_size : s.diagonal() * quality.patch_fraction;
    settings.element_size = o.element_size > 0.0 ? o.element_size : settings.patch_size / quality.elements_per_patch_edge;
    return settings;
}

std::vector<formfactor::ShotRequest> bench_shots(const mesh::Mesh& m, int count) {
    std::vector<formfactor::ShotRequest> shots;
    for (int i = 0; i < count; ++i)
        shots.push_back(formfactor::ShotRequest::of_patch(
            static_cast<std::uint32_t>((static_cast<std::size_t>(i) * 7919u) % m.patches.size()),
            static_cast<std::uint64_t>(i)));
    return shots;
}

std::vector<formfactor::ShotRequest> shots_from(const std::vector<formfactor::ShotRequest>& shots, std::size_t first,
                                                int batch) {
    const std::size_t end = std::min(shots.size(), first + static_cast<std::size_t>(batch));
    return {shots.begin() + static_cast<std::ptrdiff_t>(first), shots.begin() + static_cast<std::ptrdiff_t>(end)};
}

std::string batch_table(const ordered_json& results, const std::vector<int>& batches) {
    std::string out = "\nshots/s against batch size\n\n| scene | N | engine | device |";
    for (int b : batches) out += fmt::format(" {} |", b);
    out += "\n|---|---|---|---|";
    for (std::size_t i = 0; i < batches.size(); ++i) out += "---|";
    out += "\n";
    // Rows in the order the results first name them; a cell per batch size.
    std::vector<std::string> keys;
    std::map<std::string, std::map<int, double>> cells;
    for (const ordered_json& r : results) {
        const std::string key = fmt::format("| {} | {} | {} | {} |", r.at("scene").get<std::string>(),
                                            r.at("hemicube").get<int>(), r.at("engine").get<std::string>(),
                                            r.at("device").get<std::string>());
        if (cells.find(key) == cells.end()) keys.push_back(key);
        cells[key][r.at("batch").get<int>()] = r.at("shots_per_s").get<double>();
    }
    for (const std::string& key : keys) {
        out += key;
        for (int b : batches) {
            const auto it = cells[key].find(b);
            out += it == cells[key].end() ? " – |" : fmt::format(" {:.4g} |", it->second);
        }
        out += "\n";
    }
    return out;
}

namespace {

// The most elements a benchmark's mesh may have: a tiny --element-size (1e-4 on a room) would
// exhaust the memory long after the calibration.
constexpr double kMaxElements = double(1 << 24);

// Sizes the mesher cannot take, or that would need too many elements: bad input, found by
// counting the mesh (mesh::build stopped once it has counted) before anything is measured.
void check_mesh_settings(const ThroughputOptions& o, const scene::Scene& s, const std::string& spec) {
    const mesh::Settings settings = mesh_settings_for(o, s);
    const std::string what = fmt::format("{} with --{}-size {:g}", spec, o.element_size > 0.0 ? "element" : "patch",
                                         o.element_size > 0.0 ? o.element_size : settings.patch_size);
    if (settings.element_size > settings.patch_size)
        throw InputError(fmt::format("{}: elements of {:g} are larger than the patches ({:g})", what,
                                     settings.element_size, settings.patch_size));
    struct Counted {};
    mesh::Counts counts;
    try {
        mesh::build(s, settings, [&counts](const mesh::Counts& c) {
            counts = c;
            throw Counted{};
        });
    } catch (const Counted&) {
    } catch (const InputError& e) {
        throw InputError(fmt::format("{}: {}", what, e.what()));
    }
    if (!(counts.elements <= kMaxElements))
        throw InputError(fmt::format("{}: {:.3g} elements, more than the {:.0f} a benchmark may mesh", what,
                                     counts.elements, kMaxElements));
}

}  // namespace

ordered_json run_throughput(const ThroughputOptions& o, std::ostream& log) {
    if (o.scenes.empty()) throw InputError("bench: no scene given (a glTF file, procedural:<triangles>, city:, furniture: or foliage:<triangles>)");
    for (int n : o.hemicubes)
        if (n < 8 || n > 4096 || n % 2 != 0)
            throw InputError(fmt::format("--hemicube {}: must be even, from 8 to 4096", n));
    if (o.shots < 1 || o.repeats < 1 || o.batches.empty())
        throw InputError("bench: --shots and --repeats must be at least 1, and --batch name a size");
    for (int b : o.batches)
        if (b < 1 || b > kMaxBenchBatch) throw InputError(fmt::format("--batch {}: must be from 1 to {}", b, kMaxBenchBatch));
    const EngineSelection selection = select_engines(o.engines);
    // Every scene first: bad input ends the run before any output.
    std::vector<BenchScene> scenes;
    for (const std::string& spec : o.scenes) {
        scenes.push_back(load_bench_scene(spec));
        if (scenes.back().scene.triangles.empty()) throw InputError(fmt::format("{}: no triangles", spec));
        check_mesh_settings(o, scenes.back().scene, spec);
    }

    ordered_json doc;
    doc["version"] = HEMIRAD_VERSION;
    doc["machine"] = machine_info();
    doc["settings"] = {
        {"shots", o.shots},
        {"repeats", o.repeats},
        {"batches", o.batches},
        {"seed", o.seed},
        {"sample_shots_checked", std::min<std::size_t>(kSampleShots, static_cast<std::size_t>(o.shots))}};

    // One context per device for the whole run: kernels build once per device and N.
    std::vector<std::unique_ptr<ocl::Context>> contexts;
    std::vector<Calibration> calibrations;
    ordered_json calibration_json = ordered_json::array();
    const Calibration* host_limit = nullptr;  // the CPU's, for the reference
    for (const auto& d : selection.devices) {
        contexts.push_back(std::make_unique<ocl::Context>(d));
        if (!o.calibrate) continue;
        calibrations.push_back(calibrate(*contexts.back()));
        const Calibration& c = calibrations.back();
        calibration_json.push_back({{"device", d.name + " (" + d.id() + ")"},
                                    {"type", d.type},
                                    {"fill_tests_per_s", c.fill_tests_per_s},
                                    {"bandwidth_bytes_per_s", c.bandwidth_bytes_per_s},
                                    {"seconds", c.seconds}});
        log << fmt::format("calibration {} ({}): z-buffer fill {:.3g} tests/s, bandwidth {:.3g} GB/s\n", d.name, d.id(),
                           c.fill_tests_per_s, 1e-9 * c.bandwidth_bytes_per_s);
    }
    for (std::size_t i = 0; i < calibrations.size(); ++i)
        if (selection.devices[i].type == "cpu" && host_limit == nullptr) host_limit = &calibrations[i];
    doc["calibration"] = calibration_json;

    ordered_json results = ordered_json::array();
    for (std::size_t scene_index = 0; scene_index < scenes.size(); ++scene_index) {
        const std::string& spec = o.scenes[scene_index];
        const BenchScene& bench_scene = scenes[scene_index];
        const scene::Scene& s = bench_scene.scene;
        const mesh::Settings mesh_settings = mesh_settings_for(o, s);
        const auto t_mesh = Clock::now();
        const mesh::Mesh m = mesh::build(s, mesh_settings);
        if (m.patches.empty()) throw InputError(fmt::format("{}: every triangle has zero area", spec));
        log << fmt::format("\n{}: {} triangles, {} patches ({} clusters: {} moved, {} split), {} elements (meshed in {:.2f} s)\n",
                           spec, s.triangles.size(), m.patches.size(), m.clusters, m.moved_clusters, m.split_clusters,
                           m.elements.size(), seconds_since(t_mesh));

        const std::vector<formfactor::ShotRequest> shots = bench_shots(m, o.shots);
        const std::size_t sample = std::min(kSampleShots, shots.size());

        for (int n : o.hemicubes) {
            const formfactor::Settings settings{n, o.seed};
            formfactor::ReferenceEngine reference(m, settings);
            std::vector<formfactor::ShotResult> expected(sample);
            for (std::size_t i = 0; i < sample; ++i) reference.shoot(shots[i], expected[i]);

            std::vector<Runner> runners;
            if (selection.ref)
                runners.push_back({"ref",
                                   "host (1 thread)",
                                   nullptr,
                                   std::make_unique<formfactor::ReferenceEngine>(m, settings),
                                   kExact,
                                   {}});
#if HEMIRAD_HAVE_EMBREE
            if (selection.embree) {
                auto rays = std::make_unique<formfactor::EmbreeEngine>(m, settings);
                const std::string device =
                    fmt::format("host ({}, {} threads)", formfactor::EmbreeEngine::version(), rays->threads());
                runners.push_back({"embree", device, nullptr, std::move(rays), kRayCaster, {}});
            }
#endif
            for (std::size_t d = 0; d < contexts.size(); ++d) {
                const ocl::DeviceInfo& info = contexts[d]->info();
                runners.push_back({"opencl",
                                   info.name + " (" + info.id() + ")",
                                   contexts[d].get(),
                                   std::make_unique<formfactor::OpenCLEngine>(
                                       m, *contexts[d], settings, formfactor::tuning_from_environment(info),
                                       formfactor::fault_from_environment()),
                                   kRasterizer,
                                   {}});
            }

            std::vector<formfactor::ShotResult> out;
            for (auto& r : runners) r.impl->shoot_batch({shots[0]}, out);  // warm-up: builds, first uploads
            for (const int batch_size : o.batches) {
            for (auto& r : runners) r.ms_per_shot.clear();
            using StageTimes = std::array<double, formfactor::OpenCLEngine::kStages>;
            std::vector<StageTimes> stages_before;  // the timed shots' device time is the difference
            for (auto& r : runners) {
                const auto* cl = dynamic_cast<const formfactor::OpenCLEngine*>(r.impl.get());
                stages_before.push_back(cl ? cl->stage_seconds() : StageTimes{});
            }
            for (int rep = 0; rep < o.repeats; ++rep) {
                for (auto& r : runners) {
                    double seconds = 0.0;
                    for (std::size_t first = 0; first < shots.size(); first += static_cast<std::size_t>(batch_size)) {
                        const std::vector<formfactor::ShotRequest> batch = shots_from(shots, first, batch_size);
                        const auto t0 = Clock::now();
                        r.impl->shoot_batch(batch, out);
                        seconds += seconds_since(t0);
                        for (std::size_t b = 0; b < batch.size(); ++b) {
                            double sum = out[b].blocked;
                            for (double f : out[b].F) sum += f;
                            r.sum_min = std::min(r.sum_min, sum);
                            r.sum_max = std::max(r.sum_max, sum);
                            if (first + b >= sample) continue;
                            const ShotDifference d = shot_difference(out[b], expected[first + b]);
                            r.worst.max_abs = std::max(r.worst.max_abs, d.max_abs);
                            r.worst.l1 = std::max(r.worst.l1, d.l1);
                        }
                    }
                    r.ms_per_shot.push_back(1e3 * seconds / static_cast<double>(shots.size()));
                }
            }

            // A fast wrong engine cannot win: any failed check ends the run without a result.
            for (const auto& r : runners) {
                std::string problem;
                if (!r.worst.within(r.tolerance))
                    problem = fmt::format("disagrees with the reference (|ΔF| up to {:.3g}, Σ|ΔF| {:.3g})",
                                          r.worst.max_abs, r.worst.l1);
                else if (r.sum_max > 1.0 + kSumSlack)
                    problem = fmt::format("form factors sum to {:.12f} > 1", r.sum_max);
                // A closed scene's shots sum to 1 within what the engine owes the reference: the
                // ray caster's rays may slip through a float's gap between neighbours.
                else if (bench_scene.closed && r.sum_min < 1.0 - std::max(kSumSlack, r.tolerance.l1))
                    problem = fmt::format("form factors sum to {:.12f} < 1 in a closed scene", r.sum_min);
                if (!problem.empty())
                    throw formfactor::VerifyError(
                        fmt::format("{} on {} at N = {}: {} {}; no result", r.engine, spec, n, r.device, problem));
            }

            const double ref_median = selection.ref ? stats(runners[0].ms_per_shot).median : 0.0;
            log << fmt::format("\nN = {}, {} shots × {} repeats, batches of {}\n\n", n, o.shots, o.repeats, batch_size);
            log << "| engine | device | ms/shot median (min, σ) | shots/s | samples/s | vs ref | % of limit | worst "
                   "Σ\\|ΔF\\| vs ref |\n|---|---|---|---|---|---|---|---|\n";
            for (std::size_t i = 0; i < runners.size(); ++i) {
                const Runner& r = runners[i];
                const Stats st = stats(r.ms_per_shot);
                const double shots_per_s = 1e3 / st.median;
                ordered_json row = {
                    {"engine", r.engine},
                    {"device", r.device},
                    {"scene", spec},
                    {"closed", bench_scene.closed},
                    {"triangles", s.triangles.size()},
                    {"patches", m.patches.size()},
                    {"elements", m.elements.size()},
                    {"hemicube", n},
                    {"batch", batch_size},
                    {"shots_per_s", shots_per_s},
                    {"samples_per_s", 3.0 * n * n * shots_per_s},
                    {"ms_per_shot", {{"min", st.min}, {"median", st.median}, {"sigma_percent", st.sigma_percent}}},
                    {"sum_F_blocked", {{"min", r.sum_min}, {"max", r.sum_max}}},
                    {"vs_ref", {{"worst_abs_dF", r.worst.max_abs}, {"worst_l1_dF", r.worst.l1}}}};
                if (selection.ref) row["speedup_vs_ref"] = ref_median / st.median;
                // The limit: the device's own calibration; the reference's, the CPU device's. It
                // bounds a rasterizer, which reads every element each shot; a ray caster reads
                // only what its rays reach, so it gets none.
                const Calibration* limit = r.engine == "ref" ? host_limit : nullptr;
                if (r.context != nullptr) {
                    limit = nullptr;
                    for (std::size_t d = 0; d < contexts.size() && d < calibrations.size(); ++d)
                        if (contexts[d].get() == r.context) limit = &calibrations[d];
                }
                std::string limit_cell = "–";
                if (limit != nullptr) {
                    const double limit_ms = limit_ms_per_shot(*limit, n, m.elements.size());
                    row["limit"] = {
                        {"device", limit->device}, {"ms_per_shot", limit_ms}, {"fraction", limit_ms / st.median}};
                    limit_cell = fmt::format("{:.1f}%", 100.0 * limit_ms / st.median);
                }
                if (const auto* cl = dynamic_cast<const formfactor::OpenCLEngine*>(r.impl.get())) {
                    ordered_json device_ms;
                    const double timed = static_cast<double>(o.repeats) * static_cast<double>(shots.size());
                    for (std::size_t k = 0; k < formfactor::OpenCLEngine::kStages; ++k)
                        device_ms[formfactor::OpenCLEngine::kStageNames[k]] =
                            1e3 * (cl->stage_seconds()[k] - stages_before[i][k]) / timed;
                    row["device_ms_per_shot"] = device_ms;
                    // Over the engine's every shot (its checked and warm-up shots too).
                    row["occlusion"] = {{"lane_groups_tested", cl->occlusion_tested()},
                                        {"lane_groups_hidden", cl->occlusion_hidden()}};
                }
                log << fmt::format(
                    "| {} | {} | {:.3g} ({:.3g}, ±{:.0f}%) | {:.4g} | {:.3g} | {} | {} | {:.1e} |\n", r.engine,
                    r.device, st.median, st.min, st.sigma_percent, shots_per_s, 3.0 * n * n * shots_per_s,
                    selection.ref ? fmt::format("{:.2f}×", ref_median / st.median) : "–", limit_cell, r.worst.l1);
                results.push_back(row);
            }
            for (const auto& row : results) {
                if (!row.contains("device_ms_per_shot") || row["scene"] != spec || row["hemicube"] != n ||
                    row["batch"] != batch_size)
                    continue;
                log << fmt::format("\n{} device time per shot (ms, event profiling):",
                                   row["device"].get<std::string>());
                for (const auto& [stage, ms] : row["device_ms_per_shot"].items())
                    log << fmt::format(" {} {:.3f}", stage, ms.get<double>());
                const auto tested = row["occlusion"]["lane_groups_tested"].get<std::uint64_t>();
                if (tested > 0)
                    log << fmt::format("; occlusion culling hid {:.0f}% of the lane groups it tested",
                                       100.0 * static_cast<double>(row["occlusion"]["lane_groups_hidden"].get<std::uint64_t>()) /
                                           static_cast<double>(tested));
                log << "\n";
            }
            }
        }
    }
    doc["results"] = results;
    if (o.batches.size() > 1) log << batch_table(results, o.batches);
    return doc;
}

}  // namespace hemirad::bench
