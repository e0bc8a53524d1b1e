// Shot-by-shot comparison of an engine against the scalar reference (see verify.h).
#include "formfactor/verify.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <fmt/core.h>

#include "formfactor/parallel_opencl.h"

namespace hemirad::formfactor {

std::string compare_shot(const ShotResult& got, const ShotResult& want, VerifySummary* summary) {
    // Every element either row lists (F = 0 where the other lacks it), then the blocked share,
    // checked like any element; the first failure is reported.
    std::string failure;
    const auto check = [&](std::int64_t element, double g, double w) {  // element −1: the blocked share
        const double abs_error = std::abs(g - w);
        if (summary) {
            summary->max_abs_error = std::max(summary->max_abs_error, abs_error);
            if (std::abs(w) > VerifyingEngine::kAbsoluteTolerance)
                summary->max_rel_error = std::max(summary->max_rel_error, abs_error / std::abs(w));
        }
        if (failure.empty() &&
            abs_error > VerifyingEngine::kAbsoluteTolerance + VerifyingEngine::kRelativeTolerance * std::abs(w))
            failure = fmt::format("{} has F = {:.9g}, the reference says {:.9g} (|error| {:.3g} > {:g} + {:g}·F)",
                                  element < 0 ? std::string("the blocked share") : fmt::format("element {}", element),
                                  g, w, abs_error, VerifyingEngine::kAbsoluteTolerance,
                                  VerifyingEngine::kRelativeTolerance);
    };
    for_each_in_union(got, want, check);
    check(-1, got.blocked, want.blocked);
    return failure;
}

VerifyingEngine::VerifyingEngine(std::unique_ptr<Engine> engine, std::unique_ptr<Engine> reference, long every)
    : engine_(std::move(engine)), reference_(std::move(reference)), every_(std::max(1L, every)) {}

void VerifyingEngine::shoot(const ShotRequest& request, ShotResult& out) {
    shoot_batch({request}, batch_);
    out = std::move(batch_[0]);
}

void VerifyingEngine::shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
    engine_->shoot_batch(shots, out);
    for (std::size_t i = 0; i < shots.size(); ++i) {
        const std::uint64_t shot = shots[i].shot;
        if (shot % static_cast<std::uint64_t>(every_) != 0) continue;
        reference_->shoot(shots[i], expected_);
        ++summary_.shots_checked;

        const auto* ids = engine_->last_ids(i);
        const auto* ref_ids = reference_->last_ids();
        if (ids && ref_ids && ids->size() == ref_ids->size()) {
            summary_.cells_compared += static_cast<long>(ids->size());
            for (std::size_t c = 0; c < ids->size(); ++c) summary_.cells_mismatched += (*ids)[c] != (*ref_ids)[c];
        }
        const std::string problem = compare_shot(out[i], expected_, &summary_);
        if (!problem.empty())
            throw VerifyError(fmt::format("verify: shot {} (patch {}) on {}: {}; {} of {} cells differ so far", shot,
                                          shots[i].shooter.patch, engine_->name(), problem, summary_.cells_mismatched,
                                          summary_.cells_compared));
    }
}

ParallelRaster* VerifyingEngine::parallel_raster() {
    ParallelRaster* raster = engine_->parallel_raster();
    if (!raster) return nullptr;
    if (!parallel_) parallel_ = std::make_unique<VerifyingParallelRaster>(*raster);
    return parallel_.get();
}

}  // namespace hemirad::formfactor
