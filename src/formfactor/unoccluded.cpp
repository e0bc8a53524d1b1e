// Occlusion-free form factors: reciprocity of the exact point-to-polygon factor, averaged
// over each receiving element by a midpoint rule whose order grows as the element nears the
// shooter.
#include "formfactor/unoccluded.h"

#include <algorithm>
#include <cmath>

#include "formfactor/analytic.h"

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
    for (const mesh::Patch& p : mesh.patches) patch_size_.push_back(mesh::longest_edge(p.poly));
    eps_ = 1e-9 * glm::length(hi - lo);
}

void UnoccludedEngine::shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) {
    (void)shot;
    out.F.assign(receivers_.size(), 0.0);
    out.blocked = 0.0;
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

    for (std::size_t j = 0; j < receivers_.size(); ++j) {
        const Receiver& r = receivers_[j];
        if (r.patch == patch) continue;                          // the shooter's own elements
        if (glm::dot(ni, r.centroid) - di <= eps_) continue;     // coplanar, or behind the shooter
        bool faces = false;                                      // any of the shooter in front of the receiver
        for (int k = 0; k < shooter.poly.n && !faces; ++k) faces = glm::dot(r.normal, shooter.poly.v[k] - r.centroid) > eps_;
        if (!faces) continue;

        const int q = subdivisions(glm::length(r.centroid - shooter.centroid), std::max(r.size, si));
        double mean = 0.0;
        if (q == 1) {
            mean = at(r.centroid, r.normal);
        } else if (r.n == 4) {
            // Bilinear q×q cells; each is a planar quad, weighted by its area at its area centroid.
            const double step = 1.0 / q;
            auto bilinear = [&](double u, double v) {
                return (1.0 - u) * (1.0 - v) * r.v[0] + u * (1.0 - v) * r.v[1] + u * v * r.v[2] + (1.0 - u) * v * r.v[3];
            };
            double sum = 0.0, weight = 0.0;
            for (int b = 0; b < q; ++b) {
                const double v0 = b * step, v1 = (b + 1) * step;
                glm::dvec3 c00 = bilinear(0.0, v0), c01 = bilinear(0.0, v1);
                for (int a = 0; a < q; ++a) {
                    const double u1 = (a + 1) * step;
                    const glm::dvec3 c10 = bilinear(u1, v0), c11 = bilinear(u1, v1);
                    const double w1 = glm::length(glm::cross(c10 - c00, c11 - c00));
                    const double w2 = glm::length(glm::cross(c11 - c00, c01 - c00));
                    const double w = w1 + w2;
                    if (w > 0.0) {
                        const glm::dvec3 centroid = (w1 * (c00 + c10 + c11) + w2 * (c00 + c11 + c01)) / (3.0 * w);
                        sum += w * at(centroid, r.normal);
                        weight += w;
                    }
                    c00 = c10;
                    c01 = c11;
                }
            }
            mean = weight > 0.0 ? sum / weight : 0.0;
        } else {
            // The standard q² subdivision of a triangle into equal triangles, at their centroids.
            const glm::dvec3 e1 = (r.v[1] - r.v[0]) / static_cast<double>(q), e2 = (r.v[2] - r.v[0]) / static_cast<double>(q);
            double sum = 0.0;
            for (int b = 0; b < q; ++b)
                for (int a = 0; a + b < q; ++a) {
                    sum += at(r.v[0] + (a + 1.0 / 3.0) * e1 + (b + 1.0 / 3.0) * e2, r.normal);
                    if (a + b < q - 1) sum += at(r.v[0] + (a + 2.0 / 3.0) * e1 + (b + 2.0 / 3.0) * e2, r.normal);
                }
            mean = sum / (q * q);
        }
        out.F[j] = r.area * inv_area * mean;
    }
}

}  // namespace hemirad::formfactor
