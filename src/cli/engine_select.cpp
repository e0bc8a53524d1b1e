// Device selection for `hemirad bake` (see engine_select.h).
#include "cli/engine_select.h"

#include <fmt/core.h>

#include <algorithm>
#include <cstdlib>

#include "core/error.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"

namespace hemirad::cli {
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

std::unique_ptr<formfactor::OpenCLEngine> make_opencl_engine(const mesh::Mesh& mesh, const EngineChoice& choice,
                                                             const formfactor::Settings& settings) {
    formfactor::OpenCLTuning tuning = choice.tuning;
    tuning.on_shrink = [shrinks = choice.shrinks](std::size_t, std::size_t limit, const std::string& why) {
        if (shrinks->count++ == 0) shrinks->why = why;
        shrinks->smallest = std::min(shrinks->smallest, limit);
    };
    return std::make_unique<formfactor::OpenCLEngine>(mesh, *choice.context, settings, tuning, choice.fault);
}

}  // namespace

EngineChoice choose_engine(const std::string& device, bool verify, long verify_every, const mesh::Mesh& mesh,
                           const formfactor::Settings& settings) {
    std::string spec = device, label = "--device " + device;  // `auto` may become HEMIRAD_DEVICE's value
    if (spec == "auto") {
        const char* env = std::getenv("HEMIRAD_DEVICE");
        if (env && *env) {
            spec = env;
            label = "HEMIRAD_DEVICE=" + spec;
        }
    }
    const bool wants_opencl = spec != "ref";
    const std::vector<ocl::DeviceInfo> devices = wants_opencl ? ocl::list_devices() : std::vector<ocl::DeviceInfo>{};
    const ocl::DeviceInfo* chosen = ocl::resolve_device(spec, label, devices);

    EngineChoice out;
    if (!chosen) {
        if (verify)
            throw InputError(devices.empty() && wants_opencl
                                 ? "--verify checks an OpenCL engine against the reference, and no OpenCL device was "
                                   "found (see hemirad devices)"
                                 : "--verify checks an OpenCL engine against the reference; choose --device opencl");
        out.engine = std::make_unique<formfactor::ReferenceEngine>(mesh, settings);
        out.backend = "ref";
        out.platform = "host";
        out.name = "scalar reference hemicube (1 thread)";
        out.id = "ref";
        return out;
    }
    // Malformed: exit 2, never a fallback.
    out.fault = formfactor::fault_from_environment();
    out.tuning = formfactor::tuning_from_environment(*chosen);
    if (spec == "auto") {
        // Any failure of the automatic choice falls back to the reference, with a warning; bad
        // input (tuning knobs the device cannot take) stays exit 2.
        try {
            out.context = std::make_unique<ocl::Context>(*chosen);
            out.engine = make_opencl_engine(mesh, out, settings);
            if (const std::string problem = probe(*out.engine, mesh, settings); !problem.empty())
                throw std::runtime_error("its first shot disagrees with the reference: " + problem);
        } catch (const InputError&) {
            throw;
        } catch (const std::exception& e) {
            EngineChoice fallback = choose_engine("ref", verify, verify_every, mesh, settings);
            fallback.warning = fmt::format("{} ({}): {}; using the reference engine", chosen->id(), chosen->name,
                                           first_line(e.what()));
            return fallback;
        }
    } else {
        out.context = std::make_unique<ocl::Context>(*chosen);
        out.engine = make_opencl_engine(mesh, out, settings);
    }
    out.automatic = spec == "auto";
    if (verify) {
        auto verifying = std::make_unique<formfactor::VerifyingEngine>(
            std::move(out.engine), std::make_unique<formfactor::ReferenceEngine>(mesh, settings), verify_every);
        out.verifier = verifying.get();
        out.engine = std::move(verifying);
    }
    out.backend = "opencl";
    out.platform = chosen->platform_name;
    out.name = chosen->name;
    out.id = chosen->id();
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
    if (choice.context) return make_opencl_engine(mesh, choice, settings);
    return std::make_unique<formfactor::ReferenceEngine>(mesh, settings);
}

}  // namespace hemirad::cli
