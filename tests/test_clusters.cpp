// Patches as clusters of small faces: their size and shape, and bakes on curved, finely
// tessellated and double-sided surfaces checked against analytic answers.
#include <catch2/catch.hpp>

#include <cmath>

#include "formfactor/analytic.h"
#include "formfactor/near_field.h"
#include "formfactor/reference.h"
#include "mesh/mesh.h"
#include "scene/builder.h"
#include "solve/progressive.h"

using namespace hemirad;
using glm::dvec3;

namespace {

// A node of its own holding a UV sphere of rings × segments (triangles at the poles, split quads
// elsewhere, as exporters write them), counter-clockwise seen from outside, or from inside when
// `inward`.
void add_sphere(scene::Scene& s, dvec3 centre, double radius, int rings, int segments, std::uint32_t material,
                bool inward) {
    const auto node = static_cast<std::uint32_t>(s.nodes.size());
    s.nodes.push_back({"sphere" + std::to_string(node), static_cast<int>(node)});
    const auto at = [&](int ring, int segment) {
        const double theta = M_PI * ring / rings, phi = 2.0 * M_PI * (segment % segments) / segments;
        if (ring == 0) return centre + dvec3(0, 0, radius);
        if (ring == rings) return centre - dvec3(0, 0, radius);
        return centre + radius * dvec3(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
    };
    const dvec3 rho = s.materials[material].base_color;
    const auto add = [&](dvec3 a, dvec3 b, dvec3 c) {
        if (inward) std::swap(b, c);
        s.triangles.push_back({{a, b, c}, {rho, rho, rho}, material, node, node});
    };
    for (int r = 0; r < rings; ++r)
        for (int g = 0; g < segments; ++g) {
            const dvec3 a = at(r, g), b = at(r + 1, g), c = at(r + 1, g + 1), d = at(r, g + 1);
            if (r > 0) add(a, b, d);
            if (r + 1 < rings) add(d, b, c);
        }
}

// A planar quad p0..p3 in a node of its own, cut into n × n cells of two triangles each.
void add_tessellated_quad(scene::Scene& s, dvec3 p0, dvec3 p1, dvec3 p3, int n, std::uint32_t material) {
    const auto node = static_cast<std::uint32_t>(s.nodes.size());
    s.nodes.push_back({"quad" + std::to_string(node), static_cast<int>(node)});
    const auto at = [&](int i, int j) { return p0 + (p1 - p0) * (double(i) / n) + (p3 - p0) * (double(j) / n); };
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            scene::add_quad_to(s, at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1), material, node, node);
}

// An inward-facing closed box [0, 1]³, every wall cut into n × n cells.
void add_tessellated_box(scene::Scene& s, int n, std::uint32_t wall, std::uint32_t ceiling) {
    add_tessellated_quad(s, {0, 0, 0}, {0, 1, 0}, {0, 0, 1}, n, wall);  // x = 0, normal +x
    add_tessellated_quad(s, {1, 0, 0}, {1, 0, 1}, {1, 1, 0}, n, wall);  // x = 1, normal −x
    add_tessellated_quad(s, {0, 0, 0}, {0, 0, 1}, {1, 0, 0}, n, wall);  // y = 0, normal +y
    add_tessellated_quad(s, {0, 1, 0}, {1, 1, 0}, {0, 1, 1}, n, wall);  // y = 1, normal −y
    add_tessellated_quad(s, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, n, wall);  // z = 0, normal +z
    add_tessellated_quad(s, {0, 0, 1}, {0, 1, 1}, {1, 0, 1}, n, ceiling);  // z = 1, normal −z
}

std::vector<glm::dvec3> bake(const mesh::Mesh& m, int hemicube, double threshold, bool ambient = true) {
    formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{hemicube, 7}));
    solve::Progressive solver(m, engine, {threshold, 100000});
    while (solver.step()) {
    }
    REQUIRE(solver.converged());
    return solver.radiosity(ambient);
}

}  // namespace

TEST_CASE("a finely tessellated wall becomes patches of about the patch size, its cells the elements", "[clusters]") {
    scene::Scene s;
    const std::uint32_t grey = scene::add_material(s, dvec3(0.5), dvec3(0.0));
    add_tessellated_quad(s, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 32, grey);
    scene::finish(s);
    mesh::Settings settings{0.25, 0.125};
    const mesh::Mesh clustered = mesh::build(s, settings);
    settings.cluster = false;
    const mesh::Mesh plain = mesh::build(s, settings);

    CHECK(plain.patches.size() == 32 * 32);  // a patch per cell (the split quads paired again)
    CHECK(clustered.elements.size() == 32 * 32);
    CHECK(clustered.patches.size() <= 48);  // the area over the patch size's discs, not the cell count
    CHECK(clustered.patches.size() >= 16);
    double area = 0.0;
    for (const mesh::Patch& p : clustered.patches) {
        CHECK(p.cluster() == (p.element_count > 1));
        CHECK(glm::dot(p.normal, dvec3(0, 0, 1)) == Approx(1.0));
        for (std::uint32_t k = p.first_element; k < p.first_element + p.element_count; ++k) {
            const mesh::Element& e = clustered.elements[k];
            CHECK(e.patch == std::uint32_t(&p - clustered.patches.data()));
            for (int i = 0; i < e.poly.n; ++i) CHECK(glm::length(e.poly.v[i] - p.centroid) <= 0.25 * std::sqrt(2.0) + 1e-12);
        }
        area += p.area;
    }
    CHECK(area == Approx(1.0).epsilon(1e-12));
}

TEST_CASE("a cluster keeps its faces' normals within the cone and its material, and never spans nodes", "[clusters]") {
    scene::Scene s;
    const std::uint32_t a = scene::add_material(s, dvec3(0.5), dvec3(0.0));
    const std::uint32_t b = scene::add_material(s, dvec3(0.3), dvec3(0.0));
    add_sphere(s, {0, 0, 0}, 1.0, 24, 48, a, false);
    add_sphere(s, {0.5, 0, 0}, 1.0, 24, 48, b, false);  // overlapping: shares no edge with the first
    scene::finish(s);
    const mesh::Mesh m = mesh::build(s, {0.6, 0.6});
    CHECK(m.patches.size() < s.triangles.size() / 8);
    CHECK(m.clusters > 0);
    const double cone = std::cos(2.0 * std::acos(mesh::kClusterCos));  // both within the cone of the first face
    for (const mesh::Patch& p : m.patches) {
        const mesh::Element& first = m.elements[p.first_element];
        for (std::uint32_t k = p.first_element; k < p.first_element + p.element_count; ++k) {
            const mesh::Element& e = m.elements[k];
            CHECK(e.node == first.node);
            CHECK(e.material == first.material);
            for (std::uint32_t j = p.first_element; j < k; ++j) CHECK(glm::dot(e.normal, m.elements[j].normal) >= cone - 1e-12);
        }
    }
}

TEST_CASE("inside a clustered sphere that glows everywhere, radiosity is E / (1 − ρ) on every element", "[clusters]") {
    // A closed surface of uniform emission E and reflectance ρ: every point receives the same, so
    // B = E + ρB everywhere. The sphere's curvature is what clusters must get right: each shoots
    // from off the surface, along its mean normal.
    scene::Scene s;
    const std::uint32_t glow = scene::add_material(s, dvec3(0.5), dvec3(1.0));
    add_sphere(s, {0, 0, 0}, 1.0, 16, 32, glow, true);
    scene::finish(s);
    const bool cluster = GENERATE(true, false);
    const mesh::Mesh m = mesh::build(s, {0.7, 0.7, cluster});
    CHECK((m.clusters > 0) == cluster);
    const std::vector<glm::dvec3> B = bake(m, 128, 1e-4);
    double worst = 0.0, flux = 0.0, area = 0.0;
    for (std::size_t k = 0; k < B.size(); ++k) {
        worst = std::max(worst, std::abs(B[k].x / 2.0 - 1.0));
        flux += B[k].x * m.elements[k].area;
        area += m.elements[k].area;
    }
    CAPTURE(cluster, m.patches.size(), m.elements.size(), worst, flux / area);
    CHECK(flux / area == Approx(2.0).epsilon(0.005));
    CHECK(worst < 0.05);  // an element's hemicube noise at N = 128
}

TEST_CASE("a double-sided clustered sphere in a lit room lights nothing inside itself", "[clusters]") {
    // Its inside is closed off: the back faces (its twin clusters) can receive no light at all. From
    // a cluster's area centroid, a little inside the convex surface, the twins' elements face the
    // shooter: shooting from in front of its elements' planes instead is what keeps them dark.
    scene::Scene s;
    const std::uint32_t wall = scene::add_material(s, dvec3(0.6), dvec3(0.0));
    const std::uint32_t lamp = scene::add_material(s, dvec3(0.0), dvec3(4.0));
    const std::uint32_t ball = scene::add_material(s, dvec3(0.7), dvec3(0.0), /*double_sided=*/true);
    add_tessellated_box(s, 2, wall, lamp);
    add_sphere(s, {0.5, 0.5, 0.4}, 0.25, 12, 24, ball, false);
    scene::finish(s);
    const bool cluster = GENERATE(true, false);
    const mesh::Mesh m = mesh::build(s, {0.3, 0.3, cluster});
    CHECK((m.clusters > 0) == cluster);
    const std::vector<glm::dvec3> B = bake(m, 64, 1e-3, /*ambient=*/false);  // the ambient term lands everywhere
    std::size_t inside = 0, outside_lit = 0;
    for (std::size_t k = 0; k < m.elements.size(); ++k) {
        if (m.elements[k].material != ball) continue;
        if (m.elements[k].back) {
            ++inside;
            CHECK(B[k].x == 0.0);
        } else {
            outside_lit += B[k].x > 0.0;
        }
    }
    CHECK(inside > 0);
    CHECK(outside_lit > 0);
}

TEST_CASE("a furnace of finely tessellated walls gives the same flux with clusters as with a patch per cell", "[clusters]") {
    // A closed box lit by its ceiling: Σ B A = Φ_E / (1 − ρ) whatever the mesh; and the walls'
    // means agree with the unclustered mesh's within the hemicube's noise.
    scene::Scene s;
    const std::uint32_t wall = scene::add_material(s, dvec3(0.8), dvec3(0.0));
    const std::uint32_t ceiling = scene::add_material(s, dvec3(0.8), dvec3(1.0));
    add_tessellated_box(s, 12, wall, ceiling);
    scene::finish(s);
    mesh::Settings settings{0.34, 0.34};
    const mesh::Mesh clustered = mesh::build(s, settings);
    settings.cluster = false;
    const mesh::Mesh plain = mesh::build(s, settings);
    REQUIRE(clustered.patches.size() * 4 < plain.patches.size());
    const std::vector<glm::dvec3> Bc = bake(clustered, 128, 1e-4), Bp = bake(plain, 128, 1e-4);
    const auto node_mean = [](const mesh::Mesh& m, const std::vector<glm::dvec3>& B, std::uint32_t node) {
        double flux = 0.0, area = 0.0;
        for (std::size_t k = 0; k < m.elements.size(); ++k)
            if (m.elements[k].node == node) {
                flux += B[k].x * m.elements[k].area;
                area += m.elements[k].area;
            }
        return flux / area;
    };
    double total = 0.0;
    for (std::uint32_t node = 0; node < 6; ++node) {
        CAPTURE(node);
        CHECK(node_mean(clustered, Bc, node) == Approx(node_mean(plain, Bp, node)).epsilon(0.01));
        total += node_mean(clustered, Bc, node);
    }
    // Σ B A over the six unit walls = E·1 / (1 − ρ) = 5.
    CHECK(total == Approx(5.0).epsilon(0.005));
}

TEST_CASE("no cluster shoots from across another face: a ball resting on the floor, a wall around a ledge", "[clusters]") {
    // A closed room of single-sided surfaces, each facing into it: from any point a shooter may
    // stand for, every cell sees the front of something, so a shot's form factors sum to 1 with
    // nothing blocked. Two clusters' centroids break that: the bottom cap of a ball resting at its
    // pole on the floor shoots from under the floor (nothing at all), and a wall panel clustered
    // around a ledge shoots from inside the ledge (the backs of its faces).
    scene::Scene s;
    const std::uint32_t wall = scene::add_material(s, dvec3(0.6), dvec3(0.0));
    const std::uint32_t lamp = scene::add_material(s, dvec3(0.0), dvec3(4.0));
    const std::uint32_t ball = scene::add_material(s, dvec3(0.7), dvec3(0.0));
    // x = 0: a panel of 8 × 8 cells over [0.25, 0.75]² with a ledge 0.1 deep where cells
    // (2..5, 3..4) are, and four large quads around the panel.
    add_tessellated_quad(s, {0, 0, 0}, {0, 1, 0}, {0, 0, 0.25}, 1, wall);
    add_tessellated_quad(s, {0, 0, 0.75}, {0, 1, 0.75}, {0, 0, 1}, 1, wall);
    add_tessellated_quad(s, {0, 0, 0.25}, {0, 0.25, 0.25}, {0, 0, 0.75}, 1, wall);
    add_tessellated_quad(s, {0, 0.75, 0.25}, {0, 1, 0.25}, {0, 0.75, 0.75}, 1, wall);
    const auto panel = static_cast<std::uint32_t>(s.nodes.size());
    s.nodes.push_back({"panel", static_cast<int>(panel)});
    const auto quad = [&](dvec3 a, dvec3 b, dvec3 c, dvec3 d) { scene::add_quad_to(s, a, b, c, d, wall, panel, panel); };
    const auto at = [](int i) { return 0.25 + i / 16.0; };
    for (int j = 0; j < 8; ++j)
        for (int i = 0; i < 8; ++i)
            if (i < 2 || i > 5 || j < 3 || j > 4)
                quad({0, at(i), at(j)}, {0, at(i + 1), at(j)}, {0, at(i + 1), at(j + 1)}, {0, at(i), at(j + 1)});
    const double y0 = at(2), y1 = at(6), z0 = at(3), z1 = at(5), d = 0.1;
    quad({d, y0, z0}, {d, y1, z0}, {d, y1, z1}, {d, y0, z1});  // front, +x
    quad({0, y0, z1}, {d, y0, z1}, {d, y1, z1}, {0, y1, z1});  // top, +z
    quad({0, y0, z0}, {0, y1, z0}, {d, y1, z0}, {d, y0, z0});  // bottom, −z
    quad({0, y0, z0}, {d, y0, z0}, {d, y0, z1}, {0, y0, z1});  // end, −y
    quad({0, y1, z0}, {0, y1, z1}, {d, y1, z1}, {d, y1, z0});  // end, +y
    add_tessellated_quad(s, {1, 0, 0}, {1, 0, 1}, {1, 1, 0}, 4, wall);
    add_tessellated_quad(s, {0, 0, 0}, {0, 0, 1}, {1, 0, 0}, 4, wall);
    add_tessellated_quad(s, {0, 1, 0}, {1, 1, 0}, {0, 1, 1}, 4, wall);
    add_tessellated_quad(s, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 4, wall);
    add_tessellated_quad(s, {0, 0, 1}, {0, 1, 1}, {1, 0, 1}, 4, lamp);
    const auto ball_node = static_cast<std::uint32_t>(s.nodes.size());
    add_sphere(s, {0.7, 0.5, 0.2}, 0.2, 12, 24, ball, false);  // its south pole on the floor
    scene::finish(s);

    const mesh::Mesh m = mesh::build(s, {1.0, 0.25});
    CHECK(m.split_clusters > 0);
    CHECK(m.moved_clusters == 1);
    std::size_t ball_patches = 0, ball_clusters = 0;
    for (const mesh::Patch& p : m.patches) {
        ball_patches += p.node == ball_node;
        ball_clusters += p.node == ball_node && p.cluster();
    }
    // Its bottom cap is halved until the halves shoot from above the floor, not split into its
    // 15 faces: of the ball's 50 shooters, only one is a lone face (60 with 15 before halving).
    CAPTURE(ball_patches, ball_clusters, m.split_clusters);
    CHECK(ball_patches - ball_clusters <= 2);
    CHECK(ball_patches <= 52);
    formfactor::ReferenceEngine engine(m, formfactor::Settings{64, 7});
    formfactor::ShotResult r;
    std::size_t bad = 0;
    for (std::uint32_t p = 0; p < m.patches.size(); ++p) {
        engine.shoot(p, 0, r);
        const bool ok = std::abs(r.sum() + r.blocked - 1.0) < 1e-9 && r.blocked < 1e-9;
        if (!ok) UNSCOPED_INFO("patch " << p << " (node " << m.patches[p].node << "): F " << r.sum() << ", blocked " << r.blocked);
        bad += !ok;
    }
    CHECK(bad == 0);
}

namespace {

// A square card of side `side` centred at `c`, facing unit `n` (counter-clockwise seen from it),
// in an existing node.
void add_card(scene::Scene& s, dvec3 c, dvec3 n, double side, std::uint32_t material, std::uint32_t node) {
    const dvec3 u = glm::normalize(glm::cross(n, std::abs(n.x) < 0.9 ? dvec3(1, 0, 0) : dvec3(0, 0, 1)));
    const dvec3 v = glm::cross(n, u), h = 0.5 * side * u, k = 0.5 * side * v;
    scene::add_quad_to(s, c - h - k, c + h - k, c + h + k, c - h + k, material, node, node);
}

std::uint32_t add_node(scene::Scene& s, const std::string& name) {
    const auto node = static_cast<std::uint32_t>(s.nodes.size());
    s.nodes.push_back({name, static_cast<int>(node)});
    return node;
}

// Per patch, its elements' (material, node) and count.
std::size_t patches_of_node(const mesh::Mesh& m, std::uint32_t node) {
    std::size_t n = 0;
    for (const mesh::Patch& p : m.patches) n += p.node == node;
    return n;
}

}  // namespace

TEST_CASE("faces apart join one cluster: one material and node, next to it, within the cone, seeing its point",
          "[clusters]") {
    scene::Scene s;
    const std::uint32_t a = scene::add_material(s, dvec3(0.5), dvec3(0.0));
    const std::uint32_t b = scene::add_material(s, dvec3(0.3), dvec3(0.0));
    const std::uint32_t wall = scene::add_material(s, dvec3(0.6), dvec3(0.0));
    const std::uint32_t leaf = scene::add_material(s, dvec3(0.4), dvec3(0.0), true);
    const dvec3 up(0, 0, 1);
    // Four cards 0.2 apart (sharing no edge; within twice their radii, 0.28, of each other), a
    // card of another material beside them, one turned 40° away, one 0.6 off (in the radius, not
    // next to any), one 3 m off: the four are one patch, the others one each.
    const std::uint32_t cards = add_node(s, "cards");
    for (const dvec3 c : {dvec3(0, 0, 0), dvec3(0.2, 0, 0), dvec3(0, 0.2, 0), dvec3(0.2, 0.2, 0)}) add_card(s, c, up, 0.1, a, cards);
    add_card(s, {0.1, -0.15, 0}, up, 0.1, b, cards);
    const double t = glm::radians(40.0);
    add_card(s, {0.1, 0.35, 0}, {0, std::sin(t), std::cos(t)}, 0.1, a, cards);
    add_card(s, {-0.6, 0, 0}, up, 0.1, a, cards);
    add_card(s, {3, 0, 0}, up, 0.1, a, cards);
    // Two cards 0.26 apart on either side of a wall of several patches (x = 5): their joint point
    // would be in the wall, so they stay apart. Two double-sided ones with a small card of their
    // own material between them (x = 8): such siblings (a crown's leaves) do not block, so they
    // join; two one-sided ones with one between them (x = 11) do not (a closed solid's skin).
    const std::uint32_t walled = add_node(s, "walled");
    add_card(s, {4.87, 0, 0}, up, 0.1, a, walled);
    add_card(s, {5.13, 0, 0}, up, 0.1, a, walled);
    scene::add_quad(s, {5, -1, -1}, {5, 1, -1}, {5, 1, 1}, {5, -1, 1}, wall, "wall");
    const std::uint32_t siblings = add_node(s, "siblings");
    add_card(s, {7.87, 0, 0}, up, 0.1, leaf, siblings);
    add_card(s, {8.13, 0, 0}, up, 0.1, leaf, siblings);
    add_card(s, {8, 0, 0.05}, {1, 0, 0}, 0.1, leaf, siblings);
    const std::uint32_t skin = add_node(s, "skin");
    add_card(s, {10.87, 0, 0}, up, 0.1, a, skin);
    add_card(s, {11.13, 0, 0}, up, 0.1, a, skin);
    add_card(s, {11, 0, 0.05}, {1, 0, 0}, 0.1, a, skin);
    scene::finish(s);

    mesh::Settings settings{1.0, 1.0};
    settings.cluster_apart = true;
    const mesh::Mesh m = mesh::build(s, settings);
    settings.cluster_apart = false;
    const mesh::Mesh connected = mesh::build(s, settings);
    CHECK(patches_of_node(connected, cards) == 8);
    CHECK(patches_of_node(m, cards) == 5);  // the four, b's card, the turned one, the two off
    CHECK(patches_of_node(m, walled) == 2);
    CHECK(patches_of_node(m, siblings) == 4);  // both sides: the two facing up joined; the one facing +x apart
    CHECK(patches_of_node(m, skin) == 3);
    CHECK(m.joined_clusters == 3);  // the four cards; the siblings' front and back
    CHECK(connected.joined_clusters == 0);
    for (const mesh::Patch& p : m.patches) {
        if (p.element_count == 4) {  // the four cards: their centroid, their normal, their area
            CHECK(p.node == cards);
            CHECK(p.cluster());
            CHECK(p.area == Approx(0.04));
            CHECK(glm::length(p.centroid - dvec3(0.1, 0.1, 0)) < 2e-5);  // a margin in front
            CHECK(p.centroid.z > 0.0);
            CHECK(glm::dot(p.normal, up) == Approx(1.0));
        }
        for (std::uint32_t k = p.first_element; k < p.first_element + p.element_count; ++k)
            CHECK(m.elements[k].material == m.elements[p.first_element].material);
    }
}

TEST_CASE("emitting cards apart, joined, light a floor within a point source's error of their exact form factors",
          "[clusters]") {
    // Twelve 5 cm lamp cards scattered 1 m above a black floor, facing down, tilted up to 15°: they
    // join into a few clusters, each shooting their light from one point. The floor's irradiance
    // is compared with Σ E · F(element centroid → card), exact point-to-polygon form factors.
    // Each card its own shooter: only the hemicube's error. Joined: each shooter from the mean of
    // its cards' points, a point source for the floor beyond the near field's reach (4 × the
    // cluster's radius). Measured, one-sided cards: 0.26% mean, 0.86% worst apart; 0.52% and 1.9%
    // joined in 9 shooters (one-sided cards between two block their joint point; 3.7% and 8.1%
    // when the point was raised in front of every card's plane, 66% when it lay behind the middle
    // card). Double-sided: 0.32% and 1.2% apart; 2.3% and 5.8% joined in 2 shooters a side (17.7%
    // while the near field let each card's other side, in its plane, take the card's light).
    for (const bool double_sided : {false, true}) {
        scene::Scene s;
        const double E = 2.0;
        const std::uint32_t lamp = scene::add_material(s, dvec3(0.0), dvec3(E), double_sided);
        const std::uint32_t black = scene::add_material(s, dvec3(0.0), dvec3(0.0));
        scene::add_quad(s, {-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}, black, "floor");
        const std::uint32_t cards = add_node(s, "cards");
        std::uint64_t state = 12345;
        const auto next = [&] {  // a fixed sequence in [0, 1)
            state = state * 6364136223846793005ull + 1442695040888963407ull;
            return double(state >> 11) / double(1ull << 53);
        };
        std::vector<mesh::Polygon> lamps;
        for (int i = 0; i < 12; ++i) {  // on a 4 × 3 grid of 10 cm cells, none shading another
            const dvec3 c(-0.15 + 0.1 * (i % 4) + 0.04 * next() - 0.02, -0.1 + 0.1 * (i / 4) + 0.04 * next() - 0.02, 1.0);
            const double tilt = glm::radians(15.0) * next(), azimuth = 2 * M_PI * next();
            const dvec3 n(std::sin(tilt) * std::cos(azimuth), std::sin(tilt) * std::sin(azimuth), -std::cos(tilt));
            add_card(s, c, n, 0.05, lamp, cards);
            const scene::Triangle& t0 = s.triangles[s.triangles.size() - 2];
            const scene::Triangle& t1 = s.triangles.back();
            mesh::Polygon q;
            q.n = 4;
            q.v = {t0.p[0], t0.p[1], t0.p[2], t1.p[2]};
            lamps.push_back(q);
        }
        scene::finish(s);
        const std::size_t sides = double_sided ? 2 : 1;
        for (const bool apart : {false, true}) {
            mesh::Settings settings{0.5, 0.125};
            settings.cluster_apart = apart;
            const mesh::Mesh m = mesh::build(s, settings);
            const std::size_t shooters = patches_of_node(m, cards);
            CAPTURE(double_sided, apart, shooters);
            CHECK((apart ? shooters <= (double_sided ? 4u : 9u) : shooters == 12 * sides));
            formfactor::NearFieldEngine engine(m, std::make_unique<formfactor::ReferenceEngine>(m, formfactor::Settings{256, 7}));
            solve::Progressive solver(m, engine, {1e-6, 100000});
            while (solver.step()) {
            }
            REQUIRE(solver.converged());
            const std::vector<dvec3> H = solver.irradiance(false);
            double worst = 0.0, error = 0.0, total = 0.0;
            for (std::size_t k = 0; k < m.elements.size(); ++k) {
                const mesh::Element& e = m.elements[k];
                if (e.node != 0) continue;  // the floor
                double exact = 0.0;
                for (const mesh::Polygon& q : lamps) exact += E * formfactor::point_to_polygon(e.centroid, e.normal, q);
                worst = std::max(worst, std::abs(H[k].x - exact) / exact);
                error += std::abs(H[k].x - exact) * e.area;
                total += exact * e.area;
            }
            CAPTURE(worst, error / total);
            CHECK(error / total < (!apart ? 0.005 : double_sided ? 0.03 : 0.01));
            CHECK(worst < (!apart ? 0.015 : double_sided ? 0.07 : 0.03));
        }
    }
}
