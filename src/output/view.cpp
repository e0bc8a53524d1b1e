// Which camera the images are rendered from: a named one, the scene's first, or one framing it.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>
#include <glm/gtc/matrix_transform.hpp>

#include "core/error.h"
#include "output/output.h"

namespace hemirad::output {
namespace {

constexpr double kFramingYfov = 0.8;  // radians

// A closed interior (interior_view): of kProbeRays rays from the bounds' centre, at least
// kClosedShare hit the scene, and of those at least kFrontShare hit a face that shows (a front,
// or either face of a doubleSided surface): a room's walls facing in. An object seen from its
// own middle shows backs; an open scene lets the rays escape. And the rays that hit travel, by
// the median, at least kReachShare of the way to the bounds: a room's walls are its bounds, while
// the middle of a diorama or a city lies inside one of its buildings or under its base.
constexpr int kProbeRays = 64;
constexpr double kClosedShare = 0.8, kFrontShare = 0.8, kReachShare = 0.5;
constexpr double kInteriorYfov = 1.2;       // radians (69°); 4:3, about 85° across
constexpr double kInteriorAspect = 4.0 / 3.0;
constexpr double kEyeHeight = 1.6;          // scene units (glTF: metres), at most kEyeShare of the room's height
constexpr double kEyeShare = 0.5;
// A room taller than this is not in metres (a SketchUp export in millimetres, 1,874 units high):
// the eye at kEyeShare of its height, not 1.6 units above its floor.
constexpr double kTallestRoom = 10.0;
constexpr double kFromWall = 0.1;           // the eye's distance from the far end's wall, in the room's length

// The nearest hit of the ray o + t d (t > 0) with the scene's own triangles (not the sky dome):
// its distance (inf: none) and whether the face it meets shows from the ray's side.
struct Hit {
    double t = HUGE_VAL;
    bool shows = false;
};
void intersect(const scene::Scene& scene, const glm::dvec3& o, const glm::dvec3* d, int rays, Hit* hits) {
    for (const scene::Triangle& tri : scene.triangles) {
        if (tri.node < scene.nodes.size() && scene.nodes[tri.node].synthetic) continue;
        const glm::dvec3 e1 = tri.p[1] - tri.p[0], e2 = tri.p[2] - tri.p[0], s = o - tri.p[0];
        const glm::dvec3 normal = glm::cross(e1, e2);
        const bool double_sided = tri.material < scene.materials.size() && scene.materials[tri.material].double_sided;
        for (int r = 0; r < rays; ++r) {  // Möller–Trumbore
            const glm::dvec3 p = glm::cross(d[r], e2);
            const double det = glm::dot(e1, p);
            if (det == 0.0) continue;
            const double inv = 1.0 / det;
            const double u = glm::dot(s, p) * inv;
            if (u < 0.0 || u > 1.0) continue;
            const glm::dvec3 q = glm::cross(s, e1);
            const double v = glm::dot(d[r], q) * inv;
            if (v < 0.0 || u + v > 1.0) continue;
            const double t = glm::dot(e2, q) * inv;
            if (t > 0.0 && t < hits[r].t) hits[r] = {t, double_sided || glm::dot(normal, d[r]) < 0.0};
        }
    }
}

// Looks across a closed room from near one end, at eye height, when the scene is one (above);
// else nothing.
std::optional<View> interior_view(const scene::Scene& scene) {
    const glm::dvec3 lo = scene.bbox_min, hi = scene.bbox_max, centre = 0.5 * (lo + hi), extent = hi - lo;
    if (!(glm::length(extent) > 0.0)) return std::nullopt;
    glm::dvec3 d[kProbeRays];
    for (int r = 0; r < kProbeRays; ++r) {  // a Fibonacci sphere: even, and the same every time
        const double y = 1.0 - 2.0 * (r + 0.5) / kProbeRays, ring = std::sqrt(1.0 - y * y);
        const double phi = r * M_PI * (3.0 - std::sqrt(5.0));
        d[r] = glm::dvec3(ring * std::cos(phi), y, ring * std::sin(phi));
    }
    Hit hits[kProbeRays];
    intersect(scene, centre, d, kProbeRays, hits);
    int hit = 0, shows = 0;
    std::vector<double> reach_share;  // of the hits: distance ÷ the distance to the bounds along the ray
    for (int r = 0; r < kProbeRays; ++r) {
        if (!(hits[r].t < HUGE_VAL)) continue;
        ++hit;
        shows += hits[r].shows;
        double exit = HUGE_VAL;
        for (int axis = 0; axis < 3; ++axis) {
            if (d[r][axis] != 0.0) exit = std::min(exit, ((d[r][axis] > 0.0 ? hi[axis] : lo[axis]) - centre[axis]) / d[r][axis]);
        }
        reach_share.push_back(exit > 0.0 ? hits[r].t / exit : 1.0);
    }
    if (hit < kClosedShare * kProbeRays || shows < kFrontShare * hit) return std::nullopt;
    std::nth_element(reach_share.begin(), reach_share.begin() + reach_share.size() / 2, reach_share.end());
    if (reach_share[reach_share.size() / 2] < kReachShare) return std::nullopt;
    // Along the longer horizontal axis, from its + end towards its − end (along −Z, glTF's front,
    // when the room is square), the eye pulled in front of whatever stands between it and the centre.
    const bool along_x = extent.x > extent.z;
    const glm::dvec3 axis = along_x ? glm::dvec3(1.0, 0.0, 0.0) : glm::dvec3(0.0, 0.0, 1.0);
    const double half = 0.5 * (along_x ? extent.x : extent.z);
    const double eye_height = extent.y > kTallestRoom ? kEyeShare * extent.y : std::min(kEyeHeight, kEyeShare * extent.y);
    const glm::dvec3 middle(centre.x, lo.y + eye_height, centre.z);
    double reach = half * (1.0 - 2.0 * kFromWall);
    Hit back;
    intersect(scene, middle, &axis, 1, &back);
    reach = std::min(reach, 0.8 * back.t);
    const glm::dvec3 eye = middle + reach * axis;
    const glm::dmat4 world_to_camera = glm::lookAt(eye, eye - axis, glm::dvec3(0.0, 1.0, 0.0));
    return View{glm::inverse(world_to_camera), kInteriorYfov, kInteriorAspect, "framing (inside)"};
}

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
    if (std::optional<View> inside = interior_view(scene)) return *inside;
    return framing_view(scene);
}

}  // namespace hemirad::output
