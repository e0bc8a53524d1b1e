// An independent, converged radiosity reference for a convex box room: exact unoccluded form factors, no hemicube.
#pragma once

// The benchmark bakes the room with hemirad at many settings and compares against this. Nothing here
// uses hemirad's engines, mesh builder or solver: the room is gridded into rectangles, form factors come
// from Lambert's closed form (formfactor::point_to_polygon) integrated over the sending cell by adaptive
// Gauss–Legendre quadrature, and B = E + ρFB is solved to a 1e-12 relative residual. The box is convex
// and the emitter is part of the ceiling, so no surface hides any other and the form factors need no
// visibility term.
//
// Conventions: the box is [0, size.x] × [0, size.y] × [0, size.z] in metres, Y up. Walls: north at
// z = 0, south at z = size.z, west at x = 0, east at x = size.x. Every surface faces into the room.
// Radiosity and emission are in W/m² per channel (hemirad's convention: B = E + ρ·irradiance).

#include <array>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "mesh/mesh.h"
#include "scene/scene.h"

namespace hemirad::bench {

// The named surfaces, also the scene's mesh nodes and materials in this order.
enum class Surface : int { floor, ceiling, light, wall_north, wall_south, wall_east, wall_west };
inline constexpr int kSurfaceCount = 7;

// "floor", "ceiling", "light", "wall_north", "wall_south", "wall_east", "wall_west".
const char* surface_name(Surface s);

// `Room{}` is the default room: 4 × 2.5 × 5 m, grey 0.7 walls with a red west wall (colour bleeding), a
// warm floor, and a centred 1 × 1 m light panel in the ceiling emitting 10 W/m².
struct Room {
    glm::dvec3 size{4.0, 2.5, 5.0};  // metres, each > 0
    // The light: a rectangle of the ceiling (x, z in metres), inside [0, size.x] × [0, size.z],
    // with positive width and depth. The rest of the ceiling is Surface::ceiling.
    glm::dvec2 light_min{1.5, 2.0};
    glm::dvec2 light_max{2.5, 3.0};
    // Reflectance per Surface (index by int(Surface)), each channel in [0, scene::kMaxReflectance].
    std::array<glm::dvec3, kSurfaceCount> rho{{
        {0.5, 0.45, 0.4},  // floor
        {0.7, 0.7, 0.7},   // ceiling
        {0.8, 0.8, 0.8},   // light
        {0.7, 0.7, 0.7},   // wall_north
        {0.7, 0.7, 0.7},   // wall_south
        {0.7, 0.7, 0.7},   // wall_east
        {0.7, 0.2, 0.2},   // wall_west
    }};
    // Emission per Surface, W/m² per channel, >= 0. Only the light by default.
    std::array<glm::dvec3, kSurfaceCount> emission{{
        {0.0, 0.0, 0.0},     // floor
        {0.0, 0.0, 0.0},     // ceiling
        {10.0, 10.0, 10.0},  // light
        {0.0, 0.0, 0.0},     // wall_north
        {0.0, 0.0, 0.0},     // wall_south
        {0.0, 0.0, 0.0},     // wall_east
        {0.0, 0.0, 0.0},     // wall_west
    }};
};

// Cell edge length for solve_room: the default room then has 8500 cells, takes ~1 s on 2 cores and a
// 290 MB matrix, and its surface averages are within ~0.005% and its gathered point values within ~0.07%
// of converged (extrapolated from the h² convergence recorded in tests/test_room_reference.cpp).
inline constexpr double kDefaultCellSize = 0.1;

// The room as a hemirad scene: each surface one inward-facing quad (two counter-clockwise triangles,
// one primitive per quad), except the ceiling, which is the up-to-8 rectangles around the light so that
// it is coplanar with the light and overlaps nothing. One material and one MeshNode per Surface, in
// Surface order, named by surface_name. Throws std::invalid_argument for an invalid room.
scene::Scene make_room_scene(const Room& room);

// One rectangle of the reference grid.
struct Cell {
    std::array<glm::dvec3, 4> v;  // corners, counter-clockwise seen from inside the room
    glm::dvec3 centre{0.0};
    glm::dvec3 normal{0.0};  // unit, into the room
    double area = 0.0;       // m²
    Surface surface = Surface::floor;
    int face = 0;  // box face: 0 floor, 1 ceiling (light cells too), 2 north, 3 south, 4 west, 5 east
};

// The room cut into rectangles. The cell boundaries along each axis are shared by every face that axis
// lies in, and include the light's edges, so every cell is wholly light or wholly something else.
struct RoomGrid {
    Room room;
    double cell_size = 0.0;                    // requested maximum edge length, metres
    std::array<std::vector<double>, 3> edges;  // cell boundaries along x, y, z (ascending, from 0 to size)
    std::vector<Cell> cells;                   // face by face

    // The cell containing `point`, which must lie on the face whose inward normal is `normal` (the
    // normal only picks the face, so points on a room edge are unambiguous). A point on a cell boundary
    // goes to the cell with the larger coordinate. Throws std::invalid_argument when off the surface.
    std::size_t cell_at(const glm::dvec3& point, const glm::dvec3& normal) const;
};

// Cells of about `cell_size` metres (each axis segment between box and light edges is split evenly into
// ceil(length / cell_size) parts). Throws std::invalid_argument for an invalid room or cell size, or
// more than kMaxCells cells.
RoomGrid make_room_grid(const Room& room, double cell_size);

// The form-factor matrix is n² floats: this caps it at ~0.9 GB.
inline constexpr std::size_t kMaxCells = 15000;

// Form factor from rectangle `from` to rectangle `to` (area average over `from` of Lambert's
// point-to-polygon factor), with `to` wholly in front of `from`'s plane and nothing between them.
// Adaptive Gauss–Legendre: a piece of `from` closer to `to` than its own diagonal is split in four, down
// to 2⁻⁸ of the cell, so cells sharing an edge (where the integrand's slope is log-singular) stay accurate
// to ~1e-8; farther pieces take 4, 3 or 2 points a side by distance. ~1e-8 relative on the closed forms.
double cell_form_factor(const Cell& from, const Cell& to);

// The dense form-factor matrix of a room grid. Cells on the same face see each other with F = 0.
struct RoomFormFactors {
    RoomGrid grid;
    std::vector<float> f;  // row-major n × n: F_ij = f[i·n + j], from cell i to cell j

    std::size_t size() const { return grid.cells.size(); }
    double operator()(std::size_t i, std::size_t j) const { return f[i * size() + j]; }
};

// Every F_ij is integrated (F_ji is not derived by reciprocity, so reciprocity is a check). Cell pairs
// that are translates or mirror images of one another along an axis both faces contain have equal
// factors, so each distinct configuration is integrated once (2.4M instead of 59M at 0.1 m); uses all
// hardware threads.
RoomFormFactors room_form_factors(const Room& room, double cell_size);

struct RoomSolution {
    RoomGrid grid;
    std::vector<glm::dvec3> radiosity;  // per cell, W/m²
    std::vector<glm::dvec3> incident;   // per cell: irradiance Σ_j F_ij B_j, W/m²
    // Per surface, in Surface order: area-weighted average radiosity (RGB).
    std::vector<std::pair<std::string, glm::dvec3>> surface_average;
    int iterations = 0;     // matrix–vector products the solve took
    double residual = 0.0;  // max |E + ρFB − B| / max B of the returned B, worst channel

    glm::dvec3 average(Surface s) const { return surface_average[static_cast<std::size_t>(s)].second; }

    // Radiosity at a point on the surface (normal as in RoomGrid::cell_at): a final gather,
    // E + ρ Σ_j F(point → cell j) B_j with Lambert's exact point-to-cell factors. Smoother and more
    // accurate than the containing cell's value (which is off by ~gradient × cell/2), and it keeps the
    // jump at the light's edge sharp. Costs one point_to_polygon per cell.
    glm::dvec3 radiosity_at(const glm::dvec3& point, const glm::dvec3& normal) const;

    // Average radiosity over a triangle or convex quad lying on one surface, counter-clockwise seen from
    // inside (a hemirad element's polygon): radiosity_at at 3 (triangle) or 2 × 2 (quad) quadrature points.
    // What a piecewise-constant element approximates, so comparing with it leaves out the in-element
    // variation that a point comparison charges the element with (several % next to the light).
    glm::dvec3 average_over(const mesh::Polygon& polygon) const;
};

// Solves (I − ρF)B = E by restarted GMRES, the three channels sharing each (threaded) pass over the
// matrix, until the true residual is below 1e-12 relative; throws InternalError if it is not reached.
RoomSolution solve_room(const RoomFormFactors& factors);
RoomSolution solve_room(const Room& room, double cell_size = kDefaultCellSize);

// A point at which to compare a bake with the reference.
struct Probe {
    std::string surface;  // surface_name
    glm::dvec3 point{0.0};
    glm::dvec3 normal{0.0};  // unit, into the room
};

// The centres of a per_edge × per_edge grid on each surface's rectangle (for the ceiling, its full
// rectangle, keeping only points outside the light's closed rectangle), surfaces in Surface order.
// per_edge >= 1.
std::vector<Probe> room_probes(const Room& room, int per_edge);

}  // namespace hemirad::bench
