// Picks the form-factor engine of a bake from --device, HEMIRAD_DEVICE and --verify.
#pragma once

#include <exception>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "cl/runtime.h"
#include "formfactor/engine.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/verify.h"
#include "mesh/mesh.h"

namespace hemirad::cli {

struct EngineChoice {
    std::unique_ptr<ocl::Context> context;           // outlives the OpenCL engine that uses it
    std::unique_ptr<formfactor::Engine> engine;      // the hemicube engine, verifying if asked
    formfactor::VerifyingEngine* verifier = nullptr; // into `engine` when --verify
    std::string backend, platform, name, id;         // what report.json and the log say
    std::string warning;                             // why `auto` fell back to the reference, if it did
    bool automatic = false;                          // `auto` chose this OpenCL device: a bake may fall back
    formfactor::OpenCLFault fault;                   // HEMIRAD_FAULT, for every engine made on the device
    formfactor::OpenCLTuning tuning;                 // the device's, with HEMIRAD_OPENCL_OPTIONS applied
    // How often the device's engines ran out of memory and cut their batches, and to how few.
    struct Shrinks {
        long count = 0;
        std::size_t smallest = std::numeric_limits<std::size_t>::max();
        std::string why;  // the first OpenCL error
    };
    std::shared_ptr<Shrinks> shrinks = std::make_shared<Shrinks>();
};

// `device`: auto | ref | opencl | opencl:P.D. `opencl` takes the first OpenCL GPU, else the
// first OpenCL device. `auto` takes HEMIRAD_DEVICE when it is set, else what `opencl` would,
// else the reference; an automatic OpenCL choice whose kernels fail to build or whose first shot
// disagrees with the reference falls back to the reference with `warning` set. Throws InputError
// for a device that is malformed or not present, --verify without an OpenCL engine, or a
// malformed HEMIRAD_FAULT or HEMIRAD_OPENCL_OPTIONS.
EngineChoice choose_engine(const std::string& device, bool verify, long verify_every, const mesh::Mesh& mesh,
                           const formfactor::Settings& settings);

// The one-line reason when `e` is a failure of the device rather than of the input or of
// hemirad: the device failed (ocl::DeviceError, an OpenCL call's cl::Error), its kernels did not
// build, or --verify caught it computing something else. Empty for any other exception.
std::string device_failure(const std::exception& e);

// Another engine of the kind `choice` holds, on its device and context, for another mesh (a
// refined one); never verifying.
std::unique_ptr<formfactor::Engine> engine_like(const EngineChoice& choice, const mesh::Mesh& mesh,
                                                const formfactor::Settings& settings);

}  // namespace hemirad::cli
