// FormFactorEngine: shoot(patch) → F[patch → element] for every element of the mesh, one shot
// or a batch of shots at a time. Implemented by the scalar reference hemicube, the OpenCL
// engine, and decorators (near field, verification).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace hemirad::formfactor {

struct Settings {
    int hemicube = 256;       // resolution N: top face N×N, four half faces N×N/2; even, >= 8
    std::uint64_t seed = 1;   // drives the per-shot rotation of the hemicube about the normal
};

// What one shot sees. F has one entry per element (zero where unseen). `blocked` is the part
// of the hemisphere covered by the backs of one-sided surfaces (opaque, absorbing); the rest,
// 1 − ΣF − blocked, escapes the scene.
struct ShotResult {
    std::vector<double> F;
    double blocked = 0.0;
};

// One shot of a batch: the shooter and the global shot counter.
struct ShotRequest {
    std::uint32_t patch = 0;
    std::uint64_t shot = 0;
};

class Engine {
public:
    virtual ~Engine() = default;
    virtual std::string name() const = 0;  // "ref", "opencl"
    // Form factors from patch `patch` to every element. `shot` is the global shot counter:
    // with the seed it fixes the hemicube's rotation, so any engine reproduces the same shot.
    virtual void shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) = 0;
    // Several shots at once, with exactly the results of shoot() one at a time (out[i] for
    // shots[i]). Engines that can run them together (the OpenCL engine: one launch per stage)
    // override it; this one shoots in turn.
    virtual void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
        out.resize(shots.size());
        for (std::size_t i = 0; i < shots.size(); ++i) shoot(shots[i].patch, shots[i].shot, out[i]);
    }
    // The id buffer of shot i of the last shoot_batch (a shoot() is a batch of one): element
    // index, −1 empty, −2 blocker, cells in DeltaFormFactors order; nullptr where the engine
    // does not keep it. Used by verification.
    virtual const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const {
        (void)i;
        return nullptr;
    }
};

}  // namespace hemirad::formfactor
