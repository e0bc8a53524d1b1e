// The bake's one progress line (see stage_progress.h).
#include "bake/stage_progress.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <system_error>

#include <fmt/core.h>

#include "solve/progressive.h"

namespace hemirad::bake {

namespace {

// Host constants, measured on this machine (2 Xeon cores through PoCL, shared with other work;
// release build) from the stages' own timings: the load and mesh on the Cornell box and generated
// scenes of 20k–150k triangles; the solve, refinement and output fitted on five bakes (the kitchen,
// Littlest Tokyo and the sport hall of the README's public exports under --sun and --sky, and
// furniture:20k and city:60k at draft) and checked on the others. They are where the progress
// line starts; each stage's own rate takes over as it runs.
// Loading (and setting up): a fixed part, and per byte of the scene file (a .gltf's external
// buffers are not counted).
constexpr double kLoadSeconds = 0.15, kLoadSecondsPerByte = 2e-7;
// Meshing: per triangle.
constexpr double kMeshSecondsPerTriangle = 1.2e-5;
// Output: a fixed part, per element (the weld, none where the gather welded; the render's
// elements; the baked glTF), per pixel (the render, render.exr, render.png) and per triangle of the
// scene (the baked glTF). Fitted (least squares, the fixed part and the pixels' share set) on the
// kitchen, Littlest Tokyo, the sport hall, furniture:20k and city:60k at draft (0.21–4.3 s); on ten
// other bakes (public exports, generated scenes, the bundled scenes; 0.16–12 s) the model was
// 0.86–1.97× the measured output.
constexpr double kOutputSeconds = 0.05;
constexpr double kWeldSecondsPerElement = 3e-7;
constexpr double kRenderSecondsPerPixel = 5e-8, kRenderSecondsPerElement = 1e-6;
constexpr double kExrSecondsPerPixel = 1.5e-7, kPngSecondsPerPixel = 1e-7;
constexpr double kGltfSecondsPerElement = 1.2e-6, kGltfSecondsPerTriangle = 3.4e-6;
// The gather's vertices a pass per element of the refined mesh: 0.86–2.44 on six bakes (the Cornell
// box 0.86, the atrium 0.96, the lit room 1.17, city:4k 1.41 and city:10k 1.58 at draft, furniture:20k
// at draft 2.44), 1.3 their geometric mean, which counts its work and decides whether it is
// expected past its budget (a sparse gather, gather.h).
constexpr double kGatherVerticesPerElement = 1.3;
// Refinement's growth over two levels: 3.6×, the geometric mean of the public exports (the
// kitchen 2.2, the Japanese room 1.9, the workplace corner 3.1, the fantasy inn 3.6, the sport hall
// 3.9, Littlest Tokyo 4.7, the keyboard 5.6, the sci-fi hall 6.6, the autumn river 8.3: textures
// give contrast to split) and generated scenes (the Cornell box 1.8, city:20k 2.75; at N 64 over
// 1.4–6.1), with no clear trend in N; at most 4× a level.
constexpr double kRefineGrowth = 3.6;
// Refinement, a level: re-gathering the strongest shooters onto the finer mesh and the host's
// marking and splitting grow with the elements before it and with the hemicube: 47 µs an element
// a level at N 256 (from the kitchen and Littlest Tokyo; the sport hall 56), 8–14 µs at N 64
// (furniture:20k and city:60k at draft), and a fixed part that small scenes show (about a second
// a level at N 256: the atrium and lit room 2.1–2.2 s over two levels, the keyboard 4.7 s).
constexpr double kRefineSecondsPerElement256 = 4.7e-5, kRefineNExponent = 1.2, kRefineLevelSeconds256 = 1.0;
// The progressive solve's passes, before its error has fallen (expected_solve_passes): the tail
// of passes the reflected light takes, per patch, as measured. Under a sky dome
// (--sky), 0.017 a patch (the geometric mean of the kitchen 0.008, Littlest Tokyo 0.016 and the
// sport hall 0.037: the dome's 1,024 faces shoot first and the scene's reflected light with
// them); without one, 0.56 ρ/(1 − ρ) a patch with ρ the mean reflectance (furniture:20k 0.62,
// city:60k 0.50 at draft; a closed room of furniture of ρ 0.53 takes 0.7 passes a patch).
constexpr double kSkyTailPerPatch = 0.017, kTailPerPatch = 0.56;
// A progressive pass: per element of the mesh, and a hemicube's fixed part at N 256 (its cells
// grow as N²): fitted on the same five bakes (2.1–12.3 ms a pass at N 256, 0.6–1.5 ms at N 64);
// on six others 0.55–1.4× the measured.
constexpr double kPassSecondsPerElement = 3.3e-8, kPassSeconds256 = 5e-4;
// Gather refinement's new vertices, as a share of the gather's (at most half again); a vertex's
// later passes, as a share of its first (they re-use its row where the budget kept it).
constexpr double kGatherRefineShare = 0.3;
// A gather vertex's first pass, at the hemicube's N: a part that grows as the square root of the
// elements the gather draws (solve::gather_mesh: a planar patch one, a cluster's face one; from one
// point most of them are culled in groups, behind its plane or hidden, so the cost grows well below
// linearly), a little with N, and its cells' part (3N² of them). Measured on 2 PoCL cores with the
// gather stage's host work (the sparse gather's levels and interpolation) in it: seven public
// scenes at the default (N 96; 32k–526k drawn, 2.9–10.2 ms a point) fit a square root (exponent
// 0.53 free), where the linear model before was 1.0–3.4× short; the Cornell box at N 32 to 384
// (742 drawn, 0.24–1.74 ms) and an inn at N 32 to 192 (32k drawn, 2.9–5.2 ms) set the N parts.
// Measured over the model: 0.70–1.30 on those fourteen bakes.
constexpr double kGatherSecondsPerRootDrawn = 1.7e-5, kGatherSecondsPerCell = 2.5e-9;
constexpr double kLaterPassShare = 0.05;
// The matrix solve measured against the budget's model (bake/budget.h, made for choosing a
// solver): 0.27–0.72 on six generated and bundled bakes (the Cornell box, the atrium, the lit
// room, city:4k and city:10k at draft, city:20k), 0.48 their geometric mean.
constexpr double kMatrixShare = 0.48;
// The engines' set-up before the solve (the device's mesh; PoCL's kernels when its cache holds
// them, else about 10 s more to build them).
constexpr double kEnginesSeconds = 0.3;

double growth_per_level() {
    return std::min(4.0, std::sqrt(kRefineGrowth));
}

double n_share(int hemicube) { return double(std::max(8, hemicube)) / 256.0; }

}  // namespace

std::vector<std::pair<std::string, double>> predict_output(double elements, double triangles, double pixels) {
    return {{"weld", kOutputSeconds + elements * kWeldSecondsPerElement},
            {"render", pixels * kRenderSecondsPerPixel + elements * kRenderSecondsPerElement},
            {"render.exr", pixels * kExrSecondsPerPixel},
            {"render.png", pixels * kPngSecondsPerPixel},
            {"baked.gltf", elements * kGltfSecondsPerElement + triangles * kGltfSecondsPerTriangle}};
}

double refine_level_seconds(const WorkCounts& w) {
    const BakeShape& s = w.shape;
    if (s.refine_levels <= 0) return 0.0;
    const double n = n_share(s.hemicube);
    return kRefineLevelSeconds256 * n * n + s.counts.elements * kRefineSecondsPerElement256 * std::pow(n, kRefineNExponent);
}

double expected_solve_passes(const WorkCounts& w, double holders) {
    const double P = w.shape.counts.patches;
    const double rho = std::clamp(w.reflectance, 0.0, 0.95);
    const double tail = w.sky ? kSkyTailPerPatch * P : kTailPerPatch * rho / (1.0 - rho) * P;
    double passes = std::max(1.0, holders + tail);
    if (w.max_passes > 0.0) passes = std::min(passes, w.max_passes);
    return passes;
}

double gather_point_seconds(double drawn, int hemicube) {
    const double n = double(std::max(8, hemicube));
    return kGatherSecondsPerRootDrawn * std::sqrt(std::max(1.0, drawn)) * (0.6 + 0.4 * n / 96.0) +
           kGatherSecondsPerCell * 3.0 * n * n;
}

double timed_gather_budget(double drawn, int hemicube) {
    return std::max(kMinGatherPoints, std::floor(kGatherSeconds / gather_point_seconds(drawn, hemicube)));
}

double gather_drawn(const WorkCounts& w) {
    return w.gather_planar_patches + w.gather_cluster_cells;
}

double planned_gather_budget(const WorkCounts& w) {
    if (w.gather_budget > 0.0 && !w.gather_points_given)
        return std::min(w.gather_budget, timed_gather_budget(gather_drawn(w), w.gather));
    return w.gather_budget;
}

double expected_pass_seconds(const BakeShape& s) {
    const double n = n_share(s.hemicube);
    return kPassSeconds256 * n * n + s.counts.elements * kPassSecondsPerElement;
}

std::vector<StagePlan> predict_stages(const WorkCounts& w) {
    const BakeShape& s = w.shape;
    const double E = s.counts.elements, P = s.counts.patches;
    std::vector<StagePlan> out;
    out.push_back({"engines", Cost::own, 1.0, kEnginesSeconds});
    out.push_back({"lights", Cost::hemicube, w.light_hemicubes, batched_shot_seconds(s, s.hemicube)});
    if (w.solver == "matrix") {
        // A row per patch, and the Gauss–Seidel sweeps spread over them.
        out.push_back({"solve", Cost::hemicube, P, kMatrixShare * expected_times(s).matrix / std::max(1.0, P)});
    } else {
        out.push_back({"solve", Cost::hemicube, expected_solve_passes(w, w.emitting_holders), expected_pass_seconds(s)});
    }
    double refined = E;
    if (w.refine && s.refine_levels > 0) {
        // A unit a level; its host work besides its shots makes its rate no measure of the gather's.
        StagePlan refine{"refine", Cost::hemicube, double(s.refine_levels), refine_level_seconds(w)};
        refine.evidence = false;
        out.push_back(refine);
        refined *= std::pow(growth_per_level(), s.refine_levels);
    }
    if (w.gather > 0) {
        // A unit is a vertex's first hemicube; its later passes re-use the row (kLaterPassShare
        // each); gather refinement's vertices take one hemicube each. Beyond the budget, a sparse
        // gather: the budget's hemicubes, one pass.
        const double passes = std::max(1, w.gather_passes);
        const double points = refined * kGatherVerticesPerElement;
        const double drawn = gather_drawn(w);
        const double budget = planned_gather_budget(w);
        const bool sparse = budget > 0.0 && points > budget;
        const double units =
            sparse ? budget
                   : points * (1.0 + kLaterPassShare * (passes - 1.0) + (w.gather_refine ? kGatherRefineShare : 0.0));
        out.push_back({"gather", Cost::hemicube, units, gather_point_seconds(drawn, w.gather)});
    }
    double output = 0.0;
    for (const auto& step : predict_output(refined, w.triangles, s.pixels)) output += step.second;
    out.push_back({"output", Cost::own, 1.0, output});
    return out;
}

// The passes expected: the plan's and the decay's fit, in log space, the fit weighted by how
// far the error has fallen towards the threshold (in log): early on, the fit of a few passes
// follows the emitters' fast first decay and is short (a 150k-triangle city: a third of the
// truth a twelfth of the way in).
double blend_passes(double planned, double fitted, const DecayFit& decay, double threshold) {
    const auto& samples = decay.samples();
    if (!(planned > 0.0) || samples.empty()) return fitted;
    const double first = samples.front().second, now = samples.back().second;
    if (!(first > threshold) || !(now > 0.0)) return fitted;
    const double fallen = std::clamp(std::log(first / now) / std::log(first / threshold), 0.0, 1.0);
    return std::exp((1.0 - fallen) * std::log(planned) + fallen * std::log(std::max(fitted, 1.0)));
}

void StageProgress::plan_load(const std::string& file) {
    std::error_code ec;
    const auto bytes = std::filesystem::file_size(file, ec);
    eta_.add({"load", Cost::own, 1.0, kLoadSeconds + (ec ? 0.0 : double(bytes)) * kLoadSecondsPerByte});
    load_detail_ = std::filesystem::path(file).filename().string();
    eta_.add({"mesh", Cost::own, 1.0, 0.0});
}

void StageProgress::plan_mesh(double triangles) {
    eta_.replan("mesh", triangles, kMeshSecondsPerTriangle);
    mesh_detail_ = fmt::format("{:.0f} triangles", triangles);
}

void StageProgress::plan_rest(const WorkCounts& w) {
    if (planned_) return;  // a restart on the reference engine keeps the plan
    for (const StagePlan& s : predict_stages(w)) eta_.add(s);
    max_passes_ = w.max_passes;
    work_ = w;
    refine_levels_ = w.shape.refine_levels;
    gather_extra_ = w.gather_refine ? kGatherRefineShare : 0.0;
    gather_passes_ = std::max(1, w.gather_passes);
    double refined = w.shape.counts.elements;
    if (w.refine) refined *= std::pow(growth_per_level(), w.shape.refine_levels);
    output_steps_ = predict_output(refined, w.triangles, w.shape.pixels);
    planned_ = true;
}

// The model's stage `stage` begins, if it is not running: the one before shows its end.
void StageProgress::into(const std::string& stage) {
    if (eta_.current() == stage || !eta_.has(stage)) return;
    if (!eta_.current().empty()) end_stage();
    last_shown_ = -1e9;
    shown_.begin_stage(stage);
    eta_.begin(stage, now());
}

void StageProgress::begin_stage(const std::string& stage) {
    std::string model = stage;
    if (stage == "solve") {
        const auto& st = eta_.stages();
        const bool lights = std::any_of(st.begin(), st.end(), [](const Eta::Stage& s) {
            return s.plan.name == "lights" && s.plan.units > 0.0;
        });
        if (lights) model = "lights";
        decay_ = DecayFit();
        fitted_at_ = expected_passes_ = -1.0;
        solve_replanned_ = false;
    }
    if (stage == "gather") {
        gather_base_ = gather_last_done_ = gather_last_units_ = 0.0;
        gather_phase_ = 0;
    }
    into(model);
    show(stage == "load" ? load_detail_ : stage == "mesh" ? mesh_detail_ : "");
}

void StageProgress::end_stage() {
    const std::string stage = eta_.current();
    if (!stage.empty()) {
        eta_.end(now());
        Status st;
        st.stage = stage;
        st.detail = detail_;
        st.fraction = 1.0;
        const auto& stages = eta_.stages();
        for (const Eta::Stage& s : stages)
            if (s.plan.name == stage) st.elapsed = s.measured;
        st.left = planned_ ? eta_.left(now()) : -1.0;
        st.last = true;
        if (planned_) eta_.sample(now());
        shown_.status(st);
    }
    shown_.end_stage();
}

void StageProgress::show(const std::string& detail, bool last) {
    detail_ = detail;
    const double t = now();
    if (planned_) eta_.sample(t);
    if (!last && t - last_shown_ < 0.1) return;
    last_shown_ = t;
    Status st;
    st.stage = eta_.current();
    if (st.stage.empty()) return;
    st.detail = detail;
    st.fraction = eta_.fraction();
    for (const Eta::Stage& s : eta_.stages())
        if (s.plan.name == st.stage) st.elapsed = t - s.begun;
    st.left = planned_ ? eta_.left(t) : -1.0;
    st.last = last;
    shown_.status(st);
}

void StageProgress::writing(const std::string& what) {
    into("output");
    double before = 0.0, total = 0.0;
    bool found = false;
    for (const auto& [step, seconds] : output_steps_) {
        if (step == what) found = true;
        if (!found) before += seconds;
        total += seconds;
    }
    if (found && total > 0.0) eta_.update(now(), before / total, 1.0);
    show(what);
}

void StageProgress::lights(std::size_t done, std::size_t total) {
    into("lights");
    eta_.update(now(), double(done), double(total));
    show(fmt::format("lights' hemicubes {} / {}", done, total));
}

void StageProgress::passes(const solve::Progressive& solver, double threshold) {
    into("solve");
    const double done = double(solver.passes());
    if (!solve_replanned_) {
        // The solve's first pass: the holders of its unshot light are known now (the sun's light
        // reflected among them), and the passes expected are counted from them.
        solve_replanned_ = true;
        for (const Eta::Stage& s : eta_.stages())
            if (s.plan.name == "solve")
                eta_.replan("solve", done + expected_solve_passes(work_, double(solver.holders(threshold))),
                            s.plan.unit_seconds);
    }
    decay_.add(done, solver.error());
    // The fit is redone when the decay has a new sample (every 2% more passes).
    double planned = 0.0;  // the passes expected before the decay (expected_solve_passes)
    for (const Eta::Stage& s : eta_.stages())
        if (s.plan.name == "solve") planned = s.plan.units;
    if (double(decay_.samples().size()) != fitted_at_) {
        fitted_at_ = double(decay_.samples().size());
        double fitted = decay_.total_passes(threshold);
        // A fit of the first few passes, before the error has moved, can run to millions: it is held
        // to the cap before it is blended, so that even its small weight cannot pull the plan there
        // (the sci-fi hall showed "pass 5 of ~178,388" for a solve planned at 4,832 that took 3,881).
        if (fitted >= 0.0 && max_passes_ > 0.0) fitted = std::min(fitted, max_passes_);
        expected_passes_ = fitted >= 0.0 ? std::ceil(blend_passes(planned, fitted, decay_, threshold)) : -1.0;
        if (expected_passes_ >= 0.0 && max_passes_ > 0.0) expected_passes_ = std::min(expected_passes_, max_passes_);
    }
    double total = expected_passes_ >= 0.0 ? expected_passes_ : planned;  // no decay seen yet: the plan's
    if (solver.done()) total = done;
    eta_.update(now(), done, std::max(total, done));
    const std::string of = solver.done() ? std::string() : fmt::format(" of ~{:.0f}", std::max(total, done));
    show(fmt::format("pass {}{}, error {:.2e}", solver.passes(), of, solver.error()), false);
}

void StageProgress::rows(long done, long total) {
    into("solve");
    eta_.update(now(), double(done), double(total));
    show(fmt::format("form-factor rows {} / {}", done, total));
}

void StageProgress::refining(int level, long shots, long total) {
    into("refine");
    const double levels = std::max(refine_levels_, level);
    eta_.update(now(), double(level - 1) + double(shots) / double(std::max(1L, total)), levels);
    show(fmt::format("level {}: re-gather {} / {} shots", level, shots, total));
}

// Refinement is over: the gather and the output are predicted again from the elements it left.
void StageProgress::refined(std::size_t elements) {
    WorkCounts w = work_;
    w.refine = false;  // its growth is known: the elements as refined
    w.shape.counts.elements = double(elements);
    for (const StagePlan& s : predict_stages(w))
        if (s.name == "gather" || s.name == "output") eta_.replan(s.name, s.units, s.unit_seconds);
    if (!eta_.has("gather")) return;
    bool gather = false;
    for (const StagePlan& s : predict_stages(w)) gather = gather || s.name == "gather";
    if (!gather) eta_.replan("gather", 0.0, 0.0);  // it will be left out for its size
    output_steps_ = predict_output(double(elements), w.triangles, w.shape.pixels);
}

void StageProgress::gathering(long points, long total) {
    into("gather");
    const double done = double(points), work = double(total);
    // A count that starts again is the next phase (gather refinement's new vertices, a pass each):
    // what came before is its base.
    // In units of a vertex's first hemicube: the first pass's vertices one each, the later
    // passes' kLaterPassShare; the later phases' vertices one each.
    const auto units = [&](double count) {
        if (gather_phase_ > 0) return count;
        const double first = work / gather_passes_;
        return std::min(count, first) + kLaterPassShare * std::max(0.0, count - first);
    };
    if (done < gather_last_done_) {
        gather_base_ += gather_last_units_;
        ++gather_phase_;
    }
    gather_last_done_ = done;
    gather_last_units_ = units(work);
    const double extra = gather_phase_ == 0 ? gather_extra_ * work / gather_passes_ : 0.0;
    eta_.update(now(), gather_base_ + units(done), gather_base_ + units(work) + extra);
    show(fmt::format("{} / {} vertices{}", points, total, gather_phase_ > 0 ? " (refined)" : ""));
}

void StageProgress::gathering_sparse(long points, long budget) {
    into("gather");
    // A hemicube a unit, as the plan counts a sparse gather; it may stop short of its budget.
    eta_.update(now(), double(points), double(std::max(points, budget)));
    show(fmt::format("{} / {} points (sparse)", points, budget));
}

}  // namespace hemirad::bake
