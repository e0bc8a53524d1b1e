// Inverted-hull outlines told apart from rooms, and the light that lands on one-sided backs (see outlines.h).
#include "scene/outlines.h"

#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

namespace hemirad::scene {

namespace {

// Past this many triangle visits (over all candidate shells) the search stops, and the shells
// left are taken for rooms: a scene of thousands of inward shells each as large as the scene
// (never seen) would otherwise be quadratic.
constexpr double kMaxVisits = 2e8;

bool names_outline(const std::string& name) {
    std::string s;
    for (char c : name) s += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    for (const char* word : {"outline", "hull", "inverted"})
        if (s.find(word) != std::string::npos) return true;
    // "ink" as a word of its own ("ink", "Body_Ink", "ink.001"), not inside "pink" or "sink".
    for (std::size_t at = s.find("ink"); at != std::string::npos; at = s.find("ink", at + 1)) {
        const bool start = at == 0 || !std::isalpha(static_cast<unsigned char>(s[at - 1]));
        const bool end = at + 3 == s.size() || !std::isalpha(static_cast<unsigned char>(s[at + 3]));
        if (start && end) return true;
    }
    return false;
}

struct Box {
    glm::dvec3 lo{std::numeric_limits<double>::infinity()}, hi{-std::numeric_limits<double>::infinity()};
    void add(const glm::dvec3& p) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    bool empty() const { return !(lo.x <= hi.x); }
    double diagonal() const { return empty() ? 0.0 : glm::length(hi - lo); }
    bool contains(const glm::dvec3& p) const {
        return p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
    }
};

// Area centroid and the share of the area whose front faces it: a group of triangles faces
// inwards when that share is kInwardShare or more.
struct Facing {
    glm::dvec3 weighted{0.0};
    double area = 0.0, facing = 0.0;
    glm::dvec3 centroid() const { return area > 0.0 ? weighted / area : glm::dvec3(0.0); }
    bool inward(double share = kInwardShare) const { return area > 0.0 && facing >= share * area; }
};

struct Shell {
    std::uint32_t node = 0;
    std::size_t triangles = 0;
    Facing facing;
    Box box;
    bool named = false;
    std::uint32_t material = 0;  // its first triangle's
    bool one_material = true;    // all its triangles have that material
    std::vector<glm::dvec3> vertices;  // distinct positions
    bool candidate = false, hull = false;
    bool sibling = false;  // a hull by its material (mark_siblings)
    double gap = 0.0;
};

// One-sided triangles grouped into shells, and which shells are hulls.
struct Analysis {
    std::vector<std::int32_t> shell;  // per triangle; -1: not one-sided (or sky, see-through, no area)
    std::vector<Shell> shells;
};

bool see_through(const Scene& scene, const Triangle& t) {
    return t.material < scene.materials.size() && !scene.materials[t.material].see_through.empty();
}
bool synthetic(const Scene& scene, const Triangle& t) { return t.node < scene.nodes.size() && scene.nodes[t.node].synthetic; }
bool one_sided(const Scene& scene, const Triangle& t) {
    return t.material < scene.materials.size() && !scene.materials[t.material].double_sided;
}
glm::dvec3 doubled_normal(const Triangle& t) { return glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]); }
glm::dvec3 centroid(const Triangle& t) { return (t.p[0] + t.p[1] + t.p[2]) / 3.0; }

std::uint64_t mix(std::uint64_t h, std::uint64_t v) {
    h ^= v + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2);
    h *= 0xff51afd7ed558ccdull;
    return h ^ (h >> 33);
}
std::uint64_t bits(double d) {
    if (d == 0.0) d = 0.0;  // −0 and +0 are one position
    std::uint64_t b;
    std::memcpy(&b, &d, sizeof b);
    return b;
}

struct UnionFind {
    std::vector<std::uint32_t> parent;
    explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
    std::uint32_t find(std::uint32_t x) {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    }
    void unite(std::uint32_t a, std::uint32_t b) {
        a = find(a);
        b = find(b);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
};

// Shells: one-sided triangles of one node connected through corners at the same position.
void make_shells(const Scene& scene, Analysis& A) {
    const std::size_t n = scene.triangles.size();
    A.shell.assign(n, -1);
    std::vector<char> eligible(n, 0);
    // Corners keyed by a 64-bit hash of their node and position, sorted (a radix sort: this is
    // most of the work). Equal keys are taken for one vertex: two distinct positions share a key
    // with a chance of about n² / 2^65 (1e-7 for a million triangles), and would at worst join
    // two shells.
    struct Corner {
        std::uint64_t key;
        std::uint32_t corner;  // 3 × triangle + k
    };
    std::vector<Corner> corners;
    for (std::size_t i = 0; i < n; ++i) {
        const Triangle& t = scene.triangles[i];
        if (!one_sided(scene, t) || see_through(scene, t) || synthetic(scene, t)) continue;
        if (!(glm::length(doubled_normal(t)) > 0.0)) continue;
        eligible[i] = 1;
        for (int k = 0; k < 3; ++k)
            corners.push_back({mix(mix(mix(mix(0, t.node), bits(t.p[k].x)), bits(t.p[k].y)), bits(t.p[k].z)),
                               static_cast<std::uint32_t>(3 * i + k)});
    }
    {
        std::vector<Corner> buffer(corners.size());
        for (int shift = 0; shift < 64; shift += 16) {
            std::vector<std::size_t> count((1 << 16) + 1, 0);
            for (const Corner& c : corners) ++count[((c.key >> shift) & 0xffff) + 1];
            for (std::size_t d = 0; d < (1 << 16); ++d) count[d + 1] += count[d];
            for (const Corner& c : corners) buffer[count[(c.key >> shift) & 0xffff]++] = c;
            corners.swap(buffer);
        }
    }
    const auto position = [&](std::uint32_t c) { return scene.triangles[c / 3].p[c % 3]; };
    std::vector<std::uint32_t> vertex_of(3 * n, 0);
    std::vector<std::uint32_t> first_corner;  // per vertex
    for (std::size_t j = 0; j < corners.size(); ++j) {
        if (j == 0 || corners[j].key != corners[j - 1].key) first_corner.push_back(corners[j].corner);
        vertex_of[corners[j].corner] = static_cast<std::uint32_t>(first_corner.size() - 1);
    }
    corners = {};
    UnionFind uf(first_corner.size());
    for (std::size_t i = 0; i < n; ++i)
        if (eligible[i]) {
            uf.unite(vertex_of[3 * i], vertex_of[3 * i + 1]);
            uf.unite(vertex_of[3 * i], vertex_of[3 * i + 2]);
        }
    std::vector<char> named_material(scene.materials.size()), named_node(scene.nodes.size());
    for (std::size_t m = 0; m < scene.materials.size(); ++m) named_material[m] = names_outline(scene.materials[m].name);
    for (std::size_t k = 0; k < scene.nodes.size(); ++k) named_node[k] = names_outline(scene.nodes[k].name);
    // Shells numbered in the order of their first triangle.
    std::vector<std::int32_t> shell_of_root(first_corner.size(), -1);
    for (std::size_t i = 0; i < n; ++i) {
        if (!eligible[i]) continue;
        const std::uint32_t root = uf.find(vertex_of[3 * i]);
        if (shell_of_root[root] < 0) {
            shell_of_root[root] = static_cast<std::int32_t>(A.shells.size());
            A.shells.emplace_back();
            A.shells.back().node = scene.triangles[i].node;
            A.shells.back().material = scene.triangles[i].material;
        }
        const std::int32_t s = shell_of_root[root];
        A.shell[i] = s;
        Shell& shell = A.shells[s];
        const Triangle& t = scene.triangles[i];
        const double area = 0.5 * glm::length(doubled_normal(t));
        ++shell.triangles;
        shell.facing.area += area;
        shell.facing.weighted += area * centroid(t);
        for (const glm::dvec3& p : t.p) shell.box.add(p);
        shell.named = shell.named || named_material[t.material] || (t.node < named_node.size() && named_node[t.node]);
        shell.one_material = shell.one_material && t.material == shell.material;
    }
    for (std::uint32_t v = 0; v < first_corner.size(); ++v)
        A.shells[shell_of_root[uf.find(v)]].vertices.push_back(position(first_corner[v]));
    for (std::size_t i = 0; i < n; ++i) {
        if (A.shell[i] < 0) continue;
        Shell& shell = A.shells[A.shell[i]];
        const Triangle& t = scene.triangles[i];
        const glm::dvec3 nn = doubled_normal(t);
        if (glm::dot(nn, shell.facing.centroid() - centroid(t)) > 0.0) shell.facing.facing += 0.5 * glm::length(nn);
    }
}

// A grid of triangles by centroid over `box`, about one cell per two triangles (CSR: the
// triangles of cell c are items[start[c] .. start[c + 1])).
struct Grid {
    Box box;
    glm::ivec3 dims{1};
    glm::dvec3 cell{1.0};
    std::vector<std::uint32_t> start, items;

    glm::ivec3 index(const glm::dvec3& p) const {
        glm::ivec3 i;
        for (int a = 0; a < 3; ++a)
            i[a] = std::clamp(static_cast<int>(std::floor((p[a] - box.lo[a]) / cell[a])), 0, dims[a] - 1);
        return i;
    }
    std::size_t flat(const glm::ivec3& i) const {
        return (static_cast<std::size_t>(i.z) * dims.y + i.y) * dims.x + i.x;
    }
};

Grid make_grid(const std::vector<glm::dvec3>& points, const std::vector<std::uint32_t>& ids, double target_cells) {
    Grid g;
    for (const glm::dvec3& p : points) g.box.add(p);
    if (points.empty()) g.box.add(glm::dvec3(0.0));
    const glm::dvec3 extent = g.box.hi - g.box.lo;
    const double floor_extent = std::max(1e-12, 1e-6 * glm::length(extent));
    const glm::dvec3 e = glm::max(extent, glm::dvec3(floor_extent));
    const double side = std::cbrt(e.x * e.y * e.z / std::max(1.0, target_cells));
    for (int a = 0; a < 3; ++a) {
        g.dims[a] = static_cast<int>(std::clamp(std::ceil(e[a] / side), 1.0, 1024.0));
        g.cell[a] = e[a] / g.dims[a];
    }
    const std::size_t cells = static_cast<std::size_t>(g.dims.x) * g.dims.y * g.dims.z;
    g.start.assign(cells + 1, 0);
    std::vector<std::uint32_t> cell_of(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) ++g.start[(cell_of[i] = static_cast<std::uint32_t>(g.flat(g.index(points[i])))) + 1];
    for (std::size_t c = 0; c < cells; ++c) g.start[c + 1] += g.start[c];
    g.items.resize(points.size());
    std::vector<std::uint32_t> fill(g.start.begin(), g.start.end() - 1);
    for (std::size_t i = 0; i < points.size(); ++i) g.items[fill[cell_of[i]]++] = ids[i];
    return g;
}

// The fraction of `vertices` within `reach` of one of `points` (a dense grid of cells of side
// `reach` over `box`, at most 14 a side: reach is a tenth or a fifth of the box's diagonal).
double hugged_share(const std::vector<glm::dvec3>& vertices, const std::vector<glm::dvec3>& points, const Box& box,
                    double reach) {
    if (vertices.empty()) return 0.0;
    const glm::dvec3 lo = box.lo - glm::dvec3(reach);
    glm::ivec3 dims;
    for (int a = 0; a < 3; ++a) dims[a] = std::max(1, static_cast<int>(std::ceil((box.hi[a] - lo[a] + reach) / reach)));
    const auto cell = [&](const glm::dvec3& p) {
        glm::ivec3 i;
        for (int a = 0; a < 3; ++a) i[a] = std::clamp(static_cast<int>(std::floor((p[a] - lo[a]) / reach)), 0, dims[a] - 1);
        return i;
    };
    const auto flat = [&](const glm::ivec3& i) { return (static_cast<std::size_t>(i.z) * dims.y + i.y) * dims.x + i.x; };
    const std::size_t cells = static_cast<std::size_t>(dims.x) * dims.y * dims.z;
    std::vector<std::uint32_t> start(cells + 1, 0), items(points.size());
    for (const glm::dvec3& p : points) ++start[flat(cell(p)) + 1];
    for (std::size_t c = 0; c < cells; ++c) start[c + 1] += start[c];
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < points.size(); ++i) items[fill[flat(cell(points[i]))]++] = static_cast<std::uint32_t>(i);
    const double reach2 = reach * reach;
    std::size_t hugged = 0;
    for (const glm::dvec3& v : vertices) {
        const glm::ivec3 c = cell(v);
        bool near = false;
        for (int dz = -1; dz <= 1 && !near; ++dz)
            for (int dy = -1; dy <= 1 && !near; ++dy)
                for (int dx = -1; dx <= 1 && !near; ++dx) {
                    const glm::ivec3 o = c + glm::ivec3(dx, dy, dz);
                    if (o.x < 0 || o.y < 0 || o.z < 0 || o.x >= dims.x || o.y >= dims.y || o.z >= dims.z) continue;
                    const std::size_t f = flat(o);
                    for (std::uint32_t k = start[f]; k < start[f + 1] && !near; ++k) {
                        const glm::dvec3 d = points[items[k]] - v;
                        near = glm::dot(d, d) <= reach2;
                    }
                }
        hugged += near;
    }
    return static_cast<double>(hugged) / static_cast<double>(vertices.size());
}

// An outline material's other shells: pieces of hulls cut open, or around objects the search did
// not reach (see kSiblingShare). A room's walls never share a material with hulls that make up
// most of it, and are larger than any of them; what a hull encloses faces outwards.
void mark_siblings(const Scene& scene, Analysis& A) {
    std::vector<double> area(scene.materials.size() + 1, 0.0), hull_area(area.size(), 0.0), largest(area.size(), 0.0);
    const auto slot = [&](const Shell& s) { return std::min<std::size_t>(s.material, scene.materials.size()); };
    for (const Shell& s : A.shells) {
        if (!s.one_material) continue;
        area[slot(s)] += s.facing.area;
        if (!s.hull) continue;
        hull_area[slot(s)] += s.facing.area;
        largest[slot(s)] = std::max(largest[slot(s)], s.box.diagonal());
    }
    for (Shell& s : A.shells) {
        const std::size_t m = slot(s);
        if (s.hull || !s.one_material || !s.facing.inward(kSiblingInwardShare)) continue;
        if (!(hull_area[m] > kSiblingShare * area[m]) || s.box.diagonal() > largest[m]) continue;
        s.hull = s.sibling = true;
    }
}

Analysis analyse(const Scene& scene) {
    Analysis A;
    make_shells(scene, A);
    for (Shell& s : A.shells) {
        const glm::dvec3 e = s.box.hi - s.box.lo;
        const double d = s.box.diagonal();
        s.candidate = s.triangles >= 4 && s.facing.inward() && e.x > 1e-6 * d && e.y > 1e-6 * d && e.z > 1e-6 * d;
    }
    if (std::none_of(A.shells.begin(), A.shells.end(), [](const Shell& s) { return s.candidate; })) return A;

    // What a shell may enclose: every other surface that blocks light (not the sky, not glass,
    // not another candidate shell), binned by centroid.
    std::vector<glm::dvec3> centroids;
    std::vector<std::uint32_t> ids;
    for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
        const Triangle& t = scene.triangles[i];
        if (see_through(scene, t) || synthetic(scene, t)) continue;
        if (A.shell[i] >= 0 && A.shells[A.shell[i]].candidate) continue;
        if (!(glm::length(doubled_normal(t)) > 0.0)) continue;
        centroids.push_back(centroid(t));
        ids.push_back(static_cast<std::uint32_t>(i));
    }
    const Grid grid = make_grid(centroids, ids, 0.5 * static_cast<double>(ids.size()));
    double visits = 0.0;
    for (Shell& s : A.shells) {
        if (!s.candidate) continue;
        const double diagonal = s.box.diagonal();
        Box box = s.box;
        box.lo -= glm::dvec3(1e-6 * diagonal);
        box.hi += glm::dvec3(1e-6 * diagonal);
        // A camera inside: a room seen from within, whatever it holds.
        if (std::any_of(scene.cameras.begin(), scene.cameras.end(),
                        [&](const Camera& c) { return box.contains(glm::dvec3(c.camera_to_world[3])); }))
            continue;
        if (centroids.empty() || visits > kMaxVisits) continue;
        Box inner;
        std::vector<glm::dvec3> points;
        const glm::ivec3 a = grid.index(box.lo), b = grid.index(box.hi);
        for (int z = a.z; z <= b.z; ++z)
            for (int y = a.y; y <= b.y; ++y)
                for (int x = a.x; x <= b.x; ++x) {
                    const std::size_t f = grid.flat({x, y, z});
                    visits += grid.start[f + 1] - grid.start[f];
                    for (std::uint32_t k = grid.start[f]; k < grid.start[f + 1]; ++k) {
                        const Triangle& t = scene.triangles[grid.items[k]];
                        if (!box.contains(t.p[0]) || !box.contains(t.p[1]) || !box.contains(t.p[2])) continue;
                        for (const glm::dvec3& p : t.p) {
                            inner.add(p);
                            points.push_back(p);
                        }
                    }
                }
        if (inner.empty()) continue;
        s.gap = 0.0;
        for (int k = 0; k < 3; ++k)
            s.gap = std::max({s.gap, (inner.lo[k] - s.box.lo[k]) / diagonal, (s.box.hi[k] - inner.hi[k]) / diagonal});
        const double reach = (s.named ? 2.0 : 1.0) * kHugFraction;
        if (s.gap > reach) continue;
        s.hull = hugged_share(s.vertices, points, s.box, reach * diagonal) >= kHuggedVertices;
    }
    mark_siblings(scene, A);
    return A;
}

}  // namespace

OutlineSearch find_outline_hulls(const Scene& scene) {
    const Analysis A = analyse(scene);
    OutlineSearch out;
    for (const Shell& s : A.shells) {
        if (s.hull) {
            out.hulls.push_back({s.node, s.triangles, s.gap, s.named, s.sibling});
        } else if (s.candidate) {
            if (out.inward_shells++ == 0)
                out.example_shell = s.node < scene.nodes.size() ? scene.nodes[s.node].name : fmt::format("node{}", s.node);
        }
    }
    for (std::size_t i = 0; i < A.shell.size(); ++i)
        if (A.shell[i] >= 0 && A.shells[A.shell[i]].hull) out.triangles.push_back(i);
    return out;
}

namespace {

// One orthographic view of the scene along `d` (where the light travels): per cell of a grid
// across it (256 on its longer side), the nearest triangle, or −1.
struct LightView {
    std::vector<std::int64_t> nearest;
    double cell_area = 0.0;
};

LightView view_along(const Scene& scene, const glm::dvec3& d) {
    const glm::dvec3 u = glm::normalize(glm::cross(std::abs(d.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0), d));
    const glm::dvec3 v = glm::cross(d, u);
    double u0 = std::numeric_limits<double>::infinity(), v0 = u0, u1 = -u0, v1 = -u0;
    for (const Triangle& t : scene.triangles) {
        if (synthetic(scene, t) || see_through(scene, t)) continue;
        for (const glm::dvec3& p : t.p) {
            u0 = std::min(u0, glm::dot(p, u));
            u1 = std::max(u1, glm::dot(p, u));
            v0 = std::min(v0, glm::dot(p, v));
            v1 = std::max(v1, glm::dot(p, v));
        }
    }
    LightView view;
    if (!(u1 > u0) && !(v1 > v0)) return view;
    constexpr int kSide = 256;
    const double s = std::max(u1 - u0, v1 - v0) / kSide;
    const int nu = std::max(1, static_cast<int>(std::ceil((u1 - u0) / s))), nv = std::max(1, static_cast<int>(std::ceil((v1 - v0) / s)));
    view.cell_area = s * s;
    view.nearest.assign(static_cast<std::size_t>(nu) * nv, -1);
    std::vector<double> depth(view.nearest.size(), std::numeric_limits<double>::infinity());
    for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
        const Triangle& t = scene.triangles[i];
        if (synthetic(scene, t) || see_through(scene, t)) continue;
        std::array<glm::dvec2, 3> q;
        std::array<double, 3> z;
        for (int k = 0; k < 3; ++k) {
            q[k] = {(glm::dot(t.p[k], u) - u0) / s - 0.5, (glm::dot(t.p[k], v) - v0) / s - 0.5};  // cell centres at integers
            z[k] = glm::dot(t.p[k], d);
        }
        const double area = (q[1].x - q[0].x) * (q[2].y - q[0].y) - (q[2].x - q[0].x) * (q[1].y - q[0].y);
        if (!(std::abs(area) > 1e-12)) continue;  // seen edge-on: covers no cell
        const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({q[0].x, q[1].x, q[2].x}))));
        const int x1 = std::min(nu - 1, static_cast<int>(std::floor(std::max({q[0].x, q[1].x, q[2].x}))));
        const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({q[0].y, q[1].y, q[2].y}))));
        const int y1 = std::min(nv - 1, static_cast<int>(std::floor(std::max({q[0].y, q[1].y, q[2].y}))));
        for (int y = y0; y <= y1; ++y)
            for (int x = x0; x <= x1; ++x) {
                const glm::dvec2 c(x, y);
                double w[3];
                for (int k = 0; k < 3; ++k) {
                    const glm::dvec2 a = q[(k + 1) % 3], b = q[(k + 2) % 3];
                    w[k] = ((b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y)) / area;
                }
                if (w[0] < 0.0 || w[1] < 0.0 || w[2] < 0.0) continue;
                const double depth_here = w[0] * z[0] + w[1] * z[1] + w[2] * z[2];
                const std::size_t f = static_cast<std::size_t>(y) * nu + x;
                if (depth_here < depth[f]) {
                    depth[f] = depth_here;
                    view.nearest[f] = static_cast<std::int64_t>(i);
                }
            }
    }
    return view;
}

}  // namespace

std::optional<BackLight> back_light(const Scene& scene) {
    // The light's directions (where it travels) and their weights (lux).
    std::vector<std::pair<glm::dvec3, double>> lights;
    for (const PunctualLight& l : scene.lights)
        if (l.type == PunctualLight::Type::directional && l.intensity != glm::dvec3(0.0))
            lights.push_back({glm::normalize(l.direction), std::max({l.intensity.x, l.intensity.y, l.intensity.z})});
    double sky_area = 0.0, sky_emission = 0.0;
    for (const Triangle& t : scene.triangles)
        if (synthetic(scene, t) && t.material < scene.materials.size()) {
            const glm::dvec3& e = scene.materials[t.material].emission;
            const double a = 0.5 * glm::length(doubled_normal(t));
            sky_area += a;
            sky_emission += a * std::max({e.x, e.y, e.z});
        }
    if (sky_emission > 0.0) {
        // The sky from overhead and from four points of the compass at 45°, in equal parts.
        const double e = sky_emission / sky_area / 5.0, c = std::sqrt(0.5);
        lights.push_back({glm::dvec3(0, -1, 0), e});
        for (const glm::dvec3& h : {glm::dvec3(1, 0, 0), glm::dvec3(-1, 0, 0), glm::dvec3(0, 0, 1), glm::dvec3(0, 0, -1)})
            lights.push_back({-(c * h + glm::dvec3(0, c, 0)), e});
    }
    if (lights.empty()) return std::nullopt;

    // The nearest surface in each cell of each light's view; the backs among them.
    std::vector<LightView> views;
    double total = 0.0, raw = 0.0;
    const auto back_of = [&](std::int64_t i, const glm::dvec3& d) {
        const Triangle& t = scene.triangles[static_cast<std::size_t>(i)];
        return one_sided(scene, t) && glm::dot(doubled_normal(t), d) > 0.0;
    };
    for (const auto& [d, lux] : lights) {
        views.push_back(view_along(scene, d));
        const double w = lux * views.back().cell_area;
        for (const std::int64_t i : views.back().nearest) {
            if (i < 0) continue;
            total += w;
            if (back_of(i, d)) raw += w;
        }
    }
    if (!(total > 0.0)) return std::nullopt;
    BackLight out;
    out.share = raw / total;
    if (out.share < kBackLightWarning) return out;  // the exclusions below only lower it

    // Backs that are meant to face away from the viewer: those of inward shells that are not
    // hulls, of inward nodes, or of everything when the whole scene faces inwards (an interior).
    const Analysis A = analyse(scene);
    std::vector<Facing> nodes(scene.nodes.size() + 1);
    Facing whole;
    const auto node_slot = [&](const Triangle& t) { return std::min<std::size_t>(t.node, scene.nodes.size()); };
    for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
        if (A.shell[i] < 0) continue;
        const Triangle& t = scene.triangles[i];
        const double area = 0.5 * glm::length(doubled_normal(t));
        nodes[node_slot(t)].area += area;
        nodes[node_slot(t)].weighted += area * centroid(t);
        whole.area += area;
        whole.weighted += area * centroid(t);
    }
    for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
        if (A.shell[i] < 0) continue;
        const Triangle& t = scene.triangles[i];
        const glm::dvec3 n = doubled_normal(t);
        Facing& f = nodes[node_slot(t)];
        if (glm::dot(n, f.centroid() - centroid(t)) > 0.0) f.facing += 0.5 * glm::length(n);
        if (glm::dot(n, whole.centroid() - centroid(t)) > 0.0) whole.facing += 0.5 * glm::length(n);
    }
    const auto counted = [&](std::size_t i) {
        if (A.shell[i] < 0) return true;
        const Shell& s = A.shells[A.shell[i]];
        if (s.hull) return true;
        return !(s.facing.inward() || nodes[node_slot(scene.triangles[i])].inward() || whole.inward());
    };

    double back = 0.0;
    std::vector<double> taken(scene.nodes.size() + 1, 0.0);
    std::vector<char> seen(scene.triangles.size(), 0);
    for (std::size_t l = 0; l < lights.size(); ++l) {
        const glm::dvec3& d = lights[l].first;
        const double w = lights[l].second * views[l].cell_area;
        for (const std::int64_t i : views[l].nearest) {
            if (i < 0 || !back_of(i, d) || !counted(static_cast<std::size_t>(i))) continue;
            back += w;
            taken[node_slot(scene.triangles[static_cast<std::size_t>(i)])] += w;
            if (!seen[static_cast<std::size_t>(i)]) {
                seen[static_cast<std::size_t>(i)] = 1;
                ++out.triangles;
            }
        }
    }
    out.share = back / total;
    const std::size_t most = static_cast<std::size_t>(std::max_element(taken.begin(), taken.end()) - taken.begin());
    out.example = most < scene.nodes.size() ? scene.nodes[most].name : std::string();
    return out;
}

std::string grouped(std::size_t n) {
    const std::string digits = std::to_string(n);
    std::string out;
    for (std::size_t i = 0; i < digits.size(); ++i) {
        if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
        out += digits[i];
    }
    return out;
}

std::optional<std::string> back_light_warning(const Scene& scene) {
    const std::optional<BackLight> b = back_light(scene);
    if (!b || b->share < kBackLightWarning) return std::nullopt;
    return fmt::format("{}: {:.0f}% of the light the sun and sky send into the scene lands first on the backs of "
                       "one-sided surfaces ({} triangles, most on node '{}'), which block and absorb it though viewers "
                       "cull those faces: if they are toon outlines (inverted hulls), --effects outlines=on leaves them "
                       "out; if their normals are flipped, --effects two_sided=on makes every surface double-sided",
                       scene.path.string(), 100.0 * b->share, grouped(b->triangles), b->example);
}

}  // namespace hemirad::scene
