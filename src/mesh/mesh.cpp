// Meshing: pairs coplanar triangles into convex quads, then grids every face into patches
// (shooters) and each patch into elements (receivers), in double precision.
#include "mesh/mesh.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <unordered_map>
#include <utility>

#include "core/error.h"
#include "core/parallel.h"
#include "mesh/refine.h"
#include "mesh/texturing.h"

namespace hemirad::mesh {
namespace {

using glm::dvec3;

// A triangle is dropped when its area is at most this × (longest edge)²: a needle or a point.
constexpr double kDegenerateArea = 1e-12;
// Two triangles are coplanar when their unit normals' dot product exceeds this.
constexpr double kCoplanarDot = 1.0 - 1e-9;
// A quad is strictly convex when every corner turns left by more than this sine: a corner of
// ~180° would make a triangle with a split edge, not a quad worth gridding.
constexpr double kConvexSin = 1e-6;
// An edge of exactly k × size must give k divisions even when rounding makes it a hair longer.
constexpr double kCountSlack = 1e-9;
// Divisions along one face edge (patches × elements); keeps lattice indices far from overflow.
constexpr double kMaxDivisions = 1 << 15;

// A face to grid: a lone triangle (n = 3) or a quad of two source triangles (n = 4), CCW.
struct Face {
    Polygon poly;
    std::array<const scene::Triangle*, 2> src{};  // src[1] only for a quad
};

// A patch polygon and the polygons of its elements, before attributes are filled in.
struct PatchCells {
    Polygon poly;
    std::vector<Polygon> elements;
};

// Lattice points of one face, (nu + 1) × (nv + 1); a triangle uses the half i + j <= n.
// Every sub-polygon takes its corners from here, so neighbours share bit-identical vertices.
struct Lattice {
    int nu = 0, nv = 0;
    std::vector<dvec3> p;

    Lattice(int nu_, int nv_) : nu(nu_), nv(nv_), p(std::size_t(nu_ + 1) * std::size_t(nv_ + 1)) {}
    dvec3& at(int i, int j) { return p[std::size_t(j) * std::size_t(nu + 1) + std::size_t(i)]; }
    const dvec3& at(int i, int j) const { return p[std::size_t(j) * std::size_t(nu + 1) + std::size_t(i)]; }
};

double longest_edge(const std::array<dvec3, 3>& p) {
    return std::max({glm::length(p[1] - p[0]), glm::length(p[2] - p[1]), glm::length(p[0] - p[2])});
}

// NaN-safe: a triangle with a NaN or infinite coordinate never passes the comparison.
bool is_degenerate(const scene::Triangle& t) {
    const double area = 0.5 * glm::length(glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]));
    const double longest = longest_edge(t.p);
    return !(area > kDegenerateArea * longest * longest);
}

dvec3 unit_normal(const scene::Triangle& t) {
    return glm::normalize(glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]));
}

// Divisions needed so no piece of an edge of this length is longer than size, as a double: a
// count of the cells a size would make must not overflow, however small the size.
double divisions_needed(double length, double size) {
    return std::max(1.0, std::ceil(length / size - kCountSlack));
}

// The same as an int, for building the lattice.
int divisions(double n) {
    if (!(n <= kMaxDivisions))
        throw InputError(fmt::format("an edge needs {:.3g} divisions, more than {}: the patch or element size (--patch-size, "
                                     "--element-size) is too small for the scene", n, kMaxDivisions));
    return static_cast<int>(n);
}

// A face's fine lattice (patches × elements along a side) must stay within kMaxDivisions too.
void check_fine_divisions(double n) {
    if (n > kMaxDivisions)
        throw InputError(fmt::format("the element size (--element-size) is too small for the scene (over {} elements "
                                     "along a face's side)", kMaxDivisions));
}

bool lex_less(const dvec3& a, const dvec3& b) {
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    return a.z < b.z;
}

// Point k of n along segment pq, computed the same whichever way round the segment is given,
// so faces that share an edge and divide it equally get bit-identical points on it.
dvec3 edge_point(dvec3 p, dvec3 q, int k, int n) {
    if (k == 0) return p;
    if (k == n) return q;
    if (lex_less(q, p)) {
        std::swap(p, q);
        k = n - k;
    }
    return p + (q - p) * (double(k) / double(n));
}

// Bilinear lattice over a convex quad: u runs v0→v1, v runs v0→v3.
Lattice quad_lattice(const Polygon& q, int nu, int nv) {
    Lattice g(nu, nv);
    for (int j = 0; j <= nv; ++j) {
        for (int i = 0; i <= nu; ++i) {
            if (j == 0) {
                g.at(i, j) = edge_point(q.v[0], q.v[1], i, nu);
            } else if (j == nv) {
                g.at(i, j) = edge_point(q.v[3], q.v[2], i, nu);
            } else if (i == 0) {
                g.at(i, j) = edge_point(q.v[0], q.v[3], j, nv);
            } else if (i == nu) {
                g.at(i, j) = edge_point(q.v[1], q.v[2], j, nv);
            } else {
                const double u = double(i) / double(nu), v = double(j) / double(nv);
                g.at(i, j) =
                    (1.0 - u) * (1.0 - v) * q.v[0] + u * (1.0 - v) * q.v[1] + u * v * q.v[2] + (1.0 - u) * v * q.v[3];
            }
        }
    }
    return g;
}

// Barycentric lattice over a triangle a, b, c: i runs along a→b, j along a→c, i + j <= n.
Lattice triangle_lattice(const Polygon& t, int n) {
    Lattice g(n, n);
    for (int j = 0; j <= n; ++j) {
        for (int i = 0; i + j <= n; ++i) {
            if (j == 0) {
                g.at(i, j) = edge_point(t.v[0], t.v[1], i, n);
            } else if (i == 0) {
                g.at(i, j) = edge_point(t.v[0], t.v[2], j, n);
            } else if (i + j == n) {
                g.at(i, j) = edge_point(t.v[1], t.v[2], j, n);
            } else {
                const double wb = double(i) / double(n), wc = double(j) / double(n);
                g.at(i, j) = double(n - i - j) / double(n) * t.v[0] + wb * t.v[1] + wc * t.v[2];
            }
        }
    }
    return g;
}

Polygon make_polygon(std::initializer_list<dvec3> corners) {
    Polygon poly;
    poly.n = 0;
    for (const dvec3& c : corners) poly.v[std::size_t(poly.n++)] = c;
    return poly;
}

// How a face is gridded. A quad: nu × nv bilinear patches, each cut into mu × mv elements, the
// counts from its longer opposite sides (in a bilinear quad every row of cells is a straight
// segment, longest at an end, so the largest step is that side over the count). A needle, whose
// shortest side needs at most half the patch divisions of its longest, likewise as the quad
// (B, C, A, A) collapsed at the corner A opposite its shortest side BC: strips across it, where n²
// congruent cells would be n² slivers as thin as the needle (a 1:100 fan of 200 needles made
// 25,590 patches). Any other triangle: n² congruent cells (nu = n) of m² elements (mu = m), n
// from its longest side, paired into n(n + 1)/2 patches. Counts are doubles, so that counting
// never overflows.
struct Grid {
    bool quad_like = false;
    Polygon poly;
    double nu = 1.0, nv = 1.0, mu = 1.0, mv = 1.0;

    // A triangle's n² cells pair up into parallelograms, with the n cells along its third side
    // left over (face_cells).
    double patches() const { return quad_like ? nu * nv : nu * (nu + 1.0) / 2.0; }
    double elements() const { return quad_like ? nu * nv * mu * mv : nu * nu * mu * mu; }
};

Grid bilinear_grid(const Polygon& q, const Settings& s) {
    Grid g;
    g.quad_like = true;
    g.poly = q;
    const double u_side = std::max(glm::length(q.v[1] - q.v[0]), glm::length(q.v[2] - q.v[3]));
    const double v_side = std::max(glm::length(q.v[3] - q.v[0]), glm::length(q.v[2] - q.v[1]));
    g.nu = divisions_needed(u_side, s.patch_size);
    g.nv = divisions_needed(v_side, s.patch_size);
    g.mu = divisions_needed(u_side / g.nu, s.element_size);
    g.mv = divisions_needed(v_side / g.nv, s.element_size);
    return g;
}

Grid grid_of(const Polygon& face, const Settings& s) {
    if (face.n == 4) return bilinear_grid(face, s);
    const auto side = [&](int k) { return glm::length(face.v[std::size_t((k + 1) % 3)] - face.v[std::size_t(k)]); };
    int shortest = 0;
    for (int k = 1; k < 3; ++k)
        if (side(k) < side(shortest)) shortest = k;
    const double longest = std::max({side(0), side(1), side(2)});
    const double n = divisions_needed(longest, s.patch_size);
    if (2.0 * divisions_needed(side(shortest), s.patch_size) <= n) {
        const dvec3& a = face.v[std::size_t((shortest + 2) % 3)];
        return bilinear_grid(make_polygon({face.v[std::size_t(shortest)], face.v[std::size_t((shortest + 1) % 3)], a, a}), s);
    }
    Grid g;
    g.poly = face;
    g.nu = n;
    g.mu = divisions_needed(longest / n, s.element_size);
    return g;
}

// Cells of a quad-like grid: nu × nv patches, each cut into mu × mv elements on one fine
// lattice. The element counts are the largest any patch needs, the same for all patches of the
// face, so elements of neighbouring patches meet vertex to vertex (no T-junctions) even on a
// trapezoid.
std::vector<PatchCells> quad_cells(const Grid& grid) {
    const Polygon& q = grid.poly;
    const int nu = divisions(grid.nu), nv = divisions(grid.nv), mu = divisions(grid.mu), mv = divisions(grid.mv);
    check_fine_divisions(double(nu) * mu);
    check_fine_divisions(double(nv) * mv);

    const Lattice g = quad_lattice(q, nu * mu, nv * mv);
    auto cell = [&g](int i0, int j0, int i1, int j1) {
        return make_polygon({g.at(i0, j0), g.at(i1, j0), g.at(i1, j1), g.at(i0, j1)});
    };
    std::vector<PatchCells> cells;
    for (int pj = 0; pj < nv; ++pj) {
        for (int pi = 0; pi < nu; ++pi) {
            PatchCells pc;
            pc.poly = cell(pi * mu, pj * mv, (pi + 1) * mu, (pj + 1) * mv);
            for (int b = 0; b < mv; ++b)
                for (int a = 0; a < mu; ++a) {
                    const int i = pi * mu + a, j = pj * mv + b;
                    pc.elements.push_back(cell(i, j, i + 1, j + 1));
                }
            cells.push_back(std::move(pc));
        }
    }
    return cells;
}

// Lattice coordinates (i, j) of a triangle lattice.
struct Node2 {
    int i, j;
};

// The standard n² subdivision of the lattice triangle A, B, C (CCW, each side k·n lattice
// steps long): upward triangles, and downward ones between them, row by row.
void subdivide_triangle(const Lattice& g, Node2 A, Node2 B, Node2 C, int n, std::vector<Polygon>& out) {
    const int bu_i = (B.i - A.i) / n, bu_j = (B.j - A.j) / n;  // one local step along A→B
    const int cv_i = (C.i - A.i) / n, cv_j = (C.j - A.j) / n;  // one local step along A→C
    auto at = [&](int a, int b) -> const dvec3& { return g.at(A.i + a * bu_i + b * cv_i, A.j + a * bu_j + b * cv_j); };
    for (int b = 0; b < n; ++b) {
        for (int a = 0; a + b < n; ++a) {
            out.push_back(make_polygon({at(a, b), at(a + 1, b), at(a, b + 1)}));
            if (a + b < n - 1) out.push_back(make_polygon({at(a + 1, b), at(a + 1, b + 1), at(a, b + 1)}));
        }
    }
}

// The polygon without a corner equal to the one before it: a quad with two equal corners is the
// triangle of the other three.
Polygon without_repeated_corner(const Polygon& poly) {
    for (int k = 0; k < poly.n; ++k) {
        if (poly.v[std::size_t(k)] != poly.v[std::size_t((k + 1) % poly.n)]) continue;
        Polygon out;
        out.n = 0;
        for (int i = 0; i < poly.n; ++i)
            if (i != k) out.v[std::size_t(out.n++)] = poly.v[std::size_t(i)];
        return out;
    }
    return poly;
}

// Cells of a face by its grid. A needle's quad is collapsed at its apex: the cells there are
// triangles. A triangle's n² congruent cells are each cut into m² congruent elements, all taken
// from one fine lattice of n·m divisions, and pair up into patches.
std::vector<PatchCells> face_cells(const Grid& grid) {
    if (grid.quad_like) {
        std::vector<PatchCells> cells = quad_cells(grid);
        if (grid.poly.v[2] == grid.poly.v[3]) {
            for (PatchCells& pc : cells) {
                pc.poly = without_repeated_corner(pc.poly);
                for (Polygon& e : pc.elements) e = without_repeated_corner(e);
            }
        }
        return cells;
    }
    const int n = divisions(grid.nu), m = divisions(grid.mu);
    check_fine_divisions(double(n) * m);

    const Lattice g = triangle_lattice(grid.poly, n * m);
    std::vector<PatchCells> cells;
    const auto at = [&g](Node2 A) -> const dvec3& { return g.at(A.i, A.j); };
    for (int b = 0; b < n; ++b) {
        for (int a = 0; a + b < n; ++a) {
            // The upward cell and the downward one beside it make a parallelogram patch: half as
            // many shooters as cells, each no longer along a side than a cell. The last upward cell
            // of a row, on the triangle's third side, stays a triangle.
            const Node2 A{a * m, b * m}, B{(a + 1) * m, b * m}, C{a * m, (b + 1) * m}, D{(a + 1) * m, (b + 1) * m};
            PatchCells pc;
            subdivide_triangle(g, A, B, C, m, pc.elements);
            if (a + b < n - 1) {
                pc.poly = make_polygon({at(A), at(B), at(D), at(C)});
                subdivide_triangle(g, B, D, C, m, pc.elements);
            } else {
                pc.poly = make_polygon({at(A), at(B), at(C)});
            }
            cells.push_back(std::move(pc));
        }
    }
    return cells;
}

Polygon reversed(const Polygon& poly) {
    Polygon r = poly;
    for (int k = 1; k < poly.n; ++k) r.v[std::size_t(k)] = poly.v[std::size_t(poly.n - k)];
    return r;
}

// One piece of a patch: a cell of a face's grid and the face it lies in.
struct Part {
    const Face* face;
    const PatchCells* cells;
};

// How far a cluster's shooting point must rise along its mean normal, from its area centroid, to
// stand in front of the plane through `point` with unit normal `plane` (Patch): the cluster's
// lift is the largest of these over its elements' planes, and no less than 0.
double plane_lift(const dvec3& point, const dvec3& plane, const dvec3& centroid, const dvec3& normal) {
    return glm::dot(point - centroid, plane) / glm::dot(normal, plane);
}

// One element before its side is chosen: its polygon (front winding), shape, source triangles
// and attributes.
struct Piece {
    Polygon poly;
    Shape shape;
    std::array<std::uint32_t, 2> source{kNoSource, kNoSource};
    dvec3 rho{0.0}, emission{0.0};
};

// The elements of a patch's parts. Untextured: each cell element, its reflectance interpolated
// at its centroid. Textured: averaged over the element; where an emissive texture or a MASK
// cutoff changes across an element it splits (up to kTextureLevels times), and MASK holes are
// left out. `whole` tells whether the pieces still tile the parts' cells (no hole).
std::vector<Piece> pieces_of(const std::vector<Part>& parts, const scene::Scene& scene, const Texturing& texturing,
                             Mesh& mesh, bool& whole) {
    std::vector<Piece> pieces;
    whole = true;
    for (const Part& part : parts) {
        const scene::Triangle& a = *part.face->src[0];
        const scene::Triangle* b = part.face->src[1];
        const std::array<std::uint32_t, 2> source{
            std::uint32_t(&a - scene.triangles.data()),
            b ? std::uint32_t(b - scene.triangles.data()) : kNoSource};
        const auto add = [&](const Polygon& poly, const SurfaceAverage* avg) {
            Piece piece{poly, shape_of(poly), source};
            const dvec3 vertex_rho = vertex_rho_at(a, b, piece.shape.centroid);
            if (!avg) {
                piece.rho = vertex_rho;
                piece.emission = scene.materials[a.material].emission;
            } else {
                piece.rho = texturing.rho(vertex_rho, *avg);
                piece.emission = texturing.emission(a.material, *avg);
            }
            pieces.push_back(piece);
        };
        if (!texturing.samples(a.material)) {
            for (const Polygon& poly : part.cells->elements) add(poly, nullptr);
            continue;
        }
        // Depth-first, so a split element's children stay together in order.
        const auto visit = [&](const auto& self, const Polygon& poly, const SurfaceAverage& avg, int depth) -> void {
            if (depth < kTextureLevels && texturing.may_split(a.material, avg)) {
                const std::array<Polygon, 4> child = split_polygon(poly);
                std::array<SurfaceAverage, 4> child_avg;
                for (std::size_t c = 0; c < 4; ++c) child_avg[c] = texturing.average(child[c], a, b);
                if (texturing.should_split(a.material, avg, child_avg)) {
                    ++mesh.texture_splits;
                    for (std::size_t c = 0; c < 4; ++c) self(self, child[c], child_avg[c], depth + 1);
                    return;
                }
            }
            if (avg.coverage < kMinCoverage) {
                ++mesh.holes;
                whole = false;
                return;
            }
            add(poly, &avg);
        };
        for (const Polygon& poly : part.cells->elements) visit(visit, poly, texturing.average(poly, a, b), 0);
    }
    return pieces;
}

// Appends one patch of one side, followed by its contiguous elements: a cell of a face's grid
// (one part, all of its elements), or a cluster of small faces or a cell with holes (poly.n = 0).
// `from`, where set, is the point a cluster shoots from instead (see split_blocked_clusters).
// `cell`, where set, is the patch's polygon instead of its part's cell: an element made a patch
// of its own (split_emitter).
void append_patch(Mesh& mesh, const std::vector<Part>& parts, const std::vector<Piece>& pieces, bool whole,
                  const scene::Material& mat, bool back, const std::optional<dvec3>& from,
                  const Polygon* cell = nullptr, bool apart = false) {
    const std::size_t count = pieces.size();
    if (mesh.patches.size() >= std::numeric_limits<std::uint32_t>::max() ||
        mesh.elements.size() + count >= std::numeric_limits<std::uint32_t>::max())
        throw InternalError("mesh: more patches or elements than 32-bit indices can hold");
    Patch patch;
    const scene::Triangle& t0 = *parts.front().face->src[0];
    patch.node = t0.node;
    patch.first_element = static_cast<std::uint32_t>(mesh.elements.size());
    patch.element_count = static_cast<std::uint32_t>(count);
    const auto patch_index = static_cast<std::uint32_t>(mesh.patches.size());

    dvec3 emitted{0.0}, weighted_normal{0.0}, weighted_centroid{0.0};
    double area = 0.0;
    for (const Piece& piece : pieces) {
        Element e;
        const Shape& es = piece.shape;
        e.poly = back ? reversed(piece.poly) : piece.poly;
        e.normal = back ? -es.normal : es.normal;
        e.centroid = es.centroid;
        e.area = es.area;
        e.rho = piece.rho;
        e.emission = piece.emission;
        e.patch = patch_index;
        e.node = t0.node;
        e.material = t0.material;
        e.has_twin = mat.double_sided;
        e.back = back;
        e.coarse = mat.coarse;
        e.source = piece.source;
        emitted += e.area * e.emission;
        weighted_normal += e.area * e.normal;
        weighted_centroid += e.area * e.centroid;
        area += e.area;
        mesh.elements.push_back(e);
    }
    if (cell || (parts.size() == 1 && whole)) {
        const Polygon& poly = cell ? *cell : parts.front().cells->poly;
        const Shape ps = shape_of(poly);
        patch.poly = back ? reversed(poly) : poly;
        patch.normal = back ? -ps.normal : ps.normal;
        patch.centroid = ps.centroid;
        patch.area = ps.area;
    } else {
        // It shoots from its area centroid, raised along its mean normal until it is in front of
        // every one of its elements' planes: on a convex surface the centroid lies behind the
        // surface, where the backs of neighbouring faces (a doubleSided mesh's inside) face it,
        // and light leaked into closed objects. On a concave one it stays where it is.
        patch.poly.n = 0;
        patch.normal = glm::normalize(weighted_normal);
        const dvec3 centroid = weighted_centroid / area;
        double lift = 0.0;
        for (std::uint32_t k = patch.first_element; k < patch.first_element + patch.element_count; ++k) {
            const Element& e = mesh.elements[k];
            lift = std::max(lift, plane_lift(e.centroid, e.normal, centroid, patch.normal));
        }
        patch.centroid = from ? *from : centroid + lift * patch.normal;
        patch.area = area;
        patch.apart = apart;
        ++mesh.clusters;
    }
    patch.emission = emitted / area;
    mesh.patches.push_back(patch);
}

// A patch shoots all of its elements' light from one point, so one that an emissive texture's
// edge crosses would send its lit part's light from its middle (the floor under a half-lit lamp
// got it 4% off). Its elements' emissions differ when, in some channel, the dimmest falls short
// of the brightest by more than this share of the brightest channel's.
constexpr double kShooterContrast = 0.02;

bool uneven_emission(const std::vector<Piece>& pieces) {
    if (pieces.size() < 2) return false;
    dvec3 lo = pieces.front().emission, hi = lo;
    for (const Piece& piece : pieces) {
        lo = glm::min(lo, piece.emission);
        hi = glm::max(hi, piece.emission);
    }
    const double top = std::max({hi.x, hi.y, hi.z});
    const dvec3 spread = hi - lo;
    return top > 0.0 && std::max({spread.x, spread.y, spread.z}) > kShooterContrast * top;
}

// How many patches splitting emitters may still add (kMaxEmissionShooters).
struct EmitterBudget {
    double left = 0.0;
};

// One patch to append: its parts, its elements, and (an element of a split emitter) its own cell.
struct Shooting {
    std::size_t part = 0;
    std::vector<Piece> pieces;
    bool whole = true;
    std::optional<Polygon> cell;
};

// The back sides of a doubleSided face's patches (or a cluster's one patch), kept by append_sides
// for append_backs. `cells` owns what `patches`' parts point to.
struct BackSides {
    std::vector<std::vector<PatchCells>> cells;
    std::vector<std::vector<Part>> patches;
    std::vector<Shooting> shooting;
    const scene::Material* material = nullptr;
    std::optional<std::array<dvec3, 2>> from;
    bool apart = false;
    std::size_t front = 0;  // the first of the front patches
};

// Appends one side (`back`) of a face's shooting patches, from `from`'s point for that side.
void append_side(Mesh& mesh, const std::vector<std::vector<Part>>& patches, const std::vector<Shooting>& shooting,
                 const scene::Material& mat, const std::optional<std::array<dvec3, 2>>& from, bool apart, bool back) {
    for (const Shooting& sh : shooting) {
        const Polygon* cell = sh.cell ? &*sh.cell : nullptr;
        const std::optional<dvec3> point =
            from && !cell ? std::optional<dvec3>((*from)[back ? 1 : 0]) : std::nullopt;
        append_patch(mesh, patches[sh.part], sh.pieces, sh.whole, mat, back, point, cell, apart && !cell);
    }
}

// Appends a face's patches (or a cluster's one patch) on its front and, for a doubleSided
// material, keeps what its back needs in `backs` (append_backs appends every back after every
// front). A patch all of whose elements are MASK holes is left out on both sides. A patch whose
// elements' emissions differ (uneven_emission) is appended as one patch per element, each
// shooting its own light from its own centroid, while `budget` lasts. `cells` owns the
// PatchCells that `patches`' parts point to, and is kept with the back.
void append_sides(Mesh& mesh, std::vector<std::vector<PatchCells>> cells, std::vector<std::vector<Part>> patches,
                  const scene::Scene& scene, const Texturing& texturing, EmitterBudget& budget,
                  std::vector<BackSides>& backs, const std::optional<std::array<dvec3, 2>>& from = std::nullopt,
                  bool apart = false) {
    const scene::Material& mat = scene.materials[patches.front().front().face->src[0]->material];
    const double sides = mat.double_sided ? 2.0 : 1.0;
    std::vector<Shooting> shooting;
    for (std::size_t i = 0; i < patches.size(); ++i) {
        bool w = true;
        std::vector<Piece> pieces = pieces_of(patches[i], scene, texturing, mesh, w);
        if (pieces.empty()) continue;
        if (uneven_emission(pieces)) {
            const double added = sides * double(pieces.size() - 1);
            if (added <= budget.left) {
                budget.left -= added;
                mesh.emission_splits += std::size_t(sides);
                for (Piece& piece : pieces) {
                    const Polygon cell = piece.poly;
                    shooting.push_back({i, {std::move(piece)}, true, cell});
                }
                continue;
            }
            mesh.emission_unsplit += std::size_t(sides);
        }
        shooting.push_back({i, std::move(pieces), w, std::nullopt});
    }
    const std::size_t front = mesh.patches.size();
    append_side(mesh, patches, shooting, mat, from, apart, false);
    if (!mat.double_sided || shooting.empty()) return;
    backs.push_back({std::move(cells), std::move(patches), std::move(shooting), &mat, from, apart, front});
}

// Appends the back sides append_sides kept, in order, each side's patches the other's twins. The
// mesh holds every front before every back, so that setup's lane groups (HR_SETUP_LANES elements
// in mesh order) mostly hold one side: from any point one side faces away and is its twin's to
// draw, and a group of such lanes is dropped whole (with a face's back beside its front they were
// mixed into the groups: 48% of the lanes the fantasy inn's gather set up).
void append_backs(Mesh& mesh, const std::vector<BackSides>& backs) {
    for (const BackSides& b : backs) {
        const std::size_t back = mesh.patches.size();
        append_side(mesh, b.patches, b.shooting, *b.material, b.from, b.apart, true);
        for (std::size_t i = 0; i < b.shooting.size(); ++i) {
            mesh.patches[b.front + i].twin = static_cast<std::uint32_t>(back + i);
            mesh.patches[back + i].twin = static_cast<std::uint32_t>(b.front + i);
        }
    }
}

// Clusters of faces that fit in one patch: each grows from its first face (in face order) across
// shared edges to faces of the same material and node whose normals are within kClusterCos of
// the first's and whose corners lie within half a patch diagonal of its centroid. Returns each
// face's cluster (−1 for a face of several patches) and the clusters' faces, in the order they
// joined. Faces meet along an edge when they share its two corners exactly, as glTF exports
// share vertex positions across seams.
struct Clusters {
    std::vector<std::int64_t> of;
    std::vector<std::vector<std::size_t>> faces;
    std::vector<std::int64_t> from;  // per cluster: the face from whose centroid it shoots, or −1
    std::vector<char> apart;         // per cluster: whether it took clusters apart from it (join_clusters_apart)
    std::vector<std::array<dvec3, 2>> points;  // per cluster that did: where its front and back shoot from
    // Per side, as Mesh::clusters: halvings of curved clusters and flat ones that shoot from a
    // face's centroid instead (split_blocked_clusters).
    std::size_t split = 0, moved = 0;
};

Clusters cluster_faces(const std::vector<Face>& faces, const std::vector<Grid>& grids, const Settings& settings,
                       const std::vector<char>& coarse) {
    Clusters c;
    c.of.assign(faces.size(), -1);
    std::vector<bool> small(faces.size());
    for (std::size_t f = 0; f < faces.size(); ++f) small[f] = !coarse[f] && grids[f].patches() == 1.0;

    struct Edge {
        std::uint32_t material, node;
        std::array<double, 6> ab;  // corners, lexicographically smaller first
        bool operator==(const Edge& o) const { return material == o.material && node == o.node && ab == o.ab; }
    };
    struct EdgeHash {
        std::size_t operator()(const Edge& e) const {
            std::uint64_t h = 1469598103934665603ull ^ (std::uint64_t(e.material) << 32 | e.node);
            for (const double d : e.ab) {
                std::uint64_t bits;
                std::memcpy(&bits, &d, sizeof bits);
                h = (h ^ bits) * 1099511628211ull;
                h ^= h >> 29;
            }
            return static_cast<std::size_t>(h);
        }
    };
    const auto edge_of = [&faces](std::size_t f, int k) {
        const Face& face = faces[f];
        dvec3 a = face.poly.v[std::size_t(k)], b = face.poly.v[std::size_t((k + 1) % face.poly.n)];
        if (lex_less(b, a)) std::swap(a, b);
        return Edge{face.src[0]->material, face.src[0]->node, {a.x, a.y, a.z, b.x, b.y, b.z}};
    };
    std::unordered_map<Edge, std::vector<std::size_t>, EdgeHash> edges;
    if (settings.cluster)
        for (std::size_t f = 0; f < faces.size(); ++f)
            if (small[f])
                for (int k = 0; k < faces[f].poly.n; ++k) edges[edge_of(f, k)].push_back(f);

    const double radius = settings.patch_size * std::sqrt(0.5);
    for (std::size_t seed = 0; seed < faces.size(); ++seed) {
        if (!small[seed] || c.of[seed] >= 0) continue;
        const auto id = static_cast<std::int64_t>(c.faces.size());
        std::vector<std::size_t> members{seed};
        c.of[seed] = id;
        const Shape first = shape_of(faces[seed].poly);
        const auto fits = [&](std::size_t g) {
            if (glm::dot(shape_of(faces[g].poly).normal, first.normal) < kClusterCos) return false;
            for (int k = 0; k < faces[g].poly.n; ++k)
                if (glm::length(faces[g].poly.v[std::size_t(k)] - first.centroid) > radius) return false;
            return true;
        };
        for (std::size_t next = 0; settings.cluster && next < members.size(); ++next) {
            const std::size_t f = members[next];
            for (int k = 0; k < faces[f].poly.n; ++k) {
                const auto it = edges.find(edge_of(f, k));
                if (it == edges.end()) continue;
                for (const std::size_t g : it->second) {
                    if (c.of[g] >= 0 || !fits(g)) continue;
                    c.of[g] = id;
                    members.push_back(g);
                }
            }
        }
        c.faces.push_back(std::move(members));
    }
    c.from.assign(c.faces.size(), -1);
    c.apart.assign(c.faces.size(), 0);
    c.points.resize(c.faces.size());
    return c;
}

// Faces in a bounding volume hierarchy, for segment queries: boxes cut at the median of their
// faces' centroids across their longest side, down to a few faces a leaf. A query visits the boxes
// the segment crosses, about log n of them wherever the faces crowd. (A uniform grid of at most
// 2^7 cells across the scene, which this replaced, held thousands of small faces a cell on a
// 682k-triangle classroom of 1,592 props: 159 s of queries.)
class FaceBvh {
public:
    // Each face's box is widened by `pad` on every side, so that a segment that touches a face at
    // its edge is tested against it.
    FaceBvh(const std::vector<Face>& faces, double pad) : order_(faces.size()), lo_(faces.size()), hi_(faces.size()) {
        std::vector<dvec3> centre(faces.size());
        for (std::size_t f = 0; f < faces.size(); ++f) {
            const Polygon& poly = faces[f].poly;
            dvec3 lo = poly.v[0], hi = poly.v[0];
            for (int k = 1; k < poly.n; ++k) {
                lo = glm::min(lo, poly.v[std::size_t(k)]);
                hi = glm::max(hi, poly.v[std::size_t(k)]);
            }
            lo_[f] = lo - pad;
            hi_[f] = hi + pad;
            centre[f] = 0.5 * (lo + hi);
            order_[f] = static_cast<std::uint32_t>(f);
        }
        if (faces.empty()) return;
        nodes_.reserve(2 * faces.size() / kLeafFaces + 2);
        nodes_.push_back({});
        build(0, 0, order_.size(), centre);
    }

    // Calls hit(f) for faces whose boxes the segment a→b crosses until it returns true; returns
    // whether one did.
    template <class Hit>
    bool any(const dvec3& a, const dvec3& b, Hit hit) const {
        if (nodes_.empty()) return false;
        const dvec3 d = b - a;
        std::vector<std::uint32_t> stack{0};
        while (!stack.empty()) {
            const Node& node = nodes_[stack.back()];
            stack.pop_back();
            if (!crosses(node.lo, node.hi, a, d)) continue;
            if (node.count > 0) {
                for (std::uint32_t i = node.first; i < node.first + node.count; ++i)
                    if (crosses(lo_[order_[i]], hi_[order_[i]], a, d) && hit(order_[i])) return true;
            } else {
                stack.push_back(node.first);
                stack.push_back(node.first + 1);
            }
        }
        return false;
    }

private:
    static constexpr std::size_t kLeafFaces = 4;
    // A leaf (count > 0) holds order_[first, first + count); an inner node's children are
    // nodes_[first] and nodes_[first + 1].
    struct Node {
        dvec3 lo{0.0}, hi{0.0};
        std::uint32_t first = 0, count = 0;
    };

    // Whether the segment a + t d, t in [0, 1], meets the box [lo, hi] (faces included).
    static bool crosses(const dvec3& lo, const dvec3& hi, const dvec3& a, const dvec3& d) {
        double t0 = 0.0, t1 = 1.0;
        for (int k = 0; k < 3; ++k) {
            if (d[k] == 0.0) {
                if (a[k] < lo[k] || a[k] > hi[k]) return false;
                continue;
            }
            double u = (lo[k] - a[k]) / d[k], v = (hi[k] - a[k]) / d[k];
            if (u > v) std::swap(u, v);
            t0 = std::max(t0, u);
            t1 = std::min(t1, v);
            if (t0 > t1) return false;
        }
        return true;
    }

    // Makes nodes_[index] the node of order_[first, last); the cut is by centroid, ties by face
    // index, so the tree is the same on every run.
    void build(std::size_t index, std::size_t first, std::size_t last, const std::vector<dvec3>& centre) {
        dvec3 lo = lo_[order_[first]], hi = hi_[order_[first]], clo = centre[order_[first]], chi = clo;
        for (std::size_t i = first + 1; i < last; ++i) {
            lo = glm::min(lo, lo_[order_[i]]);
            hi = glm::max(hi, hi_[order_[i]]);
            clo = glm::min(clo, centre[order_[i]]);
            chi = glm::max(chi, centre[order_[i]]);
        }
        nodes_[index].lo = lo;
        nodes_[index].hi = hi;
        const dvec3 extent = chi - clo;
        if (last - first <= kLeafFaces || (extent.x <= 0.0 && extent.y <= 0.0 && extent.z <= 0.0)) {
            nodes_[index].first = static_cast<std::uint32_t>(first);
            nodes_[index].count = static_cast<std::uint32_t>(last - first);
            return;
        }
        const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : (extent.y >= extent.z ? 1 : 2);
        const std::size_t middle = first + (last - first) / 2;
        std::nth_element(order_.begin() + std::ptrdiff_t(first), order_.begin() + std::ptrdiff_t(middle),
                         order_.begin() + std::ptrdiff_t(last), [&](std::uint32_t x, std::uint32_t y) {
                             const double cx = centre[x][axis], cy = centre[y][axis];
                             return cx < cy || (cx == cy && x < y);
                         });
        const std::size_t left = nodes_.size();
        nodes_[index].first = static_cast<std::uint32_t>(left);
        nodes_.push_back({});
        nodes_.push_back({});
        build(left, first, middle, centre);
        build(left + 1, middle, last, centre);
    }

    std::vector<std::uint32_t> order_;
    std::vector<dvec3> lo_, hi_;
    std::vector<Node> nodes_;
};

// Whether segment a→b meets triangle (p, q, r), edges and far end included, its start excluded;
// a segment parallel to the triangle's plane does not meet it (Möller and Trumbore 1997).
bool segment_meets(const dvec3& a, const dvec3& b, const dvec3& p, const dvec3& q, const dvec3& r) {
    const dvec3 d = b - a, e1 = q - p, e2 = r - p;
    const dvec3 h = glm::cross(d, e2);
    const double det = glm::dot(e1, h);
    if (std::abs(det) <= 1e-12 * glm::length(d) * glm::length(e1) * glm::length(e2)) return false;
    const dvec3 s = a - p;
    const double u = glm::dot(s, h) / det;
    if (u < 0.0 || u > 1.0) return false;
    const dvec3 qv = glm::cross(s, e1);
    const double v = glm::dot(d, qv) / det;
    if (v < 0.0 || u + v > 1.0) return false;
    const double t = glm::dot(e2, qv) / det;
    return t > 1e-9 && t <= 1.0;
}

bool segment_meets(const dvec3& a, const dvec3& b, const Polygon& poly) {
    for (int k = 1; k + 1 < poly.n; ++k)
        if (segment_meets(a, b, poly.v[0], poly.v[std::size_t(k)], poly.v[std::size_t(k + 1)])) return true;
    return false;
}

// Cuts a cluster's faces (with their shapes) in two across the longest side of the box of their
// centroids, at the median: `members` keeps the lower half, the upper one is returned. Both keep
// the faces' order, and ties go by that order, so the cut is the same on every run.
std::vector<std::size_t> halve(std::vector<std::size_t>& members, const std::vector<const Shape*>& shapes) {
    dvec3 lo = shapes.front()->centroid, hi = lo;
    for (const Shape* sh : shapes) {
        lo = glm::min(lo, sh->centroid);
        hi = glm::max(hi, sh->centroid);
    }
    const dvec3 extent = hi - lo;
    const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : (extent.y >= extent.z ? 1 : 2);
    std::vector<std::size_t> rank(members.size());
    for (std::size_t i = 0; i < rank.size(); ++i) rank[i] = i;
    std::stable_sort(rank.begin(), rank.end(),
                     [&](std::size_t a, std::size_t b) { return shapes[a]->centroid[axis] < shapes[b]->centroid[axis]; });
    std::vector<bool> upper(members.size(), false);
    for (std::size_t i = members.size() / 2; i < rank.size(); ++i) upper[rank[i]] = true;
    std::vector<std::size_t> lower_half, upper_half;
    for (std::size_t i = 0; i < members.size(); ++i) (upper[i] ? upper_half : lower_half).push_back(members[i]);
    members = std::move(lower_half);
    return upper_half;
}

// The mean plane of a cluster's faces: area centroid, unit mean normal (front side).
struct Aim {
    dvec3 centroid{0.0}, normal{0.0};
};
Aim aim_of(const std::vector<const Shape*>& shapes) {
    dvec3 weighted_normal{0.0}, weighted_centroid{0.0};
    double area = 0.0;
    for (const Shape* sh : shapes) {
        weighted_normal += sh->area * sh->normal;
        weighted_centroid += sh->area * sh->centroid;
        area += sh->area;
    }
    return {weighted_centroid / area, glm::normalize(weighted_normal)};
}

// Where a cluster shoots from on one side (+1 front, −1 back, Patch): its area centroid raised
// along its mean normal until it is in front of every face's plane (a back side's planes and mean
// normal are the front's reversed).
dvec3 shooting_point(const std::vector<const Shape*>& shapes, const Aim& aim, double side) {
    double lift = 0.0;
    for (const Shape* sh : shapes)
        lift = std::max(lift, plane_lift(sh->centroid, side * sh->normal, aim.centroid, side * aim.normal));
    return aim.centroid + side * lift * aim.normal;
}

// Whether a cluster's faces see its shooting point: the segments from faces' centroids to the
// point, both ends moved a margin (far above the engines' clip distance) along the side's normal,
// so that faces meeting the cluster's plane at an edge or in contact with it do not count.
class Clearance {
public:
    explicit Clearance(const std::vector<Face>& faces) : faces_(faces) {
        dvec3 lo{std::numeric_limits<double>::max()}, hi{-std::numeric_limits<double>::max()};
        for (const Face& face : faces)
            for (int k = 0; k < face.poly.n; ++k) {
                lo = glm::min(lo, face.poly.v[std::size_t(k)]);
                hi = glm::max(hi, face.poly.v[std::size_t(k)]);
            }
        const double extent = std::max({std::abs(lo.x), std::abs(lo.y), std::abs(lo.z), std::abs(hi.x),
                                        std::abs(hi.y), std::abs(hi.z), 1e-30});
        margin_ = 1e-6 * extent;
        bvh_ = std::make_unique<FaceBvh>(faces, 1e-9 * extent);
    }
    double margin() const { return margin_; }
    // Whether the segment from `from` to `point`, both moved along `normal` by the margin, meets
    // a face f for which other(f) holds.
    template <class Other>
    bool blocked(const dvec3& from, const dvec3& point, const dvec3& normal, Other other) const {
        const dvec3 off = margin_ * normal, a = from + off, b = point + off;
        return bvh_->any(a, b, [&](std::uint32_t f) { return other(f) && segment_meets(a, b, faces_[f].poly); });
    }

private:
    const std::vector<Face>& faces_;
    double margin_ = 0.0;
    std::unique_ptr<FaceBvh> bvh_;
};

// The index in `shapes` of the one whose centroid is nearest `point` (the first of equals).
std::size_t nearest_to(const std::vector<const Shape*>& shapes, const dvec3& point) {
    std::size_t nearest = 0;
    for (std::size_t i = 1; i < shapes.size(); ++i)
        if (glm::length(shapes[i]->centroid - point) < glm::length(shapes[nearest]->centroid - point)) nearest = i;
    return nearest;
}

// A cluster shoots from one point (Patch): its area centroid raised along its mean normal until
// it is in front of every face's plane. Where that point lies across other geometry (the bottom
// cap of a ball resting on a floor shoots from under the floor, a rock's cap through the terrain
// it sinks into, a wall clustered across a cornice from inside the cornice), its shots would see
// the outside of the scene, another room or the inside of a solid. A flat cluster then shoots from
// the centroid of its face nearest the point; a curved one is halved, and each half checked again.
// Checked for each side the material has: the segment from the centroid of the cluster's face
// nearest the point to the point must meet no face outside the cluster (Clearance).
void split_blocked_clusters(const std::vector<Face>& faces, const std::vector<Shape>& shape,
                            const scene::Scene& scene, const Clearance& clearance, Clusters& c) {
    // Settles cluster `id`: returns false when it was halved, so that its first half (which keeps
    // the id) is checked again. The second half gets a new id past the others, checked in its
    // turn, so c.of always tells a cluster's own faces from the rest.
    const auto settle = [&](std::size_t id) {
        std::vector<std::size_t>& members = c.faces[id];
        if (members.size() < 2) return true;
        std::vector<const Shape*> shapes;
        shapes.reserve(members.size());
        for (const std::size_t f : members) shapes.push_back(&shape[f]);
        const Aim aim = aim_of(shapes);
        const bool double_sided = scene.materials[faces[members.front()].src[0]->material].double_sided;
        bool flat = true;  // every face in the mean plane
        for (const Shape* sh : shapes)
            flat = flat && glm::dot(sh->normal, aim.normal) > kCoplanarDot &&
                   std::abs(glm::dot(sh->centroid - aim.centroid, aim.normal)) <= clearance.margin();
        bool blocked = false;
        std::size_t nearest = 0;  // of the point, on the side found blocked
        for (const double side : {1.0, -1.0}) {
            if (side < 0.0 && !double_sided) break;
            const dvec3 point = shooting_point(shapes, aim, side);
            nearest = nearest_to(shapes, point);
            blocked = clearance.blocked(shapes[nearest]->centroid, point, side * aim.normal,
                                        [&](std::uint32_t f) { return c.of[f] != std::int64_t(id); });
            if (blocked) break;
        }
        if (!blocked) return true;
        if (flat) {
            // A planar cluster around a hole or a ledge (a wall clustered across a cornice has its
            // centroid inside the cornice): any point of its surface stands for it as well as the
            // centroid does, so it shoots from its face nearest the centroid, on both sides.
            c.from[id] = static_cast<std::int64_t>(members[nearest]);
            c.moved += double_sided ? 2 : 1;
            return true;
        }
        // A curved one is cut in two across its longest extent, at the median face; each half
        // is checked again (and cut again if it is blocked), down to single faces if need be.
        std::vector<std::size_t> second = halve(members, shapes);
        for (const std::size_t f : second) c.of[f] = static_cast<std::int64_t>(c.faces.size());
        c.faces.push_back(std::move(second));  // invalidates members
        c.from.push_back(-1);
        c.apart.push_back(0);
        c.points.emplace_back();
        c.split += double_sided ? 2 : 1;
        return false;
    };
    for (std::size_t id = 0; id < c.faces.size();)
        if (settle(id)) ++id;
}

// At most this many parts join one cluster: each joining checks every part's sight of the point
// again, so a crown of n parts costs n² checks.
constexpr std::size_t kMaxParts = 32;

// Clusters of faces apart (Settings::cluster_apart): each settled cluster, in order, takes in
// whole the later clusters (parts) of its material and node that
// - fit it as its own faces do: every face within kClusterCos of its first face's normal and
//   within half a patch diagonal of that face's centroid;
// - lie next to it: a face within twice the two faces' radii of one of its faces (a crown of
//   leaves, a grille; not two lamps a metre apart);
// - and, joined, still see its point: on each side, the segment from each part's face nearest
//   the point to the point meets no face but the small ones of its own material and node
//   (Clearance; the other leaves of a crown stand between any point and some leaves).
// The joined cluster shoots, on each side, from the area-weighted mean of its parts' own points
// (each raised in front of its own faces' planes only: raised in front of every part's plane, a
// crown's point sat a tilted leaf's height nearer what it lit), moved in front of any of its
// faces that the line along its normal crosses. A part that fails stays as it was, so joining
// never cuts a cluster. Flat clusters that shoot from one of their faces (moved) join nothing.
void join_clusters_apart(const std::vector<Face>& faces, const std::vector<Shape>& shape,
                         const scene::Scene& scene, const Settings& settings, const Clearance& clearance,
                         Clusters& c) {
    const double radius = settings.patch_size * std::sqrt(0.5);
    if (!std::isfinite(radius) || c.faces.empty()) return;
    // Clusters by material, node and cell (side `radius`) of their first face's centroid: the
    // clusters a first face may take lie in the 27 cells around its own.
    struct CellKey {
        std::uint32_t material, node;
        std::int64_t x, y, z;
        bool operator==(const CellKey& o) const {
            return material == o.material && node == o.node && x == o.x && y == o.y && z == o.z;
        }
    };
    struct CellHash {
        std::size_t operator()(const CellKey& k) const {
            std::uint64_t h = 1469598103934665603ull ^ (std::uint64_t(k.material) << 32 | k.node);
            for (const std::int64_t v : {k.x, k.y, k.z}) h = (h ^ std::uint64_t(v)) * 1099511628211ull;
            return static_cast<std::size_t>(h ^ (h >> 29));
        }
    };
    const auto cell_of = [&](std::size_t f) {
        const dvec3& p = shape[f].centroid;
        const auto at = [&](double v) { return static_cast<std::int64_t>(std::floor(v / radius)); };
        return CellKey{faces[f].src[0]->material, faces[f].src[0]->node, at(p.x), at(p.y), at(p.z)};
    };
    std::unordered_map<CellKey, std::vector<std::size_t>, CellHash> cells;
    for (std::size_t id = 0; id < c.faces.size(); ++id)
        if (!c.faces[id].empty() && c.from[id] < 0) cells[cell_of(c.faces[id].front())].push_back(id);

    std::vector<double> reach_of(faces.size(), 0.0);  // per face: centroid to farthest corner
    for (std::size_t f = 0; f < faces.size(); ++f)
        for (int k = 0; k < faces[f].poly.n; ++k)
            reach_of[f] = std::max(reach_of[f], glm::length(faces[f].poly.v[std::size_t(k)] - shape[f].centroid));
    // A part's faces, area and shooting point on each side, as a cluster of its own.
    struct Part {
        std::vector<std::size_t> faces;
        std::vector<const Shape*> shapes;
        double area = 0.0;
        std::array<dvec3, 2> point{};
        // A sphere around its faces' centroids, and the largest of its faces' radii: two parts
        // farther apart than these allow have no faces next to each other.
        dvec3 centre{0.0};
        double radius = 0.0, reach = 0.0;
    };
    const auto part_of = [&](std::size_t id) {
        Part part;
        part.faces = c.faces[id];
        for (const std::size_t f : c.faces[id]) {
            part.shapes.push_back(&shape[f]);
            part.area += shape[f].area;
        }
        const Aim aim = aim_of(part.shapes);
        part.point = {shooting_point(part.shapes, aim, 1.0), shooting_point(part.shapes, aim, -1.0)};
        part.centre = aim.centroid;
        for (std::size_t i = 0; i < part.faces.size(); ++i) {
            part.radius = std::max(part.radius, glm::length(part.shapes[i]->centroid - part.centre));
            part.reach = std::max(part.reach, reach_of[part.faces[i]]);
        }
        return part;
    };
    std::vector<std::int64_t> group(c.faces.size(), -1);  // per cluster: the cluster that took it
    std::vector<std::size_t> near, checked, taken;
    std::vector<Part> parts, candidates;
    std::vector<char> settled;
    for (std::size_t id = 0; id < c.faces.size(); ++id) {
        if (group[id] >= 0 || c.faces[id].empty() || c.from[id] >= 0) continue;
        group[id] = static_cast<std::int64_t>(id);
        const Shape& first = shape[c.faces[id].front()];
        const std::uint32_t material = faces[c.faces[id].front()].src[0]->material;
        const std::uint32_t node = faces[c.faces[id].front()].src[0]->node;
        const bool double_sided = scene.materials[material].double_sided;
        const auto fits = [&](std::size_t f) {
            if (glm::dot(shape[f].normal, first.normal) < kClusterCos) return false;
            for (int k = 0; k < faces[f].poly.n; ++k)
                if (glm::length(faces[f].poly.v[std::size_t(k)] - first.centroid) > radius) return false;
            return true;
        };
        // Faces that may stand between a part and the point: other materials' and nodes', faces
        // of several patches (walls), and one-sided ones (a closed solid's skin: a cloud's lumps,
        // whose insides the point would see); small double-sided faces of its own material and
        // node (the other leaves of a crown) may not, or no crown would ever join.
        const auto blocks = [&](std::uint32_t f) {
            return c.of[f] < 0 || !double_sided || faces[f].src[0]->material != material ||
                   faces[f].src[0]->node != node;
        };
        near.clear();
        const CellKey at = cell_of(c.faces[id].front());
        for (std::int64_t dx = -1; dx <= 1; ++dx)
            for (std::int64_t dy = -1; dy <= 1; ++dy)
                for (std::int64_t dz = -1; dz <= 1; ++dz) {
                    const auto it = cells.find({at.material, at.node, at.x + dx, at.y + dy, at.z + dz});
                    if (it == cells.end()) continue;
                    for (const std::size_t h : it->second)
                        if (h > id && group[h] < 0) near.push_back(h);
                }
        std::sort(near.begin(), near.end());
        near.erase(std::remove_if(near.begin(), near.end(),
                                  [&](std::size_t h) { return !std::all_of(c.faces[h].begin(), c.faces[h].end(), fits); }),
                   near.end());
        parts.assign(1, part_of(id));
        taken.assign(1, id);
        dvec3 weighted_normal{0.0};
        for (const Shape* sh : parts.front().shapes) weighted_normal += sh->area * sh->normal;
        std::array<dvec3, 2> point_sum{parts.front().area * parts.front().point[0],
                                       parts.front().area * parts.front().point[1]};
        double area = parts.front().area;
        std::array<dvec3, 2> point = parts.front().point;
        // The parts' mean point may lie behind a face of one of them (the middle leaf of a row),
        // whose back would then fill the hemicube: moved along `n` in front of every face that
        // the line through it along `n` crosses, and a margin more.
        const auto clear_of_parts = [&](const dvec3& p, const dvec3& n) {
            const double reach = 4.0 * radius;
            double lift = 0.0;
            for (const Part& part : parts)
                for (const std::size_t f : part.faces)
                    if (segment_meets(p - reach * n, p + reach * n, faces[f].poly))
                        lift = std::max(lift, plane_lift(shape[f].centroid,
                                                         glm::dot(shape[f].normal, n) >= 0.0 ? shape[f].normal : -shape[f].normal,
                                                         p, n));
            return p + (lift + clearance.margin()) * n;
        };
        // A part joins only next to the cluster: one of its faces within twice the two faces'
        // radii (centroid to farthest corner) of one of the cluster's, so a crown of leaves or a
        // grille joins while lamps a metre apart on a wall do not (their light would leave from
        // the wall between them). Whether `part` is next to parts [from, end).
        const auto next_to = [&](const Part& part, std::size_t from) {
            for (std::size_t p = from; p < parts.size(); ++p) {
                if (glm::length(part.centre - parts[p].centre) - part.radius - parts[p].radius >
                    2.0 * (part.reach + parts[p].reach))
                    continue;
                for (std::size_t i = 0; i < part.faces.size(); ++i)
                    for (std::size_t j = 0; j < parts[p].faces.size(); ++j)
                        if (glm::length(part.shapes[i]->centroid - parts[p].shapes[j]->centroid) <=
                            2.0 * (reach_of[part.faces[i]] + reach_of[parts[p].faces[j]]))
                            return true;
            }
            return false;
        };
        // Tries the candidate part k, next to the cluster: whether it joined.
        const auto join = [&](std::size_t k) {
            parts.push_back(candidates[k]);
            const Part& added = parts.back();
            dvec3 normal = weighted_normal;
            for (const Shape* sh : added.shapes) normal += sh->area * sh->normal;
            const double joint_area = area + added.area;
            std::array<dvec3, 2> joint{};
            bool clear = true;
            for (std::size_t side = 0; side < 2 && clear; ++side) {
                const dvec3 n = (side == 0 ? 1.0 : -1.0) * glm::normalize(normal);
                joint[side] = clear_of_parts((point_sum[side] + added.area * added.point[side]) / joint_area, n);
                if (side == 1 && !double_sided) break;  // no back patch: its point is never used
                for (std::size_t i = 0; i < parts.size() && clear; ++i) {
                    const Shape& from = *parts[i].shapes[nearest_to(parts[i].shapes, joint[side])];
                    clear = !clearance.blocked(from.centroid, joint[side], n, blocks);
                }
            }
            if (!clear) {
                parts.pop_back();
                return false;
            }
            group[near[k]] = static_cast<std::int64_t>(id);
            taken.push_back(near[k]);
            weighted_normal = normal;
            for (std::size_t side = 0; side < 2; ++side) point_sum[side] += added.area * added.point[side];
            area = joint_area;
            point = joint;
            return true;
        };
        // In order, each candidate once it is next to the cluster; one not yet next to it is
        // checked again, against the parts that joined since, while parts join. One that is next
        // to it but would block its point (or be blocked) stays out.
        candidates.clear();
        for (const std::size_t h : near) candidates.push_back(part_of(h));
        checked.assign(near.size(), 0);
        settled.assign(near.size(), 0);
        for (bool joined = true; joined && parts.size() < kMaxParts;) {
            joined = false;
            for (std::size_t k = 0; k < near.size() && parts.size() < kMaxParts; ++k) {
                if (settled[k]) continue;
                const bool next = next_to(candidates[k], checked[k]);
                checked[k] = parts.size();
                if (!next) continue;
                settled[k] = 1;
                joined = join(k) || joined;
            }
        }
        if (taken.size() < 2) continue;
        c.apart[id] = 1;
        c.points[id] = point;
        for (std::size_t i = 1; i < taken.size(); ++i) {
            for (const std::size_t f : c.faces[taken[i]]) {
                c.of[f] = static_cast<std::int64_t>(id);
                c.faces[id].push_back(f);
            }
            c.faces[taken[i]].clear();
        }
    }
    // The clusters left, renumbered in order.
    std::vector<std::int64_t> index(c.faces.size(), -1);
    Clusters kept;
    kept.split = c.split;
    kept.moved = c.moved;
    for (std::size_t id = 0; id < c.faces.size(); ++id) {
        if (c.faces[id].empty()) continue;
        index[id] = static_cast<std::int64_t>(kept.faces.size());
        kept.faces.push_back(std::move(c.faces[id]));
        kept.from.push_back(c.from[id]);
        kept.apart.push_back(c.apart[id]);
        kept.points.push_back(c.points[id]);
    }
    for (std::size_t f = 0; f < c.of.size(); ++f)
        if (c.of[f] >= 0) c.of[f] = index[std::size_t(c.of[f])];
    kept.of = std::move(c.of);
    c = std::move(kept);
}

// A directed edge a→b of a triangle, qualified by what may be paired with it.
struct EdgeKey {
    std::uint32_t primitive, material, node;
    std::array<double, 6> ab;

    bool operator<(const EdgeKey& o) const {
        if (primitive != o.primitive) return primitive < o.primitive;
        if (material != o.material) return material < o.material;
        if (node != o.node) return node < o.node;
        return ab < o.ab;
    }
};

EdgeKey edge_key(const scene::Triangle& t, const dvec3& a, const dvec3& b) {
    return {t.primitive, t.material, t.node, {a.x, a.y, a.z, b.x, b.y, b.z}};
}

// The quad made by triangle t and a partner across t's edge k (t.p[k] → t.p[k+1]) whose third
// vertex is d, starting at the shared edge's end so t is (v0, v1, v2).
Polygon quad_across(const scene::Triangle& t, int k, const dvec3& d) {
    return make_polygon({t.p[std::size_t((k + 1) % 3)], t.p[std::size_t((k + 2) % 3)], t.p[std::size_t(k)], d});
}

bool strictly_convex(const Polygon& q, const dvec3& normal) {
    for (int k = 0; k < 4; ++k) {
        const dvec3 in = q.v[std::size_t(k)] - q.v[std::size_t((k + 3) % 4)];
        const dvec3 out = q.v[std::size_t((k + 1) % 4)] - q.v[std::size_t(k)];
        const double turn = glm::dot(glm::cross(in, out), normal);
        if (!(turn > kConvexSin * glm::length(in) * glm::length(out))) return false;
    }
    return true;
}

// Faces in input order: each kept triangle either joins a partner (pairing greedily, trying
// its longest edge first since that is the diagonal of a split quad) or stands alone.
std::vector<Face> make_faces(const scene::Scene& scene, Mesh& mesh) {
    const auto& tris = scene.triangles;
    std::vector<bool> keep(tris.size()), used(tris.size(), false);
    std::map<EdgeKey, std::vector<std::pair<std::size_t, int>>> edges;  // directed edge → (triangle, edge)
    for (std::size_t t = 0; t < tris.size(); ++t) {
        keep[t] = !is_degenerate(tris[t]);
        if (!keep[t]) {
            ++mesh.dropped_triangles;
            continue;
        }
        for (int k = 0; k < 3; ++k)
            edges[edge_key(tris[t], tris[t].p[std::size_t(k)], tris[t].p[std::size_t((k + 1) % 3)])].push_back({t, k});
    }

    std::vector<Face> faces;
    for (std::size_t t = 0; t < tris.size(); ++t) {
        if (!keep[t] || used[t]) continue;
        used[t] = true;
        const scene::Triangle& tri = tris[t];
        std::array<int, 3> order{0, 1, 2};
        auto edge_len = [&tri](int k) { return glm::length(tri.p[std::size_t((k + 1) % 3)] - tri.p[std::size_t(k)]); };
        std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return edge_len(a) > edge_len(b); });

        Face face;
        face.poly = make_polygon({tri.p[0], tri.p[1], tri.p[2]});
        face.src[0] = &tri;
        const dvec3 normal = unit_normal(tri);
        for (int k : order) {
            const auto it = edges.find(edge_key(tri, tri.p[std::size_t((k + 1) % 3)], tri.p[std::size_t(k)]));
            if (it == edges.end()) continue;
            for (const auto& [u, ku] : it->second) {
                if (used[u] || glm::dot(normal, unit_normal(tris[u])) <= kCoplanarDot) continue;
                const Polygon quad = quad_across(tri, k, tris[u].p[std::size_t((ku + 2) % 3)]);
                if (!strictly_convex(quad, normal)) continue;
                used[u] = true;
                face.poly = quad;
                face.src[1] = &tris[u];
                ++mesh.quads;
                break;
            }
            if (face.src[1]) break;
        }
        faces.push_back(face);
    }
    return faces;
}

void check_settings(const Settings& s) {
    const bool ok = std::isfinite(s.patch_size) && std::isfinite(s.element_size) && s.patch_size > 0.0 &&
                    s.element_size > 0.0 && s.element_size <= s.patch_size;
    if (!ok)
        throw InternalError(fmt::format("mesh: invalid sizes patch_size={} element_size={} (need 0 < element <= patch)",
                                        s.patch_size, s.element_size));
}

}  // namespace

// Normal, area centroid and area of a planar convex polygon; a quad is taken as two triangles
// so its centroid is the true area centroid, not the vertex mean.
Shape shape_of(const Polygon& poly) {
    Shape s;
    if (poly.n == 3) {
        const dvec3 c = glm::cross(poly.v[1] - poly.v[0], poly.v[2] - poly.v[0]);
        s.area = 0.5 * glm::length(c);
        s.normal = glm::normalize(c);
        s.centroid = (poly.v[0] + poly.v[1] + poly.v[2]) / 3.0;
        return s;
    }
    const double a1 = 0.5 * glm::length(glm::cross(poly.v[1] - poly.v[0], poly.v[2] - poly.v[0]));
    const double a2 = 0.5 * glm::length(glm::cross(poly.v[2] - poly.v[0], poly.v[3] - poly.v[0]));
    s.area = a1 + a2;
    s.normal = glm::normalize(glm::cross(poly.v[2] - poly.v[0], poly.v[3] - poly.v[1]));
    s.centroid = (a1 * (poly.v[0] + poly.v[1] + poly.v[2]) + a2 * (poly.v[0] + poly.v[2] + poly.v[3])) / (3.0 * s.area);
    return s;
}

double longest_edge(const Polygon& poly) {
    double longest = 0.0;
    for (int i = 0; i < poly.n; ++i)
        longest = std::max(longest, glm::length(poly.v[std::size_t((i + 1) % poly.n)] - poly.v[std::size_t(i)]));
    return longest;
}

std::vector<mesh::LightShooter> light_shooters(const std::vector<scene::PunctualLight>& lights) {
    std::vector<mesh::LightShooter> out;
    for (std::size_t i = 0; i < lights.size(); ++i) {
        const scene::PunctualLight& l = lights[i];
        const auto index = static_cast<std::uint32_t>(i);
        switch (l.type) {
            case scene::PunctualLight::Type::point:
                out.push_back({l.position, glm::dvec3(0.0, 1.0, 0.0), index});
                out.push_back({l.position, glm::dvec3(0.0, -1.0, 0.0), index});
                break;
            case scene::PunctualLight::Type::spot:
                out.push_back({l.position, l.direction, index});  // its cone is at most the half-space
                break;
            case scene::PunctualLight::Type::directional:
                break;
        }
    }
    return out;
}

std::vector<mesh::DirectionalShooter> directional_shooters(const std::vector<scene::PunctualLight>& lights) {
    std::vector<mesh::DirectionalShooter> out;
    for (std::size_t i = 0; i < lights.size(); ++i)
        if (lights[i].type == scene::PunctualLight::Type::directional && lights[i].intensity != glm::dvec3(0.0))
            out.push_back({lights[i].direction, static_cast<std::uint32_t>(i)});
    return out;
}

Mesh build(const scene::Scene& scene, const Settings& settings, const std::function<void(const Counts&)>& before) {
    check_settings(settings);
    Mesh mesh;
    const std::vector<Face> faces = make_faces(scene, mesh);
    for (const Face& face : faces)
        if (face.src[0]->material >= scene.materials.size())
            throw InternalError(fmt::format("mesh: triangle material {} out of range", face.src[0]->material));
    std::vector<Grid> grids;
    grids.reserve(faces.size());
    // A coarse material's faces (the sky dome's) are one patch and one element each.
    Settings whole = settings;
    whole.patch_size = whole.element_size = std::numeric_limits<double>::infinity();
    std::vector<char> coarse(faces.size(), 0);
    for (std::size_t f = 0; f < faces.size(); ++f) {
        coarse[f] = scene.materials[faces[f].src[0]->material].coarse;
        grids.push_back(grid_of(faces[f].poly, coarse[f] ? whole : settings));
    }
    Clusters clusters = cluster_faces(faces, grids, settings, coarse);
    // The shooting points need checking only where a cluster has several faces, or may join others.
    const bool several = std::any_of(clusters.faces.begin(), clusters.faces.end(), [](const auto& m) { return m.size() > 1; });
    if (settings.cluster && (several || settings.cluster_apart)) {
        std::vector<Shape> shape(faces.size());
        parallel::for_each(faces.size(), 4096, [&](std::size_t f) { shape[f] = shape_of(faces[f].poly); });
        const Clearance clearance(faces);
        split_blocked_clusters(faces, shape, scene, clearance, clusters);
        if (settings.cluster_apart) join_clusters_apart(faces, shape, scene, settings, clearance, clusters);
    }
    mesh.split_clusters = clusters.split;
    mesh.moved_clusters = clusters.moved;
    for (std::size_t id = 0; id < clusters.faces.size(); ++id)
        if (clusters.apart[id])
            mesh.joined_clusters +=
                scene.materials[faces[clusters.faces[id].front()].src[0]->material].double_sided ? 2 : 1;
    Counts counts;
    for (std::size_t f = 0; f < faces.size(); ++f) {
        const double sides = scene.materials.at(faces[f].src[0]->material).double_sided ? 2.0 : 1.0;
        const bool clustered = clusters.of[f] >= 0;
        const bool first = clustered && clusters.faces[std::size_t(clusters.of[f])].front() == f;
        counts.patches += sides * (clustered ? (first ? 1.0 : 0.0) : grids[f].patches());
        counts.elements += sides * grids[f].elements();
    }
    if (before) before(counts);
    EmitterBudget budget{kMaxEmissionShooters + counts.patches / 16.0};
    // Patches in face order, every front before every back (append_backs); a cluster where its
    // first face is, with all of its faces.
    const Texturing texturing(scene);
    mesh.lights = light_shooters(scene.lights);
    mesh.directions = directional_shooters(scene.lights);
    std::vector<BackSides> backs;
    for (std::size_t f = 0; f < faces.size(); ++f) {
        if (clusters.of[f] < 0) {
            std::vector<std::vector<PatchCells>> cells{face_cells(grids[f])};
            std::vector<std::vector<Part>> patches;
            for (const PatchCells& pc : cells.front()) patches.push_back({{&faces[f], &pc}});
            append_sides(mesh, std::move(cells), std::move(patches), scene, texturing, budget, backs);
            continue;
        }
        const std::vector<std::size_t>& members = clusters.faces[std::size_t(clusters.of[f])];
        if (members.front() != f) continue;
        std::vector<std::vector<PatchCells>> cells;  // one cell each: the face fits in one patch
        cells.reserve(members.size());
        for (const std::size_t g : members) cells.push_back(face_cells(grids[g]));
        std::vector<Part> parts;
        for (std::size_t i = 0; i < members.size(); ++i) parts.push_back({&faces[members[i]], &cells[i].front()});
        const auto id = std::size_t(clusters.of[f]);
        std::optional<std::array<dvec3, 2>> from;
        if (clusters.from[id] >= 0) {
            const dvec3 centroid = shape_of(faces[std::size_t(clusters.from[id])].poly).centroid;
            from = std::array<dvec3, 2>{centroid, centroid};
        } else if (clusters.apart[id]) {
            from = clusters.points[id];
        }
        append_sides(mesh, std::move(cells), {parts}, scene, texturing, budget, backs, from, clusters.apart[id] != 0);
    }
    append_backs(mesh, backs);
    return mesh;
}

}  // namespace hemirad::mesh
