// The Embree ray-casting peer (bench/) against the scalar reference (the analytic answers it
// owes, as every backend does: test_formfactor.cpp). Built
// only with Embree (HEMIRAD_HAVE_EMBREE). The rays go through the cell centres that the
// rasterizers test, so the two may differ only where float rounding moves a centre across an
// element's edge, and on genuine depth ties (which the reference gives the lower element id,
// and Embree to either).
#if HEMIRAD_HAVE_EMBREE
#include <algorithm>
#include <catch2/catch.hpp>

#include "formfactor/embree_engine.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "test_compare.h"
#include "test_scenes.h"

using namespace hemirad;
using Catch::Matchers::WithinAbs;
using Catch::Matchers::WithinRel;

namespace {

// The scene without the triangles of node `name`.
scene::Scene without_node(scene::Scene s, const std::string& name) {
    std::uint32_t node = 0;
    while (node < s.nodes.size() && s.nodes[node].name != name) ++node;
    s.triangles.erase(std::remove_if(s.triangles.begin(), s.triangles.end(),
                                     [node](const scene::Triangle& t) { return t.node == node; }),
                      s.triangles.end());
    return s;
}

}  // namespace

TEST_CASE("embree: id buffers and form factors match the reference but for rounding", "[embree]") {
    for (const test::Case& c : test::comparison_cases()) {
        // Without the z-fighting copy: every cell left has one right answer.
        const mesh::Mesh m = mesh::build(without_node(c.scene, "copy_b"), c.mesh);
        for (int n : {8, 40, 256}) {
            formfactor::ReferenceEngine ref(m, {n, 42});
            formfactor::EmbreeEngine rays(m, {n, 42});
            const test::Comparison r = test::compare(m, ref, rays, 20);
            INFO(c.name << ": " << m.patches.size() << " patches, " << m.elements.size() << " elements, N = " << n);
            CAPTURE(r.shots, r.cells, r.hit_cells, r.blocker_cells, r.mismatched_cells, r.worst_f, r.worst_total,
                    r.worst_l1);
            CHECK(r.hit_cells > r.cells / 10);
            if (c.name == "occluders") CHECK(r.blocker_cells > 0);
            // A centre within a float's rounding (~1e-7) of an edge: a few cells in a million.
            CHECK(r.mismatched_cells <= r.cells / 100000);
            CHECK(r.worst_l1 <= 1e-4);
            CHECK(r.worst_total <= 1e-9);  // the same cells hit, whoever wins them
        }
    }
}

TEST_CASE("embree: depth ties go to one of the tied elements", "[embree]") {
    const test::Case c = test::comparison_cases()[2];
    REQUIRE(c.name == "occluders");
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    std::uint32_t copy_a = 0;
    while (c.scene.nodes[copy_a].name != "copy_a") ++copy_a;
    formfactor::ReferenceEngine ref(m, {64, 5});
    formfactor::EmbreeEngine rays(m, {64, 5});
    double seen = 0.0;
    for (std::uint32_t patch = 0; patch < m.patches.size(); ++patch) {
        formfactor::ShotResult a, b;
        ref.shoot(patch, patch, a);
        rays.shoot(patch, patch, b);
        const double tied_ref = test::node_form_factor(m, a, copy_a) + test::node_form_factor(m, a, copy_a + 1);
        const double tied_rays = test::node_form_factor(m, b, copy_a) + test::node_form_factor(m, b, copy_a + 1);
        CHECK_THAT(tied_rays, WithinAbs(tied_ref, 1e-5));
        seen += tied_ref;
    }
    CHECK(seen > 0.1);  // the copies are in view of some shooters
}

// The analytic answers every backend owes, Embree among them (parallel and perpendicular squares,
// a closed box, the furnace), are test_formfactor.cpp's "every backend: ..." tests.

// A coaster lying on the floor of a closed unit box, `gap` above it: its underside (a patch
// facing down, node "coaster") sees the floor from `gap` away across its whole hemicube.
scene::Scene coaster_box(double gap) {
    scene::Scene s;
    const std::uint32_t grey = scene::add_material(s, glm::dvec3(0.7), glm::dvec3(0.0));
    const double a = 0.45, b = 0.55;
    scene::add_quad(s, {a, gap, a}, {b, gap, a}, {b, gap, b}, {a, gap, b}, grey, "coaster");  // normal −y
    return test::closed_box({1.0, 1.0, 1.0}, [&](int) { return grey; }, s);
}

// On the H200 `hemirad bench procedural:1M --engines opencl,embree` stopped with "form factors
// sum to 0.465 < 1 in a closed scene": a patch facing the floor from 4.2e-5 above it (8e-6 of the
// scene) cast its rays from a sphere of 1e-5 of the scene around its centre, through the floor,
// and out of the room. Not a race (one thread did the same): the rays now start at a height above
// the shooter's plane, as the reference clips, of 1e-6 of the scene.
TEST_CASE("embree: a shooter just above a surface it faces sees that surface, as the reference does", "[embree]") {
    for (const double gap : {8e-6, 2e-6}) {
        const mesh::Mesh m = mesh::build(coaster_box(gap), {0.25, 0.125});
        std::uint32_t coaster = 0;
        while (coaster < m.patches.size() && m.patches[coaster].normal.y > -0.5) ++coaster;
        REQUIRE(coaster < m.patches.size());
        REQUIRE_THAT(m.patches[coaster].centroid.y, WithinAbs(gap, 1e-12));
        for (const int n : {64, 256}) {
            formfactor::ReferenceEngine ref(m, {n, 3});
            formfactor::EmbreeEngine rays(m, {n, 3}, 2);
            formfactor::ShotResult expected, got;
            ref.shoot(coaster, 0, expected);
            rays.shoot(coaster, 0, got);
            INFO("gap " << gap << ", N = " << n);
            double sum = got.blocked;
            for (const double f : got.F) sum += f;
            CHECK_THAT(sum, WithinAbs(1.0, 1e-9));  // a closed box: every ray hits
            // Almost all of it on the floor (node "y0"), as the reference finds.
            const double floor_ref = test::node_form_factor(m, expected, 3), floor = test::node_form_factor(m, got, 3);
            CHECK(floor_ref > 0.99);
            CHECK_THAT(floor, WithinAbs(floor_ref, 1e-3));
        }
    }
}

TEST_CASE("embree: the same bits for any thread count, and a batch as its shots one at a time", "[embree]") {
    const test::Case c = test::comparison_cases().back();
    const mesh::Mesh m = mesh::build(c.scene, c.mesh);
    formfactor::EmbreeEngine one(m, {128, 9}, 1), three(m, {128, 9}, 3);
    std::vector<formfactor::ShotRequest> shots;
    std::vector<formfactor::ShotResult> singles;
    std::vector<std::int32_t> last_ids;
    for (std::uint32_t patch : {0u, 7u, 19u}) {
        formfactor::ShotResult a, b, again;
        one.shoot(patch, patch, a);
        three.shoot(patch, patch, b);
        three.shoot(patch, patch, again);
        CHECK(*one.last_ids() == *three.last_ids());
        // Tiles summed apart and added in tile order, whichever thread cast them.
        CHECK(a == b);
        CHECK(b == again);
        shots.push_back(formfactor::ShotRequest::of_patch(patch, patch));
        singles.push_back(a);
        last_ids = *one.last_ids();
    }
    std::vector<formfactor::ShotResult> batch;
    three.shoot_batch(shots, batch);
    REQUIRE(batch.size() == shots.size());
    for (std::size_t i = 0; i < shots.size(); ++i) {
        CHECK(batch[i] == singles[i]);
        CHECK(batch[i].blocked == singles[i].blocked);
    }
    REQUIRE(three.last_ids(shots.size() - 1) != nullptr);
    CHECK(*three.last_ids(shots.size() - 1) == last_ids);
    CHECK(three.last_ids(0) == nullptr);  // only the batch's last shot keeps its id buffer

    // Many more threads than cores (a 16-core machine's count on 2), a batch of 64 shots: the
    // bits of one thread shooting them one at a time.
    formfactor::EmbreeEngine sixteen(m, {128, 9}, 16);
    std::vector<formfactor::ShotRequest> many;
    std::vector<formfactor::ShotResult> alone(64);
    for (std::uint32_t i = 0; i < 64; ++i) {
        many.push_back(formfactor::ShotRequest::of_patch(static_cast<std::uint32_t>((i * 7919u) % m.patches.size()), i));
        one.shoot(many.back(), alone[i]);
    }
    for (int round = 0; round < 3; ++round) {
        sixteen.shoot_batch(many, batch);
        REQUIRE(batch.size() == many.size());
        for (std::size_t i = 0; i < many.size(); ++i) {
            CHECK(batch[i] == alone[i]);
            CHECK(batch[i].blocked == alone[i].blocked);
        }
    }
}
#endif
