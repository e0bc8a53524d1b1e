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

// The solid angle of the triangle a, b, c seen from the origin (Van Oosterom and Strackee 1983).
double solid_angle(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c);

// The solid angle of `polygon` seen from `point`, of its part on the side of the plane through
// `point` that `axis` points to (at least `eps` from it). Unoccluded.
double solid_angle(const glm::dvec3& point, const glm::dvec3& axis, const mesh::Polygon& polygon, double eps);

}  // namespace hemirad::formfactor
