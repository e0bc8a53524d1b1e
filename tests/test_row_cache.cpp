// The form-factor row memo (formfactor::RowCacheEngine) and the progressive solver's repeated
// shots: a kept row is the engine's row bit for bit, the budget decides only how often a row is
// shot, and a patch's later shots cycle through the counters of its first few, also across a
// resume.
#include <catch2/catch.hpp>

#include <map>
#include <sstream>

#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "formfactor/row_cache.h"
#include "mesh/mesh.h"
#include "solve/progressive.h"
#include "test_scenes.h"

using namespace hemirad;

namespace {

// Passes shots on to the reference engine and counts them, by request.
class CountingEngine final : public formfactor::Engine {
public:
    CountingEngine(const mesh::Mesh& m, std::map<std::pair<std::uint32_t, std::uint64_t>, int>& counts)
        : inner_(m, formfactor::Settings{32, 5}), counts_(counts) {}
    std::string name() const override { return "counting"; }
    using formfactor::Engine::shoot;
    void shoot(const formfactor::ShotRequest& request, formfactor::ShotResult& out) override {
        ++counts_[{request.shooter.patch, request.shot}];
        inner_.shoot(request, out);
    }

private:
    formfactor::ReferenceEngine inner_;
    std::map<std::pair<std::uint32_t, std::uint64_t>, int>& counts_;
};

mesh::Mesh lit_box(double rho) {
    scene::Scene s;
    const auto wall = test::add_material(s, glm::dvec3(rho, 0.8 * rho, 0.6 * rho), glm::dvec3(0.0));
    const auto light = test::add_material(s, glm::dvec3(0.5), glm::dvec3(3.0, 2.0, 1.0));
    s = test::closed_box({1.0, 0.8, 1.2}, [&](int face) { return face == 3 ? light : wall; }, s);
    return mesh::build(s, {0.3, 0.15});
}

using Counts = std::map<std::pair<std::uint32_t, std::uint64_t>, int>;

formfactor::RowCacheEngine memo(const mesh::Mesh& m, Counts& counts, double budget) {
    return formfactor::RowCacheEngine(std::make_unique<CountingEngine>(m, counts), budget);
}

}  // namespace

TEST_CASE("the row memo keeps the rows of shooters that come back, and every answer is the engine's row", "[row_cache]") {
    const mesh::Mesh m = lit_box(0.7);
    formfactor::ReferenceEngine direct(m, formfactor::Settings{32, 5});
    Counts counts;
    formfactor::RowCacheEngine cache = memo(m, counts, 1e9);
    const std::vector<formfactor::ShotRequest> batch = {formfactor::ShotRequest::of_patch(0, 10),
                                                        formfactor::ShotRequest::of_patch(3, 11),
                                                        formfactor::ShotRequest::of_patch(0, 12)};
    for (int round = 0; round < 4; ++round) {
        std::vector<formfactor::ShotResult> out;
        cache.shoot_batch(batch, out);
        REQUIRE(out.size() == batch.size());
        for (std::size_t i = 0; i < batch.size(); ++i) {
            formfactor::ShotResult expected;
            direct.shoot(batch[i], expected);
            CHECK(out[i] == expected);  // element lists, form factors and blocked share, bit for bit
            CHECK(out[i].size() > 0);
        }
    }
    // A shooter's first request is not kept: patch 0's first row and patch 3's are shot again in
    // the second round, then kept; patch 0's second row (a second rotation) was kept at once.
    CHECK(counts.size() == 3);
    CHECK(counts[{0, 10}] == 2);
    CHECK(counts[{3, 11}] == 2);
    CHECK(counts[{0, 12}] == 1);
    CHECK(cache.stats().requests == 12);
    CHECK(cache.stats().hits == 7);
    CHECK(cache.stats().shot == 5);
    CHECK(cache.stats().kept == 3);
    CHECK(cache.stats().dropped == 0);
    CHECK(cache.stats().peak_bytes > 0.0);
}

TEST_CASE("over its budget the row memo drops the least recently used row, and shoots it again to the same bits", "[row_cache]") {
    const mesh::Mesh m = lit_box(0.7);
    formfactor::ReferenceEngine direct(m, formfactor::Settings{32, 5});
    double all_three = 0.0;
    for (std::uint32_t p = 0; p < 3; ++p) {
        formfactor::ShotResult row;
        direct.shoot(p, 20 + p, row);
        row.element.shrink_to_fit();  // as kept
        row.F.shrink_to_fit();
        all_three += formfactor::RowCacheEngine::row_bytes(row);
    }
    Counts counts;
    const double budget = all_three - 1.0;  // room for any two rows, not all three
    formfactor::RowCacheEngine cache = memo(m, counts, budget);
    const auto ask = [&](std::uint32_t p) {
        formfactor::ShotResult out, expected;
        cache.shoot(formfactor::ShotRequest::of_patch(p, 20 + p), out);
        direct.shoot(p, 20 + p, expected);
        CHECK(out == expected);
    };
    for (std::uint32_t p = 0; p < 3; ++p) {  // each shooter seen once, under another counter
        formfactor::ShotResult out;
        cache.shoot(formfactor::ShotRequest::of_patch(p, 100 + p), out);
    }
    CHECK(cache.stats().kept == 0);
    for (std::uint32_t p = 0; p < 3; ++p) {
        ask(p);
        ask(p);  // kept; the third keeps out the first
    }
    CHECK(cache.stats().dropped == 1);
    CHECK(cache.stats().peak_bytes <= budget);
    for (std::uint32_t p = 1; p < 3; ++p) CHECK(counts[{p, 20 + p}] == 1);
    ask(2);  // still kept
    CHECK(counts[{2, 22}] == 1);
    ask(0);  // dropped: shot again and kept, dropping the least recently used (1)
    CHECK(counts[{0, 20}] == 2);
    ask(1);
    CHECK(counts[{1, 21}] == 2);
    CHECK(cache.stats().dropped == 3);
}

TEST_CASE("progressive: a patch's later shots cycle through its first rotations, and the memo changes no bit", "[row_cache][solver]") {
    // Reflectance 0.95: light goes round the box many times, so patches shoot many times.
    const mesh::Mesh m = lit_box(0.95);
    const auto solve = [&](double budget, bool with_memo, Counts& counts) {
        std::unique_ptr<formfactor::Engine> engine = std::make_unique<CountingEngine>(m, counts);
        if (with_memo) engine = std::make_unique<formfactor::RowCacheEngine>(std::move(engine), budget);
        solve::Progressive solver(m, *engine, {1e-3, 100000});
        while (solver.step()) {
        }
        REQUIRE(solver.converged());
        return std::make_pair(solver.radiosity(true), solver.passes());
    };
    Counts plain, none, all;
    const auto [b_plain, passes] = solve(0.0, false, plain);
    const auto [b_none, passes_none] = solve(0.0, true, none);
    const auto [b_all, passes_all] = solve(1e9, true, all);
    CHECK(passes_none == passes);
    CHECK(passes_all == passes);
    CHECK(b_none == b_plain);
    CHECK(b_all == b_plain);

    // Without the memo every pass is a shot. A patch's requests carry at most
    // Settings::rotations counters, each some pass's own, so no two patches share one; a patch
    // that shot more often than that repeated its rows.
    const long rotations = solve::Settings{}.rotations;
    long shots = 0, repeating = 0;
    std::map<std::uint32_t, std::pair<long, long>> per_patch;  // counters, shots
    std::map<std::uint64_t, int> owners;
    for (const auto& [request, n] : plain) {
        shots += n;
        ++per_patch[request.first].first;
        per_patch[request.first].second += n;
        ++owners[request.second];
        CHECK(request.second < static_cast<std::uint64_t>(passes));
    }
    CHECK(shots == passes);
    for (const auto& [patch, c] : per_patch) {
        CHECK(c.first == std::min(c.second, rotations));
        repeating += c.second > rotations;
    }
    CHECK(repeating > 0);
    for (const auto& [counter, n] : owners) CHECK(n == 1);
    // With room for every row, the memo shoots each request once, or twice where it was a
    // shooter's first (not kept, in case the patch never came back).
    long memo_shots = 0;
    for (const auto& [request, n] : all) {
        CHECK(n <= 2);
        memo_shots += n;
    }
    CAPTURE(passes, memo_shots);
    CHECK(memo_shots * 2 < passes);
}

TEST_CASE("progressive: a resumed solve shoots its patches under the same counters as one that ran through", "[row_cache][solver]") {
    const mesh::Mesh m = lit_box(0.9);
    Counts counts;
    formfactor::RowCacheEngine through_engine = memo(m, counts, 1e9);
    solve::Progressive through(m, through_engine, {1e-4, 100000});
    std::stringstream state;
    for (int pass = 0; pass < 60 && through.step(); ++pass) {
    }
    through.save(state);
    while (through.step()) {
    }
    REQUIRE(through.converged());

    // A new solver and a new, empty memo from the saved state: the later shots of patches that
    // shot before the save are asked for under their first counters, so they match.
    Counts resumed_counts;
    formfactor::RowCacheEngine resumed_engine = memo(m, resumed_counts, 1e9);
    solve::Progressive resumed(m, resumed_engine, {1e-4, 100000});
    resumed.load(state);
    while (resumed.step()) {
    }
    CHECK(resumed.passes() == through.passes());
    CHECK(resumed.radiosity(true) == through.radiosity(true));
    for (const auto& [request, n] : resumed_counts) CHECK(counts.count(request) == 1);
}

TEST_CASE("progressive with rotations 0 takes a new rotation every pass, as before the memo", "[row_cache][solver]") {
    const mesh::Mesh m = lit_box(0.95);
    Counts counts;
    CountingEngine engine(m, counts);
    solve::Settings settings{1e-3, 100000};
    settings.rotations = 0;
    solve::Progressive solver(m, engine, settings);
    while (solver.step()) {
    }
    REQUIRE(solver.converged());
    CHECK(static_cast<long>(counts.size()) == solver.passes());  // every request its own counter
    std::map<std::uint64_t, int> counters;
    for (const auto& [request, n] : counts) {
        CHECK(n == 1);
        ++counters[request.second];
    }
    CHECK(counters.size() == counts.size());
    CHECK(counters.rbegin()->first == static_cast<std::uint64_t>(solver.passes() - 1));  // the pass counter
}
