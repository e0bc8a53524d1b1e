// Parallel shots (a directional light's), cell for cell the host's draw_parallel
// (src/formfactor/parallel.cpp): a work-group per tile of HR_PARALLEL_TILE x HR_PARALLEL_TILE
// cells, a work-item per cell, walking its tile's records in ascending order. The inside test is
// the reference's exact integer edge test (covers_cell) on corners snapped on the host; the
// depth is the host's expression in double precision, in the same order, without contraction;
// the nearest record wins, the first on a tie. Each record counts the cell centres it holds
// (atomic increments of 32-bit counters: integers, so in any order).
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#include "hemicube_types.h"

#ifndef HR_PARALLEL_TILE
#define HR_PARALLEL_TILE 16
#endif
#define SUBCELL ((long)1 << HR_SUBCELL_BITS)

// formfactor::covers_cell: whether the centre of cell (i, j) lies in the counter-clockwise
// polygon, or on an edge the top-left rule gives it.
bool covers(__global const long* px, __global const long* py, int n, int i, int j) {
    const long x = (long)i * SUBCELL + SUBCELL / 2, y = (long)j * SUBCELL + SUBCELL / 2;
    for (int a = 0; a < n; ++a) {
        const int b = a + 1 == n ? 0 : a + 1;
        const long dx = px[b] - px[a], dy = py[b] - py[a];
        if (dx == 0 && dy == 0) continue;  // snapping can repeat a vertex
        const long edge = dx * (y - py[a]) - dy * (x - px[a]);
        if (!(edge > 0 || (edge == 0 && (dy < 0 || (dy == 0 && dx > 0))))) return false;
    }
    return true;
}

__kernel __attribute__((reqd_work_group_size(HR_PARALLEL_TILE, HR_PARALLEL_TILE, 1)))
void parallel_raster(const int width, const int height, const int tiles_x, const double cell, const double xmin,
                     const double ymin, __global const long* px, __global const long* py,
                     __global const int* shape, __global const double* plane, __global const uint* bin_start,
                     __global const uint* bin_items, __global int* owner, __global volatile uint* covered) {
    const int i = (int)get_global_id(0), j = (int)get_global_id(1);
    const uint tile = (uint)get_group_id(1) * (uint)tiles_x + (uint)get_group_id(0);
    const double x = (i + 0.5) * cell + xmin, y = (j + 0.5) * cell + ymin;
    int best = -1;
    double best_depth = 0.0;
    const uint end = bin_start[tile + 1];
    for (uint k = bin_start[tile]; k < end; ++k) {
        const uint q = bin_items[k];
        __global const int* s = shape + 5 * (size_t)q;
        if (i < s[1] || i > s[2] || j < s[3] || j > s[4]) continue;
        if (!covers(px + 4 * (size_t)q, py + 4 * (size_t)q, s[0], i, j)) continue;
        atomic_inc(&covered[q]);
        __global const double* p = plane + 4 * (size_t)q;
        const double depth = (p[3] - p[0] * x - p[1] * y) / p[2];
        if (best < 0 || depth < best_depth) {
            best = (int)q;
            best_depth = depth;
        }
    }
    if (i < width && j < height) owner[(size_t)j * (size_t)width + (size_t)i] = best;
}
