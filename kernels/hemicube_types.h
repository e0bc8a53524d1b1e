// Layout of every struct that crosses the host/kernel boundary of kernels/hemicube.cl. Included
// by the kernel (inlined at embedding) and by the host (src/formfactor/opencl_engine.cpp), so the
// two cannot drift: scalar double and 32-bit int fields only, doubles first, sizes a multiple of
// 8 bytes. The host static_asserts sizes and offsets.
#ifndef HEMIRAD_HEMICUBE_TYPES_H
#define HEMIRAD_HEMICUBE_TYPES_H

// Device compilers define __OPENCL_VERSION__ (the spec requires it); plain clang only the C version.
#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)
typedef double hr_double;
typedef int hr_int;
typedef uint hr_uint;
typedef long hr_long;
#else
#include <cstdint>
typedef double hr_double;
typedef std::int32_t hr_int;
typedef std::uint32_t hr_uint;
typedef std::int64_t hr_long;
#endif

#define HR_FACES 5        // top (+z), +x, -x, +y, -y: the order of formfactor::to_face
#define HR_MAX_CLIPPED 9  // a quad clipped by 5 planes: at most one vertex more per plane (clip)
#define HR_EMPTY (-1)     // id of a cell nothing covers
#define HR_BLOCKER (-2)   // id of a cell won by the back of a one-sided surface
// Delta form factors are summed in 64-bit fixed point (integer addition is associative, so
// the atomic sums are bit-identical run to run): one unit of form factor is 2^62.
#define HR_FIXED_SHIFT 62
// Projected vertices are snapped to 2^16 units per cell (formfactor::kSubcell).
#define HR_SUBCELL_BITS 16
// Occlusion culling keeps a shot's least 1/depth per block of HR_DEPTH_BLOCK² cells.
#define HR_DEPTH_BLOCK 8

// One receiver element: a planar convex triangle or quad, counter-clockwise from its front.
typedef struct {
    hr_double v[12];      // up to 4 vertices, x y z each, world space
    hr_double normal[3];  // unit, front side
    hr_double centroid[3];
    hr_int n;         // 3 or 4
    hr_int has_twin;  // 1: a doubleSided twin draws this surface's back
    hr_int patch;     // the patch it belongs to
    hr_int pad;
} HrElement;

// Elements in groups of HR_SETUP_LANES as structures of arrays, what the CPU setup loads a
// vector at a time: lane l of group g is element g * HR_SETUP_LANES + l. A triangle repeats its
// last vertex; lanes past the last element have n = 0.
#define HR_SETUP_LANES 8
typedef struct {
    hr_double v[4 * 3 * HR_SETUP_LANES];  // [vertex][x, y, z][lane], world space
    hr_double normal[3 * HR_SETUP_LANES];
    hr_double centroid[3 * HR_SETUP_LANES];
    hr_int n[HR_SETUP_LANES];  // 3 or 4; 0 for no element
    hr_int has_twin[HR_SETUP_LANES];
    hr_int patch[HR_SETUP_LANES];
    // A sphere holding every vertex of the group (centre x, y, z, radius): a group wholly behind
    // the shooter's base plane is culled with one test, so that a shot's setup costs little
    // for the part of a large scene behind the shooter.
    hr_double bound[4];
} HrElementLanes;

// One patch: its polygon decides whether all of its elements lie below the base plane (each
// element's HrElement::patch says which).
typedef struct {
    hr_double v[12];
    hr_int n;
    hr_int pad;
} HrPatch;

// Everything one shot needs besides the buffers: the frame (from formfactor::make_frame on the
// host), the clip distance and the tiling of the five faces.
typedef struct {
    hr_double origin[3], u[3], v[3], w[3];  // frame: w the shooter's normal
    hr_double eps;                          // base-plane clip distance, scene units
    hr_int n;                               // hemicube resolution N (top NxN, sides NxN/2)
    hr_int shooter;                         // patch whose elements the shot skips: the shooter, −1 for a cluster
    hr_int twin;                            // the shooter's twin (the surface's other side), likewise, or −1
    hr_int elements;                        // element count
    hr_int patches;                         // patch count
    hr_int tiles_x;                         // tiles across a face: ceil(N / TILE)
    hr_int tile_base[HR_FACES + 1];         // first tile of each face, then the tile count
    hr_uint list_capacity;                  // entries the per-tile record lists can hold
    // Lanes setup: record slots per setup work-group (a region each; a group that needs more
    // counts them without storing, and the host grows the regions and reruns), and work-groups
    // the record buffers hold per shot.
    hr_uint group_capacity;
    hr_uint group_rows;
    hr_uint table;  // the cell weights: 0 form factors (a patch), 1 solid angles (a light)
} HrShot;

// One edge of a record's inside test, exact in 64-bit integers: at cell (i, j) its value is
// a i + b j + c, the reference's edge function of the polygon's snapped edge at the cell centre
// plus 1 where the top-left rule gives the edge its centres, so that inside is value > 0.
typedef struct {
    hr_long a, b, c;
} HrEdge;

// The cells a record may cover, inclusive (its cell bounding box on its face): what the tile
// binning reads, apart from the records.
typedef struct {
    hr_int i0, i1, j0, j1;
    hr_int face;
    hr_int pad;
} HrBox;

// Rows a span record holds: the room of the edges it goes without.
#define HR_SPAN_ROWS (HR_MAX_CLIPPED * (int)sizeof(HrEdge) / 4)
// A span row: the cells lo .. hi of the row (lo > hi: none), packed as lo | hi << 16.
#define HR_SPAN_NONE 0xffff

// One element seen on one face: its clipped polygon in cell coordinates (x in [0, N), y in
// [0, rows)) as the edges of the inside test (a cell centre is inside where every edge is > 0)
// or, where setup worked them out (and they fit), as the spans of cells inside on each of the
// box's rows; and its plane for the depth. The fixed fields come first; a record spans four
// cache lines, of which a small span record touches one or two.
typedef struct {
    hr_double plane[3];  // 1/depth = plane[0] s + plane[1] t + plane[2] at face coordinates (s, t)
    hr_int element;      // element index
    hr_int back;         // 1: the back of a one-sided surface (a blocker)
    hr_int edges;        // edge count, degenerate edges dropped; 0 in a span record
    hr_int spans;        // 1: cover.span[r] are the cells of row box.j0 + r, box.j0 .. box.j1
    union {
        HrEdge edge[HR_MAX_CLIPPED];
        hr_int span[HR_SPAN_ROWS];
    } cover;
} HrRecord;

#endif
