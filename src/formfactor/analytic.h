// Closed-form form factors used by the delta-form-factor table and the near-field correction.
#pragma once

#include <glm/glm.hpp>

#include "mesh/mesh.h"

namespace hemirad::formfactor {

// Form factor from a differential area at the origin with unit normal `normal` to the polygon
// `v` (Lambert's formula, unoccluded). The polygon must lie wholly above the tangent plane.
double point_to_polygon(const glm::dvec3& normal, const glm::dvec3* v, int count);

// Form factor from a differential area at `point` (unit normal `normal`) to `polygon`, with the
// part of the polygon behind the tangent plane clipped away first. Unoccluded.
double point_to_polygon(const glm::dvec3& point, const glm::dvec3& normal, const mesh::Polygon& polygon);

}  // namespace hemirad::formfactor
