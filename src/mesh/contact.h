// Contact lines: where one surface meets another inside the angle between them (a box standing on
// a floor, a wall meeting the ceiling, a rock sunk into the ground). Light falls off sharply toward
// such a line, within a few millimetres on the Cornell box, where elements are two centimetres:
// a vertex value interpolated across an element there cannot follow it (the bottom row of the
// short block's front was +37% against the path tracer a few pixels above the floor). Grading the
// mesh toward the line (solve::grade_contacts) lets the final gather's vertices sample the fall.
#pragma once

#include <vector>

#include "mesh/mesh.h"

namespace hemirad::mesh {

// Per element: it touches, or crosses, an element of another patch whose normal is more than 40°
// from its own, and that stands in front of it while it stands in front of that one (a concave
// junction: convex edges like a box's top rim, and surfaces lying face to face, do not count),
// and its longest edge is longer than `min_size`.
// Touching is within a hundredth of the larger element's longest edge (a box that rests a hair
// above the floor still stands on it). A hash grid finds the candidates; the test between two
// elements is the exact distance between two convex polygons.
std::vector<bool> contact_elements(const Mesh& mesh, double min_size);

// The distance between two planar convex polygons (0 where they touch or cross).
double polygon_distance(const Polygon& a, const Polygon& b);

}  // namespace hemirad::mesh
