// Closed-form form factors (Howell's catalogue, as written in shared/REFERENCES.md) and the
// area form factor measured through any engine.
#include "test_scenes.h"

#include <algorithm>
#include <cmath>

namespace hemirad::test {

scene::Scene lamp_scene(bool occluder) {
    scene::Scene s;
    const std::uint32_t floor = add_material(s, glm::dvec3(0.5), glm::dvec3(0.0));
    const std::uint32_t lamp = add_material(s, glm::dvec3(0.0), glm::dvec3(1.0));
    add_quad(s, {0, 0, 0}, {4, 0, 0}, {4, 4, 0}, {0, 4, 0}, floor, "floor");
    add_quad(s, {1.5, 1.5, 1}, {1.5, 2.5, 1}, {2.5, 2.5, 1}, {2.5, 1.5, 1}, lamp, "lamp");
    if (occluder) {
        const std::uint32_t black = add_material(s, glm::dvec3(0.0), glm::dvec3(0.0));
        add_quad(s, {1, 1, 0.5}, {1, 3, 0.5}, {2, 3, 0.5}, {2, 1, 0.5}, black, "plate");
    }
    finish(s);
    return s;
}

mesh::Polygon rectangle_at(double x0, double x1, double y0, double y1, double z) {
    mesh::Polygon p;
    p.n = 4;
    p.v = {glm::dvec3(x0, y0, z), glm::dvec3(x0, y1, z), glm::dvec3(x1, y1, z), glm::dvec3(x1, y0, z)};
    return p;
}

scene::Scene needle_box(int needles) {
    scene::Scene s;
    const std::uint32_t wall = scene::add_material(s, glm::dvec3(0.7), glm::dvec3(0.0));
    const std::uint32_t lamp = scene::add_material(s, glm::dvec3(0.0), glm::dvec3(5.0), /*double_sided=*/true);
    // The box without its floor (face 2, y = 0, which the fan replaces).
    s = closed_box({1.0, 1.0, 1.0}, [&](int face) { return face == 2 ? lamp : wall; }, s);
    s.triangles.erase(std::remove_if(s.triangles.begin(), s.triangles.end(),
                                     [&](const scene::Triangle& t) { return t.material == lamp; }),
                      s.triangles.end());
    for (int i = 0; i < needles; ++i) {
        const auto edge = [&](int k) {
            const double t = double(k) / needles;  // along the far edges x = 1 then z = 1
            return t <= 0.5 ? glm::dvec3(1.0, 0.0, 2.0 * t) : glm::dvec3(2.0 - 2.0 * t, 0.0, 1.0);
        };
        add_triangle(s, {0, 0, 0}, edge(i + 1), edge(i), wall, "floor needle");  // normal +y
    }
    add_quad(s, {0.45, 0.5, 0.45}, {0.55, 0.5, 0.45}, {0.55, 0.5, 0.55}, {0.45, 0.5, 0.55}, lamp, "lamp");
    finish(s);
    return s;
}

double node_form_factor(const mesh::Mesh& m, const formfactor::ShotResult& r, std::uint32_t node) {
    double f = 0.0;
    for (std::size_t i = 0; i < r.size(); ++i)
        if (m.elements[r.element[i]].node == node) f += r.F[i];
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

bool same_triangles(const scene::Scene& a, const scene::Scene& b) {
    if (a.triangles.size() != b.triangles.size()) return false;
    for (std::size_t i = 0; i < a.triangles.size(); ++i) {
        const scene::Triangle &x = a.triangles[i], &y = b.triangles[i];
        if (x.p != y.p || x.rho != y.rho || x.material != y.material || x.node != y.node || x.primitive != y.primitive)
            return false;
    }
    return true;
}

}  // namespace hemirad::test
