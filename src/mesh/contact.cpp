// Contact lines between surfaces (see contact.h).
#include "mesh/contact.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <unordered_map>

#include "core/parallel.h"

namespace hemirad::mesh {

namespace {

using glm::dvec3;

// Newell's normal (unit; zero for a degenerate polygon).
dvec3 normal_of(const Polygon& p) {
    dvec3 n(0.0);
    for (int i = 0; i < p.n; ++i) n += glm::cross(p.v[std::size_t(i)], p.v[std::size_t((i + 1) % p.n)]);
    const double length = glm::length(n);
    return length > 0.0 ? n / length : dvec3(0.0);
}

// Whether p's projection onto the polygon's plane lies inside it (on an edge counts).
bool projects_inside(const dvec3& p, const Polygon& poly, const dvec3& normal) {
    for (int i = 0; i < poly.n; ++i) {
        const dvec3& a = poly.v[std::size_t(i)];
        const dvec3& b = poly.v[std::size_t((i + 1) % poly.n)];
        if (glm::dot(glm::cross(b - a, p - a), normal) < 0.0) return false;
    }
    return true;
}

double point_segment(const dvec3& p, const dvec3& a, const dvec3& b) {
    const dvec3 ab = b - a;
    const double length2 = glm::dot(ab, ab);
    const double t = length2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / length2, 0.0, 1.0) : 0.0;
    return glm::length(p - (a + t * ab));
}

// The distance between segments p1–q1 and p2–q2 (Ericson, Real-Time Collision Detection, 5.1.9).
double segment_segment(const dvec3& p1, const dvec3& q1, const dvec3& p2, const dvec3& q2) {
    const dvec3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
    const double a = glm::dot(d1, d1), e = glm::dot(d2, d2), f = glm::dot(d2, r);
    if (a <= 0.0 || e <= 0.0) return a <= 0.0 ? point_segment(p1, p2, q2) : point_segment(p2, p1, q1);
    const double c = glm::dot(d1, r), b = glm::dot(d1, d2);
    const double denominator = a * e - b * b;
    double s = denominator > 0.0 ? std::clamp((b * f - c * e) / denominator, 0.0, 1.0) : 0.0;
    double t = (b * s + f) / e;
    if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
    } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
    }
    return glm::length((p1 + s * d1) - (p2 + t * d2));
}

double point_polygon(const dvec3& p, const Polygon& poly, const dvec3& normal) {
    if (normal != dvec3(0.0) && projects_inside(p, poly, normal))
        return std::abs(glm::dot(p - poly.v[0], normal));
    double d = std::numeric_limits<double>::infinity();
    for (int i = 0; i < poly.n; ++i) d = std::min(d, point_segment(p, poly.v[std::size_t(i)], poly.v[std::size_t((i + 1) % poly.n)]));
    return d;
}

// Whether segment a–b passes through the polygon (strictly from one side of its plane to the other).
bool pierces(const dvec3& a, const dvec3& b, const Polygon& poly, const dvec3& normal) {
    if (normal == dvec3(0.0)) return false;
    const double da = glm::dot(a - poly.v[0], normal), db = glm::dot(b - poly.v[0], normal);
    if ((da >= 0.0 && db >= 0.0) || (da <= 0.0 && db <= 0.0)) return false;
    return projects_inside(a + (da / (da - db)) * (b - a), poly, normal);
}

// How far the polygon reaches in front of the plane through `point` with unit `normal`.
double reach_in_front(const Polygon& p, const dvec3& point, const dvec3& normal) {
    double most = -std::numeric_limits<double>::infinity();
    for (int i = 0; i < p.n; ++i) most = std::max(most, glm::dot(p.v[std::size_t(i)] - point, normal));
    return most;
}

}  // namespace

double polygon_distance(const Polygon& a, const Polygon& b) {
    const dvec3 na = normal_of(a), nb = normal_of(b);
    double d = std::numeric_limits<double>::infinity();
    for (int i = 0; i < a.n; ++i) d = std::min(d, point_polygon(a.v[std::size_t(i)], b, nb));
    for (int j = 0; j < b.n; ++j) d = std::min(d, point_polygon(b.v[std::size_t(j)], a, na));
    for (int i = 0; i < a.n; ++i) {
        const dvec3 &p = a.v[std::size_t(i)], &q = a.v[std::size_t((i + 1) % a.n)];
        if (pierces(p, q, b, nb)) return 0.0;
        for (int j = 0; j < b.n; ++j) d = std::min(d, segment_segment(p, q, b.v[std::size_t(j)], b.v[std::size_t((j + 1) % b.n)]));
    }
    for (int j = 0; j < b.n; ++j)
        if (pierces(b.v[std::size_t(j)], b.v[std::size_t((j + 1) % b.n)], a, na)) return 0.0;
    return d;
}

std::vector<bool> contact_elements(const Mesh& mesh, double min_size) {
    constexpr double kTouch = 0.01;       // touching: within this much of the larger longest edge
    // Normals within the crease angle (the welder's): one smoothly shaded surface folding gently
    // (a tessellated bowl), not a junction. Parallel faces that touch (a book lying on a table)
    // fail the test in front below.
    const double kSmoothCos = std::cos(kCreaseAngle);
    const std::size_t count = mesh.elements.size();
    std::vector<bool> marked(count, false);
    if (count == 0) return marked;

    std::vector<double> longest(count);
    std::vector<dvec3> lo(count), hi(count);
    double mean = 0.0, largest = 0.0;
    for (std::size_t k = 0; k < count; ++k) {
        const Polygon& p = mesh.elements[k].poly;
        longest[k] = longest_edge(p);
        mean += longest[k] / double(count);
        largest = std::max(largest, longest[k]);
        lo[k] = hi[k] = p.v[0];
        for (int i = 1; i < p.n; ++i) {
            lo[k] = glm::min(lo[k], p.v[std::size_t(i)]);
            hi[k] = glm::max(hi[k], p.v[std::size_t(i)]);
        }
        lo[k] -= dvec3(kTouch * longest[k]);
        hi[k] += dvec3(kTouch * longest[k]);
    }
    // Cells twice the mean element, no fewer than a 64th of the largest (a sky dome's faces).
    const double cell = std::max(2.0 * mean, largest / 64.0);
    if (!(cell > 0.0) || !std::isfinite(cell)) return marked;
    const auto cell_of = [&](const dvec3& p) { return glm::i64vec3(glm::floor(p / cell)); };
    const auto key = [](const glm::i64vec3& c) {
        return (std::uint64_t(c.x) * 0x9E3779B97F4A7C15ull) ^ (std::uint64_t(c.y) * 0xC2B2AE3D27D4EB4Full) ^
               (std::uint64_t(c.z) * 0x165667B19E3779F9ull);
    };
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> grid;
    for (std::size_t k = 0; k < count; ++k) {
        if (mesh.elements[k].coarse) continue;
        const glm::i64vec3 a = cell_of(lo[k]), b = cell_of(hi[k]);
        for (std::int64_t x = a.x; x <= b.x; ++x)
            for (std::int64_t y = a.y; y <= b.y; ++y)
                for (std::int64_t z = a.z; z <= b.z; ++z) grid[key({x, y, z})].push_back(static_cast<std::uint32_t>(k));
    }
    // The cells on the host's threads; a pair marks both elements, whichever cell finds it first.
    std::vector<const std::pair<const std::uint64_t, std::vector<std::uint32_t>>*> cells;
    cells.reserve(grid.size());
    for (const auto& entry : grid) cells.push_back(&entry);
    std::unique_ptr<std::atomic<unsigned char>[]> marks(new std::atomic<unsigned char>[count]);
    for (std::size_t k = 0; k < count; ++k) marks[k].store(0, std::memory_order_relaxed);
    parallel::for_each(cells.size(), 16, [&](std::size_t c) {
        const std::uint64_t where = cells[c]->first;
        const std::vector<std::uint32_t>& members = cells[c]->second;
        for (std::size_t i = 0; i < members.size(); ++i) {
            const std::uint32_t a = members[i];
            const Element& ea = mesh.elements[a];
            for (std::size_t j = i + 1; j < members.size(); ++j) {
                const std::uint32_t b = members[j];
                const Element& eb = mesh.elements[b];
                if (ea.patch == eb.patch) continue;
                if (!(longest[a] > min_size) && !(longest[b] > min_size)) continue;
                const dvec3 from = glm::max(lo[a], lo[b]), to = glm::min(hi[a], hi[b]);
                if (from.x > to.x || from.y > to.y || from.z > to.z) continue;
                if (key(cell_of(from)) != where) continue;  // each pair once: in the cell of its overlap's corner
                if (glm::dot(ea.normal, eb.normal) > kSmoothCos) continue;
                const double tolerance = kTouch * std::max(longest[a], longest[b]);
                if (reach_in_front(eb.poly, ea.centroid, ea.normal) <= tolerance ||
                    reach_in_front(ea.poly, eb.centroid, eb.normal) <= tolerance)
                    continue;  // a convex edge, or one behind the other
                if (polygon_distance(ea.poly, eb.poly) > tolerance) continue;
                if (longest[a] > min_size) marks[a].store(1, std::memory_order_relaxed);
                if (longest[b] > min_size) marks[b].store(1, std::memory_order_relaxed);
            }
        }
    });
    for (std::size_t k = 0; k < count; ++k) marked[k] = marks[k].load(std::memory_order_relaxed) != 0;
    return marked;
}

}  // namespace hemirad::mesh
