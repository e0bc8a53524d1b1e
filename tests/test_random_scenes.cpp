// Seeded random real-shaped scenes (issue 20): the generator writes what it says, and each scene
// bakes through the real pipeline (glTF file in, every output out) on the reference engine and
// on OpenCL where a device is present, keeping every invariant, the two engines bit for bit equal.
#include <catch2/catch.hpp>

#include <cmath>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "backends.h"
#include "cl/runtime.h"
#include "bake/bake.h"
#include "core/error.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "random_bake.h"
#include "gen/random_scene.h"
#include "scene/scene.h"

using namespace hemirad;

namespace {

std::string joined(const std::vector<std::string>& lines) {
    std::string s;
    for (const std::string& l : lines) s += l + "\n";
    return s;
}

// Σ p0 · (p1 × p2) / 6 over a closed surface: the volume it encloses, positive when its fronts face out.
double signed_volume(const std::vector<const scene::Triangle*>& triangles) {
    double v = 0.0;
    for (const scene::Triangle* t : triangles) v += glm::dot(t->p[0], glm::cross(t->p[1], t->p[2])) / 6.0;
    return v;
}

}  // namespace

TEST_CASE("random scenes: a seed always writes the same file and another seed another", "[random]") {
    test::ScratchDir dir("hemirad-random-scene");
    const auto write = [&](std::uint64_t seed, const std::string& name) {
        gen::Choices c = gen::Choices::from_seed(seed);
        gen::write_random_scene(c, dir.path() / name);
        return test::read_file_text(dir.path() / name);
    };
    const std::string a = write(7, "a.gltf"), b = write(7, "b.gltf"), other = write(8, "c.gltf");
    CHECK(!a.empty());
    CHECK(a == b);
    CHECK(a != other);
    // Any bytes make a scene, even none.
    gen::Choices none(std::vector<std::uint8_t>{});
    const gen::RandomSceneInfo info = gen::write_random_scene(none, dir.path() / "none.gltf");
    CHECK(info.objects.size() >= 1);
    CHECK_NOTHROW(scene::load(dir.path() / "none.gltf"));
}

TEST_CASE("random scenes: the loader keeps every object's triangles, its emitter and its fronts through mirrored nodes",
          "[random]") {
    // 300 scenes, loaded back: the triangle counts the generator wrote, an emitting triangle with
    // area, and every closed surface still enclosing a positive volume (negative facing in) after
    // its chain of rotated, scaled and mirrored nodes: a mirroring transform turns the winding
    // over, and the loader must turn it back.
    test::ScratchDir dir("hemirad-random-scene");
    int mirrored_closed = 0, double_sided = 0, degenerate = 0, scales_small = 0, scales_large = 0;
    for (std::uint64_t seed = 1; seed <= 300; ++seed) {
        gen::Choices c = gen::Choices::from_seed(seed);
        const std::filesystem::path file = dir.path() / "scene.gltf";
        const gen::RandomSceneInfo info = gen::write_random_scene(c, file);
        CAPTURE(seed, info.summary);
        const scene::Scene s = scene::load(file);
        CHECK(s.triangles.size() == info.triangles);

        std::map<std::string, std::vector<const scene::Triangle*>> by_node;
        bool emits = false;
        for (const scene::Triangle& t : s.triangles) {
            by_node[s.nodes[t.node].name].push_back(&t);
            const double area = glm::length(glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]));
            const glm::dvec3 e = s.materials[t.material].emission;
            emits = emits || (area > 0.0 && (e.x > 0.0 || e.y > 0.0 || e.z > 0.0));
        }
        CHECK(emits);
        for (const gen::RandomObject& object : info.objects) {
            CAPTURE(object.node, object.shape, object.mirrored, object.inward);
            REQUIRE(by_node.count(object.node) == 1);
            CHECK(by_node[object.node].size() == object.triangles);
            if (!object.closed) continue;
            const double v = signed_volume(by_node[object.node]);
            CHECK((object.inward ? -v : v) > 0.0);
            if (object.mirrored) ++mirrored_closed;
        }
        if (info.double_sided) ++double_sided;
        if (info.degenerate > 0) ++degenerate;
        const double diagonal = s.diagonal();
        if (diagonal < 0.1) ++scales_small;
        if (diagonal > 1000.0) ++scales_large;
    }
    // The generator still makes what it is for.
    CHECK(mirrored_closed >= 30);
    CHECK(double_sided >= 100);
    CHECK(degenerate >= 100);
    CHECK(scales_small >= 20);
    CHECK(scales_large >= 20);
}

TEST_CASE("random scenes: the reference and OpenCL engines give the same form factors bit for bit", "[random][opencl]") {
    // Both sum the cells each element wins in 64-bit fixed point, so equal cells give equal bits.
    // (The reference's double sums differed in the last bits; seed 1, a 4-sided cylinder lamp,
    // then baked differently on the two engines: the progressive solver picked between two of its
    // patches of nearly equal flux differently.)
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    const std::vector<ocl::DeviceInfo> devices = ocl::list_devices();
    ocl::Context context(devices.front());
    test::ScratchDir dir("hemirad-random-engines");
    for (std::uint64_t seed = 1; seed <= 6; ++seed) {
        gen::Choices c = gen::Choices::from_seed(seed);
        const gen::RandomSceneInfo info = gen::write_random_scene(c, dir.path() / "scene.gltf");
        CAPTURE(seed, info.summary);
        const scene::Scene s = scene::load(dir.path() / "scene.gltf");
        const double patch = s.diagonal() / 6.0;
        const mesh::Mesh m = mesh::build(s, {patch, patch / 2.0});
        formfactor::ReferenceEngine ref(m, {24, seed});
        formfactor::OpenCLEngine cl(m, context, {24, seed});
        formfactor::ShotResult a, b;
        long differing = 0;
        const std::uint32_t step = std::max<std::uint32_t>(1, std::uint32_t(m.patches.size() / 12));
        for (std::uint32_t p = 0; p < m.patches.size(); p += step) {
            ref.shoot(p, p, a);
            cl.shoot(p, p, b);
            differing += a.blocked != b.blocked;
            formfactor::for_each_in_union(a, b, [&differing](std::uint32_t, double fa, double fb) { differing += fa != fb; });
        }
        CHECK(differing == 0);
    }
}

namespace {

// "Converged" must mean the answer is close to the one shooting on gives: a progressive bake that
// converged at threshold t is baked again with convergence forced off (shooting on until 1e-6 is
// left), and the flux-weighted difference of the meshes' incident light, Σ|ΔH|A / ΣHA per
// channel, must be within 3 t: the measure the solver stops on is a share of that light. Bakes
// the max-passes cap stopped again are not compared.
void check_converged_answer(const test::RandomBake& bake, const std::filesystem::path& dir, int& checked) {
    const nlohmann::json report = nlohmann::json::parse(test::read_file_text(std::filesystem::path(bake.options.output) / "report.json"));
    if (report.at("settings").at("solver") != "progressive" || !report.at("converged").get<bool>()) return;
    if (bake.options.effects.find("convergence") != std::string::npos) return;
    bake::Options full = bake.options;
    full.effects = full.effects.empty() ? "convergence=off" : full.effects + ",convergence=off";
    full.max_passes = 20000;
    full.output = (dir / "out_full").string();
    full.on_shot = nullptr;
    REQUIRE_NOTHROW(bake::run(full));
    const nlohmann::json shot_on = nlohmann::json::parse(test::read_file_text(std::filesystem::path(full.output) / "report.json"));
    if (!shot_on.at("converged").get<bool>()) return;
    const double threshold = report.at("settings").at("threshold");
    for (int c = 0; c < 3; ++c) {
        double difference = 0.0, total = 0.0;
        for (std::size_t m = 0; m < report.at("meshes").size(); ++m) {
            const double area = report["meshes"][m].at("area");
            const double a = report["meshes"][m].at("irradiance").at(c), b = shot_on["meshes"][m].at("irradiance").at(c);
            difference += std::abs(a - b) * area;
            total += b * area;
        }
        CAPTURE(c, difference, total, threshold, report.at("converged_by"), report.at("passes"), shot_on.at("passes"));
        CHECK(difference <= 3.0 * threshold * total + 1e-12);
    }
    ++checked;
}

}  // namespace

TEST_CASE("random scenes: 30 seeded scenes bake on the reference and OpenCL with every invariant and the same bits",
          "[random]") {
    // Each seed: a scene and small settings (random_bake.h), baked through bake::run as the CLI
    // runs it. Every shot must have F >= 0 and ΣF + blocked <= 1 + 1e-9; the outputs must be
    // complete and finite with balanced books; the OpenCL bake must be the reference's, bit for bit.
    const bool opencl = !ocl::list_devices().empty();
    if (!opencl) WARN("no OpenCL device: the reference engine only");
    int baked = 0, refused = 0, converged_checks = 0;
    for (std::uint64_t seed = 1; seed <= 30; ++seed) {
        test::ScratchDir dir("hemirad-random-bake");
        gen::Choices c = gen::Choices::from_seed(seed);
        test::RandomBakeLimits limits;
        limits.scene.max_objects = 4;
        limits.scene.max_triangles = 300;
        test::RandomBake bake = test::make_random_bake(c, dir.path(), limits);
        CAPTURE(seed, bake.scene.summary, bake.settings);
        if (test::refused_by_design(bake.options)) {
            CHECK_THROWS_AS(bake::run(bake.options), InputError);
            ++refused;
            continue;
        }
        test::ShotChecker shots;
        bake.options.on_shot = std::ref(shots);
        REQUIRE_NOTHROW(bake::run(bake.options));
        ++baked;
        CHECK(shots.shots() > 0);
        INFO("shots: " << joined(shots.problems()));
        CHECK(shots.problems().empty());
        const std::vector<std::string> problems = test::check_bake_output(bake.options.output);
        INFO("outputs: " << joined(problems));
        CHECK(problems.empty());
        check_converged_answer(bake, dir.path(), converged_checks);

        if (!opencl) continue;
        test::ShotChecker cl_shots;
        bake::Options on_cl = bake.options;
        on_cl.device = "opencl";
        on_cl.output = (dir.path() / "out_opencl").string();
        on_cl.on_shot = std::ref(cl_shots);
        REQUIRE_NOTHROW(bake::run(on_cl));
        CHECK(cl_shots.shots() == shots.shots());
        const std::vector<std::string> differences = test::compare_bakes(bake.options.output, on_cl.output);
        INFO("reference against OpenCL: " << joined(differences));
        CHECK(differences.empty());
    }
    CHECK(baked >= 20);
    CHECK(converged_checks >= 5);  // progressive bakes that converged and were shot on to compare
    (void)refused;
}
