// Packing the mesh for the kernels (see device_mesh.h).
#include "formfactor/device_mesh.h"

#include <algorithm>
#include <array>
#include <limits>

#include "formfactor/hemicube.h"

namespace hemirad::formfactor {
namespace {

void copy_polygon(const mesh::Polygon& poly, hr_double (&v)[12]) {
    for (int i = 0; i < 4; ++i)
        for (int c = 0; c < 3; ++c) v[3 * i + c] = i < poly.n ? poly.v[static_cast<std::size_t>(i)][c] : 0.0;
}

void copy3(const glm::dvec3& from, hr_double (&to)[3]) {
    for (int c = 0; c < 3; ++c) to[c] = from[c];
}

}  // namespace

std::array<double, 4> bounding_sphere(const mesh::Mesh& mesh, std::size_t first, std::size_t count) {
    const std::size_t end = std::min(mesh.elements.size(), first + count);
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
    for (std::size_t k = first; k < end; ++k)
        for (int i = 0; i < mesh.elements[k].poly.n; ++i) {
            lo = glm::min(lo, mesh.elements[k].poly.v[static_cast<std::size_t>(i)]);
            hi = glm::max(hi, mesh.elements[k].poly.v[static_cast<std::size_t>(i)]);
        }
    const glm::dvec3 centre = 0.5 * (lo + hi);
    double radius = 0.0;
    for (std::size_t k = first; k < end; ++k)
        for (int i = 0; i < mesh.elements[k].poly.n; ++i)
            radius = std::max(radius, glm::length(mesh.elements[k].poly.v[static_cast<std::size_t>(i)] - centre));
    return {centre.x, centre.y, centre.z, radius};
}

void pack_elements(const mesh::Mesh& mesh, std::size_t first, std::size_t count, HrElement* out) {
    for (std::size_t k = first; k < std::min(mesh.elements.size(), first + count); ++k) {
        const mesh::Element& e = mesh.elements[k];
        HrElement& h = out[k - first];
        h = {};
        copy_polygon(e.poly, h.v);
        copy3(e.normal, h.normal);
        copy3(e.centroid, h.centroid);
        h.n = e.poly.n;
        h.has_twin = e.has_twin ? 1 : 0;
        h.patch = static_cast<hr_int>(e.patch);
    }
}

void pack_lanes(const mesh::Mesh& mesh, std::size_t first, std::size_t count, HrElementLanes* out) {
    // A triangle repeats its last vertex; lanes past the last element stay n = 0.
    for (std::size_t g = first; g < first + count; ++g) {
        HrElementLanes& group = out[g - first];
        group = {};
        for (std::size_t lane = 0; lane < HR_SETUP_LANES; ++lane) {
            const std::size_t k = g * HR_SETUP_LANES + lane;
            if (k >= mesh.elements.size()) break;
            const mesh::Element& e = mesh.elements[k];
            for (int i = 0; i < 4; ++i)
                for (int c = 0; c < 3; ++c)
                    group.v[(3 * i + c) * HR_SETUP_LANES + lane] =
                        e.poly.v[static_cast<std::size_t>(std::min(i, e.poly.n - 1))][c];
            for (int c = 0; c < 3; ++c) {
                group.normal[c * HR_SETUP_LANES + lane] = e.normal[c];
                group.centroid[c * HR_SETUP_LANES + lane] = e.centroid[c];
            }
            group.n[lane] = e.poly.n;
            group.has_twin[lane] = e.has_twin ? 1 : 0;
            group.patch[lane] = static_cast<hr_int>(e.patch);
        }
        // The group's bounding sphere, for group_behind in setup.
        const std::array<double, 4> bound = bounding_sphere(mesh, g * HR_SETUP_LANES, HR_SETUP_LANES);
        std::copy(bound.begin(), bound.end(), group.bound);
    }
}

std::vector<HrPatch> pack_patches(const mesh::Mesh& mesh) {
    std::vector<HrPatch> patches(mesh.patches.size());
    for (std::size_t p = 0; p < mesh.patches.size(); ++p) {
        patches[p] = {};
        copy_polygon(mesh.patches[p].poly, patches[p].v);
        patches[p].n = mesh.patches[p].poly.n;
    }
    return patches;
}

std::size_t lane_groups(const mesh::Mesh& mesh) {
    return (mesh.elements.size() + HR_SETUP_LANES - 1) / HR_SETUP_LANES;
}

DeviceMesh::DeviceMesh(const mesh::Mesh& mesh, Packing packing)
    : patches(pack_patches(mesh)), eps(base_plane_epsilon(mesh)), packing_(packing) {
    if (has(Packing::elements)) {
        elements.resize(mesh.elements.size());
        pack_elements(mesh, 0, elements.size(), elements.data());
    }
    if (has(Packing::lanes)) {
        lanes.resize(lane_groups(mesh));
        pack_lanes(mesh, 0, lanes.size(), lanes.data());
    }
}

double DeviceMesh::bytes(double elements, double patches) {
    return elements * std::max(double(sizeof(HrElement)), double(sizeof(HrElementLanes)) / HR_SETUP_LANES) +
           patches * sizeof(HrPatch);
}

}  // namespace hemirad::formfactor
