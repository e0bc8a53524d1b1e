// Closed-form form factors (Howell's catalogue, as written in shared/REFERENCES.md) and the
// area form factor measured through any engine.
#include "test_scenes.h"

#include <cmath>

namespace hemirad::test {

double node_form_factor(const mesh::Mesh& m, const formfactor::ShotResult& r, std::uint32_t node) {
    double f = 0.0;
    for (std::size_t k = 0; k < m.elements.size(); ++k)
        if (m.elements[k].node == node) f += r.F[k];
    return f;
}

double area_form_factor(const mesh::Mesh& m, formfactor::Engine& engine, std::uint32_t from, std::uint32_t to,
                        std::uint64_t first_shot) {
    formfactor::ShotResult r;
    double weighted = 0.0, area = 0.0;
    std::uint64_t shot = first_shot;
    for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
        if (m.patches[p].node != from) continue;
        engine.shoot(p, shot++, r);
        weighted += m.patches[p].area * node_form_factor(m, r, to);
        area += m.patches[p].area;
    }
    return weighted / area;
}

double parallel_rectangles_ff(double a, double b, double c) {
    const double X = a / c, Y = b / c;
    const double X2 = X * X, Y2 = Y * Y;
    const double t = std::log(std::sqrt((1 + X2) * (1 + Y2) / (1 + X2 + Y2))) +
                     X * std::sqrt(1 + Y2) * std::atan(X / std::sqrt(1 + Y2)) +
                     Y * std::sqrt(1 + X2) * std::atan(Y / std::sqrt(1 + X2)) - X * std::atan(X) - Y * std::atan(Y);
    return 2.0 / (M_PI * X * Y) * t;
}

double perpendicular_rectangles_ff(double l, double w, double h) {
    const double W = w / l, H = h / l;
    const double W2 = W * W, H2 = H * H, S = W2 + H2;
    const double a = (1 + W2) * (1 + H2) / (1 + S);
    const double b = std::pow(W2 * (1 + S) / ((1 + W2) * S), W2);
    const double c = std::pow(H2 * (1 + S) / ((1 + H2) * S), H2);
    const double t = W * std::atan(1 / W) + H * std::atan(1 / H) - std::sqrt(S) * std::atan(1 / std::sqrt(S)) +
                     0.25 * std::log(a * b * c);
    return t / (M_PI * W);
}

}  // namespace hemirad::test
