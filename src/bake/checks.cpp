// The bake's checks of its input (see checks.h).
#include "bake/checks.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <vector>

#include <fmt/core.h>

#include "bake/budget.h"
#include "cl/runtime.h"
#include "core/counted.h"
#include "core/error.h"
#include "core/memory.h"

namespace hemirad::bake {

bool emits(const scene::Scene& scene, const scene::Triangle& t) {
    const glm::dvec3& e = scene.materials[t.material].emission;
    return e.x > 0.0 || e.y > 0.0 || e.z > 0.0;
}

// "X,Y,Z": three finite numbers, or exit 2 naming the option.
glm::dvec3 parse_point(const std::string& text, const std::string& option) {
    glm::dvec3 p(0.0);
    std::size_t at = 0;
    for (int i = 0; i < 3; ++i) {
        const std::size_t end = i < 2 ? text.find(',', at) : text.size();
        const std::string part = end == std::string::npos ? std::string() : text.substr(at, end - at);
        char* stop = nullptr;
        p[i] = std::strtod(part.c_str(), &stop);
        if (part.empty() || stop != part.c_str() + part.size() || !std::isfinite(p[i]) ||
            (i == 2 && text.find(',', at) != std::string::npos))
            throw InputError(fmt::format("{} '{}': expected X,Y,Z, three finite numbers", option, text));
        at = end + 1;
    }
    return p;
}

// The punctual lights of a scene that shine (point, spot and directional ones).
std::size_t shining_lights(const scene::Scene& scene) {
    return static_cast<std::size_t>(std::count_if(scene.lights.begin(), scene.lights.end(), [](const scene::PunctualLight& l) {
        return l.intensity != glm::dvec3(0.0);
    }));
}

void check_scene(const scene::Scene& scene) {
    if (scene.triangles.empty())
        throw InputError(fmt::format("{}: no triangles to bake (no mesh with TRIANGLES primitives)", scene.path.string()));
    if (shining_lights(scene) > 0 ||
        std::any_of(scene.triangles.begin(), scene.triangles.end(), [&](const scene::Triangle& t) { return emits(scene, t); }))
        return;
    throw InputError(fmt::format(
        "{}: nothing emits light: 0 emissive triangles (no triangle's material has emission > 0) and {} "
        "KHR_lights_punctual light{} of intensity > 0 (of {}); hemirad bakes emissive materials and point, spot and "
        "directional lights, --sky RADIANCE[,ZENITH_RADIANCE] adds a sky and --sun AZIMUTH,ELEVATION,LUX a sun",
        scene.path.string(), shining_lights(scene), shining_lights(scene) == 1 ? "" : "s", scene.lights.size()));
}

// After the see_through decision: a scene whose only emitters were see-through (faint blended
// glows) has nothing left to light it. Such glows are decoration beside a light the file does not
// hold (an interior lit by the sun through its windows, a street by the sky), so the first advice
// is to add that light; baking the glows as lamps comes second.
void check_emitters_left(const scene::Scene& scene, const scene::EffectsPlan& plan) {
    if (!plan.see_through.on || shining_lights(scene) > 0) return;
    if (std::any_of(scene.triangles.begin(), scene.triangles.end(), [&](const scene::Triangle& t) { return emits(scene, t); }))
        return;
    std::vector<std::string> glows;
    for (const scene::Material& m : scene.materials)
        if (m.emission != glm::dvec3(0.0) && !m.see_through.empty()) glows.push_back(m.name);
    constexpr std::size_t kNamed = 3;
    std::string names;
    for (std::size_t i = 0; i < glows.size() && i < kNamed; ++i) names += fmt::format("{}'{}'", i ? ", " : "", glows[i]);
    if (glows.size() > kNamed) names += fmt::format(" and {} more", grouped(glows.size() - kNamed));
    throw InputError(fmt::format(
        "{}: nothing emits light once see-through surfaces are left out: the only emitters are {} ({}), faint "
        "alpha-blended or transmissive glows that, like glass, neither block nor give light; light the scene with "
        "--sun AZIMUTH,ELEVATION,LUX (e.g. --sun 135,40,20) and/or --sky RADIANCE (e.g. --sky 0.3), or add "
        "lamps to the file; only if the glows are the scene's lamps, --effects see_through=off bakes them as opaque "
        "emitters",
        scene.path.string(), counted(glows.size(), "glow material"), names));
}

// After meshing: a material that emits in the file but whose surfaces give the mesh no light
// (every texel cut away by alphaMode MASK, an emissive texture black where the surface is, or
// only triangles of no area) is a lamp the bake cannot see: a warning naming it. With no light
// left anywhere the bake would be black: exit 2, saying why.
void warn_uneven_emitters(scene::Scene& scene, const mesh::Mesh& mesh) {
    if (mesh.emission_unsplit == 0) return;
    scene.warnings.push_back(fmt::format(
        "{}: {} emitter patches whose emissive texture changes across them shoot from their centres (the cap "
        "on extra shooters was reached after {} were split): the light near them is approximate; a --patch-size "
        "nearer --element-size needs fewer",
        scene.path.string(), mesh.emission_unsplit, mesh.emission_splits));
}

void check_lamps_seen(scene::Scene& scene, const mesh::Mesh& mesh) {
    std::vector<double> flux(scene.materials.size(), 0.0);
    for (const mesh::Element& e : mesh.elements)
        flux[e.material] += e.area * std::max({e.emission.x, e.emission.y, e.emission.z});
    std::vector<std::size_t> triangles(scene.materials.size(), 0);
    for (const scene::Triangle& t : scene.triangles)
        if (emits(scene, t)) ++triangles[t.material];
    std::vector<std::string> unseen;
    for (std::size_t m = 0; m < scene.materials.size(); ++m) {
        if (triangles[m] == 0 || flux[m] > 0.0) continue;
        const scene::Material& mat = scene.materials[m];
        const std::string why = mat.alpha_cutoff >= 0.0
                                    ? fmt::format("its surfaces are cut away by alphaMode MASK (alpha below its cutoff {:g})",
                                                  mat.alpha_cutoff)
                                : mat.emissive_texture ? "its emissive texture is black where its surfaces are"
                                                       : "its triangles have no area";
        unseen.push_back(fmt::format("material '{}' emits, but its {} {} the bake no light: {}", mat.name,
                                     counted(triangles[m], "triangle"), triangles[m] == 1 ? "gives" : "give", why));
    }
    // One line for them all (a file of many masked lamps would repeat it per material).
    constexpr std::size_t kNamed = 3;
    if (unseen.size() == 1) {
        scene.warnings.push_back(scene.path.string() + ": " + unseen.front());
    } else if (unseen.size() > 1) {
        std::string some;
        for (std::size_t i = 0; i < unseen.size() && i < kNamed; ++i) some += (i ? "; " : "") + unseen[i];
        if (unseen.size() > kNamed) some += fmt::format("; and {} more", grouped(unseen.size() - kNamed));
        scene.warnings.push_back(fmt::format("{}: {} emit but give the bake no light: {}", scene.path.string(),
                                             counted(unseen.size(), "material"), some));
    }
    const bool lit = shining_lights(scene) > 0 ||
                     std::any_of(flux.begin(), flux.end(), [](double f) { return f > 0.0; });
    if (!lit && !unseen.empty()) {
        std::string all;
        for (const std::string& u : unseen) all += (all.empty() ? "" : "; ") + u;
        throw InputError(fmt::format("{}: nothing gives light, the bake would be black: {}", scene.path.string(), all));
    }
}

MemoryLimit memory_limit_of(const std::string& option) {
    if (!option.empty()) {
        try {
            return {parse_bytes(option), "--max-memory allows", std::nullopt};
        } catch (const std::invalid_argument& e) {
            throw InputError(fmt::format("--max-memory {}: {}", option, e.what()));
        }
    }
    const std::optional<double> machine = machine_memory();
    return {machine ? *machine : double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE)), "this machine has",
            available_memory()};
}

bool may_use_opencl(const std::string& device) {
    if (device == "ref") return false;
    if (device == "auto") {
        const char* env = std::getenv("HEMIRAD_DEVICE");
        if (env && std::string(env) == "ref") return false;
        return !ocl::list_devices().empty();
    }
    return true;
}

}  // namespace hemirad::bake
