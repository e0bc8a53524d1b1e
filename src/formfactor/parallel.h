// A parallel shot: what a directional light (a sun) lights. Its rays are parallel, so a
// hemicube, which looks out from a point, cannot take it; the elements are drawn instead onto a
// grid across the light's direction (an orthographic projection), with a depth test along it. An
// element's lit share is the share of the cell centres it holds where it is the nearest surface
// (exact in full light and full shadow at any cell size); one smaller than a cell, holding no
// centre, is lit as its centroid is (a shadow map's test, against the plane of the surface
// nearest the light there).
//
// The host projects, snaps and bins the elements into tiles (ParallelRecords); a ParallelRaster
// draws the tiles: the host's (draw_parallel, the reference) or a device's (the OpenCL engine's,
// kernels/parallel.cl), which must give the same owner for every cell. The host's is scalar and
// simple like the reference hemicube (reference.cpp), with the same exact inside test
// (covers_cell: vertices snapped to kSubcell units per cell, the top-left rule), so that elements
// sharing an edge share its cells exactly; its tiles are drawn on threads, and each element's
// cell count is an integer, so the result does not depend on their order.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "formfactor/engine.h"
#include "mesh/mesh.h"

namespace hemirad::formfactor {

struct ParallelSettings {
    // The grid's cell, as a fraction of the median element's edge (the square root of its
    // area): the median element, facing the light, covers about 1 / cell² cells.
    double cell = 1.0 / 16.0;
    int max_cells = 4096;  // per side of the grid: where the scene is wide, cells grow instead (16M cells)
    int threads = 0;       // 0: the machine's
};

// The grid one shot drew: its cell's side (scene units) and its size in cells.
struct ParallelGrid {
    double cell = 0.0;
    int width = 0, height = 0;
};

// Cells per side of the tiles records are binned into: one work-group each on a device.
inline constexpr int kParallelTile = 16;

// What a raster draws: the elements facing the light or blocking it, projected and snapped, in
// element order, binned by the tiles their cell boxes meet. Flat arrays, as a device reads them.
struct ParallelRecords {
    ParallelGrid grid;
    double xmin = 0.0, ymin = 0.0;  // the grid's corner in the light's frame (u, v)
    int tiles_x = 0, tiles_y = 0;
    // Per record r: its polygon's corners px[4r + i], py[4r + i] (counter-clockwise, kSubcell
    // units per cell; a triangle repeats none, its fourth unused), shape[5r..5r+4] = n, i0, i1, j0,
    // j1 (its vertex count and the cells its box holds), plane[4r..4r+3] = nu, nv, nw, c (its plane
    // n·(x u + y v + z w) = c: depth along the light (c − nu x − nv y) / nw at cell centre (x, y)).
    std::vector<std::int64_t> px, py;
    std::vector<std::int32_t> shape;
    std::vector<double> plane;
    // Tile t's records, ascending: bin_items[bin_start[t] .. bin_start[t + 1]).
    std::vector<std::uint32_t> bin_start, bin_items;
    std::size_t size() const { return shape.size() / 5; }
};

// Draws records onto their grid: per cell (row-major) the record nearest the light whose polygon
// holds the cell's centre (the first on a depth tie; −1 where none), and per record the cell
// centres its polygon holds. The host's (draw_parallel) is the reference; a device's must give
// the same, cell for cell (the OpenCL engine's: kernels/parallel.cl).
class ParallelRaster {
public:
    virtual ~ParallelRaster() = default;
    virtual std::string name() const = 0;
    virtual void draw(const ParallelRecords& records, std::vector<std::int32_t>& owner,
                      std::vector<std::uint32_t>& covered) = 0;
};

// The host's raster: tiles on the machine's threads (`threads` 0: all), scalar and simple.
void draw_parallel(const ParallelRecords& records, std::vector<std::int32_t>& owner, std::vector<std::uint32_t>& covered,
                   int threads = 0);

// Elements lit by parallel light travelling along unit `direction`: the row holds, per element,
// cos θ times its lit share (θ between its normal and the light). An element of a mesh lit by a
// directional light of E lux (lm/m²) receives E × that value. Fronts facing the light receive
// it; backs of one-sided surfaces block it (their share is `blocked`, in scene units²); a
// doubleSided surface's back is its twin's front. Coarse elements (the sky dome) neither block
// nor receive: the sun lies beyond them. `shot` turns the grid about the direction (seeded like
// a hemicube's frame) so that its cells' aliasing is not the same at every refinement level.
// `raster` draws the records (null: the host's). `owner`, if set, receives the owner of each cell
// (the raster's, row-major over the grid; empty where nothing was drawn): what --verify compares.
ParallelGrid shoot_parallel(const mesh::Mesh& mesh, const glm::dvec3& direction, std::uint64_t shot, ShotResult& out,
                            const ParallelSettings& settings = {}, ParallelRaster* raster = nullptr,
                            std::vector<std::int32_t>* owner = nullptr);

// A directional shooter's shot (Shooter::Kind::directional): shoot_parallel along the direction
// of mesh.directions[request.shooter.patch], its grid turned by request.shot, at the default
// settings. How every engine answers such a request, each with its own raster (null: the host's).
ParallelGrid shoot_directional(const mesh::Mesh& mesh, const ShotRequest& request, ShotResult& out,
                               ParallelRaster* raster = nullptr, std::vector<std::int32_t>* owner = nullptr);

// For engines whose batches run hemicubes together: the batch's shots but its directional ones,
// in order, into `hemicubes`, and per shot its place there (−1: a directional one). False, with
// nothing filled, when the batch holds no directional shot.
bool split_directional(const std::vector<ShotRequest>& shots, std::vector<ShotRequest>& hemicubes,
                       std::vector<long>& place);

}  // namespace hemirad::formfactor
