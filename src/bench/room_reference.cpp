// The box-room radiosity reference: grid, exact unoccluded form factors, GMRES solve, final gather.
#include "bench/room_reference.h"

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>

#include "core/error.h"
#include "formfactor/analytic.h"
#include "scene/builder.h"

namespace hemirad::bench {
namespace {

// The six box faces. Each cell lies in the plane coordinate[axis] = plane (0 or the box size) and
// spans the two other axes, u < v.
struct Face {
    int axis;    // normal axis: 0 x, 1 y, 2 z
    bool upper;  // plane at size[axis] (inward normal −axis) rather than at 0 (+axis)
    int u, v;    // tangent axes
    Surface surface;
};
constexpr std::array<Face, 6> kFaces{{
    {1, false, 0, 2, Surface::floor},
    {1, true, 0, 2, Surface::ceiling},
    {2, false, 0, 1, Surface::wall_north},
    {2, true, 0, 1, Surface::wall_south},
    {0, false, 1, 2, Surface::wall_west},
    {0, true, 1, 2, Surface::wall_east},
}};

glm::dvec3 axis_vector(int axis, double length) {
    glm::dvec3 r(0.0);
    r[axis] = length;
    return r;
}

glm::dvec3 inward_normal(const Face& f) {
    return axis_vector(f.axis, f.upper ? -1.0 : 1.0);
}

// The rectangle [u0, u1] × [v0, v1] of face f, counter-clockwise seen from inside the room.
std::array<glm::dvec3, 4> face_rectangle(const Face& f, const glm::dvec3& size, double u0, double u1, double v0,
                                         double v1) {
    auto at = [&](double u, double v) {
        glm::dvec3 p(0.0);
        p[f.axis] = f.upper ? size[f.axis] : 0.0;
        p[f.u] = u;
        p[f.v] = v;
        return p;
    };
    // e_u × e_v is +normal axis for (x,y)→z and (y,z)→x, −y for (x,z): reverse where it points outwards.
    const bool ccw = glm::dot(glm::cross(axis_vector(f.u, 1.0), axis_vector(f.v, 1.0)), inward_normal(f)) > 0.0;
    if (ccw) return {at(u0, v0), at(u1, v0), at(u1, v1), at(u0, v1)};
    return {at(u0, v0), at(u0, v1), at(u1, v1), at(u1, v0)};
}

int face_of_surface(Surface s) {
    if (s == Surface::light) return 1;
    int i = 0;
    while (kFaces[i].surface != s) ++i;
    return i;
}

// The rectangle (u0, u1, v0, v1) a surface's probes spread over: the light's own, else the whole face (for
// the ceiling, the light included: probes there are dropped).
std::array<double, 4> surface_extent(const Room& room, Surface s) {
    if (s == Surface::light) return {room.light_min.x, room.light_max.x, room.light_min.y, room.light_max.y};
    const Face& f = kFaces[face_of_surface(s)];
    return {0.0, room.size[f.u], 0.0, room.size[f.v]};
}

void validate(const Room& room) {
    auto fail = [](const std::string& what) { throw std::invalid_argument("room_reference: " + what); };
    for (int k = 0; k < 3; ++k)
        if (!(room.size[k] > 0.0) || !std::isfinite(room.size[k])) fail("every box size must be positive");
    for (int k = 0; k < 2; ++k) {
        const double extent = room.size[k == 0 ? 0 : 2];
        if (!(room.light_min[k] >= 0.0 && room.light_min[k] < room.light_max[k] && room.light_max[k] <= extent))
            fail("the light must be a rectangle of positive area inside the ceiling");
    }
    for (int s = 0; s < kSurfaceCount; ++s)
        for (int c = 0; c < 3; ++c) {
            if (!(room.rho[s][c] >= 0.0 && room.rho[s][c] <= scene::kMaxReflectance))
                fail(fmt::format("reflectance of {} must be in [0, {}]", surface_name(Surface(s)),
                                 scene::kMaxReflectance));
            if (!(room.emission[s][c] >= 0.0) || !std::isfinite(room.emission[s][c]))
                fail(fmt::format("emission of {} must be finite and >= 0", surface_name(Surface(s))));
        }
}

// Runs body(i) for i in [0, count) on all hardware threads, in chunks taken in turn. The first
// exception is rethrown after every worker has been joined (also when starting one fails).
template <class Body>
void parallel_for(std::size_t count, std::size_t chunk, Body body) {
    const unsigned threads = std::max(1u, std::min(std::thread::hardware_concurrency(), 64u));
    std::atomic<std::size_t> next{0};
    std::exception_ptr error;
    std::mutex error_mutex;
    auto work = [&] {
        try {
            for (std::size_t begin; (begin = next.fetch_add(chunk)) < count;)
                for (std::size_t i = begin; i < std::min(count, begin + chunk); ++i) body(i);
        } catch (...) {
            const std::lock_guard<std::mutex> lock(error_mutex);
            if (!error) error = std::current_exception();
            next = count;
        }
    };
    std::vector<std::thread> pool;
    try {
        for (unsigned t = 1; t < threads && count > chunk; ++t) pool.emplace_back(work);
    } catch (...) {
        next = count;
        for (auto& t : pool) t.join();
        throw;
    }
    work();
    for (auto& t : pool) t.join();
    if (error) std::rethrow_exception(error);
}

// ---- quadrature -----------------------------------------------------------------------------------

// Gauss–Legendre rules on [0, 1] with 2, 3 and 4 points. The order is picked per piece from how far the
// receiver (the integrand's nearest singularity) is, in units of the piece's diagonal, so that each rule's
// error bound (~ρ^-2n, ρ the Bernstein-ellipse parameter that distance allows) stays below ~1e-7.
struct GaussRule {
    int n;
    std::array<double, 4> x, w;
};
constexpr double kG3 = 0.7745966692414834, kG4a = 0.3399810435848563, kG4b = 0.8611363115940526;
constexpr std::array<GaussRule, 3> kRules{{
    {2, {0.5 - 0.5 / 1.7320508075688772, 0.5 + 0.5 / 1.7320508075688772, 0, 0}, {0.5, 0.5, 0, 0}},
    {3, {0.5 * (1 - kG3), 0.5, 0.5 * (1 + kG3), 0}, {5.0 / 18, 8.0 / 18, 5.0 / 18, 0}},
    {4,
     {0.5 * (1 - kG4b), 0.5 * (1 - kG4a), 0.5 * (1 + kG4a), 0.5 * (1 + kG4b)},
     {0.5 * 0.3478548451374538, 0.5 * 0.6521451548625461, 0.5 * 0.6521451548625461, 0.5 * 0.3478548451374538}},
}};
// A piece closer to the receiver than kNear × its diagonal is split in four, at most kMaxDepth times
// (2⁻⁸ of the cell: the leftover error of pieces touching a shared edge is then ~1e-8 of F). From kNear
// the 4-point rule is used, from kFar3 the 3-point, from kFar2 the 2-point.
constexpr double kNear = 1.0, kFar3 = 5.0, kFar2 = 16.0;
constexpr int kMaxDepth = 8;

struct Box {
    glm::dvec3 lo, hi;
};

Box bounds(const glm::dvec3* v, int n) {
    Box b{v[0], v[0]};
    for (int i = 1; i < n; ++i) {
        b.lo = glm::min(b.lo, v[i]);
        b.hi = glm::max(b.hi, v[i]);
    }
    return b;
}

double gap(const Box& a, const Box& b) {
    const glm::dvec3 d = glm::max(glm::dvec3(0.0), glm::max(a.lo - b.hi, b.lo - a.hi));
    return glm::length(d);
}

double point_to_cell(const glm::dvec3& p, const glm::dvec3& normal, const Cell& to) {
    const glm::dvec3 r[4] = {to.v[0] - p, to.v[1] - p, to.v[2] - p, to.v[3] - p};
    return formfactor::point_to_polygon(normal, r, 4);
}

// ∫∫ F(P(s,t) → to) ds dt over [s0,s1]×[t0,t1], P(s,t) = origin + s·eu + t·ev.
double integrate(const glm::dvec3& origin, const glm::dvec3& eu, const glm::dvec3& ev, const glm::dvec3& normal,
                 const Cell& to, const Box& to_box, double s0, double s1, double t0, double t1, int depth) {
    const glm::dvec3 c[4] = {origin + s0 * eu + t0 * ev, origin + s1 * eu + t0 * ev, origin + s1 * eu + t1 * ev,
                             origin + s0 * eu + t1 * ev};
    const double diagonal = glm::length(c[2] - c[0]);
    const double distance = gap(bounds(c, 4), to_box);
    if (depth < kMaxDepth && distance < kNear * diagonal) {
        const double sm = 0.5 * (s0 + s1), tm = 0.5 * (t0 + t1);
        return integrate(origin, eu, ev, normal, to, to_box, s0, sm, t0, tm, depth + 1) +
               integrate(origin, eu, ev, normal, to, to_box, sm, s1, t0, tm, depth + 1) +
               integrate(origin, eu, ev, normal, to, to_box, s0, sm, tm, t1, depth + 1) +
               integrate(origin, eu, ev, normal, to, to_box, sm, s1, tm, t1, depth + 1);
    }
    const GaussRule& rule = kRules[distance >= kFar2 * diagonal ? 0 : distance >= kFar3 * diagonal ? 1 : 2];
    double sum = 0.0;
    for (int a = 0; a < rule.n; ++a)
        for (int b = 0; b < rule.n; ++b) {
            const glm::dvec3 p = origin + (s0 + (s1 - s0) * rule.x[a]) * eu + (t0 + (t1 - t0) * rule.x[b]) * ev;
            sum += rule.w[a] * rule.w[b] * point_to_cell(p, normal, to);
        }
    return sum * (s1 - s0) * (t1 - t0);
}

// ---- distinct cell-pair configurations -------------------------------------------------------------

// Along an axis that both faces contain, a cell pair's relative geometry is (offset, length_i,
// length_j): pairs with equal triples are translates and share one form factor; so are mirror images
// (reflecting that axis maps both faces onto themselves), whose offset is −(offset + length_j − length_i).
struct AxisClasses {
    int n = 0;                             // cells along the axis
    std::vector<int> of;                   // n × n: class of (i, j)
    std::vector<std::pair<int, int>> rep;  // a representative (i, j) per class
};

AxisClasses classify_axis(const std::vector<double>& edges, double quantum) {
    AxisClasses a;
    a.n = static_cast<int>(edges.size()) - 1;
    a.of.resize(std::size_t(a.n) * a.n);
    std::map<std::array<long long, 3>, int> ids;
    auto q = [&](double x) { return std::llround(x / quantum); };
    for (int i = 0; i < a.n; ++i)
        for (int j = 0; j < a.n; ++j) {
            const long long li = q(edges[i + 1] - edges[i]), lj = q(edges[j + 1] - edges[j]);
            const long long offset = q(edges[j] - edges[i]);
            const std::array<long long, 3> key{std::min(offset, -(offset + lj - li)), li, lj};
            auto [it, added] = ids.emplace(key, static_cast<int>(a.rep.size()));
            if (added) a.rep.emplace_back(i, j);
            a.of[std::size_t(i) * a.n + j] = it->second;
        }
    return a;
}

// The factors from face a's cells to face b's, indexed by one class per axis: the AxisClasses class
// where both faces contain the axis, the cell index on the face that contains it where only one does,
// 0 where neither does (parallel faces).
struct PairTable {
    int a = 0, b = 0;
    std::array<int, 3> dim{1, 1, 1};
    std::size_t first = 0;  // offset into the concatenated values

    std::size_t size() const { return std::size_t(dim[0]) * dim[1] * dim[2]; }
    std::array<std::size_t, 3> strides() const { return {std::size_t(dim[1]) * dim[2], std::size_t(dim[2]), 1}; }
};

}  // namespace

const char* surface_name(Surface s) {
    static constexpr std::array<const char*, kSurfaceCount> kNames{"floor",      "ceiling",   "light",    "wall_north",
                                                                   "wall_south", "wall_east", "wall_west"};
    return kNames.at(static_cast<std::size_t>(s));
}

scene::Scene make_room_scene(const Room& room) {
    validate(room);
    scene::Scene s;
    s.path = "room_reference";  // named in any message about the scene
    for (int i = 0; i < kSurfaceCount; ++i) {
        scene::Material m;
        m.name = surface_name(Surface(i));
        m.base_color = room.rho[i];
        m.emission = room.emission[i];
        s.materials.push_back(m);
        s.nodes.push_back({surface_name(Surface(i)), -1});  // built in memory: no glTF node
    }
    // Material and node of a surface are its index; validate() kept every reflectance <= kMaxReflectance.
    std::uint32_t primitive = 0;
    auto add_quad = [&](const std::array<glm::dvec3, 4>& q, Surface surface) {
        const auto id = static_cast<std::uint32_t>(surface);
        scene::add_quad_to(s, q[0], q[1], q[2], q[3], id, id, primitive++);
    };
    for (const Face& f : kFaces) {
        if (f.surface != Surface::ceiling) {
            add_quad(face_rectangle(f, room.size, 0.0, room.size[f.u], 0.0, room.size[f.v]), f.surface);
            continue;
        }
        // The ceiling as the 3 × 3 rectangles cut by the light's edges, the middle one being the light;
        // empty ones (a light touching a wall) are left out.
        const std::array<double, 4> xs{0.0, room.light_min.x, room.light_max.x, room.size.x};
        const std::array<double, 4> zs{0.0, room.light_min.y, room.light_max.y, room.size.z};
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                if (xs[i + 1] <= xs[i] || zs[j + 1] <= zs[j]) continue;
                add_quad(face_rectangle(f, room.size, xs[i], xs[i + 1], zs[j], zs[j + 1]),
                         i == 1 && j == 1 ? Surface::light : Surface::ceiling);
            }
    }
    s.bbox_min = glm::dvec3(0.0);
    s.bbox_max = room.size;
    return s;
}

RoomGrid make_room_grid(const Room& room, double cell_size) {
    validate(room);
    if (!(cell_size > 0.0) || !std::isfinite(cell_size))
        throw std::invalid_argument("room_reference: the cell size must be positive");
    RoomGrid g;
    g.room = room;
    g.cell_size = cell_size;
    // Breakpoints: the box, and on x and z the light's edges, so no cell straddles the light's border.
    const std::array<std::vector<double>, 3> breaks{{{0.0, room.light_min.x, room.light_max.x, room.size.x},
                                                     {0.0, room.size.y},
                                                     {0.0, room.light_min.y, room.light_max.y, room.size.z}}};
    for (int k = 0; k < 3; ++k) {
        std::vector<double>& e = g.edges[k];
        e.push_back(0.0);
        for (std::size_t b = 1; b < breaks[k].size(); ++b) {
            const double lo = breaks[k][b - 1], hi = breaks[k][b];
            if (hi <= lo) continue;  // the light touches a wall
            // The 1e-9 keeps an exact multiple (1.0 / 0.1) from becoming one cell more through rounding.
            const double parts = std::max(1.0, std::ceil((hi - lo) / cell_size - 1e-9));
            if (parts > double(kMaxCells)) throw std::invalid_argument("room_reference: too many cells");
            for (int p = 1; p < int(parts); ++p) e.push_back(lo + (hi - lo) * p / parts);
            e.push_back(hi);
        }
    }
    std::size_t total = 0;
    for (const Face& f : kFaces) total += (g.edges[f.u].size() - 1) * (g.edges[f.v].size() - 1);
    if (total > kMaxCells)
        throw std::invalid_argument("room_reference: " + std::to_string(total) + " cells at cell size " +
                                    std::to_string(cell_size) + " m, more than " + std::to_string(kMaxCells));
    g.cells.reserve(total);
    for (int fi = 0; fi < 6; ++fi) {
        const Face& f = kFaces[fi];
        const std::vector<double>&eu = g.edges[f.u], &ev = g.edges[f.v];
        for (std::size_t i = 0; i + 1 < eu.size(); ++i)
            for (std::size_t j = 0; j + 1 < ev.size(); ++j) {
                Cell c;
                c.v = face_rectangle(f, room.size, eu[i], eu[i + 1], ev[j], ev[j + 1]);
                c.centre = 0.25 * (c.v[0] + c.v[1] + c.v[2] + c.v[3]);
                c.normal = inward_normal(f);
                c.area = (eu[i + 1] - eu[i]) * (ev[j + 1] - ev[j]);
                c.face = fi;
                c.surface = f.surface;
                if (f.surface == Surface::ceiling && c.centre.x > room.light_min.x && c.centre.x < room.light_max.x &&
                    c.centre.z > room.light_min.y && c.centre.z < room.light_max.y)
                    c.surface = Surface::light;
                g.cells.push_back(c);
            }
    }
    return g;
}

std::size_t RoomGrid::cell_at(const glm::dvec3& point, const glm::dvec3& normal) const {
    int axis = 0;
    for (int k = 1; k < 3; ++k)
        if (std::abs(normal[k]) > std::abs(normal[axis])) axis = k;
    const bool upper = normal[axis] < 0.0;  // inward −axis: the face at size[axis]
    int fi = 0;
    while (kFaces[fi].axis != axis || kFaces[fi].upper != upper) ++fi;
    const Face& f = kFaces[fi];
    const double tol = 1e-6 * std::max({room.size.x, room.size.y, room.size.z});
    const double plane = upper ? room.size[axis] : 0.0;
    if (!(std::abs(point[axis] - plane) <= tol) || !(point[f.u] >= -tol && point[f.u] <= room.size[f.u] + tol) ||
        !(point[f.v] >= -tol && point[f.v] <= room.size[f.v] + tol))
        throw std::invalid_argument("room_reference: point is not on the room face its normal names");
    auto index = [&](int k) {
        const std::vector<double>& e = edges[k];
        const long i = long(std::upper_bound(e.begin(), e.end(), point[k]) - e.begin()) - 1;
        return std::size_t(std::clamp(i, 0L, long(e.size()) - 2));
    };
    std::size_t first = 0;
    for (int i = 0; i < fi; ++i) first += (edges[kFaces[i].u].size() - 1) * (edges[kFaces[i].v].size() - 1);
    return first + index(f.u) * (edges[f.v].size() - 1) + index(f.v);
}

double cell_form_factor(const Cell& from, const Cell& to) {
    // With P(s,t) over the unit square, F = (1/A) ∫ F(dA → to) dA = ∫∫ F(P(s,t) → to) ds dt.
    return integrate(from.v[0], from.v[1] - from.v[0], from.v[3] - from.v[0], from.normal, to, bounds(to.v.data(), 4),
                     0.0, 1.0, 0.0, 1.0, 0);
}

RoomFormFactors room_form_factors(const Room& room, double cell_size) {
    RoomFormFactors ff;
    ff.grid = make_room_grid(room, cell_size);
    const RoomGrid& g = ff.grid;
    const std::size_t n = g.cells.size();

    const double quantum = 1e-9 * std::max({room.size.x, room.size.y, room.size.z});
    std::array<AxisClasses, 3> axes;
    for (int k = 0; k < 3; ++k) axes[k] = classify_axis(g.edges[k], quantum);
    std::array<std::size_t, 7> face_first{};
    for (int fi = 0; fi < 6; ++fi)
        face_first[fi + 1] = face_first[fi] + std::size_t(axes[kFaces[fi].u].n) * axes[kFaces[fi].v].n;

    // One table per ordered pair of distinct faces.
    std::vector<PairTable> tables;
    std::size_t values = 0;
    for (int a = 0; a < 6; ++a)
        for (int b = 0; b < 6; ++b) {
            if (a == b) continue;
            PairTable t;
            t.a = a;
            t.b = b;
            for (int k = 0; k < 3; ++k) {
                const bool in_a = kFaces[a].axis != k, in_b = kFaces[b].axis != k;
                t.dim[k] = in_a && in_b ? static_cast<int>(axes[k].rep.size()) : in_a || in_b ? axes[k].n : 1;
            }
            t.first = values;
            values += t.size();
            tables.push_back(t);
        }

    // Integrate each distinct configuration once, from a representative cell pair.
    std::vector<double> value(values);
    auto cell_index = [&](int face, const std::array<int, 3>& idx) {
        const Face& f = kFaces[face];
        return face_first[face] + std::size_t(idx[f.u]) * axes[f.v].n + idx[f.v];
    };
    parallel_for(values, 64, [&](std::size_t g_index) {
        const auto it = std::upper_bound(tables.begin(), tables.end(), g_index,
                                         [](std::size_t x, const PairTable& t) { return x < t.first; });
        const PairTable& t = *(it - 1);
        std::size_t flat = g_index - t.first;
        std::array<int, 3> c{};
        for (int k = 2; k >= 0; --k) {
            c[k] = static_cast<int>(flat % std::size_t(t.dim[k]));
            flat /= std::size_t(t.dim[k]);
        }
        std::array<int, 3> ia{}, ib{};  // per-axis cell indices of the representative pair
        for (int k = 0; k < 3; ++k) {
            const bool in_a = kFaces[t.a].axis != k, in_b = kFaces[t.b].axis != k;
            if (in_a && in_b)
                std::tie(ia[k], ib[k]) = axes[k].rep[std::size_t(c[k])];
            else if (in_b)
                ib[k] = c[k];
            else if (in_a)
                ia[k] = c[k];
        }
        value[g_index] = cell_form_factor(g.cells[cell_index(t.a, ia)], g.cells[cell_index(t.b, ib)]);
    });

    // Scatter the tables into the dense matrix, one row at a time.
    ff.f.assign(n * n, 0.0f);
    parallel_for(n, 16, [&](std::size_t row) {
        int a = 0;
        while (row >= face_first[a + 1]) ++a;
        const Face& fa = kFaces[a];
        std::array<int, 3> ia{};
        const std::size_t local = row - face_first[a];
        ia[fa.u] = static_cast<int>(local / std::size_t(axes[fa.v].n));
        ia[fa.v] = static_cast<int>(local % std::size_t(axes[fa.v].n));
        float* out = ff.f.data() + row * n;
        std::vector<std::size_t> off_u, off_v;
        for (const PairTable& t : tables) {
            if (t.a != a) continue;
            const Face& fb = kFaces[t.b];
            const auto stride = t.strides();
            // Contribution of axis k, which face b contains, for b's cell index j along it.
            auto term = [&](int k, int j) {
                const int c = kFaces[a].axis != k ? axes[k].of[std::size_t(ia[k]) * axes[k].n + j] : j;
                return std::size_t(c) * stride[k];
            };
            const std::size_t base =
                t.first + (fb.axis != fa.axis ? std::size_t(ia[fb.axis]) * stride[fb.axis] : std::size_t(0));
            off_u.resize(std::size_t(axes[fb.u].n));
            off_v.resize(std::size_t(axes[fb.v].n));
            for (int j = 0; j < axes[fb.u].n; ++j) off_u[std::size_t(j)] = term(fb.u, j);
            for (int j = 0; j < axes[fb.v].n; ++j) off_v[std::size_t(j)] = term(fb.v, j);
            float* dst = out + face_first[t.b];
            for (std::size_t ju = 0; ju < off_u.size(); ++ju)
                for (std::size_t jv = 0; jv < off_v.size(); ++jv)
                    *dst++ = static_cast<float>(value[base + off_u[ju] + off_v[jv]]);
        }
    });
    return ff;
}

namespace {

using Channels = std::array<std::vector<double>, 3>;

// out_c = F · in_c for the three channels in one threaded pass over the matrix (the pass is memory-bound,
// so the channels share it).
void multiply(const RoomFormFactors& ff, const std::array<std::size_t, 7>& face_first,
              const std::array<const double*, 3>& in, const std::array<double*, 3>& out) {
    const std::size_t n = ff.size();
    parallel_for(n, 32, [&](std::size_t i) {
        const float* row = ff.f.data() + i * n;
        // Four partial sums per channel: one chain of dependent adds would make the loop latency-bound; the
        // order is fixed, so the result does not depend on the thread count.
        double h[3][4] = {};
        // The row's own face is all zeros (coplanar cells): skipping it saves ~1/5 of the work.
        const int face = ff.grid.cells[i].face;
        for (const auto& [lo, hi] : {std::pair(std::size_t(0), face_first[face]), std::pair(face_first[face + 1], n)}) {
            std::size_t j = lo;
            for (; j + 4 <= hi; j += 4)
                for (int c = 0; c < 3; ++c)
                    for (int u = 0; u < 4; ++u) h[c][u] += double(row[j + u]) * in[c][j + u];
            for (; j < hi; ++j)
                for (int c = 0; c < 3; ++c) h[c][0] += double(row[j]) * in[c][j];
        }
        for (int c = 0; c < 3; ++c) out[c][i] = (h[c][0] + h[c][1]) + (h[c][2] + h[c][3]);
    });
}

double dot(const std::vector<double>& a, const std::vector<double>& b) {
    double s = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
    return s;
}

double max_abs(const std::vector<double>& a) {
    double m = 0.0;
    for (double x : a) m = std::max(m, std::abs(x));
    return m;
}

// One channel's restarted-GMRES state: the Arnoldi basis and the Givens-rotated Hessenberg matrix.
struct Krylov {
    std::vector<std::vector<double>> basis;
    std::vector<std::vector<double>> r;  // r[col][row], upper triangular after the rotations
    std::vector<double> cs, sn, g;
    int steps = 0;
    bool active = false;
    double target = 0.0;  // stop once the residual's 2-norm (≥ its max-norm) is below this
};

}  // namespace

RoomSolution solve_room(const RoomFormFactors& ff) {
    RoomSolution sol;
    sol.grid = ff.grid;
    const std::size_t n = ff.size();
    const Room& room = ff.grid.room;
    Channels e, rho;
    for (int c = 0; c < 3; ++c) {
        e[c].resize(n);
        rho[c].resize(n);
        for (std::size_t i = 0; i < n; ++i) {
            const auto s = static_cast<std::size_t>(ff.grid.cells[i].surface);
            e[c][i] = room.emission[s][c];
            rho[c][i] = room.rho[s][c];
        }
    }
    std::array<std::size_t, 7> face_first{};  // cells are stored face by face
    for (const Cell& c : ff.grid.cells) ++face_first[std::size_t(c.face) + 1];
    for (int f = 0; f < 6; ++f) face_first[f + 1] += face_first[f];

    // Restarted GMRES on (I − ρF)B = E, the three channels in lockstep so each matrix pass serves all of
    // them. F is a discretised compact operator: only a few of its eigenvalues are far from 0, so the
    // Krylov residual falls superlinearly (~19 products in all on the default room, where Jacobi needs 55
    // at its (max ρ)-like rate). Each cycle starts from the true residual, which is also the exit test.
    constexpr double kTolerance = 1e-12;  // max |E + ρFB − B| / max B, per channel
    constexpr int kRestart = 40, kMaxCycles = 100;
    Channels x = e, h, w;
    for (int c = 0; c < 3; ++c) {
        h[c].resize(n);
        w[c].resize(n);
    }
    const std::vector<double> zeros(n, 0.0);
    auto ptrs = [](Channels& v) { return std::array<double*, 3>{v[0].data(), v[1].data(), v[2].data()}; };
    std::array<Krylov, 3> kry;
    for (int cycle = 0;; ++cycle) {
        multiply(ff, face_first, {x[0].data(), x[1].data(), x[2].data()}, ptrs(h));
        ++sol.iterations;
        sol.residual = 0.0;
        for (int c = 0; c < 3; ++c) {
            for (std::size_t i = 0; i < n; ++i) w[c][i] = e[c][i] + rho[c][i] * h[c][i] - x[c][i];
            const double scale = max_abs(x[c]);
            if (scale > 0.0) sol.residual = std::max(sol.residual, max_abs(w[c]) / scale);
            Krylov& k = kry[c];
            k = Krylov{};
            k.target = 0.5 * kTolerance * scale;
            const double beta = std::sqrt(dot(w[c], w[c]));
            k.active = beta > k.target;
            if (!k.active) continue;
            k.basis.push_back(w[c]);
            for (double& v : k.basis[0]) v /= beta;
            k.g.push_back(beta);
        }
        if (sol.residual < kTolerance) break;
        if (cycle == kMaxCycles)
            throw InternalError("room_reference: GMRES did not converge (residual " + std::to_string(sol.residual) +
                                ")");
        for (int step = 0; step < kRestart; ++step) {
            std::array<const double*, 3> in{};
            bool any = false;
            for (int c = 0; c < 3; ++c) {
                in[c] = kry[c].active ? kry[c].basis.back().data() : zeros.data();
                any = any || kry[c].active;
            }
            if (!any) break;
            multiply(ff, face_first, in, ptrs(w));
            ++sol.iterations;
            for (int c = 0; c < 3; ++c) {
                Krylov& k = kry[c];
                if (!k.active) continue;
                std::vector<double>& v = w[c];
                const std::vector<double>& q = k.basis.back();
                for (std::size_t i = 0; i < n; ++i) v[i] = q[i] - rho[c][i] * v[i];  // (I − ρF) q
                std::vector<double> col(std::size_t(step) + 2);
                for (int i = 0; i <= step; ++i) {  // modified Gram–Schmidt
                    col[i] = dot(v, k.basis[i]);
                    for (std::size_t t = 0; t < n; ++t) v[t] -= col[i] * k.basis[i][t];
                }
                const double next = std::sqrt(dot(v, v));
                col[step + 1] = next;
                for (int i = 0; i < step; ++i) {
                    const double a = col[i], b = col[i + 1];
                    col[i] = k.cs[i] * a + k.sn[i] * b;
                    col[i + 1] = -k.sn[i] * a + k.cs[i] * b;
                }
                const double rr = std::hypot(col[step], col[step + 1]);
                k.cs.push_back(col[step] / rr);
                k.sn.push_back(col[step + 1] / rr);
                col[step] = rr;
                col.pop_back();
                k.r.push_back(col);
                k.g.push_back(-k.sn[step] * k.g[step]);
                k.g[step] *= k.cs[step];
                k.steps = step + 1;
                // Stop at the target, or when the Krylov space is exhausted (then the solution is exact).
                if (std::abs(k.g[step + 1]) <= k.target || next <= 1e-300) {
                    k.active = false;
                    continue;
                }
                for (double& t : v) t /= next;
                k.basis.push_back(v);
            }
        }
        // x += Σ y_i q_i with R y = g (back substitution).
        for (int c = 0; c < 3; ++c) {
            Krylov& k = kry[c];
            std::vector<double> y(std::size_t(k.steps), 0.0);
            for (int i = k.steps - 1; i >= 0; --i) {
                double s = k.g[i];
                for (int j = i + 1; j < k.steps; ++j) s -= k.r[j][i] * y[j];
                y[i] = s / k.r[i][i];
            }
            for (int i = 0; i < k.steps; ++i)
                for (std::size_t t = 0; t < n; ++t) x[c][t] += y[i] * k.basis[i][t];
        }
    }
    // The last product was F·B for the returned B.
    sol.radiosity.resize(n);
    sol.incident.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        sol.radiosity[i] = {x[0][i], x[1][i], x[2][i]};
        sol.incident[i] = {h[0][i], h[1][i], h[2][i]};
    }

    std::array<glm::dvec3, kSurfaceCount> sum{};
    std::array<double, kSurfaceCount> area{};
    for (std::size_t i = 0; i < n; ++i) {
        const Cell& c = ff.grid.cells[i];
        sum[std::size_t(c.surface)] += c.area * sol.radiosity[i];
        area[std::size_t(c.surface)] += c.area;
    }
    for (int s = 0; s < kSurfaceCount; ++s)
        sol.surface_average.emplace_back(surface_name(Surface(s)), area[s] > 0.0 ? sum[s] / area[s] : glm::dvec3(0.0));
    return sol;
}

RoomSolution solve_room(const Room& room, double cell_size) {
    return solve_room(room_form_factors(room, cell_size));
}

glm::dvec3 RoomSolution::radiosity_at(const glm::dvec3& point, const glm::dvec3& normal) const {
    const Cell& here = grid.cells[grid.cell_at(point, normal)];
    glm::dvec3 gathered(0.0);
    for (std::size_t j = 0; j < grid.cells.size(); ++j)
        if (grid.cells[j].face != here.face)
            gathered += point_to_cell(point, here.normal, grid.cells[j]) * radiosity[j];
    const auto s = static_cast<std::size_t>(here.surface);
    return grid.room.emission[s] + grid.room.rho[s] * gathered;
}

glm::dvec3 RoomSolution::average_over(const mesh::Polygon& polygon) const {
    if (polygon.n != 3 && polygon.n != 4) throw std::invalid_argument("average_over: a polygon has 3 or 4 vertices");
    const glm::dvec3* v = polygon.v.data();
    const glm::dvec3 cross =
        polygon.n == 3 ? glm::cross(v[1] - v[0], v[2] - v[0]) : glm::cross(v[2] - v[0], v[3] - v[1]);
    const double twice_area = glm::length(cross);
    if (!(twice_area > 0.0)) throw std::invalid_argument("average_over: degenerate polygon");
    const glm::dvec3 normal = cross / twice_area;
    glm::dvec3 sum(0.0);
    double weight = 0.0;
    if (polygon.n == 3) {
        // Degree-2 rule, points at barycentric (2/3, 1/6, 1/6) and permutations, equal weights.
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3 p = (2.0 / 3.0) * v[k] + (1.0 / 6.0) * (v[(k + 1) % 3] + v[(k + 2) % 3]);
            sum += radiosity_at(p, normal);
            weight += 1.0;
        }
        return sum / weight;
    }
    // 2 × 2 Gauss–Legendre through the bilinear map of the quad, weighted by its Jacobian (exact for
    // parallelograms, right for any convex quad).
    constexpr double kG = 0.5 / 1.7320508075688772;
    for (double s : {0.5 - kG, 0.5 + kG})
        for (double t : {0.5 - kG, 0.5 + kG}) {
            const glm::dvec3 p = (1 - s) * (1 - t) * v[0] + s * (1 - t) * v[1] + s * t * v[2] + (1 - s) * t * v[3];
            const glm::dvec3 ds = (1 - t) * (v[1] - v[0]) + t * (v[2] - v[3]);
            const glm::dvec3 dt = (1 - s) * (v[3] - v[0]) + s * (v[2] - v[1]);
            const double jacobian = glm::length(glm::cross(ds, dt));
            sum += jacobian * radiosity_at(p, normal);
            weight += jacobian;
        }
    return sum / weight;
}

std::vector<Probe> room_probes(const Room& room, int per_edge) {
    validate(room);
    if (per_edge < 1) throw std::invalid_argument("room_probes: per_edge must be >= 1");
    std::vector<Probe> probes;
    for (int si = 0; si < kSurfaceCount; ++si) {
        const auto s = Surface(si);
        const Face& f = kFaces[face_of_surface(s)];
        const std::array<double, 4> ext = surface_extent(room, s);
        for (int i = 0; i < per_edge; ++i)
            for (int j = 0; j < per_edge; ++j) {
                const double u = ext[0] + (ext[1] - ext[0]) * (i + 0.5) / per_edge;
                const double v = ext[2] + (ext[3] - ext[2]) * (j + 0.5) / per_edge;
                // Ceiling points on or in the light's closed rectangle are not the ceiling (and on its
                // border the radiosity jumps, so neither surface owns them).
                if (s == Surface::ceiling && u >= room.light_min.x && u <= room.light_max.x && v >= room.light_min.y &&
                    v <= room.light_max.y)
                    continue;
                Probe p;
                p.surface = surface_name(s);
                p.point[f.axis] = f.upper ? room.size[f.axis] : 0.0;
                p.point[f.u] = u;
                p.point[f.v] = v;
                p.normal = inward_normal(f);
                probes.push_back(p);
            }
    }
    return probes;
}

}  // namespace hemirad::bench
