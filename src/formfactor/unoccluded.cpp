// Occlusion-free form factors: reciprocity of the exact point-to-polygon factor, averaged
// over each receiving element by a midpoint rule whose order grows as the element nears the
// shooter.
#include "formfactor/unoccluded.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <mutex>
#include <thread>

#include "core/error.h"
#include "formfactor/analytic.h"
#include "formfactor/parallel.h"

namespace hemirad::formfactor {

int UnoccludedEngine::subdivisions(double d, double s) {
    if (d > 4.0 * s) return 1;
    if (d > 2.0 * s) return 2;
    if (d > s) return 4;
    return 8;
}

UnoccludedEngine::UnoccludedEngine(const mesh::Mesh& mesh) : mesh_(mesh) {
    glm::dvec3 lo(0.0), hi(0.0);
    bool any = false;
    receivers_.reserve(mesh.elements.size());
    for (const mesh::Element& e : mesh.elements) {
        Receiver r{};
        for (int i = 0; i < 4; ++i) r.v[i] = e.poly.v[i];
        r.n = e.poly.n;
        r.normal = e.normal;
        r.centroid = e.centroid;
        r.area = e.area;
        r.size = mesh::longest_edge(e.poly);
        r.patch = e.patch;
        receivers_.push_back(r);
        for (int i = 0; i < e.poly.n; ++i) {
            lo = any ? glm::min(lo, e.poly.v[i]) : e.poly.v[i];
            hi = any ? glm::max(hi, e.poly.v[i]) : e.poly.v[i];
            any = true;
        }
    }
    patch_size_.reserve(mesh.patches.size());
    for (const mesh::Patch& p : mesh.patches) {
        // Its rules integrate over each patch's polygon; a bake meshes without clusters for it.
        if (p.cluster()) throw InternalError("unoccluded form factors need a mesh without clusters");
        patch_size_.push_back(mesh::longest_edge(p.poly));
    }
    eps_ = 1e-9 * glm::length(hi - lo);
}

namespace {

// Calls visit(point, weight) for the cells of a q-level midpoint rule over a triangle or a
// bilinear quad v[0, n): q×q bilinear cells of a quad, each at its area centroid weighted by its
// area; the standard q² equal sub-triangles of a triangle at their centroids, weight 1. At q = 1
// the one point is the polygon's area centroid. The weights are not normalised.
template <class Visit>
void for_each_cell(const glm::dvec3* v, int n, const glm::dvec3& centroid, int q, Visit visit) {
    if (q == 1) {
        visit(centroid, 1.0);
    } else if (n == 4) {
        const double step = 1.0 / q;
        auto bilinear = [&](double u, double w) {
            return (1.0 - u) * (1.0 - w) * v[0] + u * (1.0 - w) * v[1] + u * w * v[2] + (1.0 - u) * w * v[3];
        };
        for (int b = 0; b < q; ++b) {
            const double w0 = b * step, w1 = (b + 1) * step;
            glm::dvec3 c00 = bilinear(0.0, w0), c01 = bilinear(0.0, w1);
            for (int a = 0; a < q; ++a) {
                const double u1 = (a + 1) * step;
                const glm::dvec3 c10 = bilinear(u1, w0), c11 = bilinear(u1, w1);
                const double area1 = glm::length(glm::cross(c10 - c00, c11 - c00));
                const double area2 = glm::length(glm::cross(c11 - c00, c01 - c00));
                const double area = area1 + area2;
                if (area > 0.0) visit((area1 * (c00 + c10 + c11) + area2 * (c00 + c11 + c01)) / (3.0 * area), area);
                c00 = c10;
                c01 = c11;
            }
        }
    } else {
        const glm::dvec3 e1 = (v[1] - v[0]) / static_cast<double>(q), e2 = (v[2] - v[0]) / static_cast<double>(q);
        for (int b = 0; b < q; ++b)
            for (int a = 0; a + b < q; ++a) {
                visit(v[0] + (a + 1.0 / 3.0) * e1 + (b + 1.0 / 3.0) * e2, 1.0);
                if (a + b < q - 1) visit(v[0] + (a + 2.0 / 3.0) * e1 + (b + 2.0 / 3.0) * e2, 1.0);
            }
    }
}

// The weighted mean of f over a q-level midpoint rule (for_each_cell).
template <class F>
double cell_mean(const glm::dvec3* v, int n, const glm::dvec3& centroid, int q, F f) {
    double sum = 0.0, weight = 0.0;
    for_each_cell(v, n, centroid, q, [&](const glm::dvec3& x, double w) {
        sum += w * f(x);
        weight += w;
    });
    return weight > 0.0 ? sum / weight : 0.0;
}

}  // namespace

void UnoccludedEngine::shoot(const ShotRequest& request, ShotResult& out) {
    if (request.shooter.kind == Shooter::Kind::directional) {
        // A sun's parallel shot, the host's, with its depth test like every engine's.
        shoot_directional(mesh_, request, out);
        return;
    }
    if (request.shooter.kind == Shooter::Kind::light) {
        // A light's hemicube: the exact solid angle of each element facing the light, over its
        // part in the hemicube's half-space, over 4π (Weights::solid_angle).
        const mesh::LightShooter& light = mesh_.lights.at(request.shooter.patch);
        out.clear();
        for (std::size_t k = 0; k < receivers_.size(); ++k) {
            const mesh::Element& e = mesh_.elements[k];
            if (!(glm::dot(e.normal, light.position - e.centroid) > 0.0)) continue;  // its back faces the light
            const double omega = solid_angle(light.position, light.axis, e.poly, eps_);
            if (omega > 0.0) out.push(static_cast<std::uint32_t>(k), omega / (4.0 * M_PI));
        }
        return;
    }
    if (request.shooter.kind == Shooter::Kind::point) {
        // A gather point: the exact form factor from the point to each element facing it, over
        // the element's part in front of the point's plane.
        const mesh::GatherPoint& point = mesh_.gather_points.at(request.shooter.patch);
        out.clear();
        for (std::size_t k = 0; k < receivers_.size(); ++k) {
            const mesh::Element& e = mesh_.elements[k];
            // Its back faces the point, or the point lies in its plane (its own surface's).
            if (!(glm::dot(e.normal, point.position - e.centroid) > eps_)) continue;
            const double f = point_to_polygon(point.position, point.normal, e.poly);
            if (f > 0.0) out.push(static_cast<std::uint32_t>(k), f);
        }
        return;
    }
    const std::uint32_t patch = request.shooter.patch;
    out.clear();
    const mesh::Patch& shooter = mesh_.patches[patch];
    if (!(shooter.area > 0.0)) return;
    const glm::dvec3 ni = shooter.normal;
    const double di = glm::dot(ni, shooter.centroid);
    const double si = patch_size_[patch];
    const double inv_area = 1.0 / shooter.area;

    // F(dA_x → shooter) at a point x of the receiver; zero behind the shooter's plane (its back
    // neither emits nor is seen).
    auto at = [&](const glm::dvec3& x, const glm::dvec3& nj) {
        return glm::dot(ni, x) - di > 0.0 ? point_to_polygon(x, nj, shooter.poly) : 0.0;
    };
    // What can receive from the shooter: not its own, in front of its plane, and facing it.
    auto receives = [&](const glm::dvec3& centroid, const glm::dvec3& normal) {
        if (glm::dot(ni, centroid) - di <= eps_) return false;  // coplanar, or behind the shooter
        for (int k = 0; k < shooter.poly.n; ++k)
            if (glm::dot(normal, shooter.poly.v[k] - centroid) > eps_) return true;
        return false;
    };

    double row = 0.0;
    for (std::size_t j = 0; j < receivers_.size(); ++j) {
        const Receiver& r = receivers_[j];
        if (r.patch == patch || !receives(r.centroid, r.normal)) continue;
        const int q = subdivisions(glm::length(r.centroid - shooter.centroid), std::max(r.size, si));
        const double mean = cell_mean(r.v, r.n, r.centroid, q, [&](const glm::dvec3& x) { return at(x, r.normal); });
        const double f = r.area * inv_area * mean;
        if (f == 0.0) continue;
        out.push(static_cast<std::uint32_t>(j), f);
        row += f;
    }

    // The row's total, from the shooter's side: at every point x of the shooter, Lambert's factors
    // to the patches that receive tile the part of its hemisphere they cover exactly (all of it in
    // a closed scene), so their mean over the shooter is the row's exact total up to the rule's
    // error in the share that escapes, which is none in a closed scene and small where openings
    // are far. The receiver-side rule above is right element by element but its sum is not (1 +
    // 1.4e-4 in a closed box, which 1/(1 − ρ) turns into 16% at ρ = 0.999), so the row is scaled
    // to this total where successive rules agree on it to kRowTolerance; otherwise it is only kept
    // from exceeding 1.
    std::vector<const mesh::Polygon*> receivers;  // the patches in front of the shooter, once per shot
    for (std::uint32_t p = 0; p < mesh_.patches.size(); ++p) {
        const mesh::Patch& target = mesh_.patches[p];
        if (p != patch && receives(target.centroid, target.normal)) receivers.push_back(&target.poly);
    }
    const auto covered = [&](const glm::dvec3& x) {
        double sum = 0.0;
        for (const mesh::Polygon* poly : receivers) sum += point_to_polygon(x, ni, *poly);
        return sum;
    };
    const glm::dvec3* sv = shooter.poly.v.data();
    double total = cell_mean(sv, shooter.poly.n, shooter.centroid, 1, covered);
    bool settled = false;
    for (int q = 2; q <= kMaxShooterRule && !settled; q *= 2) {
        const double finer = cell_mean(sv, shooter.poly.n, shooter.centroid, q, covered);
        settled = std::abs(finer - total) <= kRowTolerance;
        total = finer;
    }
    const double want = settled ? std::min(total, 1.0) : std::min(row, 1.0);
    if (row > 0.0 && want != row) {
        const double scale = want / row;
        for (double& f : out.F) f *= scale;
    }
}

void UnoccludedEngine::shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    out.resize(shots.size());
    const std::size_t workers =
        std::min<std::size_t>(shots.size(), std::max(1u, std::thread::hardware_concurrency()));
    if (workers <= 1) {
        Engine::shoot_batch(shots, out);
        return;
    }
    std::atomic<std::size_t> next{0};
    std::mutex failed;
    std::exception_ptr failure;  // the first exception a worker met, thrown again here
    const auto work = [&] {
        try {
            for (std::size_t i; (i = next.fetch_add(1)) < shots.size();) shoot(shots[i], out[i]);
        } catch (...) {
            const std::lock_guard<std::mutex> lock(failed);
            if (!failure) failure = std::current_exception();
            next = shots.size();
        }
    };
    std::vector<std::thread> pool;
    for (std::size_t t = 1; t < workers; ++t) pool.emplace_back(work);
    work();
    for (std::thread& t : pool) t.join();
    if (failure) std::rethrow_exception(failure);
}

}  // namespace hemirad::formfactor
