// The scalar reference hemicube: clip each element to each face's frustum, rasterize it at
// cell centres with a depth test, then sum the delta form factors of the cells each element won.
#include "formfactor/reference.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "formfactor/clip.h"
#include "formfactor/parallel.h"
#include "hemicube_types.h"

namespace hemirad::formfactor {
namespace {

// A triangle or quad clipped by the 5 planes of a face: clip_convex adds at most one vertex per
// plane, whatever the rounding, so 4 + 5.
constexpr int kMaxClipped = 4 + 5;

struct ClipPolygon {
    glm::dvec3 v[kMaxClipped];
    int n = 0;
};

// Clips only where the plane cuts the polygon (clip_convex); false when it is wholly outside.
template <class Plane>
bool clip_if_needed(ClipPolygon& poly, Plane plane) {
    bool any_in = false, any_out = false;
    for (int i = 0; i < poly.n; ++i) {
        const bool in = plane(poly.v[i]) >= 0.0;
        any_in = any_in || in;
        any_out = any_out || !in;
    }
    if (any_out && any_in) {
        ClipPolygon out;
        out.n = clip_convex(poly.v, poly.n, plane, out.v);
        poly = out;
    }
    return any_in && poly.n >= 3;
}

// Top-left rule for a counter-clockwise polygon: a cell centre exactly on an edge belongs to
// the polygon only for edges going down, or going right along a horizontal; the neighbour
// that shares the edge walks it the other way, so exactly one of the two owns the centre.
bool owns_edge_point(std::int64_t dx, std::int64_t dy) { return dy < 0 || (dy == 0 && dx > 0); }

}  // namespace

std::int64_t snap(double cells) { return static_cast<std::int64_t>(std::floor(cells * kSubcell + 0.5)); }

int first_centre(std::int64_t lo) {
    return static_cast<int>(std::ceil(static_cast<double>(lo - kSubcell / 2) / kSubcell));
}
int last_centre(std::int64_t hi) {
    return static_cast<int>(std::floor(static_cast<double>(hi - kSubcell / 2) / kSubcell));
}

bool covers_cell(const std::int64_t* px, const std::int64_t* py, int n, int i, int j) {
    const std::int64_t x = i * kSubcell + kSubcell / 2, y = j * kSubcell + kSubcell / 2;
    for (int a = 0; a < n; ++a) {
        const int b = (a + 1) % n;
        const std::int64_t dx = px[b] - px[a], dy = py[b] - py[a];
        if (dx == 0 && dy == 0) continue;  // clipping or snapping can repeat a vertex
        const std::int64_t edge = dx * (y - py[a]) - dy * (x - px[a]);  // exact
        if (!(edge > 0 || (edge == 0 && owns_edge_point(dx, dy)))) return false;
    }
    return true;
}

bool ReferenceEngine::above_base_plane(const mesh::Polygon& poly, const Frame& frame) const {
    if (poly.n == 0) return true;  // a cluster: no polygon bounds its elements
    for (int i = 0; i < poly.n; ++i)
        if (frame.to_local(poly.v[i]).z > eps_) return true;
    return false;
}

ReferenceEngine::ReferenceEngine(const mesh::Mesh& mesh, const Settings& settings)
    : mesh_(mesh), settings_(settings), delta_(settings.hemicube) {
    if (settings.hemicube < 8 || settings.hemicube % 2 != 0 || settings.hemicube > kMaxHemicube)
        throw InternalError("hemicube resolution must be even, at least 8 and at most 4096");
    eps_ = base_plane_epsilon(mesh);
    ids_.assign(delta_.cells(), kEmpty);
    depth_.assign(delta_.cells(), 0.0);
    owner_.assign(delta_.cells(), -1);
    back_.assign(delta_.cells(), 0);
    fixed_ = fixed_point(delta_.table());
}

std::vector<std::int64_t> fixed_point(const std::vector<double>& table) {
    std::vector<std::int64_t> out(table.size());
    for (std::size_t c = 0; c < out.size(); ++c)
        out[c] = static_cast<std::int64_t>(std::llround(std::ldexp(table[c], HR_FIXED_SHIFT)));
    return out;
}

void ReferenceEngine::shoot(const ShotRequest& request, ShotResult& out) {
    last_batch_ = 1;
    last_directional_ = request.shooter.kind == Shooter::Kind::directional;
    if (last_directional_) {
        shoot_directional(mesh_, request, out, nullptr, &owners_);
        return;
    }
    const Frame frame = make_frame(mesh_, request.shooter, settings_.seed, request.shot);
    const bool light = weights_of(request.shooter) == Weights::solid_angle;
    if (light && light_fixed_.empty()) light_fixed_ = fixed_point(DeltaFormFactors(delta_.n(), Weights::solid_angle).table());
    const std::vector<std::int64_t>& weight = light ? light_fixed_ : fixed_;
    // A cell's own elements, and its twin's, lie in its base plane: skipped. A cluster's are drawn
    // like any other, since the rim of a concave one rises in front of the shooter and must block
    // and receive its light (skipped, they let the inside of a double-sided cylinder light the room).
    const ShotSkips skips = shot_skips(mesh_, request.shooter);
    const int n = delta_.n();
    const double half = 0.5 * n;  // cells per unit of face coordinate

    std::fill(depth_.begin(), depth_.end(), 0.0);
    std::fill(owner_.begin(), owner_.end(), -1);
    std::fill(back_.begin(), back_.end(), 0);

    for (std::size_t k = 0; k < mesh_.elements.size(); ++k) {
        const mesh::Element& e = mesh_.elements[k];
        if (skips.skips(e.patch)) continue;
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

            // Project to cell coordinates, x in [0, n) and y in [0, rows), snapped to fixed point.
            const double t0 = face == 0 ? 1.0 : 0.0;
            std::int64_t px[kMaxClipped], py[kMaxClipped];
            for (int i = 0; i < poly.n; ++i) {
                px[i] = snap((poly.v[i].x / poly.v[i].z + 1.0) * half);
                py[i] = snap((poly.v[i].y / poly.v[i].z + t0) * half);
            }
            std::int64_t area2 = 0;
            for (int i = 0; i < poly.n; ++i) {
                const int j = (i + 1) % poly.n;
                area2 += px[i] * py[j] - px[j] * py[i];
            }
            if (area2 == 0) continue;
            if (area2 < 0) {  // make counter-clockwise
                std::reverse(px, px + poly.n);
                std::reverse(py, py + poly.n);
            }
            // The cells whose centres (i + 1/2, j + 1/2) lie in the polygon's bounding box.
            const std::int64_t xmin = *std::min_element(px, px + poly.n), xmax = *std::max_element(px, px + poly.n);
            const std::int64_t ymin = *std::min_element(py, py + poly.n), ymax = *std::max_element(py, py + poly.n);
            const int rows = delta_.rows(face);
            const int i0 = std::max(0, first_centre(xmin)), i1 = std::min(n - 1, last_centre(xmax));
            const int j0 = std::max(0, first_centre(ymin)), j1 = std::min(rows - 1, last_centre(ymax));
            const std::size_t base = delta_.offset(face);

            for (int j = j0; j <= j1; ++j) {
                for (int i = i0; i <= i1; ++i) {
                    if (!covers_cell(px, py, poly.n, i, j)) continue;
                    const double s = (i + 0.5) / half - 1.0, t = (j + 0.5) / half - t0;
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

    // The cells' delta form factors are summed in 64-bit fixed point, the layout header's unit, as
    // the kernels sum them: integer addition does not depend on the order, so an engine that gives
    // the same cells gives the same form factors, bit for bit. (Summed in double precision they
    // differed in the last bits, and the progressive solver's pick between two patches of nearly
    // equal flux, as a symmetric scene has, turned that into a different bake.)
    const std::size_t elements = mesh_.elements.size();
    sums_.assign(elements + 1, 0);
    for (std::size_t cell = 0; cell < owner_.size(); ++cell) {
        if (owner_[cell] < 0) {
            ids_[cell] = kEmpty;
        } else if (back_[cell]) {
            ids_[cell] = kBlocker;
            sums_[elements] += weight[cell];
        } else {
            ids_[cell] = owner_[cell];
            sums_[static_cast<std::size_t>(owner_[cell])] += weight[cell];
        }
    }
    const double unit = std::ldexp(1.0, -HR_FIXED_SHIFT);
    out.assign_nonzero(sums_.data(), elements, [unit](std::int64_t s) { return static_cast<double>(s) * unit; });
    out.blocked = static_cast<double>(sums_[elements]) * unit;
}

}  // namespace hemirad::formfactor
