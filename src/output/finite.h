// Checks that no NaN or Inf reaches an output: the solution, the rendered image, the report.
#pragma once

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "output/output.h"

namespace hemirad::output {

bool all_finite(const std::vector<glm::dvec3>& values);
bool all_finite(const Image& image);

// The JSON pointer of the first number in `doc` that is NaN or infinite (nlohmann would write
// it as null), or an empty string when every number is finite.
std::string first_non_finite(const nlohmann::ordered_json& doc);

}  // namespace hemirad::output
