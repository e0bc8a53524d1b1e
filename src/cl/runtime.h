// OpenCL runtime: device discovery, selection, and per-context program caching with build logs
// (built binaries also kept on the disk across runs: program_cache.h).
// Namespace `ocl` (not `cl`) so the Khronos C++ bindings' `cl::` stays unambiguous.
#pragma once

#include <CL/opencl.hpp>

#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "cl/program_cache.h"

namespace hemirad::ocl {

struct DeviceInfo {
    int platform = 0, device = 0;     // indices as `opencl:P.D`
    std::string platform_name, name, vendor, version, driver;
    std::string type;                 // "cpu", "gpu", "accelerator" or "other"
    bool fp64 = false;                // cl_khr_fp64
    bool int64_atomics = false;       // cl_khr_int64_base_atomics
    int compute_units = 0;
    std::size_t max_work_group = 0;
    std::size_t global_memory = 0;    // bytes
    std::string id() const { return "opencl:" + std::to_string(platform) + "." + std::to_string(device); }
};

// Every OpenCL device of every platform; empty (never throws) when there is no ICD or platform.
std::vector<DeviceInfo> list_devices();

// The device a --device spec names among `devices`: auto (the first GPU, else the first device,
// else nullptr for the reference), ref (nullptr), opencl (as auto, but no device is an error) or
// opencl:P.D. Throws InputError naming `label` ("--device X", "HEMIRAD_DEVICE=X") otherwise.
const DeviceInfo* resolve_device(const std::string& spec, const std::string& label,
                                 const std::vector<DeviceInfo>& devices);

// Whether hemirad should ask PoCL to pin its worker threads (POCL_AFFINITY=1, worker i on CPU
// i), which the first OpenCL call in the process does where this says so: only when the user
// set none of POCL_AFFINITY, POCL_MAX_PTHREAD_COUNT above `allowed`, or POCL_PTHREAD_MIN_THREADS
// (null where unset), and this process may run on exactly CPUs 0 .. online - 1 (`allowed` of
// them, the first `allowed_prefix` consecutive from 0), so that every worker's CPU exists and is
// allowed. Unpinned, the workers migrated between cores and the Cornell bench ran ~1.3x slower
// on 2 cores (README, Known limits).
bool should_pin_pocl_threads(const char* affinity, const char* max_threads, const char* min_threads, int allowed,
                             int allowed_prefix, int online);

// A program failed to build. what() holds the device, the options and the full build log.
class BuildError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// The device failed at run time: out of memory even for one shot, lost, or an OpenCL call that
// returned an error. what() names the device and the failed call with its CL_ error code.
class DeviceError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// "CL_MEM_OBJECT_ALLOCATION_FAILURE (-4)" and the like; "OpenCL error -N" for codes it does not know.
std::string error_name(cl_int code);

// Whether `code` says the device (or the host driving it) had not the memory for a request.
bool out_of_memory(cl_int code);

// How a context's programs were made: tests look, HEMIRAD_SHOW_KERNELS says.
struct ProgramCounts {
    int built = 0;     // compiled from source
    int loaded = 0;    // from a binary in the disk cache
    int rejected = 0;  // disk entries the driver would not build (then built from source)
    int stored = 0;    // binaries written to the disk cache
};

// One device, its context and an in-order queue with profiling. Programs are built once per
// (source, options) and kept for the life of the context: the cache belongs to the context,
// never to a global, so tests and engines cannot interfere. Across runs, built binaries are kept
// in `cache_dir` (nullopt: not kept), keyed by source, options, device, driver and platform.
class Context {
public:
    explicit Context(const DeviceInfo& device) : Context(device, program_cache_directory(device.type)) {}
    Context(const DeviceInfo& device, std::optional<std::filesystem::path> cache_dir);
    const DeviceInfo& info() const { return info_; }
    cl::Context& context() { return context_; }
    cl::Device& device() { return device_; }
    cl::CommandQueue& queue() { return queue_; }

    // Builds (or returns the cached) program from `source` with `options`: from the disk cache
    // where it holds a binary the driver accepts, else from source, then stored there. With
    // HEMIRAD_SHOW_KERNELS=1 the exact source and options, and which way, go to stderr first.
    // Throws BuildError with the build log on failure.
    cl::Program& program(const std::string& source, const std::string& options);

    const ProgramCounts& program_counts() const { return counts_; }
    const ProgramCache& program_cache() const { return disk_; }
    // The disk cache's key for a program: everything a stored binary depends on, source included.
    std::string program_key(const std::string& source, const std::string& options) const;

private:
    cl::Program build_from_source(const std::string& source, const std::string& options);

    DeviceInfo info_;
    cl::Device device_;
    cl::Context context_;
    cl::CommandQueue queue_;
    std::map<std::string, cl::Program> programs_;  // key: options + '\0' + source
    ProgramCache disk_;
    std::string identity_;  // the platform, device and driver part of program_key
    ProgramCounts counts_;
};

// The embedded text of kernels/<name>, its includes of kernels/ files inlined with #line directives
// (cmake/EmbedKernels.cmake). Throws std::out_of_range for an unknown name or a file another includes.
std::string_view kernel_source(std::string_view name);

}  // namespace hemirad::ocl
