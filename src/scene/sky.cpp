// The sky dome (see sky.h).
#include "scene/sky.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <regex>
#include <sstream>

#include "core/error.h"

namespace hemirad::scene {

namespace {

// The comma-separated parts of `text` as numbers; false where a part is not a whole finite
// number (a trailing comma leaves no part: callers check it).
bool comma_numbers(const std::string& text, std::vector<double>& values) {
    std::stringstream in(text);
    std::string part;
    // Plain decimal numbers: strtod alone would take hex ("0x1p3"), "inf" and leading blanks.
    static const std::regex kDecimal(R"([+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)");
    while (std::getline(in, part, ',')) {
        if (!std::regex_match(part, kDecimal)) return false;
        char* end = nullptr;
        const double v = std::strtod(part.c_str(), &end);
        if (end != part.c_str() + part.size() || !std::isfinite(v)) return false;
        values.push_back(v);
    }
    return true;
}

}  // namespace

Sky parse_sky(const std::string& text, const std::string& option) {
    std::vector<double> values;
    if (!comma_numbers(text, values) || std::any_of(values.begin(), values.end(), [](double v) { return v < 0.0; }))
        throw InputError(fmt::format("{} '{}': each radiance must be a finite number >= 0", option, text));
    if (values.empty() || values.size() > 2 || text.back() == ',')
        throw InputError(fmt::format("{} '{}': expected RADIANCE or HORIZON_RADIANCE,ZENITH_RADIANCE", option, text));
    Sky sky{values[0], values.size() == 2 ? values[1] : values[0]};
    if (sky.horizon == 0.0 && sky.zenith == 0.0)
        throw InputError(fmt::format("{} '{}': a sky of radiance 0 lights nothing", option, text));
    if (M_PI * std::max(sky.horizon, sky.zenith) > kMaxEmission)
        throw InputError(fmt::format("{} '{}': above the largest emission, {:g}", option, text, kMaxEmission));
    return sky;
}

PunctualLight parse_sun(const std::string& text, const std::string& option) {
    std::vector<double> values;
    if (!comma_numbers(text, values))
        throw InputError(fmt::format("{} '{}': expected AZIMUTH,ELEVATION,ILLUMINANCE, three finite numbers "
                                     "(degrees, degrees, lux)",
                                     option, text));
    if (values.size() != 3 || text.back() == ',')
        throw InputError(fmt::format("{} '{}': expected AZIMUTH,ELEVATION,ILLUMINANCE (degrees, degrees, lux)", option, text));
    const double azimuth = values[0] * M_PI / 180.0, elevation = values[1] * M_PI / 180.0, lux = values[2];
    if (!(values[1] > 0.0 && values[1] <= 90.0))
        throw InputError(fmt::format("{} '{}': the elevation must be above 0 (the horizon) and at most 90 degrees", option, text));
    if (!(lux > 0.0 && lux <= kMaxEmission))
        throw InputError(fmt::format("{} '{}': the illuminance must be above 0 and at most {:g} lux", option, text, kMaxEmission));
    PunctualLight sun;
    sun.type = PunctualLight::Type::directional;
    sun.name = "sun";
    sun.intensity = glm::dvec3(lux);
    const glm::dvec3 towards(std::sin(azimuth) * std::cos(elevation), std::sin(elevation),
                             -std::cos(azimuth) * std::cos(elevation));
    sun.direction = -glm::normalize(towards);
    return sun;
}

Dome dome_of(const Scene& scene) {
    const double diagonal = std::max(scene.diagonal(), 1e-6);
    return {glm::dvec3(0.5 * (scene.bbox_min.x + scene.bbox_max.x), scene.bbox_min.y,
                       0.5 * (scene.bbox_min.z + scene.bbox_max.z)),
            kSkyRadius * diagonal};
}

double sky_radiance(const Sky& sky, double sin_elevation) {
    return sky.horizon + (sky.zenith - sky.horizon) * sin_elevation;
}

void add_sky(Scene& scene, const Sky& sky) {
    const Dome place = dome_of(scene);
    const double radius = place.radius;
    const glm::dvec3 centre = place.centre;
    const auto at = [&](int ring, int segment) {
        const double elevation = 0.5 * M_PI * ring / kSkyRings;
        const double azimuth = 2.0 * M_PI * segment / kSkySegments;
        if (ring == kSkyRings) return centre + glm::dvec3(0.0, radius, 0.0);  // the zenith, exactly
        return centre + radius * glm::dvec3(std::cos(elevation) * std::cos(azimuth), std::sin(elevation),
                                            std::cos(elevation) * std::sin(azimuth));
    };
    const auto node = static_cast<std::uint32_t>(scene.nodes.size());
    MeshNode dome;
    dome.name = "sky";
    dome.synthetic = true;
    scene.nodes.push_back(dome);
    std::uint32_t primitive = 0;
    for (const Triangle& t : scene.triangles) primitive = std::max(primitive, t.primitive + 1);
    const glm::dvec3 zero(0.0);
    for (int ring = 0; ring < kSkyRings; ++ring) {
        Material m;
        m.name = fmt::format("sky ring {}", ring);
        m.base_color = zero;
        const double elevation = 0.5 * M_PI * (ring + 0.5) / kSkyRings;
        m.emission = glm::dvec3(M_PI * sky_radiance(sky, std::sin(elevation)));
        m.coarse = true;
        const auto material = static_cast<std::uint32_t>(scene.materials.size());
        scene.materials.push_back(m);
        for (int s = 0; s < kSkySegments; ++s) {
            // Counter-clockwise seen from inside the dome: its front faces the scene. The top
            // ring's quads close at the zenith (c = d): a triangle each.
            const glm::dvec3 a = at(ring, s), b = at(ring, s + 1), c = at(ring + 1, s + 1), d = at(ring + 1, s);
            scene.triangles.push_back({{a, b, c}, {zero, zero, zero}, material, node, primitive});
            if (ring + 1 < kSkyRings) scene.triangles.push_back({{a, c, d}, {zero, zero, zero}, material, node, primitive});
        }
    }
}

}  // namespace hemirad::scene
