// A bake's files (see outputs.h).
#include "bake/outputs.h"

#include <signal.h>

#include <cerrno>

#include "solve/progressive.h"

namespace hemirad::bake {

void check_output_names(const Options& o) {
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

void check_inputs_kept(const Options& o, const std::vector<fs::path>& inputs) {
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

void write_png_preview(const scene::Scene& scene, const mesh::Mesh& mesh, const solve::Progressive& solver,
                       const output::View& view, int width, int height, OutputTransaction& out) {
    out.write_preview(solver.passes(),
                      output::render(scene, mesh, solver.radiosity(/*ambient=*/true), view, width, height));
}

}  // namespace hemirad::bake
