// A stage's light as checkpoint bytes (see stage_checkpoint.h).
#include "bake/stage_checkpoint.h"

#include <csignal>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <stdexcept>
#include <system_error>
#include <type_traits>

#include <fmt/core.h>

#include "bake/budget.h"
#include "bake/gather.h"
#include "core/error.h"
#include "formfactor/opencl_engine.h"

namespace hemirad::bake {

namespace {

// Appends raw values; plain structs only, so that bytes read back are the values written.
class Writer {
public:
    template <class T>
    void put(const T& value) {
        static_assert(std::is_trivially_copyable_v<T>);
        bytes_.append(reinterpret_cast<const char*>(&value), sizeof value);
    }
    template <class T>
    void put(const std::vector<T>& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        put(static_cast<std::uint64_t>(v.size()));
        bytes_.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
    }
    void put(const std::string& s) {
        put(static_cast<std::uint64_t>(s.size()));
        bytes_ += s;
    }
    template <class T>
    void put_nested(const std::vector<std::vector<T>>& v) {
        put(static_cast<std::uint64_t>(v.size()));
        for (const std::vector<T>& inner : v) put(inner);
    }
    std::string take() { return std::move(bytes_); }

private:
    std::string bytes_;
};

class Reader {
public:
    explicit Reader(const std::string& bytes) : bytes_(bytes) {}
    template <class T>
    void get(T& value) {
        static_assert(std::is_trivially_copyable_v<T>);
        need(sizeof value);
        std::memcpy(&value, bytes_.data() + at_, sizeof value);
        at_ += sizeof value;
    }
    template <class T>
    void get(std::vector<T>& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        const std::uint64_t n = count(sizeof(T));
        v.resize(static_cast<std::size_t>(n));
        if (n > 0) std::memcpy(v.data(), bytes_.data() + at_, n * sizeof(T));
        at_ += n * sizeof(T);
    }
    void get(std::string& s) {
        const std::uint64_t n = count(1);
        s.assign(bytes_, at_, static_cast<std::size_t>(n));
        at_ += n;
    }
    template <class T>
    void get_nested(std::vector<std::vector<T>>& v) {
        v.resize(static_cast<std::size_t>(count(sizeof(std::uint64_t))));
        for (std::vector<T>& inner : v) get(inner);
    }
    bool done() const { return at_ == bytes_.size(); }

private:
    // A length, checked against the bytes left (items of `size` bytes each).
    std::uint64_t count(std::size_t size) {
        std::uint64_t n = 0;
        get(n);
        if (n > (bytes_.size() - at_) / size) throw std::runtime_error("it ends early");
        return n;
    }
    void need(std::size_t n) const {
        if (bytes_.size() - at_ < n) throw std::runtime_error("it ends early");
    }
    const std::string& bytes_;
    std::size_t at_ = 0;
};

// 2: the mesh holds joined_clusters.
constexpr std::uint32_t kLitFormat = 2;

template <class IO, class M>
void mesh_io(IO& io, M& mesh) {
    io.item(mesh.patches);
    io.item(mesh.lights);
    io.item(mesh.directions);
    io.item(mesh.gather_points);
    io.item(mesh.elements);
    io.item(mesh.dropped_triangles);
    io.item(mesh.quads);
    io.item(mesh.clusters);
    io.item(mesh.split_clusters);
    io.item(mesh.moved_clusters);
    io.item(mesh.joined_clusters);
    io.item(mesh.texture_splits);
    io.item(mesh.holes);
}

template <class IO, class L>
void solved_io(IO& io, L& lit) {
    auto& s = lit.solved.solution;
    io.item(s.radiosity);
    io.item(s.irradiance);
    io.item(s.ambient);
    io.item(s.shot);
    io.item(s.energy);
    io.item(s.passes);
    io.item(s.converged);
    io.item(s.error);
    io.item(s.unshot_fraction);
    io.item(s.iterations);
    io.item(s.convergence_rule);
    io.item(s.resumed_from);
    io.item(lit.solved.formfactor_seconds);
    io.item(lit.solved.solve_seconds);
    io.optional(lit.solved.verified);
    io.optional(lit.solved.row_cache);
    io.item(lit.levels);
    io.item(lit.refine_seconds);
    io.item(lit.gather_seconds);
    io.nested(lit.gathered.light.radiosity);
    io.nested(lit.gathered.light.irradiance);
    io.item(lit.gathered.points);
    io.item(lit.gathered.contact_split);
    io.item(lit.gathered.gather_split);
    io.item(lit.gathered.sparse_seeds);
    io.item(lit.gathered.sparse_levels);
    io.item(lit.gathered.sparse_covered);
    io.item(lit.gathered.sparse_vertices);
    io.item(lit.gathered.sparse_interpolated);
    io.item(lit.gathered.sparse_unreached);
    io.item(lit.gathered.sparse_capped);
    io.item(lit.gathered.sparse_budget);
}

template <class IO, class N>
void node_io(IO& io, N& n) {
    io.item(n.positions);
    io.item(n.normals);
    io.item(n.radiosity);
    io.item(n.indices);
    io.item(n.element);
    io.item(n.corner_start);
    io.item(n.corner_element);
    io.item(n.halfway);
}

struct Save {
    Writer w;
    template <class T>
    void item(const T& v) { w.put(v); }
    template <class T>
    void nested(const std::vector<std::vector<T>>& v) { w.put_nested(v); }
    template <class T>
    void optional(const std::optional<T>& v) {
        w.put(static_cast<std::uint8_t>(v.has_value()));
        if (v) w.put(*v);
    }
};

struct Load {
    Reader r;
    template <class T>
    void item(T& v) { r.get(v); }
    template <class T>
    void nested(std::vector<std::vector<T>>& v) { r.get_nested(v); }
    template <class T>
    void optional(std::optional<T>& v) {
        std::uint8_t has = 0;
        r.get(has);
        if (has > 1) throw std::runtime_error("it is damaged");
        v.reset();
        if (has) r.get(v.emplace());
    }
};

}  // namespace

std::string stage_settings(const Plan& plan, const Setup& setup, const Meshed& meshed, Stage stage) {
    const Options& o = plan.o;
    std::string s = fmt::format("solver {}, threshold {:.17g}, max passes {}, tolerance {:.17g}, sweeps {}", meshed.solver,
                                setup.threshold, max_passes_for(o, meshed.mesh.patches.size()), setup.matrix.tolerance,
                                setup.matrix.max_iterations);
    if (stage >= Stage::refined)
        s += fmt::format("; refinement {}, levels {}, contrast {:.17g}, batch {}, room {}", setup.effects.refinement.on,
                         o.refine_levels, o.contrast, o.batch,
                         refinement_room(meshed.shape, meshed.solver, plan.memory_limit.bytes));
    if (stage >= Stage::gathered)
        s += fmt::format("; gather {}{}, passes {}, refine {}, contrast {:.17g}, points {}", o.gather,
                         plan.gather_given ? " given" : "", o.gather_passes, o.gather_refine, o.gather_contrast,
                         gather_budget(plan));
    return s;
}

std::string save_lit(const Lit& lit, bool with_mesh, const std::string& settings, const std::vector<std::string>& warnings) {
    Save io;
    io.w.put(kLitFormat);
    io.w.put(settings);
    io.w.put(static_cast<std::uint64_t>(warnings.size()));
    for (const std::string& w : warnings) io.w.put(w);
    io.w.put(static_cast<std::uint8_t>(with_mesh));
    if (with_mesh) mesh_io(io, lit.mesh);
    solved_io(io, lit);
    io.w.put(static_cast<std::uint8_t>(lit.welded.has_value()));
    if (lit.welded) {
        io.w.put(static_cast<std::uint64_t>(lit.welded->nodes.size()));
        for (const output::WeldedNode& n : lit.welded->nodes) node_io(io, n);
    }
    return io.w.take();
}

StageState load_lit(const std::string& state, const std::string& settings) {
    Load io{Reader(state)};
    StageState out;
    std::uint32_t format = 0;
    io.r.get(format);
    if (format != kLitFormat) throw std::runtime_error(fmt::format("its stage format is {}, not {}", format, kLitFormat));
    std::string saved;
    io.r.get(saved);
    if (saved != settings)
        throw std::runtime_error(fmt::format("it was made with other settings ([{}], this bake [{}])", saved, settings));
    std::uint64_t warnings = 0;
    io.r.get(warnings);
    if (warnings > state.size()) throw std::runtime_error("it is damaged");
    out.warnings.resize(static_cast<std::size_t>(warnings));
    for (std::string& w : out.warnings) io.r.get(w);
    std::uint8_t with_mesh = 0, welded = 0;
    io.r.get(with_mesh);
    out.has_mesh = with_mesh != 0;
    if (out.has_mesh) mesh_io(io, out.lit.mesh);
    solved_io(io, out.lit);
    io.r.get(welded);
    if (welded) {
        std::uint64_t nodes = 0;
        io.r.get(nodes);
        if (nodes > state.size()) throw std::runtime_error("it is damaged");
        out.lit.welded.emplace().nodes.resize(static_cast<std::size_t>(nodes));
        for (output::WeldedNode& n : out.lit.welded->nodes) node_io(io, n);
    }
    if (!io.r.done()) throw std::runtime_error("it has bytes left over");
    return out;
}

bool StageCheckpoints::save(const std::function<void(const std::filesystem::path&)>& write, bool force) {
    if (file.empty()) return false;
    if (automatic && !force && seconds_since(last) < every_seconds) return false;
    try {
        write(file);
    } catch (const InputError& e) {
        if (!automatic) throw;
        if (warnings) warnings->add(fmt::format("the automatic checkpoint cannot be written, the bake goes on without: {}", e.what()));
        file.clear();
        return false;
    }
    last = Clock::now();
    return true;
}

namespace {

namespace fs = std::filesystem;

// When `file` was last written, in UTC ("2026-12-05 12:40 UTC"); empty where unknown.
std::string written_at(const fs::path& file) {
    std::error_code ec;
    const auto t = fs::last_write_time(file, ec);
    if (ec) return {};
    const auto system = std::chrono::time_point_cast<std::chrono::system_clock::duration>(
        t - fs::file_time_type::clock::now() + std::chrono::system_clock::now());
    const std::time_t seconds = std::chrono::system_clock::to_time_t(system);
    std::tm utc{};
    gmtime_r(&seconds, &utc);
    char text[32];
    return std::strftime(text, sizeof text, "%Y-%m-%d %H:%M:%S UTC", &utc) ? text : "";
}

// Takes a checkpoint's `state` into `cp` as what the bake resumes; std::runtime_error saying why
// it cannot be.
void take(StageCheckpoints& cp, const Plan& plan, const Setup& setup, const Meshed& meshed, const fs::path& file,
          const std::string& state) {
    const Stage stage = checkpoint_stage(state);
    if (stage == Stage::solving)
        cp.solver_state = state;
    else
        cp.light = load_lit(stage_state(state), stage_settings(plan, setup, meshed, stage));
    cp.resumed = stage;
    cp.resume_file = file;
    cp.written = written_at(file);
}

// What a stage's resumption skips, for the note.
std::string goes_on_with(Stage stage) {
    switch (stage) {
        case Stage::solving: return "the solve goes on from its last checkpoint";
        case Stage::solved: return "solved; refinement, the gather and the outputs follow";
        case Stage::refined: return "solved and refined; the gather and the outputs follow";
        case Stage::gathered: return "solved, refined and gathered; the outputs follow";
    }
    return {};
}

}  // namespace

StageCheckpoints read_resume(const Plan& plan, const Setup& setup, const Meshed& meshed, const std::string& fingerprint) {
    StageCheckpoints cp;
    cp.fingerprint = fingerprint;
    const Options& o = plan.o;
    if (o.resume.empty()) return cp;
    const std::string state = read_checkpoint(o.resume, fingerprint);
    try {
        take(cp, plan, setup, meshed, o.resume, state);
    } catch (const std::runtime_error& e) {
        throw InputError(fmt::format("{}: the checkpoint cannot be resumed: {}", o.resume, e.what()));
    }
    return cp;
}

void plan_checkpoints(StageCheckpoints& cp, const Plan& plan, const Setup& setup, const Meshed& meshed,
                      double expected_seconds, Warnings& warnings, Progress& progress) {
    const Options& o = plan.o;
    cp.warnings = &warnings;
    if (!o.checkpoint.empty()) {
        cp.file = o.checkpoint;
        cp.why = "--checkpoint";
    } else if (!o.no_checkpoint) {
        double above = kAutomaticCheckpointAbove;
        if (const char* text = std::getenv("HEMIRAD_CHECKPOINT_ABOVE"); text && *text) {
            char* end = nullptr;
            above = std::strtod(text, &end);
            if (*end != '\0' || !(above >= 0.0))
                throw InputError(fmt::format("HEMIRAD_CHECKPOINT_ABOVE={}: expected seconds (a number >= 0)", text));
        }
        const std::optional<fs::path> dir = expected_seconds > above ? checkpoint_directory() : std::nullopt;
        std::error_code ec;
        if (dir && (fs::create_directories(*dir, ec), fs::is_directory(*dir, ec))) {
            cp.file = automatic_checkpoint_file(*dir, cp.fingerprint);
            cp.automatic = true;
            cp.every_seconds = kAutomaticCheckpointEvery;
            cp.why = fmt::format("expected to take {}, more than {}", format_duration(expected_seconds),
                                 format_duration(above));
            prune_checkpoints(*dir, cp.file);
        } else if (dir) {
            warnings.add(fmt::format("no automatic checkpoint: cannot make the folder {}", dir->string()));
        }
    }
    if (!cp.automatic || !o.resume.empty() || !fs::exists(fs::symlink_status(cp.file))) return;
    // The same command run again: its own checkpoint, whatever stage it had reached.
    try {
        check_resume_source(cp.file);
        take(cp, plan, setup, meshed, cp.file, read_checkpoint(cp.file, cp.fingerprint));
    } catch (const std::exception& e) {
        warnings.add(fmt::format("ignored the automatic checkpoint {}: {}", cp.file.string(), e.what()));
        cp.resumed.reset();
        cp.resume_file.clear();
        cp.solver_state.clear();
        cp.light.reset();
        std::error_code ignored;
        fs::remove(cp.file, ignored);
        return;
    }
    progress.note(fmt::format("resuming from the checkpoint of {}, written {}: {}", cp.file.string(), cp.written,
                              goes_on_with(*cp.resumed)));
}

void save_stage(StageCheckpoints& cp, const Plan& plan, const Setup& setup, const Meshed& meshed, Stage stage,
                const Lit& lit, const std::vector<std::string>& warnings) {
    cp.save(
        [&](const fs::path& file) {
            write_stage_checkpoint(file, cp.fingerprint, stage,
                                   save_lit(lit, stage != Stage::solved, stage_settings(plan, setup, meshed, stage), warnings));
        },
        /*force=*/true);
}

void finish_checkpoints(const StageCheckpoints& cp, Progress& progress) {
    if (!cp.automatic || cp.file.empty()) return;
    std::error_code ec;
    if (fs::remove(cp.file, ec)) progress.note(fmt::format("removed the automatic checkpoint {}", cp.file.string()));
}

void fault_point(const char* stage) {
    if (formfactor::fault_from_environment().stage == stage) std::raise(SIGKILL);
}

}  // namespace hemirad::bake
