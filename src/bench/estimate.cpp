// `hemirad bench --estimate` (see estimate.h).
#include "bench/estimate.h"

#include <fmt/core.h>

#include <filesystem>
#include <optional>

#include "bake/bake.h"
#include "bench/support.h"
#include "core/error.h"
#include "gen/content_scenes.h"
#include "scene/writer.h"

namespace hemirad::bench {

namespace fs = std::filesystem;
using ordered_json = nlohmann::ordered_json;

std::vector<std::pair<std::string, std::string>> estimate_bench_scenes(bool quick) {
    if (quick) return {{"procedural:2k", "draft"}, {"city:4k", "draft"}};  // about 20 s
    // Small to large: a closed room of furniture, an open city, a courtyard of foliage cards.
    return {{"furniture:20k", "draft"}, {"city:60k", "draft"}, {"foliage:150k", "draft"}};
}

ordered_json run_estimate_bench(const EstimateBenchOptions& o, std::ostream& log) {
    std::vector<std::pair<std::string, std::string>> scenes;
    for (const std::string& s : o.scenes) scenes.emplace_back(s, o.quick ? "draft" : "default");
    if (scenes.empty()) scenes = estimate_bench_scenes(o.quick);
    const TempDir temp("hemirad-bench-estimate");
    // Every scene checked (and generated) before any bake runs.
    std::vector<fs::path> files;
    for (const auto& [spec, quality] : scenes) {
        (void)quality;
        std::optional<scene::Scene> generated = gen::generated_scene(spec);
        if (generated) {
            files.push_back(temp.path() / fmt::format("scene-{}.glb", files.size()));
            scene::write_gltf(*generated, files.back());
            continue;
        }
        std::error_code ec;
        if (!fs::is_regular_file(spec, ec))
            throw InputError(fmt::format("{}: neither a file nor a generated scene (procedural:, city:, furniture:, "
                                         "foliage:<triangles>)",
                                         spec));
        files.push_back(spec);
    }
    log << fmt::format("bench --estimate: {} bakes, --device {}\n\n", scenes.size(), o.device);
    log << "| scene | quality | triangles | stage | predicted s | re-fitted s | measured s |\n";
    log << "|---|---|---:|---|---:|---:|---:|\n";
    ordered_json bakes = ordered_json::array();
    ordered_json summary = ordered_json::array();
    for (std::size_t k = 0; k < scenes.size(); ++k) {
        bake::Options b;
        b.scene = files[k].string();
        b.output = (temp.path() / fmt::format("bake-{}", k)).string();
        b.device = o.device;
        b.quality = scenes[k].second;
        b.quiet = true;
        bake::run(b);
        const ordered_json report = read_report(fs::path(b.output) / "report.json");
        const ordered_json& e = report.at("estimate");
        const double measured = e.at("total_measured_s").get<double>();
        const double at10 = e.contains("at_10_percent") ? e["at_10_percent"]["ratio"].get<double>() : 0.0;
        const double at_end = measured > 0.0 ? e.at("total_predicted_s").get<double>() / measured : 0.0;
        for (const ordered_json& s : e.at("stages"))
            log << fmt::format("| {} | {} | {} | {} | {:.2f} | {:.2f} | {:.2f} |\n", scenes[k].first, scenes[k].second,
                               report["counts"]["triangles"].get<long>(), s["name"].get<std::string>(),
                               s["predicted_s"].get<double>(), s["refit_s"].get<double>(), s["measured_s"].get<double>());
        log << fmt::format("| {} | {} | | **total** | {:.2f} | | {:.2f} |\n", scenes[k].first, scenes[k].second,
                           e.at("total_predicted_s").get<double>(), measured);
        summary.push_back({scenes[k].first, scenes[k].second, measured, at10, at_end});
        bakes.push_back({{"scene", scenes[k].first},
                         {"quality", scenes[k].second},
                         {"triangles", report["counts"]["triangles"]},
                         {"elements", report["counts"]["elements"]},
                         {"solver", report["settings"]["solver"]},
                         {"estimate", e},
                         {"ratio_at_10_percent", at10},
                         {"ratio_at_end", at_end}});
    }
    // The ratios: the bake's total as predicted (elapsed + left) over the measured total, at 10%
    // of the bake (the progress line's), and the first prediction (before the solve).
    log << "\n| scene | quality | measured s | predicted/measured at 10% | first prediction/measured |\n";
    log << "|---|---|---:|---:|---:|\n";
    for (const ordered_json& s : summary)
        log << fmt::format("| {} | {} | {:.1f} | {:.2f} | {:.2f} |\n", s[0].get<std::string>(), s[1].get<std::string>(),
                           s[2].get<double>(), s[3].get<double>(), s[4].get<double>());
    return {{"version", HEMIRAD_VERSION}, {"device", o.device}, {"bakes", bakes}};
}

}  // namespace hemirad::bench
