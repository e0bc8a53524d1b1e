// `hemirad devices`: the form-factor engines this build can use.
#include "cli/app.h"

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "cl/runtime.h"
#include "dist/dist.h"
#include "image/image.h"

namespace hemirad::cli {

using ordered_json = nlohmann::ordered_json;

void list_devices(std::ostream& out, bool json) {
    const std::vector<ocl::DeviceInfo> devices = ocl::list_devices();
    if (json) {
        ordered_json j = ordered_json::array();
        j.push_back({{"id", "ref"}, {"backend", "ref"}, {"platform", "host"},
                     {"name", "scalar reference hemicube (1 thread)"}});
        for (const auto& d : devices)
            j.push_back({{"id", d.id()}, {"backend", "opencl"}, {"platform", d.platform_name}, {"name", d.name},
                         {"vendor", d.vendor}, {"version", d.version}, {"driver", d.driver},
                         {"type", d.type}, {"compute_units", d.compute_units},
                         {"global_memory_bytes", d.global_memory}, {"fp64", d.fp64},
                         {"int64_atomics", d.int64_atomics}});
        out << j.dump(2) << "\n";
        return;
    }
    out << "ref          scalar reference hemicube (host, 1 thread)\n";
    for (const auto& d : devices)
        out << fmt::format("{:<12} {} | {} | {} | {} compute units | fp64 {}\n", d.id(), d.name, d.platform_name,
                           d.type, d.compute_units, d.fp64 ? "yes" : "no");
    if (devices.empty()) out << "(no OpenCL platform or device found)\n";
    out << "all          every OpenCL device above, sharing each batch (as does a list: opencl:0.0,opencl:0.1)\n";
    out << (dist::built_with_mpi() ? "MPI          built in: under mpirun or srun, ranks share each batch too\n"
                                   : "MPI          not built in (a build with libopenmpi-dev has it)\n");
#ifdef HEMIRAD_HAVE_EMBREE
    out << "embree       built in: the ray-casting peer of hemirad bench (--engines embree)\n";
#else
    out << "embree       not built in (a build with libembree-dev has the benchmark's ray-casting peer)\n";
#endif
    out << fmt::format("images       {}: PNG, JPEG and WebP textures, EXR and PNG output\n", image::backend().name);
}

}  // namespace hemirad::cli
