// `hemirad bench --effects` (see bench_effects.h): each effect as planned against forced the
// other way, baked in-process, timed and compared mesh by mesh.
#include "bench/effects.h"
#include "bench/support.h"

#include <fmt/core.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <system_error>
#include <vector>

#include "bench/throughput.h"
#include "bake/bake.h"
#include "core/error.h"

namespace hemirad::bench {
namespace fs = std::filesystem;
using ordered_json = nlohmann::ordered_json;

namespace {

// Convergence forced off shoots until 1e-6 is left; the Cornell box takes a few thousand passes,
// so this only guards against a bake that never gets there.
constexpr long kManyPasses = 200000;

// One bake configuration; bakes shared by several cases run once.
struct BakeSpec {
    std::string scene;  // file name under scenes_dir
    std::string solver = "auto";
    std::string effects;
    long max_passes = 100000;

    std::string key() const { return fmt::format("{}|{}|{}|{}", scene, solver, effects, max_passes); }
};

struct CaseSpec {
    std::string name;    // the effect (or "solver")
    std::string effect;  // the report's effects key; empty for the solver case
    BakeSpec planned, forced;
    bool expect_planned_on = true;  // the decision the planner should make on this scene
    bool expect_saving = true;      // false where the planned bake does more work on purpose
};

struct BakeResult {
    std::vector<double> total, formfactors, refine, solve, gather;
    ordered_json report;  // of the first run (the rest differ only in their timings)
};

BakeSpec spec(const std::string& scene, const std::string& solver = "auto", const std::string& effects = "",
              long max_passes = 100000) {
    BakeSpec s;
    s.scene = scene;
    s.solver = solver;
    s.effects = effects;
    s.max_passes = max_passes;
    return s;
}

std::vector<CaseSpec> cases() {
    const std::string room = "empty_room.gltf", box = "cornell_box.gltf";
    std::vector<CaseSpec> c;
    c.push_back({"occlusion", "occlusion", spec(room), spec(room, "auto", "occlusion=on"), false, true});
    c.push_back({"colour", "colour", spec(room), spec(room, "auto", "colour=on"), false, true});
    c.push_back({"refinement", "refinement", spec(box), spec(box, "auto", "refinement=off"), true, false});
    c.push_back({"convergence", "convergence", spec(box, "progressive", "", kManyPasses),
                 spec(box, "progressive", "convergence=off", kManyPasses), true, true});
    c.push_back(
        {"interreflection", "interreflection", spec(box), spec(box, "auto", "interreflection=off"), true, false});
    c.push_back({"solver", "", spec(box), spec(box, "progressive"), true, true});
    return c;
}

std::string describe(const BakeSpec& s, const std::string& quality) {
    std::string out = fmt::format("{} --quality {}", s.scene, quality);
    if (s.solver != "auto") out += " --solver " + s.solver;
    if (!s.effects.empty()) out += " --effects " + s.effects;
    if (s.max_passes != 100000) out += fmt::format(" --max-passes {}", s.max_passes);
    return out;
}

double median(const std::vector<double>& v) {
    return bench::stats(v).median;
}

ordered_json bake_json(const BakeSpec& spec, const BakeResult& r, const std::string& label, const std::string& quality,
                       const std::string& device) {
    const ordered_json& rep = r.report;
    const bench::Stats total = bench::stats(r.total);
    return {{"label", label},
            {"options",
             {{"scene", spec.scene},
              {"solver", spec.solver},
              {"effects", spec.effects},
              {"quality", quality},
              {"max_passes", spec.max_passes},
              {"device", device}}},
            {"total_s", total.median},
            {"total_min_s", total.min},
            {"total_sigma_percent", total.sigma_percent},
            {"total_runs_s", r.total},
            {"formfactors_s", median(r.formfactors)},
            {"solve_s", median(r.solve)},
            {"refine_s", median(r.refine)},
            {"gather_s", median(r.gather)},
            {"solver", rep["settings"]["solver"]},
            {"device", rep["device"]["id"]},
            {"passes", rep["passes"]},
            {"converged", rep["converged"]},
            {"patches", rep["counts"]["patches"]},
            {"elements_before_refinement", rep["counts"]["elements_before_refinement"]},
            {"elements", rep["counts"]["elements"]},
            {"effects", rep["effects"]}};
}

const char* on_off(bool on) {
    return on ? "on" : "off";
}

std::string percent(double x) {
    return fmt::format("{:.3g}%", 100.0 * x);
}

// The one-line note of a case, from what its bakes did.
std::string case_note(const CaseSpec& c, const ordered_json& p, const ordered_json& f) {
    const auto t = [](const ordered_json& b, const char* stage) { return b[stage].get<double>(); };
    if (c.name == "occlusion")
        return fmt::format(
            "convex room: exact analytic form factors, no hemicubes (form factors {:.3g} vs {:.3g} s, "
            "refinement {:.3g} vs {:.3g} s)",
            t(p, "formfactors_s"), t(f, "formfactors_s"), t(p, "refine_s"), t(f, "refine_s"));
    if (c.name == "colour")
        return fmt::format("grey room: one channel solved instead of three (solve {:.3g} vs {:.3g} s)", t(p, "solve_s"),
                           t(f, "solve_s"));
    if (c.name == "refinement")
        return fmt::format("the cost of refinement ({} → {} elements, refine {:.3g} s); it keeps every mesh's average",
                           p["elements_before_refinement"].get<long>(), p["elements"].get<long>(), t(p, "refine_s"));
    if (c.name == "convergence")
        return fmt::format("stop at the threshold ({} passes) vs shoot until 1e-6 is left ({} passes)",
                           p["passes"].get<long>(), f["passes"].get<long>());
    if (c.name == "interreflection")
        return fmt::format(
            "forced off: not a saving but a different result, the difference is the bounced light "
            "({} vs {} form-factor rows)",
            p["passes"].get<long>(), f["passes"].get<long>());
    return fmt::format("{} (auto's choice, {} rows) vs progressive ({} passes)", p["solver"].get<std::string>(),
                       p["passes"].get<long>(), f["passes"].get<long>());
}

}  // namespace

ordered_json max_mesh_difference(const ordered_json& a, const ordered_json& b) {
    if (!a.is_array() || !b.is_array() || a.size() != b.size())
        throw InternalError("max_mesh_difference: the two bakes do not list the same meshes");
    ordered_json out = {{"value", 0.0}, {"mesh", ""}, {"channel", ""}};
    double worst = -1.0;
    for (std::size_t i = 0; i < a.size(); ++i) {
        const std::string name = a[i]["name"].get<std::string>();
        if (b[i]["name"].get<std::string>() != name)
            throw InternalError(fmt::format("max_mesh_difference: mesh {} is {} in one bake, {} in the other", i, name,
                                            b[i]["name"].get<std::string>()));
        for (int c = 0; c < 3; ++c) {
            const double x = a[i]["radiosity"][c].get<double>(), y = b[i]["radiosity"][c].get<double>();
            if (!std::isfinite(x) || !std::isfinite(y))  // a broken bake must not look equal
                throw InternalError(fmt::format("max_mesh_difference: mesh {} has a non-finite radiosity", name));
            const double d = std::abs(x - y) / std::max({std::abs(x), std::abs(y), 1e-12});
            if (d > worst) {
                worst = d;
                out = {{"value", d}, {"mesh", name}, {"channel", std::string(1, "rgb"[c])}};
            }
        }
    }
    return out;
}

ordered_json run_effects_bench(const EffectsBenchOptions& o, std::ostream& log) {
    const std::string quality = o.quick ? "draft" : "default";
    const int repeats = o.repeats > 0 ? o.repeats : (o.quick ? 1 : 3);
    const std::vector<CaseSpec> specs = cases();

    // The distinct bakes, in order of first use; every scene checked before any bake runs.
    std::vector<BakeSpec> bakes;
    std::map<std::string, std::size_t> index;
    for (const CaseSpec& c : specs)
        for (const BakeSpec* s : {&c.planned, &c.forced})
            if (index.emplace(s->key(), bakes.size()).second) {
                bakes.push_back(*s);
                const fs::path file = fs::path(o.scenes_dir) / s->scene;
                std::error_code ec;
                if (!fs::is_regular_file(file, ec))
                    throw InputError(
                        fmt::format("{}: not found (bench --effects bakes the bundled scenes; run it from "
                                    "the repository root)",
                                    file.string()));
            }

    const TempDir temp("hemirad-bench-effects");
    long counter = 0;
    const auto bake = [&](const BakeSpec& s) {
        bake::Options b;
        b.scene = (fs::path(o.scenes_dir) / s.scene).string();
        b.output = (temp.path() / fmt::format("bake-{}", counter++)).string();
        b.device = o.device;
        b.quality = quality;
        b.solver = s.solver;
        b.effects = s.effects;
        b.max_passes = s.max_passes;
        b.quiet = true;
        bake::run(b);
        ordered_json report = read_report(fs::path(b.output) / "report.json");
        std::error_code ec;
        fs::remove_all(b.output, ec);
        return report;
    };

    log << fmt::format("bench --effects: {} bakes × {} repeat{}, --quality {}, --device {}\n", bakes.size(), repeats,
                       repeats == 1 ? "" : "s", quality, o.device);
    // A device's first bake builds its kernels: once, untimed, so that no bake pays for it.
    if (o.device != "ref") bake(bakes.front());

    // Round after round over every bake, so that a slow spell of the machine hits all alike.
    std::vector<BakeResult> results(bakes.size());
    for (int r = 0; r < repeats; ++r)
        for (std::size_t k = 0; k < bakes.size(); ++k) {
            ordered_json report = bake(bakes[k]);
            const ordered_json& t = report["timings_s"];
            BakeResult& res = results[k];
            res.total.push_back(t["total"].get<double>());
            res.formfactors.push_back(t["formfactors"].get<double>());
            res.refine.push_back(t["refine"].get<double>());
            res.solve.push_back(t["solve"].get<double>());
            res.gather.push_back(t["gather"].get<double>());
            log << fmt::format("  repeat {}/{}: {}: {:.3f} s\n", r + 1, repeats, describe(bakes[k], quality),
                               res.total.back());
            if (res.report.is_null()) res.report = std::move(report);
        }

    ordered_json doc;
    doc["version"] = HEMIRAD_VERSION;
    doc["machine"] = bench::machine_info();
    ordered_json device = {{"requested", o.device}};
    for (const BakeResult& r : results)
        if (r.report["device"]["backend"] != "analytic") {
            device["id"] = r.report["device"]["id"];
            device["backend"] = r.report["device"]["backend"];
            device["name"] = r.report["device"]["name"];
            break;
        }
    doc["device"] = device;
    doc["settings"] = {{"quick", o.quick}, {"quality", quality}, {"repeats", repeats}, {"time", "median of total_s"}};

    ordered_json out = ordered_json::array();
    log << "\n| case | planned | forced | planned s | forced s | forced ÷ planned | max mesh Δ | note |\n"
           "|---|---|---|---|---|---|---|---|\n";
    for (std::size_t i = 0; i < specs.size(); ++i) {
        const CaseSpec& c = specs[i];
        const BakeResult& p = results[index.at(c.planned.key())];
        const BakeResult& f = results[index.at(c.forced.key())];
        bool planned_on, forced_on;
        std::string planned_label, forced_label;
        if (c.effect.empty()) {  // the solver
            const std::string chosen = p.report["settings"]["solver"].get<std::string>();
            planned_on = chosen == "matrix";
            forced_on = f.report["settings"]["solver"] == "matrix";
            planned_label = fmt::format("solver auto ({})", chosen);
            forced_label = "solver " + c.forced.solver;
        } else {
            planned_on = p.report["effects"][c.effect]["on"].get<bool>();
            forced_on = f.report["effects"][c.effect]["on"].get<bool>();
            const std::string prefix = c.planned.solver == "auto" ? "" : c.planned.solver + ", ";
            planned_label = fmt::format("{}{} auto ({})", prefix, c.effect, on_off(planned_on));
            forced_label = prefix + c.forced.effects;
        }
        const ordered_json planned = bake_json(c.planned, p, planned_label, quality, o.device);
        const ordered_json forced = bake_json(c.forced, f, forced_label, quality, o.device);
        const double tp = planned["total_s"].get<double>(), tf = forced["total_s"].get<double>();
        const double ratio = tp > 0.0 ? tf / tp : 0.0;
        const ordered_json diff = max_mesh_difference(p.report["meshes"], f.report["meshes"]);
        const bool as_expected = planned_on == c.expect_planned_on && forced_on != c.expect_planned_on;
        std::string note = case_note(c, planned, forced);
        if (!as_expected) note += "; NOT the expected decisions (see effects)";
        if (c.expect_saving && ratio < 1.0) note += "; the planned bake is the slower one here";

        out.push_back({{"case", i + 1},
                       {"name", c.name},
                       {"scene", c.planned.scene},
                       {"planned", planned},
                       {"forced", forced},
                       {"decisions_as_expected", as_expected},
                       {"expect_saving", c.expect_saving},
                       {"time_ratio", ratio},
                       {"saved_s", tf - tp},
                       {"max_mesh_difference", diff},
                       {"note", note}});
        log << fmt::format("| {} {} ({}) | {} | {} | {:.3f} | {:.3f} | {:.2f}× | {} ({} {}) | {} |\n", i + 1, c.name,
                           c.planned.scene, planned_label, forced_label, tp, tf, ratio,
                           percent(diff["value"].get<double>()), diff["mesh"].get<std::string>(),
                           diff["channel"].get<std::string>(), note);
    }
    doc["cases"] = out;
    return doc;
}

}  // namespace hemirad::bench
