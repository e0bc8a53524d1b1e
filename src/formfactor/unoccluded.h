// An occlusion-free engine for scenes the effects planner found free of occlusion (surfaces
// bounding a convex region seen from inside). No hemicube: the form factor from patch i to
// element j is taken by reciprocity from the exact point-to-polygon factor,
//   F_ij = (A_j / A_i) × (area average over element j of F(dA_x → patch i)),
// Lambert's closed form for the inner integral and a q×q midpoint rule over the element for
// the outer one, q from the element's distance to the shooter relative to their sizes. Each row
// is then scaled to its total seen from the shooter's side, exact in a closed scene, so that rows
// conserve energy as the hemicube's do (see shoot). Deterministic: the shot counter is ignored. Nothing blocks anything, so on a scene with
// occlusion (or with doubleSided twins, whose backs it does not hide) it lets light through
// surfaces. Per-element data is taken at construction: build a new engine for a new mesh.
#pragma once

#include <vector>

#include "formfactor/engine.h"

namespace hemirad::formfactor {

class UnoccludedEngine final : public Engine {
public:
    explicit UnoccludedEngine(const mesh::Mesh& mesh);
    std::string name() const override { return "analytic"; }
    // F[j] = 0 for the shooter's own elements, elements coplanar with it, and elements whose
    // centroid is not in front of its plane. `blocked` = 0. `shot` is ignored. A directional
    // light's shot is the host's parallel shot (parallel.h), occluded like any engine's.
    using Engine::shoot;
    void shoot(const ShotRequest& request, ShotResult& out) override;
    // The shots on the machine's hardware threads, a shot to a thread at a time: each row is
    // shoot()'s, whichever thread takes it (a shot reads the engine and writes its own row only).
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override;

    // The quadrature's sub-cells per element side, q (q² sub-cells): d is the distance from the
    // element's centroid to the shooter's, s the larger of their longest edges. 1 if d > 4s,
    // 2 if d > 2s, 4 if d > s, else 8.
    static int subdivisions(double d, double s);

    // The row's total from the shooter's side (see shoot) is trusted once midpoint rules of q and
    // 2q points a side agree to this, q up to kMaxShooterRule.
    static constexpr double kRowTolerance = 1e-7;
    static constexpr int kMaxShooterRule = 8;

private:
    struct Receiver {
        glm::dvec3 v[4];
        glm::dvec3 normal;
        glm::dvec3 centroid;
        double area;
        double size;  // longest edge
        std::uint32_t patch;
        int n;
    };
    const mesh::Mesh& mesh_;
    std::vector<Receiver> receivers_;
    std::vector<double> patch_size_;  // longest edge of each patch
    double eps_;                      // plane tolerance, relative to the scene's size
};

}  // namespace hemirad::formfactor
