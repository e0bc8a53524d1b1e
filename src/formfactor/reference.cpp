// The scalar reference hemicube: clip each element to each face's frustum, rasterize it at
// cell centres with a depth test, then sum the delta form factors of the cells each element won.
#include "formfactor/reference.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace hemirad::formfactor {
namespace {

constexpr int kMaxClipped = 4 + 5;  // a convex n-gon clipped by 5 planes gains at most 5 vertices

struct ClipPolygon {
    glm::dvec3 v[kMaxClipped + 1];
    int n = 0;
};

bool lexicographically_less(const glm::dvec3& a, const glm::dvec3& b) {
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    return a.z < b.z;
}

// Keeps the part of `poly` where plane(p) >= 0 (Sutherland–Hodgman). The crossing point is
// computed from the lexicographically smaller endpoint, so an edge shared by two elements is
// cut at bit-identical points whichever direction each element walks it.
template <class Plane>
void clip(ClipPolygon& poly, Plane plane) {
    ClipPolygon out;
    for (int i = 0; i < poly.n; ++i) {
        const glm::dvec3& a = poly.v[i];
        const glm::dvec3& b = poly.v[(i + 1) % poly.n];
        const double fa = plane(a), fb = plane(b);
        if (fa >= 0.0) out.v[out.n++] = a;
        if ((fa >= 0.0) != (fb >= 0.0)) {
            const bool a_first = lexicographically_less(a, b);
            const glm::dvec3& p = a_first ? a : b;
            const glm::dvec3& q = a_first ? b : a;
            const double fp = a_first ? fa : fb, fq = a_first ? fb : fa;
            out.v[out.n++] = p + (q - p) * (fp / (fp - fq));
        }
    }
    poly = out;
}

// Clips only where the plane cuts the polygon; false when it is wholly outside.
template <class Plane>
bool clip_if_needed(ClipPolygon& poly, Plane plane) {
    bool any_in = false, any_out = false;
    for (int i = 0; i < poly.n; ++i) {
        const bool in = plane(poly.v[i]) >= 0.0;
        any_in = any_in || in;
        any_out = any_out || !in;
    }
    if (any_out && any_in) clip(poly, plane);
    return any_in && poly.n >= 3;
}

// Top-left rule for a counter-clockwise polygon: a cell centre exactly on an edge belongs to
// the polygon only for edges going down, or going right along a horizontal; the neighbour
// that shares the edge walks it the other way, so exactly one of the two owns the centre.
bool owns_edge_point(double dx, double dy) { return dy < 0.0 || (dy == 0.0 && dx > 0.0); }

// Signed area of (a, b, p), positive when p is left of a→b. Evaluated from the endpoint that is
// lower in (y, x) order, so the two polygons sharing an edge get exactly opposite values.
double edge_function(double ax, double ay, double bx, double by, double x, double y) {
    const bool forward = ay < by || (ay == by && ax < bx);
    if (!forward) return -edge_function(bx, by, ax, ay, x, y);
    return (bx - ax) * (y - ay) - (by - ay) * (x - ax);
}

}  // namespace

bool ReferenceEngine::above_base_plane(const mesh::Polygon& poly, const Frame& frame) const {
    for (int i = 0; i < poly.n; ++i)
        if (frame.to_local(poly.v[i]).z > eps_) return true;
    return false;
}

ReferenceEngine::ReferenceEngine(const mesh::Mesh& mesh, const Settings& settings)
    : mesh_(mesh), settings_(settings), delta_(settings.hemicube) {
    if (settings.hemicube < 8 || settings.hemicube % 2 != 0)
        throw InternalError("hemicube resolution must be even and at least 8");
    eps_ = base_plane_epsilon(mesh);
    ids_.assign(delta_.cells(), kEmpty);
    depth_.assign(delta_.cells(), 0.0);
    owner_.assign(delta_.cells(), -1);
    back_.assign(delta_.cells(), 0);
}

void ReferenceEngine::shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) {
    const mesh::Patch& shooter = mesh_.patches.at(patch);
    const Frame frame = make_frame(shooter, settings_.seed, shot);
    last_batch_ = 1;
    const int n = delta_.n();
    const double half = 0.5 * n;  // cells per unit of face coordinate

    std::fill(depth_.begin(), depth_.end(), 0.0);
    std::fill(owner_.begin(), owner_.end(), -1);
    std::fill(back_.begin(), back_.end(), 0);

    for (std::size_t k = 0; k < mesh_.elements.size(); ++k) {
        const mesh::Element& e = mesh_.elements[k];
        if (e.patch == patch) continue;  // the shooter's own elements lie in its base plane
        if (k == mesh_.patches[e.patch].first_element && !above_base_plane(mesh_.patches[e.patch].poly, frame)) {
            k += mesh_.patches[e.patch].element_count - 1;  // elements tile their patch: all are below
            continue;
        }
        const double facing = glm::dot(e.normal, frame.origin - e.centroid);
        const bool is_back = facing < 0.0;
        if (is_back && e.has_twin) continue;  // the twin draws this surface from this side

        glm::dvec3 local[4];
        bool above = false;
        for (int i = 0; i < e.poly.n; ++i) {
            local[i] = frame.to_local(e.poly.v[i]);
            above = above || local[i].z > eps_;
        }
        if (!above) continue;
        const glm::dvec3 normal_local{glm::dot(e.normal, frame.u), glm::dot(e.normal, frame.v), glm::dot(e.normal, frame.w)};

        for (int face = 0; face < kFaces; ++face) {
            ClipPolygon poly;
            for (int i = 0; i < e.poly.n; ++i) poly.v[poly.n++] = to_face(face, local[i]);
            // The face's frustum: the base plane z >= eps (z is d on top, v on the sides), then
            // |u| <= d and |v| <= d (v <= d only on the sides). Clipping is skipped for planes
            // no vertex crosses, and the face for a plane every vertex is outside of.
            const double eps = eps_;
            const auto base_plane = [eps, face](const glm::dvec3& p) { return (face == 0 ? p.z : p.y) - eps; };
            const auto right = [](const glm::dvec3& p) { return p.z - p.x; };
            const auto left = [](const glm::dvec3& p) { return p.z + p.x; };
            const auto top = [](const glm::dvec3& p) { return p.z - p.y; };
            const auto bottom = [](const glm::dvec3& p) { return p.z + p.y; };
            const bool visible = clip_if_needed(poly, base_plane) && clip_if_needed(poly, right) &&
                                 clip_if_needed(poly, left) && clip_if_needed(poly, top) &&
                                 (face != 0 || clip_if_needed(poly, bottom));
            if (!visible) continue;

            // The element's plane n·p = c in face coordinates gives depth exactly: with
            // s = u/d, t = v/d, 1/d = (n_u s + n_v t + n_d) / c, a linear function of s and t.
            const glm::dvec3 nf = to_face(face, normal_local);
            const double c = glm::dot(nf, poly.v[0]);
            if (std::abs(c) <= eps_ * 1e-3) continue;  // seen edge-on: covers no area
            const glm::dvec3 plane{nf.x / c, nf.y / c, nf.z / c};

            // Project to cell coordinates: x in [0, n), y in [0, rows).
            const double t0 = face == 0 ? 1.0 : 0.0;
            double px[kMaxClipped], py[kMaxClipped];
            double area2 = 0.0;
            for (int i = 0; i < poly.n; ++i) {
                px[i] = (poly.v[i].x / poly.v[i].z + 1.0) * half;
                py[i] = (poly.v[i].y / poly.v[i].z + t0) * half;
            }
            for (int i = 0; i < poly.n; ++i) {
                const int j = (i + 1) % poly.n;
                area2 += px[i] * py[j] - px[j] * py[i];
            }
            if (area2 == 0.0) continue;
            if (area2 < 0.0) {  // make counter-clockwise
                std::reverse(px, px + poly.n);
                std::reverse(py, py + poly.n);
            }
            double xmin = px[0], xmax = px[0], ymin = py[0], ymax = py[0];
            for (int i = 1; i < poly.n; ++i) {
                xmin = std::min(xmin, px[i]); xmax = std::max(xmax, px[i]);
                ymin = std::min(ymin, py[i]); ymax = std::max(ymax, py[i]);
            }
            const int rows = delta_.rows(face);
            const int i0 = std::max(0, static_cast<int>(std::floor(xmin - 0.5)));
            const int i1 = std::min(n - 1, static_cast<int>(std::ceil(xmax - 0.5)));
            const int j0 = std::max(0, static_cast<int>(std::floor(ymin - 0.5)));
            const int j1 = std::min(rows - 1, static_cast<int>(std::ceil(ymax - 0.5)));
            const std::size_t base = delta_.offset(face);

            for (int j = j0; j <= j1; ++j) {
                const double y = j + 0.5;
                for (int i = i0; i <= i1; ++i) {
                    const double x = i + 0.5;
                    bool inside = true;
                    for (int a = 0; a < poly.n && inside; ++a) {
                        const int b = (a + 1) % poly.n;
                        if (px[a] == px[b] && py[a] == py[b]) continue;  // clipping can repeat a vertex
                        const double edge = edge_function(px[a], py[a], px[b], py[b], x, y);
                        inside = edge > 0.0 || (edge == 0.0 && owns_edge_point(px[b] - px[a], py[b] - py[a]));
                    }
                    if (!inside) continue;
                    const double s = x / half - 1.0, t = y / half - t0;
                    const double inv_depth = plane.x * s + plane.y * t + plane.z;
                    const std::size_t cell = base + static_cast<std::size_t>(j) * n + i;
                    const bool nearer = inv_depth > depth_[cell] ||
                                        (inv_depth == depth_[cell] && owner_[cell] > static_cast<std::int32_t>(k));
                    if (owner_[cell] < 0 || nearer) {
                        depth_[cell] = inv_depth;
                        owner_[cell] = static_cast<std::int32_t>(k);
                        back_[cell] = is_back;
                    }
                }
            }
        }
    }

    out.F.assign(mesh_.elements.size(), 0.0);
    out.blocked = 0.0;
    const auto& table = delta_.table();
    for (std::size_t cell = 0; cell < owner_.size(); ++cell) {
        if (owner_[cell] < 0) {
            ids_[cell] = kEmpty;
        } else if (back_[cell]) {
            ids_[cell] = kBlocker;
            out.blocked += table[cell];
        } else {
            ids_[cell] = owner_[cell];
            out.F[static_cast<std::size_t>(owner_[cell])] += table[cell];
        }
    }
}

}  // namespace hemirad::formfactor
