// TimedEngine: times every shot of the engine it wraps, so that a bake's report (and the scaling
// benchmark) can split the form factors' time from the solver's.
#pragma once

#include <string>
#include <vector>

#include "core/timing.h"
#include "formfactor/engine.h"

namespace hemirad::formfactor {

class TimedEngine final : public Engine {
public:
    explicit TimedEngine(Engine& inner) : inner_(inner) {}
    std::string name() const override { return inner_.name(); }
    std::size_t preferred_batch() const override { return inner_.preferred_batch(); }
    using Engine::shoot;
    void shoot(const ShotRequest& request, ShotResult& out) override {
        const auto t0 = Clock::now();
        inner_.shoot(request, out);
        seconds_ += seconds_since(t0);
    }
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override {
        const auto t0 = Clock::now();
        inner_.shoot_batch(shots, out);
        seconds_ += seconds_since(t0);
    }
    double seconds() const { return seconds_; }

private:
    Engine& inner_;
    double seconds_ = 0.0;
};

}  // namespace hemirad::formfactor
