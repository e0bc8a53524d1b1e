// What hidden geometry costs a shot, with and without the OpenCL engine's culling: the shooters
// are the floor of procedural:10k, and up to 1M more triangles of objects lie either below the
// floor, wholly behind them (culled against the base plane), or beyond the room's +x wall, in
// front of them but hidden by the wall (occlusion culling). Every engine's shots are checked
// against the reference first.
// Usage: hemirad_bench_culling [--hemicube N] [--shots K] [--repeats R]
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <vector>

#include "bench/throughput.h"
#include "cl/runtime.h"
#include "core/timing.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "gen/procedural.h"
#if HEMIRAD_HAVE_EMBREE
#include "formfactor/embree_engine.h"
#endif

using namespace hemirad;

namespace {

// procedural:10k with the objects of procedural:<count> moved 20 m down, under its floor, or
// (beside) 20 m along +x, beyond its wall; procedural:10k alone for 0.
scene::Scene room_with_clutter(std::size_t count, bool beside) {
    if (count == 0) return gen::procedural_scene(10000);
    return gen::procedural_with_clutter(10000, count, beside ? gen::Clutter::beyond : gen::Clutter::below);
}

double ms_per_shot(formfactor::Engine& engine, const std::vector<std::uint32_t>& shooters, int repeats) {
    formfactor::ShotResult r;
    engine.shoot(shooters[0], 0, r);  // warm-up
    std::vector<double> ms;
    for (int rep = 0; rep < repeats; ++rep) {
        const auto t0 = Clock::now();
        for (std::size_t i = 0; i < shooters.size(); ++i) engine.shoot(shooters[i], i, r);
        ms.push_back(1e3 * seconds_since(t0) / static_cast<double>(shooters.size()));
    }
    return bench::stats(ms).median;
}

// Every engine must give the reference's form factors on the shots it is timed on, within what
// `hemirad bench` allows it.
void check(formfactor::Engine& engine, formfactor::ReferenceEngine& reference,
           const std::vector<std::uint32_t>& shooters, const bench::Tolerance& tolerance) {
    formfactor::ShotResult got, want;
    for (std::size_t i = 0; i < shooters.size(); ++i) {
        engine.shoot(shooters[i], i, got);
        reference.shoot(shooters[i], i, want);
        const bench::ShotDifference d = bench::shot_difference(got, want);
        if (!d.within(tolerance))
            throw std::runtime_error(fmt::format("{} disagrees with the reference: |ΔF| up to {:.3g}, Σ|ΔF| {:.3g}",
                                                 engine.name(), d.max_abs, d.l1));
    }
}

// Device time per stage (ms a shot) and the lane groups occlusion culling hid.
std::string stage_line(const formfactor::OpenCLEngine& engine, double shots) {
    std::string line;
    for (std::size_t k = 0; k < formfactor::OpenCLEngine::kStages; ++k)
        line += fmt::format("{} {:.3f} ms, ", formfactor::OpenCLEngine::kStageNames[k],
                            1e3 * engine.stage_seconds()[k] / shots);
    const double tested = static_cast<double>(engine.occlusion_tested());
    const double hidden = static_cast<double>(engine.occlusion_hidden());
    return line + fmt::format("{:.0f}% of {:.0f} lane groups tested hidden", tested > 0 ? 100.0 * hidden / tested : 0.0,
                              tested);
}

}  // namespace

int main(int argc, char** argv) {
    int hemicube = 256, shots = 16, repeats = 3;
    CLI::App app{"what hidden geometry costs a shot, with and without culling"};
    app.add_option("--hemicube", hemicube)->capture_default_str();
    app.add_option("--shots", shots, "floor shooters")->capture_default_str();
    app.add_option("--repeats", repeats)->capture_default_str();
    CLI11_PARSE(app, argc, argv);
    const std::vector<ocl::DeviceInfo> devices = ocl::list_devices();
    if (devices.empty()) {
        std::cerr << "hemirad_bench_culling: no OpenCL device\n";
        return 1;
    }
    try {
        ocl::Context context(devices.front());
        std::cout << fmt::format("floor shooters of procedural:10k, N = {}, {} shots × {} repeats, {}\n\n", hemicube,
                                 shots, repeats, devices.front().name);
        std::cout << "| hidden triangles | where | elements | OpenCL | OpenCL, occlusion culling every shot | "
                     "OpenCL, no occlusion culling | OpenCL, no culling | Embree |\n|---|---|---|---|---|---|---|---|\n";
        const std::size_t room_triangles = room_with_clutter(0, false).triangles.size();
        std::vector<std::string> stage_lines;
        struct Row {
            std::size_t count;
            bool beside;
        };
        for (const Row row : {Row{0, false}, Row{100000, false}, Row{1000000, false}, Row{100000, true},
                              Row{1000000, true}}) {
            const scene::Scene s = room_with_clutter(row.count, row.beside);
            const char* where = row.count == 0 ? "–" : row.beside ? "beyond a wall" : "below the floor";
            const double patch = 10.0 * std::sqrt(3.0) / 16.0;  // the room's default, whatever lies below
            const mesh::Mesh m = mesh::build(s, {patch, patch / 3.0});
            std::vector<std::uint32_t> floor;  // upward patches of the room (node 0): its floor
            for (std::uint32_t p = 0; p < m.patches.size(); ++p)
                if (m.patches[p].node == 0 && m.patches[p].normal.y > 0.99) floor.push_back(p);
            std::vector<std::uint32_t> shooters;
            for (int i = 0; i < shots; ++i) shooters.push_back(floor[static_cast<std::size_t>(i) * 7 % floor.size()]);
            const formfactor::Settings settings{hemicube, 1};
            formfactor::ReferenceEngine reference(m, settings);
            // The default (occlusion culling where it pays), on every shot, none, no culling at all.
            std::vector<double> cells;
            std::string stages;  // of occlusion culling on every shot
            for (int variant = 0; variant < 4; ++variant) {
                formfactor::OpenCLTuning tuning = formfactor::tuning_from_environment(context.info());
                if (variant == 1) tuning.occlusion = formfactor::Occlusion::on;
                if (variant > 1) tuning.occlusion = formfactor::Occlusion::off;
                tuning.cull = variant < 3;
                formfactor::OpenCLEngine engine(m, context, settings, tuning);
                check(engine, reference, shooters, bench::kRasterizer);
                cells.push_back(ms_per_shot(engine, shooters, repeats));
                if (variant == 1)  // over every shot of the engine: checked, warm-up and timed
                    stages = stage_line(engine, static_cast<double>(shooters.size()) * (2.0 + repeats) + 1.0);
            }
            std::string embree = "–";
#if HEMIRAD_HAVE_EMBREE
            formfactor::EmbreeEngine rays(m, settings);
            check(rays, reference, shooters, bench::kRayCaster);
            embree = fmt::format("{:.2f} ms", ms_per_shot(rays, shooters, repeats));
#endif
            std::cout << fmt::format("| {} | {} | {} | {:.2f} ms | {:.2f} ms | {:.2f} ms | {:.2f} ms | {} |\n",
                                     s.triangles.size() - room_triangles, where, m.elements.size(), cells[0],
                                     cells[1], cells[2], cells[3], embree);
            stage_lines.push_back(fmt::format("{} {}: {}", s.triangles.size() - room_triangles, where, stages));
        }
        std::cout << "\nWith occlusion culling on every shot:\n";
        for (const std::string& line : stage_lines) std::cout << "- " << line << "\n";
    } catch (const std::exception& e) {
        std::cerr << "hemirad_bench_culling: " << e.what() << "\n";
        return 1;
    }
    return 0;
}
