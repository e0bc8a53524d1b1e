// Near-field correction for any hemicube engine. A hemicube samples the shooter at one point,
// its centroid, which misjudges receivers closer than a few shooter sizes (31% too much for
// squares a quarter apart). For those receivers the transfer is taken instead at the
// receiver's centroid, exactly over the whole shooter polygon (Lambert), and scaled by the
// share of the receiver the hemicube found visible: F_ij = vis_j · F(dA_j → A_i) · A_j / A_i.
// A cluster's F(dA_j → A_i) is the sum over its elements' polygons.
#pragma once

#include <memory>
#include <vector>

#include "formfactor/engine.h"

namespace hemirad::formfactor {

class NearFieldEngine final : public Engine {
public:
    // `reach`: receivers whose centroid is nearer than reach × the shooter's radius (centroid
    // to farthest vertex) are corrected.
    NearFieldEngine(const mesh::Mesh& mesh, std::unique_ptr<Engine> inner, double reach = kDefaultReach);
    std::string name() const override { return inner_->name(); }
    using Engine::shoot;
    void shoot(const ShotRequest& request, ShotResult& out) override;
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override;
    const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const override { return inner_->last_ids(i); }
    std::size_t preferred_batch() const override { return inner_->preferred_batch(); }

    static constexpr double kDefaultReach = 4.0;

private:
    const mesh::Mesh& mesh_;
    std::unique_ptr<Engine> inner_;
    double reach_;

    void correct(std::uint32_t patch, ShotResult& out);  // the inner engine's shot, in place
};

}  // namespace hemirad::formfactor
