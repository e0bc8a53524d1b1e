// Tests for the content-like benchmark scenes (city, furniture, foliage): triangle counts, same
// bytes for the same seed, a closed shell and an emitter, specs, and `hemirad scene write` files
// that load back whole.
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "cli_support.h"
#include "core/error.h"
#include "gen/content_scenes.h"
#include "scene/writer.h"
#include "test_scenes.h"

using glm::dvec3;
using hemirad::InputError;
using hemirad::gen::ContentKind;
using hemirad::gen::content_scene;
using hemirad::gen::parse_content_spec;
using hemirad::scene::Scene;
using hemirad::scene::Triangle;
namespace test = hemirad::test;

namespace {

const std::array<ContentKind, 3> kKinds{ContentKind::kCity, ContentKind::kFurniture, ContentKind::kFoliage};

double relative_error(std::size_t got, std::size_t wanted) {
    return std::abs(double(got) - double(wanted)) / double(wanted);
}

dvec3 normal_of(const Triangle& t) {
    return glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]);
}

// Empty when every directed edge a→b of the triangles is matched by exactly one b→a: a closed,
// consistently oriented surface sharing bit-identical vertices. Else the first problem.
std::string closure_problem(const std::vector<const Triangle*>& surface) {
    using Key = std::array<double, 3>;
    const auto key = [](const dvec3& p) { return Key{p.x, p.y, p.z}; };
    std::map<std::pair<Key, Key>, int> directed;
    for (const Triangle* t : surface)
        for (std::size_t k = 0; k < 3; ++k) ++directed[{key(t->p[k]), key(t->p[(k + 1) % 3])}];
    for (const auto& [edge, count] : directed) {
        if (count != 1) return "an edge is used " + std::to_string(count) + " times in one direction";
        if (!directed.count({edge.second, edge.first})) return "an edge has no opposite (a hole or flipped triangle)";
    }
    return {};
}

}  // namespace

TEST_CASE("content scenes have the requested triangle count within 3%", "[content]") {
    for (const ContentKind kind : kKinds)
        for (const std::size_t n : {10'000u, 100'000u}) {
            const Scene s = content_scene(kind, n);
            INFO(s.path.string() << ": " << s.triangles.size() << " triangles");
            CHECK(relative_error(s.triangles.size(), n) <= 0.03);
        }
    CHECK(content_scene(ContentKind::kCity, 100'000).path.string() == "city:100k");
    CHECK(content_scene(ContentKind::kFoliage, 12'345).path.string() == "foliage:12345");
}

TEST_CASE("content scenes are deterministic, and the seed changes them", "[content]") {
    for (const ContentKind kind : kKinds) {
        const Scene a = content_scene(kind, 20'000, 3), b = content_scene(kind, 20'000, 3);
        const Scene c = content_scene(kind, 20'000, 4);
        INFO(a.path.string());
        CHECK(test::same_triangles(a, b));
        CHECK_FALSE(test::same_triangles(a, c));
        CHECK(relative_error(c.triangles.size(), 20'000) <= 0.03);
    }
    // The same bytes on the disk, too.
    test::TempDir dir;
    hemirad::scene::write_gltf(content_scene(ContentKind::kCity, 10'000, 5), dir / "a.glb");
    hemirad::scene::write_gltf(content_scene(ContentKind::kCity, 10'000, 5), dir / "b.glb");
    const std::string a = test::read_text(dir / "a.glb");
    CHECK(a.size() > 100'000);
    CHECK(a == test::read_text(dir / "b.glb"));
}

TEST_CASE("content scenes have emitters, and the room kinds are closed", "[content]") {
    for (const ContentKind kind : kKinds) {
        const Scene s = content_scene(kind, 10'000);
        INFO(s.path.string());
        CHECK(hemirad::gen::content_kind_closed(kind) == (kind != ContentKind::kCity));
        std::vector<const Triangle*> shell;
        std::size_t emitting = 0, down = 0, degenerate = 0;
        for (const Triangle& t : s.triangles) {
            if (t.node == 0) shell.push_back(&t);
            const double area = 0.5 * glm::length(normal_of(t));
            if (!(area > 1e-9)) ++degenerate;
            if (s.materials[t.material].emission != dvec3(0.0)) {
                ++emitting;
                if (glm::normalize(normal_of(t)).y < -0.999) ++down;  // every emitter lights from above
            }
        }
        CHECK(degenerate == 0);
        CHECK(emitting > 0);
        CHECK(down == emitting);
        CHECK(s.cameras.size() == 1);
        if (kind == ContentKind::kCity) {
            // Open: the sky lid (node 1) spans the whole city from above, facing the ground.
            double lid = 0.0;
            for (const Triangle& t : s.triangles)
                if (t.node == 1) lid += 0.5 * glm::length(normal_of(t));
            CHECK(lid == Approx((s.bbox_max.x - s.bbox_min.x) * (s.bbox_max.z - s.bbox_min.z)).epsilon(1e-9));
        } else {
            // Node 0 is the room or courtyard, closed and facing in; everything lies inside it.
            CHECK(closure_problem(shell).empty());
            const dvec3 centre = 0.5 * (s.bbox_min + s.bbox_max);
            for (const Triangle* t : shell) CHECK(glm::dot(normal_of(*t), centre - t->p[0]) > 0.0);
        }
    }
}

TEST_CASE("foliage cards are double-sided, everything else is not", "[content]") {
    const Scene s = content_scene(ContentKind::kFoliage, 10'000);
    std::size_t two_sided = 0;
    for (const Triangle& t : s.triangles) two_sided += s.materials[t.material].double_sided;
    CHECK(two_sided > s.triangles.size() / 2);  // most triangles are leaf and grass cards
    for (const ContentKind kind : {ContentKind::kCity, ContentKind::kFurniture})
        for (const auto& m : content_scene(kind, 10'000).materials) CHECK_FALSE(m.double_sided);
}

TEST_CASE("parse_content_spec", "[content]") {
    const auto city = parse_content_spec("city:150k");
    REQUIRE(city);
    CHECK(city->kind == ContentKind::kCity);
    CHECK(city->triangles == 150'000u);
    CHECK(parse_content_spec("furniture:2.5M")->triangles == 2'500'000u);
    CHECK(parse_content_spec("foliage:1M")->kind == ContentKind::kFoliage);
    CHECK_FALSE(parse_content_spec("procedural:1M"));
    CHECK_FALSE(parse_content_spec("scenes/city.glb"));
    CHECK_THROWS_AS(parse_content_spec("city:abc"), InputError);
    CHECK_THROWS_AS(parse_content_spec("foliage:0"), InputError);
    CHECK_THROWS_AS(parse_content_spec("furniture:51M"), InputError);
    bool closed = true;
    CHECK(hemirad::gen::generated_scene("city:1000", &closed));
    CHECK_FALSE(closed);
    CHECK(hemirad::gen::generated_scene("procedural:1000", &closed));
    CHECK(closed);
    CHECK_FALSE(hemirad::gen::generated_scene("scene.gltf"));
}

TEST_CASE("hemirad scene write: the file loads back with the same triangles", "[content][cli]") {
    test::TempDir dir;
    for (const std::string spec : {"city:10k", "furniture:10k", "foliage:10k"}) {
        INFO(spec);
        const test::RunResult r = test::run_hemirad(dir, {"scene", "write", spec, "scene.glb"});
        INFO(r.err);
        REQUIRE(r.code == 0);
        const Scene generated = *hemirad::gen::generated_scene(spec);
        const Scene loaded = hemirad::scene::load(dir / "scene.glb");
        CHECK(loaded.triangles.size() == generated.triangles.size());
        CHECK(loaded.materials.size() == generated.materials.size());
        REQUIRE(loaded.cameras.size() == 1);
        CHECK(loaded.cameras[0].name == generated.cameras[0].name);
        std::size_t emitting = 0;
        for (const Triangle& t : loaded.triangles) emitting += loaded.materials[t.material].emission != dvec3(0.0);
        CHECK(emitting > 0);
        CHECK(r.out.find(std::to_string(generated.triangles.size()) + " triangles") != std::string::npos);
    }
    CHECK(test::run_hemirad(dir, {"scene", "write", "city:abc", "x.glb"}).code == 2);
    CHECK(test::run_hemirad(dir, {"scene", "write", "cornell.gltf", "x.glb"}).code == 2);
    CHECK(test::run_hemirad(dir, {"scene", "write", "city:1k", "x.obj"}).code == 2);
}
