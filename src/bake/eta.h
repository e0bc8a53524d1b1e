// The bake's time model: a prediction per stage from its work counts, re-fitted from each stage's
// measured rate as the bake runs, and the time left it gives (the progress line's "left ~T").
// Plain arithmetic on the times it is given: testable without a bake or a clock.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace hemirad::bake {

// Stages whose per-unit costs move together: a stage's measured/predicted ratio corrects the
// predictions of the later stages of its kind (the solve's hemicubes tell how wrong refinement's
// and the gather's are). `own`: a stage whose rate tells nothing of another's (load, mesh, output).
enum class Cost { own, hemicube };

// One stage of the plan: `units` of work (rows, passes, shots, vertices; 1 where the stage has
// no count) at `unit_seconds` each, as predicted.
struct StagePlan {
    std::string name;
    Cost cost = Cost::own;
    double units = 1.0;
    double unit_seconds = 0.0;
    // Whether this stage's measured ratio corrects the later stages of its kind: not where its
    // units count its cost poorly (refinement: per level, host work besides its shots).
    bool evidence = true;
    double predicted() const { return units * unit_seconds; }
};

// Seconds left of a stage `fraction` done after `elapsed` seconds, at the rate so far.
double extrapolate_left(double elapsed, double fraction);

// The passes a progressive solve needs until its error falls to `threshold`, from (pass, error)
// samples: log(error) is fitted as a straight line in the passes (least squares) and followed to
// the threshold. Returns the total pass count (not the passes left, and never fewer than the last
// sample's); a negative value where the samples show no decay (fewer than two distinct passes, or
// a slope that does not fall).
double passes_to_threshold(const std::vector<std::pair<double, double>>& samples, double threshold);
// The same with log(error) a straight line in log(pass): a power law.
double passes_to_threshold_power(const std::vector<std::pair<double, double>>& samples, double threshold);
// What a solve's progress uses: the decay slows as the light spreads from the emitters over
// many patches that each hold little, so that the exponential fit is short and the power law
// long while it slows (a 150k-triangle city at draft: 0.65 and 4.7 of the truth a sixth of the
// way in); their geometric mean was within 0.45–1.75 from then on. A decay that is a straight
// line in log space to rounding (no curvature) is followed as it is: the exponential fit.
double hedged_passes_to_threshold(const std::vector<std::pair<double, double>>& samples, double threshold);

// The progressive solve's error as it falls, thinned to a sample each time the passes grow by
// kGrowth (and by a pass at least), so that a fit stays cheap on a solve of 10^5 passes; the fit
// uses the samples of the latter half of the passes (the decay slows as the light spreads).
class DecayFit {
public:
    static constexpr double kGrowth = 1.02;
    void add(double pass, double error);
    // Total passes expected (hedged_passes_to_threshold over the latter half), or < 0 while unknown.
    double total_passes(double threshold) const;
    const std::vector<std::pair<double, double>>& samples() const { return samples_; }

private:
    std::vector<std::pair<double, double>> samples_;
};

class Eta {
public:
    // The plan's stages, in the order they run.
    void add(const StagePlan& stage);
    // A stage's work is counted again (the gather's vertices once the mesh is refined): its
    // prediction from now on. The first prediction of a stage is kept for the report; one planned
    // with no work (the mesh's, before its triangles are counted) takes this one.
    void replan(const std::string& name, double units, double unit_seconds);
    bool has(const std::string& name) const;

    // `name` starts at `t` seconds into the bake: the running stage ends, and every stage planned
    // between them is skipped (it did not run: refinement that found nothing to do).
    void begin(const std::string& name, double t);
    // The running stage has done `done` of `total` units (total may change: a progressive solve's
    // passes are an estimate that moves).
    void update(double t, double done, double total);
    // The running stage ends at `t`.
    void end(double t);

    const std::string& current() const;  // empty: none running
    double fraction() const;             // of the running stage, 0 where none
    // Seconds left of the running stage, and of the bake (the running stage's and every later
    // stage's, corrected by its kind's ratio); < 0 while nothing is planned.
    double stage_left(double t) const;
    double left(double t) const;
    // Measured over predicted seconds per unit, from the latest stage of that kind with enough
    // measured: a finished one's; a running one's weighed in log against the one before it (or 1)
    // by the share of it done. 1 where none has.
    double ratio(Cost cost) const;

    // The predicted end of the bake (t + left) is kept every `kSampleSeconds` or so (sample());
    // prediction_at(share, total) is the one made at `share` of the measured `total`.
    static constexpr double kSampleSeconds = 0.05;
    void sample(double t);
    struct Prediction {
        double at = 0.0, total = 0.0;  // seconds into the bake, predicted total seconds
    };
    Prediction prediction_at(double share, double total) const;

    struct Stage {
        StagePlan plan;
        double first_predicted = 0.0;  // seconds, as first planned
        double predicted_at_begin = -1.0;  // re-fitted by the earlier stages when it began
        enum class State { pending, running, done, skipped } state = State::pending;
        double begun = 0.0, measured = 0.0;
        double done = 0.0, total = 0.0;
        // Progress samples (t, done): the first update (the rate's base: a resumed solve starts
        // part-way) and a thinned record for the recent rate.
        std::vector<std::pair<double, double>> samples;
        std::pair<double, double> last{0.0, 0.0};  // the latest update
    };
    const std::vector<Stage>& stages() const { return stages_; }

    // Below this much measured time a stage's rate is not trusted (start-up costs dominate).
    static constexpr double kMinEvidenceSeconds = 0.5;
    // A stage's own extrapolation takes over from the prediction as its progress goes to this.
    static constexpr double kTrustFraction = 0.05;

private:
    std::vector<Stage> stages_;
    int running_ = -1;
    std::vector<Prediction> history_;
    Stage* find(const std::string& name);
    const Stage* find(const std::string& name) const;
    double stage_ratio(const Stage& s) const;  // < 0: not enough evidence
    double corrected(const Stage& s) const;              // its prediction, scaled by its kind's ratio
};

}  // namespace hemirad::bake
