// The list of form-factor backends the tests run on (backends.h).
#include "backends.h"

#include <stdexcept>

#include "core/error.h"
#include "dist/dist.h"
#include "formfactor/opencl_engine.h"
#include "formfactor/reference.h"
#include "formfactor/sharded.h"
#if HEMIRAD_HAVE_EMBREE
#include "formfactor/embree_engine.h"
#endif

namespace hemirad::test {
namespace {

std::string device_failure(const std::exception& e) {
    return dynamic_cast<const ocl::DeviceError*>(&e) ? std::string(e.what()) : std::string();
}

std::vector<Backend> make_backends() {
    std::vector<Backend> out;
    Backend ref;
    ref.name = "ref";
    ref.present = true;
    ref.device = "ref";
    ref.make = [](const mesh::Mesh& m, const formfactor::Settings& s) -> std::unique_ptr<formfactor::Engine> {
        return std::make_unique<formfactor::ReferenceEngine>(m, s);
    };
    out.push_back(ref);

    // Each device's engine as the tests have always made them: default tuning, one context per
    // device for the process (its programs built once).
    const std::vector<ocl::DeviceInfo> devices = ocl::list_devices();
    for (const ocl::DeviceInfo& d : devices) {
        Backend cl;
        cl.name = d.id();
        cl.present = true;
        cl.device = d.id();
        cl.context_ = std::make_shared<ocl::Context>(d);
        cl.make = [context = cl.context_](const mesh::Mesh& m,
                                          const formfactor::Settings& s) -> std::unique_ptr<formfactor::Engine> {
            return std::make_unique<formfactor::OpenCLEngine>(m, *context, s);
        };
        out.push_back(cl);
    }
    if (devices.empty()) {
        Backend cl;
        cl.name = "opencl";
        cl.why = "no OpenCL device (no ICD, platform or device found)";
        out.push_back(cl);
    }

    Backend embree;
    embree.name = "embree";
    embree.exact = false;
#if HEMIRAD_HAVE_EMBREE
    embree.present = true;
    embree.make = [](const mesh::Mesh& m, const formfactor::Settings& s) -> std::unique_ptr<formfactor::Engine> {
        return std::make_unique<formfactor::EmbreeEngine>(m, s);
    };
#else
    embree.why = "built without Embree 3 (HEMIRAD_HAVE_EMBREE unset)";
#endif
    out.push_back(embree);

    // Two members sharing every batch: the reference beside the first device (what --device
    // ref,opencl:P.D bakes on), else two references.
    Backend sharded;
    sharded.name = "sharded";
    sharded.present = true;
    const Backend* first_cl = devices.empty() ? nullptr : &out[1];
    const std::shared_ptr<ocl::Context> context = first_cl ? first_cl->context_ : nullptr;
    if (first_cl) sharded.device = "ref," + first_cl->name;
    const std::string second = first_cl ? first_cl->name : "ref 2";
    sharded.make = [context, second](const mesh::Mesh& m,
                                     const formfactor::Settings& s) -> std::unique_ptr<formfactor::Engine> {
        std::vector<formfactor::ShardedEngine::Member> members;
        members.push_back({std::make_unique<formfactor::ReferenceEngine>(m, s), "ref", false});
        if (context)
            members.push_back({std::make_unique<formfactor::OpenCLEngine>(m, *context, s), second, false});
        else
            members.push_back({std::make_unique<formfactor::ReferenceEngine>(m, s), second, false});
        return std::make_unique<formfactor::ShardedEngine>(std::move(members), device_failure);
    };
    out.push_back(sharded);

    Backend ranks;
    ranks.name = "ranks";
    ranks.why = dist::built_with_mpi()
                    ? "MPI worker ranks exist only under mpirun (tests/mpi/run_mpi_tests.sh bakes on them); this "
                      "process is rank 0 of " + std::to_string(dist::size())
                    : "built without MPI";
    out.push_back(ranks);
    return out;
}

}  // namespace

ocl::Context* Backend::context() const { return context_.get(); }

const std::vector<Backend>& backends() {
    // Kept for the process (never destroyed): the OpenCL contexts are not released after main,
    // when the driver may have gone.
    static const std::vector<Backend>* list = new std::vector<Backend>(make_backends());
    return *list;
}

std::vector<std::string> backend_names() {
    std::vector<std::string> names;
    for (const Backend& b : backends()) names.push_back(b.name);
    return names;
}

const Backend& backend(const std::string& name) {
    for (const Backend& b : backends())
        if (b.name == name) return b;
    throw std::out_of_range("no backend named " + name);
}

const Backend& first_opencl() {
    for (const Backend& b : backends())
        if (b.name == "opencl" || b.name.rfind("opencl:", 0) == 0) return b;
    throw InternalError("the backends list has no opencl entry");
}

Presence bakeable(const Backend& b) {
    Presence p{b.name, b.present && !b.device.empty(), b.why};
    if (b.present && b.device.empty())
        p.why = b.name == "embree" ? "no --device bakes on it (a bench engine: bench --engines embree)"
                                   : "no --device bakes on it here (a --device list may not name ref twice, and "
                                     "there is no OpenCL device to pair the reference with)";
    return p;
}

}  // namespace hemirad::test
