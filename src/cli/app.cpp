// The command line: parses options, runs the bake pipeline, and is the one catch point that
// maps errors to exit codes (0 done, 2 bad input or usage, 1 internal failure).
#include "cli/app.h"

#include <fmt/core.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <iostream>
#include <ostream>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include "bake/bake.h"
#include "image/image.h"
#include "bake/engine_select.h"
#include "bench/command.h"
#include "cl/runtime.h"
#include "cli/progress_line.h"
#include "core/error.h"
#include "core/quality.h"
#include "dist/dist.h"
#include "formfactor/verify.h"
#include "gen/content_scenes.h"
#include "scene/effects.h"
#include "scene/writer.h"

namespace hemirad::cli {
namespace {

using BakeOptions = hemirad::bake::Options;

// CLI11 converts with strtod and strtoll, which take "nan", "inf", "1e400" (as inf), hex and
// octal, and its Range and PositiveNumber checks let NaN through (every comparison with NaN is
// false), so a NaN threshold used to run a whole bake. Every number option goes through one of
// these instead: the whole text a finite decimal number within the range, rewritten in a plain
// spelling that CLI11's own conversion reads the same way.
CLI::Validator real_in(double lo, double hi, bool above_lo = false) {
    const std::string range = fmt::format("{}{:g}, {:g}]", above_lo ? "(" : "[", lo, hi);
    return CLI::Validator(
        [=](std::string& text) -> std::string {
            char* end = nullptr;
            errno = 0;
            const double value = std::strtod(text.c_str(), &end);
            if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(value))
                return fmt::format("'{}' is not a finite number", text);
            if (errno == ERANGE) return fmt::format("'{}' is out of the range of a double", text);
            if (!(above_lo ? value > lo : value >= lo) || !(value <= hi))
                return fmt::format("{} is outside {}", text, range);
            text = fmt::format("{:.17g}", value);
            return {};
        },
        "finite, in " + range);
}

template <class Int>
CLI::Validator integer_in(Int lo, Int hi) {
    const std::string range = fmt::format("[{}, {}]", lo, hi);
    return CLI::Validator(
        [=](std::string& text) -> std::string {
            const std::size_t digits = !text.empty() && text[0] == '-' ? 1 : 0;
            if (text.size() == digits || text.find_first_not_of("0123456789", digits) != std::string::npos)
                return fmt::format("'{}' is not a whole decimal number", text);
            const std::string outside = fmt::format("{} is outside {}", text, range);
            errno = 0;
            if (digits == 1) {
                if constexpr (std::is_unsigned_v<Int>) {
                    return outside;
                } else {
                    const long long value = std::strtoll(text.c_str(), nullptr, 10);
                    if (errno == ERANGE || value < lo || value > hi) return outside;
                    text = std::to_string(value);
                }
            } else {
                const unsigned long long value = std::strtoull(text.c_str(), nullptr, 10);
                if (errno == ERANGE || value > static_cast<unsigned long long>(hi)) return outside;
                if constexpr (std::is_signed_v<Int>) {
                    if (static_cast<long long>(value) < lo) return outside;
                } else {
                    if (value < lo) return outside;
                }
                text = std::to_string(value);  // no leading zeros, which CLI11 would read as octal
            }
            return {};
        },
        "in " + range);
}

template <class Int>
CLI::Validator integer_from(Int lo) {
    return integer_in<Int>(lo, std::numeric_limits<Int>::max());
}

constexpr double kLargestSize = 1e30;  // patch and element sizes, in scene units

void add_bake_options(CLI::App& bake, BakeOptions& o) {
    bake.add_option("scene", o.scene, "glTF 2.0 scene (.gltf or .glb)")->required();
    bake.add_option("-o,--output", o.output, "output directory (created if missing)")->capture_default_str();
    bake.add_option("--device", o.device,
                    "form-factor engine: auto|all|ref|opencl|opencl:P.D, or a list (opencl:0.0,opencl:0.1,ref) "
                    "whose devices share every batch (see hemirad devices; under mpirun, each rank's own)")
        ->capture_default_str();
    std::string presets;
    std::vector<std::string> names;
    for (const QualityPreset& p : kQualityPresets) {
        presets += fmt::format("{}{} (N {}, patches diagonal/{:g}, {:g} elements a side, threshold {:g}, contrast "
                               "{:g}, gather N {} × {}, refined {} levels at contrast {:g})",
                               presets.empty() ? "" : ", ", p.name, p.hemicube, 1.0 / p.patch_fraction,
                               p.elements_per_patch_edge, p.threshold, p.contrast, p.gather, p.gather_passes,
                               p.gather_refine, p.gather_contrast);
        names.emplace_back(p.name);
    }
    bake.add_option("--quality", o.quality,
                    "settings preset from the accuracy-against-time benchmark: " + presets +
                        "; the options below override their part")
        ->check(CLI::IsMember(names))
        ->capture_default_str();
    bake.add_option("--hemicube", o.hemicube,
                    "hemicube resolution N: top face N×N plus four N×N/2 half faces (default: the quality's)")
        ->transform(integer_in(8, 4096));
    bake.add_option("--gather", o.gather,
                    "final gather: a hemicube of this resolution from every output vertex gathers the solved light "
                    "(0: none; default: the quality's)")
        ->transform(integer_in(0, 4096));
    bake.add_option("--gather-passes", o.gather_passes,
                    "final gathers, each drawing the last one's light (default: the quality's)")
        ->transform(integer_in(1, 8));
    bake.add_option("--gather-refine", o.gather_refine,
                    "gather refinement: after the gather, split the elements whose vertices' light differs by more "
                    "than --gather-contrast and gather their new vertices, this many times (0: none; default: the "
                    "quality's)")
        ->transform(integer_in(0, 8));
    bake.add_option("--gather-contrast", o.gather_contrast,
                    "gather refinement splits an element when its reflectance times the span of its vertices' "
                    "gathered irradiance (luminance) is more than this share of its brightest radiosity (default: "
                    "the quality's)")
        ->transform(real_in(0.0, 1.0, true));
    bake.add_option("--gather-points", o.gather_points,
                    "the most hemicubes the final gather shoots: a mesh with more output vertices is gathered where "
                    "the light varies and interpolated between (report.json's gather.sparse says how); 0: every "
                    "vertex, however many (default: 50000, or every vertex where --gather is given)")
        ->transform(integer_from(0L));
    bake.add_option("--patch-size", o.patch_size,
                    "maximum patch edge, scene units (default: scene diagonal × the quality's fraction)")
        ->transform(real_in(0.0, kLargestSize, true));
    bake.add_option("--element-size", o.element_size,
                    "maximum element edge, scene units (default: patch size / the quality's elements a side)")
        ->transform(real_in(0.0, kLargestSize, true));
    bake.add_option("--threshold", o.threshold,
                    "progressive: stop when the share of final flux not yet placed is below this; matrix: iterate until "
                    "a bound on the error is below min(1e-4, T/100) (default: the quality's; 0 would never stop)")
        ->transform(real_in(0.0, 1.0, true));
    bake.add_option("--max-passes", o.max_passes,
                    "stop after this many shots (0: no limit; default: 100000 or twice the patches, whichever is more)")
        ->transform(integer_from(0L));
    bake.add_option("--batch", o.batch,
                    "shoot the K patches with the most unshot flux together (one launch on OpenCL); "
                    "each still shoots its flux at the time it is applied (default: those holding at least half "
                    "the largest unshot flux, up to 256)")
        ->transform(integer_in(1, 256));
    bake.add_flag("--cluster-apart,!--no-cluster-apart", o.cluster_apart,
                  "small faces of one material and node that share no edge but lie next to each other (a tree's "
                  "leaves, a grille) join one shooter where they face the same way and see its point: far fewer "
                  "passes for foliage-heavy scenes (default: on; --no-cluster-apart joins connected faces only)");
    bake.add_option("--threads", o.threads,
                    "host threads for the stages the host runs in parallel (contact lines, the gather's drawing "
                    "and rows, its interpolation, welding, the render); 0: every core. The bytes baked are the "
                    "same for any count")
        ->transform(integer_in(0, 4096))
        ->capture_default_str();
    bake.add_option("--solver", o.solver,
                    "matrix (a form-factor row per patch, then Gauss-Seidel), progressive (shooting), or auto: "
                    "matrix up to 3000 patches and reflectances up to 0.95, unless --preview-every is given")
        ->check(CLI::IsMember({"auto", "matrix", "progressive"}))
        ->capture_default_str();
    bake.add_option("--effects", o.effects,
                    fmt::format("force effects on or off, e.g. occlusion=off,colour=on (effects: {}; each on|off|auto); "
                                "by default each is planned from the scene and report.json says why",
                                hemirad::scene::effect_names("and")));
    bake.add_option("--sky", o.sky,
                    "light the scene with a sky dome of this radiance (emission / pi): RADIANCE, or "
                    "HORIZON,ZENITH radiances (between them by the sine of the elevation)");
    bake.add_option("--output-mode", o.output_mode,
                    "baked.gltf: scene (the input's nodes, materials, textures, cameras and lights, each baked "
                    "primitive refined, with COLOR_0 a viewer shows under unlit materials and the linear light in "
                    "_RADIOSITY and _IRRADIANCE) or radiosity (the element mesh alone, COLOR_0 = linear radiosity)")
        ->check(CLI::IsMember({"scene", "radiosity"}))
        ->capture_default_str();
    bake.add_option("--sun", o.sun,
                    "light the scene with a sun: AZIMUTH,ELEVATION,LUX (degrees clockwise from north, -Z, towards "
                    "east, +X; degrees above the horizon; illuminance on a surface facing it)");
    bake.add_option("--refine-levels", o.refine_levels,
                    "adaptive refinement: split an element at most this often where the irradiance contrasts (0: off)")
        ->transform(integer_in(0, 6))
        ->capture_default_str();
    bake.add_option("--contrast", o.contrast,
                    "adaptive refinement: split neighbours whose irradiance differs by more than this share "
                    "(default: the quality's)")
        ->transform(real_in(0.01, 1.0));
    bake.add_option("--checkpoint", o.checkpoint,
                    "write the solver's state to this file every --checkpoint-every passes or rows, and the light "
                    "after the solve, refinement and gather (atomically); --resume goes on from the last");
    bake.add_option("--checkpoint-every", o.checkpoint_every, "passes between checkpoints")
        ->transform(integer_from(1L))
        ->capture_default_str();
    bake.add_option("--resume", o.resume,
                    "go on from this checkpoint of the same scene and settings (after its last finished stage); the bake ends "
                    "with exactly the numbers of an uninterrupted one");
    bake.add_flag("--no-checkpoint", o.no_checkpoint,
                  "no automatic checkpoint (by default a bake expected to take over a minute keeps its solver's "
                  "state and each finished stage in $HEMIRAD_CACHE_DIR/checkpoints or ~/.cache/hemirad/checkpoints, "
                  "which the same command run again resumes, and removes it when the bake is done)")
        ->excludes("--checkpoint");
    bake.add_option("--seed", o.seed, "seed of every random choice (hemicube rotations)")
        ->transform(integer_from(std::uint64_t{0}))
        ->capture_default_str();
    bake.add_flag("--verify", o.verify, "check shots of the OpenCL engine against the scalar reference");
    bake.add_option("--verify-every", o.verify_every, "with --verify, check every K-th shot")
        ->transform(integer_from(1L))
        ->capture_default_str();
    bake.add_option("--camera", o.camera, "render from the camera with this name");
    bake.add_option("--look-from", o.look_from, "render from this point X,Y,Z (with --look-at): a view the file lacks");
    bake.add_option("--look-at", o.look_at, "... looking at this point X,Y,Z, +Y up");
    bake.add_option("--fov", o.fov, "vertical field of view of the render, degrees (default: the camera's, else 45.8)")
        ->transform(real_in(0.0, 179.0, true));
    bake.add_option("--exposure", o.exposure,
                    "render.png's exposure in stops: linear radiance x 2^EV (default: automatic, the 90th percentile "
                    "of lit pixels at 0.6)")
        ->transform(real_in(-64.0, 64.0));
    bake.add_option("--preview-every", o.preview_every, "write DIR/preview/pass_NNNNNN.png every K passes")
        ->transform(integer_from(0L));
    bake.add_option("--image-width", o.image_width, "width of render.exr/png; height follows the camera's aspect")
        ->transform(integer_in(16, hemirad::bake::kMaxImageSide))
        ->capture_default_str();
    bake.add_option("--max-memory", o.max_memory,
                    "memory the bake may use, e.g. 8G or 512M (default: what the machine has available); a bake "
                    "estimated to need more is refused before it starts, --solver auto takes the solver that fits, "
                    "and refinement stops where it would pass it");
    bake.add_flag("--strict-textures", o.strict_textures,
                  "a base colour or emissive texture whose image is missing or does not decode stops the bake "
                  "(exit 2); without it the material bakes with its factors alone, with a warning per image");
    bake.add_flag("--quiet", o.quiet, "no progress line");
    bake.add_flag("--progress", o.progress,
                  "report progress when stderr is not a terminal too (a log): a line every few seconds");
}

void add_bench_options(CLI::App& cmd, bench::BenchCommand& c) {
    bench::ThroughputOptions& o = c.throughput;
    cmd.add_option("scenes", o.scenes, "glTF files or generated scenes: procedural:, city:, furniture:, foliage:<triangles> (e.g. city:100k, procedural:1M)");
    cmd.add_option("--hemicube", o.hemicubes, "hemicube resolutions N, comma-separated")
        ->delimiter(',')
        ->transform(integer_in(8, 4096))
        ->capture_default_str();
    cmd.add_option("--engines", o.engines, "ref, embree, opencl (every device) or opencl:P.D; default: all")
        ->delimiter(',');
    cmd.add_option("--shots", o.shots, "shots per engine per repeat")
        ->transform(integer_from(1))
        ->capture_default_str();
    cmd.add_option("--repeats", o.repeats, "timed repeats (min, median and spread over them)")
        ->transform(integer_from(1))
        ->capture_default_str();
    cmd.add_option("--batch", o.batches,
                   "shots per engine call, comma-separated (each a run; with several, a table of shots/s against "
                   "them ends the output; --scaling takes the first)")
        ->delimiter(',')
        ->transform(integer_in(1, bench::kMaxBenchBatch))
        ->capture_default_str();
    const QualityPreset& quality = quality_preset("default");
    cmd.add_option(
           "--patch-size", o.patch_size,
           fmt::format("maximum patch edge (default: scene diagonal / {:g}, as a bake)", 1.0 / quality.patch_fraction))
        ->transform(real_in(0.0, kLargestSize, true));
    cmd.add_option("--element-size", o.element_size,
                   fmt::format("maximum element edge (default: patch size / {:g})", quality.elements_per_patch_edge))
        ->transform(real_in(0.0, kLargestSize, true));
    cmd.add_option("--seed", o.seed, "seed of the hemicube rotations")
        ->transform(integer_from(std::uint64_t{0}))
        ->capture_default_str();
    cmd.add_flag(
        "--no-calibrate", [&o](std::int64_t) { o.calibrate = false; },
        "skip measuring the machine's limit (fill rate, bandwidth)");
    cmd.add_flag("--accuracy", c.accuracy,
                 "instead of throughput: error against time over the settings, on analytic cases and a room");
    cmd.add_flag("--effects", c.effects,
                 "instead of throughput: bake the bundled scenes with each effect as planned and forced the other "
                 "way, and report the time saved and what changed (run from the repository root)");
    cmd.add_flag("--scaling", c.scaling,
                 "instead of throughput: shots/s and bake time against MPI ranks (run under mpirun) and devices "
                 "(--device all or a list), on one scene (default city:100k; --hemicube, --shots, --batch, --repeats "
                 "apply)");
    cmd.add_flag("--estimate", c.estimate,
                 "instead of throughput: how good the progress line's time left is: bake generated scenes of a few "
                 "sizes (or the scenes given) and print each stage's predicted against measured seconds and the "
                 "bake's total as predicted at 10% of it");
    cmd.add_flag("--quick", c.quick,
                 "with --accuracy, --effects or --estimate: a smoke test of a few coarse runs (seconds; --estimate: "
                 "under a minute)");
    cmd.add_option("--device", c.device,
                   "with --accuracy, --effects, --estimate or --scaling: auto, ref or opencl:P.D (--scaling: also all "
                   "or a list)")
        ->capture_default_str();
    cmd.add_option("--json", c.json, "also write the results here (JSON)");
}

struct SceneWriteCommand {
    std::string spec;
    std::string output;
    std::uint64_t seed = 1;
};

// `hemirad scene write`: generates the scene and writes it where the bake can load it.
void write_generated_scene(const SceneWriteCommand& c, std::ostream& out) {
    const std::filesystem::path file(c.output);
    if (file.extension() != ".glb" && file.extension() != ".gltf")
        throw InputError(fmt::format("{}: the output must end in .glb or .gltf", c.output));
    std::optional<scene::Scene> s = gen::generated_scene(c.spec, nullptr, c.seed);
    if (!s)
        throw InputError(fmt::format("{}: not a generated scene (procedural:, city:, furniture: or foliage:<triangles>)",
                                     c.spec));
    scene::write_gltf(*s, file);
    out << fmt::format("{}: {} triangles, {} nodes, {} materials -> {}\n", s->path.string(), s->triangles.size(),
                       s->nodes.size(), s->materials.size(), c.output);
}

// A worker rank's loop: its engines are made as a bake on rank 0 would make them on one device
// (choose_engine, then engine_like for the next meshes), never verifying.
int serve_rank(const std::string& device) {
    std::shared_ptr<bake::EngineChoice> choice;
    const auto factory = [&](const mesh::Mesh& mesh, const formfactor::Settings& settings) {
        if (!choice) {
            choice = std::make_shared<bake::EngineChoice>(bake::choose_engine(device, false, 1, mesh, settings));
            if (!choice->warning.empty())
                std::cerr << "hemirad: rank " << dist::rank() << ": warning: " << choice->warning << "\n";
            return std::move(choice->engine);
        }
        return bake::engine_like(*choice, mesh, settings);
    };
    return dist::serve(factory, [](const std::exception& e) { return bake::device_failure(e); });
}

}  // namespace

int run(int argc, char** argv) {
    if (!dist::built_with_mpi() && dist::launched_processes() > 1) {
        std::cerr << fmt::format("hemirad: started as {} processes (mpirun or srun), but this hemirad was built without "
                                 "MPI, so each would bake the whole scene into the same output; install libopenmpi-dev "
                                 "and build again, or run one process\n",
                                 dist::launched_processes());
        return 2;
    }
    const dist::Session mpi(argc, argv);
    CLI::App app{"hemirad: radiosity baker with a hemicube form-factor engine"};
    app.set_version_flag("--version", fmt::format("hemirad {}\nimages: {}", HEMIRAD_VERSION, image::backend().name));
    app.require_subcommand(1);
    BakeOptions bake_options;
    CLI::App* bake = app.add_subcommand("bake", "bake diffuse global illumination into a glTF scene");
    add_bake_options(*bake, bake_options);
    bench::BenchCommand bench_command;
    CLI::App* bench_app =
        app.add_subcommand("bench", "benchmark the form-factor engines against each other and the machine");
    add_bench_options(*bench_app, bench_command);
    SceneWriteCommand scene_write;
    CLI::App* scene_app = app.add_subcommand("scene", "generated benchmark scenes");
    scene_app->require_subcommand(1);
    CLI::App* scene_write_app = scene_app->add_subcommand(
        "write", "write a generated scene as glTF, for hemirad bake: procedural:, city:, furniture:, foliage:<triangles>");
    scene_write_app->add_option("spec", scene_write.spec, "e.g. city:150k, furniture:1M, foliage:2.5M")->required();
    scene_write_app->add_option("output", scene_write.output, "the file to write, .glb or .gltf (+ .bin)")->required();
    scene_write_app->add_option("--seed", scene_write.seed, "seed of the layout, sizes and colours")
        ->transform(integer_from<std::uint64_t>(0))
        ->capture_default_str();
    bool devices_json = false;
    CLI::App* devices = app.add_subcommand("devices", "list the form-factor engines this build can use");
    devices->add_flag("--json", devices_json, "machine-readable output");

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // Under mpirun rank 0 alone prints help, versions and usage errors.
        if (dist::rank() > 0) return e.get_exit_code() == 0 ? 0 : 2;
        if (dynamic_cast<const CLI::CallForHelp*>(&e) || dynamic_cast<const CLI::CallForAllHelp*>(&e) ||
            dynamic_cast<const CLI::CallForVersion*>(&e))
            return app.exit(e);
        std::cerr << "hemirad: " << printable(e.what()) << " (see hemirad --help)\n";
        return 2;
    }

    // An option given an empty value ("--sun ''", "--max-memory ''") would read as not given.
    for (const CLI::Option* option : bake->get_options())
        if (option->get_expected_min() > 0)
            for (const std::string& value : option->results())
                if (value.empty()) {
                    if (dist::rank() == 0)
                        std::cerr << "hemirad: " << option->get_name() << ": an empty value (give one, or leave the option out)\n";
                    return 2;
                }
    bake_options.batch_given = bake->get_option("--batch")->count() > 0;
    if (bench_command.scaling) {  // the throughput options that were given, over the scaling bench's defaults
        bench::ScalingOptions& sc = bench_command.scaling_options;
        const bench::ThroughputOptions& t = bench_command.throughput;
        sc.device = bench_command.device;
        if (!t.scenes.empty()) sc.scene = t.scenes.front();
        if (bench_app->get_option("--hemicube")->count() > 0) sc.hemicube = t.hemicubes.front();
        if (bench_app->get_option("--shots")->count() > 0) sc.shots = t.shots;
        if (bench_app->get_option("--batch")->count() > 0) sc.batch = t.batches.front();
        if (bench_app->get_option("--repeats")->count() > 0) sc.repeats = t.repeats;
        sc.seed = t.seed;
    }
    // Under mpirun, every rank but 0 serves rank 0's shots (dist.h) with its own --device; rank 0
    // runs the command alone.
    if (dist::rank() > 0) return serve_rank(*bake ? bake_options.device : bench_command.device);

    try {
        if (*devices) {
            list_devices(std::cout, devices_json);
            return 0;
        }
        if (*bench_app) {
            bench::run_bench(bench_command, std::cout);
            return 0;
        }
        if (*scene_write_app) {
            write_generated_scene(scene_write, std::cout);
            return 0;
        }
        // Every signal that would end the process stops the bake instead: it cleans up and exits
        // 130 (SIGINT, SIGTERM, SIGHUP) or 128 + the signal, within a second (core/cancel.h).
        bake_options.progress_tty = isatty(fileno(stderr));
        bake_options.progress = !bake_options.quiet && (bake_options.progress || bake_options.progress_tty);
        cancel::install();
        ProgressLine line(bake_options.progress, bake_options.progress_tty, bake_options.quiet);
        hemirad::bake::run(bake_options, line);
        return 0;
    } catch (const InputError& e) {
        std::cerr << "hemirad: " << printable(e.what()) << "\n";
        return 2;
    } catch (const cancel::Interrupted&) {
        cancel::reported();
        // The progress line was erased as the bake unwound (ProgressLine's destructor).
        std::cerr << "hemirad: " << cancel::describe() << "; no output written\n";
        return cancel::exit_code();
    } catch (const formfactor::VerifyError& e) {
        std::cerr << "hemirad: verification failed: " << printable(e.what()) << "\n";
        return 1;
    } catch (const ocl::BuildError& e) {
        std::cerr << "hemirad: " << e.what() << "\n";
        return 1;
    } catch (const ocl::DeviceError& e) {
        std::cerr << "hemirad: device failed: " << printable(e.what())
                  << " (--device auto would start again on the reference)\n";
        return 1;
    } catch (const cl::Error& e) {
        std::cerr << "hemirad: device failed: " << printable(bake::device_failure(e)) << "\n";
        return 1;
    } catch (const OutputError& e) {
        std::cerr << "hemirad: " << printable(e.what()) << "\n";
        return 1;
    } catch (const std::bad_alloc&) {
        std::cerr << "hemirad: out of memory\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "hemirad: internal error: " << printable(e.what()) << "\n";
        return 1;
    }
}

}  // namespace hemirad::cli
