// `hemirad bake`: load → mesh → progressive solve → report.json, baked.gltf, render.exr/.png.
// Final files are written to a temporary directory and renamed into place only when all exist.
#include "cli/bake.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <system_error>
#include <vector>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "cl/runtime.h"
#include "cli/budget.h"
#include "cli/checkpoint.h"
#include "cli/engine_select.h"
#include "core/cancel.h"
#include "core/durable.h"
#include "core/error.h"
#include "core/memory.h"
#include "core/timing.h"
#include "dist/dist.h"
#include "formfactor/near_field.h"
#include "formfactor/parallel.h"
#include "formfactor/row_cache.h"
#include "formfactor/timed.h"
#include "mesh/mesh.h"
#include "mesh/texturing.h"
#include "scene/sky.h"
#include "formfactor/hemicube.h"
#include "solve/final_gather.h"
#include "solve/lights.h"
#include "output/finite.h"
#include "output/output.h"
#include "scene/scene.h"
#include "scene/effects.h"
#include "formfactor/unoccluded.h"
#include "solve/matrix.h"
#include "solve/progressive.h"
#include "solve/refinement.h"

namespace hemirad::cli {
namespace fs = std::filesystem;
using ordered_json = nlohmann::ordered_json;

namespace {

// Shows every shot of the engine it wraps to an observer (BakeOptions::on_shot).
class ObservedEngine final : public formfactor::Engine {
public:
    using Observer = std::function<void(const formfactor::ShotResult&)>;
    ObservedEngine(std::unique_ptr<formfactor::Engine> inner, Observer observer)
        : inner_(std::move(inner)), observer_(std::move(observer)) {}
    std::string name() const override { return inner_->name(); }
    using formfactor::Engine::shoot;
    void shoot(const formfactor::ShotRequest& request, formfactor::ShotResult& out) override {
        inner_->shoot(request, out);
        observer_(out);
    }
    void shoot_batch(const std::vector<formfactor::ShotRequest>& shots,
                     std::vector<formfactor::ShotResult>& out) override {
        inner_->shoot_batch(shots, out);
        for (const formfactor::ShotResult& r : out) observer_(r);
    }
    const std::vector<std::int32_t>* last_ids(std::size_t i) const override { return inner_->last_ids(i); }

private:
    std::unique_ptr<formfactor::Engine> inner_;
    Observer observer_;
};

std::unique_ptr<formfactor::Engine> observed(std::unique_ptr<formfactor::Engine> engine,
                                             const ObservedEngine::Observer& observer) {
    if (!observer) return engine;
    return std::make_unique<ObservedEngine>(std::move(engine), observer);
}

// A bake stages its files in DIR/.hemirad-tmp-<pid> until all of them exist.
constexpr char kStagingPrefix[] = ".hemirad-tmp-";
// What a bake writes into DIR, in the order they are moved into place (report.json last).
const std::vector<std::string> kOutputNames = {"baked.gltf", "baked.bin", "render.exr", "render.png", "report.json"};

// Before any work: whatever is in the way of the outputs is the user's and stays. A directory
// (or a FIFO, a device) named like an output would stop the bake only when it is moved into
// place, at the end; a file named preview, only at the first preview frame.
void check_output_names(const BakeOptions& o) {
    std::error_code ec;
    const fs::path dir = o.output;
    for (const std::string& name : kOutputNames) {
        const fs::file_status st = fs::symlink_status(dir / name, ec);
        if (fs::exists(st) && !fs::is_regular_file(st) && !fs::is_symlink(st))
            throw InputError(fmt::format("{}: exists and is not a file; the bake would replace it", (dir / name).string()));
    }
    if (o.preview_every > 0 && fs::exists(dir / "preview", ec) && !fs::is_directory(dir / "preview", ec))
        throw InputError(fmt::format("{}: exists and is not a directory (--preview-every writes its frames there)",
                                     (dir / "preview").string()));
}

// Before any work: no output may replace the scene or a file it reads (`inputs`: the scene, then
// its buffers and images), compared as files, not as names: the same directory entry (a link
// named like an output is the user's too) or the same file through a link. Re-baking
// out/baked.gltf into out/, or a scene with a texture named render.png into its own folder,
// would otherwise replace the input with the bake's output.
void check_inputs_kept(const BakeOptions& o, const std::vector<fs::path>& inputs) {
    std::error_code ec;
    const fs::path dir = o.output;
    if (!fs::is_directory(dir, ec)) return;  // made by this bake: it holds nothing of the user's
    const auto entry = [](const fs::path& p) {
        std::error_code e;
        return fs::weakly_canonical(fs::absolute(p, e).parent_path(), e) / p.filename();
    };
    const auto same = [&](const fs::path& a, const fs::path& b) {
        std::error_code e;
        return entry(a) == entry(b) || fs::equivalent(a, b, e);
    };
    std::vector<fs::path> outputs;
    for (const std::string& name : kOutputNames) outputs.push_back(dir / name);
    const fs::path previews = dir / "preview";
    for (std::size_t i = 0; i < inputs.size(); ++i) {
        const std::string what = i == 0 ? "the scene being baked" : fmt::format("'{}', a file the scene reads", inputs[i].string());
        for (const fs::path& out : outputs)
            if (fs::exists(fs::symlink_status(out, ec)) && same(out, inputs[i]))
                throw InputError(fmt::format("{}: is {}; the bake would replace it: choose another output directory (-o)",
                                             out.string(), what));
        // Preview frames are pass_NNNNNN.png in DIR/preview.
        const std::string name = inputs[i].filename().string();
        if (o.preview_every > 0 && name.rfind("pass_", 0) == 0 && inputs[i].extension() == ".png" &&
            fs::exists(previews, ec) && same(inputs[i].parent_path(), previews))
            throw InputError(fmt::format("{}: is {}, and --preview-every writes its frames there; choose another "
                                         "output directory (-o)",
                                         (previews / name).string(), what));
    }
}

// Staging directories left by bakes that were killed (SIGKILL, power loss): those whose process
// no longer exists. A live process's, another user's or a reused pid's are left alone.
void remove_stale_staging(const fs::path& dir) {
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
        const std::string name = entry.path().filename().string();
        if (name.rfind(kStagingPrefix, 0) != 0 || !entry.is_directory(ec)) continue;
        const std::string digits = name.substr(sizeof kStagingPrefix - 1);
        if (digits.empty() || digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos) continue;
        const auto pid = static_cast<pid_t>(std::stol(digits));
        if (pid > 0 && pid != getpid() && kill(pid, 0) != 0 && errno == ESRCH) fs::remove_all(entry.path(), ec);
    }
}

// Where a preview frame is written before it is renamed into place.
fs::path preview_staging(const fs::path& file) { return file.parent_path() / (".tmp-" + file.filename().string()); }

// Everything this run creates under the output directory; removed unless commit() is reached.
class OutputTransaction {
public:
    explicit OutputTransaction(const fs::path& dir) : dir_(dir) {
        // Every directory this run creates (parents too), to remove them on failure.
        std::error_code ec;
        std::vector<fs::path> created_dirs;
        for (fs::path p = fs::absolute(dir_, ec); !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
            created_dirs.push_back(p);
            if (p == p.parent_path()) break;
        }
        staging_ = dir_ / fmt::format("{}{}", kStagingPrefix, static_cast<long>(getpid()));
        // What a failed run removes (by the destructor, or by the watchdog should the bake not
        // unwind by itself: core/cancel.h): the staging directory, the preview frames, then the
        // directories this run made, deepest first, if empty.
        cleanup_.remove_tree(staging_);
        for (const auto& d : created_dirs) cleanup_.remove_if_empty(d);
        fs::create_directories(dir_, ec);
        if (ec || !fs::is_directory(dir_))
            throw InputError(fmt::format("{}: cannot create output directory: {}", dir_.string(), ec ? ec.message() : "not a directory"));
        remove_stale_staging(dir_);
        fs::remove_all(staging_, ec);
        fs::create_directories(staging_, ec);
        if (ec) throw InputError(fmt::format("{}: cannot write: {}", dir_.string(), ec.message()));
    }
    OutputTransaction(const OutputTransaction&) = delete;
    OutputTransaction& operator=(const OutputTransaction&) = delete;
    ~OutputTransaction() { cleanup_.remove_now(); }  // nothing once committed; never throws

    fs::path staged(const std::string& name) const { return staging_ / name; }

    // Previews are visible while the bake runs (so a user can watch), each written atomically.
    fs::path preview_path(long pass) {
        const fs::path dir = dir_ / "preview";
        std::error_code ec;
        if (!fs::exists(dir, ec) && fs::create_directories(dir, ec)) cleanup_.remove_if_empty(dir);
        const fs::path file = dir / fmt::format("pass_{:06d}.png", pass);
        cleanup_.remove_file(file);
        cleanup_.remove_file(preview_staging(file));
        return file;
    }

    // Renames the staged files into place; report.json last, so its presence means complete.
    // Should a rename fail part-way, the files already moved are taken out again. The files are
    // flushed to the disk first (a disk that fills up may say so only then) and the directory
    // after, so that a power cut leaves the old files or the new, never a new name on no data.
    void commit(const std::vector<std::string>& names) {
        for (const auto& name : names)
            if (!sync_to_disk(staging_ / name))
                throw InternalError(fmt::format("{}: cannot flush {} to the disk", dir_.string(), name));
        // The renames run whole: a signal's watchdog waits for them (and then leaves the outputs).
        cleanup_.critical([&] {
            std::vector<fs::path> moved;
            for (const auto& name : names) {
                std::error_code ec;
                fs::rename(staging_ / name, dir_ / name, ec);
                if (ec) {
                    for (const auto& f : moved) fs::remove(f, ec);
                    throw InternalError(fmt::format("{}: cannot move {} into place: {}", dir_.string(), name, ec.message()));
                }
                moved.push_back(dir_ / name);
            }
            cleanup_.release();
        });
        std::error_code ec;
        fs::remove_all(staging_, ec);
        sync_to_disk(dir_);
    }

private:
    fs::path dir_, staging_;
    cancel::Cleanup cleanup_;
};

ordered_json vec3(const glm::dvec3& v) { return ordered_json::array({v.x, v.y, v.z}); }

bool emits(const scene::Scene& scene, const scene::Triangle& t) {
    const glm::dvec3& e = scene.materials[t.material].emission;
    return e.x > 0.0 || e.y > 0.0 || e.z > 0.0;
}

// "X,Y,Z": three finite numbers, or exit 2 naming the option.
glm::dvec3 parse_point(const std::string& text, const std::string& option) {
    glm::dvec3 p(0.0);
    std::size_t at = 0;
    for (int i = 0; i < 3; ++i) {
        const std::size_t end = i < 2 ? text.find(',', at) : text.size();
        const std::string part = end == std::string::npos ? std::string() : text.substr(at, end - at);
        char* stop = nullptr;
        p[i] = std::strtod(part.c_str(), &stop);
        if (part.empty() || stop != part.c_str() + part.size() || !std::isfinite(p[i]) ||
            (i == 2 && text.find(',', at) != std::string::npos))
            throw InputError(fmt::format("{} '{}': expected X,Y,Z, three finite numbers", option, text));
        at = end + 1;
    }
    return p;
}

// The punctual lights of a scene that shine (point, spot and directional ones).
std::size_t shining_lights(const scene::Scene& scene) {
    return static_cast<std::size_t>(std::count_if(scene.lights.begin(), scene.lights.end(), [](const scene::PunctualLight& l) {
        return l.intensity != glm::dvec3(0.0);
    }));
}

void check_scene(const scene::Scene& scene) {
    if (scene.triangles.empty())
        throw InputError(fmt::format("{}: no triangles to bake (no mesh with TRIANGLES primitives)", scene.path.string()));
    if (shining_lights(scene) > 0 ||
        std::any_of(scene.triangles.begin(), scene.triangles.end(), [&](const scene::Triangle& t) { return emits(scene, t); }))
        return;
    throw InputError(fmt::format(
        "{}: nothing emits light: 0 emissive triangles (no triangle's material has emission > 0) and {} "
        "KHR_lights_punctual light{} of intensity > 0 (of {}); hemirad bakes emissive materials and point, spot and "
        "directional lights, --sky RADIANCE[,ZENITH_RADIANCE] adds a sky and --sun AZIMUTH,ELEVATION,LUX a sun",
        scene.path.string(), shining_lights(scene), shining_lights(scene) == 1 ? "" : "s", scene.lights.size()));
}

// After the see_through decision: a scene whose only emitters were see-through (faint blended
// glows) has nothing left to light it, which the user can change.
void check_emitters_left(const scene::Scene& scene, const scene::EffectsPlan& plan) {
    if (!plan.see_through.on || shining_lights(scene) > 0) return;
    if (std::none_of(scene.triangles.begin(), scene.triangles.end(),
                     [&](const scene::Triangle& t) { return emits(scene, t); }))
        throw InputError(fmt::format("{}: nothing emits light once see-through surfaces are left out: every emissive "
                                     "triangle is a faint alpha-blended or transmissive glow; --effects see_through=off "
                                     "bakes them as opaque emitters",
                                     scene.path.string()));
}

// After meshing: a material that emits in the file but whose surfaces give the mesh no light
// (every texel cut away by alphaMode MASK, an emissive texture black where the surface is, or
// only triangles of no area) is a lamp the bake cannot see: a warning naming it. With no light
// left anywhere the bake would be black: exit 2, saying why.
void check_lamps_seen(scene::Scene& scene, const mesh::Mesh& mesh) {
    std::vector<double> flux(scene.materials.size(), 0.0);
    for (const mesh::Element& e : mesh.elements)
        flux[e.material] += e.area * std::max({e.emission.x, e.emission.y, e.emission.z});
    std::vector<std::size_t> triangles(scene.materials.size(), 0);
    for (const scene::Triangle& t : scene.triangles)
        if (emits(scene, t)) ++triangles[t.material];
    std::vector<std::string> unseen;
    for (std::size_t m = 0; m < scene.materials.size(); ++m) {
        if (triangles[m] == 0 || flux[m] > 0.0) continue;
        const scene::Material& mat = scene.materials[m];
        const std::string why = mat.alpha_cutoff >= 0.0
                                    ? fmt::format("its surfaces are cut away by alphaMode MASK (alpha below its cutoff {:g})",
                                                  mat.alpha_cutoff)
                                : mat.emissive_texture ? "its emissive texture is black where its surfaces are"
                                                       : "its triangles have no area";
        unseen.push_back(fmt::format("material '{}' emits, but its {} triangle{} the bake no light: {}", mat.name,
                                     triangles[m], triangles[m] == 1 ? " gives" : "s give", why));
        scene.warnings.push_back(scene.path.string() + ": " + unseen.back());
    }
    const bool lit = shining_lights(scene) > 0 ||
                     std::any_of(flux.begin(), flux.end(), [](double f) { return f > 0.0; });
    if (!lit && !unseen.empty()) {
        std::string all;
        for (const std::string& u : unseen) all += (all.empty() ? "" : "; ") + u;
        throw InputError(fmt::format("{}: nothing gives light, the bake would be black: {}", scene.path.string(), all));
    }
}

void write_png_preview(const scene::Scene& scene, const mesh::Mesh& mesh, const solve::Progressive& solver,
                       const output::View& view, int width, int height, const fs::path& file) {
    const output::Image image = output::render(scene, mesh, solver.radiosity(/*ambient=*/true), view, width, height);
    const fs::path tmp = preview_staging(file);
    output::write_png(image, tmp, output::auto_exposure(image));
    fs::rename(tmp, file);
}

// The memory a bake may use, and where that figure comes from (for messages and the report).
// The solver and refinement are planned by `bytes`, which does not change from run to run (so
// neither do the numbers a bake gives); without --max-memory, a bake that needs more than is
// `available` at the moment is also refused rather than swapped or killed part-way.
struct MemoryLimit {
    double bytes = 0.0;
    std::string source;
    std::optional<double> available;  // without --max-memory: what is free now
};

MemoryLimit memory_limit_of(const std::string& option) {
    if (!option.empty()) {
        try {
            return {parse_bytes(option), "--max-memory allows", std::nullopt};
        } catch (const std::invalid_argument& e) {
            throw InputError(fmt::format("--max-memory {}: {}", option, e.what()));
        }
    }
    const std::optional<double> machine = machine_memory();
    return {machine ? *machine : double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE)), "this machine has",
            available_memory()};
}

// Whether the hemicube engine --device picks may be an OpenCL one (whose buffers, on a CPU device,
// are host memory).
bool may_use_opencl(const std::string& device) {
    if (device == "ref") return false;
    if (device == "auto") {
        const char* env = std::getenv("HEMIRAD_DEVICE");
        if (env && std::string(env) == "ref") return false;
        return !ocl::list_devices().empty();
    }
    return true;
}

// Convergence forced off: shoot until this little is left (progressive), or solve to rounding (matrix).
constexpr double kUnconvergedThreshold = 1e-6;
constexpr double kUnconvergedTolerance = 1e-12;
// Gauss–Seidel sweeps at most (each costs P² per channel; --solver auto avoids the matrix where
// reflectances are high enough to need many).
constexpr int kMaxSweeps = 20000;

// Before a final gather, elements along contact lines longer than this fraction of the element size
// (those not yet refined) are split once. Measured on the Cornell box against the path tracer
// (per-pixel error, gather points): default 2.31% (10,370) → 2.16% (12,660); a uniformly finer
// element (0.015 for 0.02) costs more for less, 2.08% (16,661); split twice (0.3) 2.11% (17,382);
// high 1.74% → 1.67%, draft 5.76% → 5.58%.
constexpr double kContactGrading = 0.6;

// Gather refinement (--gather-refine, --gather-contrast; solve::gather_contrasts): elements whose
// vertices' gathered light spans more than the contrast and kGatherNoiseFloor of the mean are
// split, down to kGatherMinSize of the element size, and only their new vertices gathered. On the
// Cornell box (per-pixel error, gather points; four levels; bench --accuracy): at the default
// 1.76% (12,660) → contrast 0.5 1.48% (14,570), 0.3 1.36% (18,478), 0.2 1.31% (26,398); one
// level 1.61%, two 1.53%; down to 0.12 of the element instead of 0.06, contrast 0.2 gave 1.42%
// (19,935). At high (gather N 192) 1.46% → 0.4 1.14% (18,880), 0.3 1.10% (20,877), 0.2 1.07%
// (26,487). A uniformly finer element (0.01 for 0.02) gives 1.30% with 3× the gather.
constexpr double kGatherNoiseFloor = 0.02;
constexpr double kGatherMinSize = 0.06;

// The most output vertices the quality's final gather takes on by itself (see solve_and_refine).
constexpr std::size_t kMaxPlannedGather = 50000;

// A bake expected to take longer than this (seconds) says so before it starts.
constexpr double kSayTimeAbove = 60.0;

class ProgressLine {
public:
    // On a terminal (tty), one line redrawn in place five times a second; in a log, a line every
    // kLogSeconds.
    static constexpr double kLogSeconds = 5.0;
    ProgressLine(bool on, bool tty) : on_(on), tty_(tty), start_(Clock::now()) {}
    void update(const solve::Progressive& solver, double threshold) {
        if (!due(solver.done())) return;
        const double elapsed = seconds_since(start_);
        const double err = solver.error();
        if (first_error_ <= 0.0 && std::isfinite(err) && err > 0.0) {
            first_error_ = err;
            first_time_ = elapsed;
        }
        // The error falls roughly exponentially with time: extrapolate log(error) linearly.
        std::string eta = "?";
        if (first_error_ > 0.0 && err > threshold && err < first_error_ && elapsed > first_time_) {
            const double rate = std::log(first_error_ / err) / (elapsed - first_time_);
            eta = fmt::format("~{:.0f} s", std::log(err / threshold) / rate);
        } else if (solver.done()) {
            eta = "0 s";
        }
        print(fmt::format("pass {}  unshot {:.2e}  error {:.2e}  {:.1f} s  left {}", solver.passes(),
                          solver.unshot_fraction(), err, elapsed, eta));
    }
    void lights(std::size_t done, std::size_t total) {
        if (!due(done >= total)) return;
        print(fmt::format("lights' hemicubes {} / {}  {:.1f} s", done, total, seconds_since(start_)));
    }
    void rows(long done, long total) {
        if (!due(done >= total)) return;
        print(fmt::format("form-factor rows {} / {}  {:.1f} s", done, total, seconds_since(start_)));
    }
    void gathering(long points, long total) {
        if (!due(points >= total)) return;
        print(fmt::format("final gather {} / {} vertices  {:.1f} s", points, total, seconds_since(start_)));
    }
    void refining(int level, long shots, long total) {
        if (!due(shots >= total)) return;
        print(fmt::format("refinement level {}: re-gather {} / {} shots  {:.1f} s", level, shots, total,
                          seconds_since(start_)));
    }
    void finish() {
        if (on_ && tty_ && printed_) std::fprintf(stderr, "\n");
        printed_ = false;
    }

private:
    bool due(bool last) {
        if (!on_) return false;
        const double elapsed = seconds_since(start_);
        if (elapsed - last_ < (tty_ ? 0.2 : kLogSeconds) && !last) return false;
        last_ = elapsed;
        return true;
    }
    void print(const std::string& line) {
        std::fprintf(stderr, tty_ ? "\r\033[K%s" : "hemirad: %s\n", line.c_str());
        std::fflush(stderr);
        printed_ = true;
    }
    bool on_, tty_;
    Clock::time_point start_;
    double last_ = -1e9, first_error_ = 0.0, first_time_ = 0.0;
    bool printed_ = false;
};

}  // namespace

void list_devices(std::ostream& out, bool json) {
    const std::vector<ocl::DeviceInfo> devices = ocl::list_devices();
    if (json) {
        ordered_json j = ordered_json::array();
        j.push_back({{"id", "ref"}, {"backend", "ref"}, {"platform", "host"},
                     {"name", "scalar reference hemicube (1 thread)"}});
        for (const auto& d : devices)
            j.push_back({{"id", d.id()}, {"backend", "opencl"}, {"platform", d.platform_name}, {"name", d.name},
                         {"vendor", d.vendor}, {"version", d.version}, {"driver", d.driver},
                         {"type", d.type}, {"compute_units", d.compute_units},
                         {"global_memory_bytes", d.global_memory}, {"fp64", d.fp64},
                         {"int64_atomics", d.int64_atomics}});
        out << j.dump(2) << "\n";
        return;
    }
    out << "ref          scalar reference hemicube (host, 1 thread)\n";
    for (const auto& d : devices)
        out << fmt::format("{:<12} {} | {} | {} | {} compute units | fp64 {}\n", d.id(), d.name, d.platform_name,
                           d.type, d.compute_units, d.fp64 ? "yes" : "no");
    if (devices.empty()) out << "(no OpenCL platform or device found)\n";
    out << "all          every OpenCL device above, sharing each batch (as does a list: opencl:0.0,opencl:0.1)\n";
    out << (dist::built_with_mpi() ? "MPI          built in: under mpirun or srun, ranks share each batch too\n"
                                   : "MPI          not built in (install libopenmpi-dev and build again)\n");
}

namespace {

// What either solver leaves for the output and the report.
struct Solution {
    std::vector<glm::dvec3> radiosity, irradiance;  // per element, the ambient term included
    glm::dvec3 ambient{0.0};
    std::vector<glm::dvec3> shot;  // per patch, the radiosity it shot in all
    solve::Energy energy;
    long passes = 0;  // hemicubes shot by the solver
    bool converged = false;
    double error = 0.0;
    double unshot_fraction = 0.0;
    int iterations = 0;  // Gauss–Seidel sweeps (matrix)
    std::string convergence_rule;  // what "converged" rests on
    long resumed_from = -1;  // the passes or rows a --resume started from
};

ordered_json effect_json(const scene::EffectDecision& d) {
    return {{"on", d.on}, {"forced", d.forced}, {"why", d.why}};
}

// What either solver needs of a bake besides the mesh and the engine.
struct SolveContext {
    const BakeOptions& o;                  // the effective options
    double threshold;                      // progressive: stop below it
    const solve::MatrixSettings& matrix;   // the matrix solver's settings
    const std::string& fingerprint;        // of the checkpoints written
    const std::string& resume_state;       // what --resume read, or empty
    ProgressLine& progress;
    std::function<void(const solve::Progressive&)> preview;  // writes a preview frame of the passes so far
    const std::vector<glm::dvec3>* direct;  // the punctual lights' irradiance per element, or null
};

Solution solve_with_matrix(const mesh::Mesh& mesh, formfactor::Engine& engine, const SolveContext& c) {
    const BakeOptions& o = c.o;
    solve::Matrix solver(mesh, engine, c.matrix, c.direct);
    Solution solution;
    if (!o.resume.empty()) {
        restore(solver, c.resume_state, o.resume);
        solution.resumed_from = solver.rows();
    }
    long checkpointed = solver.rows();  // the rows of the last checkpoint written or resumed
    solver.solve([&](long done, long total) {
        cancel::check();
        c.progress.rows(done, total);
        // Every K rows, and all of them: a bake killed while solving or refining then resumes
        // without shooting a row again.
        if (!o.checkpoint.empty() && done != checkpointed &&
            (done / o.checkpoint_every > checkpointed / o.checkpoint_every || done == total)) {
            checkpointed = done;
            write_checkpoint(o.checkpoint, c.fingerprint, solver);
        }
    });
    solution.radiosity = solver.radiosity();
    solution.irradiance = solver.irradiance();
    solution.shot = solver.patch_radiosity();
    solution.energy = solver.energy();
    solution.passes = solver.rows();
    solution.converged = solver.converged();
    solution.error = solver.error_bound();
    solution.unshot_fraction = solution.energy.emitted > 0.0 ? solution.energy.unshot / solution.energy.emitted : 0.0;
    solution.iterations = solver.iterations();
    if (solution.converged) solution.convergence_rule = "error bound";
    return solution;
}

Solution solve_progressively(const mesh::Mesh& mesh, formfactor::Engine& engine, const SolveContext& c) {
    const BakeOptions& o = c.o;
    solve::Settings settings;
    settings.threshold = c.threshold;
    settings.max_passes = max_passes_for(o, mesh.patches.size());
    settings.batch = o.batch;
    solve::Progressive solver(mesh, engine, settings, c.direct);
    Solution solution;
    if (!o.resume.empty()) {
        restore(solver, c.resume_state, o.resume);
        solution.resumed_from = solver.passes();
    }
    // Preview frames and checkpoints: one each time the passes cross a multiple of K.
    long previews = o.preview_every > 0 ? solver.passes() / o.preview_every : 0;
    long checkpointed = solver.passes();  // the passes of the last checkpoint written or resumed
    while (solver.step()) {
        cancel::check();
        c.progress.update(solver, c.threshold);
        if (!o.checkpoint.empty() && solver.passes() / o.checkpoint_every > checkpointed / o.checkpoint_every) {
            checkpointed = solver.passes();
            write_checkpoint(o.checkpoint, c.fingerprint, solver);
        }
        if (o.preview_every > 0 && solver.passes() / o.preview_every > previews) {
            previews = solver.passes() / o.preview_every;
            c.preview(solver);
        }
    }
    // The finished solve too: a bake killed while refining resumes straight to refinement.
    if (!o.checkpoint.empty() && solver.passes() != checkpointed) write_checkpoint(o.checkpoint, c.fingerprint, solver);
    c.progress.update(solver, c.threshold);
    solution.radiosity = solver.radiosity(/*ambient=*/true);
    solution.irradiance = solver.irradiance(/*ambient=*/true);
    solution.ambient = solver.ambient();
    solution.shot = solver.shot();
    solution.energy = solver.energy();
    solution.passes = solver.passes();
    solution.converged = solver.converged();
    solution.error = solver.error();
    solution.unshot_fraction = solver.unshot_fraction();
    solution.convergence_rule = solver.convergence_rule();
    return solution;
}

}  // namespace

int planned_batch(std::size_t members) {
    return members <= 1 ? 1 : static_cast<int>(std::min<std::size_t>(256, kShotsPerMember * members));
}

// A fixed cap stopped scenes of many patches before one round: city:1M at draft (364,391 patches)
// converges after 150,795 passes, foliage:100k (95,553) after more than 100,000.
long max_passes_for(const BakeOptions& o, std::size_t patches) {
    return o.max_passes >= 0 ? o.max_passes : std::max<long>(100000, 2 * static_cast<long>(patches));
}

void run_bake(const BakeOptions& options) {
    const auto t_total = Clock::now();
    const QualityPreset& quality = quality_preset(options.quality);
    BakeOptions o = options;  // with the preset's settings where none was given
    if (o.hemicube == 0) o.hemicube = quality.hemicube;
    if (o.threshold < 0.0) o.threshold = quality.threshold;
    if (o.hemicube % 2 != 0) throw InputError(fmt::format("--hemicube {}: must be even", o.hemicube));
    // Several devices or ranks share each batch: the top-K shooters grow with them.
    // A resumed bake keeps its checkpoint's batch, on any number of them.
    if (!o.batch_given) {
        const std::optional<int> resumed = o.resume.empty() ? std::nullopt : checkpoint_batch(o.resume);
        o.batch = resumed ? *resumed : planned_batch(device_count(o.device) + EngineChoice::remote_ranks());
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
    scene::EffectOverrides overrides;
    try {
        overrides = scene::parse_effect_overrides(o.effects);
    } catch (const std::invalid_argument& e) {
        throw InputError(fmt::format("--effects {}: {}", o.effects, e.what()));
    }
    if (o.look_from.empty() != o.look_at.empty())
        throw InputError(o.look_from.empty() ? "--look-at needs --look-from" : "--look-from needs --look-at");
    if (!o.look_from.empty() && !o.camera.empty())
        throw InputError("--camera and --look-from name two views; give one");
    const std::optional<std::pair<glm::dvec3, glm::dvec3>> look =
        o.look_from.empty() ? std::nullopt
                            : std::optional(std::pair(parse_point(o.look_from, "--look-from"), parse_point(o.look_at, "--look-at")));
    const std::optional<scene::Sky> sky =
        o.sky.empty() ? std::nullopt : std::optional<scene::Sky>(scene::parse_sky(o.sky, "--sky"));
    const std::optional<scene::PunctualLight> sun =
        o.sun.empty() ? std::nullopt : std::optional(scene::parse_sun(o.sun, "--sun"));

    // Files named by options, before any work: a wrong --resume fails at once, and a --checkpoint
    // naming the scene (or any file not a checkpoint) must not be overwritten.
    if (!o.checkpoint.empty()) check_checkpoint_target(o.checkpoint);
    if (!o.resume.empty()) check_resume_source(o.resume);
    check_output_names(o);
    const MemoryLimit memory_limit = memory_limit_of(o.max_memory);

    auto t0 = Clock::now();
    scene::LoadOptions load_options;
    load_options.max_bytes = memory_limit.bytes;
    load_options.limit_source = memory_limit.source;
    load_options.inputs = [&](const std::vector<fs::path>& inputs) { check_inputs_kept(o, inputs); };
    scene::Scene scene = scene::load(o.scene, load_options);
    if (sky && !scene.triangles.empty()) scene::add_sky(scene, *sky);
    if (sun) scene.lights.push_back(*sun);
    check_scene(scene);
    const double t_load = seconds_since(t0);
    cancel::check();  // a signal while loading a large scene

    // Which effects this scene calls for (report.json `effects` says why).
    scene::EffectsPlan plan = scene::plan_effects(scene, overrides);
    scene::apply_see_through(scene, plan);
    check_emitters_left(scene, plan);
    scene::apply_two_sided(scene, plan, overrides);
    scene::apply_colour(scene, plan);
    if (o.verify && !plan.occlusion.on) {
        if (plan.occlusion.forced)
            throw InputError("--verify checks the hemicube engines, which --effects occlusion=off does not use");
        plan.occlusion = {true, false, "kept on for --verify, which checks the hemicube engines (" + plan.occlusion.why + ")"};
    }
    if (overrides.interreflection == scene::Force::off && o.solver == "progressive")
        throw InputError("--solver progressive: direct light only (--effects interreflection=off) is solved by --solver matrix");

    mesh::Settings mesh_settings;
    const double diagonal = scene.diagonal();
    if (!(diagonal > 0.0) || !std::isfinite(diagonal))
        throw InputError(fmt::format("{}: the scene has no extent (all vertices coincide)", o.scene));
    mesh_settings.patch_size = o.patch_size > 0.0 ? o.patch_size : diagonal * quality.patch_fraction;
    mesh_settings.element_size = o.element_size > 0.0 ? o.element_size : mesh_settings.patch_size / quality.elements_per_patch_edge;
    // The exact unoccluded engine integrates over each patch's polygon: clusters only for the hemicube.
    mesh_settings.cluster = plan.occlusion.on;
    if (mesh_settings.element_size > mesh_settings.patch_size)
        throw InputError(fmt::format("--element-size {} is larger than the patch size {}", mesh_settings.element_size, mesh_settings.patch_size));
    output::View view = look ? output::look_view(look->first, look->second, 0.8)
                             : output::choose_view(scene, o.camera);  // fails early on a bad --camera
    if (o.fov > 0.0) view.yfov = o.fov * M_PI / 180.0;
    const int width = o.image_width;
    const double rows = std::max(1.0, std::round(width / view.aspect));  // the loader keeps aspects within [1/16, 16]
    if (!(rows <= kMaxImageSide))
        throw InputError(fmt::format("--image-width {}: camera '{}' (aspect ratio {:g}) makes the image {:g} pixels "
                                     "high, above {}; choose a smaller --image-width",
                                     width, view.name, view.aspect, rows, kMaxImageSide));
    const int height = static_cast<int>(rows);

    // Before any of the mesh is built: how much memory the bake will need with each solver, which
    // solver `auto` takes (by that memory and by expected time), and whether the bake fits at all.
    const bool direct_only = !plan.interreflection.on;
    solve::MatrixSettings matrix_settings = solve::matrix_settings(o.threshold, o.batch);
    if (!plan.convergence.on) matrix_settings.tolerance = kUnconvergedTolerance;
    matrix_settings.grey = !plan.colour.on;
    matrix_settings.interreflection = !direct_only;
    matrix_settings.max_iterations = kMaxSweeps;
    BakeShape shape;
    shape.hemicube = o.hemicube;
    shape.batch = o.batch;
    shape.matrix = matrix_settings;
    shape.opencl = plan.occlusion.on && may_use_opencl(o.device);
    shape.fallback_copy = shape.opencl && o.device == "auto";
    for (const scene::Triangle& t : scene.triangles)
        for (const glm::dvec3& rho : t.rho) shape.max_reflectance = std::max({shape.max_reflectance, rho.x, rho.y, rho.z});
    shape.refine_levels = plan.refinement.on ? o.refine_levels : 0;
    shape.pixels = double(width) * double(height);
    // A parallel shot's grid follows the median element, which the counts do not give (clusters'
    // faces can be far smaller than the element size): counted at its cap.
    if (std::any_of(scene.lights.begin(), scene.lights.end(), [](const scene::PunctualLight& l) {
            return l.type == scene::PunctualLight::Type::directional && l.intensity != glm::dvec3(0.0);
        })) {
        const double side = formfactor::ParallelSettings().max_cells;
        shape.parallel_cells = side * side;
    }
    std::string solver_name = o.solver, solver_why = "--solver " + o.solver;
    MemoryEstimate memory;
    const auto plan_memory = [&](const mesh::Counts& counts) {
        shape.counts = counts;
        // Direct light only is a matrix of the emitters' rows; previews show the progressive
        // solution pass by pass, which a matrix solve does not have.
        if (solver_name == "auto") {
            if (overrides.interreflection == scene::Force::off) {
                solver_name = "matrix";
                solver_why = "--effects interreflection=off: direct light only is the emitters' rows";
            } else if (o.preview_every > 0) {
                solver_name = "progressive";
                solver_why = "--preview-every shows the progressive solver's passes";
            } else {
                const SolverChoice c = choose_solver(shape, memory_limit.bytes);
                solver_name = c.solver;
                solver_why = c.why;
            }
        }
        memory = estimate_memory(shape, solver_name);
        if (memory.needed() <= memory_limit.bytes) {
            if (!memory_limit.available || memory.needed() <= *memory_limit.available) return;
            throw InputError(fmt::format("{}: the bake would need about {} ({}), more than the {} available on this "
                                         "machine now (of {} it has); free some, or give --max-memory to bake anyway",
                                         o.scene, format_bytes(memory.needed()), memory.describe(),
                                         format_bytes(*memory_limit.available), format_bytes(memory_limit.bytes)));
        }
        std::string hint = fmt::format("a larger --patch-size or --element-size (now {:.4g} and {:.4g}) needs less",
                                       mesh_settings.patch_size, mesh_settings.element_size);
        if (solver_name == "matrix") {
            const double progressive = estimate_memory(shape, "progressive").needed();
            if (progressive <= memory_limit.bytes)
                hint = fmt::format("--solver progressive would need about {}", format_bytes(progressive));
        }
        throw InputError(fmt::format("{}: the bake would need about {} for {:.4g} patches and {:.4g} elements ({}), "
                                     "more than the {} {}; {}",
                                     o.scene, format_bytes(memory.needed()), counts.patches, counts.elements,
                                     memory.describe(), format_bytes(memory_limit.bytes), memory_limit.source, hint));
    };

    t0 = Clock::now();
    mesh::Mesh mesh = mesh::build(scene, mesh_settings, plan_memory);
    const double t_mesh = seconds_since(t0);
    if (mesh.patches.empty())
        throw InputError(fmt::format("{}: every triangle has zero area; nothing to bake", o.scene));
    if (mesh.dropped_triangles > 0)
        scene.warnings.push_back(fmt::format("{}: {} of {} triangles have no area (under 1e-12 of their longest edge "
                                             "squared) and were dropped; report.json counts them",
                                             o.scene, mesh.dropped_triangles, scene.triangles.size()));

    check_lamps_seen(scene, mesh);

    const bool checkpoints = !o.checkpoint.empty() || !o.resume.empty();
    if (o.preview_every > 0 && solver_name == "matrix")
        throw InputError("--preview-every shows the passes of the progressive solver; the matrix solver has none");

    formfactor::Settings ff_settings;
    ff_settings.hemicube = o.hemicube;
    ff_settings.seed = o.seed;
    // With nothing to hide anything, exact unoccluded form factors replace the hemicube.
    EngineChoice choice;
    if (plan.occlusion.on) {
        choice = choose_engine(o.device, o.verify, o.verify_every, mesh, ff_settings);
    } else {
        choice.backend = "analytic";
        choice.platform = "host";
        choice.name = "exact unoccluded form factors (Lambert, point to polygon)";
        choice.id = "analytic";
    }
    // A form-factor engine of the chosen kind for a mesh: the hemicube ones get the near-field correction.
    // A refined mesh's engine raises the hemicube's resolution with the level, so that children
    // cover as many cells as their parents did.
    const auto make_engine = [&](const mesh::Mesh& m, int level) -> std::unique_ptr<formfactor::Engine> {
        if (!plan.occlusion.on) return observed(std::make_unique<formfactor::UnoccludedEngine>(m), o.on_shot);
        formfactor::Settings s = ff_settings;
        s.hemicube = solve::regather_hemicube(ff_settings.hemicube, level);
        return observed(std::make_unique<formfactor::NearFieldEngine>(m, engine_like(choice, m, s)), o.on_shot);
    };

    // A checkpoint resumes only the bake it was made by: the same mesh and the settings that
    // decide its numbers (not the device: every engine gives the reference's bits). The matrix
    // solver's holds its rows, which depend on neither the batch nor the threshold.
    // The lights are not in the mesh: their placement and intensity go into the fingerprint too.
    std::string lights;
    for (const scene::PunctualLight& l : scene.lights)
        lights += fmt::format("; light {} at {:.17g},{:.17g},{:.17g} along {:.17g},{:.17g},{:.17g} of {:.17g},{:.17g},{:.17g} "
                              "cones {:.17g},{:.17g} range {:.17g}",
                              static_cast<int>(l.type), l.position.x, l.position.y, l.position.z, l.direction.x,
                              l.direction.y, l.direction.z, l.intensity.x, l.intensity.y, l.intensity.z, l.inner_cone,
                              l.outer_cone, l.range);
    const std::string form_factors = fmt::format("{} form factors, N {}, seed {}{}", plan.occlusion.on ? "hemicube" : "exact",
                                                 o.hemicube, o.seed, lights);
    const std::string fingerprint =
        !checkpoints ? std::string()
        : solver_name == "matrix"
            ? bake_fingerprint(mesh, fmt::format("{}, matrix rows of {}", form_factors,
                                                 direct_only ? "the emitters" : "every patch that holds light"))
            : bake_fingerprint(mesh, fmt::format("{}, batch {}, threshold {:.17g}", form_factors, o.batch,
                                                 plan.convergence.on ? o.threshold : kUnconvergedThreshold));
    const std::string resume_state = o.resume.empty() ? std::string() : read_checkpoint(o.resume, fingerprint);

    OutputTransaction out(o.output);
    // Only now, so that bad input is always exactly one line on stderr.
    for (const auto& w : scene.warnings) std::cerr << "hemirad: warning: " << printable(w) << "\n";
    std::vector<std::string> warnings = scene.warnings;  // for report.json
    if (!choice.warning.empty()) {
        std::cerr << "hemirad: warning: " << choice.warning << "\n";
        warnings.push_back(choice.warning);
    }
    // Work that would take minutes is said before it starts (by the model of 2 CPU cores).
    const TimeEstimate expected = [&] {
        const double refined = shape.counts.elements * (shape.refine_levels > 0 ? 2.0 : 1.0);
        const bool gathered = o.gather > 0 && (options.gather >= 0 || refined <= kMaxPlannedGather);
        return expected_bake_time(shape, solver_name, double(mesh.lights.size()), gathered ? refined : 0.0, o.gather);
    }();
    if (expected.total() > kSayTimeAbove) {
        const std::string warning = fmt::format(
            "this bake is expected to take about {} ({}; modelled on 2 CPU cores through PoCL, a GPU is faster); "
            "--progress shows how far it is, and Ctrl-C stops it leaving nothing behind",
            format_duration(expected.total()), expected.describe());
        if (!o.quiet) std::cerr << "hemirad: warning: " << warning << "\n";
        warnings.push_back(warning);
    }
    const double threshold = plan.convergence.on ? o.threshold : kUnconvergedThreshold;
    const std::size_t elements_before = mesh.elements.size();
    // Should the automatically chosen device fail part-way, the bake starts again on the
    // reference engine from the mesh as built (refinement replaces it).
    const mesh::Mesh built = choice.automatic ? mesh : mesh::Mesh{};
    ordered_json fallback;  // that device and why it failed, when it did
    Solution solution;
    std::vector<solve::RefineLevel> levels;
    double t_formfactors = 0.0, t_solve = 0.0, t_refine = 0.0, t_gather = 0.0;
    output::VertexLight gathered;  // the final gather's light at the output vertices
    long gather_points = 0;
    std::size_t contact_split = 0;  // elements split along contact lines for the final gather
    std::size_t gather_split = 0;   // elements split where the gathered light changes fast
    std::optional<formfactor::VerifySummary> verified;  // what --verify compared
    formfactor::RowCacheEngine* row_cache = nullptr;      // the progressive solve's, while it runs
    std::optional<formfactor::RowCacheStats> row_cache_stats;

    // The solve, then adaptive refinement, on the engines `choice` makes.
    const auto solve_and_refine = [&] {
        if (!o.quiet)
            std::cerr << fmt::format("hemirad: form factors on {} ({}){}, {} solver\n", choice.id, choice.name,
                                     EngineChoice::remote_ranks() > 0
                                         ? fmt::format(" and {} more MPI ranks", EngineChoice::remote_ranks())
                                         : std::string(),
                                     solver_name);
        std::unique_ptr<formfactor::Engine> base_engine =
            plan.occlusion.on
                ? observed(std::make_unique<formfactor::NearFieldEngine>(mesh, std::move(choice.engine)), o.on_shot)
                : make_engine(mesh, 0);
        // Progressive shooting asks for a patch's row again each time it shoots: keep them.
        if (solver_name == "progressive") {
            auto cached = std::make_unique<formfactor::RowCacheEngine>(std::move(base_engine), row_cache_bytes(shape));
            row_cache = cached.get();
            base_engine = std::move(cached);
        }
        formfactor::TimedEngine engine(*base_engine);

        t0 = Clock::now();
        levels.clear();
        ProgressLine progress(o.progress, o.progress_tty);
        // The punctual lights shoot first: the solvers start from their direct light.
        std::vector<glm::dvec3> direct;
        if (solve::has_direct_light(mesh, scene.lights))
            direct = solve::direct_light(mesh, scene.lights, engine, 0, nullptr,
                                         [&](std::size_t done, std::size_t total) { progress.lights(done, total); });
        const SolveContext context{o, threshold, matrix_settings, fingerprint, resume_state, progress,
                                   [&](const solve::Progressive& solver) {
                                       write_png_preview(scene, mesh, solver, view, width, height,
                                                         out.preview_path(solver.passes()));
                                   },
                                   direct.empty() ? nullptr : &direct};
        solution = solver_name == "matrix" ? solve_with_matrix(mesh, engine, context)
                                           : solve_progressively(mesh, engine, context);
        progress.finish();
        if (!solution.converged && !o.quiet) {
            if (solver_name == "matrix")
                std::cerr << fmt::format("hemirad: warning: Gauss-Seidel stopped after {} sweeps with an error bound of {:.3g}\n",
                                         solution.iterations, solution.error);
            else
                std::cerr << fmt::format("hemirad: warning: stopped at --max-passes {} before the threshold {} was reached (error {:.3g})\n",
                                         max_passes_for(o, mesh.patches.size()), threshold, solution.error);
        }

        t_formfactors = engine.seconds();
        if (choice.verifier) verified = choice.verifier->summary();  // the engine ends with this call
        if (row_cache) row_cache_stats = row_cache->stats();
        row_cache = nullptr;  // ends with the engine
        t_solve = seconds_since(t0) - engine.seconds();
        base_engine.reset();  // refinement makes engines of its own: the solve's buffers go first

        // Adaptive refinement: split where the irradiance contrasts, re-gather onto the children.
        t0 = Clock::now();
        if (plan.refinement.on && o.refine_levels > 0) {
            solve::RefineSettings rs;
            rs.contrast = o.contrast;
            rs.max_levels = o.refine_levels;
            rs.batch = std::max(o.batch, 64);
            rs.max_elements = refinement_room(shape, solver_name, memory_limit.bytes);
            rs.cancelled = [] { return cancel::requested(); };
            const mesh::Texturing texturing(scene);
            rs.texturing = &texturing;
            rs.lights = &scene.lights;
            ProgressLine refining(o.progress, o.progress_tty);
            rs.progress = [&](int level, long shots, long total) { refining.refining(level, shots, total); };
            solve::RefineResult refined =
                solve::refine(std::move(mesh), std::move(solution.irradiance), solution.shot, make_engine, rs);
            refining.finish();
            cancel::check();
            if (refined.stopped_for_memory.level > 0) {
                const std::string warning = fmt::format(
                    "refinement stopped before level {}: splitting {} more elements would pass the {} {}",
                    refined.stopped_for_memory.level, refined.stopped_for_memory.split,
                    format_bytes(memory_limit.bytes), memory_limit.source);
                if (!o.quiet) std::cerr << "hemirad: warning: " << warning << "\n";
                warnings.push_back(warning);
            }
            mesh = std::move(refined.mesh);
            solution.irradiance = std::move(refined.irradiance);
            solution.radiosity = std::move(refined.radiosity);
            levels = std::move(refined.levels);
        }
        t_refine = seconds_since(t0);

        // Final gather: the light at every output vertex from the converged solution.
        t0 = Clock::now();
        gather_points = 0;
        contact_split = 0;
        gather_split = 0;
        if (o.gather > 0) {
            // Every vertex of the output but the sky dome's, through the patches' cells (gather_mesh).
            const auto gathered_node = [&](std::size_t n) { return !scene.nodes[n].synthetic; };
            output::WeldedMesh welded = output::weld(scene.nodes.size(), mesh, solution.radiosity);
            const auto gathered_vertices = [&](const output::WeldedMesh& w) {
                std::size_t vertices = 0;
                for (std::size_t n = 0; n < w.nodes.size(); ++n)
                    if (gathered_node(n)) vertices += w.nodes[n].positions.size();
                return vertices;
            };
            // A hemicube per vertex: on real content many times the solve's shots, each costing about
            // as much (a 113k-vertex material ball at draft: the gather ran 15× the solve's time).
            // Beyond kMaxPlannedGather vertices the quality's gather is left out (a warning says
            // so); --gather N asks for it whatever the size. The count is the graded mesh's (below),
            // so a mesh is graded only to be gathered.
            const auto too_many = [&](std::size_t vertices, const char* graded) {
                if (options.gather >= 0 || vertices <= kMaxPlannedGather) return false;
                const std::string warning = fmt::format(
                    "final gather left out: {} vertices{} would each take a hemicube (more than {}); --gather {} "
                    "asks for it",
                    vertices, graded, kMaxPlannedGather, o.gather);
                if (!o.quiet) std::cerr << "hemirad: warning: " << warning << "\n";
                warnings.push_back(warning);
                t_gather = seconds_since(t0);
                return true;
            };
            if (too_many(gathered_vertices(welded), "")) return;
            // Elements along contact lines halved once, so that the gather's vertices follow the
            // light's fall there (mesh/contact.h): on copies, kept if the gather goes ahead.
            {
                const mesh::Texturing texturing(scene);
                mesh::Mesh graded = mesh;
                std::vector<glm::dvec3> radiosity = solution.radiosity, irradiance = solution.irradiance;
                const std::size_t split = solve::grade_contacts(graded, radiosity, irradiance,
                                                                kContactGrading * mesh_settings.element_size, &texturing);
                if (split > 0) {
                    output::WeldedMesh graded_welded = output::weld(scene.nodes.size(), graded, radiosity);
                    if (too_many(gathered_vertices(graded_welded), " (once graded along contact lines)")) return;
                    mesh = std::move(graded);
                    solution.radiosity = std::move(radiosity);
                    solution.irradiance = std::move(irradiance);
                    welded = std::move(graded_welded);
                    contact_split = split;
                }
            }
            std::vector<glm::dvec3> direct;  // punctual and directional lights' light, on the solved mesh
            if (solve::has_direct_light(mesh, scene.lights)) {
                std::unique_ptr<formfactor::Engine> lights_engine = make_engine(mesh, 0);
                direct = solve::direct_light(mesh, scene.lights, *lights_engine, o.refine_levels + 1);
            }
            mesh::Mesh drawn = solve::gather_mesh(mesh);
            drawn.gather_points = solve::gather_points(welded, gathered_node);
            formfactor::Settings s = ff_settings;
            s.hemicube = o.gather;
            std::unique_ptr<formfactor::Engine> gather_engine =
                plan.occlusion.on ? observed(engine_like(choice, drawn, s), o.on_shot)
                                  : observed(std::make_unique<formfactor::UnoccludedEngine>(drawn), o.on_shot);
            solve::GatherSettings gs;
            gs.batch = std::max(o.batch, 64);
            gs.passes = o.gather_passes;
            // The later passes re-use the first's rows, within the progressive solve's row-cache
            // budget (its cache is gone by now).
            gs.kept_entries = static_cast<std::size_t>(row_cache_bytes(shape) / (sizeof(std::uint32_t) + sizeof(double)));
            gs.cancelled = [] { return cancel::requested(); };
            ProgressLine gathering(o.progress, o.progress_tty);
            gs.progress = [&](long done, long total) { gathering.gathering(done, total); };
            // Direct light only (interreflection off): the gather sees the emitters' light alone, or
            // it would add the bounce the plan leaves out.
            std::vector<glm::dvec3> emitted;
            if (direct_only) {
                emitted.resize(mesh.elements.size());
                for (std::size_t k = 0; k < mesh.elements.size(); ++k) emitted[k] = mesh.elements[k].emission;
                gs.passes = 1;
            }
            const bool done = solve::final_gather(mesh, welded, gathered_node, direct_only ? emitted : solution.radiosity,
                                                  solution.irradiance, direct, drawn, *gather_engine, gs, gathered);
            if (!done) {
                gathering.finish();
                throw Interrupted();
            }
            gather_points = static_cast<long>(drawn.gather_points.size());
            // Where the gathered light changes faster than the vertices follow, the elements are
            // split and only their new vertices gathered, drawing the last pass's light.
            if (o.gather_refine > 0 && !direct_only) {
                const mesh::Texturing texturing(scene);
                solve::GatherRefinement r;
                r.levels = o.gather_refine;
                r.contrast = o.gather_contrast;
                r.noise_floor = kGatherNoiseFloor;
                r.min_size = kGatherMinSize * mesh_settings.element_size;
                // At most half as many vertices again as the gather's (the jungle at draft with --gather 32:
                // 82,724 vertices in 161 s, and four levels went on past 500 s), and the quality's
                // within kMaxPlannedGather.
                const std::size_t base = static_cast<std::size_t>(gather_points);
                r.max_vertices = base + base / 2;
                if (options.gather < 0) r.max_vertices = std::min(r.max_vertices, kMaxPlannedGather);
                r.texturing = &texturing;
                r.make_engine = [&](const mesh::Mesh& finer_drawn) {
                    return plan.occlusion.on ? observed(engine_like(choice, finer_drawn, s), o.on_shot)
                                             : observed(std::make_unique<formfactor::UnoccludedEngine>(finer_drawn), o.on_shot);
                };
                if (!direct.empty()) {
                    r.direct_light = [&](const mesh::Mesh& finer) {
                        std::unique_ptr<formfactor::Engine> lights_engine = make_engine(finer, 0);
                        return solve::direct_light(finer, scene.lights, *lights_engine, o.refine_levels + 1);
                    };
                }
                solve::GatheredMesh g{mesh, solution.radiosity, solution.irradiance, direct, welded, gathered};
                const solve::GatherRefined refined = solve::refine_gather(g, gathered_node, gs, r);
                if (refined.cancelled) {
                    gathering.finish();
                    throw Interrupted();
                }
                gather_points += refined.points;
                gather_split = refined.split;
                if (refined.capped) {
                    const std::string warning = fmt::format(
                        "gather refinement stopped at level {} of {}: more would gather at more than {} vertices "
                        "(half again the gather's {}, and {} at most unless --gather is given); that level split "
                        "only its elements of the highest contrast",
                        refined.levels, o.gather_refine, r.max_vertices, base, kMaxPlannedGather);
                    if (!o.quiet) std::cerr << "hemirad: warning: " << warning << "\n";
                    warnings.push_back(warning);
                }
            }
            gathering.finish();
        }
        t_gather = seconds_since(t0);
    };

    for (;;) {
        try {
            solve_and_refine();
            break;
        } catch (const std::exception& e) {
            const std::string why = device_failure(e);
            if (why.empty() || !choice.automatic) throw;
            // What was solved on the failed device is dropped, not mixed with the reference's:
            // the bake is then exactly a reference bake.
            fallback = {{"from", choice.id}, {"name", choice.name}, {"why", why}};
            const std::string warning =
                fmt::format("{} failed part-way: {}; starting again on the reference engine", choice.id, why);
            std::cerr << (o.progress && o.progress_tty ? "\n" : "") << "hemirad: warning: " << warning << "\n";
            warnings.push_back(warning);
            verified.reset();
            mesh = built;
            choice = choose_engine("ref", false, o.verify_every, mesh, ff_settings);
        }
    }
    if (choice.stats)
        for (const formfactor::ShardStats::Member& m : choice.stats->members)
            if (!m.dropped.empty()) {
                const std::string warning = fmt::format("{} failed and left the bake: {}; its shots were redone by the others",
                                                        m.id, m.dropped);
                if (!o.quiet) std::cerr << "hemirad: warning: " << warning << "\n";
                warnings.push_back(warning);
            }
    if (const EngineChoice::Shrinks& shrinks = *choice.shrinks; shrinks.count > 0) {
        const std::string warning = fmt::format(
            "{} ran out of memory {} times ({}): its batches were cut to as few as {} shots, with the same results",
            choice.id, shrinks.count, shrinks.why, shrinks.smallest);
        if (!o.quiet) std::cerr << "hemirad: warning: " << warning << "\n";
        warnings.push_back(warning);
    }

    t0 = Clock::now();
    const auto& radiosity = solution.radiosity;
    const auto& irradiance = solution.irradiance;
    if (!output::all_finite(radiosity) || !output::all_finite(irradiance))
        throw InternalError("the solution has a non-finite value; nothing written");
    const output::VertexLight* vertex_light = gather_points > 0 ? &gathered : nullptr;
    const output::Image image = output::render(scene, mesh, radiosity, view, width, height, vertex_light);
    if (!output::all_finite(image)) throw InternalError("the rendered image has a non-finite pixel; nothing written");
    output::write_exr(image, out.staged("render.exr"));
    const double exposure = std::isnan(o.exposure) ? output::auto_exposure(image) : std::exp2(o.exposure);
    output::write_png(image, out.staged("render.png"), exposure);
    // The user's scene with the light baked in; or (--output-mode radiosity, and scenes not read
    // from a file) the element mesh alone.
    if (o.output_mode == "scene" && scene.source) {
        for (const std::string& w : output::write_scene_gltf(out.staged("baked.gltf"), o.output, scene, mesh, radiosity,
                                                             irradiance, exposure, vertex_light)) {
            const std::string warning = "baked.gltf: " + w;
            if (!o.quiet) std::cerr << "hemirad: warning: " << warning << "\n";
            warnings.push_back(warning);
        }
    } else {
        output::write_baked_gltf(out.staged("baked.gltf"), scene, mesh, radiosity, vertex_light);
    }
    const double t_output_files = seconds_since(t0);

    const solve::Energy& energy = solution.energy;
    ordered_json report;
    report["version"] = HEMIRAD_VERSION;
    report["scene"] = o.scene;
    report["device"] = {{"backend", choice.backend}, {"platform", choice.platform}, {"name", choice.name}, {"id", choice.id}};
    if (!fallback.is_null()) report["device"]["fallback"] = fallback;
    if (choice.stats && choice.stats->members.size() > 1) {
        ordered_json members = ordered_json::array();
        for (const formfactor::ShardStats::Member& m : choice.stats->members) {
            ordered_json member = {{"id", m.id}, {"shots", m.shots}, {"chunks", m.chunks}, {"seconds", m.seconds}};
            if (!m.dropped.empty()) member["dropped"] = m.dropped;
            members.push_back(member);
        }
        report["device"]["members"] = members;
    }
    report["device"]["ranks"] = dist::size();
    report["settings"] = {
        {"quality", o.quality},
        {"hemicube", o.hemicube},
        {"patch_size", mesh_settings.patch_size},
        {"element_size", mesh_settings.element_size},
        {"threshold", threshold},
        {"max_passes", max_passes_for(o, mesh.patches.size())},
        {"batch", o.batch},
        {"gather", o.gather},
        {"gather_passes", o.gather_passes},
        {"gather_refine", o.gather_refine},
        {"gather_contrast", o.gather_contrast},
        {"seed", o.seed},
        {"device", o.device},
        {"verify", o.verify},
        {"verify_every", o.verify_every},
        {"solver", solver_name},
        {"effects", o.effects},
        {"refine_levels", o.refine_levels},
        {"contrast", o.contrast},
        {"camera", view.name},
        {"exposure", exposure},
        {"output_mode", o.output_mode},
        {"image", {width, height}},
        {"preview_every", o.preview_every},
        {"checkpoint", o.checkpoint},
        {"checkpoint_every", o.checkpoint_every},
        {"resume", o.resume},
    };
    report["counts"] = {{"triangles", scene.triangles.size()},
                        {"patches", mesh.patches.size()},
                        {"elements", mesh.elements.size()},
                        {"elements_before_refinement", elements_before},
                        {"gather_points", gather_points},
                        {"contact_split", contact_split},
                        {"gather_split", gather_split},
                        {"quads", mesh.quads},
                        {"clusters", mesh.clusters},
                        {"split_clusters", mesh.split_clusters},
                        {"moved_clusters", mesh.moved_clusters},
                        {"texture_splits", mesh.texture_splits},
                        {"mask_holes", mesh.holes},
                        {"dropped_triangles", mesh.dropped_triangles},
                        {"skipped_primitives", scene.skipped_primitives}};
    report["plan"] = {{"solver", {{"name", solver_name}, {"why", solver_why}}},
                      {"memory", {{"limit", memory_limit.bytes},
                                  {"limit_from", memory_limit.source},
                                  {"estimate", memory.total()},
                                  {"needed", memory.needed()},
                                  {"parts", [&] {
                                       ordered_json parts = ordered_json::object();
                                       for (const MemoryPart& p : memory.parts) parts[p.what] = p.bytes;
                                       return parts;
                                   }()}}}};
    if (memory_limit.available) report["plan"]["memory"]["available"] = *memory_limit.available;  // without --max-memory
    // Measured: the most this process held so far (resident), the outputs not yet written.
    report["plan"]["memory"]["peak"] = peak_memory();
    report["plan"]["expected_seconds"] = ordered_json::object();
    for (const auto& [what, seconds] : expected.parts) report["plan"]["expected_seconds"][what] = seconds;
    report["passes"] = solution.passes;
    if (solution.resumed_from >= 0) report["resumed_from_pass"] = solution.resumed_from;
    report["converged"] = solution.converged;
    if (solution.converged) report["converged_by"] = solution.convergence_rule;
    report["error"] = solution.error;
    if (solver_name == "matrix") report["iterations"] = solution.iterations;
    if (row_cache_stats) {
        const formfactor::RowCacheStats& r = *row_cache_stats;
        report["row_cache"] = {{"requests", r.requests},
                               {"reused", r.hits},
                               {"shot", r.shot},
                               {"kept", r.kept},
                               {"dropped", r.dropped},
                               {"peak_bytes", r.peak_bytes},
                               {"budget_bytes", r.budget_bytes}};
    }
    report["energy"] = {{"emitted", energy.emitted},
                        {"absorbed", energy.absorbed},
                        {"escaped", energy.escaped},
                        {"unshot", energy.unshot},
                        {"unshot_fraction", solution.unshot_fraction},
                        {"ambient_irradiance", vec3(solution.ambient)}};
    std::string refine_why = plan.refinement.why;
    if (plan.refinement.on && o.refine_levels == 0) {
        refine_why = "turned off by --refine-levels 0";
    } else if (plan.refinement.on) {
        std::size_t split = 0;
        for (const auto& l : levels) split += l.split;
        refine_why += levels.empty()
                          ? fmt::format("; no neighbours' irradiance differed by more than {:g}: nothing split", o.contrast)
                          : fmt::format("; {} elements split over {} levels ({} → {} elements)", split, levels.size(),
                                        elements_before, mesh.elements.size());
    }
    const bool hemicube = plan.occlusion.on;
    report["effects"] = {
        {"occlusion", effect_json(plan.occlusion)},
        {"colour", effect_json(plan.colour)},
        {"interreflection", effect_json(plan.interreflection)},
        {"two_sided", effect_json(plan.two_sided)},
        {"see_through", effect_json(plan.see_through)},
        {"refinement", effect_json({plan.refinement.on && !levels.empty(), plan.refinement.forced, refine_why})},
        {"convergence", effect_json({plan.convergence.on, plan.convergence.forced,
                                     plan.convergence.why + fmt::format(" (solver {}, threshold {:g})", solver_name, threshold)})},
        {"near_field", {{"on", hemicube}, {"forced", false},
                        {"why", hemicube ? fmt::format("receivers within {} shooter radii get the exact form factor at their centroid, scaled by the visible share the hemicube measured", formfactor::NearFieldEngine::kDefaultReach)
                                         : std::string("the form factors are exact: nothing to correct")}}},
        {"ambient", {{"on", solver_name == "progressive"}, {"forced", false},
                     {"why", solver_name == "progressive" ? "the unshot flux is added as an ambient term (Cohen et al. 1988) with the measured reflectance"
                                                          : "the matrix solve leaves no unshot light to stand in for"}}},
    };
    report["timings_s"] = ordered_json::object();  // keeps the contract's key order; filled last
    ordered_json meshes = ordered_json::array();
    const auto summaries = output::summarize(scene, mesh, radiosity, irradiance);
    for (std::size_t n = 0; n < summaries.size(); ++n) {
        if (scene.nodes[n].synthetic) continue;  // the sky dome: not one of the file's meshes
        const auto& s = summaries[n];
        meshes.push_back({{"name", s.name}, {"area", s.area}, {"radiosity", vec3(s.radiosity)}, {"irradiance", vec3(s.irradiance)}});
    }
    report["meshes"] = meshes;
    if (verified) {
        const formfactor::VerifySummary& v = *verified;
        report["verify"] = {{"shots_checked", v.shots_checked},
                            {"cells_compared", v.cells_compared},
                            {"cells_mismatched", v.cells_mismatched},
                            {"max_abs_error", v.max_abs_error},
                            {"max_rel_error", v.max_rel_error},
                            {"tolerance", {{"absolute", formfactor::VerifyingEngine::kAbsoluteTolerance},
                                           {"relative", formfactor::VerifyingEngine::kRelativeTolerance}}}};
    }
    report["warnings"] = warnings;
    report["timings_s"] = {{"load", t_load},
                           {"mesh", t_mesh},
                           {"formfactors", t_formfactors},
                           {"solve", t_solve},
                           {"refine", t_refine},
                           {"gather", t_gather},
                           {"output", t_output_files},
                           {"total", seconds_since(t_total)}};
    // NaN and Inf would be written as null: refuse the whole bake rather than a report that lies.
    if (const std::string where = output::first_non_finite(report); !where.empty())
        throw InternalError(fmt::format("report.json: {} is not finite; nothing written", where));
    {
        std::ofstream f(out.staged("report.json"));
        f << report.dump(2) << "\n";
        if (!f) throw InternalError("cannot write report.json");
    }
    cancel::check();  // a signal while writing: nothing is committed
    out.commit(kOutputNames);
    if (!o.quiet)
        std::cerr << fmt::format("hemirad: {}, {} elements, wrote {}/report.json, baked.gltf, render.exr, render.png\n",
                                 solver_name == "matrix"
                                     ? fmt::format("{} form-factor rows, {} sweeps, error bound {:.2e}", solution.passes,
                                                   solution.iterations, solution.error)
                                     : fmt::format("{} passes, error {:.2e}", solution.passes, solution.error),
                                 mesh.elements.size(), o.output);
}

}  // namespace hemirad::cli
