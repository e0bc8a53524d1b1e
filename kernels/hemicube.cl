// Hemicube form factors on an OpenCL device, cell for cell the scalar reference's result
// (src/formfactor/reference.cpp): the same double-precision operations in the same order, no
// contraction into FMAs, up to the projected vertices, which are snapped to fixed point; from
// there the inside test is exact integer arithmetic, evaluated in any order. For a batch of
// shots (dimension 1 of every NDRange), per shot: setup (cull, clip and project each element on
// each face into packed records with their cell boxes, then count them per tile) -> scan
// (per-tile list offsets) -> scatter (record indices into per-tile lists) -> raster, on GPUs one
// work-group per tile and one work-item per cell, on CPUs (raster_records) one work-item per
// tile walking its records: inside and depth tests, the cell's id, the winner's delta form
// factor added in 64-bit fixed point.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL FP_CONTRACT OFF

#include "hemicube_types.h"

// Tuning knobs; the host passes its per-device values as -D options.
#ifndef HEMIRAD_TILE
#define HEMIRAD_TILE 16  // raster tile edge in cells: a raster work-group is TILE*TILE items
#endif
#ifndef HEMIRAD_WG
#define HEMIRAD_WG 64  // work-group size of the per-patch and per-record kernels
#endif
#ifndef HEMIRAD_RASTER_WG
#define HEMIRAD_RASTER_WG 4  // work-group size of raster_records (one work-item per tile)
#endif
#ifndef HEMIRAD_COUNT_COPIES
#define HEMIRAD_COUNT_COPIES 1  // copies of the per-tile counters, one per work-group mod this: less contention
#endif
#ifndef HEMIRAD_LANES
#define HEMIRAD_LANES 4  // cells per row step of raster_records: 4 or 8 (double8 on AVX-512)
#endif
#ifndef HEMIRAD_SETUP_LANES
#define HEMIRAD_SETUP_LANES 0  // 1: setup takes HR_SETUP_LANES elements per work-item in double8 (CPUs)
#endif
#ifndef HEMIRAD_CULL
#define HEMIRAD_CULL 1  // 0: no bounding-sphere test per lane group (the host sets it with its cluster culling)
#endif
#ifndef HEMIRAD_SCAN_WG
#define HEMIRAD_SCAN_WG 256  // the single work-group of the tile-offset scan, a power of two
#endif

typedef struct {
    double x, y, z;
} Vec;

typedef struct {
    Vec v[HR_MAX_CLIPPED];
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

Vec to_local(const HrShot* shot, Vec p) {
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

// Sutherland-Hodgman against one plane, keeping only the run of vertices at or above it that
// holds the largest value (the first on ties), with the crossings that bound it: formfactor::
// clip_convex (src/formfactor/clip.h), which says why. At most n + 1 vertices for any input, so a
// triangle or quad through 5 planes fits HR_MAX_CLIPPED. Crossing points are computed from the
// lexicographically smaller endpoint, so an edge two elements share is cut at bit-identical points.
void clip(ClipPolygon* poly, int plane, int face, double eps) {
    const int n = poly->n;
    double f[HR_MAX_CLIPPED];
    int top = 0;
    for (int i = 0; i < n; ++i) {
        f[i] = plane_value(plane, face, eps, poly->v[i]);
        if (f[i] > f[top]) top = i;
    }
    int first = top, length = 1;
    while (length < n && f[(first + n - 1) % n] >= 0.0) {
        first = (first + n - 1) % n;
        ++length;
    }
    while (length < n && f[(first + length) % n] >= 0.0) ++length;

    ClipPolygon out;
    out.n = 0;
    for (int i = 0; i < n; ++i) {
        const int j = (i + 1) % n;
        const bool kept_i = (i - first + n) % n < length, kept_j = (j - first + n) % n < length;
        const Vec a = poly->v[i];
        const Vec b = poly->v[j];
        // The bounds tests never fail (n + 1 <= HR_MAX_CLIPPED); they keep private memory safe.
        if (kept_i && out.n < HR_MAX_CLIPPED) out.v[out.n++] = a;
        if (kept_i != kept_j && out.n < HR_MAX_CLIPPED) {
            const bool a_first = lexicographically_less(a, b);
            const Vec p = a_first ? a : b;
            const Vec q = a_first ? b : a;
            const double fp = a_first ? f[i] : f[j], fq = a_first ? f[j] : f[i];
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

// Bit 5 * face + plane set where p (hemicube frame) is outside that plane of that face by more
// than margin (0: outside at all), the plane values exactly those plane_value(plane, face, eps,
// to_face(face, p)) computes: to_face only permutes and negates coordinates, so each face's
// value is one of seven differences below or its exact negation (fl(-a - -b) = -fl(a - b)),
// outside where it is < -margin.
uint outside_bits(Vec p, double eps, double margin) {
    const double low = -margin;
    const double base = p.z - eps;  // every face's base plane
    const double zmx = p.z - p.x, zpx = p.z + p.x, zmy = p.z - p.y, zpy = p.z + p.y;
    const double xmy = p.x - p.y, xpy = p.x + p.y;
    const uint face0 = (base < low) | (zmx < low) << 1 | (zpx < low) << 2 | (zmy < low) << 3 | (zpy < low) << 4;
    const uint face1 = (base < low) | (xmy < low) << 1 | (xpy < low) << 2 | (zmx > margin) << 3;  // (y, z, x)
    const uint face2 = (base < low) | (xmy > margin) << 1 | (xpy > margin) << 2 | (zpx > margin) << 3;  // (-y, z, -x)
    const uint face3 = (base < low) | (xpy < low) << 1 | (xmy > margin) << 2 | (zmy > margin) << 3;  // (-x, z, y)
    const uint face4 = (base < low) | (xpy > margin) << 1 | (xmy < low) << 2 | (zpy > margin) << 3;  // (x, z, -y)
    return face0 | face1 << 5 | face2 << 10 | face3 << 15 | face4 << 20;
}

// Where every vertex of an element is outside one plane of a face by more than HIDDEN_MARGIN
// times M (M: the largest magnitude of its coordinates and eps), the reference's clipping
// finds the face hidden, whatever the planes before it do: where it clips by earlier planes
// first, each new vertex is a convex combination of the element's vertices computed with an
// error below ~5 2^-53 M per clipping (the error of t only slides the point along its edge),
// at most four deep, so its computed value on that plane stays below -margin + ~50 2^-53 M
// < 0: outside, and the face hidden, as a plane with every vertex out hides it at once.
// 2^-40 leaves a factor of 100 (and an element that close to a face's plane is rare).
#define HIDDEN_MARGIN 0x1p-40

// Top-left rule for a counter-clockwise polygon: a centre on an edge belongs to it only for
// edges going down, or going right along a horizontal.
bool owns_edge_point(long dx, long dy) {
    return dy < 0 || (dy == 0 && dx > 0);
}

// The reference's fixed-point snap and cell ranges, SUBCELL (formfactor::kSubcell) units per cell.
#define SUBCELL (1L << HR_SUBCELL_BITS)
long snap(double cells) {
    return (long)floor(cells * (double)SUBCELL + 0.5);
}
int first_centre(long lo) {
    return (int)ceil((double)(lo - SUBCELL / 2) / (double)SUBCELL);
}
int last_centre(long hi) {
    return (int)floor((double)(hi - SUBCELL / 2) / (double)SUBCELL);
}

// What setup_element reads of an element, from either of its copies in global memory.
typedef struct {
    Vec v[4];
    Vec normal, centroid;
    int n, has_twin;
} Element;

Element element_at(__global const HrElement* e) {
    Element out;
    for (int i = 0; i < 4; ++i) out.v[i] = vec(e->v[3 * i], e->v[3 * i + 1], e->v[3 * i + 2]);
    out.normal = vec(e->normal[0], e->normal[1], e->normal[2]);
    out.centroid = vec(e->centroid[0], e->centroid[1], e->centroid[2]);
    out.n = e->n;
    out.has_twin = e->has_twin;
    return out;
}

// Lane l of a group (HrElementLanes), which setup_lanes has just read: in cache.
Element element_in_lanes(__global const HrElementLanes* group, int l) {
    Element out;
    for (int i = 0; i < 4; ++i) {
        __global const double* v = group->v + 3 * i * HR_SETUP_LANES + l;
        out.v[i] = vec(v[0], v[HR_SETUP_LANES], v[2 * HR_SETUP_LANES]);
    }
    out.normal = vec(group->normal[l], group->normal[HR_SETUP_LANES + l], group->normal[2 * HR_SETUP_LANES + l]);
    out.centroid =
        vec(group->centroid[l], group->centroid[HR_SETUP_LANES + l], group->centroid[2 * HR_SETUP_LANES + l]);
    out.n = group->n[l];
    out.has_twin = group->has_twin[l];
    return out;
}

int face_rows(int face, int n) {
    return face == 0 ? n : n / 2;
}

// Shot b of a batch. The first comes by value as a kernel argument, so that a lone shot (a bake's
// default) launches without a buffer write before it: on PoCL (2 cores, Cornell, N = 256) that
// write cost ~0.08 ms of a 1.29 ms shot, most of it idle time between commands. The rest of the
// batch comes from the shot buffer.
HrShot batch_shot(const HrShot first, __global const HrShot* rest, size_t b) {
    return b == 0 ? first : rest[b - 1];
}

// Every per-shot buffer holds a batch of shots, shot b at b times these strides; a kernel's
// dimension 1 is the shot within the batch.
size_t record_stride(const HrShot* shot) {
#if HEMIRAD_SETUP_LANES
    return (size_t)shot->group_rows * shot->group_capacity;  // a region per setup work-group
#else
    return (size_t)shot->elements * HR_FACES;  // five per element, at five times its index
#endif
}

// The end of this setup work-group's record slots: past it, records are counted, not stored.
uint region_end(const HrShot* shot) {
#if HEMIRAD_SETUP_LANES
    return (uint)(get_group_id(0) + 1) * shot->group_capacity;
#else
    return UINT_MAX;
#endif
}
size_t counter_stride(const HrShot* shot) {
    return (size_t)shot->tile_base[HR_FACES] * HEMIRAD_COUNT_COPIES;
}
// Per element; then the blocked share, the list entries needed, the lane groups setup tested for
// occlusion and those it found hidden (occlusion culling's count, for benchmarks), and the most
// records a setup work-group made (lanes setup: more than group_capacity, the host reruns).
size_t sum_stride(const HrShot* shot) {
    return (size_t)shot->elements + 5;
}

// Occlusion culling's depth buffer: per block of DEPTH_BLOCK x DEPTH_BLOCK cells, face by face,
// row-major within a face, the least 1/depth over the block's cells (0 where one is empty).
#define DEPTH_BLOCK HR_DEPTH_BLOCK
int depth_blocks_x(int n) {
    return (n + DEPTH_BLOCK - 1) / DEPTH_BLOCK;
}
int depth_block_base(int face, int n) {
    const int top = depth_blocks_x(n) * depth_blocks_x(n), side = depth_blocks_x(n) * ((n / 2 + DEPTH_BLOCK - 1) / DEPTH_BLOCK);
    return face == 0 ? 0 : top + (face - 1) * side;
}
size_t depth_stride(int n) {
    return (size_t)depth_block_base(HR_FACES, n);
}
size_t cell_stride(const HrShot* shot) {
    return (size_t)3 * shot->n * shot->n;
}

// The record counts of setup's work-groups (group_records): a shot's launch has at most this many
// (one per cluster of lane groups, or per HEMIRAD_WG patches), whatever the launch's row length,
// so that the occluder pass's counts sit where the final pass finds them.
size_t group_stride(const HrShot* shot) {
#if HEMIRAD_SETUP_LANES
    const size_t items = ((size_t)shot->elements + HR_SETUP_LANES - 1) / HR_SETUP_LANES;
#else
    const size_t items = (size_t)shot->patches;
#endif
    return max((size_t)1, (items + HEMIRAD_WG - 1) / HEMIRAD_WG);
}

// The first counter of the copy that this work-group's records count in (and scatter to): copy
// (work-group) mod COUNT_COPIES, each copy `tiles` counters. Work-groups that run at the same
// time on different cores then rarely increment the same cache line.
int counter_copy(int tiles) {
    return (int)(get_group_id(0) % HEMIRAD_COUNT_COPIES) * tiles;
}

// A record's fields besides its edges, and its cell box (both setups write records through this).
void store_record_fields(__global HrRecord* r, __global HrBox* box, double plane_s, double plane_t, double plane_1,
                         int k, int back, int edges, int spans, int i0, int i1, int j0, int j1, int face) {
    r->plane[0] = plane_s;
    r->plane[1] = plane_t;
    r->plane[2] = plane_1;
    r->element = k;
    r->back = back;
    r->edges = edges;
    r->spans = spans;
    box->i0 = i0;
    box->i1 = i1;
    box->j0 = j0;
    box->j1 = j1;
    box->face = face;
}

// Element k's records, and their cell boxes, for each face on which it may cover a cell centre,
// packed in its work-group's region of the record slots: at records[*used], *used counting up.
void setup_element(const HrShot* shot, const Element* e, int k, __global HrRecord* records,
                   __global HrBox* boxes, __local uint* used) {
    const double eps = shot->eps;
    const Vec normal = e->normal;
    const Vec origin = vec(shot->origin[0], shot->origin[1], shot->origin[2]);
    const double facing =
        dot3(normal, vec(origin.x - e->centroid.x, origin.y - e->centroid.y, origin.z - e->centroid.z));
    const int is_back = facing < 0.0;
    if (is_back && e->has_twin) return;  // the twin draws this surface from this side

    Vec in_frame[4];
    bool above = false;
    for (int i = 0; i < e->n; ++i) {
        in_frame[i] = to_local(shot, e->v[i]);
        above = above || in_frame[i].z > eps;
    }
    if (!above) return;
    const Vec normal_local = vec(dot3(normal, vec(shot->u[0], shot->u[1], shot->u[2])),
                                 dot3(normal, vec(shot->v[0], shot->v[1], shot->v[2])),
                                 dot3(normal, vec(shot->w[0], shot->w[1], shot->w[2])));
    const int n = shot->n;
    const double per_unit = 0.5 * n;  // cells per unit of face coordinate (the reference's `half`)

    // Which vertices lie outside which face planes, from the seven plane values every face
    // shares; and the planes every vertex is outside of by the margin (HIDDEN_MARGIN).
    double magnitude = eps;
    for (int i = 0; i < e->n; ++i)
        magnitude = fmax(magnitude, fmax(fabs(in_frame[i].x), fmax(fabs(in_frame[i].y), fabs(in_frame[i].z))));
    uint outside_all = ~0u, outside_any = 0u, deep_all = ~0u;
    for (int i = 0; i < e->n; ++i) {
        const uint bits = outside_bits(in_frame[i], eps, 0.0);
        outside_all &= bits;
        outside_any |= bits;
        deep_all &= outside_bits(in_frame[i], eps, magnitude * HIDDEN_MARGIN);
    }

    for (int face = 0; face < HR_FACES; ++face) {
        // Planes in the clipping order: while no plane has cut the polygon it is the element
        // itself, so a plane with every vertex in changes nothing and one with every vertex out
        // hides the face, as clip_if_needed would decide. From the first plane that cuts it on,
        // the clipping itself.
        const int planes = face == 0 ? 5 : 4;
        if ((deep_all >> (5 * face)) & ((1u << planes) - 1)) continue;  // hidden (HIDDEN_MARGIN)
        int first_cut = planes;
        bool hidden = false;
        for (int plane = 0; plane < planes && first_cut == planes && !hidden; ++plane) {
            const uint bit = 1u << (face * 5 + plane);
            hidden = (outside_all & bit) != 0;
            if (!hidden && (outside_any & bit) != 0) first_cut = plane;
        }
        if (hidden) continue;
        ClipPolygon poly;
        poly.n = 0;
        for (int i = 0; i < e->n; ++i) poly.v[poly.n++] = to_face(face, in_frame[i]);
        bool visible = true;
        for (int plane = first_cut; plane < planes && visible; ++plane)
            visible = clip_if_needed(&poly, plane, face, eps);
        if (!visible) continue;

        // The plane n.p = c in face coordinates gives 1/depth = (n_u s + n_v t + n_d) / c, stored
        // divided through (the reference's `plane`).
        const Vec nf = to_face(face, normal_local);
        const double c = dot3(nf, poly.v[0]);
        if (fabs(c) <= eps * 1e-3) continue;  // seen edge-on: covers no area

        // Cell coordinates, x in [0, n) and y in [0, rows), snapped to fixed point (the
        // reference's snap): from here on the inside test is exact integer arithmetic.
        const double t0 = face == 0 ? 1.0 : 0.0;
        long px[HR_MAX_CLIPPED], py[HR_MAX_CLIPPED];
        for (int i = 0; i < poly.n; ++i) {
            px[i] = snap((poly.v[i].x / poly.v[i].z + 1.0) * per_unit);
            py[i] = snap((poly.v[i].y / poly.v[i].z + t0) * per_unit);
        }
        long area2 = 0;
        for (int i = 0; i < poly.n; ++i) {
            const int j = (i + 1) % poly.n;
            area2 += px[i] * py[j] - px[j] * py[i];
        }
        if (area2 == 0) continue;
        const bool reverse = area2 < 0;  // make counter-clockwise
        long x[HR_MAX_CLIPPED], y[HR_MAX_CLIPPED];
        long xmin = px[0], xmax = px[0], ymin = py[0], ymax = py[0];
        for (int i = 0; i < poly.n; ++i) {
            const int from = reverse ? poly.n - 1 - i : i;
            x[i] = px[from];
            y[i] = py[from];
            xmin = min(xmin, px[i]);
            xmax = max(xmax, px[i]);
            ymin = min(ymin, py[i]);
            ymax = max(ymax, py[i]);
        }
        const int rows = face_rows(face, n);
        const int i0 = max(0, first_centre(xmin)), i1 = min(n - 1, last_centre(xmax));
        const int j0 = max(0, first_centre(ymin)), j1 = min(rows - 1, last_centre(ymax));
        if (i0 > i1 || j0 > j1) continue;  // no cell centre on the face: no record

        // The next slot of the work-group's region: a counter no other core touches, and the
        // records stay packed, so the raster reads little memory. Their order may vary from
        // run to run; the raster's result does not depend on it.
        const uint slot = atomic_inc(used);
        if (slot >= region_end(shot)) continue;  // the region is full: counted only
        __global HrRecord* r = records + slot;
        // The edges of the inside test: the reference's dx * (Y - ay) - dy * (X - ax) at the
        // centre X = S i + S/2, Y = S j + S/2 (S = SUBCELL), as a i + b j + c, plus 1 for an
        // edge the top-left rule gives its centres (integers: value >= 0 there is value + 1 > 0).
        const long half_cell = SUBCELL / 2;
        int edges = 0;
        for (int e = 0; e < poly.n; ++e) {
            const int f = e + 1 == poly.n ? 0 : e + 1;
            const long dx = x[f] - x[e], dy = y[f] - y[e];
            if (dx == 0 && dy == 0) continue;  // clipping or snapping can repeat a vertex
            __global HrEdge* edge = &r->cover.edge[edges++];
            edge->a = -dy * SUBCELL;
            edge->b = dx * SUBCELL;
            edge->c = dx * (half_cell - y[e]) - dy * (half_cell - x[e]) + (owns_edge_point(dx, dy) ? 1 : 0);
        }
        store_record_fields(r, boxes + slot, nf.x / c, nf.y / c, nf.z / c, k, is_back, edges, 0, i0, i1, j0, j1, face);
    }
}

// Whether any lane of a mask (0 or -1 per lane) is set, the lanes folded with | and tested
// once: any() can become a branch per lane. (sum_lanes(mask) != 0 says the same, measured ~4%
// slower in the raster on PoCL.)
bool any_of4(long4 mask) {
    const long2 pair = mask.lo | mask.hi;
    return (pair.x | pair.y) != 0;
}
bool any_of8(long8 mask) {
    return any_of4(mask.lo | mask.hi);
}

// One row down for exact edge bounds kept as floor quotient q and remainder r (0 <= r < d) of
// m = -(b j + c) by d: m falls by b = sq d + sr, and a borrow (-1 in a vector comparison)
// takes one more off the quotient.
void step_row(long8* q, long8* r, long8 d, long8 sq, long8 sr) {
    *r -= sr;
    const long8 borrow = *r < 0;
    *r += d & borrow;
    *q += borrow - sq;
}

#if HEMIRAD_SETUP_LANES
// setup_lanes: HR_SETUP_LANES elements per work-item, each lane an element, in the operations
// (and order) of setup_element. The common case takes no branch per element: an element
// wholly inside one face's frustum and hidden on the other four (by the rule setup_element
// follows: the first plane any vertex is outside of has every vertex outside) needs no
// clipping. The other lanes go through setup_element.
typedef double8 ldouble;
typedef long8 llong;

// Where face == f (per lane), these values, as to_face permutes and negates.
void to_face_lanes(llong face, ldouble x, ldouble y, ldouble z, ldouble* u, ldouble* v, ldouble* d) {
    *u = select(select(select(select(x, -x, face == 3), -y, face == 2), y, face == 1), x, face == 0);
    *v = select(z, y, face == 0);
    *d = select(select(select(select(-y, y, face == 3), -x, face == 2), x, face == 1), z, face == 0);
}

// outside_bits, a lane per element, where a plane value is < -margin (outside_bits: margin 0).
llong outside_bits_lanes(ldouble x, ldouble y, ldouble z, double eps, ldouble margin) {
    const ldouble low = -margin;
    const llong base = (z - eps < low) & 1;
    const ldouble zmx = z - x, zpx = z + x, zmy = z - y, zpy = z + y, xmy = x - y, xpy = x + y;
    const llong face0 = base | ((zmx < low) & 2) | ((zpx < low) & 4) | ((zmy < low) & 8) | ((zpy < low) & 16);
    const llong face1 = base | ((xmy < low) & 2) | ((xpy < low) & 4) | ((zmx > margin) & 8);
    const llong face2 = base | ((xmy > margin) & 2) | ((xpy > margin) & 4) | ((zpx > margin) & 8);
    const llong face3 = base | ((xpy < low) & 2) | ((xmy > margin) & 4) | ((zmy > margin) & 8);
    const llong face4 = base | ((xpy > margin) & 2) | ((xmy < low) & 4) | ((zpy > margin) & 8);
    return face0 | face1 << 5 | face2 << 10 | face3 << 15 | face4 << 20;
}

// floor_div (below) a lane at a time, for |m| < 2^53 and inverse ~ 1 / d: the estimate m
// inverse truncated, then corrected until every remainder is in [0, d).
llong floor_div_lanes(llong m, llong d, ldouble inverse, llong* rem) {
    llong q = convert_long8_rtz(convert_double8(m) * inverse);
    llong r = m - q * d;
    while (any_of8(r < 0)) {
        const llong under = r < 0;  // -1 in such lanes
        q += under;
        r += d & under;
    }
    while (any_of8(r >= d)) {
        const llong over = r >= d;
        q -= over;
        r -= d & over;
    }
    *rem = r;
    return q;
}

llong abs_lanes(llong v) {
    return select(v, -v, v < 0);
}

llong snap_lanes(ldouble cells) {
    return convert_long8(floor(cells * (double)SUBCELL + 0.5));
}

// Whether a group's bounding sphere lies wholly behind the base plane, below -eps: then every
// vertex of every element is below the plane, where setup_element would drop it too (it keeps
// an element with a vertex above +eps; the margin of 2 eps dwarfs this test's rounding).
bool group_behind(const HrShot* shot, __global const HrElementLanes* group) {
    const Vec d = vec(group->bound[0] - shot->origin[0], group->bound[1] - shot->origin[1],
                      group->bound[2] - shot->origin[2]);
    return dot3(d, vec(shot->w[0], shot->w[1], shot->w[2])) + group->bound[3] < -shot->eps;
}

// Occlusion culling (setup's `occluded`): whether every cell any element of a lane group could
// cover holds something nearer already, so that setup may drop the group without changing one
// cell. block_depth[b] is the least 1/depth over depth block b's cells in the occluder pass (0
// where a cell was empty); the final raster only adds records, so a cell's winner is at least that
// near. A group is hidden when, on every face its bounding sphere reaches, an upper bound of the
// 1/depth its records could hold at any cell is below block_depth on every block the sphere's
// projection (widened as below) touches. The bound must hold for the values setup and the raster
// compute, not only for the geometry:
// - a cell centre inside a record lies within 2^-17 sqrt2 cells of the element's true projection
//   (its vertices are snapped to 2^-16 cells), where the plane's 1/depth is at most 1/(z - r)
//   (z the sphere centre's depth on the face); beyond it, the plane rises at most 1/c per unit of
//   face coordinate (c the plane's distance from the shooter, the normal a unit vector), so the
//   bound adds delta/c with delta that distance in face units;
// - setup computes c from rounded vertices (any of the element's, or a clipped one): absolute error
//   ~1e-15 |v - origin|, bounded here by 1e-12 times `extent`, which bounds |v - origin| for every
//   point of the bounding sphere (the plane's 1/depth scales by c/c_computed), with c_eff the
//   smallest c less that and a group with c_eff <= 0 never hidden (a plane through the shooter);
// - the rest is rounding of order 1e-15 relative, covered by the factor 1 + 1e-9, and a sphere
//   within 1e-4 of its size from a face's eye plane is never hidden on it, unless it lies wholly
//   outside the face's frustum (beyond a side plane by more than rounding: setup clips to the
//   frustum, and a cell centre lies half a cell inside it), where it covers nothing on the face.
// Triangles repeat their last vertex, so vertex 0 and the normal of live lanes suffice for c.
// The least distance |n . (v - origin)| of a lane group's live elements' planes from the shooter,
// as computed (INFINITY when no lane is live).
double group_plane_distance(const HrShot* shot, __global const HrElementLanes* group) {
    const llong live = convert_long8(vload8(0, group->n)) > 0;
    const ldouble c = fabs(vload8(0, group->normal) * (vload8(0, group->v) - shot->origin[0]) +
                           vload8(1, group->normal) * (vload8(1, group->v) - shot->origin[1]) +
                           vload8(2, group->normal) * (vload8(2, group->v) - shot->origin[2]));
    const ldouble c_live = select((ldouble)(INFINITY), c, live);
    const double4 c_half = fmin(c_live.lo, c_live.hi);
    return fmin(fmin(c_half.x, c_half.y), fmin(c_half.z, c_half.w));
}

// Whether every element inside the sphere bound = {x, y, z, radius} (world), whose planes lie at
// least c_raw from the shooter as group_plane_distance computes it, is hidden (see above).
bool sphere_hidden(const HrShot* shot, const double* bound, double c_raw, __global const double* block_depth) {
    const Vec centre = to_local(shot, vec(bound[0], bound[1], bound[2]));
    const double r = bound[3];
    const double size = fabs(centre.x) + fabs(centre.y) + fabs(centre.z) + r;
    const double extent = size + r;  // >= the 1-norm of any point of the sphere less the origin
    const double c_min = c_raw - 1e-12 * extent;
    if (!(c_min > 0.0) || c_min == INFINITY) return false;

    const int n = shot->n;
    const double per_unit = 0.5 * n;
    const double delta = 0x1p-17 * 1.4142135623730951 * 1.01 / per_unit;  // face units
    const double slack = delta / c_min;
    const double scale = 1.0 + 1e-9 + 4e-12 * extent / c_min;
    for (int face = 0; face < HR_FACES; ++face) {
        const Vec f = to_face(face, centre);
        if (f.z + r <= 0.0) continue;                   // wholly behind this face's eye plane: not on it
        // Wholly beyond one of the face's side planes (|x| = z, |y| = z; a side face's bottom is
        // the base plane, y = 0): its elements, clipped to the frustum, cover none of its cells.
        const double beyond = 1.4142135623730951 * r * (1.0 + 1e-9) + 1e-9 * size;
        if (f.x - f.z > beyond || -f.x - f.z > beyond || f.y - f.z > beyond ||
            (face == 0 ? -f.y - f.z > beyond : -f.y > r * (1.0 + 1e-9) + 1e-9 * size))
            continue;
        if (f.z - r <= 1e-4 * size) return false;       // (near) the eye plane: no bound
        const double near_depth = f.z - r, far_depth = f.z + r;
        const double s_lo = fmin((f.x - r) / near_depth, (f.x - r) / far_depth) - delta;
        const double s_hi = fmax((f.x + r) / near_depth, (f.x + r) / far_depth) + delta;
        const double t_lo = fmin((f.y - r) / near_depth, (f.y - r) / far_depth) - delta;
        const double t_hi = fmax((f.y + r) / near_depth, (f.y + r) / far_depth) + delta;
        const double t0 = face == 0 ? 1.0 : 0.0;
        // Cells whose centre (i + 1/2) may lie in the box, clamped to the face; none: not on it.
        const double x_lo = (s_lo + 1.0) * per_unit - 0.5, x_hi = (s_hi + 1.0) * per_unit - 0.5;
        const double y_lo = (t_lo + t0) * per_unit - 0.5, y_hi = (t_hi + t0) * per_unit - 0.5;
        const int rows = face_rows(face, n);
        if (x_hi < -1.0 || y_hi < -1.0 || x_lo > n || y_lo > rows) continue;
        const int i0 = max(0, (int)floor(x_lo)), i1 = min(n - 1, (int)ceil(x_hi));
        const int j0 = max(0, (int)floor(y_lo)), j1 = min(rows - 1, (int)ceil(y_hi));
        if (i0 > i1 || j0 > j1) continue;
        const double bound = (1.0 / near_depth + slack) * scale;
        __global const double* depth = block_depth + depth_block_base(face, n);
        for (int by = j0 / DEPTH_BLOCK; by <= j1 / DEPTH_BLOCK; ++by)
            for (int bx = i0 / DEPTH_BLOCK; bx <= i1 / DEPTH_BLOCK; ++bx)
                if (!(bound < depth[by * depth_blocks_x(n) + bx])) return false;
    }
    return true;
}

bool group_hidden(const HrShot* shot, __global const HrElementLanes* group, __global const double* block_depth) {
    const double bound[4] = {group->bound[0], group->bound[1], group->bound[2], group->bound[3]};
    return sphere_hidden(shot, bound, group_plane_distance(shot, group), block_depth);
}

void setup_lanes(const HrShot* shot, __global const HrElementLanes* group, int first,
                 __global HrRecord* records, __global HrBox* boxes,
                 __local uint* used) {
    const double eps = shot->eps;
    const llong n_lanes = convert_long8(vload8(0, group->n));
    const int8 patch = vload8(0, group->patch);
    const llong mine = convert_long8(patch == (int8)(shot->shooter) || patch == (int8)(shot->twin));
    const llong has_twin = convert_long8(vload8(0, group->has_twin) != 0);
    const ldouble normal_x = vload8(0, group->normal), normal_y = vload8(1, group->normal),
                  normal_z = vload8(2, group->normal);
    const ldouble facing = normal_x * (shot->origin[0] - vload8(0, group->centroid)) +
                           normal_y * (shot->origin[1] - vload8(1, group->centroid)) +
                           normal_z * (shot->origin[2] - vload8(2, group->centroid));
    const llong is_back = facing < 0.0;
    llong live = (n_lanes > 0) & ~mine & ~(is_back & has_twin);

    // to_local, four vertices (a triangle's last repeated: the same values, the same bits).
    ldouble lx[4], ly[4], lz[4];
    llong above = 0, outside_all = -1, outside_any = 0;
    ldouble magnitude = eps;  // of every coordinate and eps
    for (int i = 0; i < 4; ++i) {
        const ldouble dx = vload8(3 * i, group->v) - shot->origin[0];
        const ldouble dy = vload8(3 * i + 1, group->v) - shot->origin[1];
        const ldouble dz = vload8(3 * i + 2, group->v) - shot->origin[2];
        lx[i] = dx * shot->u[0] + dy * shot->u[1] + dz * shot->u[2];
        ly[i] = dx * shot->v[0] + dy * shot->v[1] + dz * shot->v[2];
        lz[i] = dx * shot->w[0] + dy * shot->w[1] + dz * shot->w[2];
        above |= lz[i] > eps;
        const llong bits = outside_bits_lanes(lx[i], ly[i], lz[i], eps, 0.0);
        outside_all &= bits;
        outside_any |= bits;
        magnitude = fmax(magnitude, fmax(fabs(lx[i]), fmax(fabs(ly[i]), fabs(lz[i]))));
    }
    live &= above;
    if (!any_of8(live)) return;  // all behind the base plane (or the shooter's): no record
    // Planes every vertex is outside of by the margin: the face is hidden (HIDDEN_MARGIN).
    llong deep_all = -1;
    {
        const ldouble margin = magnitude * HIDDEN_MARGIN;
        for (int i = 0; i < 4; ++i) deep_all &= outside_bits_lanes(lx[i], ly[i], lz[i], eps, margin);
    }

    // The one face with no vertex outside, every other hidden: the first of its planes any
    // vertex is outside of (lowest bit) has all outside, or one has all outside by the margin.
    llong face = -1, fast = live;
    for (int f = 0; f < HR_FACES; ++f) {
        const long planes = f == 0 ? 0x1f : 0x0f;
        const llong any_out = (outside_any >> (5 * f)) & planes, all_out = (outside_all >> (5 * f)) & planes;
        const llong inside = any_out == 0;
        fast &= ~(inside & (face >= 0));  // two such faces: leave it to setup_element
        face = select(face, (llong)(f), inside);
        const llong deep_out = (deep_all >> (5 * f)) & planes;
        fast &= inside | ((any_out & -any_out & all_out) != 0) | (deep_out != 0);
    }
    fast &= face >= 0;

    const ldouble normal_u = normal_x * shot->u[0] + normal_y * shot->u[1] + normal_z * shot->u[2];
    const ldouble normal_v = normal_x * shot->v[0] + normal_y * shot->v[1] + normal_z * shot->v[2];
    const ldouble normal_w = normal_x * shot->w[0] + normal_y * shot->w[1] + normal_z * shot->w[2];
    ldouble nu, nv, nd;
    to_face_lanes(face, normal_u, normal_v, normal_w, &nu, &nv, &nd);
    const double per_unit = 0.5 * shot->n;
    const ldouble t0 = select((ldouble)(0.0), (ldouble)(1.0), face == 0);
    llong px[4], py[4];
    ldouble c = 0.0;
    for (int i = 0; i < 4; ++i) {
        ldouble u, v, d;
        to_face_lanes(face, lx[i], ly[i], lz[i], &u, &v, &d);
        if (i == 0) c = nu * u + nv * v + nd * d;
        px[i] = snap_lanes((u / d + 1.0) * per_unit);
        py[i] = snap_lanes((v / d + t0) * per_unit);
    }
    llong record = fast & (fabs(c) > eps * 1e-3);  // else seen edge-on: covers no area
    llong area2 = 0;
    for (int i = 0; i < 4; ++i) area2 += px[i] * py[(i + 1) & 3] - px[(i + 1) & 3] * py[i];
    record &= area2 != 0;
    const llong reverse = area2 < 0;  // make counter-clockwise
    llong x[4], y[4];
    llong xmin = px[0], xmax = px[0], ymin = py[0], ymax = py[0];
    for (int i = 0; i < 4; ++i) {
        x[i] = select(px[i], px[3 - i], reverse);
        y[i] = select(py[i], py[3 - i], reverse);
        xmin = min(xmin, px[i]);
        xmax = max(xmax, px[i]);
        ymin = min(ymin, py[i]);
        ymax = max(ymax, py[i]);
    }
    const double sub = (double)SUBCELL;
    const llong rows = select((llong)(shot->n / 2), (llong)(shot->n), face == 0);
    const llong i0 = max((llong)(0), convert_long8(ceil(convert_double8(xmin - SUBCELL / 2) / sub)));
    const llong i1 = min((llong)(shot->n - 1), convert_long8(floor(convert_double8(xmax - SUBCELL / 2) / sub)));
    const llong j0 = max((llong)(0), convert_long8(ceil(convert_double8(ymin - SUBCELL / 2) / sub)));
    const llong j1 = min(rows - 1, convert_long8(floor(convert_double8(ymax - SUBCELL / 2) / sub)));
    record &= (i0 <= i1) & (j0 <= j1);
    // No record and nothing for setup_element: common where elements are smaller than a cell.
    if (!any_of8(record | (live & ~fast))) return;

    // The edges of the inside test, as setup_element makes them; and in lanes, divided through
    // by SUBCELL = S (a and b are multiples of it, and for integers a' i + b' j, a i + b j + c > 0
    // is a' i + b' j > -c / S, is a' i + b' j + ceil(c / S) > 0), which keeps the quotients
    // below in doubles' exact range (|m| < 2^42 up to N = 4096).
    // Per lane from here, through private copies (portable OpenCL C indexes no vector).
    long a_lane[4][HR_SETUP_LANES], b_lane[4][HR_SETUP_LANES], c_lane[4][HR_SETUP_LANES];
    llong edge_a[4], edge_b[4], edge_c[4];
    for (int e = 0; e < 4; ++e) {
        const int f = (e + 1) & 3;
        const llong dx = x[f] - x[e], dy = y[f] - y[e];
        const llong owns = (dy < 0) | ((dy == 0) & (dx > 0));  // owns_edge_point
        const long half_cell = SUBCELL / 2;
        const llong c_full = dx * (half_cell - y[e]) - dy * (half_cell - x[e]) + (owns & 1);
        // A repeated vertex (a triangle's, or one snapping made) gives no edge: a = b = 0 marks it.
        vstore8(-dy * SUBCELL, 0, a_lane[e]);
        vstore8(dx * SUBCELL, 0, b_lane[e]);
        vstore8(c_full, 0, c_lane[e]);
        // Zero in lanes without a record, whose values may be anything (an element behind the
        // shooter projects to infinities): the divisions below must end.
        edge_a[e] = select((llong)(0), -dy, record);
        edge_b[e] = select((llong)(0), dx, record);
        const llong minus_c = -c_full;  // ceil(c / S) = -floor(-c / S), the floor exact in integers
        edge_c[e] = select((llong)(0), -((minus_c - (minus_c & (SUBCELL - 1))) / SUBCELL), record);
    }

    // Spans, for records of at most HR_SPAN_ROWS rows: the raster's row bounds (see
    // raster_records), worked out here for a lane of elements at once. Horizontal edges bound
    // the rows; on each row, left edges (a > 0) the first cell and right edges (a < 0) the last,
    // exact quotients stepped from row to row.
    llong row0 = j0, row1 = j1;
    for (int e = 0; e < 4; ++e) {
        const llong flat = (edge_a[e] == 0) & (edge_b[e] != 0);
        if (!any_of8(flat)) continue;
        llong rem;
        const llong d = select((llong)(1), abs_lanes(edge_b[e]), flat);
        const llong q = floor_div_lanes(select((llong)(0), -edge_c[e], flat), d, 1.0 / convert_double8(d), &rem);
        row0 = select(row0, max(row0, q + 1), flat & (edge_b[e] > 0));
        row1 = select(row1, min(row1, -q - 1), flat & (edge_b[e] < 0));
    }
    const llong span_rows = row1 - row0 + 1;
    const llong spans = record & (span_rows <= HR_SPAN_ROWS);
    llong edge_q[4], edge_r[4], edge_d[4], edge_sq[4], edge_sr[4];
    for (int e = 0; e < 4; ++e) {
        edge_d[e] = select((llong)(1), abs_lanes(edge_a[e]), edge_a[e] != 0);
        const ldouble inverse = 1.0 / convert_double8(edge_d[e]);
        edge_sq[e] = floor_div_lanes(edge_b[e], edge_d[e], inverse, &edge_sr[e]);
        edge_q[e] = floor_div_lanes(-(edge_b[e] * row0 + edge_c[e]), edge_d[e], inverse, &edge_r[e]);
    }
    long rows_most = 0;
    {
        long rows_lane[HR_SETUP_LANES];
        vstore8(select((llong)(0), span_rows, spans), 0, rows_lane);
        for (int l = 0; l < HR_SETUP_LANES; ++l) rows_most = max(rows_most, rows_lane[l]);
    }
    int span[HR_SPAN_ROWS][HR_SETUP_LANES];
    llong span_i0 = (llong)(1 << 30), span_i1 = -1;  // the columns the spans reach
    for (int row = 0; row < (int)rows_most; ++row) {
        llong lo = i0, hi = i1;
        for (int e = 0; e < 4; ++e) {
            lo = select(lo, max(lo, edge_q[e] + 1), edge_a[e] > 0);
            hi = select(hi, min(hi, -edge_q[e] - 1), edge_a[e] < 0);
            step_row(&edge_q[e], &edge_r[e], edge_d[e], edge_sq[e], edge_sr[e]);
        }
        const llong cells = ((llong)(row) < span_rows) & (lo <= hi);
        span_i0 = select(span_i0, min(span_i0, lo), cells);
        span_i1 = select(span_i1, max(span_i1, hi), cells);
        vstore8(convert_int8(select((llong)(HR_SPAN_NONE), lo | hi << 16, cells)), 0, span[row]);
    }
    record &= ~spans | (span_i0 <= span_i1);  // spans covering no cell centre: no record
    double plane[3][HR_SETUP_LANES];
    vstore8(nu / c, 0, plane[0]);
    vstore8(nv / c, 0, plane[1]);
    vstore8(nd / c, 0, plane[2]);
    long flags[5][HR_SETUP_LANES];  // live, fast, record, face, back
    vstore8(live, 0, flags[0]);
    vstore8(fast, 0, flags[1]);
    vstore8(record, 0, flags[2]);
    vstore8(face, 0, flags[3]);
    vstore8(is_back, 0, flags[4]);
    long box_lane[5][HR_SETUP_LANES];  // i0, i1, j0, j1; spans: 1 for a span record
    vstore8(select(i0, span_i0, spans), 0, box_lane[0]);
    vstore8(select(i1, span_i1, spans), 0, box_lane[1]);
    vstore8(select(j0, row0, spans), 0, box_lane[2]);
    vstore8(select(j1, row1, spans), 0, box_lane[3]);
    vstore8(spans & 1, 0, box_lane[4]);

    // One atomic for the records of all fast lanes: on CPUs an atomic waits for the stores
    // before it, so one per record would cost more than the record.
    uint fast_records = 0;
    for (int l = 0; l < HR_SETUP_LANES; ++l) fast_records += flags[2][l] != 0;
    uint slot = fast_records > 0 ? atomic_add(used, fast_records) : 0u;
    const uint end = region_end(shot);
    for (int l = 0; l < HR_SETUP_LANES; ++l) {
        const int k = first + l;
        if (!flags[0][l]) continue;
        if (!flags[1][l]) {
            const Element element = element_in_lanes(group, l);
            setup_element(shot, &element, k, records, boxes, used);
            continue;
        }
        if (!flags[2][l]) continue;
        if (slot >= end) continue;  // the region is full: counted only (later slots are past it too)
        __global HrRecord* r = records + slot;
        int edges = 0;
        if (box_lane[4][l]) {
            const int rows = (int)(box_lane[3][l] - box_lane[2][l]) + 1;
            for (int row = 0; row < rows; ++row) r->cover.span[row] = span[row][l];
        } else {
            for (int e = 0; e < 4; ++e) {
                if (a_lane[e][l] == 0 && b_lane[e][l] == 0) continue;
                __global HrEdge* edge = &r->cover.edge[edges++];
                edge->a = a_lane[e][l];
                edge->b = b_lane[e][l];
                edge->c = c_lane[e][l];
            }
        }
        store_record_fields(r, boxes + slot, plane[0][l], plane[1][l], plane[2][l], k, flags[4][l] != 0, edges,
                            (int)box_lane[4][l], (int)box_lane[0][l], (int)box_lane[1][l], (int)box_lane[2][l],
                            (int)box_lane[3][l], (int)flags[3][l]);
        ++slot;
    }
}
#endif

// The record slots of work-group g of setup (and of scatter): lanes setup, a region of
// group_capacity; otherwise five per element it sets up, from five times its first element.
uint group_first_slot(const HrShot* shot, __global const HrPatch* patches, int g) {
#if HEMIRAD_SETUP_LANES
    return (uint)g * shot->group_capacity;
#else
    return shot->patches == 0 ? 0u : (uint)(HR_FACES * patches[min(g * HEMIRAD_WG, shot->patches - 1)].first_element);
#endif
}

// setup and scatter: for each of the `used` records of setup's work-group g (this
// work-group's), an atomic increment of the counter of every tile its box touches, in the
// work-group's counter copy; with lists, the counter is a cursor and the record's index goes
// into the list at it.
void bin_records(const HrShot* shot, __global const HrPatch* patches, __global const HrBox* boxes, uint used,
                 __global uint* counters, __global uint* lists) {
    __global uint* copy = counters + counter_copy(shot->tile_base[HR_FACES]);
    const uint first = group_first_slot(shot, patches, (int)get_group_id(0));
    used = min(used, region_end(shot) - first);  // a full region's stored records (the host reruns the shot)
    for (uint slot = first + get_local_id(0); slot < first + used; slot += HEMIRAD_WG) {
        const HrBox box = boxes[slot];
        __global uint* face_counters = copy + shot->tile_base[box.face];
        for (int ty = box.j0 / HEMIRAD_TILE; ty <= box.j1 / HEMIRAD_TILE; ++ty)
            for (int tx = box.i0 / HEMIRAD_TILE; tx <= box.i1 / HEMIRAD_TILE; ++tx) {
                const uint at = atomic_inc(&face_counters[ty * shot->tiles_x + tx]);
                if (lists != 0 && at < shot->list_capacity) lists[at] = slot;
            }
    }
}

// One work-item per patch (setup_element for its elements, none when the patch is the shooter
// or lies below its base plane) or, with SETUP_LANES, per HR_SETUP_LANES elements
// (setup_lanes); the records packed per work-group: group_records[g] says how many the region
// of group g holds; each record then counted into the tiles it may cover (scan left the counts
// at zero). Also zeroes the sums for the raster.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_WG, 1, 1))) void setup(
    const HrShot first_shot, __global const HrShot* more_shots, __global const HrElement* elements,
    __global const HrElementLanes* element_lanes, __global const HrPatch* patches, __global HrRecord* records,
    __global HrBox* boxes, __global uint* group_records, __global uint* tile_counts, __global long* sums,
    __global const int* clusters, __global const double* block_depth, const int occluded) {
    const size_t b = get_global_id(1);
    const HrShot shot_value = batch_shot(first_shot, more_shots, b);
    const HrShot* shot = &shot_value;
    records += b * record_stride(shot);
    boxes += b * record_stride(shot);
    group_records += b * group_stride(shot);
    tile_counts += b * counter_stride(shot);
    sums += b * sum_stride(shot);
    __local uint used;
#if HEMIRAD_SETUP_LANES
    // Work-group g sets up cluster clusters[b][g] (HEMIRAD_WG lane groups; -1: none), those the
    // host found not wholly behind the shot's base plane: the rest of the scene costs nothing
    // here. The host reads back only these clusters' sums, so only theirs are cleared (ahead of
    // the raster in the queue; scan leaves the tile counts at zero), and the blocked share.
    // -2 - c: cluster c, which the occluder pass set up as work-group g already: its records and
    // their count stand, and are only counted into the tiles again.
    const int entry = clusters[b * get_num_groups(0) + get_group_id(0)];
    const bool kept = entry < -1;
    const int cluster = kept ? -2 - entry : entry;
    if (get_local_id(0) == 0)
        used = group_first_slot(shot, patches, (int)get_group_id(0)) + (kept ? group_records[get_group_id(0)] : 0u);
    barrier(CLK_LOCAL_MEM_FENCE);
    const int p = cluster * HEMIRAD_WG + (int)get_local_id(0);
    if (get_global_id(0) == 0) sums[shot->elements] = 0;
    if (get_global_id(0) == 0 && !occluded) sums[shot->elements + 2] = sums[shot->elements + 3] = 0;  // none counted here
    if (cluster >= 0)
        for (int l = 0; l < HR_SETUP_LANES && p * HR_SETUP_LANES + l < shot->elements; ++l)
            sums[p * HR_SETUP_LANES + l] = 0;
    // occluded: the occluder pass has drawn this shot's depth blocks, and the host launched only
    // the clusters cull_clusters did not hide whole; each lane group is tested (group_hidden). The
    // groups tested and those hidden are counted for benchmarks, once per work-group.
    __local uint tested, hidden;
    if (get_local_id(0) == 0) tested = hidden = 0;
    const bool in_range = !kept && cluster >= 0 && p * HR_SETUP_LANES < shot->elements;
#if HEMIRAD_CULL  // (not `HEMIRAD_CULL && …`: a constant operand draws a compiler warning on every build)
    const bool live_group = in_range && !group_behind(shot, element_lanes + p);
#else
    const bool live_group = in_range;
#endif
    barrier(CLK_LOCAL_MEM_FENCE);
    if (live_group) {
        bool drop = false;
        if (occluded) {
            drop = group_hidden(shot, element_lanes + p, block_depth + b * depth_stride(shot->n));
            atomic_inc(&tested);
            if (drop) atomic_inc(&hidden);
        }
        if (!drop) setup_lanes(shot, element_lanes + p, p * HR_SETUP_LANES, records, boxes, &used);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0 && tested > 0) {
        atom_add(&sums[shot->elements + 2], (long)tested);
        atom_add(&sums[shot->elements + 3], (long)hidden);
    }
#else
    if (get_local_id(0) == 0) used = group_first_slot(shot, patches, (int)get_group_id(0));
    barrier(CLK_LOCAL_MEM_FENCE);
    const int p = (int)get_global_id(0);
    // The sums' clear, ahead of the raster in the queue (scan leaves the tile counts at zero).
    for (int c = p; c <= shot->elements; c += (int)get_global_size(0)) sums[c] = 0;
    if (p < shot->patches && p != shot->shooter && p != shot->twin) {  // the shooter's own surface, either side
        // Elements tile their patch: when the patch is below the base plane, so are they. A
        // cluster (n = 0) has no polygon to tell.
        __global const HrPatch* patch = patches + p;
        bool patch_above = patch->n == 0;
        for (int i = 0; i < patch->n; ++i)
            patch_above = patch_above || to_local(shot, vec(patch->v[3 * i], patch->v[3 * i + 1], patch->v[3 * i + 2]))
                                                 .z > shot->eps;
        for (int k = patch->first_element; patch_above && k < patch->first_element + patch->elements; ++k) {
            const Element element = element_at(elements + k);
            setup_element(shot, &element, k, records, boxes, &used);
        }
    }
#endif
    // The work-group's records complete, each is counted into the tiles it may cover. After the
    // barrier, not as it is stored: on CPUs an atomic waits for the stores before it.
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    const uint count = used - group_first_slot(shot, patches, (int)get_group_id(0));
    if (get_local_id(0) == 0) group_records[get_group_id(0)] = count;
    bin_records(shot, patches, boxes, count, tile_counts, 0);
}

#if HEMIRAD_SETUP_LANES
// Occlusion culling of whole clusters, between the occluder pass and the final pass: a work-item
// per entry of a shot's row of clusters (clusters, row_length entries a shot), testing the
// cluster's bounding sphere with the least plane distance of its live groups (the bound of
// group_hidden, which holds for any sphere that holds the elements). hidden[entry] is the number
// of the cluster's live lane groups (not wholly behind the base plane) where the occluder pass's
// depths hide it, else 0 (and 0 for an entry that is no cluster to set up: -1, or an occluder,
// -2 - c). The host then launches setup on the clusters not hidden alone: a hidden cluster costs
// no work-group, clear or read.
__kernel void cull_clusters(const HrShot first_shot, __global const HrShot* more_shots,
                            __global const HrElementLanes* element_lanes, __global const int* clusters,
                            const int row_length, __global const double* block_depth,
                            __global const double* cluster_bounds, __global int* hidden) {
    const size_t b = get_global_id(1);
    const int g = (int)get_global_id(0);
    if (g >= row_length) return;
    const HrShot shot_value = batch_shot(first_shot, more_shots, b);
    const HrShot* shot = &shot_value;
    const int cluster = clusters[b * row_length + g];
    int live = 0;
    if (cluster >= 0) {
        double c = INFINITY;
        for (int l = 0; l < HEMIRAD_WG; ++l) {
            const int p = cluster * HEMIRAD_WG + l;
            if (p * HR_SETUP_LANES >= shot->elements) break;
#if HEMIRAD_CULL
            if (group_behind(shot, element_lanes + p)) continue;
#endif
            ++live;
            c = fmin(c, group_plane_distance(shot, element_lanes + p));
        }
        const double bound[4] = {cluster_bounds[4 * cluster], cluster_bounds[4 * cluster + 1],
                                 cluster_bounds[4 * cluster + 2], cluster_bounds[4 * cluster + 3]};
        if (!sphere_hidden(shot, bound, c, block_depth + b * depth_stride(shot->n))) live = 0;
    }
    hidden[b * row_length + g] = live;
}
#endif

// One work-group: exclusive prefix sum of the tile counts, tile by tile and within a tile copy
// by copy, into list offsets (and the scatter cursors, laid out as the counts): a tile's list is
// offsets[tile * COPIES] up to offsets[(tile + 1) * COPIES]. offsets[tiles * COPIES] is the
// total, also in sums[elements + 1], which the host checks against the list capacity. The
// counts are left at zero for the next shot's setup (the host zeroes them only when they are
// new, or after a launch that failed part-way).
__kernel __attribute__((reqd_work_group_size(HEMIRAD_SCAN_WG, 1, 1))) void scan(
    const HrShot first_shot, __global const HrShot* more_shots, __global uint* tile_counts,
    __global uint* offsets, __global uint* cursors, __global long* sums, __global const uint* group_records,
    const int groups) {
    const size_t b = get_global_id(1);
    const HrShot shot_value = batch_shot(first_shot, more_shots, b);
    const HrShot* shot = &shot_value;
    tile_counts += b * counter_stride(shot);
    offsets += b * (counter_stride(shot) + 1);
    cursors += b * counter_stride(shot);
    sums += b * sum_stride(shot);
    __local uint partial[HEMIRAD_SCAN_WG];
    const int lid = (int)get_local_id(0);
    const int tiles = shot->tile_base[HR_FACES];
    const int entries = tiles * HEMIRAD_COUNT_COPIES;
    const int chunk = (entries + HEMIRAD_SCAN_WG - 1) / HEMIRAD_SCAN_WG;
    const int begin = min(lid * chunk, entries), end = min(begin + chunk, entries);
    uint sum = 0;
    for (int t = begin; t < end; ++t) sum += tile_counts[t % HEMIRAD_COUNT_COPIES * tiles + t / HEMIRAD_COUNT_COPIES];
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
        const int counter = t % HEMIRAD_COUNT_COPIES * tiles + t / HEMIRAD_COUNT_COPIES;
        offsets[t] = run;
        cursors[counter] = run;
        run += tile_counts[counter];
        tile_counts[counter] = 0;  // for the next shot's setup, which counts into it
    }
    if (lid == HEMIRAD_SCAN_WG - 1) {
        offsets[entries] = partial[lid];
        sums[shot->elements + 1] = partial[lid];  // read back with the sums
    }
    // The most records one of the launch's `groups` setup work-groups made, also read back.
    barrier(CLK_LOCAL_MEM_FENCE);
    group_records += b * group_stride(shot);
    uint most = 0;
    for (int g = lid; g < groups; g += HEMIRAD_SCAN_WG) most = max(most, group_records[g]);
    partial[lid] = most;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int step = HEMIRAD_SCAN_WG / 2; step > 0; step >>= 1) {
        if (lid < step) partial[lid] = max(partial[lid], partial[lid + step]);
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) sums[shot->elements + 4] = partial[0];
}

// As setup's counting (the same work-groups, so the same counter copies): the index of each
// record in the list of every tile it may cover. The order within a list varies from run to
// run; the raster's result does not depend on it.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_WG, 1, 1))) void scatter(
    const HrShot first_shot, __global const HrShot* more_shots, __global const HrPatch* patches,
    __global const HrBox* boxes, __global const uint* group_records, __global uint* cursors, __global uint* lists) {
    const size_t b = get_global_id(1);
    const HrShot shot_value = batch_shot(first_shot, more_shots, b);
    const HrShot* shot = &shot_value;
    boxes += b * record_stride(shot);
    group_records += b * group_stride(shot);
    cursors += b * counter_stride(shot);
    lists += b * (size_t)shot->list_capacity;
    bin_records(shot, patches, boxes, group_records[get_group_id(0)], cursors, lists);
}

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

// The sizes of the shared structs as this compiler lays them out; the host compares them with
// its own before the first shot.
__kernel void layout(__global int* sizes) {
    sizes[0] = (int)sizeof(HrElement);
    sizes[1] = (int)sizeof(HrPatch);
    sizes[2] = (int)sizeof(HrShot);
    sizes[3] = (int)sizeof(HrRecord);
}
