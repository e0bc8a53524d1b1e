// FormFactorEngine: shoot(patch) → F[patch → element] for every element of the mesh.
// The scalar reference hemicube implements it now; the OpenCL engine will implement it next.
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

class Engine {
public:
    virtual ~Engine() = default;
    virtual std::string name() const = 0;  // "ref", "opencl"
    // Form factors from patch `patch` to every element. `shot` is the global shot counter:
    // with the seed it fixes the hemicube's rotation, so any engine reproduces the same shot.
    virtual void shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) = 0;
    // The id buffer of the last shot (element index, −1 empty, −2 blocker; cells in
    // DeltaFormFactors order), for engines that keep one; used by verification.
    virtual const std::vector<std::int32_t>* last_ids() const { return nullptr; }
};

}  // namespace hemirad::formfactor
