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

// The element layouts a packing holds: setup reads one of them, per element (a GPU's) or in lane
// groups (lanes setup, a CPU's); packing only what its engines read halves the mesh on both sides.
enum class Packing { elements = 1, lanes = 2, both = 3 };

struct DeviceMesh {
    std::vector<HrElement> elements;     // one per element (Packing::elements, else empty)
    std::vector<HrElementLanes> lanes;   // the same, HR_SETUP_LANES a group, with each group's bounding sphere (Packing::lanes)
    std::vector<HrPatch> patches;        // one per patch
    double eps = 0.0;                    // base_plane_epsilon: the reference's clip distance

    explicit DeviceMesh(const mesh::Mesh& mesh, Packing packing = Packing::both);
    bool has(Packing layout) const {
        return (static_cast<int>(packing_) & static_cast<int>(layout)) == static_cast<int>(layout);
    }
    // Bytes of a packing of one layout of `elements` elements and `patches` patches (for
    // planning a bake before its mesh is built).
    static double bytes(double elements, double patches);

private:
    Packing packing_;
};

// The packing of elements [first, first + count) (clamped to the mesh), of lane groups [first,
// first + count) (HR_SETUP_LANES elements each, the last padded with n = 0 lanes) and of every
// patch; DeviceMesh packs the whole mesh with them, an engine may pack and upload piece by piece.
void pack_elements(const mesh::Mesh& mesh, std::size_t first, std::size_t count, HrElement* out);
void pack_lanes(const mesh::Mesh& mesh, std::size_t first, std::size_t count, HrElementLanes* out);
std::vector<HrPatch> pack_patches(const mesh::Mesh& mesh);
std::size_t lane_groups(const mesh::Mesh& mesh);

// A sphere holding every vertex of elements [first, first + count) (clamped to the mesh): the
// centre of their box and the distance to the farthest, as {x, y, z, radius}.
std::array<double, 4> bounding_sphere(const mesh::Mesh& mesh, std::size_t first, std::size_t count);

}  // namespace hemirad::formfactor
