// Shared by every stage of the hemicube pipeline (included by hemicube.cl, after the knobs):
// the hemicube frame and faces, Sutherland-Hodgman clipping against a face's frustum, the
// outside-plane bits, the fixed-point snap and cell ranges, an element's two copies, the
// per-shot buffer strides, the depth blocks of occlusion culling, the record writer both setups
// use, and the lane helpers (any_of4/any_of8, step_row) of lanes setup and raster_records.

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
// (one per cluster of lane groups, or per HEMIRAD_WG elements), whatever the launch's row length,
// so that the occluder pass's counts sit where the final pass finds them.
size_t group_stride(const HrShot* shot) {
#if HEMIRAD_SETUP_LANES
    const size_t items = ((size_t)shot->elements + HR_SETUP_LANES - 1) / HR_SETUP_LANES;
#else
    const size_t items = (size_t)shot->elements;
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
