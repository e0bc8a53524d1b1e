// Picks the form-factor engine of a bake from --device, HEMIRAD_DEVICE and --verify.
#pragma once

#include <exception>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cl/runtime.h"
#include "formfactor/engine.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/sharded.h"
#include "formfactor/verify.h"
#include "mesh/mesh.h"

namespace hemirad::bake {

struct EngineChoice {
    // One device whose engine takes a share of every batch.
    struct Device {
        std::unique_ptr<ocl::Context> context;       // null: the scalar reference
        formfactor::OpenCLTuning tuning;             // the device's, with HEMIRAD_OPENCL_OPTIONS applied
        std::string id, name, platform;
    };
    std::vector<Device> devices;                     // outlive the engines that use them
    std::unique_ptr<formfactor::Engine> engine;      // the hemicube engine, verifying if asked
    formfactor::VerifyingEngine* verifier = nullptr; // into `engine` when --verify
    std::string backend, platform, name, id;         // what report.json and the log say (joined by ", ")
    std::string warning;                             // why `auto` or `all` left a device out, if it did
    // `auto` or `all` chose these OpenCL devices: a failing one drops out (its shots redone by
    // the others), and a bake whose last one fails may fall back to the reference.
    bool automatic = false;
    formfactor::OpenCLFault fault;                   // HEMIRAD_FAULT, for every engine made on the devices
    // How often the devices' engines ran out of memory and cut their batches, and to how few.
    struct Shrinks {
        std::mutex mutex;  // the devices' engines run on threads of their own
        long count = 0;
        std::size_t smallest = std::numeric_limits<std::size_t>::max();
        std::string why;  // the first OpenCL error
    };
    std::shared_ptr<Shrinks> shrinks = std::make_shared<Shrinks>();
    // What each member (device or MPI rank) computed, when more than one shares the batches.
    std::shared_ptr<formfactor::ShardStats> stats = std::make_shared<formfactor::ShardStats>();
    // The members sharing each batch: the devices, and the worker ranks of an MPI bake.
    std::size_t members() const { return devices.size() + remote_ranks(); }
    static std::size_t remote_ranks();
};

// The devices a --device spec names, without opening any: how many members a bake will have
// (for the batch it plans) before its engines are made. Throws InputError as choose_engine does.
std::size_t device_count(const std::string& device);

// `device`: auto | all | ref | opencl | opencl:P.D, or a comma-separated list of ref, opencl and
// opencl:P.D (each at most once), whose devices share every batch (formfactor::ShardedEngine).
// `opencl` takes the first OpenCL GPU, else the first OpenCL device. `auto` takes HEMIRAD_DEVICE
// when it is set, else what `opencl` would, else the reference; `all` takes every OpenCL device,
// else the reference. An automatic OpenCL device (auto, all) whose kernels fail to build or whose
// first shot disagrees with the reference is left out with `warning` set (none left: the
// reference). On rank 0 of an MPI bake the worker ranks join as members too. Throws InputError
// for a device that is malformed or not present, --verify without exactly one OpenCL engine, or a
// malformed HEMIRAD_FAULT or HEMIRAD_OPENCL_OPTIONS.
EngineChoice choose_engine(const std::string& device, bool verify, long verify_every, const mesh::Mesh& mesh,
                           const formfactor::Settings& settings);

// The one-line reason when `e` is a failure of the device rather than of the input or of
// hemirad: the device failed (ocl::DeviceError, an OpenCL call's cl::Error), its kernels did not
// build, or --verify caught it computing something else. Empty for any other exception.
std::string device_failure(const std::exception& e);

// Another engine of the kind `choice` holds, on its devices (and ranks), for another mesh (a
// refined one); never verifying.
std::unique_ptr<formfactor::Engine> engine_like(const EngineChoice& choice, const mesh::Mesh& mesh,
                                                const formfactor::Settings& settings);

// For the scaling benchmark: an engine on the first `devices` of `choice`'s devices and the first
// `ranks` worker ranks (0: none); a ShardedEngine when that is more than one member.
std::unique_ptr<formfactor::Engine> engine_on(const EngineChoice& choice, std::size_t devices, int ranks,
                                              const mesh::Mesh& mesh, const formfactor::Settings& settings);

}  // namespace hemirad::bake
