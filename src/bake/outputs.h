// A bake's files: what it may not write over (the user's files, the scene's inputs), the staging
// folder its outputs are written into until all of them exist, and the outputs themselves.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include <fmt/core.h>

#include "bake/options.h"
#include "core/cancel.h"
#include "core/durable.h"
#include "core/error.h"
#include "mesh/mesh.h"
#include "output/output.h"
#include "scene/scene.h"

namespace hemirad::solve {
class Progressive;
}

namespace hemirad::bake {
namespace fs = std::filesystem;

// A bake stages its files in DIR/.hemirad-tmp-<pid> until all of them exist.
inline constexpr char kStagingPrefix[] = ".hemirad-tmp-";
// What a bake writes into DIR, in the order they are moved into place (report.json last).
inline const std::vector<std::string> kOutputNames = {"baked.gltf", "baked.bin", "render.exr", "render.png",
                                                      "report.json"};

// Before any work: whatever is in the way of the outputs is the user's and stays. A directory
// (or a FIFO, a device) named like an output would stop the bake only when it is moved into
// place, at the end; a file named preview, only at the first preview frame.
void check_output_names(const Options& o);

// Before any work: no output may replace the scene or a file it reads (`inputs`: the scene, then
// its buffers and images), compared as files, not as names: the same directory entry (a link
// named like an output is the user's too) or the same file through a link. Re-baking
// out/baked.gltf into out/, or a scene with a texture named render.png into its own folder,
// would otherwise replace the input with the bake's output.
void check_inputs_kept(const Options& o, const std::vector<fs::path>& inputs);

// Staging directories left by bakes that were killed (SIGKILL, power loss): those whose process
// no longer exists. A live process's, another user's or a reused pid's are left alone.
void remove_stale_staging(const fs::path& dir);

// Where a preview frame is written before it is renamed into place.
inline fs::path preview_staging(const fs::path& file) { return file.parent_path() / (".tmp-" + file.filename().string()); }

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

    // Previews are visible while the bake runs (so a user can watch), each written atomically,
    // inside critical(): a stop's watchdog either waits for the frame and removes it, or has
    // removed everything already and the frame is not written (its folder not made again).
    void write_preview(long pass, const output::Image& image) {
        cleanup_.critical([&] {
            cancel::check();
            const fs::path dir = dir_ / "preview";
            std::error_code ec;
            if (!fs::exists(dir, ec) && fs::create_directories(dir, ec)) cleanup_.remove_if_empty(dir);
            const fs::path file = dir / fmt::format("pass_{:06d}.png", pass);
            cleanup_.remove_file(file);
            cleanup_.remove_file(preview_staging(file));
            output::write_png(image, preview_staging(file), output::auto_exposure(image));
            fs::rename(preview_staging(file), file);
        });
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

// A preview frame of the progressive solve so far, written into `out`'s preview folder.
void write_png_preview(const scene::Scene& scene, const mesh::Mesh& mesh, const solve::Progressive& solver,
                       const output::View& view, int width, int height, OutputTransaction& out);

}  // namespace hemirad::bake
