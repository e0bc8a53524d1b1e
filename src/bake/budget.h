// A bake's memory, estimated from its mesh counts before the mesh is built, and the solver
// `--solver auto` picks by that memory and by expected time.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "mesh/mesh.h"
#include "solve/matrix.h"

namespace hemirad::bake {

// What the estimate is made from.
struct BakeShape {
    mesh::Counts counts;        // of the mesh as built (before refinement)
    int hemicube = 256;         // N
    int batch = 1;              // progressive shots per engine call
    // The matrix solver's settings as the bake would use them: rows per engine call, one channel
    // (grey), direct light only (!interreflection), the tolerance of its error bound.
    solve::MatrixSettings matrix;
    bool opencl = false;        // an OpenCL engine (on a CPU, its buffers are host memory)
    bool fallback_copy = false; // auto chose OpenCL: the mesh as built is kept for a restart on the reference
    double max_reflectance = 0.0;
    int refine_levels = 2;
    double pixels = 640.0 * 480.0;  // of render.exr/.png
    // Where a directional light shines, the cells of its parallel shots' grid (formfactor/parallel.h); 0: none.
    double parallel_cells = 0.0;
};

struct MemoryPart {
    std::string what;
    double bytes = 0.0;
};

// Bytes by part: the mesh, the form-factor engine, the solver, refinement and the output.
// Estimates, not bounds: refinement is taken to double the elements (measured 1.8× on the Cornell
// box) and is stopped at run time where it would pass the budget.
struct MemoryEstimate {
    std::vector<MemoryPart> parts;
    double total() const;
    // The total without refinement's part: what a bake needs whatever refinement finds to split
    // (refinement itself is stopped where it would pass the budget).
    double needed() const;
    std::string describe() const;  // "mesh 1.2 GB, engine 300 MB, ..."
};
MemoryEstimate estimate_memory(const BakeShape& shape, const std::string& solver);

// The progressive solve's budget for kept form-factor rows (formfactor::RowCacheEngine).
double row_cache_bytes(const BakeShape& shape);

// Refined elements the budget leaves room for once the rest of the estimate is spent (at least
// the elements as built).
double refinement_room(const BakeShape& shape, const std::string& solver, double limit);

// Seconds the two solvers are expected to take, in a model with constants measured on 2 PoCL
// cores (their ratio decides, not their values): the matrix shoots every patch once, then sweeps
// a dense K per channel (expected_sweeps of it, each P² multiply-adds); progressive shooting takes
// about three rounds of one pass per patch, each pass with host work for every element.
struct SolverTimes {
    double matrix = 0.0, progressive = 0.0;
};
SolverTimes expected_times(const BakeShape& shape);

// The model's parts, for the progress line's time model (eta.h): a solver's hemicube of
// resolution `hemicube` on the mesh of `shape`; a batched one (the lights'; the final gather's is
// stage_progress.h's gather_point_seconds); the progressive passes expected (about three rounds of
// √(924·P)).
double shot_seconds(const BakeShape& shape, int hemicube);
double batched_shot_seconds(const BakeShape& shape, int hemicube);
double expected_passes(const BakeShape& shape);

// Seconds the counted work of a bake is expected to take, by part, in the model of
// expected_times (2 CPU cores through PoCL; a GPU is faster): the matrix solve's rows and sweeps
// (not progressive shooting, whose passes are not known before), the lights' hemicubes
// (`light_hemicubes`), and the final gather (`gather_points` first hemicubes of
// `gather_point_seconds` each, as stage_progress.h's model has them; the later passes re-use
// their rows). Said before a bake that would take minutes.
struct TimeEstimate {
    std::vector<std::pair<std::string, double>> parts;  // (what, seconds)
    double total() const;
    std::string describe() const;  // "solve 3.2 min, lights' hemicubes 9 min, ..."
};
std::string format_duration(double seconds);  // "45 s", "12 min", "2.5 h"
TimeEstimate expected_bake_time(const BakeShape& shape, const std::string& solver, double light_hemicubes,
                                double gather_points, double gather_point_seconds);

// `auto`'s choice: the matrix where the bake with it needs at most half the memory limit and it
// is expected to be no slower (timed as on OpenCL whatever the engine, so that every device bakes
// the same bytes); else progressive. `why` says which rule decided, with the numbers.
struct SolverChoice {
    std::string solver;
    std::string why;
};
SolverChoice choose_solver(const BakeShape& shape, double limit);

}  // namespace hemirad::bake
