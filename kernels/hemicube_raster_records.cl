// Stage 4 on CPUs, raster_records (included by hemicube.cl, after hemicube_raster.cl): one
// work-item per tile, row spans from exact integer edge bounds (floor_div, also exposed to the
// tests as floor_div_pairs), the depth test LANES cells at a time; and, in the occluder pass,
// the depth blocks of occlusion culling.

// For CPU devices: one work-item per tile walks the records of its list in turn, each over
// only its bounding box within the tile, keeping the winners in private arrays (the
// reference's loop order, parallel across tiles). The inside test becomes, row by row, the
// span of cells between the record's left and right edges, exact in integers (an edge's
// quotient and remainder stepped down the rows, all edges of a side in one vector); the span
// is depth-tested LANES cells at a time without branches, in the same double arithmetic as
// the scalar test. The winner is the reference's: the nearest at the cell centre, ties to the
// lower element index.
// Each record adds the delta form factors of the cells it takes to its element's sum with one
// atomic; a cell taken from an earlier record (overdraw) is given back by that record's
// element, through a small private table of such corrections flushed to the sums at the end.
#if HEMIRAD_LANES == 8
typedef double8 lane_double;
typedef long8 lane_long;
typedef int8 lane_int;
#define LANE_INDEX ((int8)(0, 1, 2, 3, 4, 5, 6, 7))
#define LANE_INDEX_LONG ((long8)(0, 1, 2, 3, 4, 5, 6, 7))
#define vload_lanes vload8
#define vstore_lanes vstore8
#define convert_lane_long convert_long8
#define convert_lane_int convert_int8
#elif HEMIRAD_LANES == 4
typedef double4 lane_double;
typedef long4 lane_long;
typedef int4 lane_int;
#define LANE_INDEX ((int4)(0, 1, 2, 3))
#define LANE_INDEX_LONG ((long4)(0, 1, 2, 3))
#define vload_lanes vload4
#define vstore_lanes vstore4
#define convert_lane_long convert_long4
#define convert_lane_int convert_int4
#else
#error HEMIRAD_LANES must be 4 or 8
#endif
#define HR_SUM_TABLE 64  // entries of raster_records' table of give-backs, a power of two

// The sum a raster_records winner 2 k + back adds to: its element's, or the blockers'.
int owner_sum(const HrShot* shot, int owner) {
    return (owner & 1) ? shot->elements : owner >> 1;
}

// Pending additions to the sums of a few winners, direct-mapped by the winner's low bits;
// owner -1 marks a free entry.
typedef struct {
    int owner[HR_SUM_TABLE];
    long sum[HR_SUM_TABLE];
} SumTable;

// Adds `value` to the pending sum of `owner`, first moving the entry's earlier owner, if
// another, to the global sums.
void table_add(SumTable* table, const HrShot* shot, __global long* sums, int owner, long value) {
    const int t = owner & (HR_SUM_TABLE - 1);
    if (table->owner[t] != owner) {
        if (table->owner[t] >= 0) atom_add(&sums[owner_sum(shot, table->owner[t])], table->sum[t]);
        table->owner[t] = owner;
        table->sum[t] = 0;
    }
    table->sum[t] += value;
}

// floor(m / d) for d > 0, and m - d floor(m / d) in *rem, exact: the double quotient truncated
// (for |m| < 2^62 within two of the floor: the double's rounding plus truncation toward zero),
// then corrected in integers until the remainder is in [0, d).
long floor_div(long m, long d, long* rem) {
    long q = convert_long_rtz((double)m / (double)d);
    long r = m - q * d;
    while (r < 0) {
        q -= 1;
        r += d;
    }
    while (r >= d) {
        q += 1;
        r -= d;
    }
    *rem = r;
    return q;
}

// floor_div of each pair (m[k], d[k]) into out[2 k] (quotient) and out[2 k + 1] (remainder):
// what the tests hold to exact integer division.
__kernel void floor_div_pairs(__global const long* m, __global const long* d, __global long* out) {
    const size_t k = get_global_id(0);
    long rem;
    out[2 * k] = floor_div(m[k], d[k], &rem);
    out[2 * k + 1] = rem;
}

long max_lanes(long8 v) {
    const long4 a = max(v.lo, v.hi);
    const long2 b = max(a.lo, a.hi);
    return max(b.x, b.y);
}

long sum_lanes(lane_long v) {
#if HEMIRAD_LANES == 8
    const long4 folded = v.lo + v.hi;
#else
    const long4 folded = v;
#endif
    return folded.x + folded.y + folded.z + folded.w;
}

// any_of4 or any_of8, as wide as the raster's lanes.
bool any_lanes(lane_long mask) {
#if HEMIRAD_LANES == 8
    return any_of8(mask);
#else
    return any_of4(mask);
#endif
}

__kernel __attribute__((reqd_work_group_size(HEMIRAD_RASTER_WG, 1, 1))) void raster_records(
    const HrShot first_shot, __global const HrShot* more_shots, __global const HrRecord* records,
    __global const HrBox* boxes, __global const uint* offsets, __global const uint* lists,
    __global const long* delta_fixed, __global int* ids, __global long* sums, __global double* block_depth,
    const int occluder_pass) {
    const HrShot shot_value = batch_shot(first_shot, more_shots, get_global_id(1));
    const HrShot* shot = &shot_value;
    raster_slices(shot, get_global_id(1), &records, &boxes, &offsets, &lists, &ids, &sums);
    const int tile = (int)get_global_id(0);
    int face, in_face;
    if (!raster_tile(shot, offsets, tile, &face, &in_face)) return;
    const int n = shot->n;
    const int ci0 = (in_face % shot->tiles_x) * HEMIRAD_TILE, cj0 = (in_face / shot->tiles_x) * HEMIRAD_TILE;
    const int ci1 = min(ci0 + HEMIRAD_TILE, n) - 1, cj1 = min(cj0 + HEMIRAD_TILE, face_rows(face, n)) - 1;
    const double per_unit = 0.5 * n;
    const double t0 = face == 0 ? 1.0 : 0.0;

    // Row-major tile cells; the last row's last group may reach LANES - 1 past the end. Per
    // cell: the winner as 2 k + back (the record of element k, back 1 for a blocker; -1 none;
    // in the order of k, for ties) and its 1/depth.
    int best[TILE_CELLS + HEMIRAD_LANES - 1];
    double best_depth[TILE_CELLS + HEMIRAD_LANES - 1];
    for (int c = 0; c < TILE_CELLS + HEMIRAD_LANES - 1; ++c) {
        best[c] = -1;
        best_depth[c] = 0.0;
    }
    SumTable give_back;
    for (int t = 0; t < HR_SUM_TABLE; ++t) give_back.owner[t] = -1;
    double column_s[HEMIRAD_TILE + HEMIRAD_LANES - 1];  // s = x / per_unit - 1 of the tile's columns
    for (int c = 0; c < HEMIRAD_TILE + HEMIRAD_LANES - 1; ++c) column_s[c] = (ci0 + c + 0.5) / per_unit - 1.0;
    double row_t[HEMIRAD_TILE];  // t = y / per_unit - t0 of its rows
    for (int c = 0; c < HEMIRAD_TILE; ++c) row_t[c] = (cj0 + c + 0.5) / per_unit - t0;
    const size_t face_offset = face_cell_offset(face, n);
    __global const long* delta_tile = delta_fixed + shot_table(shot) + (size_t)tile * TILE_CELLS;  // the tile's cells, row by row

    const uint end = offsets[(tile + 1) * HEMIRAD_COUNT_COPIES];
    for (uint at = offsets[tile * HEMIRAD_COUNT_COPIES]; at < end; ++at) {
        const uint slot = lists[at];
        const HrBox box = boxes[slot];
        const int i0 = max(box.i0, ci0), i1 = min(box.i1, ci1);
        long j0 = max(box.j0, cj0), j1 = min(box.j1, cj1);
        if (i0 > i1 || j0 > j1) continue;
        __global const HrRecord* r = records + slot;
        const bool spans = r->spans != 0;
        // A span record's rows come ready from setup. Otherwise the inside test edge by edge,
        // as bounds: a i + b j + c > 0 is, with m = -(b j + c), i > m / a where a > 0 (a left
        // edge), i < -m / -a where a < 0 (a right edge) and, for a horizontal edge (a = 0), a
        // bound on the rows. Exact integer quotients (floor_div), stepped from row to row as m
        // falls by b (quotient and remainder of b added in turn). Left edges in one vector,
        // right edges in another (a convex polygon has at most 8 on a side), stepped together;
        // unused lanes never bind (quotient -2^40, steps 0).
        long8 left_q = 0, left_r = 0, left_d = 1, left_sq = 0, left_sr = 0;
        long8 right_q = 0, right_r = 0, right_d = 1, right_sq = 0, right_sr = 0;
        if (!spans) {
            const int count = r->edges;
            for (int e = 0; e < count; ++e) {
                const long b = r->cover.edge[e].b, c = r->cover.edge[e].c;
                if (r->cover.edge[e].a != 0) continue;
                long rem;
                const long q = floor_div(-c, b > 0 ? b : -b, &rem);
                if (b > 0) j0 = max(j0, q + 1);
                else j1 = min(j1, -q - 1);
            }
            if (j0 > j1) continue;
            long edge_q[2][8], edge_r[2][8], edge_d[2][8], edge_sq[2][8], edge_sr[2][8];
            for (int e = 0; e < 8; ++e)
                for (int side = 0; side < 2; ++side) {
                    edge_q[side][e] = -((long)1 << 40);
                    edge_r[side][e] = 0;
                    edge_d[side][e] = 1;
                    edge_sq[side][e] = 0;
                    edge_sr[side][e] = 0;
                }
            int used_side[2] = {0, 0};
            for (int e = 0; e < count; ++e) {
                const long a = r->cover.edge[e].a, b = r->cover.edge[e].b, c = r->cover.edge[e].c;
                if (a == 0) continue;
                const int side = a > 0 ? 0 : 1;
                const int k = used_side[side]++;
                const long d = a > 0 ? a : -a;
                edge_d[side][k] = d;
                edge_sq[side][k] = floor_div(b, d, &edge_sr[side][k]);
                edge_q[side][k] = floor_div(-(b * j0 + c), d, &edge_r[side][k]);
            }
            left_q = vload8(0, edge_q[0]);
            left_r = vload8(0, edge_r[0]);
            right_q = vload8(0, edge_q[1]);
            right_r = vload8(0, edge_r[1]);
            left_d = vload8(0, edge_d[0]);
            left_sq = vload8(0, edge_sq[0]);
            left_sr = vload8(0, edge_sr[0]);
            right_d = vload8(0, edge_d[1]);
            right_sq = vload8(0, edge_sq[1]);
            right_sr = vload8(0, edge_sr[1]);
        }
        const double depth_s = r->plane[0], depth_t = r->plane[1], depth_1 = r->plane[2];
        const int owner = 2 * r->element + r->back;
        lane_long won = 0;  // the delta form factors of the cells this record takes, per lane
        for (int j = (int)j0; j <= (int)j1; ++j) {
            long lo, hi;
            if (spans) {
                const int span = r->cover.span[j - box.j0];
                lo = max(i0, span & 0xffff);
                hi = min(i1, span >> 16);
            } else {
                lo = max((long)i0, max_lanes(left_q) + 1);
                hi = min((long)i1, -max_lanes(right_q) - 1);
                step_row(&left_q, &left_r, left_d, left_sq, left_sr);
                step_row(&right_q, &right_r, right_d, right_sq, right_sr);
            }
            if (lo > hi) continue;
            const double row_depth = depth_t * row_t[j - cj0];
            const int base = (j - cj0) * HEMIRAD_TILE - ci0;
            for (int i = (int)lo; i <= (int)hi; i += HEMIRAD_LANES) {
                const lane_long in = (lane_long)(i) + LANE_INDEX_LONG <= (lane_long)(hi);
                const lane_double s = vload_lanes(0, column_s + (i - ci0));
                const lane_double inv_depth = depth_s * s + row_depth + depth_1;
                const int cell = base + i;
                const lane_int old = vload_lanes(0, best + cell);
                const lane_double old_depth = vload_lanes(0, best_depth + cell);
                const lane_long take = in & (convert_lane_long(old < 0) | (inv_depth > old_depth) |
                                             ((inv_depth == old_depth) & convert_lane_long((lane_int)(owner) < old)));
                if (!any_lanes(take)) continue;
                const lane_int take_int = convert_lane_int(take);
                const lane_long delta = vload_lanes(0, delta_tile + cell);  // may read past the tile's row
                won += select((lane_long)(0), delta, take);
                // Cells taken from an earlier record (overdraw): its element gives them back.
                // Per lane through private copies: portable OpenCL C indexes no vector.
                if (any_lanes(take & convert_lane_long(old >= 0))) {
                    int taken[HEMIRAD_LANES], previous[HEMIRAD_LANES];
                    long given[HEMIRAD_LANES];
                    vstore_lanes(take_int, 0, taken);
                    vstore_lanes(old, 0, previous);
                    vstore_lanes(delta, 0, given);
                    for (int lane = 0; lane < HEMIRAD_LANES; ++lane)
                        if (taken[lane] && previous[lane] >= 0)
                            table_add(&give_back, shot, sums, previous[lane], -given[lane]);
                }
                vstore_lanes(select(old, (lane_int)(owner), take_int), 0, best + cell);
                vstore_lanes(select(old_depth, inv_depth, take), 0, best_depth + cell);
            }
        }
        // Integer sums: the order of these atomics (and of the lists) cannot change the result.
        const long total = sum_lanes(won);
        if (total != 0) atom_add(&sums[owner_sum(shot, owner)], total);
    }
    for (int t = 0; t < HR_SUM_TABLE; ++t)
        if (give_back.owner[t] >= 0) atom_add(&sums[owner_sum(shot, give_back.owner[t])], give_back.sum[t]);

    // The final pass writes the ids; the occluder pass (its sums are cleared again) each depth
    // block's least 1/depth, 0 where a cell is empty, for occlusion culling (group_hidden). Tiles
    // are whole blocks but at the face's edge: the host culls by occlusion only where TILE is a
    // multiple of DEPTH_BLOCK.
    if (!occluder_pass) {
        for (int j = cj0; j <= cj1; ++j)
            for (int i = ci0; i <= ci1; ++i) {
                const int owner = best[(j - cj0) * HEMIRAD_TILE + (i - ci0)];
                ids[face_offset + (size_t)j * n + i] = owner < 0 ? HR_EMPTY : ((owner & 1) ? HR_BLOCKER : owner >> 1);
            }
        return;
    }
#if HEMIRAD_TILE % DEPTH_BLOCK == 0
    __global double* depth = block_depth + get_global_id(1) * depth_stride(n) + depth_block_base(face, n);
    for (int bj = cj0; bj <= cj1; bj += DEPTH_BLOCK)
        for (int bi = ci0; bi <= ci1; bi += DEPTH_BLOCK) {
            double least = INFINITY;
            for (int j = bj; j <= min(bj + DEPTH_BLOCK - 1, cj1); ++j)
                for (int i = bi; i <= min(bi + DEPTH_BLOCK - 1, ci1); ++i) {
                    const int cell = (j - cj0) * HEMIRAD_TILE + (i - ci0);
                    least = fmin(least, best[cell] < 0 ? 0.0 : best_depth[cell]);
                }
            depth[(bj / DEPTH_BLOCK) * depth_blocks_x(n) + bi / DEPTH_BLOCK] = least;
        }
#endif
}
