// A sky and a sun for scenes without lights of their own. `--sky RADIANCE[,ZENITH_RADIANCE]`: a
// dome of emitting patches around the scene, shot like any emitter and so occluded by the scene
// itself. `--sun AZIMUTH,ELEVATION,ILLUMINANCE`: a directional light (solve/lights.h).
#pragma once

#include <string>

#include "scene/scene.h"

namespace hemirad::scene {

struct Sky {
    double horizon = 0.0;  // radiance at the horizon (emission units / π: a surface of emission E has radiance E / π)
    double zenith = 0.0;   // radiance overhead; between them, L = horizon + (zenith − horizon) · sin(elevation)
};

// Parses "L" (a uniform sky) or "L_horizon,L_zenith". Throws InputError naming `option`.
Sky parse_sky(const std::string& text, const std::string& option);

// Rings of the dome from the horizon to the zenith, and quads around each ring.
inline constexpr int kSkyRings = 16, kSkySegments = 64;
// The dome's radius, in scene diagonals (the distance of its faces' planes from the centre is a
// little less: cos(π / kSkySegments) and the ring's half step).
inline constexpr double kSkyRadius = 2.0;

// Adds the dome: a hemisphere of kSkyRings × kSkySegments faces (the top ring triangles) around
// the scene's bounding box, centred over the box's centre at the height of its lowest point,
// facing in, reflecting nothing. Each ring emits π × the sky's radiance at its middle elevation
// (its own material). Its node is synthetic and its materials coarse; the scene's bounding box is
// left as it was (the camera still frames the scene).
void add_sky(Scene& scene, const Sky& sky);

// Where add_sky puts the dome around `scene` (its bounding box): the centre of its rim and its radius.
struct Dome {
    glm::dvec3 centre{0.0};
    double radius = 0.0;
};
Dome dome_of(const Scene& scene);

// The sky's radiance at an elevation whose sine is `sin_elevation` (0 at the horizon, 1 overhead).
double sky_radiance(const Sky& sky, double sin_elevation);

// Parses "AZIMUTH,ELEVATION,ILLUMINANCE" (degrees, degrees, lux) into a white directional light
// named "sun". Azimuth turns clockwise seen from above, from north (−Z, glTF's forward: Blender's
// +Y) towards east (+X); elevation rises from the horizon (0 < elevation ≤ 90) towards +Y. The sun
// lights a surface facing it with ILLUMINANCE × cos θ. Throws InputError naming `option`.
PunctualLight parse_sun(const std::string& text, const std::string& option);

}  // namespace hemirad::scene
