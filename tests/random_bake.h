// A random bake, shared by the seeded random-scene test and the bake fuzzer: a scene from the
// random-scene generator, small bake settings drawn from the same choices, and the invariants
// every bake must keep, each check returning what it found wrong in words.
#pragma once

#include <tiny_gltf.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "bake/bake.h"
#include "core/error.h"
#include "formfactor/engine.h"
#include "gen/random_scene.h"
#include "scene/scene.h"

namespace hemirad::test {

// A fresh directory of its own under the system's temporary directory, removed with everything
// in it at the end.
class ScratchDir {
public:
    explicit ScratchDir(const std::string& stem) {
        static int counter = 0;
        path_ = std::filesystem::temp_directory_path() /
                fmt::format("{}-{}-{}", stem, static_cast<long>(getpid()), counter++);
        std::filesystem::remove_all(path_);
        std::filesystem::create_directories(path_);
    }
    ScratchDir(const ScratchDir&) = delete;
    ScratchDir& operator=(const ScratchDir&) = delete;
    ~ScratchDir() {
        std::error_code ec;
        std::filesystem::remove_all(path_, ec);
    }
    const std::filesystem::path& path() const { return path_; }

private:
    std::filesystem::path path_;
};

struct RandomBake {
    gen::RandomSceneInfo scene;
    bake::Options options;
    std::string settings;  // one line, for messages
};

// How large a random bake may get: its scene, and its settings' sizes.
struct RandomBakeLimits {
    gen::RandomSceneLimits scene;
    int finest_patches = 10;   // patches down to the diagonal / this (from the diagonal / 4 up to 3 ×)
    int most_elements = 3;     // elements a patch side
    long most_passes = 300;    // --max-passes from 20 to this
};

// Writes the scene to dir/scene.gltf and draws small settings for it: hemicube N 16, 24 or 32,
// patches a 4th to a 10th of the scene's diagonal with 1 to 3 elements a side, threshold 1e-1
// to 1e-3, at most 20 to 300 passes, batch 1 to 4, either solver or auto, 0 to 2 refinement
// levels, an effects override sometimes, and a small image (`limits` may narrow the sizes). The
// output goes to dir/out on the reference engine (set options.device and options.output for
// another run).
inline RandomBake make_random_bake(gen::Choices& c, const std::filesystem::path& dir,
                                   const RandomBakeLimits& limits = {}) {
    RandomBake b;
    const std::filesystem::path file = dir / "scene.gltf";
    b.scene = gen::write_random_scene(c, file, limits.scene);
    bake::Options& o = b.options;
    o.scene = file.string();
    o.output = (dir / "out").string();
    o.device = "ref";
    o.quality = "draft";
    o.quiet = true;
    o.hemicube = 16 + 8 * int(c.below(3));
    // Sizes relative to the scene, as the presets take them; the diagonal is the loaded scene's.
    double diagonal = 0.0, rho = 0.0;
    try {
        const scene::Scene s = scene::load(file);
        diagonal = s.diagonal();
        for (const scene::Material& m : s.materials) rho = std::max({rho, m.base_color.x, m.base_color.y, m.base_color.z});
    } catch (const InputError&) {
        // The bake will refuse the file the same way; leave the sizes to it.
    }
    const int patch_fraction = c.between(std::min(4, limits.finest_patches), limits.finest_patches);
    const int elements = c.between(1, limits.most_elements);
    if (diagonal > 0.0 && std::isfinite(diagonal)) {
        o.patch_size = diagonal / patch_fraction;
        o.element_size = o.patch_size / elements;
    }
    o.threshold = c.log_uniform(1e-3, 1e-1);
    o.max_passes = c.between(20, int(std::max(20L, limits.most_passes)));
    o.batch = c.between(1, 4);
    static const char* const kSolvers[] = {"auto", "auto", "matrix", "progressive"};
    o.solver = kSolvers[c.below(4)];
    // Gauss–Seidel needs thousands of sweeps over all P² entries near ρ = 1, which --solver auto
    // avoids: a forced matrix solve would only make the run slow, not test more.
    if (o.solver == "matrix" && rho > 0.95) o.solver = "progressive";
    o.refine_levels = c.between(0, 2);
    o.contrast = c.uniform(0.1, 0.5);
    o.seed = 1 + c.below(1000);
    // interreflection=off with the progressive solver is refused (exit 2): a clean refusal.
    static const char* const kEffects[] = {"",          "",           "",
                                           "two_sided=on", "two_sided=off", "colour=on",
                                           "refinement=off", "interreflection=off"};
    o.effects = kEffects[c.below(8)];
    o.image_width = c.between(16, 96);
    b.settings = fmt::format("N {}, patch diagonal/{} ({} elements a side), threshold {:.3g}, max passes {}, "
                             "batch {}, solver {}, refine {} (contrast {:.2f}), seed {}, effects '{}', image {}",
                             o.hemicube, patch_fraction, elements, o.threshold, o.max_passes, o.batch, o.solver,
                             o.refine_levels, o.contrast, o.seed, o.effects, o.image_width);
    return b;
}

// What the settings make bad usage on purpose (a bake then refuses them with an InputError).
inline bool refused_by_design(const bake::Options& o) {
    return o.effects == "interreflection=off" && o.solver == "progressive";
}

// The invariants of every shot (engine.h): F finite and >= 0, blocked in [0, 1], and
// ΣF + blocked <= 1 + 1e-9 (the hemicube's cells tile the hemisphere once).
class ShotChecker {
public:
    void operator()(const formfactor::ShotResult& r) {
        ++shots_;
        double sum = 0.0;
        for (std::size_t i = 0; i < r.size(); ++i) {
            const double f = r.F[i];
            const std::uint32_t k = r.element[i];
            if (!std::isfinite(f) || f < 0.0) {
                note(fmt::format("shot {}: F[{}] = {}", shots_, k, f));
                return;
            }
            sum += f;
        }
        if (!std::isfinite(r.blocked) || r.blocked < 0.0 || r.blocked > 1.0 + 1e-9)
            note(fmt::format("shot {}: blocked = {}", shots_, r.blocked));
        worst_total_ = std::max(worst_total_, sum + r.blocked);
        if (!(sum + r.blocked <= 1.0 + 1e-9))
            note(fmt::format("shot {}: sum of F {:.17g} + blocked {:.17g} = 1 + {:.3g}", shots_, sum, r.blocked,
                             sum + r.blocked - 1.0));
    }
    long shots() const { return shots_; }
    double worst_total() const { return worst_total_; }
    const std::vector<std::string>& problems() const { return problems_; }

private:
    void note(std::string problem) {
        if (problems_.size() < 5) problems_.push_back(std::move(problem));
    }
    long shots_ = 0;
    double worst_total_ = 0.0;
    std::vector<std::string> problems_;
};

inline std::string read_file_text(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Every number of `j` finite (report.json writes none that is not, but null stands for NaN).
inline void find_non_finite(const nlohmann::json& j, const std::string& where, std::vector<std::string>& problems) {
    if (j.is_null()) problems.push_back(where + " is null (a NaN or Inf)");
    if (j.is_number() && !std::isfinite(j.get<double>())) problems.push_back(where + " is not finite");
    if (j.is_object())
        for (auto it = j.begin(); it != j.end(); ++it) find_non_finite(it.value(), where + "/" + it.key(), problems);
    if (j.is_array())
        for (std::size_t i = 0; i < j.size(); ++i) find_non_finite(j[i], where + "/" + std::to_string(i), problems);
}

// The invariants of a finished bake in `out`: the five files; report.json's numbers finite; the
// flux books balanced (emitted = absorbed + escaped + unshot to 1e-6 of emitted, each term
// finite, emitted > 0, absorbed and escaped >= 0); a converged progressive solve below its
// threshold; every mesh's radiosity and irradiance >= 0; baked.gltf loads (with hemirad's own
// loader too) and its COLOR_0 is finite and >= 0.
inline std::vector<std::string> check_bake_output(const std::filesystem::path& out) {
    namespace fs = std::filesystem;
    std::vector<std::string> problems;
    for (const char* name : {"report.json", "baked.gltf", "baked.bin", "render.exr", "render.png"})
        if (!fs::is_regular_file(out / name)) problems.push_back(fmt::format("{} is missing", name));
    if (!problems.empty()) return problems;

    const nlohmann::json report = nlohmann::json::parse(read_file_text(out / "report.json"));
    find_non_finite(report, "report.json", problems);
    if (!problems.empty()) return problems;
    const nlohmann::json& e = report.at("energy");
    const double emitted = e.at("emitted"), absorbed = e.at("absorbed"), escaped = e.at("escaped"),
                 unshot = e.at("unshot");
    if (!(emitted > 0.0)) problems.push_back(fmt::format("emitted flux {} is not positive", emitted));
    const double slack = 1e-9 * std::abs(emitted);
    if (absorbed < -slack || escaped < -slack)
        problems.push_back(fmt::format("absorbed {} or escaped {} is negative", absorbed, escaped));
    if (!(std::abs(absorbed + escaped + unshot - emitted) <= 1e-6 * std::abs(emitted)))
        problems.push_back(fmt::format("the books do not balance: emitted {:.17g}, absorbed {:.17g} + escaped {:.17g} "
                                       "+ unshot {:.17g} = {:.17g}",
                                       emitted, absorbed, escaped, unshot, absorbed + escaped + unshot));
    // A progressive solve converges only once its measure of what the unshot light can still
    // change is below the threshold. (Not the unshot share of the emitted flux itself: light a
    // patch will send to the sky, or the flux of a closed ρ = 0.999 room that a verified ambient
    // term already stands for, may stay unshot; test_solver checks each rule on known answers.)
    const nlohmann::json& settings = report.at("settings");
    const double threshold = settings.at("threshold");
    if (settings.at("solver") == "progressive" && report.at("converged").get<bool>() &&
        !(report.at("error").get<double>() <= threshold))
        problems.push_back(fmt::format("converged at error {}, above the threshold {}", report.at("error").dump(),
                                       threshold));
    for (const nlohmann::json& m : report.at("meshes"))
        for (const char* key : {"radiosity", "irradiance"})
            for (const nlohmann::json& v : m.at(key))
                if (v.get<double>() < 0.0) problems.push_back(fmt::format("mesh {}: {} {} < 0", m.at("name").dump(), key, v.dump()));

    // baked.gltf: a glTF any reader loads, COLOR_0 (float RGB) finite and >= 0.
    tinygltf::TinyGLTF gltf;
    tinygltf::Model model;
    std::string err, warn;
    if (!gltf.LoadASCIIFromFile(&model, &err, &warn, (out / "baked.gltf").string())) {
        problems.push_back("baked.gltf does not load: " + err);
        return problems;
    }
    for (const tinygltf::Mesh& mesh : model.meshes)
        for (const tinygltf::Primitive& prim : mesh.primitives) {
            const auto colour = prim.attributes.find("COLOR_0");
            if (colour == prim.attributes.end()) continue;
            const tinygltf::Accessor& a = model.accessors.at(std::size_t(colour->second));
            const tinygltf::BufferView& v = model.bufferViews.at(std::size_t(a.bufferView));
            const std::vector<unsigned char>& data = model.buffers.at(std::size_t(v.buffer)).data;
            const std::size_t stride = v.byteStride ? v.byteStride : 12, start = v.byteOffset + a.byteOffset;
            if (a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT || a.type != TINYGLTF_TYPE_VEC3 ||
                start + (a.count ? (a.count - 1) * stride + 12 : 0) > data.size()) {
                problems.push_back("baked.gltf: COLOR_0 is not float RGB inside its buffer");
                continue;
            }
            for (std::size_t i = 0; i < a.count; ++i) {
                float rgb[3];
                std::memcpy(rgb, data.data() + start + i * stride, sizeof rgb);
                for (const float x : rgb)
                    if (!std::isfinite(x) || x < 0.0f) {
                        problems.push_back(fmt::format("baked.gltf: COLOR_0 of vertex {} is {}", i, x));
                        return problems;
                    }
            }
        }
    try {
        (void)scene::load(out / "baked.gltf");
    } catch (const InputError& error) {
        problems.push_back(std::string("hemirad's loader refuses baked.gltf: ") + error.what());
    }
    return problems;
}

// Where two JSON values differ in a number by more than `relative` of the larger or `absolute`
// (or at all in anything else).
inline void find_differences(const nlohmann::json& a, const nlohmann::json& b, double relative, double absolute,
                             const std::string& where, std::vector<std::string>& out) {
    if (a.is_number() && b.is_number()) {
        const double x = a.get<double>(), y = b.get<double>();
        if (!(std::abs(x - y) <= std::max(relative * std::max(std::abs(x), std::abs(y)), absolute)))
            out.push_back(fmt::format("{}: {:.17g} against {:.17g}", where, x, y));
    } else if (a.is_object() && b.is_object() && a.size() == b.size()) {
        for (auto it = a.begin(); it != a.end(); ++it) {
            if (!b.contains(it.key()))
                out.push_back(where + "/" + it.key() + " is missing");
            else
                find_differences(it.value(), b.at(it.key()), relative, absolute, where + "/" + it.key(), out);
        }
    } else if (a.is_array() && b.is_array() && a.size() == b.size()) {
        for (std::size_t i = 0; i < a.size(); ++i)
            find_differences(a[i], b[i], relative, absolute, where + "/" + std::to_string(i), out);
    } else if (a != b) {
        out.push_back(fmt::format("{}: {} against {}", where, a.dump(), b.dump()));
    }
}

// Two bakes of one scene and settings on two engines. The project guarantees the same baked.bin,
// byte for byte; report.json's books and per-mesh averages are sums in double precision, which
// may differ in their last bits (the reference adds each shot's delta form factors in double
// precision, the OpenCL engine in 64-bit fixed point), so they are compared to 1e-9 (of the
// emitted flux for the books, whose escaped share may be rounding around 0).
inline std::vector<std::string> compare_bakes(const std::filesystem::path& a, const std::filesystem::path& b) {
    std::vector<std::string> problems;
    if (read_file_text(a / "baked.bin") != read_file_text(b / "baked.bin"))
        problems.push_back("baked.bin differs between the engines");
    const nlohmann::json ra = nlohmann::json::parse(read_file_text(a / "report.json"));
    const nlohmann::json rb = nlohmann::json::parse(read_file_text(b / "report.json"));
    const double emitted = std::abs(ra.at("energy").at("emitted").get<double>());
    for (const char* key : {"energy", "meshes", "passes", "converged", "counts"})
        find_differences(ra.at(key), rb.at(key), 1e-9, std::string(key) == "energy" ? 1e-9 * emitted : 0.0,
                         std::string("report.json/") + key, problems);
    if (problems.size() > 8) problems.resize(8);
    return problems;
}

}  // namespace hemirad::test
