// A ray-casting peer of the hemicube engines, on Intel Embree: one ray per hemicube cell (3N²
// per shot, in packets of 16) from the shooter's centre through the cell's centre, in the same
// frame (seed, shot) as every other engine, adding the cell's delta form factor to the element
// the ray hits first. It is what a user would otherwise pick on a CPU, and a check that owes
// nothing to the rasterizers: it agrees with them except on cells whose centre lies within a
// float's rounding of an element's edge, and on ties. Built when Embree 3 is found
// (HEMIRAD_HAVE_EMBREE).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "formfactor/engine.h"
#include "formfactor/hemicube.h"

namespace hemirad::formfactor {

class EmbreeEngine final : public Engine {
public:
    // threads 0: one per hardware thread. Each thread casts a fixed range of cells into its own
    // sums, added in thread order: the same bits run after run for a thread count, and the same
    // id buffer (the sums to rounding) for any.
    EmbreeEngine(const mesh::Mesh& mesh, const Settings& settings, unsigned threads = 0);
    ~EmbreeEngine() override;
    EmbreeEngine(const EmbreeEngine&) = delete;
    EmbreeEngine& operator=(const EmbreeEngine&) = delete;

    std::string name() const override { return "embree"; }
    void shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) override;

    // Keeps the last shot's id buffer (as the reference's: element, −1 empty, −2 a blocker).
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override {
        Engine::shoot_batch(shots, out);
        last_batch_ = shots.size();
    }
    const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const override {
        return i + 1 == last_batch_ ? &ids_ : nullptr;
    }

    unsigned threads() const { return threads_; }
    static std::string version();  // "Embree 3.13.5"

    struct Impl;

private:
    std::unique_ptr<Impl> impl_;
    unsigned threads_;
    std::vector<std::vector<double>> sums_;            // per thread, per element; zero between shots
    std::vector<std::vector<std::uint32_t>> touched_;  // per thread: the elements its sums hold
    std::vector<std::int32_t> ids_;
    std::size_t last_batch_ = 1;
};

}  // namespace hemirad::formfactor
