// The bake's one progress line: the stages' calls (bake/progress.h) feed the time model
// (bake/eta.h), planned from the bake's work counts, and the caller's Progress is shown each
// stage's own progress with the bake's time left.
#pragma once

#include <string>
#include <vector>

#include "bake/budget.h"
#include "bake/eta.h"
#include "bake/progress.h"
#include "core/timing.h"

namespace hemirad::bake {

struct Plan;
struct Setup;
struct Meshed;

// What the stages after meshing are predicted from: the mesh's counts (BakeShape) and the work
// the options ask for.
struct WorkCounts {
    BakeShape shape;                 // the mesh's counts, N, the engine
    std::string solver;              // matrix | progressive
    double triangles = 0.0;          // of the scene
    double light_hemicubes = 0.0;    // the punctual lights' (two a point light, one a spot)
    bool refine = false;             // refinement on (shape.refine_levels levels)
    int gather = 0;                  // the final gather's N (0: none)
    // Gather hemicubes at most (gather_budget; 0: no limit): more vertices are gathered sparsely,
    // this many hemicubes in one pass, without gather refinement.
    double gather_budget = 50000;
    bool gather_points_given = false;  // --gather-points: else also timed_gather_budget of the drawn mesh
    int gather_passes = 1;
    bool gather_refine = false;
    // What a gather draws (solve::gather_mesh): the planar patches of more than one element (one
    // each), and the other cells (a cluster's faces, an element where a face's outline is not
    // exact, a patch of one element), counted on the mesh before refinement, which keeps faces.
    double gather_planar_patches = 0.0;
    double gather_cluster_cells = 0.0;
    double max_passes = 0.0;         // the progressive solve's cap (0: none)
    // The emitting patches that hold all but the threshold's share of the emitted flux
    // (solve::flux_holders): the sun's light reflected is not among them before the solve.
    double emitting_holders = 0.0;
    bool sky = false;           // a sky dome (--sky) is among the emitters
    double reflectance = 0.0;   // area-weighted over the elements that do not emit, r g b averaged
};

// The stages after meshing (lights, solve, refine, gather, output), predicted from `w` with the
// budget's per-unit costs (bake/budget.h, 2 CPU cores through PoCL) and the host constants
// measured for the output (stage_progress.cpp).
std::vector<StagePlan> predict_stages(const WorkCounts& w);
// The passes a progressive solve is expected to take, before its error has fallen: `holders`, the
// patches that hold all but the threshold's share of the unshot flux (solve::flux_holders), each
// shoot about once, and the light they reflect takes a tail of passes in proportion to the
// patches, longer the more the scene reflects (stage_progress.cpp says how it was measured).
double expected_solve_passes(const WorkCounts& w, double holders);
// A progressive pass's seconds on 2 CPU cores through PoCL: per element of the mesh (set up,
// drawn, received), and a hemicube's fixed part at its N.
double expected_pass_seconds(const BakeShape& shape);
// A gather vertex's first hemicube of resolution `hemicube`, by the model (2 CPU cores), for a
// drawn mesh of `drawn` elements (solve::gather_mesh), the gather stage's host work included.
double gather_point_seconds(double drawn, int hemicube);
// The gather hemicubes the quality's gather shoots at most on such a drawn mesh, unless
// --gather-points says: as many as the model expects to take kGatherSeconds, at least
// kMinGatherPoints (the 147k-triangle ww2 city, 807k output vertices drawing 242k elements: about
// 10,700 at 8.4 ms a hemicube, where every vertex would take 2 h). A count, not a time: the same on every
// device, so the same bytes.
inline constexpr double kGatherSeconds = 90.0, kMinGatherPoints = 2000.0;
double timed_gather_budget(double drawn, int hemicube);
// The elements a gather of these counts draws, and the hemicubes it is allowed (0: no limit): the
// budget, and unless --gather-points is given, at most what the time model allows them.
double gather_drawn(const WorkCounts& w);
double planned_gather_budget(const WorkCounts& w);
// The progressive solve's passes expected from the plan's `planned` and the decay's `fitted`
// (stage_progress.cpp says how).
double blend_passes(double planned, double fitted, const DecayFit& decay, double threshold);
// A refinement level's predicted seconds.
double refine_level_seconds(const WorkCounts& w);
// The output stage's steps and their predicted seconds, for elements and pixels.
std::vector<std::pair<std::string, double>> predict_output(double elements, double triangles, double pixels);

class StageProgress final : public Progress {
public:
    explicit StageProgress(Progress& shown) : shown_(shown), start_(Clock::now()) {}

    // The plan, as the bake learns it: before loading (the file's size), after loading (its
    // triangles), once the mesh's counts are known (everything else).
    void plan_load(const std::string& file);
    void plan_mesh(double triangles);
    void plan_rest(const WorkCounts& w);

    void note(const std::string& line) override { shown_.note(line); }
    void warning(const std::string& text, bool always) override { shown_.warning(text, always); }
    void begin_stage(const std::string& stage) override;
    void end_stage() override;
    void writing(const std::string& what) override;
    void lights(std::size_t done, std::size_t total) override;
    void passes(const solve::Progressive& solver, double threshold) override;
    void rows(long done, long total) override;
    void refining(int level, long shots, long total) override;
    void gathering(long points, long total) override;
    void gathering_sparse(long points, long budget) override;
    void refined(std::size_t elements) override;

    double now() const { return seconds_since(start_); }
    const Eta& eta() const { return eta_; }
    // The progressive solve's passes as the decay fit expects them at the end (< 0: no fit yet).
    double expected_passes() const { return expected_passes_; }

private:
    void show(const std::string& detail, bool last = false);
    void into(const std::string& stage);  // the model's stage, begun if not yet

    Progress& shown_;
    Clock::time_point start_;
    Eta eta_;
    bool planned_ = false;  // the whole bake is planned: the prediction is sampled from now on
    double last_shown_ = -1e9;
    std::string detail_;
    // The progressive solve's decay, the cap on its passes.
    DecayFit decay_;
    double fitted_at_ = -1.0, expected_passes_ = -1.0, max_passes_ = 0.0;
    bool solve_replanned_ = false;  // the solve's passes counted from its holders (passes())
    int refine_levels_ = 0;
    // The gather's phases (the gather, then each refinement level's new vertices): the work of
    // the phases before, and the last count seen.
    double gather_base_ = 0.0, gather_last_done_ = 0.0, gather_last_units_ = 0.0, gather_extra_ = 0.0;
    double gather_passes_ = 1.0;
    int gather_phase_ = 0;
    WorkCounts work_;
    std::string load_detail_, mesh_detail_;
    std::vector<std::pair<std::string, double>> output_steps_;
};

}  // namespace hemirad::bake
