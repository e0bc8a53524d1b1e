// Per-element texture averages (see texturing.h).
#include "mesh/texturing.h"

#include <algorithm>
#include <cmath>

#include "core/colour.h"

namespace hemirad::mesh {
namespace {

using glm::dvec2;
using glm::dvec3;

// Sample points per side of a triangle, at most: kMaxSamples^2 points per triangle of an element.
constexpr int kMaxSamples = 8;
// An emission differs across children when the brightest child's luminance exceeds the dimmest's
// by more than this share of the brightest.
constexpr double kEmissionContrast = 0.02;

// Barycentric coordinates of p (in the triangle's plane) with respect to triangle t, as ratios
// of cross products with the triangle's normal. (The Gram determinant d00·d11 − d01² that the
// textbook formula divides by cancels to nothing, or below zero, for a needle a billionth as
// wide as it is long, which the mesher keeps: its weights came out NaN.)
dvec3 barycentric(const scene::Triangle& t, const dvec3& p) {
    const dvec3 e0 = t.p[1] - t.p[0], e1 = t.p[2] - t.p[0], e2 = p - t.p[0];
    const dvec3 n = glm::cross(e0, e1);
    const double denom = glm::dot(n, n);
    const double v = glm::dot(glm::cross(e2, e1), n) / denom;
    const double w = glm::dot(glm::cross(e0, e2), n) / denom;
    return {1.0 - v - w, v, w};
}

dvec2 uv_of(const std::array<glm::vec2, 3>& uv, const dvec3& w) {
    return w.x * dvec2(uv[0]) + w.y * dvec2(uv[1]) + w.z * dvec2(uv[2]);
}

}  // namespace

SourcePoint source_point(const scene::Triangle& a, const scene::Triangle* b, const dvec3& p) {
    SourcePoint s{&a, barycentric(a, p)};
    if (b) {
        const dvec3 w1 = barycentric(*b, p);
        if (std::min({w1.x, w1.y, w1.z}) > std::min({s.w.x, s.w.y, s.w.z})) s = {b, w1};
    }
    dvec3 w = glm::max(s.w, dvec3(0.0));
    const double total = w.x + w.y + w.z;
    // Any weights that are not a convex combination (a point triangle, an overflow) give the
    // vertices' mean: a value must stay within the vertices' range, and finite.
    s.w = total > 0.0 && std::isfinite(total) ? w / total : dvec3(1.0 / 3.0);
    return s;
}

dvec3 vertex_rho_at(const scene::Triangle& a, const scene::Triangle* b, const dvec3& p) {
    const SourcePoint s = source_point(a, b, p);
    return s.w.x * s.triangle->rho[0] + s.w.y * s.triangle->rho[1] + s.w.z * s.triangle->rho[2];
}

bool Texturing::samples(std::uint32_t material) const {
    return material < scene_.materials.size() && scene_.materials[material].textured();
}

std::array<double, 2> Texturing::footprint(const Polygon& poly, const scene::Triangle& a,
                                           const scene::Triangle* b) const {
    const scene::Material& m = scene_.materials[a.material];
    std::array<double, 2> texels{0.0, 0.0};
    const std::array<scene::TextureSlot, 2> slots{m.base_texture, m.emissive_texture};
    std::array<SourcePoint, 4> corner;
    for (int i = 0; i < poly.n; ++i) corner[std::size_t(i)] = source_point(a, b, poly.v[std::size_t(i)]);
    for (std::size_t s = 0; s < 2; ++s) {
        if (!slots[s] || !(a.uv_slots & (1u << s))) continue;
        const scene::Texture& tex = *scene_.textures[std::size_t(slots[s].texture)];
        const dvec2 size(tex.width(), tex.height());
        for (int i = 0; i < poly.n; ++i) {
            const SourcePoint& p = corner[std::size_t(i)];
            const SourcePoint& q = corner[std::size_t((i + 1) % poly.n)];
            const auto& uv_p = s == 0 ? p.triangle->uv_base : p.triangle->uv_emissive;
            const auto& uv_q = s == 0 ? q.triangle->uv_base : q.triangle->uv_emissive;
            const double length = glm::length((uv_of(uv_p, p.w) - uv_of(uv_q, q.w)) * size);
            texels[s] = std::max(texels[s], std::isfinite(length) ? length : 0.0);
        }
    }
    return texels;
}

SurfaceAverage Texturing::average(const Polygon& poly, const scene::Triangle& a, const scene::Triangle* b) const {
    SurfaceAverage out;
    const scene::Material& m = scene_.materials[a.material];
    const std::array<scene::TextureSlot, 2> slots{m.base_texture, m.emissive_texture};
    const std::array<double, 2> texels = footprint(poly, a, b);
    // Samples per side from the finer texture's footprint (about one per texel, up to
    // kMaxSamples), and per texture the pyramid level whose texels are no farther apart. Each
    // sample reads the one texel holding it (a box-filtered mean of the texels below it), so
    // light spreads past an element's edge by less than one such texel, not by a filter's width.
    const int k = std::clamp(int(std::ceil(std::max(texels[0], texels[1]))), 1, kMaxSamples);
    std::array<int, 2> level{0, 0};
    std::array<const scene::Texture*, 2> tex{nullptr, nullptr};
    for (std::size_t s = 0; s < 2; ++s) {
        if (!slots[s] || !(a.uv_slots & (1u << s))) continue;
        tex[s] = scene_.textures[std::size_t(slots[s].texture)].get();
        level[s] = int(std::floor(std::log2(std::max(1.0, texels[s] / k))));
    }
    const bool mask = m.alpha_cutoff >= 0.0;
    out.texels = std::max(texels[0], texels[1]);

    dvec3 sum_base(0.0), sum_emit(0.0);
    double covered = 0.0, total = 0.0;
    const auto take = [&](const dvec3& p, double weight) {
        const SourcePoint sp = source_point(a, b, p);
        double alpha = m.alpha_factor;
        if (tex[0]) {
            const glm::dvec4 t = tex[0]->texel(uv_of(sp.triangle->uv_base, sp.w), level[0], slots[0].wrap_s, slots[0].wrap_t);
            sum_base += weight * dvec3(t);
            alpha *= t.a;
        }
        if (tex[1]) {
            const glm::dvec4 t = tex[1]->texel(uv_of(sp.triangle->uv_emissive, sp.w), level[1], slots[1].wrap_s, slots[1].wrap_t);
            sum_emit += weight * dvec3(t);
        }
        if (!mask || alpha >= m.alpha_cutoff) covered += weight;
        total += weight;
    };
    // Each triangle of the polygon's fan, cut into k^2 triangles of equal area: a sample at
    // the centroid of each.
    for (int t = 1; t + 1 < poly.n; ++t) {
        const dvec3 o = poly.v[0], e1 = poly.v[std::size_t(t)] - o, e2 = poly.v[std::size_t(t + 1)] - o;
        const double weight = 0.5 * glm::length(glm::cross(e1, e2)) / double(k * k);
        for (int i = 0; i < k; ++i)
            for (int j = 0; i + j < k; ++j) {
                take(o + ((i + 1.0 / 3.0) * e1 + (j + 1.0 / 3.0) * e2) / double(k), weight);
                if (i + j < k - 1) take(o + ((i + 2.0 / 3.0) * e1 + (j + 2.0 / 3.0) * e2) / double(k), weight);
            }
    }
    if (!(total > 0.0)) return out;
    const auto scale = [](const dvec3& mean_sample, const dvec3& mean) {
        dvec3 r(1.0);
        for (int c = 0; c < 3; ++c) r[c] = mean[c] > 0.0 ? mean_sample[c] / mean[c] : 0.0;
        return r;
    };
    if (tex[0]) out.rho_scale = scale(sum_base / total, tex[0]->mean());
    if (tex[1]) out.emission_scale = scale(sum_emit / total, tex[1]->mean());
    out.coverage = covered / total;
    return out;
}

namespace {

bool cut_by_mask(const scene::Material& m, const SurfaceAverage& whole) {
    return m.alpha_cutoff >= 0.0 && whole.coverage > 0.0 && whole.coverage < 1.0;
}

bool emits_texture(const scene::Material& m) { return m.emissive_texture && m.emission != dvec3(0.0); }

}  // namespace

bool Texturing::may_split(std::uint32_t material, const SurfaceAverage& whole) const {
    if (material >= scene_.materials.size() || whole.texels <= 2.0) return false;
    const scene::Material& m = scene_.materials[material];
    return cut_by_mask(m, whole) || emits_texture(m);
}

bool Texturing::should_split(std::uint32_t material, const SurfaceAverage& whole,
                             const std::array<SurfaceAverage, 4>& children) const {
    const scene::Material& m = scene_.materials[material];
    if (cut_by_mask(m, whole)) return true;
    if (!emits_texture(m)) return false;
    double lo = HUGE_VAL, hi = 0.0;
    for (const SurfaceAverage& c : children) {
        const double y = luminance(m.emission * c.emission_scale);
        lo = std::min(lo, y);
        hi = std::max(hi, y);
    }
    return hi - lo > kEmissionContrast * hi;
}

dvec3 Texturing::rho(const dvec3& vertex_rho, const SurfaceAverage& s) const {
    return glm::clamp(vertex_rho * s.rho_scale, dvec3(0.0), dvec3(scene::kMaxReflectance));
}

dvec3 Texturing::emission(std::uint32_t material, const SurfaceAverage& s) const {
    return scene_.materials[material].emission * s.emission_scale;
}

void Texturing::apply(Element& e) const {
    if (!samples(e.material) || e.source[0] >= scene_.triangles.size()) return;
    const scene::Triangle& a = scene_.triangles[e.source[0]];
    const scene::Triangle* b = e.source[1] < scene_.triangles.size() ? &scene_.triangles[e.source[1]] : nullptr;
    const SurfaceAverage s = average(e.poly, a, b);
    e.rho = rho(vertex_rho_at(a, b, e.centroid), s);
    e.emission = emission(e.material, s);
}

}  // namespace hemirad::mesh
