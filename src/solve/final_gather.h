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

// The points a final gather shoots from: every vertex of `welded` (weld(node_count, mesh, …)) of
// the nodes `gathered(node)` selects, in node then vertex order, each moved kGatherInset toward its
// triangles' centroid, looking along the vertex's normal.
std::vector<mesh::GatherPoint> gather_points(const output::WeldedMesh& welded,
                                             const std::function<bool(std::size_t node)>& gathered);

// What a gather draws: `mesh` with each planar cell patch as one element (its cell) and a
// cluster's elements as they are, in patch order; lights copied. A gather sums light over the
// whole hemisphere, where from afar a patch's mean radiosity is what counts; the point's shadows
// come from its own hemicube at pixel resolution, and the drawing costs a patch, not its elements
// (the Cornell box at the default quality: 742 drawn elements for 15,354).
mesh::Mesh gather_mesh(const mesh::Mesh& mesh);

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
    int passes = 1;   // gathers; each after the first draws the last one's light (see final_gather)
    std::function<bool()> cancelled;                       // checked between engine calls
    std::function<void(long done, long total)> progress;   // after each engine call (all passes)
};

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

}  // namespace hemirad::solve
