// Shot-by-shot comparison of an engine against the scalar reference (see verify.h).
#include "formfactor/verify.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <fmt/core.h>

#include "formfactor/parallel.h"


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
    // Directional shots one at a time, each checked as it comes (an engine keeps the grid of its
    // last only: up to 64 MiB), then the hemicubes as one batch, as they came.
    const bool suns = split_directional(shots, hemicubes_, place_);
    if (suns) {
        out.resize(shots.size());
        for (std::size_t i = 0; i < shots.size(); ++i) {
            if (place_[i] >= 0) continue;
            engine_->shoot(shots[i], out[i]);
            reference_->shoot(shots[i], expected_);
            ++summary_.shots_checked;
            check_directional(shots[i], out[i], engine_->last_ids(0), reference_->last_ids());
        }
        if (!hemicubes_.empty()) engine_->shoot_batch(hemicubes_, rows_);
        for (std::size_t i = 0; i < shots.size(); ++i)
            if (place_[i] >= 0) out[i] = std::move(rows_[static_cast<std::size_t>(place_[i])]);
    } else {
        engine_->shoot_batch(shots, out);
    }
    for (std::size_t i = 0; i < shots.size(); ++i) {
        if (suns && place_[i] < 0) continue;
        const std::uint64_t shot = shots[i].shot;
        if (shot % static_cast<std::uint64_t>(every_) != 0) continue;
        reference_->shoot(shots[i], expected_);
        ++summary_.shots_checked;

        const auto* ids = engine_->last_ids(suns ? static_cast<std::size_t>(place_[i]) : i);
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

// A directional light's shot: the engine's raster draws the host's grid cell for cell, and the
// row follows from the grid by the same host arithmetic, so both must be the reference's exactly.
void VerifyingEngine::check_directional(const ShotRequest& request, const ShotResult& got,
                                        const std::vector<std::int32_t>* ids, const std::vector<std::int32_t>* ref_ids) {
    long cells = 0;
    if (ids && ref_ids) {
        for (std::size_t c = 0; c < ids->size() && c < ref_ids->size(); ++c) cells += (*ids)[c] != (*ref_ids)[c];
        summary_.cells_compared += static_cast<long>(ref_ids->size());
        summary_.cells_mismatched += cells;
        if (cells > 0 || ids->size() != ref_ids->size())
            throw VerifyError(fmt::format("verify: parallel shot {} (directional light {}) on {}: {} of {} cells have "
                                          "another owner than the reference's{}",
                                          request.shot, request.shooter.patch, engine_->name(), cells, ref_ids->size(),
                                          ids->size() != ref_ids->size() ? fmt::format(" (a grid of {} cells)", ids->size())
                                                                         : std::string()));
    }
    const std::string problem = compare_shot(got, expected_, &summary_);
    if (got != expected_)
        throw VerifyError(fmt::format("verify: parallel shot {} (directional light {}) on {}: the row is not the "
                                      "reference's bit for bit: {}",
                                      request.shot, request.shooter.patch, engine_->name(),
                                      problem.empty() ? std::string("its elements or values differ within the tolerance")
                                                      : problem));
}

}  // namespace hemirad::formfactor
