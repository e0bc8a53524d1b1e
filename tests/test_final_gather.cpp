// The final gather (solve/final_gather.h): analytic values at vertices, a closed box's uniform
// light, and the same light on every engine.
#include <catch2/catch.hpp>

#include <cmath>
#include <optional>

#include "cl/runtime.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "formfactor/unoccluded.h"
#include "mesh/mesh.h"
#include "output/welded_mesh.h"
#include "scene/scene.h"
#include "solve/final_gather.h"
#include "test_scenes.h"

using namespace hemirad;
using namespace hemirad::test;

namespace {

struct Gathered {
    output::WeldedMesh welded;
    output::VertexLight light;
};

// Gathers `radiosity` (per element) at every vertex of `m` with the engine `make` builds for the
// drawn mesh.
template <class Make>
Gathered gather(const scene::Scene& s, const mesh::Mesh& m, const std::vector<glm::dvec3>& radiosity, Make make,
                int passes = 1, std::size_t kept_entries = solve::kMaxKeptEntries) {
    Gathered g;
    g.welded = output::weld(s.nodes.size(), m, radiosity);
    const auto all = [](std::size_t) { return true; };
    mesh::Mesh drawn = solve::gather_mesh(m);
    drawn.gather_points = solve::gather_points(g.welded, all);
    auto engine = make(drawn);
    solve::GatherSettings settings;
    settings.passes = passes;
    settings.kept_entries = kept_entries;
    const std::vector<glm::dvec3> irradiance(m.elements.size(), glm::dvec3(0.0));
    REQUIRE(solve::final_gather(m, g.welded, all, radiosity, irradiance, {}, drawn, *engine, settings, g.light));
    return g;
}

// Counts the rows an engine is asked for.
class CountingEngine : public formfactor::Engine {
public:
    CountingEngine(std::unique_ptr<formfactor::Engine> inner, long& shots) : inner_(std::move(inner)), shots_(shots) {}
    std::string name() const override { return inner_->name(); }
    void shoot(const formfactor::ShotRequest& request, formfactor::ShotResult& out) override {
        ++shots_;
        inner_->shoot(request, out);
    }
    void shoot_batch(const std::vector<formfactor::ShotRequest>& shots, std::vector<formfactor::ShotResult>& out) override {
        shots_ += static_cast<long>(shots.size());
        inner_->shoot_batch(shots, out);
    }

private:
    std::unique_ptr<formfactor::Engine> inner_;
    long& shots_;
};

// The Cornell box meshed coarsely, with any field of radiosity: the emitters' light plus a
// pattern over the elements.
struct PatternedCornell {
    scene::Scene scene = scene::load(std::filesystem::path(HEMIRAD_SOURCE_DIR) / "scenes" / "cornell_box.gltf");
    mesh::Mesh mesh = mesh::build(scene, mesh::Settings{0.12, 0.04});
    std::vector<glm::dvec3> radiosity;
    PatternedCornell() : radiosity(mesh.elements.size()) {
        for (std::size_t k = 0; k < mesh.elements.size(); ++k)
            radiosity[k] = mesh.elements[k].emission + glm::dvec3(0.01 * double(k % 7), 0.02 * double(k % 3), 0.005);
    }
};

std::optional<ocl::Context> first_device() {
    const auto devices = ocl::list_devices();
    if (devices.empty()) return std::nullopt;
    return std::optional<ocl::Context>(std::in_place, devices.front());
}

}  // namespace

TEST_CASE("final gather: a vertex under a square lamp gathers the analytic form factor", "[gather]") {
    // REFERENCES.md: a point 1 below the centre of a unit square facing it, F = 0.2394564705. The
    // lamp emits 1 and nothing else shines, so the floor vertex under its centre must gather
    // exactly that irradiance, and its radiosity ρ times it.
    scene::Scene s;
    const std::uint32_t floor = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    const std::uint32_t lamp = add_material(s, glm::dvec3(0.0), glm::dvec3(1.0));
    add_quad(s, {0, 0, 0}, {4, 0, 0}, {4, 4, 0}, {0, 4, 0}, floor, "floor");
    add_quad(s, {1.5, 1.5, 1}, {1.5, 2.5, 1}, {2.5, 2.5, 1}, {2.5, 1.5, 1}, lamp, "lamp");
    finish(s);
    mesh::Settings ms;
    ms.patch_size = 0.5;
    ms.element_size = 0.25;
    const mesh::Mesh m = mesh::build(s, ms);
    std::vector<glm::dvec3> radiosity(m.elements.size(), glm::dvec3(0.0));
    for (std::size_t k = 0; k < m.elements.size(); ++k) radiosity[k] = m.elements[k].emission;

    const auto check = [&](const Gathered& g, double tolerance) {
        const output::WeldedNode& node = g.welded.nodes[0];
        int found = 0;
        for (std::size_t v = 0; v < node.positions.size(); ++v) {
            if (glm::length(node.positions[v] - glm::dvec3(2, 2, 0)) > 1e-12) continue;
            ++found;
            const double h = g.light.irradiance[0][v].x;
            CAPTURE(h);
            CHECK(std::abs(h / 0.2394564705 - 1.0) < tolerance);
            CHECK(g.light.radiosity[0][v].x == Approx(0.5 * h).epsilon(1e-12));
        }
        CHECK(found == 1);
    };
    SECTION("hemicube (reference engine)") {
        check(gather(s, m, radiosity, [](const mesh::Mesh& d) {
                  return std::make_unique<formfactor::ReferenceEngine>(d, formfactor::Settings{128, 1});
              }),
              2e-3);
    }
    SECTION("exact unoccluded form factors") {
        check(gather(s, m, radiosity, [](const mesh::Mesh& d) { return std::make_unique<formfactor::UnoccludedEngine>(d); }),
              1e-4);
    }
}

TEST_CASE("final gather: every vertex of a closed box of uniform radiosity gathers it back", "[gather]") {
    // Inside a closed box the form factors from any point sum to 1, so radiosity 1 everywhere (the
    // exact solution for E = 0.4, ρ = 0.6) must gather irradiance 1 at every vertex: corners and
    // edges (the neighbouring walls drawn close by, each cell weighed by its elements), and after a
    // second pass, which draws the first pass's E + ρH, too.
    scene::Scene s;
    const std::uint32_t grey = add_material(s, glm::dvec3(0.6), glm::dvec3(0.4));
    s = closed_box({1.0, 0.8, 1.2}, [&](int) { return grey; }, s);
    mesh::Settings ms;
    ms.patch_size = 0.25;
    ms.element_size = 0.1;
    const mesh::Mesh m = mesh::build(s, ms);
    const std::vector<glm::dvec3> radiosity(m.elements.size(), glm::dvec3(1.0));
    const auto check = [&](const Gathered& g, double tolerance) {
        double worst = 0.0;
        long vertices = 0;
        for (std::size_t n = 0; n < g.welded.nodes.size(); ++n) {
            for (std::size_t v = 0; v < g.welded.nodes[n].positions.size(); ++v) {
                worst = std::max(worst, std::abs(g.light.irradiance[n][v].x - 1.0));
                CHECK(g.light.radiosity[n][v].y == Approx(0.4 + 0.6 * g.light.irradiance[n][v].y).epsilon(1e-12));
                ++vertices;
            }
        }
        CAPTURE(worst, vertices);
        CHECK(vertices > 300);
        CHECK(worst < tolerance);
    };
    SECTION("hemicube (reference engine), two passes") {
        check(gather(
                  s, m, radiosity,
                  [](const mesh::Mesh& d) { return std::make_unique<formfactor::ReferenceEngine>(d, formfactor::Settings{32, 3}); },
                  2),
              1e-9);
    }
    SECTION("exact unoccluded form factors") {
        check(gather(s, m, radiosity, [](const mesh::Mesh& d) { return std::make_unique<formfactor::UnoccludedEngine>(d); }),
              1e-6);
    }
}

TEST_CASE("final gather: the OpenCL engine gathers the reference's light, bit for bit", "[gather][opencl]") {
    auto ctx = first_device();
    if (!ctx) {
        WARN("no OpenCL device: skipped");
        return;
    }
    const PatternedCornell c;
    const scene::Scene& s = c.scene;
    const mesh::Mesh& m = c.mesh;
    const std::vector<glm::dvec3>& radiosity = c.radiosity;
    const Gathered ref = gather(
        s, m, radiosity,
        [](const mesh::Mesh& d) { return std::make_unique<formfactor::ReferenceEngine>(d, formfactor::Settings{48, 9}); }, 2);
    const Gathered cl = gather(
        s, m, radiosity,
        [&](const mesh::Mesh& d) { return std::make_unique<formfactor::OpenCLEngine>(d, *ctx, formfactor::Settings{48, 9}); },
        2);
    long vertices = 0;
    for (std::size_t n = 0; n < ref.welded.nodes.size(); ++n) {
        REQUIRE(cl.light.irradiance[n].size() == ref.light.irradiance[n].size());
        for (std::size_t v = 0; v < ref.light.irradiance[n].size(); ++v) {
            CHECK(cl.light.irradiance[n][v] == ref.light.irradiance[n][v]);
            CHECK(cl.light.radiosity[n][v] == ref.light.radiosity[n][v]);
            ++vertices;
        }
    }
    CHECK(vertices > 500);
}

TEST_CASE("final gather: later passes re-use the first pass's rows and gather what shooting again gives", "[gather]") {
    // Every pass shoots the same points with the same frames at the same drawn mesh, so the rows
    // kept from the first pass must give the later passes bit for bit the light that shooting them
    // again gives, with all rows kept, none, or some (the rest shot again).
    const PatternedCornell c;
    const scene::Scene& s = c.scene;
    const mesh::Mesh& m = c.mesh;
    const std::vector<glm::dvec3>& radiosity = c.radiosity;
    const auto run = [&](std::size_t kept_entries, long& shots) {
        return gather(
            s, m, radiosity,
            [&](const mesh::Mesh& d) {
                return std::make_unique<CountingEngine>(
                    std::make_unique<formfactor::ReferenceEngine>(d, formfactor::Settings{32, 5}), shots);
            },
            3, kept_entries);
    };
    long all_shots = 0, none_shots = 0, some_shots = 0;
    const Gathered all = run(solve::kMaxKeptEntries, all_shots);
    const Gathered none = run(0, none_shots);
    const Gathered some = run(20000, some_shots);
    long points = 0;
    for (std::size_t n = 0; n < all.welded.nodes.size(); ++n) points += static_cast<long>(all.welded.nodes[n].positions.size());
    CHECK(all_shots == points);
    CHECK(none_shots == 3 * points);
    CHECK(some_shots > points);
    CHECK(some_shots < 3 * points);
    for (std::size_t n = 0; n < all.welded.nodes.size(); ++n) {
        for (std::size_t v = 0; v < all.light.irradiance[n].size(); ++v) {
            CHECK(all.light.irradiance[n][v] == none.light.irradiance[n][v]);
            CHECK(all.light.radiosity[n][v] == none.light.radiosity[n][v]);
            CHECK(some.light.radiosity[n][v] == none.light.radiosity[n][v]);
        }
    }
}
