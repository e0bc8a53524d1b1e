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

DeviceMesh::DeviceMesh(const mesh::Mesh& mesh)
    : elements(mesh.elements.size()),
      lanes((mesh.elements.size() + HR_SETUP_LANES - 1) / HR_SETUP_LANES),
      patches(mesh.patches.size()),
      eps(base_plane_epsilon(mesh)) {
    for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
        const mesh::Element& e = mesh.elements[k];
        HrElement& h = elements[k];
        h = {};
        copy_polygon(e.poly, h.v);
        copy3(e.normal, h.normal);
        copy3(e.centroid, h.centroid);
        h.n = e.poly.n;
        h.has_twin = e.has_twin ? 1 : 0;
    }
    // Lanes: a triangle repeats its last vertex; lanes past the last element stay n = 0.
    for (HrElementLanes& group : lanes) group = {};
    for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
        const mesh::Element& e = mesh.elements[k];
        HrElementLanes& group = lanes[k / HR_SETUP_LANES];
        const std::size_t lane = k % HR_SETUP_LANES;
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
    // Each lane group's bounding sphere, for group_behind in setup.
    for (std::size_t g = 0; g < lanes.size(); ++g) {
        const std::array<double, 4> bound = bounding_sphere(mesh, g * HR_SETUP_LANES, HR_SETUP_LANES);
        std::copy(bound.begin(), bound.end(), lanes[g].bound);
    }
    for (std::size_t p = 0; p < mesh.patches.size(); ++p) {
        patches[p] = {};
        copy_polygon(mesh.patches[p].poly, patches[p].v);
        patches[p].n = mesh.patches[p].poly.n;
        patches[p].first_element = static_cast<hr_int>(mesh.patches[p].first_element);
        patches[p].elements = static_cast<hr_int>(mesh.patches[p].element_count);
    }
}

double DeviceMesh::bytes(double elements, double patches) {
    return elements * (sizeof(HrElement) + double(sizeof(HrElementLanes)) / HR_SETUP_LANES) + patches * sizeof(HrPatch);
}

}  // namespace hemirad::formfactor
