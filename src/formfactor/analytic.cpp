// Lambert's closed-form point-to-polygon form factor, with clipping at the tangent plane.
#include "formfactor/analytic.h"

#include <cmath>

#include "formfactor/clip.h"

namespace hemirad::formfactor {

double point_to_polygon(const glm::dvec3& normal, const glm::dvec3* v, int count) {
    // F = 1/(2π) Σ γ_i n·(R_i × R_i+1)/|R_i × R_i+1|, γ_i the angle between R_i and R_i+1.
    double sum = 0.0;
    for (int i = 0; i < count; ++i) {
        const glm::dvec3& a = v[i];
        const glm::dvec3& b = v[(i + 1) % count];
        const glm::dvec3 c = glm::cross(a, b);
        const double len = glm::length(c);
        if (len == 0.0) continue;  // collinear with the point: contributes nothing
        const double gamma = std::atan2(len, glm::dot(a, b));
        sum += gamma * glm::dot(normal, c) / len;
    }
    return std::abs(sum) / (2.0 * M_PI);
}

double point_to_polygon(const glm::dvec3& point, const glm::dvec3& normal, const mesh::Polygon& polygon) {
    // Relative to the point, clipped to its tangent plane n·r >= 0: at most 4 + 1 vertices.
    glm::dvec3 relative[4], clipped[5];
    for (int i = 0; i < polygon.n; ++i) relative[i] = polygon.v[i] - point;
    const int n = clip_convex(relative, polygon.n, [&](const glm::dvec3& r) { return glm::dot(normal, r); }, clipped);
    return n >= 3 ? point_to_polygon(normal, clipped, n) : 0.0;
}

double solid_angle(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
    const double la = glm::length(a), lb = glm::length(b), lc = glm::length(c);
    const double numerator = std::abs(glm::dot(a, glm::cross(b, c)));
    const double denominator = la * lb * lc + glm::dot(a, b) * lc + glm::dot(a, c) * lb + glm::dot(b, c) * la;
    return 2.0 * std::atan2(numerator, denominator);
}

double solid_angle(const glm::dvec3& point, const glm::dvec3& axis, const mesh::Polygon& polygon, double eps) {
    glm::dvec3 relative[4], clipped[5];
    for (int i = 0; i < polygon.n; ++i) relative[i] = polygon.v[i] - point;
    const int n =
        clip_convex(relative, polygon.n, [&](const glm::dvec3& r) { return glm::dot(axis, r) - eps; }, clipped);
    double omega = 0.0;
    for (int i = 1; i + 1 < n; ++i) omega += solid_angle(clipped[0], clipped[i], clipped[i + 1]);
    return omega;
}

}  // namespace hemirad::formfactor
