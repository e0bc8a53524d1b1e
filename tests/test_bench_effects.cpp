// `hemirad bench --effects`: its mesh comparison, its option checks, and a quick run on the
// reference engine whose pairs must show the physics each effect stands for.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "bench/command.h"
#include "bench/effects.h"
#include "core/error.h"

using namespace hemirad;
using nlohmann::ordered_json;
namespace fs = std::filesystem;

namespace {

ordered_json mesh_summary(const std::string& name, double r, double g, double b) {
    return {{"name", name}, {"area", 1.0}, {"radiosity", {r, g, b}}, {"irradiance", {0.0, 0.0, 0.0}}};
}

// This process's temporary bake directories (bench_effects.cpp names them after the pid).
int leftover_temp_dirs() {
    const std::string prefix = "hemirad-bench-effects-" + std::to_string(static_cast<long>(getpid())) + "-";
    int n = 0;
    for (const auto& e : fs::directory_iterator(fs::temp_directory_path()))
        if (e.path().filename().string().rfind(prefix, 0) == 0) ++n;
    return n;
}

double stage_sum(const ordered_json& bake) {
    return bake["formfactors_s"].get<double>() + bake["refine_s"].get<double>() + bake["gather_s"].get<double>();
}

}  // namespace

TEST_CASE("bench effects: the largest relative difference of any mesh's average radiosity", "[bench]") {
    ordered_json a =
        ordered_json::array({mesh_summary("floor", 1.0, 0.5, 0.0), mesh_summary("light", 17.0, 12.0, 4.0)});
    ordered_json b =
        ordered_json::array({mesh_summary("floor", 1.0, 0.4, 0.0), mesh_summary("light", 17.0, 12.0, 4.4)});
    const ordered_json d = bench::max_mesh_difference(a, b);
    CHECK(d["value"].get<double>() == Approx(0.2));  // |0.5 - 0.4| / 0.5 beats |4 - 4.4| / 4.4
    CHECK(d["mesh"] == "floor");
    CHECK(d["channel"] == "g");
    CHECK(bench::max_mesh_difference(a, a)["value"].get<double>() == 0.0);
    // A zero against a tiny value is a whole difference, not a division by zero.
    CHECK(bench::max_mesh_difference(ordered_json::array({mesh_summary("m", 0.0, 0.0, 0.0)}),
                                   ordered_json::array({mesh_summary("m", 0.0, 1e-30, 0.0)}))["value"]
              .get<double>() == Approx(1e-18));
    // A NaN must not look like agreement, wherever it is.
    for (int m = 0; m < 2; ++m) {
        ordered_json nan = a;
        nan[m]["radiosity"][0] = std::numeric_limits<double>::quiet_NaN();
        CHECK_THROWS_AS(bench::max_mesh_difference(a, nan), InternalError);
        CHECK_THROWS_AS(bench::max_mesh_difference(nan, a), InternalError);
    }
    // Different meshes are not compared.
    CHECK_THROWS_AS(bench::max_mesh_difference(a, ordered_json::array({mesh_summary("floor", 1.0, 0.5, 0.0)})),
                    InternalError);
    b[1]["name"] = "lamp";
    CHECK_THROWS_AS(bench::max_mesh_difference(a, b), InternalError);
}

TEST_CASE("bench effects: bad options and a missing scene are input errors", "[bench]") {
    std::ostringstream log;
    bench::BenchCommand c;
    c.effects = true;
    c.accuracy = true;
    CHECK_THROWS_AS(bench::run_bench(c, log), InputError);
    c.accuracy = false;
    c.throughput.scenes = {"scenes/cornell_box.gltf"};
    CHECK_THROWS_AS(bench::run_bench(c, log), InputError);
    bench::BenchCommand quick_alone;
    quick_alone.quick = true;
    quick_alone.throughput.scenes = {"procedural:100"};
    CHECK_THROWS_AS(bench::run_bench(quick_alone, log), InputError);

    bench::EffectsBenchOptions o;
    o.device = "ref";
    o.quick = true;
    o.scenes_dir = HEMIRAD_SOURCE_DIR "/no-such-scenes-dir";
    CHECK_THROWS_AS(bench::run_effects_bench(o, log), InputError);
    CHECK(leftover_temp_dirs() == 0);
}

TEST_CASE("bench effects quick on the reference: each pair shows its effect", "[bench]") {
    bench::EffectsBenchOptions o;
    o.device = "ref";
    o.quick = true;
    o.scenes_dir = HEMIRAD_SOURCE_DIR "/scenes";
    std::ostringstream log;
    const ordered_json doc = bench::run_effects_bench(o, log);
    INFO(log.str());
    CHECK(leftover_temp_dirs() == 0);
    CHECK(log.str().find("| case | planned | forced |") != std::string::npos);

    // Structure.
    CHECK(doc["version"] == HEMIRAD_VERSION);
    CHECK(doc["machine"].contains("cpu"));
    CHECK(doc["device"]["id"] == "ref");
    CHECK(doc["settings"]["repeats"] == 1);
    CHECK(doc["settings"]["quality"] == "draft");
    const ordered_json& cases = doc["cases"];
    REQUIRE(cases.size() == 6);
    const char* names[] = {"occlusion", "colour", "refinement", "convergence", "interreflection", "solver"};
    for (std::size_t i = 0; i < 6; ++i) {
        const ordered_json& c = cases[i];
        INFO("case " << i + 1);
        CHECK(c["case"] == i + 1);
        CHECK(c["name"] == names[i]);
        CHECK(c["decisions_as_expected"] == true);
        for (const char* side : {"planned", "forced"}) {
            const ordered_json& b = c[side];
            INFO(side);
            CHECK(b["total_s"].get<double>() > 0.0);
            CHECK(b["total_runs_s"].size() == 1);
            CHECK(b["passes"].get<long>() > 0);
            CHECK(b["elements"].get<long>() > 0);
            CHECK(b["converged"] == true);
            for (const char* e : {"occlusion", "colour", "interreflection", "two_sided", "refinement", "convergence"})
                CHECK(b["effects"][e].contains("on"));
        }
        CHECK(c["time_ratio"].get<double>() ==
              Approx(c["forced"]["total_s"].get<double>() / c["planned"]["total_s"].get<double>()));
        CHECK(std::isfinite(c["max_mesh_difference"]["value"].get<double>()));
        CHECK_FALSE(c["note"].get<std::string>().empty());
    }

    // 1. Occlusion: exact analytic form factors against hemicubes agree to the hemicube's error
    //    and cost less. Refinement re-gathers with the same engine, so its time is form-factor
    //    work too (at draft N = 64 the first gather alone costs the two engines about the same).
    const ordered_json& occlusion = cases[0];
    CHECK(occlusion["planned"]["effects"]["occlusion"]["on"] == false);
    CHECK(occlusion["planned"]["device"] == "analytic");
    CHECK(occlusion["forced"]["device"] == "ref");
    CHECK(occlusion["max_mesh_difference"]["value"].get<double>() < 0.02);
    CHECK(stage_sum(occlusion["planned"]) < stage_sum(occlusion["forced"]));
    // 2. Colour: a grey scene solved in one channel is the three-channel result exactly.
    CHECK(cases[1]["planned"]["effects"]["colour"]["on"] == false);
    CHECK(cases[1]["max_mesh_difference"]["value"].get<double>() < 1e-9);
    // 3. Refinement splits elements and shares each parent's flux out: the averages keep.
    const ordered_json& refinement = cases[2];
    CHECK(refinement["planned"]["elements"].get<long>() > refinement["forced"]["elements"].get<long>());
    CHECK(refinement["max_mesh_difference"]["value"].get<double>() < 1e-9);
    // 4. Convergence off shoots on to 1e-6 unshot: many more passes, a result within the threshold's reach.
    const ordered_json& convergence = cases[3];
    CHECK(convergence["forced"]["passes"].get<long>() > 2 * convergence["planned"]["passes"].get<long>());
    CHECK(convergence["planned"]["solver"] == "progressive");
    CHECK(convergence["max_mesh_difference"]["value"].get<double>() < 0.05);
    // 5. Interreflection off is direct light only: the emitters' rows, and the bounced light missing.
    const ordered_json& direct = cases[4];
    CHECK(direct["forced"]["passes"].get<long>() < direct["planned"]["passes"].get<long>());
    CHECK(direct["max_mesh_difference"]["value"].get<double>() > 0.1);
    // 6. The matrix solver (auto's choice) and the progressive one agree to about 1%.
    CHECK(cases[5]["planned"]["solver"] == "matrix");
    CHECK(cases[5]["forced"]["solver"] == "progressive");
    CHECK(cases[5]["max_mesh_difference"]["value"].get<double>() < 0.03);
}
