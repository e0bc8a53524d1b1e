// Picks the form-factor engine of a bake from --device, HEMIRAD_DEVICE and --verify.
#pragma once

#include <memory>
#include <string>

#include "cl/runtime.h"
#include "formfactor/engine.h"
#include "formfactor/verify.h"
#include "mesh/mesh.h"

namespace hemirad::cli {

struct EngineChoice {
    std::unique_ptr<ocl::Context> context;           // outlives the OpenCL engine that uses it
    std::unique_ptr<formfactor::Engine> engine;      // the hemicube engine, verifying if asked
    formfactor::VerifyingEngine* verifier = nullptr; // into `engine` when --verify
    std::string backend, platform, name, id;         // what report.json and the log say
    std::string warning;                             // why `auto` fell back to the reference, if it did
};

// `device`: auto | ref | opencl | opencl:P.D. `opencl` takes the first OpenCL GPU, else the
// first OpenCL device. `auto` takes HEMIRAD_DEVICE when it is set, else what `opencl` would,
// else the reference; an automatic OpenCL choice whose kernels fail to build or whose first shot
// disagrees with the reference falls back to the reference with `warning` set. Throws InputError
// for a device that is malformed or not present, or --verify without an OpenCL engine.
EngineChoice choose_engine(const std::string& device, bool verify, long verify_every, const mesh::Mesh& mesh,
                           const formfactor::Settings& settings);

// Another engine of the kind `choice` holds, on its device and context, for another mesh (a
// refined one); never verifying.
std::unique_ptr<formfactor::Engine> engine_like(const EngineChoice& choice, const mesh::Mesh& mesh,
                                                const formfactor::Settings& settings);

}  // namespace hemirad::cli
