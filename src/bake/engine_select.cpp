// Device selection for `hemirad bake` (see engine_select.h).
#include "bake/engine_select.h"

#include <fmt/core.h>

#include <algorithm>
#include <cstdlib>

#include "core/error.h"
#include "dist/dist.h"
#include "formfactor/device_mesh.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"

namespace hemirad::bake {
namespace {

// `auto` trusts a device only after one shot agrees with the reference: a driver that builds the
// kernels but computes something else must not quietly change a bake.
std::string probe(formfactor::Engine& engine, const mesh::Mesh& mesh, const formfactor::Settings& settings) {
    formfactor::ReferenceEngine reference(mesh, settings);
    formfactor::ShotResult got, want;
    const auto patch = static_cast<std::uint32_t>(mesh.patches.size() / 2);
    engine.shoot(patch, 0, got);
    reference.shoot(patch, 0, want);
    return formfactor::compare_shot(got, want);
}

std::string first_line(const std::string& text) { return text.substr(0, text.find('\n')); }

// The spec `auto` stands for: HEMIRAD_DEVICE when set (and `label` says so).
std::string effective_spec(const std::string& device, std::string& label) {
    label = "--device " + device;
    if (device == "auto")
        if (const char* env = std::getenv("HEMIRAD_DEVICE"); env && *env) {
            label = fmt::format("HEMIRAD_DEVICE={}", env);
            return env;
        }
    return device;
}

std::vector<std::string> split_list(const std::string& spec) {
    std::vector<std::string> out;
    std::size_t at = 0;
    for (;;) {
        const std::size_t comma = spec.find(',', at);
        out.push_back(spec.substr(at, comma == std::string::npos ? std::string::npos : comma - at));
        if (comma == std::string::npos) return out;
        at = comma + 1;
    }
}

// The devices a spec names, in its order (nullptr: the reference); `automatic` when `auto` or
// `all` chose them.
std::vector<const ocl::DeviceInfo*> resolve_devices(const std::string& spec, const std::string& label,
                                                    const std::vector<ocl::DeviceInfo>& devices, bool& automatic) {
    automatic = spec == "auto" || spec == "all";
    if (spec == "all") {
        std::vector<const ocl::DeviceInfo*> out;
        for (const ocl::DeviceInfo& d : devices) out.push_back(&d);
        if (out.empty()) out.push_back(nullptr);
        return out;
    }
    const std::vector<std::string> parts = split_list(spec);
    if (parts.size() == 1) return {ocl::resolve_device(spec, label, devices)};
    std::vector<const ocl::DeviceInfo*> out;
    std::vector<std::string> ids;
    for (const std::string& part : parts) {
        if (part != "ref" && part != "opencl" && part.rfind("opencl:", 0) != 0)
            throw InputError(fmt::format("{}: a list holds ref, opencl and opencl:P.D, not '{}'", label, part));
        const ocl::DeviceInfo* d = ocl::resolve_device(part, label, devices);
        const std::string id = d ? d->id() : "ref";
        if (std::find(ids.begin(), ids.end(), id) != ids.end())
            throw InputError(fmt::format("{}: names {} twice", label, id));
        ids.push_back(id);
        out.push_back(d);
    }
    return out;
}

std::unique_ptr<formfactor::Engine> device_engine(const EngineChoice& choice, const EngineChoice::Device& device,
                                                  const mesh::Mesh& mesh, const formfactor::DeviceMesh* packed,
                                                  const formfactor::Settings& settings) {
    if (!device.context) return std::make_unique<formfactor::ReferenceEngine>(mesh, settings);
    formfactor::OpenCLTuning tuning = device.tuning;
    tuning.on_shrink = [shrinks = choice.shrinks](std::size_t, std::size_t limit, const std::string& why) {
        std::lock_guard lock(shrinks->mutex);
        if (shrinks->count++ == 0) shrinks->why = why;
        shrinks->smallest = std::min(shrinks->smallest, limit);
    };
    const formfactor::OpenCLFault fault =
        choice.fault.device.empty() || choice.fault.device == device.id ? choice.fault : formfactor::OpenCLFault{};
    if (packed) return std::make_unique<formfactor::OpenCLEngine>(mesh, *packed, *device.context, settings, tuning, fault);
    return std::make_unique<formfactor::OpenCLEngine>(mesh, *device.context, settings, tuning, fault);
}

bool dropped(const EngineChoice& choice, const std::string& id) {
    std::lock_guard lock(choice.stats->mutex);
    for (const formfactor::ShardStats::Member& m : choice.stats->members)
        if (m.id == id) return !m.dropped.empty();
    return false;
}

// The devices' engines and the worker ranks' (`ranks` of them, or all when < 0) as one engine.
std::unique_ptr<formfactor::Engine> assemble(const EngineChoice& choice, std::vector<formfactor::ShardedEngine::Member> members,
                                             const mesh::Mesh& mesh, const formfactor::Settings& settings, int ranks = -1) {
    if (ranks != 0)
        for (dist::RemoteMember& r : dist::remote_engines(mesh, settings, std::max(ranks, 0)))
            members.push_back({std::move(r.engine), r.id, choice.automatic});
    // One member of a bake of several (the others dropped out) still counts its shots.
    if (members.size() == 1 && (choice.members() == 1 || ranks >= 0)) return std::move(members.front().engine);
    return std::make_unique<formfactor::ShardedEngine>(
        std::move(members), [](const std::exception& e) { return device_failure(e); }, choice.stats);
}

// An engine per device, in order, but for those that failed and left the bake already.
std::vector<formfactor::ShardedEngine::Member> device_engines(const EngineChoice& choice, const mesh::Mesh& mesh,
                                                              const formfactor::Settings& settings) {
    std::vector<const EngineChoice::Device*> in;
    for (const EngineChoice::Device& d : choice.devices)
        if (!dropped(choice, d.id)) in.push_back(&d);
    if (in.empty()) throw InternalError("engine_like: every device has left the bake");
    // Several devices upload one packing of the mesh.
    const auto opencl = std::count_if(in.begin(), in.end(), [](const EngineChoice::Device* d) { return d->context != nullptr; });
    const std::unique_ptr<formfactor::DeviceMesh> packed =
        opencl > 1 ? std::make_unique<formfactor::DeviceMesh>(mesh) : nullptr;
    std::vector<formfactor::ShardedEngine::Member> out;
    for (const EngineChoice::Device* d : in)
        out.push_back({device_engine(choice, *d, mesh, packed.get(), settings), d->id, choice.automatic});
    return out;
}

template <class Fn>
std::string joined(const std::vector<EngineChoice::Device>& devices, const char* separator, Fn field) {
    std::vector<std::string> seen;
    std::string out;
    for (const EngineChoice::Device& d : devices) {
        const std::string v = field(d);
        if (std::find(seen.begin(), seen.end(), v) != seen.end()) continue;
        seen.push_back(v);
        out += (out.empty() ? "" : separator) + v;
    }
    return out;
}

EngineChoice::Device reference_device() {
    EngineChoice::Device d;
    d.id = "ref";
    d.name = "scalar reference hemicube (1 thread)";
    d.platform = "host";
    return d;
}

}  // namespace

std::size_t EngineChoice::remote_ranks() { return static_cast<std::size_t>(dist::rank() == 0 ? dist::size() - 1 : 0); }

std::size_t device_count(const std::string& device) {
    std::string label;
    const std::string spec = effective_spec(device, label);
    if (spec == "all") return std::max<std::size_t>(1, ocl::list_devices().size());
    return split_list(spec).size();
}

EngineChoice choose_engine(const std::string& device, bool verify, long verify_every, const mesh::Mesh& mesh,
                           const formfactor::Settings& settings) {
    std::string label;
    const std::string spec = effective_spec(device, label);  // `auto` may become HEMIRAD_DEVICE's value
    const bool wants_opencl = spec != "ref";
    const std::vector<ocl::DeviceInfo> devices = wants_opencl ? ocl::list_devices() : std::vector<ocl::DeviceInfo>{};
    bool automatic = false;
    const std::vector<const ocl::DeviceInfo*> chosen = resolve_devices(spec, label, devices, automatic);
    const bool one_opencl = chosen.size() == 1 && chosen.front() != nullptr;
    if (verify && !one_opencl) {
        if (chosen.size() == 1)
            throw InputError(devices.empty() && wants_opencl
                                 ? "--verify checks an OpenCL engine against the reference, and no OpenCL device was "
                                   "found (see hemirad devices)"
                                 : "--verify checks an OpenCL engine against the reference; choose --device opencl");
        throw InputError("--verify checks one OpenCL device against the reference; name one device");
    }
    if (verify && EngineChoice::remote_ranks() > 0)
        throw InputError("--verify checks one OpenCL device against the reference, in one process (not under mpirun)");

    EngineChoice out;
    // Malformed: exit 2, never a fallback.
    out.fault = formfactor::fault_from_environment();
    std::vector<formfactor::ShardedEngine::Member> engines;
    std::vector<std::string> left_out;
    for (const ocl::DeviceInfo* d : chosen) {
        if (!d) {
            out.devices.push_back(reference_device());
            engines.push_back({std::make_unique<formfactor::ReferenceEngine>(mesh, settings), "ref", false});
            continue;
        }
        EngineChoice::Device device;
        device.tuning = formfactor::tuning_from_environment(*d);
        device.id = d->id();
        device.name = d->name;
        device.platform = d->platform_name;
        if (!automatic) {
            device.context = std::make_unique<ocl::Context>(*d);
            out.devices.push_back(std::move(device));
            continue;  // engines made below, sharing one packing of the mesh
        }
        // Any failure of an automatic choice leaves the device out, with a warning; bad input
        // (tuning knobs the device cannot take) stays exit 2.
        try {
            device.context = std::make_unique<ocl::Context>(*d);
            out.devices.push_back(std::move(device));
            std::unique_ptr<formfactor::Engine> engine = device_engine(out, out.devices.back(), mesh, nullptr, settings);
            if (const std::string problem = probe(*engine, mesh, settings); !problem.empty())
                throw std::runtime_error("its first shot disagrees with the reference: " + problem);
            engines.push_back({std::move(engine), d->id(), true});
        } catch (const InputError&) {
            throw;
        } catch (const std::exception& e) {
            if (!out.devices.empty() && out.devices.back().id == d->id()) out.devices.pop_back();
            left_out.push_back(fmt::format("{} ({}): {}", d->id(), d->name, first_line(e.what())));
        }
    }
    if (out.devices.empty()) {  // every automatic device failed
        EngineChoice fallback = choose_engine("ref", verify, verify_every, mesh, settings);
        for (std::size_t i = 0; i < left_out.size(); ++i)
            fallback.warning += (i ? "; " : "") + left_out[i];
        fallback.warning += "; using the reference engine";
        return fallback;
    }
    for (std::size_t i = 0; i < left_out.size(); ++i) out.warning += (i ? "; " : "") + left_out[i] + "; left out of the bake";
    if (!automatic) engines = device_engines(out, mesh, settings);
    out.automatic = automatic && std::any_of(out.devices.begin(), out.devices.end(),
                                             [](const EngineChoice::Device& d) { return d.context != nullptr; });
    out.engine = assemble(out, std::move(engines), mesh, settings);
    if (verify) {
        auto verifying = std::make_unique<formfactor::VerifyingEngine>(
            std::move(out.engine), std::make_unique<formfactor::ReferenceEngine>(mesh, settings), verify_every);
        out.verifier = verifying.get();
        out.engine = std::move(verifying);
    }
    out.backend = joined(out.devices, "+", [](const EngineChoice::Device& d) { return d.context ? "opencl" : "ref"; });
    out.platform = joined(out.devices, ", ", [](const EngineChoice::Device& d) { return d.platform; });
    out.name = joined(out.devices, ", ", [](const EngineChoice::Device& d) { return d.name; });
    out.id = joined(out.devices, ",", [](const EngineChoice::Device& d) { return d.id; });
    return out;
}

std::string device_failure(const std::exception& e) {
    if (const auto* cl_error = dynamic_cast<const cl::Error*>(&e))
        return fmt::format("{} failed: {}", cl_error->what(), ocl::error_name(cl_error->err()));
    if (dynamic_cast<const ocl::DeviceError*>(&e) || dynamic_cast<const ocl::BuildError*>(&e))
        return first_line(e.what());
    if (dynamic_cast<const formfactor::VerifyError*>(&e)) return "verification failed: " + first_line(e.what());
    return {};
}

std::unique_ptr<formfactor::Engine> engine_like(const EngineChoice& choice, const mesh::Mesh& mesh,
                                                const formfactor::Settings& settings) {
    if (choice.devices.empty()) throw InternalError("engine_like: the choice holds no device");
    return assemble(choice, device_engines(choice, mesh, settings), mesh, settings);
}

std::unique_ptr<formfactor::Engine> engine_on(const EngineChoice& choice, std::size_t devices, int ranks,
                                              const mesh::Mesh& mesh, const formfactor::Settings& settings) {
    std::vector<formfactor::ShardedEngine::Member> members = device_engines(choice, mesh, settings);
    if (devices < 1 || devices > members.size()) throw InternalError("engine_on: no such number of devices");
    members.resize(devices);
    return assemble(choice, std::move(members), mesh, settings, ranks);
}

}  // namespace hemirad::bake
