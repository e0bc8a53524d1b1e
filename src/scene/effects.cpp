// The effects planner: what a scene calls for, effect by effect, with the evidence.
#include "scene/effects.h"

#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <optional>
#include <set>
#include <stdexcept>
#include <vector>

#include "core/colour.h"
#include "core/error.h"
#include "scene/outlines.h"

namespace hemirad::scene {

namespace {

std::string trim(const std::string& s) {
    std::size_t b = 0, e = s.size();
    while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
    while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
    return s.substr(b, e - b);
}

std::string lower(std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

std::string node_name(const Scene& scene, std::size_t triangle) {
    const std::uint32_t node = scene.triangles[triangle].node;
    return node < scene.nodes.size() ? scene.nodes[node].name : fmt::format("node{}", node);
}

std::string material_name(const Scene& scene, std::uint32_t material) {
    if (material >= scene.materials.size()) return fmt::format("material{}", material);
    const std::string& name = scene.materials[material].name;
    return name.empty() ? fmt::format("material{}", material) : name;
}

std::string vec(const glm::dvec3& v) { return fmt::format("({:.4g}, {:.4g}, {:.4g})", v.x, v.y, v.z); }

bool grey(const glm::dvec3& v) { return v.r == v.g && v.g == v.b; }

const Material* material_of(const Scene& scene, const Triangle& t) {
    return t.material < scene.materials.size() ? &scene.materials[t.material] : nullptr;
}

EffectDecision automatic(bool on, std::string why) { return {on, false, std::move(why)}; }

// The decision for one effect: the scene's, unless forced.
EffectDecision decide(Force force, EffectDecision analysis) {
    if (force == Force::automatic) return analysis;
    const bool on = force == Force::on;
    return {on, true,
            fmt::format("forced {} from the command line (the scene analysis would have turned it {}: {})",
                        on ? "on" : "off", analysis.on ? "on" : "off", analysis.why)};
}

// Whether a material is double-sided once the two_sided override is applied.
bool effectively_double_sided(const Material& m, Force two_sided) {
    if (two_sided == Force::on) return true;
    if (two_sided == Force::off) return false;
    return m.double_sided;
}

// ---- occlusion ---------------------------------------------------------------------------------

struct Plane {
    glm::dvec3 n;
    double d;               // n·x = d on the plane
    std::size_t triangle;   // a triangle on it
};

// Pairs of coplanar triangles the overlap check may test before it assumes occlusion instead.
constexpr double kMaxOverlapPairs = 5e7;

// Two of the triangles (all in one plane with unit normal n) whose interiors overlap by more than
// `tolerance` (a length), if any: the separating axis test on their edge normals, over the pairs
// whose bounding boxes in the plane overlap (a sweep along the first axis). Each pair the sweep
// visits spends one of `budget`; once it is spent, `gave_up` is set and nullopt returned (a grid
// of triangles aligned with the sweep's axis makes the sweep quadratic).
std::optional<std::pair<std::size_t, std::size_t>> overlapping_pair(const Scene& scene,
                                                                      const std::vector<std::size_t>& triangles,
                                                                      const glm::dvec3& n, double tolerance,
                                                                      double& budget, bool& gave_up) {
    if (triangles.size() < 2) return std::nullopt;
    const glm::dvec3 u = glm::normalize(glm::cross(std::abs(n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0), n));
    const glm::dvec3 v = glm::cross(n, u);
    struct Flat {
        std::array<glm::dvec2, 3> p;
        double lo, hi;      // along u
        double v_lo, v_hi;  // along v
        std::size_t triangle;
    };
    std::vector<Flat> flat;
    flat.reserve(triangles.size());
    for (std::size_t t : triangles) {
        Flat f;
        for (int k = 0; k < 3; ++k) f.p[k] = {glm::dot(scene.triangles[t].p[k], u), glm::dot(scene.triangles[t].p[k], v)};
        f.lo = std::min({f.p[0].x, f.p[1].x, f.p[2].x});
        f.hi = std::max({f.p[0].x, f.p[1].x, f.p[2].x});
        f.v_lo = std::min({f.p[0].y, f.p[1].y, f.p[2].y});
        f.v_hi = std::max({f.p[0].y, f.p[1].y, f.p[2].y});
        f.triangle = t;
        flat.push_back(f);
    }
    std::sort(flat.begin(), flat.end(), [](const Flat& a, const Flat& b) { return a.lo < b.lo; });
    // Separated along the normal of an edge of a: b lies beyond it, less the tolerance.
    const auto separated = [tolerance](const Flat& a, const Flat& b) {
        for (int e = 0; e < 3; ++e) {
            const glm::dvec2 d = a.p[(e + 1) % 3] - a.p[e];
            const double len = glm::length(d);
            if (!(len > 0.0)) continue;
            const glm::dvec2 axis(d.y / len, -d.x / len);
            double a_lo = 1e300, a_hi = -1e300, b_lo = 1e300, b_hi = -1e300;
            for (int k = 0; k < 3; ++k) {
                a_lo = std::min(a_lo, glm::dot(axis, a.p[k]));
                a_hi = std::max(a_hi, glm::dot(axis, a.p[k]));
                b_lo = std::min(b_lo, glm::dot(axis, b.p[k]));
                b_hi = std::max(b_hi, glm::dot(axis, b.p[k]));
            }
            if (b_lo >= a_hi - tolerance || a_lo >= b_hi - tolerance) return true;
        }
        return false;
    };
    for (std::size_t i = 0; i < flat.size(); ++i)
        for (std::size_t j = i + 1; j < flat.size() && flat[j].lo < flat[i].hi - tolerance; ++j) {
            if (--budget < 0.0) {
                gave_up = true;
                return std::nullopt;
            }
            if (flat[j].v_lo >= flat[i].v_hi - tolerance || flat[i].v_lo >= flat[j].v_hi - tolerance) continue;
            if (!separated(flat[i], flat[j]) && !separated(flat[j], flat[i]))
                return std::make_pair(std::min(flat[i].triangle, flat[j].triangle),
                                      std::max(flat[i].triangle, flat[j].triangle));
        }
    return std::nullopt;
}

EffectDecision analyse_occlusion(const Scene& scene, Force two_sided) {
    const std::size_t count = scene.triangles.size();
    if (count == 0) return automatic(false, "the scene has no triangles, so nothing can hide anything");

    // Back faces: a double-sided triangle also faces the other way, and that side sees (and is
    // hidden by) whatever lies behind the front.
    if (two_sided == Force::on)
        return automatic(true, "two_sided is forced on, so every triangle has a back face looking away from the "
                               "front faces, and surfaces can hide one another");
    std::size_t double_sided = 0, example = 0;
    for (std::size_t i = 0; i < count; ++i) {
        const Material* m = material_of(scene, scene.triangles[i]);
        if (m && effectively_double_sided(*m, two_sided)) {
            if (double_sided++ == 0) example = i;
        }
    }
    if (double_sided > 0)
        return automatic(true, fmt::format("{} of {} triangles use a double-sided material (e.g. '{}' on node '{}'), "
                                           "whose back faces look away from the front faces, so surfaces can hide "
                                           "one another",
                                           double_sided, count, material_name(scene, scene.triangles[example].material),
                                           node_name(scene, example)));

    glm::dvec3 lo(0.0), hi(0.0);
    bool any = false;
    for (const Triangle& t : scene.triangles)
        for (const glm::dvec3& p : t.p) {
            lo = any ? glm::min(lo, p) : p;
            hi = any ? glm::max(hi, p) : p;
            any = true;
        }
    const double diagonal = glm::length(hi - lo);
    const double tolerance = 1e-9 * diagonal;

    // Distinct planes of the non-degenerate triangles (an approximate de-duplication: planes
    // that differ by rounding only are merged, others are merely checked twice).
    std::vector<Plane> planes;
    planes.reserve(count);
    for (std::size_t i = 0; i < count; ++i) {
        const Triangle& t = scene.triangles[i];
        const glm::dvec3 c = glm::cross(t.p[1] - t.p[0], t.p[2] - t.p[0]);
        const double len = glm::length(c);
        if (!(len > 1e-24 * diagonal * diagonal)) continue;  // zero area: no plane, hides nothing
        const glm::dvec3 n = c / len;
        planes.push_back({n, glm::dot(n, (t.p[0] + t.p[1] + t.p[2]) / 3.0), i});
    }
    if (planes.empty()) return automatic(false, "every triangle has zero area, so nothing can hide anything");
    // Triangles grouped by plane: coplanar ones that face the same way and overlap fight for the
    // same light (a decal, a duplicated face), which only a depth test can share out.
    std::vector<std::vector<std::size_t>> coplanar;
    {
        const double dq = diagonal > 0.0 ? 1e-9 * diagonal : 1.0;
        using Key = std::array<std::int64_t, 4>;
        auto key = [dq](const Plane& p) {
            return Key{std::llround(p.n.x * 1e9), std::llround(p.n.y * 1e9), std::llround(p.n.z * 1e9),
                       std::llround(p.d / dq)};
        };
        std::vector<std::pair<Key, std::size_t>> keyed;
        keyed.reserve(planes.size());
        for (std::size_t i = 0; i < planes.size(); ++i) keyed.push_back({key(planes[i]), i});
        std::sort(keyed.begin(), keyed.end());
        std::vector<Plane> distinct;
        for (std::size_t i = 0; i < keyed.size(); ++i) {
            if (i == 0 || keyed[i].first != keyed[i - 1].first) {
                distinct.push_back(planes[keyed[i].second]);
                coplanar.emplace_back();
            }
            coplanar.back().push_back(planes[keyed[i].second].triangle);
        }
        planes.swap(distinct);
    }

    // Distinct vertices (exact), each with a triangle it belongs to.
    struct Vertex {
        glm::dvec3 p;
        std::size_t triangle;
    };
    std::vector<Vertex> vertices;
    vertices.reserve(3 * count);
    for (std::size_t i = 0; i < count; ++i)
        for (const glm::dvec3& p : scene.triangles[i].p) vertices.push_back({p, i});
    auto less = [](const Vertex& a, const Vertex& b) {
        if (a.p.x != b.p.x) return a.p.x < b.p.x;
        if (a.p.y != b.p.y) return a.p.y < b.p.y;
        return a.p.z < b.p.z;
    };
    std::sort(vertices.begin(), vertices.end(), less);
    vertices.erase(std::unique(vertices.begin(), vertices.end(), [](const Vertex& a, const Vertex& b) { return a.p == b.p; }),
                   vertices.end());

    const double work = static_cast<double>(planes.size()) * static_cast<double>(vertices.size());
    if (work > 2e8)
        return automatic(true, fmt::format("the scene is too large to check ({} distinct planes × {} vertices), so "
                                           "occlusion is assumed",
                                           planes.size(), vertices.size()));

    // Structure of arrays for the inner loop.
    const std::size_t nv = vertices.size();
    std::vector<double> xs(nv), ys(nv), zs(nv);
    for (std::size_t k = 0; k < nv; ++k) {
        xs[k] = vertices[k].p.x;
        ys[k] = vertices[k].p.y;
        zs[k] = vertices[k].p.z;
    }
    for (const Plane& plane : planes) {
        const double nx = plane.n.x, ny = plane.n.y, nz = plane.n.z, limit = plane.d - tolerance;
        std::size_t found = 0;
        while (found < nv && nx * xs[found] + ny * ys[found] + nz * zs[found] >= limit) ++found;
        if (found == nv) continue;
        const Vertex& v = vertices[found];
        const double depth = plane.d - glm::dot(plane.n, v.p);
        return automatic(true, fmt::format("vertex {} of node '{}' (triangle {}) lies {:.4g} behind the plane of "
                                           "triangle {} of node '{}', so surfaces can hide one another",
                                           vec(v.p), node_name(scene, v.triangle), v.triangle, depth, plane.triangle,
                                           node_name(scene, plane.triangle)));
    }
    // A punctual light must lie in that region too: one behind a plane has that triangle's back
    // towards it, which casts a shadow.
    for (const PunctualLight& light : scene.lights) {
        if (light.type == PunctualLight::Type::directional) continue;
        for (const Plane& plane : planes) {
            if (glm::dot(plane.n, light.position) >= plane.d - tolerance) continue;
            return automatic(true, fmt::format("light '{}' at {} lies {:.4g} behind the plane of triangle {} of node "
                                               "'{}', so that triangle can cast its shadow",
                                               light.name, vec(light.position),
                                               plane.d - glm::dot(plane.n, light.position), plane.triangle,
                                               node_name(scene, plane.triangle)));
        }
    }
    double pair_budget = kMaxOverlapPairs;
    for (std::size_t g = 0; g < coplanar.size(); ++g) {
        bool gave_up = false;
        const auto overlap = overlapping_pair(scene, coplanar[g], planes[g].n, tolerance, pair_budget, gave_up);
        if (gave_up)
            return automatic(true, fmt::format("the scene's coplanar triangles are too many to check for overlaps (over "
                                               "{:g} pairs), so occlusion is assumed",
                                               kMaxOverlapPairs));
        if (!overlap) continue;
        return automatic(true, fmt::format("triangle {} of node '{}' and triangle {} of node '{}' overlap in one plane, "
                                           "facing the same way (a duplicated face or a decal), so only one of them can "
                                           "be lit where they overlap",
                                           overlap->first, node_name(scene, overlap->first), overlap->second,
                                           node_name(scene, overlap->second)));
    }
    return automatic(false, fmt::format("all {} vertices{} lie on or in front of all {} distinct triangle planes ({} "
                                        "triangles): the surfaces bound a convex region seen from inside, so no surface "
                                        "can hide one front face from another",
                                        nv, scene.lights.empty() ? "" : " and lights", planes.size(), count));
}

// ---- colour, interreflection, two-sidedness ----------------------------------------------------

EffectDecision analyse_colour(const Scene& scene) {
    std::size_t coloured = 0, example = 0;
    for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
        const Triangle& t = scene.triangles[i];
        if (!grey(t.rho[0]) || !grey(t.rho[1]) || !grey(t.rho[2])) {
            if (coloured++ == 0) example = i;
        }
    }
    std::vector<char> used(scene.materials.size(), 0);
    for (const Triangle& t : scene.triangles)
        if (t.material < used.size()) used[t.material] = 1;
    std::size_t coloured_emitters = 0, emitters = 0;
    std::uint32_t emitter_example = 0;
    for (std::uint32_t m = 0; m < scene.materials.size(); ++m) {
        if (!used[m]) continue;
        const glm::dvec3& e = scene.materials[m].emission;
        if (e != glm::dvec3(0.0)) ++emitters;
        if (!grey(e)) {
            if (coloured_emitters++ == 0) emitter_example = m;
        }
    }
    if (coloured > 0) {
        const Triangle& t = scene.triangles[example];
        const Material* m = material_of(scene, t);
        const std::string what =
            m && !grey(m->base_color)
                ? fmt::format("material '{}' with base colour {} on node '{}'", material_name(scene, t.material),
                              vec(m->base_color), node_name(scene, example))
                : fmt::format("triangle {} of node '{}' with vertex reflectance {} (material '{}')", example,
                              node_name(scene, example),
                              vec(!grey(t.rho[0]) ? t.rho[0] : !grey(t.rho[1]) ? t.rho[1] : t.rho[2]),
                              material_name(scene, t.material));
        return automatic(true, fmt::format("{} of {} triangles have a coloured reflectance (r, g, b not all equal), "
                                           "e.g. {}, so three channels are solved",
                                           coloured, scene.triangles.size(), what));
    }
    for (std::uint32_t m = 0; m < scene.materials.size(); ++m)
        if (used[m] && scene.materials[m].coloured_texture)
            return automatic(true, fmt::format("material '{}' has a coloured texture (its texels' r, g, b not all "
                                               "equal), so three channels are solved",
                                               material_name(scene, m)));
    for (const PunctualLight& l : scene.lights)
        if (!grey(l.intensity))
            return automatic(true, fmt::format("light '{}' shines coloured light {}, so three channels are solved",
                                               l.name, vec(l.intensity)));
    if (coloured_emitters > 0)
        return automatic(true, fmt::format("material '{}' emits coloured light {}, so three channels are solved",
                                           material_name(scene, emitter_example),
                                           vec(scene.materials[emitter_example].emission)));
    return automatic(false, fmt::format("all {} triangles' reflectances and the emission of all {} emitting "
                                        "material{} are grey (r = g = b), so one channel is solved",
                                        scene.triangles.size(), emitters, emitters == 1 ? "" : "s"));
}

EffectDecision analyse_interreflection(const Scene& scene) {
    std::size_t reflecting = 0, example = 0;
    for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
        const Triangle& t = scene.triangles[i];
        const glm::dvec3 zero(0.0);
        if (t.rho[0] != zero || t.rho[1] != zero || t.rho[2] != zero) {
            if (reflecting++ == 0) example = i;
        }
    }
    if (reflecting == 0)
        return automatic(false, fmt::format("all {} triangles have reflectance 0, so only the emitters' direct light "
                                            "is needed (one shot each)",
                                            scene.triangles.size()));
    const Triangle& t = scene.triangles[example];
    const glm::dvec3 rho = t.rho[0] != glm::dvec3(0.0) ? t.rho[0] : t.rho[1] != glm::dvec3(0.0) ? t.rho[1] : t.rho[2];
    return automatic(true, fmt::format("{} of {} triangles reflect light, e.g. triangle {} of node '{}' (material "
                                       "'{}', reflectance {}), so light bounces",
                                       reflecting, scene.triangles.size(), example, node_name(scene, example),
                                       material_name(scene, t.material), vec(rho)));
}

EffectDecision analyse_two_sided(const Scene& scene) {
    std::size_t count = 0, example = 0;
    for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
        const Material* m = material_of(scene, scene.triangles[i]);
        if (m && m->double_sided) {
            if (count++ == 0) example = i;
        }
    }
    if (count == 0) return automatic(false, "no triangle uses a double-sided material, so back faces need no patches");
    return automatic(true, fmt::format("{} of {} triangles use a double-sided material (e.g. '{}' on node '{}'), so "
                                       "their back faces get patches of their own",
                                       count, scene.triangles.size(),
                                       material_name(scene, scene.triangles[example].material),
                                       node_name(scene, example)));
}

EffectDecision analyse_see_through(const Scene& scene) {
    std::size_t count = 0, example = 0;
    std::set<std::uint32_t> materials;
    for (std::size_t i = 0; i < scene.triangles.size(); ++i) {
        const Material* m = material_of(scene, scene.triangles[i]);
        if (m && !m->see_through.empty()) {
            if (count++ == 0) example = i;
            materials.insert(scene.triangles[i].material);
        }
    }
    if (count == 0)
        return automatic(false, "no material is see-through (alphaMode BLEND or KHR_materials_transmission below "
                                "half opacity, a quarter for an emitter), so every surface is opaque");
    const std::uint32_t material = scene.triangles[example].material;
    return automatic(true, fmt::format("{} of {} triangles use {} see-through material{} (e.g. '{}' on node '{}', {}): "
                                       "like glass and fake light shafts they neither block, emit nor receive light "
                                       "(see_through=off bakes them as opaque surfaces)",
                                       count, scene.triangles.size(), materials.size(), materials.size() == 1 ? "" : "s",
                                       material_name(scene, material), node_name(scene, example),
                                       scene.materials[material].see_through));
}

EffectDecision analyse_outlines(const Scene& scene, const OutlineSearch& found) {
    if (found.hulls.empty()) {
        if (found.inward_shells == 0)
            return automatic(false, "no one-sided mesh turns its faces inwards around another object, so there is no "
                                    "inverted-hull outline to leave out");
        return automatic(false, fmt::format("{} one-sided mesh{} turn{} {} faces inwards (e.g. node '{}') but none hugs "
                                            "what it encloses as an outline's hull does (within {:g}% of its size on "
                                            "every side): rooms, whose backs rightly keep the light out",
                                            found.inward_shells, found.inward_shells == 1 ? "" : "es",
                                            found.inward_shells == 1 ? "s" : "", found.inward_shells == 1 ? "its" : "their",
                                            found.example_shell, 100.0 * kHugFraction));
    }
    double gap = 0.0;
    std::size_t named = 0, siblings = 0;
    std::set<std::uint32_t> nodes;
    for (const OutlineHull& h : found.hulls) {
        if (!h.sibling) gap = std::max(gap, h.gap);
        siblings += h.sibling;
        named += h.named;
        nodes.insert(h.node);
    }
    const std::uint32_t node = found.hulls.front().node;
    return automatic(true, fmt::format("{} inverted-hull outline{} ({} triangles on {} node{}, e.g. '{}'{}) hug{} the "
                                       "object{} {} enclose{} (the widest gap {:.3g}% of a hull's size), faces turned "
                                       "inwards, one-sided{}: left out as viewers cull them; outlines=off keeps them",
                                       grouped(found.hulls.size()), found.hulls.size() == 1 ? "" : "s",
                                       grouped(found.triangles.size()), grouped(nodes.size()), nodes.size() == 1 ? "" : "s",
                                       node < scene.nodes.size() ? scene.nodes[node].name : fmt::format("node{}", node),
                                       named == 0 ? std::string()
                                       : named == found.hulls.size() ? std::string("; named as outlines")
                                                                     : fmt::format("; {} named as outlines", named),
                                       found.hulls.size() == 1 ? "s" : "", found.hulls.size() == 1 ? "" : "s",
                                       found.hulls.size() == 1 ? "it" : "they", found.hulls.size() == 1 ? "s" : "",
                                       100.0 * gap,
                                       siblings == 0 ? std::string()
                                                     : fmt::format(" ({} of them one-sided meshes of a material mostly on "
                                                                   "such hulls, no larger than they)",
                                                                   grouped(siblings))));
}

// The effects judged on the surfaces that take part (see-through ones and outlines left out).
EffectsPlan plan_rest(const Scene& scene, const EffectOverrides& overrides, EffectsPlan plan) {
    plan.occlusion = decide(overrides.occlusion, analyse_occlusion(scene, overrides.two_sided));
    plan.colour = decide(overrides.colour, analyse_colour(scene));
    plan.interreflection = decide(overrides.interreflection, analyse_interreflection(scene));
    plan.two_sided = decide(overrides.two_sided, analyse_two_sided(scene));
    plan.refinement = decide(overrides.refinement,
                             automatic(true, "elements are split where the radiosity contrast with a neighbour exceeds "
                                             "the threshold"));
    plan.convergence = decide(overrides.convergence,
                              automatic(true, "stop when the light left unshot can no longer change the output visibly"));
    return plan;
}

}  // namespace

const char* to_string(Force force) {
    switch (force) {
        case Force::on: return "on";
        case Force::off: return "off";
        case Force::automatic: break;
    }
    return "auto";
}

std::string effect_names(const char* last) {
    std::string out;
    for (std::size_t i = 0; i < kEffectNames.size(); ++i)
        out += (i == 0 ? "" : i + 1 == kEffectNames.size() ? fmt::format(" {} ", last) : std::string(", ")) +
               kEffectNames[i];
    return out;
}

EffectOverrides parse_effect_overrides(const std::string& spec) {
    EffectOverrides out;
    if (trim(spec).empty()) return out;
    // In kEffectNames' order.
    Force* const slots[] = {&out.occlusion,  &out.colour,      &out.interreflection, &out.two_sided,
                            &out.refinement, &out.convergence, &out.see_through,     &out.outlines};
    static_assert(sizeof slots / sizeof slots[0] == kEffectNames.size(), "one slot per name of kEffectNames");
    constexpr int kEffects = int(kEffectNames.size());
    const auto& names = kEffectNames;
    bool seen[kEffects] = {};
    std::size_t start = 0;
    while (true) {
        const std::size_t comma = spec.find(',', start);
        const std::string item = trim(spec.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
        if (item.empty()) throw std::invalid_argument(fmt::format("effects '{}': empty item", spec));
        const std::size_t eq = item.find('=');
        if (eq == std::string::npos)
            throw std::invalid_argument(fmt::format("effects '{}': item '{}' is not name=on|off|auto", spec, item));
        const std::string name = lower(trim(item.substr(0, eq)));
        const std::string value = lower(trim(item.substr(eq + 1)));
        int index = -1;
        for (int i = 0; i < kEffects; ++i)
            if (name == names[i]) index = i;
        if (index < 0)
            throw std::invalid_argument(fmt::format("effects '{}': unknown effect '{}' in '{}' (expected {})", spec,
                                                    name, item, effect_names()));
        Force force;
        if (value == "on") force = Force::on;
        else if (value == "off") force = Force::off;
        else if (value == "auto") force = Force::automatic;
        else
            throw std::invalid_argument(
                fmt::format("effects '{}': bad value '{}' in '{}' (expected on, off or auto)", spec, value, item));
        if (seen[index]) throw std::invalid_argument(fmt::format("effects '{}': '{}' given twice", spec, name));
        seen[index] = true;
        *slots[index] = force;
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    return out;
}

EffectsPlan plan_effects(const Scene& scene, const EffectOverrides& overrides) {
    EffectsPlan plan;
    plan.see_through = decide(overrides.see_through, analyse_see_through(scene));
    // The other effects are judged on the surfaces that take part.
    if (plan.see_through.on) {
        Scene opaque = scene;
        apply_see_through(opaque, plan);
        EffectsPlan rest = plan_effects(opaque, [&] {
            EffectOverrides o = overrides;
            o.see_through = Force::off;
            return o;
        }());
        rest.see_through = plan.see_through;
        return rest;
    }
    // Outlines are looked for among the surfaces that block light; the other effects are judged
    // on those left once they are gone.
    OutlineSearch found = find_outline_hulls(scene);
    plan.outlines = decide(overrides.outlines, analyse_outlines(scene, found));
    if (plan.outlines.on && !found.triangles.empty()) {
        Scene rest = scene;
        plan.outline_triangles = std::move(found.triangles);
        apply_outlines(rest, plan);
        return plan_rest(rest, overrides, std::move(plan));
    }
    return plan_rest(scene, overrides, plan);
}

void apply_two_sided(Scene& scene, const EffectsPlan& plan, const EffectOverrides& overrides) {
    if (overrides.two_sided == Force::on) {
        for (Material& m : scene.materials) m.double_sided = true;
    } else if (!plan.two_sided.on) {
        for (Material& m : scene.materials) m.double_sided = false;
    }
}

void apply_see_through(Scene& scene, const EffectsPlan& plan) {
    if (!plan.see_through.on) return;
    scene.triangles.erase(std::remove_if(scene.triangles.begin(), scene.triangles.end(),
                                         [&](const Triangle& t) {
                                             return t.material < scene.materials.size() &&
                                                    !scene.materials[t.material].see_through.empty();
                                         }),
                          scene.triangles.end());
}

void apply_outlines(Scene& scene, const EffectsPlan& plan) {
    if (!plan.outlines.on || plan.outline_triangles.empty()) return;
    std::vector<char> hull(scene.triangles.size(), 0);
    for (std::size_t i : plan.outline_triangles) {
        if (i >= hull.size()) throw InternalError("apply_outlines: a hull triangle beyond the scene's (planned on another scene)");
        hull[i] = 1;
    }
    std::size_t kept = 0;
    for (std::size_t i = 0; i < scene.triangles.size(); ++i)
        if (!hull[i]) scene.triangles[kept++] = std::move(scene.triangles[i]);
    scene.triangles.resize(kept);
}

void apply_colour(Scene& scene, const EffectsPlan& plan) {
    if (plan.colour.on) return;
    // Rec. 709 luminance; a grey value is kept bit for bit, so a grey scene is unchanged.
    const auto grey = [](const glm::dvec3& c) {
        return c.x == c.y && c.y == c.z ? c : glm::dvec3(luminance(c));
    };
    for (Material& m : scene.materials) {
        m.base_color = grey(m.base_color);
        m.emission = grey(m.emission);
        m.coloured_texture = false;
    }
    for (std::shared_ptr<const Texture>& t : scene.textures) t = t->grey();
    for (Triangle& t : scene.triangles)
        for (glm::dvec3& rho : t.rho) rho = grey(rho);
    for (PunctualLight& l : scene.lights) l.intensity = grey(l.intensity);
}

}  // namespace hemirad::scene
