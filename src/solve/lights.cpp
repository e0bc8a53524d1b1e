// Direct light of punctual lights (see lights.h).
#include "solve/lights.h"

#include <algorithm>
#include <cmath>

#include "core/cancel.h"
#include "core/error.h"
#include "formfactor/parallel.h"

namespace hemirad::solve {

namespace {

bool shines_in_parallel(const scene::PunctualLight& light) {
    return light.type == scene::PunctualLight::Type::directional && light.intensity != glm::dvec3(0.0);
}

}  // namespace

bool has_direct_light(const mesh::Mesh& mesh, const std::vector<scene::PunctualLight>& lights) {
    return !mesh.lights.empty() || std::any_of(lights.begin(), lights.end(), shines_in_parallel);
}

std::vector<glm::dvec3> direct_light(const mesh::Mesh& mesh, const std::vector<scene::PunctualLight>& lights,
                                     formfactor::Engine& engine, int level, glm::dvec3* landed,
                                     const std::function<void(std::size_t, std::size_t)>& progress) {
    std::vector<glm::dvec3> H(mesh.elements.size(), glm::dvec3(0.0));
    if (landed) *landed = glm::dvec3(0.0);
    // Directional lights: a parallel shot each, its grid turned by the level and the light.
    formfactor::ShotResult lit;
    for (std::size_t l = 0; l < lights.size(); ++l) {
        if (!shines_in_parallel(lights[l])) continue;
        formfactor::shoot_parallel(mesh, lights[l].direction, static_cast<std::uint64_t>(level) * lights.size() + l, lit,
                                   {}, engine.parallel_raster());
        for (std::size_t i = 0; i < lit.size(); ++i) {
            const glm::dvec3 irradiance = lights[l].intensity * lit.F[i];
            H[lit.element[i]] += irradiance;
            if (landed) *landed += irradiance * mesh.elements[lit.element[i]].area;
        }
    }
    if (mesh.lights.empty()) return H;
    const std::uint64_t first = kLightShots + static_cast<std::uint64_t>(level) * mesh.lights.size();
    std::vector<formfactor::ShotRequest> requests;
    std::vector<formfactor::ShotResult> rows;
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
