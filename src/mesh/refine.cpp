// Splitting elements in four, for adaptive refinement.
#include "mesh/refine.h"

#include <fmt/format.h>

#include <limits>

#include "core/error.h"
#include "mesh/texturing.h"

namespace hemirad::mesh {

std::array<Polygon, 4> split_polygon(const Polygon& poly) {
    const auto mid = [&poly](int a, int b) { return 0.5 * (poly.v[std::size_t(a)] + poly.v[std::size_t(b)]); };
    const auto polygon = [](std::initializer_list<glm::dvec3> corners) {
        Polygon p;
        p.n = 0;
        for (const glm::dvec3& c : corners) p.v[std::size_t(p.n++)] = c;
        return p;
    };
    const auto& v = poly.v;
    if (poly.n == 3) {
        const glm::dvec3 m01 = mid(0, 1), m12 = mid(1, 2), m20 = mid(2, 0);
        return {polygon({v[0], m01, m20}), polygon({m01, v[1], m12}), polygon({m20, m12, v[2]}),
                polygon({m01, m12, m20})};
    }
    const glm::dvec3 m01 = mid(0, 1), m12 = mid(1, 2), m23 = mid(2, 3), m30 = mid(3, 0);
    const glm::dvec3 centre = 0.25 * (v[0] + v[1] + v[2] + v[3]);  // the bilinear centre
    return {polygon({v[0], m01, centre, m30}), polygon({m01, v[1], m12, centre}), polygon({centre, m12, v[2], m23}),
            polygon({m30, centre, m23, v[3]})};
}

Refined split_elements(const Mesh& mesh, const std::vector<bool>& split, const Texturing* texturing) {
    if (split.size() != mesh.elements.size())
        throw InternalError(fmt::format("refine: {} split flags for {} elements", split.size(), mesh.elements.size()));
    Refined out;
    out.mesh.patches = mesh.patches;
    out.mesh.lights = mesh.lights;
    out.mesh.directions = mesh.directions;
    out.mesh.dropped_triangles = mesh.dropped_triangles;
    out.mesh.quads = mesh.quads;
    out.mesh.clusters = mesh.clusters;
    out.mesh.split_clusters = mesh.split_clusters;
    out.mesh.moved_clusters = mesh.moved_clusters;
    out.mesh.joined_clusters = mesh.joined_clusters;
    out.mesh.texture_splits = mesh.texture_splits;
    out.mesh.holes = mesh.holes;
    std::size_t count = mesh.elements.size();
    for (bool s : split) count += s ? 3 : 0;
    if (count >= std::numeric_limits<std::uint32_t>::max())
        throw InternalError("refine: more elements than 32-bit indices can hold");
    out.mesh.elements.reserve(count);
    out.origin.reserve(count);
    out.is_new.reserve(count);
    for (Patch& patch : out.mesh.patches) {
        const std::uint32_t first = patch.first_element, end = patch.first_element + patch.element_count;
        patch.first_element = static_cast<std::uint32_t>(out.mesh.elements.size());
        for (std::uint32_t k = first; k < end; ++k) {
            const Element& e = mesh.elements[k];
            if (!split[k]) {
                out.mesh.elements.push_back(e);
                out.origin.push_back(k);
                out.is_new.push_back(false);
                continue;
            }
            for (const Polygon& poly : split_polygon(e.poly)) {
                Element child = e;
                const Shape shape = shape_of(poly);
                child.poly = poly;
                child.centroid = shape.centroid;
                child.area = shape.area;
                if (texturing) texturing->apply(child);
                out.mesh.elements.push_back(child);
                out.origin.push_back(k);
                out.is_new.push_back(true);
            }
        }
        patch.element_count = static_cast<std::uint32_t>(out.mesh.elements.size()) - patch.first_element;
    }
    return out;
}

}  // namespace hemirad::mesh
