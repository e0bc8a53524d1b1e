// The sparse final gather (solve/sparse_gather.h): its interpolation weights by hand, its light at
// the points it shoots against the full gather's, its floor under a lamp against the analytic
// irradiance, and a bake of the Cornell box against the path-traced reference.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "bake/bake.h"
#include "bench/image.h"
#include "formfactor/analytic.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "output/welded_mesh.h"
#include "reference_bake.h"
#include "scene/scene.h"
#include "solve/final_gather.h"
#include "solve/sparse_gather.h"
#include "test_scenes.h"

using namespace hemirad;
using namespace hemirad::test;

namespace {

// Two triangles (0, 1, 2) and (1, 3, 2) with 0 = (0,0), 1 = (1,0), 2 = (0,1), 3 = (1,2) in z = 0.
output::WeldedNode two_triangles() {
    output::WeldedNode node;
    node.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 2, 0}};
    node.normals.assign(4, glm::dvec3(0, 0, 1));
    node.radiosity.assign(4, glm::dvec3(0));
    node.indices = {0, 1, 2, 1, 3, 2};
    node.element = {0, 0};
    return node;
}

// A floor of 4 × 4 under a unit square lamp at height 1 (emitting 1), meshed in elements of
// `element`: the floor's irradiance at any point is the lamp's form factor from it.
struct LampFloor {
    scene::Scene s;
    mesh::Mesh m;
    std::vector<glm::dvec3> radiosity, irradiance;
    explicit LampFloor(double element) : s(lamp_scene(false)) {
        mesh::Settings ms;
        ms.patch_size = 4.0 * element;
        ms.element_size = element;
        m = mesh::build(s, ms);
        radiosity.resize(m.elements.size());
        irradiance.resize(m.elements.size());
        for (std::size_t k = 0; k < m.elements.size(); ++k) {
            radiosity[k] = m.elements[k].emission;
            // The elements' light as a solver leaves it: the exact value at the centroid.
            irradiance[k] = glm::dvec3(m.elements[k].emission.x > 0.0 ? 0.0 : exact(m.elements[k].centroid));
        }
    }
    static double exact(const glm::dvec3& p) { return formfactor::point_to_polygon(p, {0, 0, 1}, rectangle_at(1.5, 2.5, 1.5, 2.5, 1.0)); }
    std::size_t floor_node() const {
        for (std::size_t n = 0; n < s.nodes.size(); ++n)
            if (s.nodes[n].name == "floor") return n;
        FAIL("no floor");
        return 0;
    }
};

}  // namespace

TEST_CASE("sparse gather: Franke-Little weights along the mesh's edges, by hand", "[gather][sparse]") {
    const output::WeldedNode node = two_triangles();
    // Gathered: 0 and 3. Vertex 1 reaches 0 at 1 and 3 at 2 (directly; through 2 it is 2√2);
    // vertex 2 reaches 0 at 1 and 3 at √2.
    const solve::Interpolation w = solve::interpolation(node, {1, 0, 0, 1}, 3);
    REQUIRE(w.start.size() == 5);
    // A gathered vertex weighs itself alone.
    REQUIRE(w.start[1] - w.start[0] == 1);
    CHECK(w.source[w.start[0]] == 0);
    CHECK(w.weight[w.start[0]] == 1.0);
    REQUIRE(w.start[4] - w.start[3] == 1);
    CHECK(w.source[w.start[3]] == 3);
    // Fewer than K points: R is twice the farthest, R = 4 for vertex 1: ((4-1)/4)^2 = 0.5625 and
    // ((4-2)/8)^2 = 0.0625, normalized 0.9 and 0.1.
    REQUIRE(w.start[2] - w.start[1] == 2);
    CHECK(w.source[w.start[1]] == 0);
    CHECK(w.weight[w.start[1]] == Approx(0.9).epsilon(1e-14));
    CHECK(w.source[w.start[1] + 1] == 3);
    CHECK(w.weight[w.start[1] + 1] == Approx(0.1).epsilon(1e-14));
    // Vertex 2: R = 2√2, w0 = ((2√2 - 1)/(2√2))^2, w3 = ((2√2 - √2)/(2√2·√2))^2 = 1/8.
    const double R = 2.0 * std::sqrt(2.0), w0 = std::pow((R - 1.0) / R, 2.0), w3 = 0.125;
    REQUIRE(w.start[3] - w.start[2] == 2);
    CHECK(w.weight[w.start[2]] == Approx(w0 / (w0 + w3)).epsilon(1e-14));
    CHECK(w.weight[w.start[2] + 1] == Approx(w3 / (w0 + w3)).epsilon(1e-14));
    // With K = 2 each vertex has its two and R is the second's distance: the second weighs nothing.
    const solve::Interpolation two = solve::interpolation(node, {1, 0, 0, 1}, 2);
    REQUIRE(two.start[2] - two.start[1] == 1);
    CHECK(two.source[two.start[1]] == 0);
    CHECK(two.weight[two.start[1]] == 1.0);
    // Nothing gathered: no vertex has weights.
    const solve::Interpolation none = solve::interpolation(node, {0, 0, 0, 0}, 3);
    CHECK(none.source.empty());
}

TEST_CASE(
    "sparse gather: on a floor under a lamp, the shot points' light is the full gather's and the rest "
    "close to the analytic irradiance",
    "[gather][sparse]") {
    const LampFloor f(0.125);  // 32 × 32 floor elements: 1089 vertices
    const std::size_t node_count = f.s.nodes.size();
    const auto all = [](std::size_t) { return true; };
    const output::WeldedMesh welded = output::weld(node_count, f.m, f.radiosity);
    mesh::Mesh drawn = solve::gather_mesh(f.m);
    drawn.gather_points = solve::gather_points(welded, all);
    formfactor::ReferenceEngine engine(drawn, formfactor::Settings{128, 1});
    solve::GatherSettings settings;
    output::VertexLight full;
    REQUIRE(solve::final_gather(f.m, welded, all, f.radiosity, f.irradiance, {}, drawn, engine, settings, full));

    solve::SparseGatherSettings ss;
    ss.budget = 250;
    output::VertexLight sparse;
    const solve::SparseGathered sg =
        solve::sparse_gather(f.m, welded, all, f.radiosity, f.irradiance, {}, drawn, engine, settings, ss, sparse);
    const std::size_t n = f.floor_node();
    const output::WeldedNode& node = welded.nodes[n];
    CHECK(sg.points > 0);
    CHECK(sg.points <= 250);
    CHECK(sg.seeds <= sg.points);
    CHECK(sg.unreached == 0);
    CHECK(sg.vertices == node.positions.size() + welded.nodes[1 - n].positions.size());

    // Every vertex either keeps the full gather's light exactly (a shot point) or is interpolated.
    std::size_t same = 0;
    double err_sparse = 0.0, err_means = 0.0, err_full = 0.0, worst = 0.0;
    const output::VertexValues means = output::vertex_values(welded, f.m, f.irradiance);
    for (std::size_t v = 0; v < node.positions.size(); ++v) {
        if (sparse.irradiance[n][v] == full.irradiance[n][v]) ++same;
        const double exact = LampFloor::exact(node.positions[v]);
        const double e = sparse.irradiance[n][v].x - exact, m = means[n][v].x - exact;
        err_sparse += e * e;
        err_means += m * m;
        err_full += std::pow(full.irradiance[n][v].x - exact, 2.0);
        worst = std::max(worst, std::abs(e) / 0.2394564705);
        CHECK(sparse.radiosity[n][v].x == Approx(0.5 * sparse.irradiance[n][v].x).epsilon(1e-12));
    }
    const double rms_sparse = std::sqrt(err_sparse / double(node.positions.size())) / 0.2394564705;
    const double rms_means = std::sqrt(err_means / double(node.positions.size())) / 0.2394564705;
    const double rms_full = std::sqrt(err_full / double(node.positions.size())) / 0.2394564705;
    CAPTURE(same, rms_sparse, rms_means, rms_full, worst, sg.points, sg.levels);
    CHECK(same >= static_cast<std::size_t>(sg.points) - welded.nodes[1 - n].positions.size());
    // Of the peak irradiance: the element means, centroid values spread to vertices, are off by
    // the curvature of the light (0.22%), the full gather by its hemicube's aliasing (0.04%); the
    // sparse gather, shooting under a quarter of the vertices, comes between (0.14%).
    CHECK(rms_sparse < 0.75 * rms_means);
    CHECK(rms_sparse > rms_full);
    CHECK(worst < 0.01);

    // The same input, the same bytes.
    output::VertexLight again;
    solve::sparse_gather(f.m, welded, all, f.radiosity, f.irradiance, {}, drawn, engine, settings, ss, again);
    CHECK(again.irradiance == sparse.irradiance);
    CHECK(again.radiosity == sparse.radiosity);
}

TEST_CASE("sparse gather: the Cornell box with a third of its vertices shot, against the path-traced reference",
          "[gather][sparse][bake]") {
    // bench --accuracy's reference (an independent path tracer, bench/reference/cornell_box):
    // without a gather the default bake's pixels are 6.7% off, with the full gather 1.39%; a
    // sparse gather of 4,000 points of its 10,370 vertices must take most of the way.
    const auto bake_rms = [&](long points, int gather) {
        test::Against a = test::bake_against_reference("cornell_box", [&](bake::Options& o) {
            o.gather_points = points;
            o.gather = gather;
        });
        return std::pair(a.errors.rms, std::move(a.report));
    };
    const auto [none, none_report] = bake_rms(-1, 0);
    const auto [sparse, report] = bake_rms(4000, -1);
    CAPTURE(none, sparse, report["counts"]);
    const nlohmann::json& sg = report.at("counts").at("sparse_gather");
    CHECK(sg.at("budget") == 4000);
    CHECK(sg.at("points").get<long>() <= 4000);
    CHECK(sg.at("points").get<long>() > 3000);
    CHECK(sg.at("vertices").get<long>() > 10000);
    CHECK(sg.at("unreached") == 0);
    CHECK(report.at("counts").at("gather_points") == sg.at("points"));
    CHECK(report.at("settings").at("gather_points") == 4000);
    CHECK(none > 0.05);
    CHECK(sparse < 0.6 * none);
}

TEST_CASE("sparse gather: few points correcting many vertices never make light negative", "[gather][sparse][bake]") {
    // A vertex's light is its elements' plus the correction the points nearby make to theirs, a
    // difference, which exceeded the light of vertices in the dark: the Cornell box with 30 and
    // 100 points had pixels down to −0.0027.
    const std::filesystem::path root(HEMIRAD_SOURCE_DIR);
    const std::filesystem::path dir = std::filesystem::temp_directory_path() / "hemirad-test-sparse-negative";
    for (const long points : {30L, 100L}) {
        std::filesystem::remove_all(dir);
        bake::Options o;
        o.scene = (root / "scenes/cornell_box.gltf").string();
        o.output = dir.string();
        o.gather_points = points;
        o.image_width = 160;
        o.quiet = true;
        o.no_checkpoint = true;
        bake::run(o);
        int width = 0, height = 0;
        const std::vector<float> rgb = bench::read_rgb(dir / "render.exr", width, height);
        CAPTURE(points);
        CHECK(*std::min_element(rgb.begin(), rgb.end()) >= 0.0f);
        CHECK(*std::max_element(rgb.begin(), rgb.end()) > 0.0f);
    }
    std::filesystem::remove_all(dir);
}

TEST_CASE("sparse gather: a correction brightens by adding and darkens keeping the elements' hue", "[gather][sparse]") {
    const auto Y = [](const glm::dvec3& c) { return 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b; };
    // Brightening (luminance of the correction ≥ 0): added, channel by channel.
    const glm::dvec3 up = solve::corrected_light({0.2, 0.3, 0.4}, {0.1, -0.02, 0.2});  // luminance +0.0213
    CHECK(up.r == Approx(0.3).epsilon(1e-15));
    CHECK(up.g == Approx(0.28).epsilon(1e-15));
    CHECK(up.b == Approx(0.6).epsilon(1e-15));
    // A mild darkening that no channel's light falls below: the corrected luminance exactly, as
    // the sum would give it.
    const glm::dvec3 own{1.0, 0.5, 0.2}, mild{-0.1, -0.1, -0.1};
    CHECK(Y(solve::corrected_light(own, mild)) == Approx(Y(own) + Y(mild)).epsilon(1e-12));
    // Littlest Tokyo's wall: an orange light and a darkening larger than its green and blue. The
    // sum, clamped, is pure red (green 0); the correction keeps a green share of at least half
    // the elements' own.
    const glm::dvec3 orange{0.8, 0.3, 0.05}, dark{-0.3, -0.3, -0.3};
    const glm::dvec3 clamped = glm::max(orange + dark, glm::dvec3(0.0));
    CHECK(clamped.g == 0.0);
    const glm::dvec3 kept = solve::corrected_light(orange, dark);
    CHECK(kept.r > 0.0);
    CHECK(kept.g / kept.r > 0.5 * orange.g / orange.r);
    CHECK(kept.b / kept.r > 0.5 * orange.b / orange.r);
    // A darkening of all the light or more leaves none.
    CHECK(solve::corrected_light(orange, {-1.0, -1.0, -1.0}) == glm::dvec3(0.0));
    // Continuous where the correction's luminance changes sign.
    const glm::dvec3 tilt{0.05, -0.02, 0.01};  // luminance 0.010632 - 0.014304 + 0.000722 < 0
    const double y0 = Y(tilt);
    REQUIRE(y0 < 0.0);
    const glm::dvec3 pos = tilt + glm::dvec3(1e-9 - y0), neg = tilt + glm::dvec3(-1e-9 - y0);
    REQUIRE(Y(pos) > 0.0);
    REQUIRE(Y(neg) < 0.0);
    const glm::dvec3 a = solve::corrected_light(own, pos), b = solve::corrected_light(own, neg);
    CHECK(glm::length(a - b) < 1e-7);
    // Never below zero, on any channel (seeded pairs of lights and corrections).
    std::uint64_t state = 12345;
    const auto next = [&] {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return double(state >> 11) / double(1ull << 53);
    };
    for (int i = 0; i < 10000; ++i) {
        const glm::dvec3 l{next(), next(), next()}, c{4.0 * next() - 2.0, 4.0 * next() - 2.0, 4.0 * next() - 2.0};
        const glm::dvec3 h = solve::corrected_light(l * l * l, c);
        CHECK((h.r >= 0.0 && h.g >= 0.0 && h.b >= 0.0));
    }
}

TEST_CASE(
    "sparse gather: the leaf canopy with a point a card, and with the budget left spread, against the "
    "path-traced reference",
    "[gather][sparse][bake]") {
    // 508 double-sided cards, each a surface of its own (bench/reference/leaf_canopy), 9,327
    // vertices; every vertex gathered: 1.67% per pixel.
    // - 1,000 points give most card sides one seed, whose correction then stands for the card. The
    //   seed nearest the grid cell's centre was mostly a card's rim vertex, in its neighbours'
    //   shade: 8.2% per pixel, the whole picture 6.4% dark (at 300 points: 6.7%, 3.3%). The seed
    //   nearest the area centroid of its piece of surface: 5.6%, 1.1% light (with a shooter a card;
    //   joined across the gaps, the default since, 6.2%, 1.1% light).
    // - 4,000 points: the levels found nothing in doubt on a card of one point and shot 1,146
    //   (5.7%); the budget they leave spread over the cards: 3,910 points, 3.7% (joined: 3.8%).
    for (const long points : {1000L, 4000L}) {
        const test::Against a =
            test::bake_against_reference("leaf_canopy", [&](bake::Options& o) { o.gather_points = points; });
        const bench::PixelErrors& e = a.errors;
        const nlohmann::json& sg = a.report.at("counts").at("sparse_gather");
        CAPTURE(points, e.rms, e.mean, sg);
        CHECK(sg.at("points").get<long>() > 9 * points / 10);
        CHECK(sg.at("points").get<long>() <= points);
        CHECK(e.rms < (points == 1000 ? 0.065 : 0.045));
        CHECK(std::abs(e.mean) < 0.02);
        if (points == 4000) CHECK(sg.at("covered").get<long>() > 2000);
    }
}
