// Adaptive refinement (the article's "intelligent subdivision"): after a solve, elements whose
// irradiance contrasts with a neighbour's are split in four, down to a minimum size and a
// maximum level; patches stay the shooters. The new children take their share of the parent's
// irradiance from a re-gather: the patches that shot the most light shoot once more, with the
// light they shot during the solve, onto the refined mesh, and each parent's incident flux is
// shared out among its children in the proportions the re-gather found. The flux books therefore stay exactly as the
// solve left them, while shadow boundaries and the light's surroundings get detail.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <limits>
#include <memory>
#include <vector>

#include "formfactor/engine.h"
#include "mesh/mesh.h"
#include "mesh/texturing.h"

namespace hemirad::solve {

struct RefineSettings {
    // Neighbours (same node, same plane, sharing a vertex) whose irradiance luminance differs by
    // more than this share of the larger are both split. Hemicube noise per element is a few %
    // (aliasing), far below it.
    double contrast = 0.25;
    // ... and by more than this share of the scene's area-mean irradiance: differences among
    // the darkest elements are not worth elements.
    double noise_floor = 0.02;
    double min_size = 0.0;  // elements whose longest edge is at most this are not split
    int max_levels = 2;     // splits of one original element at most
    int batch = 64;         // re-gather shots per engine call
    bool engine_batch = false;  // ... or the engine's preferred batch where larger (Engine::preferred_batch)
    // The re-gather shoots again the emitters (whose direct light casts the sharp shadows), then
    // the patches that shot the most light until all of them cover this share of the light shot;
    // max_shooters at most. What the others shot reaches each parent's children evenly: it is
    // the smooth part of the light.
    double regather_share = 0.6;
    int max_shooters = 256;
    std::uint64_t first_shot = std::uint64_t{1} << 40;  // re-gather shot counters start here
    // A level that would leave more elements than this is not split (the bake's memory budget).
    double max_elements = std::numeric_limits<double>::infinity();
    // Checked between engine calls; when set the refinement stops at the level it is in.
    std::function<bool()> cancelled;
    // The scene's textures, so that split elements take their own averages (none: children keep
    // their parent's reflectance and emission). Must outlive the refinement.
    const mesh::Texturing* texturing = nullptr;
    // The scene's punctual lights (the mesh's light hemicubes name them): each level shoots them
    // again onto the new children, as it does the emitters. None: no lights.
    const std::vector<scene::PunctualLight>* lights = nullptr;
    // Told, after each engine call of a level's re-gather, the level (1 for the first), the shots
    // taken so far and the level's total.
    std::function<void(int, long, long)> progress;
};

struct RefineLevel {
    std::size_t split = 0;     // elements split at this level
    std::size_t elements = 0;  // elements after it
    long shots = 0;            // re-gather hemicubes
};

struct RefineResult {
    mesh::Mesh mesh;
    std::vector<glm::dvec3> irradiance;  // per element of `mesh`
    std::vector<glm::dvec3> radiosity;   // per element: E + ρ·irradiance
    std::vector<RefineLevel> levels;     // one per level that split anything
    // The level that was not split for max_elements, and the elements it would have split; level
    // 0 when none was stopped.
    struct Stop {
        int level = 0;
        std::size_t split = 0;
    } stopped_for_memory;
};

// Elements to split: both members of every neighbouring pair whose irradiance contrasts by the
// settings, that are longer than min_size and below max_levels (`level` per element).
std::vector<bool> mark_contrast(const mesh::Mesh& mesh, const std::vector<glm::dvec3>& irradiance,
                                const std::vector<int>& level, const RefineSettings& settings);

// Elements the sun's shadow edge crosses (adaptive refinement's second rule: a sun pattern finer
// than the elements, blinds' stripes, shows no contrast between them): `sun` is, per element, the
// irradiance of the shining directional lights among `lights` (direct_light's `directional`);
// an element lit by a share of what it would get in full sun (E cos θ, summed over the lights)
// between kSunEdgeShare and 1 − kSunEdgeShare is marked, if splittable as for mark_contrast (but
// down to max_levels + kSunEdgeExtraLevels). The
// parallel shot's share is exact in full light and full shadow, so the bounds need leave no room
// for noise.
inline constexpr double kSunEdgeShare = 0.01;
// Sun edges are split this many levels deeper than max_levels: a stripe of light narrower than an
// element (blinds) needs children of a few per stripe before the output's per-vertex light, each
// vertex the mean of the elements around it, shows it at its width. Only the elements an edge
// crosses are split, a line of them, not an area.
inline constexpr int kSunEdgeExtraLevels = 2;
void mark_sun_edges(const mesh::Mesh& mesh, const std::vector<glm::dvec3>& sun,
                    const std::vector<scene::PunctualLight>& lights, const std::vector<int>& level,
                    const RefineSettings& settings, std::vector<bool>& split);

// The hemicube resolution for a re-gather onto elements `level` splits deep: the base N doubled
// per level, so children cover as many cells as their parents did, up to kMaxRegatherHemicube.
inline constexpr int kMaxRegatherHemicube = 2048;
inline int regather_hemicube(int hemicube, int level) { return std::min(kMaxRegatherHemicube, hemicube << level); }

// A form-factor engine for a refined mesh whose finest elements are `level` splits deep (a
// hemicube engine raises its resolution to regather_hemicube).
using EngineFactory = std::function<std::unique_ptr<formfactor::Engine>(const mesh::Mesh&, int level)>;

// Refines `mesh` level by level, splitting where mark_contrast and (with shining directional
// lights) mark_sun_edges say. `irradiance` is the solved incident light per element (with any
// ambient estimate of the unshot light included); `shot` is, per patch, the radiosity it shot in
// all (what a progressive solve shot, or a matrix solve's patch radiosity).
// `make_engine` builds a form-factor engine for each refined mesh.
RefineResult refine(mesh::Mesh mesh, std::vector<glm::dvec3> irradiance, const std::vector<glm::dvec3>& shot,
                    const EngineFactory& make_engine, const RefineSettings& settings);

}  // namespace hemirad::solve
