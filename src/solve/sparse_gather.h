// A sparse final gather: hemicubes at some of the output's vertices, chosen where the light
// varies, and the light between them interpolated over the surface.
//
// A full final gather (final_gather.h) shoots a hemicube from every output vertex. Real scenes
// have 100k–1M of them, and on two cores a gather hemicube of such a scene costs milliseconds, so
// the full gather was left out there and the outputs showed the elements' means: the bias along
// creases and contact lines the gather corrects, and the solver's per-element noise (a closed
// room's ceiling, lit by its walls alone, blotchy). This is the irradiance-caching idea (Ward,
// Rubinstein and Clear 1988) on the welded mesh:
//  1. Seeds: per node, connected surface and cell of a grid, the vertex nearest the cell's centre,
//     the cell chosen so that the seeds are about a quarter of the budget (seed_share); a scene of
//     more separate surfaces than that has one a surface, those of the most vertices first, up to
//     the whole budget, and the surfaces left without one keep their elements' light.
//  2. Each level gathers its new points (final_gather, one pass, the others known), then
//     interpolates between the gathered points across the surface (the K nearest along the mesh's
//     edges, Franke–Little weights, so the interpolant is continuous where the neighbours change).
//  3. Where the interpolant cannot follow the light, more points: a vertex whose elements' mean
//     irradiance (the solver's) differs from the same interpolation of the gathered points' means
//     by more than `tolerance` (a contact shadow or a penumbra between the points), or whose
//     gathered neighbours differ among themselves by more than `tolerance` (light changing between
//     them), marks its cell of a grid half as fine as the last; the marked cells' worst vertices
//     are gathered next, the worst first within the budget. Vertices along contact lines
//     (mesh/contact.h) come first, where the budget is at least a quarter of the vertices.
//     What budget the levels leave goes to coverage: a point in each piece of surface, per cell
//     of a grid sized to it, that holds none (a surface of one point shows neither test).
//  4. A vertex not shot takes its elements' light plus the interpolated correction the gathered
//     points found for theirs (gathered minus their elements' mean): the elements' detail stays
//     and their bias goes. Points that saw mostly backs are no source, and end with their seen
//     neighbours' light (fill_hidden), as in a full gather.
// The direct light of punctual and directional lights (their sharp shadows) is not interpolated:
// it is the elements' own (`direct`, as final_gather adds it). Only the light the elements
// reflect is. Every choice depends on the mesh and the solution alone: the same bytes on every
// device and thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <vector>

#include "formfactor/engine.h"
#include "mesh/mesh.h"
#include "output/welded_mesh.h"
#include "solve/final_gather.h"

namespace hemirad::solve {

struct SparseGatherSettings {
    std::size_t budget = 50000;  // gather hemicubes at most, all levels
    double seed_share = 0.25;    // of the budget, for the seeds
    int levels = 4;              // rounds of densification at most
    double tolerance = 0.1;      // relative difference in luminance that asks for more points
    double noise_floor = 0.02;   // ... above this share of the gathered vertices' mean irradiance
    int neighbours = 6;          // gathered points an interpolated vertex weighs
    // Told the points shot so far and the budget, after each engine call (instead of settings').
    std::function<void(long points, long budget)> progress;
};

struct SparseGathered {
    long points = 0;               // hemicubes shot, all levels
    long seeds = 0;                // of them, the first level's
    int levels = 0;                // densification levels that added points
    long covered = 0;              // points of the coverage round (the budget the levels left)
    std::size_t vertices = 0;      // vertices of the gathered nodes
    std::size_t interpolated = 0;  // of them, those given an interpolated light
    std::size_t unreached = 0;     // ... and those no gathered point reached (the elements' means)
    bool capped = false;           // a level wanted more points than the budget left
    bool cancelled = false;
};

// The gathered points' light at the other vertices of one node: per vertex, up to `k` gathered
// vertices nearest along the mesh's edges, with weights that sum to 1 (Franke–Little:
// ((R − d)/(R d))², R the distance of the k-th nearest, so the farthest weighs nothing and the
// interpolant is continuous where the set changes; a gathered vertex weighs itself alone; a vertex
// of a surface with fewer than k gathered points weighs them all with R twice the farthest).
// `gathered_vertex[v]` marks the gathered vertices. Vertices no gathered vertex reaches get none.
// Ties in distance go to the lower vertex index: the result depends on the mesh alone.
struct Interpolation {
    std::vector<std::uint32_t> start;   // per vertex, its first entry; size vertices + 1
    std::vector<std::uint32_t> source;  // gathered vertex
    std::vector<double> weight;
};
Interpolation interpolation(const output::WeldedNode& node, const std::vector<char>& gathered_vertex, int k);

// The light of a vertex not shot: its elements' reflected light `own` (≥ 0, per channel) with the
// gathered points' correction `c` (interpolated, gathered minus elements', per channel). Where c
// brightens (luminance ≥ 0) it is added, channel by channel; where it darkens, by a weight
// w = min(1, −Y(c)/Y(own)) it is instead a scale of `own` by 1 + Y(c)/Y(own): the elements' hue
// kept and the corrected luminance given. Added alone and clamped at zero channel by channel, a
// darkening larger than a channel's light left only the other channels: Littlest Tokyo's orange
// wall behind a lantern string came out saturated red (clusters apart, 2026-12-07). The blend is
// continuous in own and c, never negative, and never lights a dark vertex in its own faint hue.
glm::dvec3 corrected_light(const glm::dvec3& own, const glm::dvec3& c);

// The sparse gather: as final_gather (its arguments; settings' batch, progress and cancel; one
// pass), but shooting at most `sparse.budget` points, chosen as above, and interpolating the
// rest. `out` then holds every vertex's light, as final_gather's does.
SparseGathered sparse_gather(const mesh::Mesh& mesh, const output::WeldedMesh& welded,
                             const std::function<bool(std::size_t node)>& gathered,
                             const std::vector<glm::dvec3>& radiosity, const std::vector<glm::dvec3>& irradiance,
                             const std::vector<glm::dvec3>& direct, const mesh::Mesh& drawn, formfactor::Engine& engine,
                             const GatherSettings& settings, const SparseGatherSettings& sparse,
                             output::VertexLight& out);

}  // namespace hemirad::solve
