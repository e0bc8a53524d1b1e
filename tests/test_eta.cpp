// The bake's time model (bake/eta.h) on synthetic stages with known rates: the extrapolation of
// a stage, the re-fit of later stages by a measured ratio, the passes of an exact geometric
// decay. Times are given, never measured: no clock in these tests.
#include <catch2/catch.hpp>

#include <cmath>
#include <utility>
#include <vector>

#include "bake/eta.h"
#include "bake/stage_progress.h"

using hemirad::bake::Cost;
using hemirad::bake::DecayFit;
using hemirad::bake::Eta;
using hemirad::bake::StagePlan;

namespace {

// A stage running from `start` at `seconds_per_unit`, updated every `step` seconds until `until`.
void run_at_rate(Eta& eta, double start, double seconds_per_unit, double total, double until, double step = 0.25) {
    for (double t = start + step; t <= until + 1e-9; t += step) eta.update(t, (t - start) / seconds_per_unit, total);
}

}  // namespace

TEST_CASE("eta: a stage's time left is extrapolated from its fraction", "[eta]") {
    CHECK(hemirad::bake::extrapolate_left(10.0, 0.1) == Approx(90.0));
    CHECK(hemirad::bake::extrapolate_left(30.0, 0.75) == Approx(10.0));
    CHECK(hemirad::bake::extrapolate_left(5.0, 1.0) == 0.0);
    CHECK(hemirad::bake::extrapolate_left(5.0, 0.0) < 0.0);  // no progress: unknown
}

TEST_CASE("eta: a stage at 10% with a known rate extrapolates to the right total, and corrects the later stages of its kind", "[eta]") {
    Eta eta;
    // Predicted 1 s a unit; it runs at 2 s a unit.
    eta.add({"solve", Cost::hemicube, 100.0, 1.0});
    eta.add({"gather", Cost::hemicube, 50.0, 1.0});  // predicted 50 s, same kind: 100 s
    eta.add({"output", Cost::own, 1.0, 7.0});       // its own: 7 s whatever the solve does
    CHECK(eta.left(0.0) == Approx(157.0));            // before anything ran: the predictions
    eta.begin("solve", 0.0);
    run_at_rate(eta, 0.0, 2.0, 100.0, 20.0);          // 10 units: 10%
    CHECK(eta.fraction() == Approx(0.1));
    CHECK(eta.stage_left(20.0) == Approx(180.0));     // 90 units at 2 s
    // A running stage's ratio counts by the share of it done: its first units are not its
    // typical ones (a solve shoots its largest patches first).
    CHECK(eta.ratio(Cost::hemicube) == Approx(std::pow(2.0, 0.1)));
    CHECK(eta.ratio(Cost::own) == 1.0);
    CHECK(eta.left(20.0) == Approx(180.0 + 50.0 * std::pow(2.0, 0.1) + 7.0));
    // Time passing since the last update comes off the stage's rest.
    CHECK(eta.stage_left(21.0) == Approx(179.0));

    // Half-way, half of the solve's ratio (in log).
    for (double t = 25.0; t <= 100.0; t += 5.0) eta.update(t, t / 2.0, 100.0);
    CHECK(eta.ratio(Cost::hemicube) == Approx(std::sqrt(2.0)));
    // The stage ends at 200 s as extrapolated: the gather began re-fitted by the solve's ratio.
    for (double t = 105.0; t <= 200.0; t += 5.0) eta.update(t, t / 2.0, 100.0);
    eta.begin("gather", 200.0);
    CHECK(eta.left(200.0) == Approx(100.0 + 7.0));
    const Eta::Stage& gather = eta.stages()[1];
    CHECK(gather.first_predicted == Approx(50.0));
    CHECK(gather.predicted_at_begin == Approx(100.0));
    CHECK(eta.stages()[0].measured == Approx(200.0));
}

TEST_CASE("eta: the recent rate leads a stage whose start was slow", "[eta]") {
    Eta eta;
    eta.add({"solve", Cost::hemicube, 1000.0, 0.01});
    eta.begin("solve", 0.0);
    // 10 s of start-up (kernels built) with nothing done, then 1 unit a second.
    for (double t = 10.0; t <= 110.0; t += 1.0) eta.update(t, t - 10.0, 1000.0);
    // 100 units done at 110 s: the rate of the latter half is 1 s a unit, not 1.1.
    CHECK(eta.stage_left(110.0) == Approx(900.0));
}

TEST_CASE("eta: before its own progress a stage is its kind's corrected prediction less its time so far", "[eta]") {
    Eta eta;
    eta.add({"lights", Cost::hemicube, 10.0, 1.0});
    eta.add({"solve", Cost::hemicube, 30.0, 1.0});
    eta.begin("lights", 0.0);
    run_at_rate(eta, 0.0, 3.0, 10.0, 30.0);  // measured 3× the prediction
    eta.begin("solve", 30.0);
    CHECK(eta.stage_left(30.0) == Approx(90.0));
    CHECK(eta.stage_left(40.0) == Approx(80.0));
    CHECK(eta.stage_left(200.0) == 0.0);
}

TEST_CASE("eta: stages that do not feed their kind's ratio, skipped stages and the ratio's bounds", "[eta]") {
    Eta eta;
    eta.add({"solve", Cost::hemicube, 10.0, 1.0});
    StagePlan refine{"refine", Cost::hemicube, 2.0, 5.0};
    refine.evidence = false;  // a level a unit: host work besides its shots
    eta.add(refine);
    eta.add({"gather", Cost::hemicube, 20.0, 1.0});
    eta.add({"output", Cost::own, 1.0, 4.0});
    eta.begin("solve", 0.0);
    run_at_rate(eta, 0.0, 1.5, 10.0, 15.0);
    eta.begin("refine", 15.0);
    // Refinement is corrected by the solve (10 s predicted: 15 s) but, running at 10× its
    // prediction, does not change the gather's correction.
    CHECK(eta.left(15.0) == Approx(15.0 + 30.0 + 4.0));
    run_at_rate(eta, 15.0, 50.0, 2.0, 65.0);  // one level of two in 50 s
    CHECK(eta.stage_left(65.0) == Approx(50.0));
    CHECK(eta.ratio(Cost::hemicube) == Approx(1.5));
    CHECK(eta.left(65.0) == Approx(50.0 + 30.0 + 4.0));
    // The gather left out: output begins, the gather is skipped and no longer counted.
    eta.begin("output", 115.0);
    CHECK(eta.stages()[2].state == Eta::Stage::State::skipped);
    CHECK(eta.left(115.0) == Approx(4.0));
    eta.end(119.0);
    CHECK(eta.left(119.0) == 0.0);

    // A ratio from a stage of a few units that took far longer is kept within bounds.
    Eta wild;
    wild.add({"lights", Cost::hemicube, 1.0, 1e-4});
    wild.add({"solve", Cost::hemicube, 10.0, 1.0});
    wild.begin("lights", 0.0);
    wild.end(10.0);  // 100,000× its prediction
    CHECK(wild.ratio(Cost::hemicube) == Approx(50.0));
}

TEST_CASE("eta: a resumed stage's rate counts from its first update", "[eta]") {
    Eta eta;
    eta.add({"solve", Cost::hemicube, 1000.0, 1.0});
    eta.begin("solve", 0.0);
    // Resumed at 600 units; then 2 units a second.
    eta.update(0.5, 600.0, 1000.0);
    for (double t = 1.0; t <= 20.5; t += 0.5) eta.update(t, 600.0 + 2.0 * (t - 0.5), 1000.0);
    CHECK(eta.stage_left(20.5) == Approx(360.0 * 0.5));  // 360 units left at 2 a second
    // Its rate, 0.5 s a unit (predicted 1), weighed by the 64% of the stage done.
    CHECK(eta.ratio(Cost::hemicube) == Approx(std::pow(0.5, 0.64)));
}

TEST_CASE("eta: the prediction made at a share of the bake", "[eta]") {
    Eta eta;
    eta.add({"solve", Cost::hemicube, 100.0, 1.0});
    eta.begin("solve", 0.0);
    for (double t = 0.25; t <= 50.0; t += 0.25) {
        eta.update(t, t / 2.0, 100.0);  // 200 s in truth
        eta.sample(t);
    }
    // At 10% of 200 s (20 s) the prediction was the truth.
    const Eta::Prediction p = eta.prediction_at(0.1, 200.0);
    CHECK(p.at == Approx(20.0));
    CHECK(p.total == Approx(200.0));
    // Before any sample: the first one.
    CHECK(eta.prediction_at(0.0001, 200.0).at == Approx(0.25));
}

TEST_CASE("eta: an exact geometric decay of the unshot energy gives the exact pass count", "[eta]") {
    // error_k = e0 q^k falls below the threshold first at pass ceil(ln(threshold / e0) / ln q).
    const double e0 = 0.8, q = 0.997, threshold = 1e-3;
    const double exact = std::log(threshold / e0) / std::log(q);
    long first_below = 0;
    while (e0 * std::pow(q, double(first_below)) >= threshold) ++first_below;
    REQUIRE(std::ceil(exact) == double(first_below));

    std::vector<std::pair<double, double>> samples;
    for (int k = 1; k <= 300; ++k) samples.emplace_back(k, e0 * std::pow(q, k));
    CHECK(hemirad::bake::passes_to_threshold(samples, threshold) == Approx(exact).epsilon(1e-9));

    // The thinned fit of a solve (a sample each 2% more passes, the latter half fitted) too,
    // and from any point of the decay.
    DecayFit fit;
    for (int k = 1; k <= 300; ++k) fit.add(k, e0 * std::pow(q, k));
    CHECK(fit.samples().size() < 150);
    CHECK(fit.total_passes(threshold) == Approx(exact).epsilon(1e-9));
    CHECK(std::ceil(fit.total_passes(threshold)) == double(first_below));

    // No decay: unknown.
    CHECK(hemirad::bake::passes_to_threshold({{1, 0.5}, {2, 0.5}, {3, 0.6}}, threshold) < 0.0);
    CHECK(hemirad::bake::passes_to_threshold({{1, 0.5}}, threshold) < 0.0);
    DecayFit flat;
    flat.add(1, 0.5);
    CHECK(flat.total_passes(threshold) < 0.0);
}

TEST_CASE("eta: a decay that slows is fitted on its latter half", "[eta]") {
    // Fast at first (q1 for 200 passes), then slower (q2): the total follows the slow part.
    const double q1 = 0.98, q2 = 0.995, threshold = 1e-4;
    DecayFit fit;
    double e = 1.0;
    for (int k = 1; k <= 1000; ++k) {
        e *= k <= 200 ? q1 : q2;
        fit.add(k, e);
    }
    const double exact = 1000.0 + std::log(threshold / e) / std::log(q2);
    CHECK(fit.total_passes(threshold) == Approx(exact).epsilon(1e-6));
}

TEST_CASE("eta: a power-law decay gives its exact pass count, and a slowing decay is hedged between the two fits", "[eta]") {
    // error_k = c k^-a reaches the threshold at k = (threshold / c)^(-1/a).
    const double c = 0.5, a = 0.8, threshold = 1e-3;
    const double exact = std::pow(threshold / c, -1.0 / a);
    std::vector<std::pair<double, double>> samples;
    for (int k = 10; k <= 400; k += 10) samples.emplace_back(k, c * std::pow(double(k), -a));
    CHECK(hemirad::bake::passes_to_threshold_power(samples, threshold) == Approx(exact).epsilon(1e-9));
    // The exponential fit of a decay that slows is short, the power law exact here: the hedge is
    // their geometric mean, between them.
    const double exponential = hemirad::bake::passes_to_threshold(samples, threshold);
    CHECK(exponential < exact);
    const double hedged = hemirad::bake::hedged_passes_to_threshold(samples, threshold);
    CHECK(hedged == Approx(std::sqrt(exponential * exact)).epsilon(1e-9));
    CHECK(exponential < hedged);
    CHECK(hedged < exact);
}

TEST_CASE("eta: a progressive solve's expected passes shoot every holder once, then a tail that grows with the reflectance", "[eta]") {
    hemirad::bake::WorkCounts w;
    w.shape.counts.patches = 10000;
    w.reflectance = 0.5;
    const double dark = [&] { auto d = w; d.reflectance = 0.1; return hemirad::bake::expected_solve_passes(d, 40); }();
    const double bright = hemirad::bake::expected_solve_passes(w, 40);
    CHECK(dark > 40);
    CHECK(bright > dark);
    // Under a sky dome its faces shoot first, the scene's reflected light among them: a short tail.
    w.sky = true;
    const double sky = hemirad::bake::expected_solve_passes(w, 1000);
    CHECK(sky > 1000);
    CHECK(sky < 1000 + 0.1 * 10000);
    w.max_passes = 500;
    CHECK(hemirad::bake::expected_solve_passes(w, 1000) == 500);
}

TEST_CASE("eta: a stage planned before its work is counted is first predicted when it is, a predicted one keeps its first", "[eta]") {
    Eta eta;
    eta.add({"mesh", Cost::own, 1.0, 0.0});  // its triangles not yet counted
    eta.add({"gather", Cost::hemicube, 50.0, 1.0});
    eta.replan("mesh", 1000.0, 0.01);   // 1,000 triangles at 10 ms
    eta.replan("gather", 0.0, 0.0);     // left out after refinement
    CHECK(eta.stages()[0].first_predicted == Approx(10.0));
    CHECK(eta.stages()[1].first_predicted == Approx(50.0));
    CHECK(eta.left(0.0) == Approx(10.0));
}

TEST_CASE("eta: a gather past its budget is planned as a sparse one of the budget's hemicubes", "[eta]") {
    hemirad::bake::WorkCounts w;
    w.shape.counts.patches = 800;
    w.shape.counts.elements = 8000;
    w.solver = "progressive";
    w.refine = true;
    w.gather = 96;
    w.gather_passes = 4;
    w.gather_refine = true;
    w.gather_planar_patches = 800;
    w.gather_cluster_cells = 0.0;
    const auto gather_of = [](const std::vector<StagePlan>& stages) -> const StagePlan* {
        for (const StagePlan& s : stages)
            if (s.name == "gather") return &s;
        return nullptr;
    };
    // No limit (--gather-points 0, or --gather given): every vertex, its later passes and refinement.
    w.gather_budget = 0.0;
    const std::vector<StagePlan> all = hemirad::bake::predict_stages(w);
    const StagePlan* full = gather_of(all);
    REQUIRE(full != nullptr);
    const double unit = hemirad::bake::gather_point_seconds(800.0, 96);
    CHECK(full->unit_seconds == Approx(unit));
    const double refined = 8000.0 * 3.6, points = refined * 1.3;
    CHECK(full->units == Approx(points * (1.0 + 0.05 * 3.0 + 0.3)));
    // A budget above the vertices changes nothing; one below them plans exactly that many
    // hemicubes, one pass, no refinement.
    w.gather_budget = 50000;
    CHECK(gather_of(hemirad::bake::predict_stages(w))->units == Approx(full->units));
    w.gather_budget = 1000;
    w.gather_points_given = true;
    CHECK(gather_of(hemirad::bake::predict_stages(w))->units == Approx(1000.0));
    // Unless given, the budget is also what the model allows the drawn mesh: here far above.
    w.gather_points_given = false;
    CHECK(hemirad::bake::timed_gather_budget(800.0, 96) > 1000.0);
    CHECK(gather_of(hemirad::bake::predict_stages(w))->units == Approx(1000.0));
    // A drawn mesh so large that the model's time allows fewer: those, and never below the floor.
    w.gather_budget = 50000;
    w.shape.counts.elements = 80000;
    w.gather_cluster_cells = 10.0 * refined;  // as many cells drawn as refined elements
    const double drawn = 800.0 + 10.0 * refined;
    const double timed = std::floor(hemirad::bake::kGatherSeconds / hemirad::bake::gather_point_seconds(drawn, 96));
    REQUIRE(timed < 10.0 * points);
    REQUIRE(timed < 50000.0);
    CHECK(hemirad::bake::timed_gather_budget(drawn, 96) == Approx(std::max(timed, hemirad::bake::kMinGatherPoints)));
    CHECK(gather_of(hemirad::bake::predict_stages(w))->units ==
          Approx(std::max(timed, hemirad::bake::kMinGatherPoints)));
    CHECK(hemirad::bake::timed_gather_budget(1e12, 96) == hemirad::bake::kMinGatherPoints);
}
