// Punctual lights' direct light: each point light shoots the two hemicubes of a full cube, each
// spot light the one along its direction, through the same engines as patches (rows of solid
// angles, formfactor::Weights); an element receives I × attenuation × Ω / A of each. Each
// directional light (a KHR_lights_punctual one, or --sun: mesh::Mesh::directions) takes a
// parallel shot (formfactor/parallel.h), through the same engines (Shooter::Kind::directional):
// an element receives E × its lit area across the light / A. The solvers start from this light,
// as if the lights had shot first.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include <glm/glm.hpp>

#include "formfactor/engine.h"
#include "mesh/mesh.h"
#include "scene/scene.h"

namespace hemirad::solve {

// Shot counters of lights' hemicubes start here (patches' passes count from 0, refinement's
// re-gathers from 2^40): hemicube i of a mesh at refinement level L takes kLightShots + L·n + i.
inline constexpr std::uint64_t kLightShots = std::uint64_t{1} << 42;

// Whether the mesh's lights give any direct light: a light hemicube, or a directional light of
// intensity > 0.
bool has_direct_light(const mesh::Mesh& mesh, const std::vector<scene::PunctualLight>& lights);

// Light hemicubes shot per engine call: a scene of 200,000 point lights held all their rows at once.
inline constexpr std::size_t kLightBatch = 256;

// Per element, the irradiance of every directional light of the mesh, shot first as one batch
// (shot counter L·lights.size() + the light's index in `lights`, L the level), and of every light
// hemicube of the mesh, shot in batches of kLightBatch (the sums in the same order whatever the
// batch). The mesh's directional lights must be the shining ones of `lights` (InternalError).
// `landed`, if set, receives the flux that reached elements (per channel). Between batches it
// checks for a stop (core/cancel.h) and reports the hemicubes shot of all (`progress`, if set).
// `directional`, if set, receives the directional lights' part alone (refinement follows the
// sun's shadow edges by it).
std::vector<glm::dvec3> direct_light(const mesh::Mesh& mesh, const std::vector<scene::PunctualLight>& lights,
                                     formfactor::Engine& engine, int level, glm::dvec3* landed = nullptr,
                                     const std::function<void(std::size_t, std::size_t)>& progress = {},
                                     std::vector<glm::dvec3>* directional = nullptr);

// Whether a light is directional and shines (it takes a parallel shot).
bool shines_in_parallel(const scene::PunctualLight& light);

}  // namespace hemirad::solve
