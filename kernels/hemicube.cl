// Hemicube form factors on an OpenCL device, cell for cell the scalar reference's result
// (src/formfactor/reference.cpp): the same double-precision operations in the same order, no
// contraction into FMAs. Per shot: setup (cull, clip and project each element on each face,
// count its records per tile) -> scan (per-tile list offsets) -> scatter (record indices into
// per-tile lists) -> raster (one work-group per tile, one work-item per cell: inside and depth
// tests, the cell's id, the winner's delta form factor added in 64-bit fixed point).
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL FP_CONTRACT OFF

#include "hemicube_types.h"

// Tuning knobs; the host passes its per-device values as -D options.
#ifndef HEMIRAD_TILE
#define HEMIRAD_TILE 16  // raster tile edge in cells: a raster work-group is TILE*TILE items
#endif
#ifndef HEMIRAD_WG
#define HEMIRAD_WG 64  // work-group size of the per-element and per-record kernels
#endif
#ifndef HEMIRAD_SCAN_WG
#define HEMIRAD_SCAN_WG 256  // the single work-group of the tile-offset scan, a power of two
#endif

typedef struct {
    double x, y, z;
} Vec;

typedef struct {
    Vec v[HR_MAX_CLIPPED + 1];
    int n;
} ClipPolygon;

Vec vec(double x, double y, double z) {
    Vec r;
    r.x = x;
    r.y = y;
    r.z = z;
    return r;
}

// glm::dot's order: (x + y) + z.
double dot3(Vec a, Vec b) {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

Vec to_local(__constant const HrShot* shot, Vec p) {
    const Vec d = vec(p.x - shot->origin[0], p.y - shot->origin[1], p.z - shot->origin[2]);
    return vec(dot3(d, vec(shot->u[0], shot->u[1], shot->u[2])), dot3(d, vec(shot->v[0], shot->v[1], shot->v[2])),
               dot3(d, vec(shot->w[0], shot->w[1], shot->w[2])));
}

// formfactor::to_face: hemicube frame (x, y, z) to face coordinates (u, v, depth).
Vec to_face(int face, Vec p) {
    switch (face) {
        case 0: return vec(p.x, p.y, p.z);
        case 1: return vec(p.y, p.z, p.x);
        case 2: return vec(-p.y, p.z, -p.x);
        case 3: return vec(-p.x, p.z, p.y);
        default: return vec(p.x, p.z, -p.y);
    }
}

// The face's frustum planes, kept where the value is >= 0: 0 the base plane, 1 right, 2 left,
// 3 top, 4 bottom (top face only; the sides' bottom is the base plane).
enum { kBasePlane = 0, kRight = 1, kLeft = 2, kTop = 3, kBottom = 4 };

double plane_value(int plane, int face, double eps, Vec p) {
    switch (plane) {
        case kBasePlane: return (face == 0 ? p.z : p.y) - eps;
        case kRight: return p.z - p.x;
        case kLeft: return p.z + p.x;
        case kTop: return p.z - p.y;
        default: return p.z + p.y;
    }
}

bool lexicographically_less(Vec a, Vec b) {
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    return a.z < b.z;
}

// Sutherland-Hodgman against one plane, crossing points computed from the lexicographically
// smaller endpoint, so an edge two elements share is cut at bit-identical points.
void clip(ClipPolygon* poly, int plane, int face, double eps) {
    ClipPolygon out;
    out.n = 0;
    for (int i = 0; i < poly->n; ++i) {
        const Vec a = poly->v[i];
        const Vec b = poly->v[(i + 1) % poly->n];
        const double fa = plane_value(plane, face, eps, a), fb = plane_value(plane, face, eps, b);
        if (fa >= 0.0 && out.n <= HR_MAX_CLIPPED) out.v[out.n++] = a;
        if ((fa >= 0.0) != (fb >= 0.0) && out.n <= HR_MAX_CLIPPED) {
            const bool a_first = lexicographically_less(a, b);
            const Vec p = a_first ? a : b;
            const Vec q = a_first ? b : a;
            const double fp = a_first ? fa : fb, fq = a_first ? fb : fa;
            const double t = fp / (fp - fq);
            out.v[out.n++] = vec(p.x + (q.x - p.x) * t, p.y + (q.y - p.y) * t, p.z + (q.z - p.z) * t);
        }
    }
    *poly = out;
}

// Clips only where the plane cuts the polygon; false when it is wholly outside.
bool clip_if_needed(ClipPolygon* poly, int plane, int face, double eps) {
    bool any_in = false, any_out = false;
    for (int i = 0; i < poly->n; ++i) {
        const bool in = plane_value(plane, face, eps, poly->v[i]) >= 0.0;
        any_in = any_in || in;
        any_out = any_out || !in;
    }
    if (any_out && any_in) clip(poly, plane, face, eps);
    return any_in && poly->n >= 3;
}

// Signed area of (a, b, p), positive when p is left of a->b, evaluated from the endpoint lower
// in (y, x) order so that the two polygons sharing an edge get exactly opposite values.
double edge_function(double ax, double ay, double bx, double by, double x, double y) {
    const bool forward = ay < by || (ay == by && ax < bx);
    if (!forward) return -((ax - bx) * (y - by) - (ay - by) * (x - bx));
    return (bx - ax) * (y - ay) - (by - ay) * (x - ax);
}

// Top-left rule for a counter-clockwise polygon: a centre on an edge belongs to it only for
// edges going down, or going right along a horizontal.
bool owns_edge_point(double dx, double dy) {
    return dy < 0.0 || (dy == 0.0 && dx > 0.0);
}

Vec element_vertex(__global const HrElement* e, int i) {
    return vec(e->v[3 * i], e->v[3 * i + 1], e->v[3 * i + 2]);
}

int face_rows(int face, int n) {
    return face == 0 ? n : n / 2;
}

// One work-item per element: the records of its (up to five) faces at records[5k + face], and
// one count per tile each record may cover.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_WG, 1, 1))) void setup(__constant const HrShot* shot,
                                                                            __global const HrElement* elements,
                                                                            __global const HrPatch* patches,
                                                                            __global HrRecord* records,
                                                                            __global uint* tile_counts) {
    const int k = (int)get_global_id(0);
    if (k >= shot->elements) return;
    __global HrRecord* out = records + (size_t)k * HR_FACES;
    for (int face = 0; face < HR_FACES; ++face) out[face].n = 0;

    __global const HrElement* e = elements + k;
    if (e->patch == shot->shooter) return;  // the shooter's own elements lie in its base plane
    const double eps = shot->eps;
    // Elements tile their patch: when the patch is below the base plane, so are they.
    __global const HrPatch* patch = patches + e->patch;
    bool patch_above = false;
    for (int i = 0; i < patch->n; ++i)
        patch_above =
            patch_above || to_local(shot, vec(patch->v[3 * i], patch->v[3 * i + 1], patch->v[3 * i + 2])).z > eps;
    if (!patch_above) return;

    const Vec normal = vec(e->normal[0], e->normal[1], e->normal[2]);
    const Vec origin = vec(shot->origin[0], shot->origin[1], shot->origin[2]);
    const double facing =
        dot3(normal, vec(origin.x - e->centroid[0], origin.y - e->centroid[1], origin.z - e->centroid[2]));
    const int is_back = facing < 0.0;
    if (is_back && e->has_twin) return;  // the twin draws this surface from this side

    Vec in_frame[4];
    bool above = false;
    for (int i = 0; i < e->n; ++i) {
        in_frame[i] = to_local(shot, element_vertex(e, i));
        above = above || in_frame[i].z > eps;
    }
    if (!above) return;
    const Vec normal_local = vec(dot3(normal, vec(shot->u[0], shot->u[1], shot->u[2])),
                                 dot3(normal, vec(shot->v[0], shot->v[1], shot->v[2])),
                                 dot3(normal, vec(shot->w[0], shot->w[1], shot->w[2])));
    const int n = shot->n;
    const double per_unit = 0.5 * n;  // cells per unit of face coordinate (the reference's `half`)

    for (int face = 0; face < HR_FACES; ++face) {
        ClipPolygon poly;
        poly.n = 0;
        for (int i = 0; i < e->n; ++i) poly.v[poly.n++] = to_face(face, in_frame[i]);
        const bool visible = clip_if_needed(&poly, kBasePlane, face, eps) && clip_if_needed(&poly, kRight, face, eps) &&
                             clip_if_needed(&poly, kLeft, face, eps) && clip_if_needed(&poly, kTop, face, eps) &&
                             (face != 0 || clip_if_needed(&poly, kBottom, face, eps));
        if (!visible || poly.n > HR_MAX_CLIPPED) continue;

        // The plane n.p = c in face coordinates gives 1/depth = (n_u s + n_v t + n_d) / c.
        const Vec nf = to_face(face, normal_local);
        const double c = dot3(nf, poly.v[0]);
        if (fabs(c) <= eps * 1e-3) continue;  // seen edge-on: covers no area

        // Cell coordinates: x in [0, n), y in [0, rows).
        const double t0 = face == 0 ? 1.0 : 0.0;
        double px[HR_MAX_CLIPPED], py[HR_MAX_CLIPPED];
        for (int i = 0; i < poly.n; ++i) {
            px[i] = (poly.v[i].x / poly.v[i].z + 1.0) * per_unit;
            py[i] = (poly.v[i].y / poly.v[i].z + t0) * per_unit;
        }
        double area2 = 0.0;
        for (int i = 0; i < poly.n; ++i) {
            const int j = (i + 1) % poly.n;
            area2 += px[i] * py[j] - px[j] * py[i];
        }
        if (area2 == 0.0) continue;
        __global HrRecord* r = out + face;
        const bool reverse = area2 < 0.0;  // make counter-clockwise
        double xmin = px[0], xmax = px[0], ymin = py[0], ymax = py[0];
        for (int i = 0; i < poly.n; ++i) {
            const int from = reverse ? poly.n - 1 - i : i;
            r->x[i] = px[from];
            r->y[i] = py[from];
            xmin = px[i] < xmin ? px[i] : xmin;
            xmax = xmax < px[i] ? px[i] : xmax;
            ymin = py[i] < ymin ? py[i] : ymin;
            ymax = ymax < py[i] ? py[i] : ymax;
        }
        const int rows = face_rows(face, n);
        const int i0 = max(0, (int)floor(xmin - 0.5));
        const int i1 = min(n - 1, (int)ceil(xmax - 0.5));
        const int j0 = max(0, (int)floor(ymin - 0.5));
        const int j1 = min(rows - 1, (int)ceil(ymax - 0.5));
        r->nf[0] = nf.x;
        r->nf[1] = nf.y;
        r->nf[2] = nf.z;
        r->c = c;
        r->element = k;
        r->back = is_back;
        r->n = poly.n;
        r->face = face;
        r->i0 = i0;
        r->i1 = i1;
        r->j0 = j0;
        r->j1 = j1;
        if (i0 > i1 || j0 > j1) continue;  // no cell centre on the face: in no tile's list
        for (int ty = j0 / HEMIRAD_TILE; ty <= j1 / HEMIRAD_TILE; ++ty)
            for (int tx = i0 / HEMIRAD_TILE; tx <= i1 / HEMIRAD_TILE; ++tx)
                atomic_inc(&tile_counts[shot->tile_base[face] + ty * shot->tiles_x + tx]);
    }
}

// One work-group: exclusive prefix sum of the tile counts into list offsets (and the scatter
// cursors); offsets[tiles] is the total, which the host checks against the list capacity.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_SCAN_WG, 1, 1))) void scan(__constant const HrShot* shot,
                                                                                __global const uint* tile_counts,
                                                                                __global uint* offsets,
                                                                                __global uint* cursors) {
    __local uint partial[HEMIRAD_SCAN_WG];
    const int lid = (int)get_local_id(0);
    const int tiles = shot->tile_base[HR_FACES];
    const int chunk = (tiles + HEMIRAD_SCAN_WG - 1) / HEMIRAD_SCAN_WG;
    const int begin = min(lid * chunk, tiles), end = min(begin + chunk, tiles);
    uint sum = 0;
    for (int t = begin; t < end; ++t) sum += tile_counts[t];
    partial[lid] = sum;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int step = 1; step < HEMIRAD_SCAN_WG; step <<= 1) {  // Hillis-Steele, inclusive
        const uint add = lid >= step ? partial[lid - step] : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        partial[lid] += add;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    uint run = partial[lid] - sum;
    for (int t = begin; t < end; ++t) {
        offsets[t] = run;
        cursors[t] = run;
        run += tile_counts[t];
    }
    if (lid == HEMIRAD_SCAN_WG - 1) offsets[tiles] = partial[lid];
}

// One work-item per record slot: its index into the list of every tile it may cover. The
// order within a list varies from run to run; the raster's result does not depend on it.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_WG, 1, 1))) void scatter(__constant const HrShot* shot,
                                                                              __global const HrRecord* records,
                                                                              __global uint* cursors,
                                                                              __global uint* lists) {
    const int slot = (int)get_global_id(0);
    if (slot >= shot->elements * HR_FACES) return;
    __global const HrRecord* r = records + slot;
    if (r->n == 0 || r->i0 > r->i1 || r->j0 > r->j1) return;  // as setup counted
    const int base = shot->tile_base[r->face];
    for (int ty = r->j0 / HEMIRAD_TILE; ty <= r->j1 / HEMIRAD_TILE; ++ty)
        for (int tx = r->i0 / HEMIRAD_TILE; tx <= r->i1 / HEMIRAD_TILE; ++tx) {
            const uint at = atomic_inc(&cursors[base + ty * shot->tiles_x + tx]);
            if (at < shot->list_capacity) lists[at] = (uint)slot;
        }
}

// One work-group per tile, one work-item per cell: the nearest record at the cell centre,
// ties to the lower element index. (depth, index) is a total order, so the winner does not
// depend on the order of the tile's list. The winner's delta form factor goes to its sum
// (sums[elements] for blockers) in fixed point: integer atomics add in any order exactly.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_TILE * HEMIRAD_TILE, 1, 1))) void raster(
    __constant const HrShot* shot, __global const HrRecord* records, __global const uint* offsets,
    __global const uint* lists, __global const long* delta_fixed, __global int* ids, __global long* sums) {
    const int tile = (int)get_group_id(0);
    const int tiles = shot->tile_base[HR_FACES];
    if (offsets[tiles] > shot->list_capacity) return;  // lists overflowed: the host grows them and reruns
    int face = 0;
    while (face < HR_FACES - 1 && tile >= shot->tile_base[face + 1]) ++face;
    const int in_face = tile - shot->tile_base[face];
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
    const uint end = offsets[tile + 1];
    for (uint at = offsets[tile]; at < end; ++at) {
        __global const HrRecord* r = records + lists[at];
        if (i < r->i0 || i > r->i1 || j < r->j0 || j > r->j1) continue;
        bool inside = true;
        for (int a = 0; a < r->n && inside; ++a) {
            const int b = a + 1 == r->n ? 0 : a + 1;
            const double ax = r->x[a], ay = r->y[a], bx = r->x[b], by = r->y[b];
            if (ax == bx && ay == by) continue;  // clipping can repeat a vertex
            const double edge = edge_function(ax, ay, bx, by, x, y);
            inside = edge > 0.0 || (edge == 0.0 && owns_edge_point(bx - ax, by - ay));
        }
        if (!inside) continue;
        const double inv_depth = (r->nf[0] * s + r->nf[1] * t + r->nf[2]) / r->c;
        const int k = r->element;
        if (best < 0 || inv_depth > best_depth || (inv_depth == best_depth && k < best)) {
            best = k;
            best_depth = inv_depth;
            best_back = r->back;
        }
    }
    const size_t face_offset = face == 0 ? 0 : (size_t)n * n + (size_t)(face - 1) * n * (n / 2);
    const size_t cell = face_offset + (size_t)j * n + i;
    ids[cell] = best < 0 ? HR_EMPTY : (best_back ? HR_BLOCKER : best);
    if (best >= 0) atom_add(&sums[best_back ? shot->elements : best], delta_fixed[cell]);
}

// The sizes of the shared structs as this compiler lays them out; the host compares them with
// its own before the first shot.
__kernel void layout(__global int* sizes) {
    sizes[0] = (int)sizeof(HrElement);
    sizes[1] = (int)sizeof(HrPatch);
    sizes[2] = (int)sizeof(HrShot);
    sizes[3] = (int)sizeof(HrRecord);
}
