// Which camera the images are rendered from: a named one, the scene's first, or one framing it.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>

#include "core/error.h"
#include "output/output.h"

namespace hemirad::output {
namespace {

constexpr double kFramingYfov = 0.8;  // radians

View from_camera(const scene::Camera& camera) {
    return View{camera.camera_to_world, camera.yfov, camera.aspect > 0.0 ? camera.aspect : 1.0, camera.name};
}

std::string camera_names(const scene::Scene& scene) {
    if (scene.cameras.empty()) return "none";
    std::string names;
    for (const scene::Camera& camera : scene.cameras) {
        names += (names.empty() ? "" : ", ") + camera.name;
    }
    return names;
}

// Looks at the bounds' centre from in front (+Z, glTF's conventional front) and a little above,
// just far enough that the bounding sphere fits the vertical field of view.
View framing_view(const scene::Scene& scene) {
    const glm::dvec3 centre = 0.5 * (scene.bbox_min + scene.bbox_max);
    const double diagonal = scene.diagonal();
    const double radius = diagonal > 0.0 ? 0.5 * diagonal : 1.0;  // an empty scene: any view
    const double distance = radius / std::sin(0.5 * kFramingYfov);
    const glm::dvec3 direction = glm::normalize(glm::dvec3(0.0, 0.3, 1.0));
    const glm::dvec3 eye = centre + distance * direction;
    const glm::dmat4 world_to_camera = glm::lookAt(eye, centre, glm::dvec3(0.0, 1.0, 0.0));
    return View{glm::inverse(world_to_camera), kFramingYfov, 1.0, "framing"};
}

}  // namespace

View look_view(const glm::dvec3& from, const glm::dvec3& at, double yfov) {
    const glm::dvec3 d = at - from;
    const double length = glm::length(d);
    if (!(length > 0.0) || !std::isfinite(length))
        throw InputError("--look-from and --look-at must be two different points");
    const glm::dvec3 up = std::abs(d.y) > 0.999 * length ? glm::dvec3(0.0, 0.0, 1.0) : glm::dvec3(0.0, 1.0, 0.0);
    return View{glm::inverse(glm::lookAt(from, at, up)), yfov, 4.0 / 3.0, "look-from"};
}

View choose_view(const scene::Scene& scene, const std::string& camera_name) {
    if (!camera_name.empty()) {
        const auto it = std::find_if(scene.cameras.begin(), scene.cameras.end(),
                                     [&](const scene::Camera& c) { return c.name == camera_name; });
        if (it == scene.cameras.end()) {
            throw InputError(fmt::format("{}: no camera named '{}' (cameras: {})", scene.path.string(), camera_name,
                                         camera_names(scene)));
        }
        return from_camera(*it);
    }
    if (!scene.cameras.empty()) return from_camera(scene.cameras.front());
    return framing_view(scene);
}

}  // namespace hemirad::output
