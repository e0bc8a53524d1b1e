// Per-node area-weighted radiosity and irradiance over front faces, for report.json "meshes".
#include <fmt/format.h>

#include "core/error.h"
#include "output/output.h"

namespace hemirad::output {

std::vector<NodeSummary> summarize(const scene::Scene& scene, const mesh::Mesh& mesh,
                                   const std::vector<glm::dvec3>& radiosity,
                                   const std::vector<glm::dvec3>& irradiance) {
    const std::size_t count = mesh.elements.size();
    if (radiosity.size() != count || irradiance.size() != count) {
        throw InternalError(fmt::format("output: {} radiosity and {} irradiance values for {} elements",
                                        radiosity.size(), irradiance.size(), count));
    }
    std::vector<NodeSummary> summaries(scene.nodes.size());
    for (std::size_t n = 0; n < scene.nodes.size(); ++n) summaries[n].name = scene.nodes[n].name;

    // Sums of area × value first; divided by the area once every element is in.
    for (std::size_t i = 0; i < count; ++i) {
        const mesh::Element& element = mesh.elements[i];
        if (element.back) continue;  // a doubleSided back face would count the surface twice
        if (element.node >= summaries.size()) {
            throw InternalError(
                fmt::format("output: element {} names node {} of {}", i, element.node, summaries.size()));
        }
        NodeSummary& summary = summaries[element.node];
        summary.area += element.area;
        summary.radiosity += element.area * radiosity[i];
        summary.irradiance += element.area * irradiance[i];
    }
    for (NodeSummary& summary : summaries) {
        if (summary.area <= 0.0) continue;  // a node whose triangles were all dropped: zeros
        summary.radiosity /= summary.area;
        summary.irradiance /= summary.area;
    }
    return summaries;
}

}  // namespace hemirad::output
