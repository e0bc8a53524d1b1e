// --verify: runs the scalar reference beside another engine on every K-th shot and compares
// the id buffers (mismatched cells counted) and the per-element form factors (absolute near
// zero, relative elsewhere). Directional lights' shots are checked every one, and exactly: the
// owner of every cell of the grid (where the engine keeps them: last_ids) and the row's bits
// must be the host's. A violation throws VerifyError with the numbers.
#pragma once

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "formfactor/engine.h"

namespace hemirad::formfactor {

class VerifyError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

struct VerifySummary {
    long shots_checked = 0;
    long cells_compared = 0;
    long cells_mismatched = 0;       // id differs from the reference (edges and depth ties)
    double max_abs_error = 0.0;      // over all per-element form factors checked
    double max_rel_error = 0.0;      // where the reference value is above kAbsoluteTolerance
};

// The first form factor (element, or the blocked share) that differs from the reference by more
// than VerifyingEngine's tolerance, described in a sentence; empty when the shot agrees. Also
// widens `max_abs_error` and `max_rel_error` of `summary` when given.
std::string compare_shot(const ShotResult& got, const ShotResult& want, VerifySummary* summary = nullptr);

class VerifyingEngine final : public Engine {
public:
    static constexpr double kAbsoluteTolerance = 1e-6;
    static constexpr double kRelativeTolerance = 1e-4;

    // `every`: check shots 0, K, 2K, … (K >= 1). Both engines must see the same mesh and settings.
    VerifyingEngine(std::unique_ptr<Engine> engine, std::unique_ptr<Engine> reference, long every);
    std::string name() const override { return engine_->name(); }
    using Engine::shoot;
    void shoot(const ShotRequest& request, ShotResult& out) override;
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override;
    const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const override { return engine_->last_ids(i); }
    std::size_t preferred_batch() const override { return engine_->preferred_batch(); }
    const VerifySummary& summary() const { return summary_; }

private:
    std::unique_ptr<Engine> engine_, reference_;
    long every_;
    ShotResult expected_;
    std::vector<ShotResult> batch_;
    std::vector<ShotRequest> hemicubes_;  // a batch's shots but its directional ones
    std::vector<long> place_;             // per shot its place among them, −1 a directional one
    std::vector<ShotResult> rows_;        // the hemicubes' rows
    VerifySummary summary_;

    void check_directional(const ShotRequest& request, const ShotResult& got, const std::vector<std::int32_t>* ids,
                           const std::vector<std::int32_t>* ref_ids);
};

}  // namespace hemirad::formfactor
