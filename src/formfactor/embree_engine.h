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
    // threads 0: one per hardware thread. The threads are started here and kept until the
    // engine goes. A shot's cells are cast in fixed tiles, claimed by whichever thread is free,
    // each tile's sums kept apart and added in tile order: the same bits for any thread count.
    EmbreeEngine(const mesh::Mesh& mesh, const Settings& settings, unsigned threads = 0);
    ~EmbreeEngine() override;
    EmbreeEngine(const EmbreeEngine&) = delete;
    EmbreeEngine& operator=(const EmbreeEngine&) = delete;

    std::string name() const override { return "embree"; }
    using Engine::shoot;
    void shoot(const ShotRequest& request, ShotResult& out) override;
    // The tiles of every shot of the batch shared out at once, so that the threads go on from
    // one shot to the next without waiting for each other; results as shoot() one at a time.
    void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) override;
    // Keeps the id buffer of the batch's last hemicube (as the reference's: element, −1 empty, −2
    // a blocker). A directional light's shot is the host's parallel shot (parallel.h).
    const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const override;

    unsigned threads() const;
    static std::string version();  // "Embree 3.13.5"

    struct Impl;

private:
    std::unique_ptr<Impl> impl_;
    // A batch with directional shots: its hemicubes, and per shot its place among them (−1 a
    // directional one); place_ empty for a batch of hemicubes alone.
    std::vector<ShotRequest> hemicubes_;
    std::vector<long> place_;
    std::vector<ShotResult> rows_;
};

}  // namespace hemirad::formfactor
