// `hemirad bench --scaling` (see bench_scaling.h).
#include "bench/scaling.h"

#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <tuple>

#include "bench/throughput.h"
#include "bake/bake.h"
#include "bake/engine_select.h"
#include "core/error.h"
#include "core/timing.h"
#include "dist/dist.h"
#include "formfactor/timed.h"
#include "solve/progressive.h"

namespace hemirad::bench {
namespace {

using nlohmann::ordered_json;

// Keeps every row it passes on, or (replaying) answers from them: a solve replayed on the rows
// of an earlier one times the solver's own work, with no device competing for the core.
class Recorder final : public formfactor::Engine {
public:
    explicit Recorder(formfactor::Engine* inner) : inner_(inner) {}
    std::string name() const override { return "recorder"; }
    using formfactor::Engine::shoot;
    void shoot(const formfactor::ShotRequest& request, formfactor::ShotResult& out) override {
        shoot_batch({request}, one_);
        out = std::move(one_.front());
    }
    void shoot_batch(const std::vector<formfactor::ShotRequest>& shots, std::vector<formfactor::ShotResult>& out) override {
        if (inner_) {
            inner_->shoot_batch(shots, out);
            for (std::size_t i = 0; i < shots.size(); ++i) rows_[key(shots[i])] = out[i];
            return;
        }
        out.resize(shots.size());
        for (std::size_t i = 0; i < shots.size(); ++i) {
            const auto row = rows_.find(key(shots[i]));
            if (row == rows_.end()) throw InternalError("bench --scaling: a replayed solve asked for a shot it never made");
            out[i] = row->second;
        }
    }
    void replay() { inner_ = nullptr; }

private:
    static std::tuple<int, std::uint32_t, std::uint64_t> key(const formfactor::ShotRequest& r) {
        return {static_cast<int>(r.shooter.kind), r.shooter.patch, r.shot};
    }
    formfactor::Engine* inner_;
    std::map<std::tuple<int, std::uint32_t, std::uint64_t>, formfactor::ShotResult> rows_;
    std::vector<formfactor::ShotResult> one_;
};

struct Config {
    std::size_t devices = 1;
    int ranks = 1;  // rank 0 and ranks − 1 workers
};

}  // namespace

ordered_json run_scaling_bench(const ScalingOptions& o, std::ostream& log) {
    if (dist::rank() != 0) throw InternalError("bench --scaling runs on rank 0");
    if (o.hemicube < 8 || o.hemicube % 2 != 0) throw InputError(fmt::format("--hemicube {}: must be even and >= 8", o.hemicube));
    const bench::BenchScene bench_scene = bench::load_bench_scene(o.scene);
    const scene::Scene& s = bench_scene.scene;
    const mesh::Mesh mesh = mesh::build(s, bench::mesh_settings_for(bench::ThroughputOptions{}, s));
    if (mesh.patches.empty()) throw InputError(fmt::format("{}: every triangle has zero area", o.scene));
    const formfactor::Settings settings{o.hemicube, o.seed};
    const std::vector<formfactor::ShotRequest> shots = bench::bench_shots(mesh, o.shots);

    bake::EngineChoice choice = bake::choose_engine(o.device, false, 1, mesh, settings);
    choice.engine.reset();  // each configuration makes its own (engine_on)
    const int world = dist::size();
    std::vector<Config> configs;
    for (std::size_t d = 1; d <= choice.devices.size(); ++d) configs.push_back({d, 1});
    for (int k = 2; k <= world; ++k) configs.push_back({choice.devices.size(), k});
    const std::size_t most = std::max<std::size_t>(choice.devices.size() + static_cast<std::size_t>(world - 1), 1);
    const int batch = o.batch > 0 ? o.batch : bake::planned_batch(most);
    const int passes = o.passes > 0 ? o.passes : 2 * batch;

    log << fmt::format("{}: {} triangles, {} patches, {} elements; N {}, {} shots a run in batches of {}, {} ranks, "
                       "devices {} ({})\n\n",
                       o.scene, s.triangles.size(), mesh.patches.size(), mesh.elements.size(), o.hemicube, shots.size(),
                       batch, world, choice.id, choice.name);
    log << "| ranks | devices | shots/s | speedup | efficiency | bake s (" << passes
        << " passes) | host s | row bytes/shot | rows identical |\n|---:|---:|---:|---:|---:|---:|---:|---:|:---|\n";

    // Every configuration's engine at once, so that the timed runs can take turns: a shared
    // machine's noise then falls on all of them alike.
    struct Measured {
        Config config;
        std::unique_ptr<formfactor::Engine> engine;
        double mesh_seconds = 0.0;
        std::uint64_t mesh_bytes = 0;
        std::vector<double> times, bakes, engine_seconds;
        std::vector<formfactor::ShotResult> rows;
        std::uint64_t request_bytes = 0, row_bytes = 0;
        long passes = 0;
    };
    std::vector<Measured> measured;
    for (const Config& c : configs) {
        Measured m;
        m.config = c;
        const dist::Traffic before = dist::traffic();
        const auto t_mesh = Clock::now();
        m.engine = engine_on(choice, c.devices, c.ranks - 1, mesh, settings);
        m.mesh_seconds = seconds_since(t_mesh);
        m.mesh_bytes = dist::traffic().mesh_bytes - before.mesh_bytes;
        // Warm: kernels built and buffers sized on every member.
        m.engine->shoot_batch(bench::shots_from(shots, 0, batch), m.rows);
        measured.push_back(std::move(m));
    }
    std::vector<formfactor::ShotResult> rows;
    for (int r = 0; r < o.repeats; ++r)
        for (Measured& m : measured) {
            const dist::Traffic before = dist::traffic();
            m.rows.resize(shots.size());
            const auto t0 = Clock::now();
            for (std::size_t first = 0; first < shots.size(); first += static_cast<std::size_t>(batch)) {
                m.engine->shoot_batch(bench::shots_from(shots, first, batch), rows);
                std::move(rows.begin(), rows.end(), m.rows.begin() + static_cast<std::ptrdiff_t>(first));
            }
            m.times.push_back(seconds_since(t0));
            const dist::Traffic after = dist::traffic();
            m.request_bytes += after.shot_bytes - before.shot_bytes;
            m.row_bytes += after.row_bytes - before.row_bytes;
            if (m.rows != measured.front().rows)
                throw InternalError(fmt::format("bench --scaling: {} ranks and {} devices computed other rows than one",
                                                m.config.ranks, m.config.devices));
        }
    // A bake's progressive passes on the same members: the host's share is what stays serial.
    // The first configuration's rows are kept, and its solve replayed on them below.
    Recorder recorder(measured.front().engine.get());
    for (int r = 0; r < o.repeats; ++r)
        for (Measured& m : measured) {
            formfactor::TimedEngine timed(&m == &measured.front() ? static_cast<formfactor::Engine&>(recorder) : *m.engine);
            solve::Settings solve_settings;
            solve_settings.batch = batch;
            solve_settings.max_passes = passes;
            solve_settings.threshold = 0.0;
            solve::Progressive solver(mesh, timed, solve_settings);  // set-up, once a bake: not timed
            const auto t_bake = Clock::now();
            while (solver.step()) {
            }
            m.bakes.push_back(seconds_since(t_bake));
            m.engine_seconds.push_back(timed.seconds());
            m.passes = solver.passes();
        }

    recorder.replay();
    std::vector<double> replays;
    for (int r = 0; r < o.repeats; ++r) {
        solve::Settings solve_settings;
        solve_settings.batch = batch;
        solve_settings.max_passes = passes;
        solve_settings.threshold = 0.0;
        solve::Progressive solver(mesh, recorder, solve_settings);
        const auto t0 = Clock::now();
        while (solver.step()) {
        }
        replays.push_back(seconds_since(t0) / static_cast<double>(std::max(1L, solver.passes())));
    }

    // Each rank's rows as sent (dist::pack_rows).
    const double row_bytes_per_shot =
        static_cast<double>(dist::pack_rows(measured.front().rows).size()) / static_cast<double>(shots.size());
    const double base_rate = static_cast<double>(shots.size()) / bench::stats(measured.front().times).median;
    const double base_bake = bench::stats(measured.front().bakes).median;
    ordered_json runs = ordered_json::array();
    for (const Measured& m : measured) {
        const Config& c = m.config;
        const double rate = static_cast<double>(shots.size()) / bench::stats(m.times).median;
        const double bake = bench::stats(m.bakes).median;
        const double engine_seconds = bench::stats(m.engine_seconds).median;
        const double members = static_cast<double>(c.devices) + c.ranks - 1;
        runs.push_back({{"ranks", c.ranks},
                        {"devices", c.devices},
                        {"members", members},
                        {"shots_per_second", rate},
                        {"seconds", m.times},
                        {"speedup", rate / base_rate},
                        {"efficiency", rate / base_rate / members},
                        {"bake_seconds", bake},
                        {"bake_speedup", base_bake / bake},
                        {"engine_seconds", engine_seconds},
                        {"host_seconds", bake - engine_seconds},
                        {"passes", m.passes},
                        {"mesh_bytes", m.mesh_bytes},
                        {"mesh_seconds", m.mesh_seconds},
                        {"request_bytes", m.request_bytes},
                        {"row_bytes", m.row_bytes},
                        {"rows_identical", true}});
        log << fmt::format("| {} | {} | {:.1f} | {:.2f} | {:.0f}% | {:.2f} | {:.2f} | {:.0f} | yes |\n", c.ranks, c.devices,
                           rate, rate / base_rate, 100.0 * rate / base_rate / members, bake, bake - engine_seconds,
                           row_bytes_per_shot);
    }
    // What one member does per shot, and what a shot's row weighs: the model's inputs. Rank 0
    // unpacks every row a worker sends: timed here on the rows of the first configuration.
    const Measured& one = measured.front();
    const std::string packed = dist::pack_rows(one.rows);
    const auto t_unpack = Clock::now();
    const std::size_t unpacked = dist::unpack_rows(packed).size();
    const double unpack_seconds = seconds_since(t_unpack) / static_cast<double>(std::max<std::size_t>(1, unpacked));
    std::size_t entries = 0;
    for (const formfactor::ShotResult& r : one.rows) entries += r.size();
    const ordered_json model = {
        {"shot_seconds", bench::stats(one.times).median / static_cast<double>(shots.size())},
        // The solver's own work a pass, replayed on kept rows (the bakes' host time above also
        // holds what the devices' threads took from the host's core).
        {"host_seconds_per_pass", bench::stats(replays).median},
        {"row_entries_per_shot", static_cast<double>(entries) / static_cast<double>(shots.size())},
        {"row_bytes_per_shot", row_bytes_per_shot},
        {"row_unpack_seconds_per_shot", unpack_seconds},
        {"request_bytes_per_shot", static_cast<double>(dist::pack_shots(0, shots).size()) / static_cast<double>(shots.size())},
        {"mesh_bytes", dist::pack_mesh(mesh).size()},
        {"batch_per_member", bake::kShotsPerMember}};
    ordered_json doc;
    doc["version"] = HEMIRAD_VERSION;
    doc["machine"] = bench::machine_info();
    doc["settings"] = {{"scene", o.scene},       {"triangles", s.triangles.size()}, {"patches", mesh.patches.size()},
                       {"elements", mesh.elements.size()}, {"hemicube", o.hemicube}, {"shots", shots.size()},
                       {"batch", batch},         {"passes", passes},                {"repeats", o.repeats},
                       {"world", world},         {"device", choice.id},            {"device_name", choice.name}};
    doc["runs"] = runs;
    doc["model_inputs"] = model;
    return doc;
}

}  // namespace hemirad::bench
