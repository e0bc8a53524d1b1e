// Final gather: the light at every output vertex, gathered from the converged solution.
//
// A solver's answer is one value per element, an average over its area, and the outputs used to
// show each vertex the mean of the elements around it. That reconstruction is biased wherever
// light changes across an element: at creases and corners, along the lines where objects stand on
// floors, beside a lamp, along shadow edges (measured against a path tracer in `hemirad bench
// --accuracy`: 6.5% per-pixel RMS error on the Cornell box at the default quality). The classic
// cure (Cohen & Wallace, Radiosity and Realistic Image Synthesis, ch. 9; Lischinski et al. 1993):
// one more hemicube from each output vertex, on the same engines, gathering the converged
// radiosities through it, H(x) = Σ F(dA_x → j) B_j. A vertex then sees what is next to it at the
// hemicube's resolution, whatever the elements' size.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <vector>

#include <glm/glm.hpp>

#include "formfactor/engine.h"
#include "mesh/mesh.h"
#include "mesh/texturing.h"
#include "output/welded_mesh.h"

namespace hemirad::solve {

// Shot counters of gather hemicubes start here (patches count from 0, re-gathers from 2^40,
// lights from 2^42): gather point i takes kGatherShots + i in every pass.
inline constexpr std::uint64_t kGatherShots = std::uint64_t{1} << 43;

// How far a gather point lies from its vertex toward the centroid of the triangles around it. At
// the vertex itself it would sample a single point of a crease, a contact line or a lamp's edge,
// which linear interpolation then spreads over whole triangles; a quarter of the way in it
// stands for its triangles (measured on the Cornell box: 2.35% per-pixel error at a hundredth,
// 2.00% at a quarter, 2.07% at 0.4).
inline constexpr double kGatherInset = 0.25;
// ... but a vertex on the rim of its surface (an edge of one triangle: where the surface ends, folds
// at a crease or meets another node) only this far: a quarter of the way in, it read the light a
// few millimetres inside the rim, where the light changes most (the Cornell box's open front edges
// +4.5% in a 16×16 tile). Measured on the Cornell box, with contact grading and gather refinement:
// default 1.48% at a quarter, 1.40% at 0.1, 1.39% at 0.05, 1.38% at 0.02, 3.1% at 0 (the point on
// the line itself); high 1.10% → 1.03% (0.05 and 0.02); draft 5.58% → 5.64% (0.05; it has no gather
// refinement and coarse elements).
inline constexpr double kGatherRimInset = 0.05;

// The points a final gather shoots from: every vertex of `welded` (weld(node_count, mesh, …)) of
// the nodes `gathered(node)` selects, in node then vertex order, each moved kGatherInset toward its
// triangles' centroid (kGatherRimInset on its surface's rim), looking along the vertex's normal.
std::vector<mesh::GatherPoint> gather_points(const output::WeldedMesh& welded,
                                             const std::function<bool(std::size_t node)>& gathered);

// What a gather draws: `mesh` with each planar cell patch as one element (its cell) and each face
// of a cluster as one element (the scene face its elements were cut from), in patch order; lights
// copied. A gather sums light over the whole hemisphere, where from afar a patch's or a face's
// mean radiosity is what counts; the point's shadows come from its own hemicube at pixel
// resolution, near cells are weighed element by element (final_gather), and the drawing costs a
// patch or a face, not its elements (the Cornell box at the default quality: 742 drawn elements
// for 15,354; the 62k-triangle living room at draft 52,989 for 225,312 drawn before faces).
mesh::Mesh gather_mesh(const mesh::Mesh& mesh);

// One element of a gather's drawing: the elements [first, first + count) of the solved mesh, drawn
// as `poly` (a cell patch's cell, a cluster face's outline, or the one element itself).
struct DrawnCell {
    std::uint32_t first = 0, count = 1;
    mesh::Polygon poly;
};
// The cells gather_mesh draws for `patch` of `mesh`, in order. A cluster's run of consecutive
// elements cut from one scene face (equal Element::source) is one cell where the face's outline
// is exact: its corners are the element corners that lie in one element only, three or four of
// them, planar, convex and of the elements' total area (to 1e-9); otherwise its elements are
// drawn one by one.
std::vector<DrawnCell> drawn_cells(const mesh::Mesh& mesh, const mesh::Patch& patch);

// Splits the elements of `mesh` marked in `split` in four (mesh::split_elements, with `texturing`),
// and carries a solution over: children take their parent's irradiance, and each of `radiosities`
// E + ρH by their own emission and reflectance (the parent's exactly where it is untextured), so
// every element average, and the light a gather draws, is unchanged.
void split_solved(mesh::Mesh& mesh, const std::vector<bool>& split, const mesh::Texturing* texturing,
                  std::initializer_list<std::vector<glm::dvec3>*> radiosities, std::vector<glm::dvec3>& irradiance);

// Grades `mesh` toward its contact lines (mesh/contact.h) for a gather: every element along one
// that is longer than `min_size` is split in four (mesh::split_elements, with `texturing`). Children
// take their parent's irradiance, and radiosity E + ρH by their own emission and reflectance (the
// parent's exactly where it is untextured), so every element average, and the light the gather
// draws, is unchanged; the gather's vertices along the line double. Returns the elements split.
std::size_t grade_contacts(mesh::Mesh& mesh, std::vector<glm::dvec3>& radiosity, std::vector<glm::dvec3>& irradiance,
                           double min_size, const mesh::Texturing* texturing);

// Entries of the first pass's rows a multi-pass gather keeps for the later passes, with their near
// cells' weights (element and form factor, 12 bytes each; a near cell's entry, 12 more): 384 MiB.
inline constexpr std::size_t kMaxKeptEntries = std::size_t{32} << 20;

struct GatherSettings {
    std::size_t kept_entries = kMaxKeptEntries;  // of the first pass's rows, kept for the later passes
    int batch = 64;   // shots per engine call
    bool engine_batch = false;  // ... or the engine's preferred batch where larger (Engine::preferred_batch)
    int passes = 1;   // gathers; each after the first draws the last one's light (see final_gather)
    // Vertices whose light is already known (a gather of the same surfaces cut coarser, see
    // refine_gather): per node and vertex of the welded mesh, known[n][v] != 0 marks one, whose
    // light `prior` holds; only the others are shot. One pass only.
    const std::vector<std::vector<char>>* known = nullptr;
    const output::VertexLight* prior = nullptr;
    // When given: per node and vertex, 1 where the shot point saw mostly the backs of one-sided
    // surfaces (its light is then its seen neighbours', see final_gather); others untouched.
    std::vector<std::vector<char>>* hidden = nullptr;
    std::function<bool()> cancelled;                       // checked between engine calls
    std::function<void(long done, long total)> progress;   // after each engine call (all passes)
};

// The elements' means at the vertices of `welded` (the one weld of `mesh`): their emission,
// reflectance and `irradiance`, and `direct` (the lights' light; empty where `direct` is).
struct VertexMeans {
    output::VertexValues emission, rho, irradiance, direct;
};
VertexMeans element_means(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                          const std::vector<glm::dvec3>& irradiance, const std::vector<glm::dvec3>& direct);

// Gives each vertex marked in `hidden` (per node and vertex; a node's list empty for none) the mean
// of its unmarked neighbours' light along the triangles' edges, ring by ring inward, as
// final_gather does for the points that see mostly backs (marked vertices with no unmarked one
// around them keep their own).
void fill_hidden(const output::WeldedMesh& welded, const std::vector<std::vector<char>>& hidden,
                 output::VertexLight& out);

// Gathers at the gather points of `drawn` (gather_mesh(mesh) with gather_points(welded, gathered)
// set, and `engine` made for it) from the solved `mesh`'s element radiosities `radiosity` (with the
// ambient term): a drawn cell weighs its elements' area-weighted mean, or within two of its sizes
// of the point each element by its exact unoccluded form factor from the point (the dark band
// where a box stands on a floor, which the mean would wash out). Adds `direct` (per element:
// punctual and directional lights' irradiance, which no element carries; empty for none) as the
// vertex mean of its elements. Each gathered vertex gets irradiance H and radiosity E + ρH (E and
// ρ the means of its elements'); a vertex that sees mostly the backs of one-sided surfaces (under
// a box on the floor, above a lamp just below the ceiling) takes its seen neighbours' mean, so
// that no triangle carries unseen darkness into the light. Vertices of nodes not gathered keep
// their elements' means. With passes > 1, each further pass draws the elements' radiosity anew
// from the last pass's vertices (each element the mean of its triangles' vertices), which corrects
// what the solver's patch-to-element form factors got wrong between surfaces close together.
// Returns false (and leaves `out` unspecified) when cancelled.
bool final_gather(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                  const std::function<bool(std::size_t node)>& gathered, const std::vector<glm::dvec3>& radiosity,
                  const std::vector<glm::dvec3>& irradiance, const std::vector<glm::dvec3>& direct,
                  const mesh::Mesh& drawn, formfactor::Engine& engine, const GatherSettings& settings,
                  output::VertexLight& out);

// Per element of `mesh`: the area-weighted mean over its triangles in `welded` (weld(…, mesh, …)) of
// `values` at their vertices, for the nodes `gathered` selects; `fallback`'s value elsewhere.
std::vector<glm::dvec3> vertex_means(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                                     const std::function<bool(std::size_t node)>& gathered,
                                     const output::VertexValues& values, const std::vector<glm::dvec3>& fallback);

// Adaptive refinement of a gather, where its light changes faster than its vertices can follow (a
// penumbra's edge, a contact line's dark band): every element of a gathered node whose vertices'
// gathered irradiance H spans, in luminance, so much that ρ times the span is more than `contrast`
// of the element's brightest radiosity E + ρH (its own E and ρ: a lamp's uneven lighting by the room
// hardly shows), the span is more than `noise_floor` of the mean H over all gathered vertices, and
// whose longest edge is above `min_size`. `scores`, when given, gets each element's ρ·span / (E + ρH)
// (0 where the element has no gathered vertex).
std::vector<bool> gather_contrasts(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                                   const std::function<bool(std::size_t node)>& gathered,
                                   const output::VertexLight& light, double contrast, double noise_floor,
                                   double min_size, std::vector<double>* scores = nullptr);

// A gathered mesh, refined in place by refine_gather: the solved mesh, its solution (per element),
// the punctual lights' light on it (per element; empty for none), its weld and the gather's light
// at the weld's vertices.
struct GatheredMesh {
    mesh::Mesh& mesh;
    std::vector<glm::dvec3>& radiosity;
    std::vector<glm::dvec3>& irradiance;
    std::vector<glm::dvec3>& direct;
    output::WeldedMesh& welded;
    output::VertexLight& light;
};

struct GatherRefinement {
    int levels = 0;            // rounds of splitting and gathering at most
    double contrast = 0.5;     // see gather_contrasts
    double noise_floor = 0.02;
    double min_size = 0.0;
    // Gathered vertices at most: a level that would pass it splits only its elements of the highest
    // contrast, as many as fit, and is the last.
    std::size_t max_vertices = ~std::size_t{0};
    const mesh::Texturing* texturing = nullptr;  // split elements' own textures (see split_solved)
    // An engine for a drawn mesh (gather_mesh of the refined mesh, with its gather points).
    std::function<std::unique_ptr<formfactor::Engine>(const mesh::Mesh& drawn)> make_engine;
    // The punctual lights' light on a refined mesh; needed when `direct` is not empty.
    std::function<std::vector<glm::dvec3>(const mesh::Mesh& mesh)> direct_light;
};

struct GatherRefined {
    int levels = 0;          // levels taken
    std::size_t split = 0;   // elements split, all levels
    long points = 0;         // vertices gathered, all levels
    bool capped = false;     // a level was cut short (or left out) for max_vertices
    bool cancelled = false;  // settings.cancelled said so (`g` is then the last whole level's)
};

// Gather refinement: up to `r.levels` times, the elements gather_contrasts marks are split in four
// (split_solved; what the gather draws is each element's mean of the last light at its vertices),
// the mesh welded again, the light of the vertices that were there carried over (carry_light),
// and only the new vertices gathered, one pass each (`settings`' batch, progress and cancel). An
// element's light then follows a penumbra or a contact line's dark band down to r.min_size, where
// linear interpolation between vertices a whole element apart could not, at the cost of the
// vertices where the light changes.
GatherRefined refine_gather(const GatheredMesh& g, const std::function<bool(std::size_t node)>& gathered,
                            const GatherSettings& settings, const GatherRefinement& r);

// The light a gather found at the vertices of `old_welded`, carried to the vertices of `welded`
// (the same nodes cut finer): a vertex at the same position, side and crease as an old one takes
// its light and is marked known; the others (the new ones) are left to be gathered.
void carry_light(const output::WeldedMesh& old_welded, const output::VertexLight& old_light,
                 const output::WeldedMesh& welded, output::VertexLight& prior,
                 std::vector<std::vector<char>>& known);

}  // namespace hemirad::solve
