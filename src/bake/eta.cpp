// The bake's time model (see eta.h).
#include "bake/eta.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hemirad::bake {

namespace {

// A ratio beyond this is a stage whose counts say little about its time (a few units, start-up
// costs): it is kept within it rather than multiplying the later stages by 1000.
constexpr double kMaxRatio = 50.0;

}  // namespace

double extrapolate_left(double elapsed, double fraction) {
    if (!(fraction > 0.0)) return -1.0;
    if (fraction >= 1.0) return 0.0;
    return elapsed * (1.0 - fraction) / fraction;
}

namespace {

// Least squares of log(error) on x(pass): slope, means, and the residual sum of squares; false
// where it cannot be fitted (fewer than two samples of distinct passes).
struct LineFit {
    double slope = 0.0, mx = 0.0, my = 0.0, rss = 0.0, span = 0.0;
};
template <typename X>
bool fit_line(const std::vector<std::pair<double, double>>& samples, X x_of, LineFit& f) {
    double n = 0.0, sx = 0.0, sy = 0.0, lo = 0.0, hi = 0.0;
    for (const auto& [pass, e] : samples) {
        if (!(e > 0.0) || !std::isfinite(e) || !(pass > 0.0)) continue;
        const double y = std::log(e);
        lo = n == 0.0 ? y : std::min(lo, y);
        hi = n == 0.0 ? y : std::max(hi, y);
        n += 1.0;
        sx += x_of(pass);
        sy += y;
    }
    if (n < 2.0) return false;
    f.mx = sx / n;
    f.my = sy / n;
    f.span = hi - lo;
    double sxx = 0.0, sxy = 0.0;
    for (const auto& [pass, e] : samples) {
        if (!(e > 0.0) || !std::isfinite(e) || !(pass > 0.0)) continue;
        sxx += (x_of(pass) - f.mx) * (x_of(pass) - f.mx);
        sxy += (x_of(pass) - f.mx) * (std::log(e) - f.my);
    }
    if (!(sxx > 0.0)) return false;
    f.slope = sxy / sxx;
    for (const auto& [pass, e] : samples) {
        if (!(e > 0.0) || !std::isfinite(e) || !(pass > 0.0)) continue;
        const double r = std::log(e) - (f.my + f.slope * (x_of(pass) - f.mx));
        f.rss += r * r;
    }
    return true;
}

double last_pass(const std::vector<std::pair<double, double>>& samples) {
    double last = 0.0;
    for (const auto& s : samples) last = std::max(last, s.first);
    return last;
}

}  // namespace

double passes_to_threshold(const std::vector<std::pair<double, double>>& samples, double threshold) {
    LineFit f;
    if (!(threshold > 0.0) || !fit_line(samples, [](double x) { return x; }, f) || !(f.slope < 0.0)) return -1.0;
    // The fitted line through the samples' mean, followed down to the threshold.
    return std::max(last_pass(samples), f.mx + (std::log(threshold) - f.my) / f.slope);
}

double passes_to_threshold_power(const std::vector<std::pair<double, double>>& samples, double threshold) {
    LineFit f;
    if (!(threshold > 0.0) || !fit_line(samples, [](double x) { return std::log(x); }, f) || !(f.slope < 0.0)) return -1.0;
    return std::max(last_pass(samples), std::exp(f.mx + (std::log(threshold) - f.my) / f.slope));
}

double hedged_passes_to_threshold(const std::vector<std::pair<double, double>>& samples, double threshold) {
    const double exponential = passes_to_threshold(samples, threshold);
    if (exponential < 0.0) return -1.0;
    LineFit f;
    fit_line(samples, [](double x) { return x; }, f);
    // A decay without curvature (a straight line in log space to rounding) is followed as it is.
    const double n = double(samples.size());
    if (f.rss <= n * 1e-18 * std::max(1.0, f.span * f.span)) return exponential;
    const double power = passes_to_threshold_power(samples, threshold);
    return power > 0.0 ? std::sqrt(exponential * power) : exponential;
}

void DecayFit::add(double pass, double error) {
    if (!(error > 0.0) || !std::isfinite(error)) return;
    if (!samples_.empty() && (pass < samples_.back().first * kGrowth || pass < samples_.back().first + 1.0)) return;
    samples_.emplace_back(pass, error);
}

double DecayFit::total_passes(double threshold) const {
    if (samples_.size() < 2) return -1.0;
    const double half = samples_.back().first / 2.0;
    std::vector<std::pair<double, double>> recent;
    for (const auto& s : samples_)
        if (s.first >= half) recent.push_back(s);
    if (recent.size() < 3) recent = samples_;
    return hedged_passes_to_threshold(recent, threshold);
}

void Eta::add(const StagePlan& stage) {
    Stage s;
    s.plan = stage;
    s.first_predicted = stage.predicted();
    s.total = stage.units;
    stages_.push_back(std::move(s));
}

Eta::Stage* Eta::find(const std::string& name) {
    for (Stage& s : stages_)
        if (s.plan.name == name) return &s;
    return nullptr;
}

const Eta::Stage* Eta::find(const std::string& name) const {
    for (const Stage& s : stages_)
        if (s.plan.name == name) return &s;
    return nullptr;
}

bool Eta::has(const std::string& name) const { return find(name) != nullptr; }

void Eta::replan(const std::string& name, double units, double unit_seconds) {
    Stage* s = find(name);
    if (!s) return;
    s->plan.units = units;
    s->plan.unit_seconds = unit_seconds;
    // A stage planned before its work was counted (the mesh's, before its triangles are) is first
    // predicted now; one already predicted keeps that for the report.
    if (s->state == Stage::State::pending && s->first_predicted == 0.0) s->first_predicted = s->plan.predicted();
    if (s->state != Stage::State::running) s->total = units;
}

void Eta::begin(const std::string& name, double t) {
    Stage* s = find(name);
    if (!s) throw std::logic_error("Eta::begin: no stage " + name);
    if (running_ >= 0) end(t);
    const std::size_t index = static_cast<std::size_t>(s - stages_.data());
    for (std::size_t k = 0; k < index; ++k)
        if (stages_[k].state == Stage::State::pending) stages_[k].state = Stage::State::skipped;
    s->predicted_at_begin = corrected(*s);
    s->state = Stage::State::running;
    s->begun = t;
    s->done = 0.0;
    s->total = s->plan.units;
    s->samples.clear();
    running_ = static_cast<int>(index);
}

void Eta::update(double t, double done, double total) {
    if (running_ < 0) return;
    Stage& s = stages_[static_cast<std::size_t>(running_)];
    s.done = std::max(0.0, done);
    if (total > 0.0) s.total = std::max(total, s.done);
    // Thinned: a sample each time the stage's time grows by a sixteenth, enough for the recent
    // rate (the latter half) without a sample per pass.
    s.last = {t, s.done};
    if (s.samples.empty() || t - s.samples.back().first >= (t - s.begun) / 16.0) s.samples.emplace_back(t, s.done);
}

void Eta::end(double t) {
    if (running_ < 0) return;
    Stage& s = stages_[static_cast<std::size_t>(running_)];
    if (s.done <= 0.0 || s.done < s.total) {
        // Counted work the stage never reported (host stages report none): it is all done.
        s.done = s.total > 0.0 ? s.total : std::max(1.0, s.done);
    }
    s.last = {t, s.done};
    s.samples.emplace_back(t, s.done);
    s.measured = t - s.begun;
    s.state = Stage::State::done;
    running_ = -1;
}

const std::string& Eta::current() const {
    static const std::string none;
    return running_ >= 0 ? stages_[static_cast<std::size_t>(running_)].plan.name : none;
}

double Eta::fraction() const {
    if (running_ < 0) return 0.0;
    const Stage& s = stages_[static_cast<std::size_t>(running_)];
    return s.total > 0.0 ? std::clamp(s.done / s.total, 0.0, 1.0) : 0.0;
}

// Measured seconds per unit over predicted: from the first update on where there are later ones
// (a resumed solve's first update already counts the work it resumed), else from the stage's start.
double Eta::stage_ratio(const Stage& s) const {
    if (!(s.plan.unit_seconds > 0.0) || s.samples.empty()) return -1.0;
    const std::pair<double, double>& last = s.last;
    double seconds = last.first - s.begun, units = last.second;
    if (s.samples.size() >= 3 && last.second > s.samples.front().second) {
        seconds = last.first - s.samples.front().first;
        units = last.second - s.samples.front().second;
    }
    if (seconds < kMinEvidenceSeconds || !(units > 0.0)) return -1.0;
    return std::clamp(seconds / units / s.plan.unit_seconds, 1.0 / kMaxRatio, kMaxRatio);
}

double Eta::ratio(Cost cost) const {
    // The latest stage of the kind with evidence: a finished one's ratio as it is; a running one's
    // weighed (in log) against the ratio before it by the share of it done, since its first units
    // are not its typical ones (a progressive solve shoots its largest patches first, at up to twice
    // a later pass's cost: on the sci-fi hall and furniture:20k its early ratio alone put the
    // stages after it 2× long).
    double running = 0.0, share = 0.0;
    bool has_running = false;
    for (auto it = stages_.rbegin(); it != stages_.rend(); ++it) {
        if (it->plan.cost != cost || !it->plan.evidence || cost == Cost::own) continue;
        if (it->state != Stage::State::done && it->state != Stage::State::running) continue;
        const double r = stage_ratio(*it);
        if (!(r > 0.0)) continue;
        if (it->state == Stage::State::done) {
            return has_running ? std::exp(share * std::log(running) + (1.0 - share) * std::log(r)) : r;
        }
        if (!has_running) {
            has_running = true;
            running = r;
            share = it->total > 0.0 ? std::clamp(it->done / it->total, 0.0, 1.0) : 0.0;
        }
    }
    return has_running ? std::exp(share * std::log(running)) : 1.0;
}

double Eta::corrected(const Stage& s) const { return s.plan.predicted() * ratio(s.plan.cost); }

double Eta::stage_left(double t) const {
    if (running_ < 0) return 0.0;
    const Stage& s = stages_[static_cast<std::size_t>(running_)];
    const double elapsed = std::max(0.0, t - s.begun);
    // The prediction before this stage's own evidence: its kind's ratio from the stages before.
    double prior_ratio = 1.0;
    for (int k = running_ - 1; k >= 0; --k) {
        const Stage& e = stages_[static_cast<std::size_t>(k)];
        if (e.plan.cost != s.plan.cost || e.state != Stage::State::done || !e.plan.evidence || e.plan.cost == Cost::own)
            continue;
        const double r = stage_ratio(e);
        if (r > 0.0) {
            prior_ratio = r;
            break;
        }
    }
    const double prior_total = s.plan.predicted() * prior_ratio;
    const double f = s.total > 0.0 ? std::clamp(s.done / s.total, 0.0, 1.0) : 0.0;
    if (!(s.done > 0.0) || s.samples.empty()) return std::max(0.0, prior_total - elapsed);
    // The recent rate: over the latter half of the stage's time so far.
    const std::pair<double, double>& last = s.last;
    const double middle = s.begun + (last.first - s.begun) / 2.0;
    std::pair<double, double> base{s.begun, 0.0};
    if (s.samples.size() >= 2) base = s.samples.front();
    for (const auto& sample : s.samples)
        if (sample.first <= middle && sample.second < last.second) base = sample;
    double rate = 0.0;
    if (last.second > base.second && last.first > base.first) {
        rate = (last.first - base.first) / (last.second - base.second);
    } else {
        rate = (last.first - s.begun) / last.second;
    }
    const double own = std::max(0.0, (s.total - s.done) * rate - (t - last.first));
    const double prior = prior_total * (1.0 - f);
    const double w = std::min(1.0, f / kTrustFraction);
    return w * own + (1.0 - w) * prior;
}

double Eta::left(double t) const {
    if (stages_.empty()) return -1.0;
    double sum = stage_left(t);
    const std::size_t from = running_ >= 0 ? static_cast<std::size_t>(running_) + 1 : 0;
    for (std::size_t k = from; k < stages_.size(); ++k)
        if (stages_[k].state == Stage::State::pending) sum += corrected(stages_[k]);
    return sum;
}

void Eta::sample(double t) {
    if (stages_.empty()) return;
    if (!history_.empty() && t - history_.back().at < kSampleSeconds) return;
    history_.push_back({t, t + left(t)});
}

Eta::Prediction Eta::prediction_at(double share, double total) const {
    if (history_.empty()) return {0.0, -1.0};
    const double target = share * total;
    Prediction best = history_.front();
    for (const Prediction& p : history_)
        if (p.at <= target) best = p;
    return best;
}

}  // namespace hemirad::bake
