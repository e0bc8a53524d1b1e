// The OpenCL hemicube engine against the scalar reference (cell for cell) and analytic answers.
// Runs on the first OpenCL device (PoCL in CI; test::first_opencl()); every test warns and skips
// without one. What every backend owes the analytic answers is in test_formfactor.cpp.
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstring>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "cl/runtime.h"
#include "formfactor/device_mesh.h"
#include "formfactor/near_field.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "formfactor/verify.h"
#include "mesh/mesh.h"
#include "gen/content_scenes.h"
#include "gen/procedural.h"
#include "scene/scene.h"
#include "solve/progressive.h"
#include "backends.h"
#include "test_compare.h"
#include "test_scenes.h"

using namespace hemirad;
using Catch::Matchers::WithinAbs;
using Catch::Matchers::WithinRel;
using test::Case;
using test::Comparison;
using test::compare;
using test::comparison_cases;

namespace {

// The agreement every OpenCL configuration owes the reference: the same doubles in the same
// order and a total order on (depth, index), so not even a genuine depth tie can differ and no
// cell may; form factors within the relative tolerance.
void check_matches_reference(const Comparison& r) {
    CAPTURE(r.mismatched_cells, r.worst_f);
    CHECK(r.mismatched_cells == 0);
    CHECK(r.worst_f <= 1e-4);
}

}  // namespace

TEST_CASE("opencl: id buffers and form factors match the reference cell for cell", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    for (const Case& c : comparison_cases()) {
        const mesh::Mesh m = mesh::build(c.scene, c.mesh);
        // 8 and 40: faces that do not fill whole tiles.
        for (int n : {8, 32, 40, 64, 256}) {
            formfactor::ReferenceEngine ref(m, {n, 42});
            formfactor::OpenCLEngine cl(m, *ctx, {n, 42});
            const int shots = n == 256 ? 20 : 30;
            const Comparison r = compare(m, ref, cl, shots);
            INFO(c.name << ": " << m.patches.size() << " patches, " << m.elements.size() << " elements, N = " << n);
            CAPTURE(r.shots, r.cells, r.hit_cells, r.blocker_cells, r.mismatched_cells, r.worst_f, r.worst_total);
            CHECK(r.hit_cells > r.cells / 10);
            if (c.name == "occluders") CHECK(r.blocker_cells > 0);
            check_matches_reference(r);
            CHECK(r.worst_total <= 1e-12);
        }
    }
}

TEST_CASE("opencl: a point light's two hemicubes match the reference cell for cell", "[opencl][lights]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    for (Case c : comparison_cases()) {
        // A point light a little off the centre of the scene's box, and a spot light near a corner.
        glm::dvec3 lo = c.scene.triangles.front().p[0], hi = lo;
        for (const scene::Triangle& t : c.scene.triangles)
            for (const glm::dvec3& p : t.p) {
                lo = glm::min(lo, p);
                hi = glm::max(hi, p);
            }
        scene::PunctualLight point, spot;
        point.position = lo + (hi - lo) * glm::dvec3(0.47, 0.53, 0.51);
        spot.type = scene::PunctualLight::Type::spot;
        spot.position = lo + (hi - lo) * glm::dvec3(0.2, 0.8, 0.3);
        spot.direction = glm::normalize(glm::dvec3(0.3, -1.0, 0.2));
        c.scene.lights = {point, spot};
        const mesh::Mesh m = mesh::build(c.scene, c.mesh);
        REQUIRE(m.lights.size() == 3);
        for (int n : {40, 256}) {
            formfactor::ReferenceEngine ref(m, {n, 42});
            formfactor::OpenCLEngine cl(m, *ctx, {n, 42});
            for (std::uint32_t l = 0; l < 3; ++l) {
                formfactor::ShotResult a, b;
                ref.shoot(formfactor::ShotRequest::of_light(l, 99 + l), a);
                cl.shoot(formfactor::ShotRequest::of_light(l, 99 + l), b);
                INFO(c.name << ": light hemicube " << l << ", N = " << n);
                CHECK(ref.ids() == *cl.last_ids());
                CHECK(a == b);  // fixed-point sums of the same cells: the same bits
                CHECK(a.sum() + a.blocked > 0.05);  // it sees the scene
            }
        }
    }
}

TEST_CASE("opencl: any tile size gives the reference's result", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const Case c = comparison_cases().back();
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    for (int tile : {5, 16}) {  // 5: tiles straddle every face edge
        formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
        tuning.tile = tile;
        for (int n : {40, 64}) {
            formfactor::ReferenceEngine ref(m, {n, 5});
            formfactor::OpenCLEngine cl(m, *ctx, {n, 5}, tuning);
            const Comparison r = compare(m, ref, cl, 10);
            CAPTURE(tile, n);
            check_matches_reference(r);
        }
    }
}

// Occlusion culling drops lane groups hidden behind what an occluder pass drew, by a bound that
// must hold for the very values setup and the raster compute: so it may change no cell. Scenes
// where it hides much (a city, foliage cards), and one built against its bound: a floor with
// thin slabs 1e-4 above it, seen at grazing angles from the floor's own shooters, where rounding
// and the snapped edges of planes passing near the shooter are largest.
TEST_CASE("opencl: occlusion culling hides lane groups and changes no cell", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    std::vector<Case> cases;
    for (const auto kind : {gen::ContentKind::kCity, gen::ContentKind::kFoliage}) {
        scene::Scene s = gen::content_scene(kind, 20000);
        const double patch = s.diagonal() / 16.0;
        cases.push_back({gen::content_kind_name(kind), std::move(s), {patch, patch / 3.0}});
    }
    {
        scene::Scene s;
        const auto grey = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
        add_quad(s, {0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}, grey, "floor");
        for (int k = 0; k < 12; ++k) {  // slabs just above the floor, and walls behind them
            const double x = 0.5 + 0.8 * k, y = 1.0 + 0.6 * (k % 5);
            add_quad(s, {x, y, 1e-4}, {x + 0.6, y, 1e-4}, {x + 0.6, y + 3.0, 1e-4}, {x, y + 3.0, 1e-4}, grey, "slab");
            test::add_block(s, {x, y + 4.0, 0.0}, {x + 0.5, y + 4.5, 0.3 + 0.2 * (k % 3)}, grey, "wall");
        }
        finish(s);
        cases.push_back({"grazing slabs", s, {0.25, 0.1}});
    }
    {  // a room, and objects standing on its floor's level 20 m beyond its +x wall: from the floor
       // they lie near the base plane and across the side faces' eye planes, but outside those
       // faces' frusta (hemirad_bench_culling's scene, smaller)
        scene::Scene s = gen::procedural_with_clutter(2000, 20000, gen::Clutter::beyond);
        const double patch = 10.0 * std::sqrt(3.0) / 16.0;
        cases.push_back({"beyond a wall", std::move(s), {patch, patch / 3.0}});
    }
    formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
    tuning.setup_lanes = true;  // what occlusion culling needs, on any device
    tuning.raster_per_record = true;
    tuning.tile = 32;
    tuning.occlusion = formfactor::Occlusion::on;
    tuning.occluder_share = 4;
    for (const Case& c : cases) {
        const mesh::Mesh m = mesh::build(c.scene, c.mesh);
        formfactor::ReferenceEngine ref(m, {128, 9});
        formfactor::OpenCLEngine cl(m, *ctx, {128, 9}, tuning);
        const Comparison r = compare(m, ref, cl, 24);
        INFO(c.name << ": " << m.elements.size() << " elements");
        CAPTURE(cl.occlusion_tested(), cl.occlusion_hidden());
        // It hid something: much in the city and the foliage, little among the slabs. Beyond the
        // wall, 31% of the groups tested (24% before groups outside a face's frustum were let
        // through its eye plane), most shooters being among the objects.
        const std::uint64_t share = c.name == "beyond a wall" ? 4 : 20;
        CHECK(cl.occlusion_hidden() > (c.name == "grazing slabs" ? 0 : cl.occlusion_tested() / share));
        check_matches_reference(r);
        CHECK(r.worst_total <= 1e-12);
        // Shots in one launch: each shot's row of clusters loses those it hides (cull_clusters),
        // so the rows are cut and re-laid at the length of the longest.
        std::vector<formfactor::ShotRequest> batch;
        for (std::uint32_t i = 0; i < 6; ++i)
            batch.push_back(formfactor::ShotRequest::of_patch(
                static_cast<std::uint32_t>((std::size_t{i} * 104729u + 11u) % m.patches.size()), 2000u + i));
        std::vector<formfactor::ShotResult> got;
        const std::uint64_t hidden_before = cl.occlusion_hidden();
        cl.shoot_batch(batch, got);
        if (c.name != "grazing slabs") CHECK(cl.occlusion_hidden() > hidden_before);
        for (std::size_t i = 0; i < batch.size(); ++i) {
            formfactor::ShotResult want;
            ref.shoot(batch[i].shooter.patch, batch[i].shot, want);
            CHECK(formfactor::compare_shot(got[i], want).empty());
        }
    }
}

TEST_CASE("opencl: lists that overflow grow and the shot is redone", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const Case c = comparison_cases().back();
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
    tuning.list_capacity = 16;  // far too small for any shot
    formfactor::ReferenceEngine ref(m, {64, 3});
    formfactor::OpenCLEngine cl(m, *ctx, {64, 3}, tuning);
    check_matches_reference(compare(m, ref, cl, 10));
}

TEST_CASE("opencl: record regions that overflow grow and the shot is redone", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const Case c = comparison_cases().back();
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
    tuning.setup_lanes = true;  // whose setup packs records in regions, on any device
    tuning.raster_per_record = true;
    tuning.group_capacity = 3;  // far too few for any shot's busiest work-group
    formfactor::ReferenceEngine ref(m, {64, 3});
    formfactor::OpenCLEngine cl(m, *ctx, {64, 3}, tuning);
    check_matches_reference(compare(m, ref, cl, 10));
}

TEST_CASE("opencl: the same shot twice gives bit-identical results", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const Case c = comparison_cases().back();
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    formfactor::OpenCLEngine a(m, *ctx, {128, 9});
    formfactor::OpenCLEngine b(m, *ctx, {128, 9});
    formfactor::ShotResult ra, rb, rc;
    for (std::uint32_t patch : {0u, 7u, static_cast<std::uint32_t>(m.patches.size() - 1)}) {
        a.shoot(patch, 17, ra);
        const std::vector<std::int32_t> ids_a = *a.last_ids();
        a.shoot(patch, 17, rb);  // the same engine again
        b.shoot(patch, 17, rc);  // a second engine
        CAPTURE(patch);
        CHECK(ra == rb);
        CHECK(ra == rc);
        CHECK(ra.blocked == rb.blocked);
        CHECK(ra.blocked == rc.blocked);
        CHECK(ids_a == *a.last_ids());
        CHECK(ids_a == *b.last_ids());
    }
}

// An engine packs the layout its setup reads piece by piece (pack_lanes or pack_elements over
// runs of groups); a DeviceMesh packs the whole mesh at once, for engines that share it.
TEST_CASE("opencl: the mesh packed piece by piece is the mesh packed whole", "[opencl]") {
    const scene::Scene city = gen::content_scene(gen::ContentKind::kCity, 3000);
    const double patch = city.diagonal() / 16.0;
    mesh::Mesh m;
    for (double per_patch = 3.0; per_patch < 4.0; per_patch += 0.1) {  // a mesh whose last lane group is padded
        m = mesh::build(city, {patch, patch / per_patch});
        if (m.elements.size() % HR_SETUP_LANES != 0) break;
    }
    REQUIRE(m.elements.size() % HR_SETUP_LANES != 0);
    const formfactor::DeviceMesh whole(m);
    REQUIRE(whole.lanes.size() == formfactor::lane_groups(m));
    std::vector<HrElementLanes> lanes(whole.lanes.size());
    std::vector<HrElement> elements(whole.elements.size());
    for (std::size_t first = 0, piece = 1; first < lanes.size(); first += piece, piece = piece * 3 + 1) {
        const std::size_t n = std::min(piece, lanes.size() - first);
        formfactor::pack_lanes(m, first, n, lanes.data() + first);
        formfactor::pack_elements(m, first * HR_SETUP_LANES, n * HR_SETUP_LANES, elements.data() + first * HR_SETUP_LANES);
    }
    CHECK(std::memcmp(lanes.data(), whole.lanes.data(), lanes.size() * sizeof(HrElementLanes)) == 0);
    CHECK(std::memcmp(elements.data(), whole.elements.data(), elements.size() * sizeof(HrElement)) == 0);
    const formfactor::DeviceMesh only_lanes(m, formfactor::Packing::lanes);
    CHECK(only_lanes.elements.empty());
    CHECK(std::memcmp(only_lanes.lanes.data(), whole.lanes.data(), lanes.size() * sizeof(HrElementLanes)) == 0);

    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
    formfactor::OpenCLEngine shared(m, whole, *ctx, {128, 9}, tuning);
    formfactor::OpenCLEngine own(m, *ctx, {128, 9}, tuning);
    formfactor::ShotResult a, b;
    for (std::uint32_t patch : {0u, 5u, static_cast<std::uint32_t>(m.patches.size() - 1)}) {
        shared.shoot(patch, 3, a);
        own.shoot(patch, 3, b);
        CAPTURE(patch);
        CHECK(a == b);
        CHECK(a.blocked == b.blocked);
        CHECK(*shared.last_ids() == *own.last_ids());
    }
}

// The analytic answers (parallel and perpendicular squares, a closed box, the furnace) every
// backend owes, OpenCL devices among them, are test_formfactor.cpp's "every backend: ..." tests.

// raster_records' spans rest on floor_div: a double quotient corrected in integers. Held to
// exact integer division where the double is least exact: large |m|, small and large d, and
// remainders 0, 1 and d - 1 on either side of zero.
TEST_CASE("opencl: floor_div is exact integer floor division", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    std::vector<cl_long> ms, ds;
    std::vector<std::pair<std::int64_t, std::int64_t>> expected;  // quotient, remainder
    const std::int64_t divisors[] = {std::int64_t{1} << 16, (std::int64_t{1} << 16) + 1, 3 << 16,
                                     (std::int64_t{1} << 40) - 1, std::int64_t{1} << 45};
    const std::int64_t quotients[] = {
        -(std::int64_t{1} << 44) - 3, -(std::int64_t{1} << 41) - 1, -4097, -5, -1, 0, 1, 7, 4095,
        (std::int64_t{1} << 41) + 3,  (std::int64_t{1} << 44) + 5};
    for (const std::int64_t d : divisors)
        for (const std::int64_t q : quotients)
            for (const std::int64_t r : {std::int64_t{0}, std::int64_t{1}, d - 1}) {
                const long double m = static_cast<long double>(q) * static_cast<long double>(d) + r;
                if (std::fabs(m) >= 4.0e18L) continue;  // |m| < 2^62
                ms.push_back(q * d + r);
                ds.push_back(d);
                expected.emplace_back(q, r);
            }
    // Where the truncated double quotient is two above the floor (found by a search like the
    // one below), and a seeded spread of large negative quotients with remainders near d.
    const std::int64_t two_off[][3] = {
        {1627377, -1554185446353, 1627341}, {405543, -8536825398791, 405535}, {5991369, -450357492379, 5991362}};
    for (const auto& c : two_off) {
        ms.push_back(c[1] * c[0] + c[2]);
        ds.push_back(c[0]);
        expected.emplace_back(c[1], c[2]);
    }
    std::mt19937_64 random(20261122);
    for (int k = 0; k < 200000; ++k) {
        const auto d = static_cast<std::int64_t>(std::uniform_int_distribution<std::int64_t>(1 << 16, 1 << 24)(random));
        const auto q =
            -std::uniform_int_distribution<std::int64_t>(std::int64_t{1} << 30, std::int64_t{1} << 37)(random);
        const auto r = d - 1 - std::uniform_int_distribution<std::int64_t>(0, 100)(random);
        ms.push_back(q * d + r);
        ds.push_back(d);
        expected.emplace_back(q, r);
    }
    REQUIRE(ms.size() > 100);
    cl::Program& program = ctx->program(std::string(ocl::kernel_source("hemicube.cl")), "");
    cl::Kernel kernel(program, "floor_div_pairs");
    cl::Context& context = ctx->context();
    cl::Buffer m_buffer(context, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, ms.size() * sizeof(cl_long), ms.data());
    cl::Buffer d_buffer(context, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, ds.size() * sizeof(cl_long), ds.data());
    cl::Buffer out_buffer(context, CL_MEM_WRITE_ONLY, 2 * ms.size() * sizeof(cl_long));
    kernel.setArg(0, m_buffer);
    kernel.setArg(1, d_buffer);
    kernel.setArg(2, out_buffer);
    ctx->queue().enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(ms.size()), cl::NullRange);
    std::vector<cl_long> out(2 * ms.size());
    ctx->queue().enqueueReadBuffer(out_buffer, CL_TRUE, 0, out.size() * sizeof(cl_long), out.data());
    std::size_t wrong = 0;
    for (std::size_t k = 0; k < ms.size(); ++k) {
        const bool ok = out[2 * k] == expected[k].first && out[2 * k + 1] == expected[k].second;
        if (!ok && wrong++ < 5)
            WARN("floor_div(" << ms[k] << ", " << ds[k] << ") = " << out[2 * k] << " rem " << out[2 * k + 1]
                              << ", expected " << expected[k].first << " rem " << expected[k].second);
    }
    CHECK(wrong == 0);
}

TEST_CASE("opencl: kernel build failures throw BuildError with the device and the log", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const std::string device = ctx->info().name;
    try {
        ctx->program("this is not OpenCL C", "");
        FAIL("a program that cannot compile was built");
    } catch (const ocl::BuildError& e) {
        const std::string what = e.what();
        CAPTURE(what);
        CHECK(what.find(device) != std::string::npos);
        CHECK(what.find("error") != std::string::npos);  // the compiler's own diagnostics
    }

    scene::Scene s;
    const auto grey = test::add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    s = test::parallel_rectangles(1, 1, 1, grey, grey, s);
    const mesh::Mesh m = mesh::build(s, {0.5, 0.25});
    formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
    tuning.extra_options = "-DClipPolygon=42";  // turns a typedef into nonsense
    CHECK_THROWS_AS(formfactor::OpenCLEngine(m, *ctx, {32, 1}, tuning), ocl::BuildError);
    // The context survives a failed build.
    formfactor::OpenCLEngine engine(m, *ctx, {32, 1});
    formfactor::ShotResult r;
    engine.shoot(0, 0, r);
    for (const std::uint32_t k : r.element) CHECK(k < m.elements.size());
    CHECK(std::is_sorted(r.element.begin(), r.element.end()));
}

TEST_CASE("opencl: a batch of shots gives exactly the shots one at a time", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const Case c = comparison_cases().back();
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    formfactor::OpenCLEngine batched(m, *ctx, {128, 5});
    formfactor::OpenCLEngine single(m, *ctx, {128, 5});
    formfactor::OpenCLTuning tight = formfactor::default_tuning(ctx->info());
    tight.batch_memory = 1;  // below one shot: every batch runs one shot per launch
    formfactor::OpenCLEngine split(m, *ctx, {128, 5}, tight);
    formfactor::ReferenceEngine ref(m, {128, 5});
    // Different shooters and shot counters, one patch twice; then a smaller batch reusing the buffers.
    for (const std::vector<formfactor::ShotRequest>& requests :
         {std::vector<formfactor::ShotRequest>{formfactor::ShotRequest::of_patch(0, 3), formfactor::ShotRequest::of_patch(5, 4),
                                               formfactor::ShotRequest::of_patch(static_cast<std::uint32_t>(m.patches.size() - 1), 5),
                                               formfactor::ShotRequest::of_patch(5, 6), formfactor::ShotRequest::of_patch(2, 7)},
          std::vector<formfactor::ShotRequest>{formfactor::ShotRequest::of_patch(1, 8), formfactor::ShotRequest::of_patch(3, 9)}}) {
        std::vector<formfactor::ShotResult> results, split_results;
        batched.shoot_batch(requests, results);
        split.shoot_batch(requests, split_results);
        REQUIRE(results.size() == requests.size());
        REQUIRE(split_results.size() == requests.size());
        // Split into launches, only the last launch's id buffer is kept.
        CHECK(split.last_ids(0) == nullptr);
        REQUIRE(split.last_ids(requests.size() - 1) != nullptr);
        CHECK(*split.last_ids(requests.size() - 1) == *batched.last_ids(requests.size() - 1));
        for (std::size_t i = 0; i < requests.size(); ++i) {
            formfactor::ShotResult one, want;
            single.shoot(requests[i], one);
            ref.shoot(requests[i], want);
            CAPTURE(i, requests[i].shooter.patch, requests[i].shot);
            CHECK(results[i] == one);
            CHECK(split_results[i] == one);
            CHECK(results[i].blocked == one.blocked);
            REQUIRE(batched.last_ids(i) != nullptr);
            CHECK(*batched.last_ids(i) == *ref.last_ids());  // cell for cell the reference's
            CHECK(formfactor::compare_shot(results[i], want).empty());
        }
        CHECK(batched.last_ids(requests.size()) == nullptr);
    }
}

TEST_CASE("opencl: batched shooting converges to the same furnace and books as one at a time", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    // A lit closed box: Σ B·A = Φ/(1 − ρ) exactly in the limit, whatever the shooting order.
    const double rho = 0.9;
    scene::Scene s;
    const auto wall = test::add_material(s, glm::dvec3(rho), glm::dvec3(0.0));
    const auto light = test::add_material(s, glm::dvec3(rho), glm::dvec3(2.0));
    s = test::closed_box(
        {1.0, 0.8, 1.2}, [&](int face) { return face == 3 ? light : wall; }, s);
    const mesh::Mesh m = mesh::build(s, {0.2, 0.1});
    // Runs: one at a time, batches of 8, one at a time with another seed (other hemicube
    // rotations: the scale of the aliasing noise that any change of shot order brings).
    std::vector<std::vector<glm::dvec3>> B;
    for (const auto& [batch, seed] : {std::pair{1, 1}, std::pair{8, 1}, std::pair{1, 2}}) {
        formfactor::OpenCLEngine engine(m, *ctx, {64, static_cast<std::uint64_t>(seed)});
        solve::Progressive solver(m, engine, {1e-4, 200000, batch});
        while (solver.step()) {
            const solve::Energy e = solver.energy();
            REQUIRE_THAT(e.absorbed + e.escaped + e.unshot, WithinRel(e.emitted, 1e-9));
        }
        CAPTURE(batch, solver.passes());
        REQUIRE(solver.converged());
        B.push_back(solver.radiosity(true));
        double flux = 0.0, emitted = 0.0;
        for (std::size_t k = 0; k < m.elements.size(); ++k) {
            flux += (B.back()[k].x + B.back()[k].y + B.back()[k].z) / 3.0 * m.elements[k].area;
            emitted += m.elements[k].emission.x * m.elements[k].area;
        }
        CHECK_THAT(flux, WithinRel(emitted / (1.0 - rho), 0.01));
    }
    // Element by element, flux-weighted: batching moves the solution no more than another
    // seed does (a bias from the order would show as a larger difference).
    const auto difference = [&](const std::vector<glm::dvec3>& a, const std::vector<glm::dvec3>& b) {
        double change = 0.0, total = 0.0;
        for (std::size_t k = 0; k < m.elements.size(); ++k) {
            change += std::abs(a[k].x - b[k].x) * m.elements[k].area;
            total += b[k].x * m.elements[k].area;
        }
        return change / total;
    };
    const double batching = difference(B[1], B[0]), reseeding = difference(B[2], B[0]);
    CAPTURE(batching, reseeding);
    CHECK(batching < 1e-2);
    CHECK(batching < 2.0 * reseeding);
}

TEST_CASE("opencl: the GPU kernels (setup per element, raster per cell) give the reference's cells too", "[opencl]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    // Whatever the device, run the tuning a GPU gets, so the kernels are checked where no GPU
    // is; and on a GPU, setup in lanes as CPUs run it. A closed box (several elements a patch,
    // the shooter's wall in its base plane) and procedural objects (patches below it).
    const std::vector<Case> cases = comparison_cases();
    for (const Case& c : {cases.front(), cases.back()}) {
        CAPTURE(c.name);
        const mesh::Mesh m = mesh::build(c.scene, c.mesh);
        formfactor::ReferenceEngine ref(m, {64, 2});
        const std::vector<formfactor::ShotRequest> requests{
            formfactor::ShotRequest::of_patch(0, 0), formfactor::ShotRequest::of_patch(3, 1),
            formfactor::ShotRequest::of_patch(static_cast<std::uint32_t>(m.patches.size() - 1), 2)};
        for (const bool setup_lanes : {false, true}) {
            formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
            tuning.raster_per_record = false;
            tuning.setup_lanes = setup_lanes;
            tuning.tile = 8;  // 64-item work-groups: within any device's limit
            formfactor::OpenCLEngine gpu_style(m, *ctx, {64, 2}, tuning);
            std::vector<formfactor::ShotResult> results;
            gpu_style.shoot_batch(requests, results);
            for (std::size_t i = 0; i < requests.size(); ++i) {
                formfactor::ShotResult want;
                ref.shoot(requests[i], want);
                CAPTURE(setup_lanes, i);
                CHECK(*gpu_style.last_ids(i) == *ref.last_ids());
                CHECK(formfactor::compare_shot(results[i], want).empty());
            }
        }
    }
}

TEST_CASE("opencl: PoCL's workers are pinned only where every worker's CPU is allowed", "[opencl][runtime]") {
    // No choice of the user's: pinned when this process may use exactly CPUs 0 .. online - 1.
    CHECK(ocl::should_pin_pocl_threads(nullptr, nullptr, nullptr, 2, 2, 2));
    CHECK(ocl::should_pin_pocl_threads(nullptr, "1", nullptr, 4, 4, 4));
    CHECK(ocl::should_pin_pocl_threads(nullptr, "4", nullptr, 4, 4, 4));
    // The user's POCL_AFFINITY (either way) or thread floor stands.
    CHECK_FALSE(ocl::should_pin_pocl_threads("0", nullptr, nullptr, 2, 2, 2));
    CHECK_FALSE(ocl::should_pin_pocl_threads("1", nullptr, nullptr, 2, 2, 2));
    CHECK_FALSE(ocl::should_pin_pocl_threads(nullptr, nullptr, "8", 2, 2, 2));
    // More workers than CPUs, or an unreadable count: a worker would ask for a CPU it cannot have.
    CHECK_FALSE(ocl::should_pin_pocl_threads(nullptr, "3", nullptr, 2, 2, 2));
    CHECK_FALSE(ocl::should_pin_pocl_threads(nullptr, "two", nullptr, 2, 2, 2));
    CHECK_FALSE(ocl::should_pin_pocl_threads(nullptr, "", nullptr, 2, 2, 2));
    // A restricted process (taskset, cgroup cpuset): CPU i may not be allowed for worker i.
    CHECK_FALSE(ocl::should_pin_pocl_threads(nullptr, nullptr, nullptr, 2, 2, 4));
    CHECK_FALSE(ocl::should_pin_pocl_threads(nullptr, nullptr, nullptr, 3, 2, 4));  // CPUs 0, 1, 3
    CHECK_FALSE(ocl::should_pin_pocl_threads(nullptr, nullptr, nullptr, 2, 1, 2));  // online 0 and 2, not 1
    CHECK_FALSE(ocl::should_pin_pocl_threads(nullptr, nullptr, nullptr, 0, 0, 0));
}

TEST_CASE("opencl: out of device memory, a batch runs again in smaller parts with the same results",
          "[opencl][faults]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const Case c = comparison_cases().back();
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    formfactor::OpenCLEngine whole(m, *ctx, {128, 5});
    formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
    std::vector<std::pair<std::size_t, std::size_t>> shrinks;  // (shots, limit)
    tuning.on_shrink = [&](std::size_t shots, std::size_t limit, const std::string& why) {
        shrinks.emplace_back(shots, limit);
        CHECK(why.find("CL_MEM_OBJECT_ALLOCATION_FAILURE") != std::string::npos);
    };
    formfactor::OpenCLFault fault;
    fault.oom_above = 2;  // buffers for three shots or more fail as out of memory
    formfactor::OpenCLEngine tight(m, *ctx, {128, 5}, tuning, fault);

    std::vector<formfactor::ShotRequest> requests;
    for (std::uint32_t i = 0; i < 7; ++i)
        requests.push_back(formfactor::ShotRequest::of_patch(static_cast<std::uint32_t>((3 * i) % m.patches.size()), 10u + i));
    std::vector<formfactor::ShotResult> want, got;
    whole.shoot_batch(requests, want);
    tight.shoot_batch(requests, got);
    // 7 fails, then 4 (halves, rounded up), and 2 fits: parts [0, 4) → [0, 2) [2, 4), [4, 7) → [4, 6) [6, 7).
    CHECK(shrinks == std::vector<std::pair<std::size_t, std::size_t>>{{7, 4}, {4, 2}});
    CHECK(tight.max_batch() == 2);
    REQUIRE(got.size() == requests.size());
    for (std::size_t i = 0; i < requests.size(); ++i) {
        CAPTURE(i);
        CHECK(got[i] == want[i]);
        CHECK(got[i].blocked == want[i].blocked);
    }
    // The id buffers kept are the last launch's: shot 6 alone.
    CHECK(tight.last_ids(5) == nullptr);
    REQUIRE(tight.last_ids(6) != nullptr);
    CHECK(*tight.last_ids(6) == *whole.last_ids(6));
    // Later batches start at the lowered limit: no new failure.
    tight.shoot_batch({requests[0], requests[1]}, got);
    CHECK(shrinks.size() == 2);
    CHECK(got[1] == want[1]);
}

TEST_CASE("opencl: a device that fails says so as a DeviceError, a wrong one is caught by comparison",
          "[opencl][faults]") {
    HEMIRAD_SKIP_ABSENT(test::first_opencl());
    ocl::Context* const ctx = test::first_opencl().context();
    const Case c = comparison_cases().back();
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    const formfactor::OpenCLTuning tuning = formfactor::default_tuning(ctx->info());
    formfactor::ShotResult got, want;
    formfactor::ReferenceEngine ref(m, {64, 5});
    ref.shoot(1, 2, want);

    formfactor::OpenCLFault none_fits;
    none_fits.oom_above = 0;  // not even the first shot's buffers
    CHECK_THROWS_WITH(formfactor::OpenCLEngine(m, *ctx, {64, 5}, tuning, none_fits),
                      Catch::Contains("cannot hold the mesh") && Catch::Contains("CL_MEM_OBJECT_ALLOCATION_FAILURE"));

    formfactor::OpenCLFault lost;
    lost.fail_after = 1;
    formfactor::OpenCLEngine failing(m, *ctx, {64, 5}, tuning, lost);
    failing.shoot(1, 2, got);
    CHECK(formfactor::compare_shot(got, want).empty());
    try {
        failing.shoot(1, 2, got);
        FAIL("the second launch should have failed");
    } catch (const ocl::DeviceError& e) {
        CHECK_THAT(e.what(), Catch::Contains(ctx->info().name) && Catch::Contains("CL_INVALID_COMMAND_QUEUE (-36)"));
    }

    formfactor::OpenCLFault wrong;
    wrong.wrong_after = 0;
    formfactor::OpenCLEngine lying(m, *ctx, {64, 5}, tuning, wrong);
    lying.shoot(1, 2, got);
    CHECK_THAT(formfactor::compare_shot(got, want), Catch::Contains("the reference says"));
}

TEST_CASE("opencl: HEMIRAD_FAULT's grammar", "[opencl][faults]") {
    const formfactor::OpenCLFault none = formfactor::parse_fault("");
    CHECK(none.oom_above == formfactor::OpenCLFault::kNever);
    CHECK(none.fail_after == formfactor::OpenCLFault::kNever);
    CHECK(none.wrong_after == formfactor::OpenCLFault::kNever);
    const formfactor::OpenCLFault both = formfactor::parse_fault("oom-above:3,wrong-after:0");
    CHECK(both.oom_above == 3);
    CHECK(both.wrong_after == 0);
    CHECK(both.fail_after == formfactor::OpenCLFault::kNever);
    for (const char* bad : {"oom-above", "oom-above:", "oom-above:-1", "lost:2", "fail-after:1x", "oom-above:1,"})
        CHECK_THROWS_AS(formfactor::parse_fault(bad), std::invalid_argument);
}

TEST_CASE("opencl: -D overrides of the host's knobs set its tuning, validated, and other options pass through", "[opencl]") {
    // No device needed: this is the parsing of HEMIRAD_OPENCL_OPTIONS' text.
    formfactor::OpenCLTuning t;
    t.extra_options = "-DKEEP=1";
    formfactor::apply_build_options(t, "  -DHEMIRAD_TILE=8 -cl-opt-disable -D HEMIRAD_COUNT_COPIES=64 -DHEMIRAD_WG=32 "
                                       "-DHEMIRAD_SCAN_WG=128 -DHEMIRAD_RASTER_WG=2 -DHEMIRAD_LANES=8 "
                                       "-DHEMIRAD_SETUP_LANES -DHEMIRAD_CULL=0 -D OTHER=3 -DClipPolygon=42");
    CHECK(t.tile == 8);
    CHECK(t.count_copies == 64);
    CHECK(t.work_group == 32);
    CHECK(t.scan_work_group == 128);
    CHECK(t.raster_work_group == 2);
    CHECK(t.lanes == 8);
    CHECK(t.setup_lanes);  // -DNAME alone is NAME=1, as the compiler reads it
    CHECK_FALSE(t.cull);
    // The knobs are the host's now (the engine passes them as -D); everything else is kept as it was.
    CHECK(t.extra_options == "-DKEEP=1 -cl-opt-disable -D OTHER=3 -DClipPolygon=42");
    CHECK(t.overrides.find("HEMIRAD_COUNT_COPIES=64") != std::string::npos);

    for (const std::string bad : {"-DHEMIRAD_TILE=3", "-DHEMIRAD_TILE=65", "-DHEMIRAD_TILE=", "-DHEMIRAD_TILE=0x8",
                                  "-DHEMIRAD_COUNT_COPIES=1000", "-DHEMIRAD_COUNT_COPIES=0", "-DHEMIRAD_SCAN_WG=96",
                                  "-DHEMIRAD_LANES=6", "-DHEMIRAD_CULL=2", "-DHEMIRAD_WG=2048", "-UHEMIRAD_TILE",
                                  "-U HEMIRAD_WG", "-DHEMIRAD_TILES=8", "-DHEMIRAD_TILE=99999999999"}) {
        INFO(bad);
        formfactor::OpenCLTuning u;
        try {
            formfactor::apply_build_options(u, bad);
            FAIL("accepted");
        } catch (const std::invalid_argument& e) {
            CHECK(std::string(e.what()).find(bad.substr(0, bad.find('='))) != std::string::npos);  // names the option
        }
        CHECK(u.tile == formfactor::OpenCLTuning{}.tile);  // nothing applied
    }
}
