// `hemirad bench --accuracy`, the image part (see bench_image.h).
#include "bench/image.h"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>

#include <glm/glm.hpp>

#include "bake/bake.h"
#include "bench/support.h"
#include "core/error.h"
#include "image/image.h"

namespace hemirad::bench {
namespace fs = std::filesystem;
using ordered_json = nlohmann::ordered_json;

namespace {

constexpr int kTile = 16;

double luminance(double r, double g, double b) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }

glm::dvec3 vec3(const ordered_json& j) { return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()}; }

// An image of the reference's size, or an InternalError (the bench renders at the reference's width).
void check_same_size(const std::vector<float>& rgb, int width, int height, const ImageReference& ref) {
    if (width != ref.width || height != ref.height || rgb.size() != std::size_t(width) * height * 3)
        throw InternalError(fmt::format("bench --accuracy: a {}x{} image against a {}x{} reference", width, height,
                                        ref.width, ref.height));
}

struct Run {
    std::string label, sweep, quality;
    int hemicube = 0;
    double element_size = 0.0;
    int gather = -1;
    int gather_passes = 0;
    int gather_refine = -1;
    double gather_contrast = -1.0;
    long gather_points = -1;
};

}  // namespace

std::vector<float> read_rgb(const fs::path& file, int& width, int& height) {
    const image::FloatImage all = image::read_exr(file);
    const int r = all.channel("R"), g = all.channel("G"), b = all.channel("B");
    if (r < 0 || g < 0 || b < 0) throw InputError(fmt::format("{}: no R, G and B channels", file.string()));
    width = all.width;
    height = all.height;
    const std::size_t n = all.channels.size();
    std::vector<float> rgb(std::size_t(width) * height * 3);
    for (std::size_t p = 0; p < std::size_t(width) * height; ++p) {
        rgb[3 * p + 0] = all.values[p * n + std::size_t(r)];
        rgb[3 * p + 1] = all.values[p * n + std::size_t(g)];
        rgb[3 * p + 2] = all.values[p * n + std::size_t(b)];
    }
    return rgb;
}

ImageReference load_image_reference(const std::string& dir) {
    ImageReference r;
    const fs::path exr = fs::path(dir) / "reference.exr", json = fs::path(dir) / "reference.json";
    {
        std::ifstream in(json);
        if (!in) throw InputError(fmt::format("{}: not found (run bench --accuracy from the repository root)", json.string()));
        try {
            r.json = ordered_json::parse(in);
        } catch (const nlohmann::json::exception& e) {
            throw InputError(fmt::format("{}: not JSON: {}", json.string(), e.what()));
        }
        if (!r.json.contains("faces")) throw InputError(fmt::format("{}: not a path-traced reference", json.string()));
    }
    const image::FloatImage all = image::read_exr(exr);
    const std::vector<std::string> want = {"R", "G", "B", "noise.Y", "face"};
    if (all.channels.size() != want.size()) throw InputError(fmt::format("{}: not a path-traced reference", exr.string()));
    std::vector<int> index(want.size());
    for (std::size_t k = 0; k < want.size(); ++k) {
        index[k] = all.channel(want[k]);
        if (index[k] < 0) throw InputError(fmt::format("{}: no channel {}", exr.string(), want[k]));
    }
    r.width = all.width;
    r.height = all.height;
    const std::size_t channels = all.channels.size();
    const std::size_t n = std::size_t(r.width) * r.height;
    r.rgb.resize(3 * n);
    r.noise_y.resize(n);
    r.face.resize(n);
    for (std::size_t p = 0; p < n; ++p) {
        const float* px = &all.values[p * channels];
        for (int c = 0; c < 3; ++c) r.rgb[3 * p + c] = px[index[c]];
        r.noise_y[p] = px[index[3]];
        r.face[p] = int(std::lround(px[index[4]]));
    }
    return r;
}

PixelErrors compare_pixels(const std::vector<float>& rgb, int width, int height, const ImageReference& ref) {
    check_same_size(rgb, width, height, ref);
    const ordered_json& faces = ref.json.at("faces");
    std::vector<bool> emitter(faces.size());
    for (std::size_t f = 0; f < faces.size(); ++f) emitter[f] = faces[f].at("emitter").get<bool>();
    PixelErrors out;
    double e2 = 0.0, s2 = 0.0, sum = 0.0;
    const int tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
    std::vector<double> tile_sum(std::size_t(tiles_x) * tiles_y, 0.0);
    std::vector<long> tile_count(tile_sum.size(), 0);
    // Per tile, the luminance of the image and the reference, and the reference's variance, summed.
    std::vector<double> tile_image(tile_sum.size(), 0.0), tile_reference(tile_sum.size(), 0.0),
        tile_variance(tile_sum.size(), 0.0);
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            const std::size_t p = std::size_t(y) * width + x;
            const int f = ref.face[p];
            if (f < 0 || std::size_t(f) >= faces.size() || emitter[f]) continue;
            const double r = luminance(ref.rgb[3 * p], ref.rgb[3 * p + 1], ref.rgb[3 * p + 2]);
            if (!(r > 0.0)) continue;
            const double h = luminance(rgb[3 * p], rgb[3 * p + 1], rgb[3 * p + 2]);
            const double e = (h - r) / r, s = ref.noise_y[p] / r;
            e2 += e * e;
            s2 += s * s;
            sum += e;
            ++out.pixels;
            const std::size_t t = std::size_t(y / kTile) * tiles_x + x / kTile;
            tile_sum[t] += e;
            ++tile_count[t];
            tile_image[t] += h;
            tile_reference[t] += r;
            tile_variance[t] += double(ref.noise_y[p]) * ref.noise_y[p];
        }
    }
    if (out.pixels == 0) return out;
    const double n = double(out.pixels);
    out.raw_rms = std::sqrt(e2 / n);
    out.noise_rms = std::sqrt(s2 / n);
    out.rms = std::sqrt(std::max(0.0, e2 / n - s2 / n));
    out.mean = sum / n;
    for (std::size_t t = 0; t < tile_sum.size(); ++t) {
        if (tile_count[t] * 4 < kTile * kTile) continue;
        const double m = tile_sum[t] / double(tile_count[t]);
        if (std::abs(m) > std::abs(out.worst_tile)) {
            out.worst_tile = m;
            out.worst_tile_x = int(t % tiles_x) * kTile;
            out.worst_tile_y = int(t / tiles_x) * kTile;
        }
        const double light = tile_image[t] / tile_reference[t] - 1.0;
        if (std::abs(light) > std::abs(out.worst_tile_light)) {
            out.worst_tile_light = light;
            out.worst_tile_light_noise = std::sqrt(tile_variance[t]) / tile_reference[t];
            out.worst_tile_light_x = int(t % tiles_x) * kTile;
            out.worst_tile_light_y = int(t / tiles_x) * kTile;
        }
    }
    return out;
}

ordered_json compare_faces(const std::vector<float>& rgb, int width, int height, const ImageReference& ref,
                           long min_pixels) {
    check_same_size(rgb, width, height, ref);
    const ordered_json& faces = ref.json.at("faces");
    std::vector<double> want(faces.size(), 0.0), got(faces.size(), 0.0);
    std::vector<long> count(faces.size(), 0);
    for (std::size_t p = 0; p < std::size_t(width) * height; ++p) {
        const int f = ref.face[p];
        if (f < 0 || std::size_t(f) >= faces.size()) continue;
        want[f] += luminance(ref.rgb[3 * p], ref.rgb[3 * p + 1], ref.rgb[3 * p + 2]);
        got[f] += luminance(rgb[3 * p], rgb[3 * p + 1], rgb[3 * p + 2]);
        ++count[f];
    }
    ordered_json out = ordered_json::array();
    for (std::size_t f = 0; f < faces.size(); ++f) {
        if (count[f] < min_pixels || !(want[f] > 0.0)) continue;
        out.push_back({{"face", f},
                       {"node", faces[f].at("node")},
                       {"normal", faces[f].at("normal")},
                       {"emitter", faces[f].at("emitter")},
                       {"pixels", count[f]},
                       {"reference", want[f] / double(count[f])},
                       {"hemirad", got[f] / double(count[f])},
                       {"error", got[f] / want[f] - 1.0}});
    }
    return out;
}

ordered_json run_image_accuracy(const ImageAccuracyOptions& o, const ImageReference& ref, std::ostream& log) {
    {
        std::error_code ec;
        if (!fs::is_regular_file(o.scene, ec))
            throw InputError(fmt::format("{}: not found (run bench --accuracy from the repository root)", o.scene));
    }
    // The presets, then sweeps of one setting at a time from the default preset: the final gather's
    // resolution, passes and refinement (levels, contrast), the solve's hemicube resolution, the
    // element size.
    std::vector<Run> runs = {{"draft", "preset", "draft"}, {"default", "preset", "default"}};
    if (!o.quick) {
        runs.push_back({"high", "preset", "high"});
        for (const int g : {0, 32, 64, 128, 256})
            runs.push_back({fmt::format("default, gather {}", g), "gather", "default", 0, 0.0, g});
        for (const int p : {1, 2, 3})
            runs.push_back({fmt::format("default, gather passes {}", p), "gather passes", "default", 0, 0.0, -1, p});
        for (const int l : {0, 1, 2})
            runs.push_back(
                {fmt::format("default, gather refine {}", l), "gather refine", "default", 0, 0.0, -1, 0, l});
        for (const double c : {0.3, 0.2})
            runs.push_back({fmt::format("default, gather contrast {:g}", c), "gather contrast", "default", 0, 0.0, -1,
                            0, -1, c});
        // The sparse gather big scenes get (solve/sparse_gather.h), at a fifth and at two fifths of
        // the box's vertices.
        for (const long p : {2000L, 4000L})
            runs.push_back({fmt::format("default, gather points {}", p), "gather points", "default", 0, 0.0, -1, 0,
                            -1, -1.0, p});
        for (const int n : {64, 128, 512})
            runs.push_back({fmt::format("default, N {}", n), "hemicube", "default", n});
        for (const double e : {0.03, 0.015})
            runs.push_back({fmt::format("default, elements {:g}", e), "element size", "default", 0, e});
    }
    const TempDir temp("hemirad-bench-image");
    log << fmt::format("\nCornell box against the path-traced reference ({}: {}x{}, {} paths a pixel), --device {}\n",
                       o.reference_dir, ref.width, ref.height,
                       ref.json.at("settings").value("samples_per_pixel", 0), o.device);
    log << "| run | bake | elements | gather points | pixel RMSE | worst 16x16 tile, light | worst 16x16 tile, mean pixel "
           "error | worst block face | worst face |\n"
           "|---|---|---|---|---|---|---|---|---|\n";
    ordered_json out_runs = ordered_json::array();
    // A device's first bake builds its kernels: a draft bake first, untimed, so that no run pays for it.
    for (std::size_t k = o.device == "ref" ? 1 : 0; k <= runs.size(); ++k) {
        const bool warm_up = k == 0;
        const Run& r = warm_up ? runs.front() : runs[k - 1];
        bake::Options b;
        b.scene = o.scene;
        b.output = (temp.path() / fmt::format("bake-{}", k)).string();
        b.device = o.device;
        b.quality = r.quality;
        b.hemicube = r.hemicube;
        b.element_size = r.element_size;
        b.gather = r.gather;
        b.gather_passes = r.gather_passes;
        b.gather_refine = r.gather_refine;
        b.gather_contrast = r.gather_contrast;
        b.gather_points = r.gather_points;
        b.image_width = ref.width;
        b.quiet = true;
        bake::run(b);
        if (warm_up) {
            std::error_code ec;
            fs::remove_all(b.output, ec);
            continue;
        }
        const ordered_json report = read_report(fs::path(b.output) / "report.json");
        int w = 0, h = 0;
        const std::vector<float> rgb = read_rgb(fs::path(b.output) / "render.exr", w, h);
        const PixelErrors px = compare_pixels(rgb, w, h, ref);
        const ordered_json faces = compare_faces(rgb, w, h, ref);
        double worst_block = 0.0, worst_face = 0.0;
        std::string worst_block_name, worst_face_name;
        for (const ordered_json& f : faces) {
            if (f.at("emitter").get<bool>()) continue;
            const double e = f.at("error").get<double>();
            const std::string node = f.at("node").get<std::string>();
            const glm::dvec3 n = vec3(f.at("normal"));
            const std::string name = fmt::format("{} ({:+.2f},{:+.2f},{:+.2f})", node, n.x, n.y, n.z);
            if (std::abs(e) > std::abs(worst_face)) worst_face = e, worst_face_name = name;
            if (node.find("block") != std::string::npos && std::abs(e) > std::abs(worst_block))
                worst_block = e, worst_block_name = name;
        }
        const double seconds = report.at("timings_s").at("total").get<double>();
        const long elements = report.at("counts").at("elements").get<long>();
        const std::string solver = report.at("settings").value("solver", std::string());
        const ordered_json& settings = report.at("settings");
        const ordered_json& counts = report.at("counts");
        std::string gather =
            settings.at("gather").get<int>() > 0
                ? fmt::format("{} (N {} × {}, refined {} at {:g})", counts.at("gather_points").get<long>(),
                              settings.at("gather").get<int>(), settings.at("gather_passes").get<int>(),
                              settings.at("gather_refine").get<int>(), settings.at("gather_contrast").get<double>())
                : std::string("none");
        if (counts.contains("sparse_gather"))
            gather = fmt::format("{} of {} (sparse, N {} × 1)", counts.at("gather_points").get<long>(),
                                 counts.at("sparse_gather").at("vertices").get<long>(), settings.at("gather").get<int>());
        log << fmt::format(
            "| {} | {:.2f} s | {} | {} | {:.2f}% | {:+.1f}% ±{:.1f}% at ({}, {}) | {:+.1f}% at ({}, {}) | {:+.2f}% {} | "
            "{:+.2f}% {} |\n",
            r.label, seconds, elements, gather, 100.0 * px.rms, 100.0 * px.worst_tile_light,
            100.0 * px.worst_tile_light_noise, px.worst_tile_light_x, px.worst_tile_light_y, 100.0 * px.worst_tile,
            px.worst_tile_x, px.worst_tile_y, 100.0 * worst_block, worst_block_name, 100.0 * worst_face, worst_face_name);
        log.flush();
        out_runs.push_back({{"label", r.label},
                            {"sweep", r.sweep},
                            {"quality", r.quality},
                            {"options", {{"hemicube", report.at("settings").at("hemicube")},
                                         {"element_size", report.at("settings").at("element_size")},
                                         {"patch_size", report.at("settings").at("patch_size")},
                                         {"contrast", report.at("settings").at("contrast")},
                                         {"gather", report.at("settings").at("gather")},
                                         {"gather_passes", report.at("settings").at("gather_passes")},
                                         {"gather_refine", report.at("settings").at("gather_refine")},
                                         {"gather_contrast", report.at("settings").at("gather_contrast")},
                                         {"gather_points_allowed", report.at("settings").at("gather_points")}}},
                            {"gather_points", report.at("counts").at("gather_points")},
                            {"seconds", seconds},
                            {"timings_s", report.at("timings_s")},
                            {"elements", elements},
                            {"solver", solver},
                            {"pixels",
                             {{"rms", px.rms},
                              {"raw_rms", px.raw_rms},
                              {"reference_noise_rms", px.noise_rms},
                              {"mean", px.mean},
                              {"count", px.pixels},
                              {"worst_tile", {{"error", px.worst_tile}, {"x", px.worst_tile_x}, {"y", px.worst_tile_y}}},
                              {"worst_tile_light",
                               {{"error", px.worst_tile_light},
                                {"reference_noise", px.worst_tile_light_noise},
                                {"x", px.worst_tile_light_x},
                                {"y", px.worst_tile_light_y}}}}},
                            {"worst_block_face", {{"error", worst_block}, {"face", worst_block_name}}},
                            {"worst_face", {{"error", worst_face}, {"face", worst_face_name}}},
                            {"faces", faces}});
        std::error_code ec;
        fs::remove_all(b.output, ec);
    }
    return {{"scene", o.scene},
            {"reference", {{"dir", o.reference_dir},
                           {"image", {ref.width, ref.height}},
                           {"settings", ref.json.at("settings")},
                           {"generator", ref.json.value("generator", std::string())}}},
            {"runs", out_runs}};
}

}  // namespace hemirad::bench
