// Stage 4, raster (included by hemicube.cl): what both rasters share (the shot's buffer slices,
// its tiles, the delta form-factor table), and `raster`, one work-item per cell (GPUs). The CPU
// raster, raster_records, is in hemicube_raster_records.cl.

// What both raster kernels read and write of shot b of the batch: its slices of the per-shot
// buffers.
void raster_slices(const HrShot* shot, size_t b, __global const HrRecord** records, __global const HrBox** boxes,
                   __global const uint** offsets, __global const uint** lists, __global int** ids,
                   __global long** sums) {
    *records += b * record_stride(shot);
    *boxes += b * record_stride(shot);
    *offsets += b * (counter_stride(shot) + 1);
    *lists += b * (size_t)shot->list_capacity;
    *ids += b * cell_stride(shot);
    *sums += b * sum_stride(shot);
}

// The face a tile lies on (tiles are numbered face by face).
int tile_face(const HrShot* shot, int tile) {
    int face = 0;
    while (face < HR_FACES - 1 && tile >= shot->tile_base[face + 1]) ++face;
    return face;
}

// Cells of a raster tile; the delta form-factor table holds the tiles' cells tile by tile.
#define TILE_CELLS (HEMIRAD_TILE * HEMIRAD_TILE)

// Where a shot's cell weights start in the weight tables (form factors, then solid angles: see
// HrShot::table), each holding every tile's cells.
size_t shot_table(const HrShot* shot) {
    return (size_t)shot->table * (size_t)shot->tile_base[HR_FACES] * TILE_CELLS;
}

// The first cell of a face in the id buffers (DeltaFormFactors::offset).
size_t face_cell_offset(int face, int n) {
    return face == 0 ? 0 : (size_t)n * n + (size_t)(face - 1) * n * (n / 2);
}

// The face `tile` lies on and its index within the face; false for no tile of the shot, or
// when the shot's lists overflowed (the host grows them and reruns).
bool raster_tile(const HrShot* shot, __global const uint* offsets, int tile, int* face, int* in_face) {
    const int tiles = shot->tile_base[HR_FACES];
    if (tile >= tiles || offsets[tiles * HEMIRAD_COUNT_COPIES] > shot->list_capacity) return false;
    *face = tile_face(shot, tile);
    *in_face = tile - shot->tile_base[*face];
    return true;
}

// One work-group per tile, one work-item per cell: the nearest record at the cell centre,
// ties to the lower element index. (depth, index) is a total order, so the winner does not
// depend on the order of the tile's list. The winner's delta form factor goes to its sum
// (sums[elements] for blockers) in fixed point: integer atomics add in any order exactly.
// It leaves block_depth alone: the host culls by occlusion only with raster_records.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_TILE * HEMIRAD_TILE, 1, 1))) void raster(
    const HrShot first_shot, __global const HrShot* more_shots, __global const HrRecord* records,
    __global const HrBox* boxes, __global const uint* offsets, __global const uint* lists,
    __global const long* delta_fixed, __global int* ids, __global long* sums, __global double* block_depth,
    const int occluder_pass) {
    const HrShot shot_value = batch_shot(first_shot, more_shots, get_global_id(1));
    const HrShot* shot = &shot_value;
    raster_slices(shot, get_global_id(1), &records, &boxes, &offsets, &lists, &ids, &sums);
    const int tile = (int)get_group_id(0);
    int face, in_face;
    if (!raster_tile(shot, offsets, tile, &face, &in_face)) return;
    const int lid = (int)get_local_id(0);
    const int i = (in_face % shot->tiles_x) * HEMIRAD_TILE + lid % HEMIRAD_TILE;
    const int j = (in_face / shot->tiles_x) * HEMIRAD_TILE + lid / HEMIRAD_TILE;
    const int n = shot->n;
    if (i >= n || j >= face_rows(face, n)) return;

    const double per_unit = 0.5 * n;
    const double t0 = face == 0 ? 1.0 : 0.0;
    const double x = i + 0.5, y = j + 0.5;
    const double s = x / per_unit - 1.0, t = y / per_unit - t0;
    int best = -1, best_back = 0;
    double best_depth = 0.0;
    const uint end = offsets[(tile + 1) * HEMIRAD_COUNT_COPIES];
    for (uint at = offsets[tile * HEMIRAD_COUNT_COPIES]; at < end; ++at) {
        const uint slot = lists[at];
        const HrBox box = boxes[slot];
        if (i < box.i0 || i > box.i1 || j < box.j0 || j > box.j1) continue;
        __global const HrRecord* r = records + slot;
        bool inside = true;
        if (r->spans) {
            const int span = r->cover.span[j - box.j0];
            inside = i >= (span & 0xffff) && i <= span >> 16;
        }
        for (int e = 0; e < r->edges && inside; ++e)
            inside = r->cover.edge[e].a * i + r->cover.edge[e].b * j + r->cover.edge[e].c > 0;
        if (!inside) continue;
        const double inv_depth = r->plane[0] * s + r->plane[1] * t + r->plane[2];
        const int k = r->element;
        if (best < 0 || inv_depth > best_depth || (inv_depth == best_depth && k < best)) {
            best = k;
            best_depth = inv_depth;
            best_back = r->back;
        }
    }
    const size_t face_offset = face_cell_offset(face, n);
    const size_t cell = face_offset + (size_t)j * n + i;
    ids[cell] = best < 0 ? HR_EMPTY : (best_back ? HR_BLOCKER : best);
    if (best >= 0)
        atom_add(&sums[best_back ? shot->elements : best], delta_fixed[shot_table(shot) + (size_t)tile * TILE_CELLS + lid]);
}
