// Shot-by-shot comparison of an engine against the scalar reference (see verify.h).
#include "formfactor/verify.h"

#include <algorithm>
#include <cmath>

#include <fmt/core.h>

namespace hemirad::formfactor {

VerifyingEngine::VerifyingEngine(std::unique_ptr<Engine> engine, std::unique_ptr<Engine> reference, long every)
    : engine_(std::move(engine)), reference_(std::move(reference)), every_(std::max(1L, every)) {}

void VerifyingEngine::shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) {
    engine_->shoot(patch, shot, out);
    if (shot % static_cast<std::uint64_t>(every_) != 0) return;
    reference_->shoot(patch, shot, expected_);
    ++summary_.shots_checked;

    const auto* ids = engine_->last_ids();
    const auto* ref_ids = reference_->last_ids();
    if (ids && ref_ids && ids->size() == ref_ids->size()) {
        summary_.cells_compared += static_cast<long>(ids->size());
        for (std::size_t c = 0; c < ids->size(); ++c) summary_.cells_mismatched += (*ids)[c] != (*ref_ids)[c];
    }
    if (out.F.size() != expected_.F.size())
        throw VerifyError(fmt::format("verify: shot {} (patch {}): {} form factors, the reference has {}", shot, patch,
                                      out.F.size(), expected_.F.size()));
    for (std::size_t k = 0; k <= out.F.size(); ++k) {
        // k == size stands for the blocked share, checked like any element.
        const double got = k < out.F.size() ? out.F[k] : out.blocked;
        const double want = k < expected_.F.size() ? expected_.F[k] : expected_.blocked;
        const double abs_error = std::abs(got - want);
        summary_.max_abs_error = std::max(summary_.max_abs_error, abs_error);
        if (std::abs(want) > kAbsoluteTolerance) summary_.max_rel_error = std::max(summary_.max_rel_error, abs_error / std::abs(want));
        if (abs_error > kAbsoluteTolerance + kRelativeTolerance * std::abs(want)) {
            const std::string what = k < out.F.size() ? fmt::format("element {}", k) : std::string("the blocked share");
            throw VerifyError(fmt::format(
                "verify: shot {} (patch {}): {} has F = {:.9g} on {}, the reference says {:.9g} "
                "(|error| {:.3g} > {:g} + {:g}·F); {} of {} cells differ so far",
                shot, patch, what, got, engine_->name(), want, abs_error, kAbsoluteTolerance, kRelativeTolerance,
                summary_.cells_mismatched, summary_.cells_compared));
        }
    }
}

}  // namespace hemirad::formfactor
