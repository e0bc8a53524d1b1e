// The scalar reference hemicube: single-threaded, simple, obviously right. Every other
// engine is verified against it.
#pragma once

#include "formfactor/engine.h"
#include "formfactor/hemicube.h"

namespace hemirad::formfactor {

// The reference's inside test: whether the centre of cell (i, j) lies inside the
// counter-clockwise polygon px, py (n vertices in kSubcell units per cell), or on an edge that
// the top-left rule gives it. Exact: two polygons sharing an edge never both take a centre on
// it, and together they leave none of them out.
bool covers_cell(const std::int64_t* px, const std::int64_t* py, int n, int i, int j);

// A cell coordinate in fixed point (kSubcell units per cell), rounded to nearest: how every
// engine snaps projected vertices before covers_cell.
std::int64_t snap(double cells);

// The first and the last cell whose centre (index + 1/2) lies at or above lo, at or below hi
// (fixed point): the cells a snapped polygon's box holds.
int first_centre(std::int64_t lo);
int last_centre(std::int64_t hi);

// A table of cell weights in fixed point, 2^HR_FIXED_SHIFT per unit, as every engine sums them.
std::vector<std::int64_t> fixed_point(const std::vector<double>& table);

class ReferenceEngine final : public Engine {
public:
    ReferenceEngine(const mesh::Mesh& mesh, const Settings& settings);
    std::string name() const override { return "ref"; }
    using Engine::shoot;
    void shoot(const ShotRequest& request, ShotResult& out) override;

    // The id buffer of the last shot, face by face (row-major, as DeltaFormFactors): element
    // index, kEmpty where nothing was hit, kBlocker for the back of a one-sided surface.
    static constexpr std::int32_t kEmpty = -1;
    static constexpr std::int32_t kBlocker = -2;
    const std::vector<std::int32_t>& ids() const { return ids_; }
    // Keeps the last shot's buffer only: that of a batch's last shot.
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override {
        Engine::shoot_batch(shots, out);
        last_batch_ = shots.size();
    }
    // A directional shooter's shot is the host's parallel shot (parallel.h), its cells' owners kept instead.
    const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const override {
        return i + 1 == last_batch_ ? (last_directional_ ? &owners_ : &ids_) : nullptr;
    }
    const DeltaFormFactors& delta() const { return delta_; }

private:
    const mesh::Mesh& mesh_;
    Settings settings_;
    DeltaFormFactors delta_;
    double eps_;  // base-plane clip distance, relative to the scene's size
    std::vector<std::int32_t> ids_;
    std::vector<double> depth_;          // 1/d per cell, larger is nearer
    std::vector<std::int32_t> owner_;    // winning element per cell, −1 for none
    std::vector<char> back_;             // the winner is the back of a one-sided surface
    std::vector<std::int64_t> fixed_;    // per cell, its delta form factor in 2^-HR_FIXED_SHIFT units
    std::vector<std::int64_t> light_fixed_;  // per cell, its solid angle over 4π likewise (made when a light first shoots)
    std::vector<std::int64_t> sums_;     // per element, then blocked: a shot's sums in those units
    std::size_t last_batch_ = 1;         // shots in the last batch: ids_ is its last
    std::vector<std::int32_t> owners_;   // the last shot's grid, when it was a directional light's
    bool last_directional_ = false;

    bool above_base_plane(const mesh::Polygon& poly, const Frame& frame) const;
};

}  // namespace hemirad::formfactor
