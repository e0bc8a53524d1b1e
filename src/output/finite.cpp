// NaN and Inf checks for every output of a bake.
#include "output/finite.h"

#include <cmath>

namespace hemirad::output {

bool all_finite(const std::vector<glm::dvec3>& values) {
    for (const glm::dvec3& v : values)
        if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) return false;
    return true;
}

bool all_finite(const Image& image) {
    for (float v : image.rgb)
        if (!std::isfinite(v)) return false;
    return true;
}

std::string first_non_finite(const nlohmann::ordered_json& doc) {
    if (doc.is_number_float()) return std::isfinite(doc.get<double>()) ? std::string() : std::string("/");
    if (doc.is_object()) {
        for (const auto& [key, value] : doc.items()) {
            const std::string inner = first_non_finite(value);
            if (!inner.empty()) return "/" + key + (inner == "/" ? "" : inner);
        }
    } else if (doc.is_array()) {
        for (std::size_t i = 0; i < doc.size(); ++i) {
            const std::string inner = first_non_finite(doc[i]);
            if (!inner.empty()) return "/" + std::to_string(i) + (inner == "/" ? "" : inner);
        }
    }
    return {};
}

}  // namespace hemirad::output
