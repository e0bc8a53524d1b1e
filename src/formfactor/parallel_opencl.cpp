// Parallel shots on an OpenCL device (see parallel_opencl.h).
#include "formfactor/parallel_opencl.h"

#include <fmt/format.h>

#include "formfactor/verify.h"

namespace hemirad::formfactor {

OpenCLParallelRaster::OpenCLParallelRaster(ocl::Context& context) : context_(context) {
    // Never -cl-fast-relaxed-math or -cl-mad-enable: depths must round as the host's do.
    cl::Program& program = context.program(std::string(ocl::kernel_source("parallel.cl")),
                                           fmt::format("-cl-std=CL1.2 -DHR_PARALLEL_TILE={}", kParallelTile));
    kernel_ = cl::Kernel(program, "parallel_raster");
}

void OpenCLParallelRaster::draw(const ParallelRecords& records, std::vector<std::int32_t>& owner,
                                std::vector<std::uint32_t>& covered) {
    const ParallelGrid& grid = records.grid;
    const std::size_t cells = static_cast<std::size_t>(grid.width) * static_cast<std::size_t>(grid.height);
    owner.assign(cells, -1);
    covered.assign(records.size(), 0);
    if (records.size() == 0 || cells == 0) return;
    try {
        cl::Context& ctx = context_.context();
        cl::CommandQueue& queue = context_.queue();
        // Buffers of at least one element: OpenCL refuses empty ones.
        const auto input = [&](const auto& v) {
            using T = typename std::decay_t<decltype(v)>::value_type;
            const std::size_t bytes = std::max<std::size_t>(1, v.size()) * sizeof(T);
            cl::Buffer b(ctx, CL_MEM_READ_ONLY, bytes);
            if (!v.empty()) queue.enqueueWriteBuffer(b, CL_FALSE, 0, v.size() * sizeof(T), v.data());
            return b;
        };
        cl::Buffer px = input(records.px), py = input(records.py), shape = input(records.shape),
                   plane = input(records.plane), start = input(records.bin_start), items = input(records.bin_items);
        cl::Buffer owner_buffer(ctx, CL_MEM_WRITE_ONLY, cells * sizeof(std::int32_t));
        cl::Buffer covered_buffer(ctx, CL_MEM_READ_WRITE, covered.size() * sizeof(std::uint32_t));
        queue.enqueueWriteBuffer(covered_buffer, CL_FALSE, 0, covered.size() * sizeof(std::uint32_t), covered.data());
        int arg = 0;
        kernel_.setArg(arg++, grid.width);
        kernel_.setArg(arg++, grid.height);
        kernel_.setArg(arg++, records.tiles_x);
        kernel_.setArg(arg++, grid.cell);
        kernel_.setArg(arg++, records.xmin);
        kernel_.setArg(arg++, records.ymin);
        for (cl::Buffer* b : {&px, &py, &shape, &plane, &start, &items, &owner_buffer, &covered_buffer})
            kernel_.setArg(arg++, *b);
        const cl::NDRange global(static_cast<std::size_t>(records.tiles_x) * kParallelTile,
                                 static_cast<std::size_t>(records.tiles_y) * kParallelTile);
        queue.enqueueNDRangeKernel(kernel_, cl::NullRange, global, cl::NDRange(kParallelTile, kParallelTile));
        queue.enqueueReadBuffer(owner_buffer, CL_FALSE, 0, cells * sizeof(std::int32_t), owner.data());
        queue.enqueueReadBuffer(covered_buffer, CL_TRUE, 0, covered.size() * sizeof(std::uint32_t), covered.data());
    } catch (const cl::Error& e) {
        throw ocl::DeviceError(fmt::format("{}: parallel shot: {} failed: {}", context_.info().name, e.what(),
                                           ocl::error_name(e.err())));
    }
}

void VerifyingParallelRaster::draw(const ParallelRecords& records, std::vector<std::int32_t>& owner,
                                   std::vector<std::uint32_t>& covered) {
    raster_.draw(records, owner, covered);
    std::vector<std::int32_t> want_owner;
    std::vector<std::uint32_t> want_covered;
    draw_parallel(records, want_owner, want_covered);
    long cells = 0, records_off = 0;
    for (std::size_t c = 0; c < owner.size() && c < want_owner.size(); ++c) cells += owner[c] != want_owner[c];
    for (std::size_t r = 0; r < covered.size() && r < want_covered.size(); ++r) records_off += covered[r] != want_covered[r];
    cells_compared_ += static_cast<long>(want_owner.size());
    if (cells > 0 || records_off > 0 || owner.size() != want_owner.size() || covered.size() != want_covered.size())
        throw VerifyError(fmt::format("{} parallel shot: {} of {} cells have another owner than the reference's, {} of {} "
                                      "elements another count of cell centres",
                                      raster_.name(), cells, want_owner.size(), records_off, want_covered.size()));
}

}  // namespace hemirad::formfactor
