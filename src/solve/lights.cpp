// Direct light of punctual lights (see lights.h).
#include "solve/lights.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/cancel.h"
#include "core/error.h"

namespace hemirad::solve {

bool shines_in_parallel(const scene::PunctualLight& light) {
    return light.type == scene::PunctualLight::Type::directional && light.intensity != glm::dvec3(0.0);
}

bool has_direct_light(const mesh::Mesh& mesh, const std::vector<scene::PunctualLight>& lights) {
    return !mesh.lights.empty() || std::any_of(lights.begin(), lights.end(), shines_in_parallel);
}

std::vector<glm::dvec3> direct_light(const mesh::Mesh& mesh, const std::vector<scene::PunctualLight>& lights,
                                     formfactor::Engine& engine, int level, glm::dvec3* landed,
                                     const std::function<void(std::size_t, std::size_t)>& progress,
                                     std::vector<glm::dvec3>* directional) {
    std::vector<glm::dvec3> H(mesh.elements.size(), glm::dvec3(0.0));
    if (landed) *landed = glm::dvec3(0.0);
    // Directional lights (the mesh's, which must be the shining ones of `lights`): a parallel shot
    // each, one batch through the engine like any shots, each grid turned by the level and the light.
    const auto shining = static_cast<std::size_t>(std::count_if(lights.begin(), lights.end(), shines_in_parallel));
    if (shining != mesh.directions.size())
        throw InternalError(fmt::format("direct light: the mesh has {} directional lights, the scene {} that shine",
                                        mesh.directions.size(), shining));
    std::vector<formfactor::ShotRequest> requests;
    std::vector<formfactor::ShotResult> rows;
    if (!mesh.directions.empty()) {
        for (std::size_t d = 0; d < mesh.directions.size(); ++d) {
            const std::size_t l = mesh.directions[d].light;
            if (l >= lights.size() || !shines_in_parallel(lights[l]) || lights[l].direction != mesh.directions[d].direction)
                throw InternalError(fmt::format("direct light: the mesh's directional light {} is not the scene's light {}", d, l));
            requests.push_back(formfactor::ShotRequest::of_directional(
                static_cast<std::uint32_t>(d), static_cast<std::uint64_t>(level) * lights.size() + l));
        }
        engine.shoot_batch(requests, rows);
        if (rows.size() != requests.size()) throw InternalError("direct light: the engine returned the wrong number of rows");
        for (std::size_t d = 0; d < mesh.directions.size(); ++d) {
            const scene::PunctualLight& light = lights[mesh.directions[d].light];
            const formfactor::ShotResult& lit = rows[d];
            for (std::size_t i = 0; i < lit.size(); ++i) {
                const glm::dvec3 irradiance = light.intensity * lit.F[i];
                H[lit.element[i]] += irradiance;
                if (landed) *landed += irradiance * mesh.elements[lit.element[i]].area;
            }
        }
    }
    if (directional) *directional = H;
    if (mesh.lights.empty()) return H;
    const std::uint64_t first = kLightShots + static_cast<std::uint64_t>(level) * mesh.lights.size();
    for (std::size_t start = 0; start < mesh.lights.size(); start += kLightBatch) {
        cancel::check();
        const std::size_t end = std::min(mesh.lights.size(), start + kLightBatch);
        requests.clear();
        for (std::size_t i = start; i < end; ++i)
            requests.push_back(formfactor::ShotRequest::of_light(static_cast<std::uint32_t>(i), first + i));
        engine.shoot_batch(requests, rows);
        for (std::size_t r = 0; r < requests.size(); ++r) {
            const mesh::LightShooter& shooter = mesh.lights[start + r];
            if (shooter.light >= lights.size()) throw InternalError("direct light: a light hemicube names no light");
            const scene::PunctualLight& light = lights[shooter.light];
            const formfactor::ShotResult& row = rows[r];
            for (std::size_t i = 0; i < row.size(); ++i) {
                const mesh::Element& e = mesh.elements[row.element[i]];
                // The row holds Ω / 4π: the flux through the element's solid angle is I · Ω.
                const glm::dvec3 flux =
                    light.intensity * (light.attenuation(e.centroid - shooter.position) * 4.0 * M_PI * row.F[i]);
                H[row.element[i]] += flux / e.area;
                if (landed) *landed += flux;
            }
        }
        if (progress) progress(end, mesh.lights.size());
    }
    return H;
}

}  // namespace hemirad::solve
