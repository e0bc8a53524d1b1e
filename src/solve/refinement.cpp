// Adaptive refinement: contrast marking, splitting, and the flux-preserving re-gather.
#include "solve/refinement.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include "core/colour.h"
#include "mesh/refine.h"
#include "solve/lights.h"

namespace hemirad::solve {
namespace {

// Two elements lie in one plane when their normals agree this closely.
constexpr double kSamePlaneDot = 1.0 - 1e-6;

struct PointKey {
    std::uint64_t b[3];
    bool operator==(const PointKey& o) const { return b[0] == o.b[0] && b[1] == o.b[1] && b[2] == o.b[2]; }
};
struct PointKeyHash {
    std::size_t operator()(const PointKey& k) const {
        return std::hash<std::uint64_t>()(k.b[0] * 0x9E3779B97F4A7C15ull ^ k.b[1] * 0xC2B2AE3D27D4EB4Full ^ k.b[2]);
    }
};
PointKey key_of(const glm::dvec3& p) {
    PointKey k{};
    const double c[3] = {p.x + 0.0, p.y + 0.0, p.z + 0.0};  // −0 and +0 alike
    std::memcpy(k.b, c, sizeof c);
    return k;
}

// The emitters, then the other patches that shot the most light, most first, until they cover
// settings.regather_share of all that was shot; at most settings.max_shooters.
std::vector<std::uint32_t> strongest_shooters(const mesh::Mesh& mesh, const std::vector<glm::dvec3>& shot,
                                              const RefineSettings& settings) {
    std::vector<std::uint32_t> order;
    std::vector<double> flux(mesh.patches.size(), 0.0);
    double total = 0.0;
    for (std::size_t p = 0; p < shot.size() && p < mesh.patches.size(); ++p) {
        flux[p] = luminance(shot[p]) * mesh.patches[p].area;
        if (flux[p] > 0.0) order.push_back(static_cast<std::uint32_t>(p));
        total += std::max(0.0, flux[p]);
    }
    const auto emits = [&](std::uint32_t p) { return luminance(mesh.patches[p].emission) > 0.0; };
    std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
        if (emits(a) != emits(b)) return emits(a);
        return flux[a] > flux[b];
    });
    double covered = 0.0;
    std::size_t count = 0;
    while (count < order.size() && count < static_cast<std::size_t>(std::max(1, settings.max_shooters)) &&
           (emits(order[count]) || covered < settings.regather_share * total))
        covered += flux[order[count++]];
    order.resize(count);
    return order;
}

}  // namespace

std::vector<bool> mark_contrast(const mesh::Mesh& mesh, const std::vector<glm::dvec3>& irradiance,
                                const std::vector<int>& level, const RefineSettings& settings) {
    const std::size_t n = mesh.elements.size();
    std::vector<bool> split(n, false);
    double lum_area = 0.0, area = 0.0;
    std::vector<double> lum(n);
    for (std::size_t k = 0; k < n; ++k) {
        lum[k] = luminance(irradiance[k]);
        lum_area += lum[k] * mesh.elements[k].area;
        area += mesh.elements[k].area;
    }
    const double floor = area > 0.0 ? settings.noise_floor * lum_area / area : 0.0;
    std::vector<double> edge(n);
    for (std::size_t k = 0; k < n; ++k) edge[k] = mesh::longest_edge(mesh.elements[k].poly);
    const auto splittable = [&](std::size_t k) {
        return level[k] < settings.max_levels && edge[k] > settings.min_size && !mesh.elements[k].coarse;
    };

    // Elements meeting at a vertex are neighbours; a vertex hanging on a coarser element's edge
    // links it to the children on either side of it through their shared corners.
    std::unordered_map<PointKey, std::vector<std::uint32_t>, PointKeyHash> at;
    at.reserve(n * 2);
    for (std::size_t k = 0; k < n; ++k) {
        const mesh::Polygon& poly = mesh.elements[k].poly;
        for (int i = 0; i < poly.n; ++i) at[key_of(poly.v[std::size_t(i)])].push_back(static_cast<std::uint32_t>(k));
    }
    for (const auto& [point, around] : at) {
        (void)point;
        for (std::size_t x = 0; x < around.size(); ++x) {
            for (std::size_t y = x + 1; y < around.size(); ++y) {
                const std::uint32_t a = around[x], b = around[y];
                const mesh::Element& ea = mesh.elements[a];
                const mesh::Element& eb = mesh.elements[b];
                if (ea.node != eb.node || ea.back != eb.back || glm::dot(ea.normal, eb.normal) < kSamePlaneDot)
                    continue;
                // The difference per element size of distance: diagonal neighbours, farther apart,
                // see a smooth gradient's difference grow by √2 and are judged by that.
                const double diff = std::abs(lum[a] - lum[b]);
                const double size = std::max(edge[a], edge[b]);
                const double distance = std::max(glm::length(ea.centroid - eb.centroid), 1e-300);
                const double rate = diff * std::min(1.0, size / distance);
                if (diff <= floor || rate <= settings.contrast * std::max(lum[a], lum[b])) continue;
                if (splittable(a)) split[a] = true;
                if (splittable(b)) split[b] = true;
            }
        }
    }
    return split;
}

void mark_sun_edges(const mesh::Mesh& mesh, const std::vector<glm::dvec3>& sun,
                    const std::vector<scene::PunctualLight>& lights, const std::vector<int>& level,
                    const RefineSettings& settings, std::vector<bool>& split) {
    for (std::size_t k = 0; k < mesh.elements.size() && k < sun.size(); ++k) {
        const mesh::Element& e = mesh.elements[k];
        if (split[k] || e.coarse || level[k] >= settings.max_levels + kSunEdgeExtraLevels ||
            mesh::longest_edge(e.poly) <= settings.min_size)
            continue;
        double full = 0.0;
        for (const scene::PunctualLight& l : lights)
            if (shines_in_parallel(l)) full += luminance(l.intensity) * std::max(0.0, -glm::dot(e.normal, l.direction));
        if (!(full > 0.0)) continue;
        const double share = luminance(sun[k]) / full;
        if (share > kSunEdgeShare && share < 1.0 - kSunEdgeShare) split[k] = true;
    }
}

RefineResult refine(mesh::Mesh mesh, std::vector<glm::dvec3> irradiance, const std::vector<glm::dvec3>& shot,
                    const EngineFactory& make_engine, const RefineSettings& settings) {
    RefineResult result;
    std::vector<int> level(mesh.elements.size(), 0);
    const std::vector<std::uint32_t> shooters = strongest_shooters(mesh, shot, settings);
    // The directional lights' light on `mesh` (the solve's, shot again on its grid): its shadow
    // edges are split even where no neighbour shows them.
    const bool sunlit = settings.lights && settings.max_levels > 0 &&
                        std::any_of(settings.lights->begin(), settings.lights->end(), shines_in_parallel);
    std::vector<glm::dvec3> sun;
    if (sunlit && !(settings.cancelled && settings.cancelled())) {
        std::unique_ptr<formfactor::Engine> engine = make_engine(mesh, 0);
        std::vector<mesh::LightShooter> hemicubes = std::move(mesh.lights);  // only the parallel shots are needed
        mesh.lights.clear();
        direct_light(mesh, *settings.lights, *engine, 0, nullptr, {}, &sun);
        mesh.lights = std::move(hemicubes);
    }

    for (int depth = 0; depth < settings.max_levels + (sunlit ? kSunEdgeExtraLevels : 0); ++depth) {
        if (settings.cancelled && settings.cancelled()) break;
        std::vector<bool> marked = mark_contrast(mesh, irradiance, level, settings);
        if (sunlit) mark_sun_edges(mesh, sun, *settings.lights, level, settings, marked);
        const std::size_t count = static_cast<std::size_t>(std::count(marked.begin(), marked.end(), true));
        if (count == 0) break;
        if (static_cast<double>(mesh.elements.size()) + 3.0 * static_cast<double>(count) > settings.max_elements) {
            result.stopped_for_memory = {depth + 1, count};
            break;
        }
        mesh::Refined refined = mesh::split_elements(mesh, marked, settings.texturing);
        const mesh::Mesh& m = refined.mesh;

        // The re-gather: light arriving at the new children from every patch that shot.
        std::vector<glm::dvec3> gathered(m.elements.size(), glm::dvec3(0.0));
        // Below max_levels only sun edges are split: the lights alone are shot again, the rest of
        // the light (a patch's, smooth at this scale) is shared evenly, and the hemicubes stay
        // at the finest level's resolution.
        const bool sun_only = depth >= settings.max_levels;
        std::unique_ptr<formfactor::Engine> engine = make_engine(m, std::min(depth + 1, settings.max_levels));
        std::vector<formfactor::ShotRequest> requests;
        std::vector<formfactor::ShotResult> results;
        long shots = 0;
        const std::size_t batch = engine->batch_for(settings.batch, settings.engine_batch);
        for (std::size_t first = 0; !sun_only && first < shooters.size(); first += batch) {
            if (settings.cancelled && settings.cancelled()) break;
            requests.clear();
            for (std::size_t i = first; i < std::min(shooters.size(), first + batch); ++i)
                requests.push_back(formfactor::ShotRequest::of_patch(
                    shooters[i],
                    settings.first_shot + static_cast<std::uint64_t>(depth) * mesh.patches.size() + shooters[i]));
            engine->shoot_batch(requests, results);
            shots += static_cast<long>(requests.size());
            if (settings.progress) settings.progress(depth + 1, shots, static_cast<long>(shooters.size()));
            for (std::size_t r = 0; r < requests.size(); ++r) {
                const std::uint32_t p = requests[r].shooter.patch;
                const glm::dvec3 flux = shot[p] * m.patches[p].area;
                const formfactor::ShotResult& row = results[r];
                for (std::size_t i = 0; i < row.size(); ++i) {
                    const std::uint32_t k = row.element[i];
                    if (refined.is_new[k] && row.F[i] != 0.0) gathered[k] += flux * row.F[i] / m.elements[k].area;
                }
            }
        }

        // The lights' direct light, shot again onto the refined mesh: their shadows are the sharpest.
        if (settings.lights && has_direct_light(m, *settings.lights)) {
            const std::vector<glm::dvec3> direct =
                direct_light(m, *settings.lights, *engine, depth + 1, nullptr, {}, sunlit ? &sun : nullptr);
            for (std::size_t k = 0; k < m.elements.size(); ++k)
                if (refined.is_new[k]) gathered[k] += direct[k];
            shots += static_cast<long>(m.lights.size());
        }

        if (settings.cancelled && settings.cancelled()) break;  // a level half gathered is not used

        // Each parent's children share its incident flux: the strong shooters' light as the
        // re-gather found it, the rest (weaker shooters, the ambient estimate) evenly. Then
        // Σ H_c A_c = H A exactly, so the books do not move.
        std::vector<glm::dvec3> next(m.elements.size());
        std::vector<int> next_level(m.elements.size());
        for (std::size_t k = 0; k < m.elements.size();) {
            const std::uint32_t parent = refined.origin[k];
            if (!refined.is_new[k]) {
                next[k] = irradiance[parent];
                next_level[k] = level[parent];
                ++k;
                continue;
            }
            std::size_t end = k;
            glm::dvec3 strong(0.0);
            while (end < m.elements.size() && refined.is_new[end] && refined.origin[end] == parent) {
                strong += gathered[end] * m.elements[end].area;
                ++end;
            }
            const double parent_area = mesh.elements[parent].area;
            const glm::dvec3 rest = glm::max(irradiance[parent] - strong / parent_area, glm::dvec3(0.0));
            const glm::dvec3 total = strong + rest * parent_area;  // Σ (gathered_c + rest) A_c
            for (std::size_t c = k; c < end; ++c) {
                for (int ch = 0; ch < 3; ++ch)
                    next[c][ch] = total[ch] > 0.0
                                      ? (gathered[c][ch] + rest[ch]) * irradiance[parent][ch] * parent_area / total[ch]
                                      : irradiance[parent][ch];
                next_level[c] = level[parent] + 1;
            }
            k = end;
        }
        result.levels.push_back({count, m.elements.size(), shots});
        mesh = std::move(refined.mesh);
        irradiance = std::move(next);
        level = std::move(next_level);
    }
    result.radiosity.resize(mesh.elements.size());
    for (std::size_t k = 0; k < mesh.elements.size(); ++k)
        result.radiosity[k] = mesh.elements[k].emission + mesh.elements[k].rho * irradiance[k];
    result.mesh = std::move(mesh);
    result.irradiance = std::move(irradiance);
    return result;
}

}  // namespace hemirad::solve
