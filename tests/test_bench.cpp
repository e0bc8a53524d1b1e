// The benchmark's own logic: the Pareto front and the presets read off it, and a bake of the
// accuracy room against the independent room reference (bench/room_reference.h).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <nlohmann/json.hpp>

#include "bench/accuracy.h"
#include "bench/room_reference.h"
#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "output/output.h"
#include "solve/progressive.h"

using namespace hemirad;
using nlohmann::ordered_json;

namespace {

ordered_json run(double seconds, double error, double threshold = 1e-3) {
    return {{"seconds", seconds}, {"rms_rel_error", error}, {"threshold", threshold}};
}

}  // namespace

TEST_CASE("pareto front: the runs nothing beats in both time and error, fastest first", "[bench]") {
    ordered_json runs = ordered_json::array();
    runs.push_back(run(2.0, 0.020));       // 0: the defaults
    runs.push_back(run(1.0, 0.035));       // 1: front
    runs.push_back(run(1.5, 0.060));       // 2: beaten by 1
    runs.push_back(run(0.5, 0.080));       // 3: front (fastest)
    runs.push_back(run(4.0, 0.010));       // 4: front
    runs.push_back(run(3.0, 0.030));       // 5: beaten by 0
    runs.push_back(run(0.1, 0.001, 0.1));  // 6: best at everything but its threshold is too loose
    runs.push_back(run(20.0, 0.005));      // 7: front (most accurate), beyond 8x the defaults' time
    const std::vector<std::size_t> front = bench::pareto_front(runs);
    CHECK(front == std::vector<std::size_t>{3, 1, 0, 4, 7});

    const ordered_json presets = bench::derive_presets(runs, front);
    CHECK(presets["draft"]["run"] == 1);    // fastest within 2 × 0.020
    CHECK(presets["default"]["run"] == 0);  // fastest at most 0.020
    CHECK(presets["high"]["run"] == 4);     // most accurate within 8 × 2.0 s
    CHECK(presets["high"]["rms_rel_error"] == 0.010);
}

TEST_CASE("pareto front: a run faster and better than the defaults becomes the default preset", "[bench]") {
    ordered_json runs = ordered_json::array();
    runs.push_back(run(2.0, 0.020));
    runs.push_back(run(1.0, 0.015));
    const std::vector<std::size_t> front = bench::pareto_front(runs);
    CHECK(front == std::vector<std::size_t>{1});
    const ordered_json presets = bench::derive_presets(runs, front);
    for (const char* name : {"draft", "default", "high"}) CHECK(presets[name]["run"] == 1);
}

TEST_CASE("the accuracy room baked by hemirad agrees with the independent reference", "[bench]") {
    // Coarse, so that it runs in seconds on the reference engine: surface averages are the
    // quantity a coarse bake gets right (the reference's own 0.25 m grid is within 0.03% of
    // converged, tests/test_room_reference.cpp).
    const bench::Room room;
    const scene::Scene s = bench::make_room_scene(room);
    const mesh::Mesh m = mesh::build(s, {0.5, 0.25});
    formfactor::NearFieldEngine engine(m,
                                       std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{128, 1}));
    solve::Settings settings;
    settings.threshold = 1e-4;
    solve::Progressive solver(m, engine, settings);
    while (solver.step()) {
    }
    REQUIRE(solver.converged());
    const auto summary = output::summarize(s, m, solver.radiosity(true), solver.irradiance(true));
    const bench::RoomSolution reference = bench::solve_room(room, 0.25);
    int compared = 0;
    for (const auto& [name, want] : reference.surface_average)
        for (const auto& got : summary)
            if (got.name == name) {
                INFO(name);
                for (int c = 0; c < 3; ++c) CHECK(got.radiosity[c] == Approx(want[c]).epsilon(0.01));
                ++compared;
            }
    CHECK(compared == bench::kSurfaceCount);
}
