// The mesh as the kernels read it (kernels/hemicube_types.h), packed once on the host and
// uploaded by every OpenCL engine that shoots it, one per device: several devices of a bake
// share one packing, and nothing in it depends on a device or its tuning.
#pragma once

#include <array>
#include <memory>
#include <vector>

#include "hemicube_types.h"
#include "mesh/mesh.h"

namespace hemirad::formfactor {

struct DeviceMesh {
    std::vector<HrElement> elements;     // one per element
    std::vector<HrElementLanes> lanes;   // the same, HR_SETUP_LANES a group, with each group's bounding sphere
    std::vector<HrPatch> patches;        // one per patch
    double eps = 0.0;                    // base_plane_epsilon: the reference's clip distance

    explicit DeviceMesh(const mesh::Mesh& mesh);
    // Bytes of a packing of `elements` elements and `patches` patches (for planning a bake before
    // its mesh is built).
    static double bytes(double elements, double patches);
};

// A sphere holding every vertex of elements [first, first + count) (clamped to the mesh): the
// centre of their box and the distance to the farthest, as {x, y, z, radius}.
std::array<double, 4> bounding_sphere(const mesh::Mesh& mesh, std::size_t first, std::size_t count);

}  // namespace hemirad::formfactor
