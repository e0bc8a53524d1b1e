// Parallel shots on an OpenCL device: kernels/parallel.cl, cell for cell the host's draw_parallel.
#pragma once

#include <string>
#include <vector>

#include "cl/runtime.h"
#include "formfactor/parallel.h"

namespace hemirad::formfactor {

class OpenCLParallelRaster final : public ParallelRaster {
public:
    // Builds kernels/parallel.cl for the context's device (BuildError on failure).
    explicit OpenCLParallelRaster(ocl::Context& context);
    std::string name() const override { return "opencl"; }
    // Throws ocl::DeviceError when the device fails (out of memory included).
    void draw(const ParallelRecords& records, std::vector<std::int32_t>& owner, std::vector<std::uint32_t>& covered) override;

private:
    ocl::Context& context_;
    cl::Kernel kernel_;
};

// Checks another raster against the host's on every shot (--verify): the owner of every cell and
// every record's count of cell centres must be the same; VerifyError says how many differ.
class VerifyingParallelRaster final : public ParallelRaster {
public:
    explicit VerifyingParallelRaster(ParallelRaster& raster) : raster_(raster) {}
    std::string name() const override { return raster_.name(); }
    void draw(const ParallelRecords& records, std::vector<std::int32_t>& owner, std::vector<std::uint32_t>& covered) override;
    long cells_compared() const { return cells_compared_; }

private:
    ParallelRaster& raster_;
    long cells_compared_ = 0;
};

}  // namespace hemirad::formfactor
