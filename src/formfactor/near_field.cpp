// Near-field correction: collocation at the receiver for receivers close to the shooter.
#include "formfactor/near_field.h"

#include <algorithm>
#include <cmath>

#include "core/parallel.h"
#include "formfactor/analytic.h"

namespace hemirad::formfactor {

NearFieldEngine::NearFieldEngine(const mesh::Mesh& mesh, std::unique_ptr<Engine> inner, double reach)
    : mesh_(mesh), inner_(std::move(inner)), reach_(reach) {}

// Only patches' rows are corrected. Lights' are left as they are: a point has no extent for
// receivers to be near, and a directional light (a sun) shoots parallel rays from no place at all.
void NearFieldEngine::shoot(const ShotRequest& request, ShotResult& out) {
    inner_->shoot(request, out);
    if (request.shooter.kind == Shooter::Kind::patch) correct(request.shooter.patch, out);
}

void NearFieldEngine::shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    inner_->shoot_batch(shots, out);
    // Each row on its own (the host's threads).
    parallel::for_each(shots.size(), 1, [&](std::size_t i) {
        if (shots[i].shooter.kind == Shooter::Kind::patch) correct(shots[i].shooter.patch, out[i]);
    });
}

void NearFieldEngine::correct(std::uint32_t patch, ShotResult& out) {
    const mesh::Patch& shooter = mesh_.patches[patch];
    // The shooter's polygons: its cell, or a cluster's elements.
    std::vector<const mesh::Polygon*> shape;
    if (shooter.cluster()) {
        for (std::uint32_t k = shooter.first_element; k < shooter.first_element + shooter.element_count; ++k)
            shape.push_back(&mesh_.elements[k].poly);
    } else {
        shape.push_back(&shooter.poly);
    }
    // Of a cluster of parts apart, only the polygons whose fronts face x send it light: parts
    // spread around their point, and a receiver among them may lie behind some (the wall below a
    // crown's upturned leaves, which their backs, another patch, light).
    // A receiver on the same face as one of them (a double-sided card's other side, lying in its
    // plane) takes nothing from it: in the plane, rounding could let the polygon pass the test
    // and count as filling the receiver's whole hemisphere.
    const auto to_shooter = [&](const mesh::Element& e) {
        double f = 0.0;
        for (std::size_t j = 0; j < shape.size(); ++j) {
            const mesh::Element* g = shooter.apart ? &mesh_.elements[shooter.first_element + j] : nullptr;
            if (g && (g->source == e.source || !(glm::dot(e.centroid - g->poly.v[0], g->normal) > 0.0))) continue;
            f += point_to_polygon(e.centroid, e.normal, *shape[j]);
        }
        return f;
    };
    double radius = 0.0;
    for (const mesh::Polygon* poly : shape)
        for (int i = 0; i < poly->n; ++i) radius = std::max(radius, glm::length(poly->v[i] - shooter.centroid));
    const double reach2 = (reach_ * radius) * (reach_ * radius);

    // Correct the near receivers, then rescale the far ones so the shot keeps its total: the
    // hemicube's ΣF is exact (the cells tile the hemisphere), and the flux books and the
    // measured hit fraction (to which the ambient term is very sensitive as ρ → 1) rely on it.
    double near_before = 0.0, near_after = 0.0, far = 0.0;
    std::vector<std::size_t> near;  // row positions of the receivers corrected, ascending
    for (std::size_t i = 0; i < out.size(); ++i) {
        if (out.F[i] == 0.0) continue;  // unseen: occluded, behind, or coplanar
        const mesh::Element& e = mesh_.elements[out.element[i]];
        if (e.patch == patch && !shooter.apart) {  // a cluster's own element (a concave one sees
            far += out.F[i];  // itself): part of its shape, no point-to-shooter factor; the hemicube's value stands
            continue;
        }
        if (e.patch == patch) {
            // A cluster of parts apart shoots from among them, so its own elements near that point
            // took its light (a crown came out mottled); each gets what the cluster's other faces
            // that face it send it, unoccluded (its own face lies in its plane and sends nothing).
            near_before += out.F[i];
            out.F[i] = to_shooter(e) * e.area / shooter.area;
            near_after += out.F[i];
            near.push_back(i);
            continue;
        }
        const glm::dvec3 d = e.centroid - shooter.centroid;
        // What the hemicube would have measured with nothing in the way, from the same point.
        const double unoccluded = glm::dot(d, d) < reach2 ? point_to_polygon(shooter.centroid, shooter.normal, e.poly) : 0.0;
        const double visible = out.F[i] / unoccluded;  // not clamped: aliasing noise stays unbiased
        if (!(unoccluded > 0.0) || !std::isfinite(visible)) {  // seen only by aliasing (F / 1e-310 is inf)
            far += out.F[i];
            continue;
        }
        near_before += out.F[i];
        out.F[i] = visible * to_shooter(e) * e.area / shooter.area;
        near_after += out.F[i];
        near.push_back(i);
    }
    if (shooter.apart && far + near_after > 0.0) {
        // A cluster of parts apart shoots from among its parts (a crown's middle), where the near
        // receivers fill most of the point's hemicube and the exact factors give them far less:
        // the rest, laid on the few far receivers seen through the gaps, lit them many times
        // over (a blob on the wall behind a tree). The total is kept by scaling every receiver.
        const double scale = (far + near_before) / (far + near_after);
        for (std::size_t i = 0; i < out.size(); ++i) out.F[i] *= scale;
        return;
    }
    const double far_scale = far > 0.0 ? (far + near_before - near_after) / far : -1.0;
    if (far_scale >= 0.0) {
        for (std::size_t i = 0, n = 0; i < out.size(); ++i) {
            if (n < near.size() && near[n] == i) {
                ++n;
                continue;
            }
            if (out.F[i] != 0.0) out.F[i] *= far_scale;
        }
    } else if (near_after > 0.0) {
        for (std::size_t i : near) out.F[i] *= near_before / near_after;
    }
}

}  // namespace hemirad::formfactor
