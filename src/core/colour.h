// Colour helpers shared by the solver, the planner, the output and the benchmarks.
#pragma once

#include <glm/glm.hpp>

namespace hemirad {

// Relative luminance of linear RGB with Rec. 709 / sRGB primaries.
inline double luminance(const glm::dvec3& rgb) { return 0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z; }

}  // namespace hemirad
