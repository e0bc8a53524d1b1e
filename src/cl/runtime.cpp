// OpenCL device discovery and per-context program cache (see runtime.h).
#include "cl/runtime.h"

#include <cstdlib>
#include <fstream>
#include <iostream>
#include <regex>

#if defined(__linux__)
#include <sched.h>
#include <unistd.h>
#endif

#include <fmt/core.h>

#include "core/error.h"

namespace hemirad::ocl {
namespace {

bool has_extension(const cl::Device& d, const char* name) {
    const std::string ext = d.getInfo<CL_DEVICE_EXTENSIONS>();
    return ext.find(name) != std::string::npos;
}

std::string trimmed(std::string s) {
    while (!s.empty() && (s.back() == '\0' || s.back() == ' ' || s.back() == '\n')) s.pop_back();
    return s;
}

// Sets POCL_AFFINITY=1 where should_pin_pocl_threads says so, once, before the ICD loader
// first starts PoCL (which reads its environment then).
void prepare_pocl_environment() {
#if defined(__linux__)
    static const bool done = [] {
        cpu_set_t set;
        CPU_ZERO(&set);
        if (sched_getaffinity(0, sizeof(set), &set) != 0) return true;
        int prefix = 0;
        while (prefix < CPU_SETSIZE && CPU_ISSET(prefix, &set)) ++prefix;
        if (should_pin_pocl_threads(std::getenv("POCL_AFFINITY"), std::getenv("POCL_MAX_PTHREAD_COUNT"),
                                    std::getenv("POCL_PTHREAD_MIN_THREADS"), CPU_COUNT(&set), prefix,
                                    static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN))))
            setenv("POCL_AFFINITY", "1", 0);
        return true;
    }();
    (void)done;
#endif
}

// The host CPU's model and feature flags, for a CPU device's cache key: such a device's name
// ("pthread-haswell-AMD EPYC") can be the same on CPUs of other generations, whose binaries may
// use instructions this one lacks (a cache in a home directory shared between machines).
std::string host_cpu() {
    std::ifstream in("/proc/cpuinfo");
    std::string line, model, flags;
    while (std::getline(in, line) && (model.empty() || flags.empty())) {
        if (model.empty() && line.rfind("model name", 0) == 0) model = line;
        if (flags.empty() && line.rfind("flags", 0) == 0) flags = line;
    }
    return model + '\n' + flags;
}

bool show_kernels() {
    const char* show = std::getenv("HEMIRAD_SHOW_KERNELS");
    return show && std::string(show) == "1";
}

std::vector<cl::Platform> get_platforms() {
    prepare_pocl_environment();
    std::vector<cl::Platform> platforms;
    cl::Platform::get(&platforms);
    return platforms;
}

}  // namespace

std::string error_name(cl_int code) {
    switch (code) {
#define HEMIRAD_CL_CODE(name) \
    case name:                \
        return fmt::format("{} ({})", #name, code);
        HEMIRAD_CL_CODE(CL_DEVICE_NOT_FOUND)
        HEMIRAD_CL_CODE(CL_DEVICE_NOT_AVAILABLE)
        HEMIRAD_CL_CODE(CL_COMPILER_NOT_AVAILABLE)
        HEMIRAD_CL_CODE(CL_MEM_OBJECT_ALLOCATION_FAILURE)
        HEMIRAD_CL_CODE(CL_OUT_OF_RESOURCES)
        HEMIRAD_CL_CODE(CL_OUT_OF_HOST_MEMORY)
        HEMIRAD_CL_CODE(CL_BUILD_PROGRAM_FAILURE)
        HEMIRAD_CL_CODE(CL_EXEC_STATUS_ERROR_FOR_EVENTS_IN_WAIT_LIST)
        HEMIRAD_CL_CODE(CL_INVALID_VALUE)
        HEMIRAD_CL_CODE(CL_INVALID_BUFFER_SIZE)
        HEMIRAD_CL_CODE(CL_INVALID_KERNEL_ARGS)
        HEMIRAD_CL_CODE(CL_INVALID_WORK_GROUP_SIZE)
        HEMIRAD_CL_CODE(CL_INVALID_WORK_ITEM_SIZE)
        HEMIRAD_CL_CODE(CL_INVALID_GLOBAL_WORK_SIZE)
        HEMIRAD_CL_CODE(CL_INVALID_COMMAND_QUEUE)
        HEMIRAD_CL_CODE(CL_INVALID_CONTEXT)
        HEMIRAD_CL_CODE(CL_INVALID_MEM_OBJECT)
#undef HEMIRAD_CL_CODE
        default:
            return fmt::format("OpenCL error {}", code);
    }
}

bool out_of_memory(cl_int code) {
    return code == CL_MEM_OBJECT_ALLOCATION_FAILURE || code == CL_OUT_OF_RESOURCES || code == CL_OUT_OF_HOST_MEMORY ||
           code == CL_INVALID_BUFFER_SIZE;
}

bool should_pin_pocl_threads(const char* affinity, const char* max_threads, const char* min_threads, int allowed,
                             int allowed_prefix, int online) {
    if (affinity != nullptr || min_threads != nullptr) return false;  // the user's choice
    if (online < 1 || allowed != online || allowed_prefix != online) return false;
    if (max_threads != nullptr) {
        char* end = nullptr;
        const long most = std::strtol(max_threads, &end, 10);
        if (end == max_threads || *end != '\0' || most < 1 || most > allowed) return false;
    }
    return true;
}

const DeviceInfo* resolve_device(const std::string& spec, const std::string& label,
                                const std::vector<DeviceInfo>& devices) {
    if (spec == "ref") return nullptr;
    if (spec == "auto" || spec == "opencl") {
        for (const auto& d : devices)
            if (d.type == "gpu") return &d;
        if (!devices.empty()) return &devices.front();
        if (spec == "auto") return nullptr;
        throw InputError(fmt::format("{}: no OpenCL device found (see hemirad devices)", label));
    }
    std::smatch m;
    static const std::regex kExact(R"(opencl:(\d+)\.(\d+))");
    if (std::regex_match(spec, m, kExact)) {
        const int p = std::stoi(m[1]), d = std::stoi(m[2]);
        for (const auto& dev : devices)
            if (dev.platform == p && dev.device == d) return &dev;
        throw InputError(fmt::format("{}: no such OpenCL device (see hemirad devices)", label));
    }
    throw InputError(fmt::format("{}: expected auto, ref, opencl or opencl:P.D", label));
}

std::vector<DeviceInfo> list_devices() {
    std::vector<DeviceInfo> out;
    std::vector<cl::Platform> platforms;
    try {
        platforms = get_platforms();
    } catch (const cl::Error&) {
        return out;  // no ICD loader configuration or no platform: no devices
    }
    for (std::size_t p = 0; p < platforms.size(); ++p) {
        std::vector<cl::Device> devices;
        try {
            platforms[p].getDevices(CL_DEVICE_TYPE_ALL, &devices);
        } catch (const cl::Error&) {
            continue;  // CL_DEVICE_NOT_FOUND on this platform
        }
        for (std::size_t d = 0; d < devices.size(); ++d) {
            const cl::Device& dev = devices[d];
            DeviceInfo info;
            info.platform = static_cast<int>(p);
            info.device = static_cast<int>(d);
            info.platform_name = trimmed(platforms[p].getInfo<CL_PLATFORM_NAME>());
            info.name = trimmed(dev.getInfo<CL_DEVICE_NAME>());
            info.vendor = trimmed(dev.getInfo<CL_DEVICE_VENDOR>());
            info.version = trimmed(dev.getInfo<CL_DEVICE_VERSION>());
            info.driver = trimmed(dev.getInfo<CL_DRIVER_VERSION>());
            const cl_device_type type = dev.getInfo<CL_DEVICE_TYPE>();
            info.type = (type & CL_DEVICE_TYPE_GPU)           ? "gpu"
                        : (type & CL_DEVICE_TYPE_CPU)         ? "cpu"
                        : (type & CL_DEVICE_TYPE_ACCELERATOR) ? "accelerator"
                                                              : "other";
            info.fp64 = has_extension(dev, "cl_khr_fp64");
            info.int64_atomics = has_extension(dev, "cl_khr_int64_base_atomics");
            info.compute_units = static_cast<int>(dev.getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>());
            info.max_work_group = dev.getInfo<CL_DEVICE_MAX_WORK_GROUP_SIZE>();
            info.global_memory = static_cast<std::size_t>(dev.getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>());
            out.push_back(info);
        }
    }
    return out;
}

Context::Context(const DeviceInfo& device, std::optional<std::filesystem::path> cache_dir)
    : info_(device), disk_(std::move(cache_dir)) {
    const std::vector<cl::Platform> platforms = get_platforms();
    std::vector<cl::Device> devices;
    platforms.at(static_cast<std::size_t>(device.platform)).getDevices(CL_DEVICE_TYPE_ALL, &devices);
    device_ = devices.at(static_cast<std::size_t>(device.device));
    context_ = cl::Context(device_);
    queue_ = cl::CommandQueue(context_, device_, CL_QUEUE_PROFILING_ENABLE);
    // Queried from the device itself, not from `info_`: the key must describe what builds the
    // binary. The driver version is in it so that a driver update never loads its old binaries.
    const cl::Platform platform(device_.getInfo<CL_DEVICE_PLATFORM>());
    identity_ =
        fmt::format("hemirad {} program binary, entry format {}\nplatform: {} | {}\ndevice: {} | {} | {}\ndriver: {}\n",
                    HEMIRAD_VERSION, kProgramCacheFormat, trimmed(platform.getInfo<CL_PLATFORM_NAME>()),
                    trimmed(platform.getInfo<CL_PLATFORM_VERSION>()), trimmed(device_.getInfo<CL_DEVICE_NAME>()),
                    trimmed(device_.getInfo<CL_DEVICE_VENDOR>()), trimmed(device_.getInfo<CL_DEVICE_VERSION>()),
                    trimmed(device_.getInfo<CL_DRIVER_VERSION>()));
    if (device_.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_CPU) identity_ += "host cpu: " + host_cpu() + '\n';
}

std::string Context::program_key(const std::string& source, const std::string& options) const {
    return identity_ + "options: " + options + "\nsource:\n" + source;
}

cl::Program& Context::program(const std::string& source, const std::string& options) {
    const std::string key = options + '\0' + source;
    if (auto it = programs_.find(key); it != programs_.end()) return it->second;
    const std::string disk_key = disk_.enabled() ? program_key(source, options) : std::string();
    const std::optional<std::vector<unsigned char>> binary = disk_.load(disk_key);
    const bool show = show_kernels();
    if (show)
        std::cerr << fmt::format(
            "hemirad: {} for {} ({}) with options '{}':\n{}\n",
            binary ? fmt::format("loading from the program cache ({})", disk_.entry_path(disk_key).string())
                   : "building",
            info_.name, info_.id(), options, source);

    if (binary) {
        // A binary the driver refuses (an entry from another build of the same driver version, or
        // damaged in a way the checksum missed) is built from source and its entry rewritten.
        try {
            cl::Program program(context_, {device_}, cl::Program::Binaries{*binary});
            program.build(std::vector<cl::Device>{device_}, options.c_str());
            ++counts_.loaded;
            return programs_.emplace(key, std::move(program)).first->second;
        } catch (const cl::Error& e) {
            ++counts_.rejected;
            if (show)
                std::cerr << fmt::format("hemirad: the program cache's entry was refused ({}); building\n",
                                         error_name(e.err()));
        }
    }
    cl::Program program = build_from_source(source, options);
    ++counts_.built;
    if (disk_.enabled()) {
        try {
            const std::vector<std::vector<unsigned char>> binaries = program.getInfo<CL_PROGRAM_BINARIES>();
            if (binaries.size() == 1 && disk_.store(disk_key, binaries.front())) ++counts_.stored;
        } catch (const cl::Error&) {
            // a driver that cannot give its binary: the next run builds again
        }
    }
    return programs_.emplace(key, std::move(program)).first->second;
}

cl::Program Context::build_from_source(const std::string& source, const std::string& options) {
    cl::Program program(context_, source);
    try {
        program.build(std::vector<cl::Device>{device_}, options.c_str());
    } catch (const cl::Error&) {
        std::string log;
        try {
            log = program.getBuildInfo<CL_PROGRAM_BUILD_LOG>(device_);
        } catch (const cl::Error&) {
            log = "(no build log)";
        }
        throw BuildError(fmt::format("OpenCL kernel build failed on {} ({}) with options '{}':\n{}", info_.name,
                                     info_.id(), options, trimmed(log)));
    }
    return program;
}

}  // namespace hemirad::ocl
