// The command line: parses options, runs the bake pipeline, and is the one catch point that
// maps errors to exit codes (0 done, 2 bad input or usage, 1 internal failure).
#include "cli/app.h"

#include <fmt/core.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "cl/runtime.h"
#include "cli/bake.h"
#include "cli/bench.h"
#include "cli/engine_select.h"
#include "core/error.h"
#include "formfactor/verify.h"

namespace hemirad::cli {
namespace {

void add_bake_options(CLI::App& bake, BakeOptions& o) {
    bake.add_option("scene", o.scene, "glTF 2.0 scene (.gltf or .glb)")->required();
    bake.add_option("-o,--output", o.output, "output directory (created if missing)")->capture_default_str();
    bake.add_option("--device", o.device, "form-factor engine: auto|ref|opencl|opencl:P.D (see hemirad devices)")
        ->capture_default_str();
    std::string presets;
    std::vector<std::string> names;
    for (const QualityPreset& p : kQualityPresets) {
        presets += fmt::format("{}{} (N {}, patches diagonal/{:g}, {:g} elements a side, threshold {:g})",
                               presets.empty() ? "" : ", ", p.name, p.hemicube, 1.0 / p.patch_fraction,
                               p.elements_per_patch_edge, p.threshold);
        names.emplace_back(p.name);
    }
    bake.add_option("--quality", o.quality,
                    "settings preset from the accuracy-against-time benchmark: " + presets +
                        "; the options below override their part")
        ->check(CLI::IsMember(names))
        ->capture_default_str();
    bake.add_option("--hemicube", o.hemicube,
                    "hemicube resolution N: top face N×N plus four N×N/2 half faces (default: the quality's)")
        ->check(CLI::Range(8, 4096));
    bake.add_option("--patch-size", o.patch_size,
                    "maximum patch edge, scene units (default: scene diagonal × the quality's fraction)")
        ->check(CLI::PositiveNumber);
    bake.add_option("--element-size", o.element_size,
                    "maximum element edge, scene units (default: patch size / the quality's elements a side)")
        ->check(CLI::PositiveNumber);
    bake.add_option("--threshold", o.threshold,
                    "progressive: stop when the share of final flux not yet placed is below this; matrix: iterate to a "
                    "residual of min(1e-4, T/100) (default: the quality's)")
        ->check(CLI::Range(0.0, 1.0));
    bake.add_option("--max-passes", o.max_passes, "stop after this many shots (0: no limit)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    bake.add_option("--batch", o.batch,
                    "shoot the K patches with the most unshot flux together (one launch on OpenCL); "
                    "each still shoots its flux at the time it is applied")
        ->check(CLI::Range(1, 256))
        ->capture_default_str();
    bake.add_option("--solver", o.solver,
                    "matrix (a form-factor row per patch, then Gauss-Seidel), progressive (shooting), or auto: "
                    "matrix up to 3000 patches and reflectances up to 0.95, unless --preview-every is given")
        ->check(CLI::IsMember({"auto", "matrix", "progressive"}))
        ->capture_default_str();
    bake.add_option("--effects", o.effects,
                    "force effects on or off, e.g. occlusion=off,colour=on (occlusion, colour, interreflection, "
                    "two_sided, refinement, convergence; on|off|auto); by default each is planned from the scene "
                    "and report.json says why");
    bake.add_option("--refine-levels", o.refine_levels,
                    "adaptive refinement: split an element at most this often where the irradiance contrasts (0: off)")
        ->check(CLI::Range(0, 6))
        ->capture_default_str();
    bake.add_option("--contrast", o.contrast,
                    "adaptive refinement: split neighbours whose irradiance differs by more than this share")
        ->check(CLI::Range(0.01, 1.0))
        ->capture_default_str();
    bake.add_option("--checkpoint", o.checkpoint,
                    "progressive solver: write its state to this file every --checkpoint-every passes (atomically)");
    bake.add_option("--checkpoint-every", o.checkpoint_every, "passes between checkpoints")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    bake.add_option("--resume", o.resume,
                    "progressive solver: go on from this checkpoint of the same scene and settings; the bake ends "
                    "with exactly the numbers of an uninterrupted one");
    bake.add_option("--seed", o.seed, "seed of every random choice (hemicube rotations)")->capture_default_str();
    bake.add_flag("--verify", o.verify, "check shots of the OpenCL engine against the scalar reference");
    bake.add_option("--verify-every", o.verify_every, "with --verify, check every K-th shot")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    bake.add_option("--camera", o.camera, "render from the camera with this name");
    bake.add_option("--preview-every", o.preview_every, "write DIR/preview/pass_NNNNNN.png every K passes")
        ->check(CLI::NonNegativeNumber);
    bake.add_option("--image-width", o.image_width, "width of render.exr/png; height follows the camera's aspect")
        ->check(CLI::Range(16, 16384))
        ->capture_default_str();
    bake.add_option("--max-memory", o.max_memory,
                    "memory the bake may use, e.g. 8G or 512M (default: what the machine has available); a bake "
                    "estimated to need more is refused before it starts, --solver auto takes the solver that fits, "
                    "and refinement stops where it would pass it");
    bake.add_flag("--quiet", o.quiet, "no progress line");
}

void add_bench_options(CLI::App& cmd, BenchCommand& c) {
    bench::ThroughputOptions& o = c.throughput;
    cmd.add_option("scenes", o.scenes, "glTF files or procedural:<triangles> (e.g. procedural:100k, procedural:1M)");
    cmd.add_option("--hemicube", o.hemicubes, "hemicube resolutions N, comma-separated")
        ->delimiter(',')
        ->check(CLI::Range(8, 4096))
        ->capture_default_str();
    cmd.add_option("--engines", o.engines, "ref, embree, opencl (every device) or opencl:P.D; default: all")
        ->delimiter(',');
    cmd.add_option("--shots", o.shots, "shots per engine per repeat")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    cmd.add_option("--repeats", o.repeats, "timed repeats (min, median and spread over them)")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    cmd.add_option("--batch", o.batch, "shots per engine call")->check(CLI::Range(1, 256))->capture_default_str();
    const QualityPreset& quality = quality_preset("default");
    cmd.add_option(
           "--patch-size", o.patch_size,
           fmt::format("maximum patch edge (default: scene diagonal / {:g}, as a bake)", 1.0 / quality.patch_fraction))
        ->check(CLI::PositiveNumber);
    cmd.add_option("--element-size", o.element_size,
                   fmt::format("maximum element edge (default: patch size / {:g})", quality.elements_per_patch_edge))
        ->check(CLI::PositiveNumber);
    cmd.add_option("--seed", o.seed, "seed of the hemicube rotations")->capture_default_str();
    cmd.add_flag(
        "--no-calibrate", [&o](std::int64_t) { o.calibrate = false; },
        "skip measuring the machine's limit (fill rate, bandwidth)");
    cmd.add_flag("--accuracy", c.accuracy,
                 "instead of throughput: error against time over the settings, on analytic cases and a room");
    cmd.add_flag("--effects", c.effects,
                 "instead of throughput: bake the bundled scenes with each effect as planned and forced the other "
                 "way, and report the time saved and what changed (run from the repository root)");
    cmd.add_flag("--quick", c.quick, "with --accuracy or --effects: a smoke test of a few coarse runs (seconds)");
    cmd.add_option("--device", c.device, "with --accuracy or --effects: auto, ref or opencl:P.D")
        ->capture_default_str();
    cmd.add_option("--json", c.json, "also write the results here (JSON)");
}

std::atomic<bool> g_interrupted{false};
extern "C" void on_interrupt(int) {
    g_interrupted = true;
}

}  // namespace

int run(int argc, char** argv) {
    CLI::App app{"hemirad: radiosity baker with a hemicube form-factor engine"};
    app.set_version_flag("--version", HEMIRAD_VERSION);
    app.require_subcommand(1);
    BakeOptions bake_options;
    CLI::App* bake = app.add_subcommand("bake", "bake diffuse global illumination into a glTF scene");
    add_bake_options(*bake, bake_options);
    BenchCommand bench_command;
    CLI::App* bench_app =
        app.add_subcommand("bench", "benchmark the form-factor engines against each other and the machine");
    add_bench_options(*bench_app, bench_command);
    bool devices_json = false;
    CLI::App* devices = app.add_subcommand("devices", "list the form-factor engines this build can use");
    devices->add_flag("--json", devices_json, "machine-readable output");

    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        std::cerr << "hemirad: " << e.what() << " (see hemirad --help)\n";
        return 2;
    }

    try {
        if (*devices) {
            list_devices(std::cout, devices_json);
            return 0;
        }
        if (*bench_app) {
            run_bench(bench_command, std::cout);
            return 0;
        }
        std::signal(SIGINT, on_interrupt);
        std::signal(SIGTERM, on_interrupt);
        bake_options.interrupted = &g_interrupted;
        bake_options.progress = !bake_options.quiet && isatty(fileno(stderr));
        run_bake(bake_options);
        return 0;
    } catch (const InputError& e) {
        std::cerr << "hemirad: " << e.what() << "\n";
        return 2;
    } catch (const Interrupted&) {
        std::cerr << (bake_options.progress ? "\n" : "") << "hemirad: interrupted; no output written\n";
        return 130;
    } catch (const formfactor::VerifyError& e) {
        std::cerr << "hemirad: verification failed: " << e.what() << "\n";
        return 1;
    } catch (const ocl::BuildError& e) {
        std::cerr << "hemirad: " << e.what() << "\n";
        return 1;
    } catch (const ocl::DeviceError& e) {
        std::cerr << "hemirad: device failed: " << e.what() << " (--device auto would start again on the reference)\n";
        return 1;
    } catch (const cl::Error& e) {
        std::cerr << "hemirad: device failed: " << device_failure(e) << "\n";
        return 1;
    } catch (const std::bad_alloc&) {
        std::cerr << "hemirad: out of memory\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "hemirad: internal error: " << e.what() << "\n";
        return 1;
    }
}

}  // namespace hemirad::cli
