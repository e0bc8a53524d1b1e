// Welding adaptively refined meshes: elements next to a finer neighbour are cut through its
// hanging vertices (no T-junctions), and those vertices take the coarse edge's interpolated
// radiosity; unrefined meshes weld exactly as before.
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>
#include <functional>
#include <map>
#include <set>
#include <tuple>
#include <utility>
#include <vector>

#include "mesh/mesh.h"
#include "mesh/refine.h"
#include "output/welded_mesh.h"
#include "core/error.h"
#include "test_scenes.h"

using namespace hemirad;
using glm::dvec3;

namespace {

// A planar element from counter-clockwise corners (seen from its front), node 0.
mesh::Element element(std::vector<dvec3> corners) {
    mesh::Element e;
    e.poly.n = static_cast<int>(corners.size());
    dvec3 cross_sum(0.0), sum(0.0);
    for (int i = 0; i < e.poly.n; ++i) {
        e.poly.v[std::size_t(i)] = corners[std::size_t(i)];
        cross_sum += glm::cross(corners[std::size_t(i)], corners[std::size_t((i + 1) % e.poly.n)]);
        sum += corners[std::size_t(i)];
    }
    e.normal = glm::normalize(cross_sum);
    e.area = 0.5 * glm::length(cross_sum);
    e.centroid = sum / double(e.poly.n);
    e.node = 0;
    return e;
}

mesh::Element square(double x0, double y0, double x1, double y1) {
    return element({{x0, y0, 0}, {x1, y0, 0}, {x1, y1, 0}, {x0, y1, 0}});
}

// The 4 children of an element, as adaptive refinement makes them (mesh::split_polygon: edge
// midpoints 0.5·(a + b), a quad's centre 0.25·(v0 + v1 + v2 + v3)).
std::vector<mesh::Element> children(const mesh::Element& e) {
    std::vector<mesh::Element> out;
    for (const mesh::Polygon& p : mesh::split_polygon(e.poly)) {
        mesh::Element c = element(std::vector<dvec3>(p.v.begin(), p.v.begin() + p.n));
        c.node = e.node;
        c.has_twin = e.has_twin;
        c.back = e.back;
        out.push_back(c);
    }
    return out;
}

// A linear congruential step of `state`, its high 24 bits.
std::uint32_t next_lcg(std::uint32_t& state) {
    state = state * 1664525u + 1013904223u;
    return state >> 8;
}

// A third of the elements split in four, `rounds` times over, by the random stream `state`.
std::vector<mesh::Element> split_at_random(std::vector<mesh::Element> elements, int rounds, std::uint32_t& state) {
    for (int round = 0; round < rounds; ++round) {
        std::vector<mesh::Element> next;
        for (const mesh::Element& e : elements) {
            if (next_lcg(state) % 3 == 0) {
                const auto kids = children(e);
                next.insert(next.end(), kids.begin(), kids.end());
            } else {
                next.push_back(e);
            }
        }
        elements = std::move(next);
    }
    return elements;
}

// Replaces elements[i] by its children (appended at the end).
void refine(std::vector<mesh::Element>& elements, std::size_t i) {
    const auto kids = children(elements[i]);
    elements.erase(elements.begin() + std::ptrdiff_t(i));
    elements.insert(elements.end(), kids.begin(), kids.end());
}

// The index of the element with `corner` as its corner 0.
std::size_t element_at(const std::vector<mesh::Element>& elements, dvec3 corner) {
    for (std::size_t i = 0; i < elements.size(); ++i) {
        if (elements[i].poly.v[0] == corner) return i;
    }
    FAIL("no element at corner");
    return 0;
}

output::WeldedNode weld_one(const std::vector<mesh::Element>& elements, const std::vector<double>& values) {
    mesh::Mesh mesh;
    mesh.elements = elements;
    std::vector<dvec3> radiosity;
    for (double v : values) radiosity.emplace_back(v);
    output::WeldedMesh welded = output::weld(1, mesh, radiosity);
    REQUIRE(welded.nodes.size() == 1);
    return welded.nodes[0];
}

output::WeldedNode weld_one(const std::vector<mesh::Element>& elements) {
    return weld_one(elements, std::vector<double>(elements.size(), 1.0));
}

// What is wrong with a planar welded node covering a region of the plane z = 0.
struct Inspection {
    int unmatched_edges = 0;  // interior triangle edges without the reversed edge: T-junctions, cracks
    int repeated_edges = 0;   // a directed edge used twice: overlapping triangles
    int flat = 0;             // zero-area triangles
    int clockwise = 0;        // triangles facing −Z
    int unused_vertices = 0;
    double area = 0.0;
};

Inspection inspect(const output::WeldedNode& node, const std::function<bool(dvec3, dvec3)>& boundary_edge) {
    Inspection r;
    std::multiset<std::pair<std::uint32_t, std::uint32_t>> edges;
    std::vector<bool> used(node.positions.size(), false);
    for (std::size_t t = 0; t < node.triangle_count(); ++t) {
        const std::uint32_t* ids = &node.indices[3 * t];
        const dvec3 cross = glm::cross(node.positions[ids[1]] - node.positions[ids[0]],
                                       node.positions[ids[2]] - node.positions[ids[0]]);
        r.area += 0.5 * cross.z;
        if (0.5 * glm::length(cross) < 1e-12) ++r.flat;
        if (cross.z <= 0.0) ++r.clockwise;
        for (int k = 0; k < 3; ++k) {
            edges.insert({ids[k], ids[(k + 1) % 3]});
            used[ids[k]] = true;
        }
    }
    for (const auto& [a, b] : edges) {
        if (edges.count({a, b}) > 1) ++r.repeated_edges;
        if (edges.count({b, a}) == 0 && !boundary_edge(node.positions[a], node.positions[b])) ++r.unmatched_edges;
    }
    for (bool u : used) r.unused_vertices += u ? 0 : 1;
    return r;
}

// An edge along the outline of the axis-aligned rectangle [x0, x1] × [y0, y1].
std::function<bool(dvec3, dvec3)> rectangle_outline(double x0, double y0, double x1, double y1) {
    return [=](dvec3 p, dvec3 q) {
        return (p.x == q.x && (p.x == x0 || p.x == x1)) || (p.y == q.y && (p.y == y0 || p.y == y1));
    };
}

// The vertices of the node at `p`, exactly.
std::vector<std::size_t> vertices_at(const output::WeldedNode& node, dvec3 p) {
    std::vector<std::size_t> found;
    for (std::size_t i = 0; i < node.positions.size(); ++i) {
        if (node.positions[i] == p) found.push_back(i);
    }
    return found;
}

std::size_t vertex_at(const output::WeldedNode& node, dvec3 p) {
    const auto found = vertices_at(node, p);
    REQUIRE(found.size() == 1);
    return found[0];
}

void check_crack_free(const output::WeldedNode& node, const std::function<bool(dvec3, dvec3)>& outline,
                      double expected_area) {
    const Inspection r = inspect(node, outline);
    CHECK(r.unmatched_edges == 0);
    CHECK(r.repeated_edges == 0);
    CHECK(r.flat == 0);
    CHECK(r.clockwise == 0);
    CHECK(r.unused_vertices == 0);
    CHECK(r.area == Approx(expected_area).epsilon(1e-12));
}

// ---- the welder as it was before T-junctions were handled, for the unrefined comparison ----

struct OldKey {
    std::uint64_t x, y, z;
    bool back;
    bool operator<(const OldKey& o) const { return std::tie(x, y, z, back) < std::tie(o.x, o.y, o.z, o.back); }
};

std::uint64_t bits(double v) {
    v += 0.0;
    std::uint64_t b = 0;
    std::memcpy(&b, &v, sizeof b);
    return b;
}

output::WeldedMesh old_weld(std::size_t node_count, const mesh::Mesh& mesh, const std::vector<dvec3>& radiosity) {
    const double crease_cos = std::cos(40.0 * 3.14159265358979323846 / 180.0);
    struct Acc {
        std::map<OldKey, std::vector<std::uint32_t>> at;
        std::vector<dvec3> cluster, normal_sum, weighted, plain;
        std::vector<double> weight;
        std::vector<std::uint32_t> count;
    };
    std::vector<Acc> acc(node_count);
    output::WeldedMesh out;
    out.nodes.resize(node_count);
    for (std::size_t i = 0; i < mesh.elements.size(); ++i) {
        const mesh::Element& e = mesh.elements[i];
        Acc& a = acc[e.node];
        output::WeldedNode& node = out.nodes[e.node];
        std::uint32_t ids[4];
        for (int k = 0; k < e.poly.n; ++k) {
            const dvec3 p = e.poly.v[std::size_t(k)];
            auto& list = a.at[{bits(p.x), bits(p.y), bits(p.z), e.back}];
            std::uint32_t id = ~0u;
            for (auto it = list.rbegin(); it != list.rend() && id == ~0u; ++it) {  // newest first, as the welder
                if (glm::dot(a.cluster[*it], e.normal) >= crease_cos) id = *it;
            }
            if (id == ~0u) {
                id = std::uint32_t(node.positions.size());
                list.push_back(id);
                node.positions.push_back(p);
                a.cluster.push_back(e.normal);
                a.normal_sum.emplace_back(0.0);
                a.weighted.emplace_back(0.0);
                a.plain.emplace_back(0.0);
                a.weight.push_back(0.0);
                a.count.push_back(0);
            }
            ids[k] = id;
            a.normal_sum[id] += e.area * e.normal;
            a.weighted[id] += e.area * radiosity[i];
            a.weight[id] += e.area;
            a.plain[id] += radiosity[i];
            ++a.count[id];
        }
        auto tri = [&](std::uint32_t x, std::uint32_t y, std::uint32_t z) {
            if (x == y || y == z || x == z) return;
            node.indices.insert(node.indices.end(), {x, y, z});
        };
        tri(ids[0], ids[1], ids[2]);
        if (e.poly.n == 4) tri(ids[0], ids[2], ids[3]);
    }
    for (std::size_t n = 0; n < node_count; ++n) {
        output::WeldedNode& node = out.nodes[n];
        const Acc& a = acc[n];
        for (std::size_t v = 0; v < node.positions.size(); ++v) {
            const double length = glm::length(a.normal_sum[v]);
            node.normals.push_back(length > 0.0 ? a.normal_sum[v] / length : a.cluster[v]);
            node.radiosity.push_back(a.weight[v] > 0.0 ? a.weighted[v] / a.weight[v] : a.plain[v] / double(a.count[v]));
        }
    }
    return out;
}

}  // namespace

TEST_CASE("welded refined: a coarse quad next to a refined quad has no T-junction", "[output]") {
    std::vector<mesh::Element> elements = {square(0, 0, 1, 1), square(1, 0, 2, 1)};
    refine(elements, 1);
    const output::WeldedNode node = weld_one(elements);

    check_crack_free(node, rectangle_outline(0, 0, 2, 1), 2.0);
    CHECK(node.positions.size() == 4 + 7);      // the coarse quad's corners, the children's 7 more
    CHECK(node.triangle_count() == 3 + 4 * 2);  // the coarse quad in 3 (through the midpoint), 4 children
    // The hanging vertex is welded, not duplicated.
    CHECK(vertices_at(node, {1, 0.5, 0}).size() == 1);
}

TEST_CASE("welded refined: two levels of refinement in one corner", "[output]") {
    std::vector<mesh::Element> elements = {square(0, 0, 1, 1), square(1, 0, 2, 1)};
    refine(elements, 1);
    refine(elements, element_at(elements, {1, 0, 0}));  // the child at the coarse quad's lower end
    const output::WeldedNode node = weld_one(elements);

    check_crack_free(node, rectangle_outline(0, 0, 2, 1), 2.0);
    CHECK(vertices_at(node, {1, 0.25, 0}).size() == 1);
    // The coarse quad: 6 outline points, 4 triangles; two children get a hanging vertex each
    // (3 triangles); 4 grandchildren and the last child, 2 each.
    CHECK(node.triangle_count() == 4 + 3 * 2 + 4 * 2 + 2);
}

TEST_CASE("welded refined: a coarse quad between refined ones and a ring of deep refinement", "[output]") {
    SECTION("refined on two opposite sides") {
        std::vector<mesh::Element> elements = {square(0, 0, 1, 1), square(1, 0, 2, 1), square(2, 0, 3, 1)};
        refine(elements, 2);
        refine(elements, 0);
        check_crack_free(weld_one(elements), rectangle_outline(0, 0, 3, 1), 3.0);
    }
    SECTION("3x3 grid refined twice around a coarse centre") {
        std::vector<mesh::Element> elements;
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) elements.push_back(square(i, j, i + 1, j + 1));
        // Refine every square but the centre, then every child touching the centre: each edge
        // of the centre carries three hanging vertices at two depths.
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) {
                if (i != 1 || j != 1) refine(elements, element_at(elements, {i, j, 0}));
            }
        std::vector<dvec3> touching;
        for (const mesh::Element& e : elements) {
            const dvec3 c = e.centroid;
            if (c.x > 0.5 && c.x < 2.5 && c.y > 0.5 && c.y < 2.5 && !(c.x > 1 && c.x < 2 && c.y > 1 && c.y < 2))
                touching.push_back(e.poly.v[0]);
        }
        REQUIRE(touching.size() == 12);
        for (const dvec3& corner : touching) refine(elements, element_at(elements, corner));
        const output::WeldedNode node = weld_one(elements);
        check_crack_free(node, rectangle_outline(0, 0, 3, 3), 9.0);
        // The centre's outline has 4 corners and 12 hanging vertices: 14 triangles.
        std::size_t centre_triangles = 0;
        for (std::size_t t = 0; t < node.triangle_count(); ++t) {
            const dvec3 c = (node.positions[node.indices[3 * t]] + node.positions[node.indices[3 * t + 1]] +
                             node.positions[node.indices[3 * t + 2]]) /
                            3.0;
            if (c.x > 1 && c.x < 2 && c.y > 1 && c.y < 2) ++centre_triangles;
        }
        CHECK(centre_triangles == 14);
        for (double t : {0.25, 0.5, 0.75}) {
            CHECK(vertices_at(node, {1 + t, 1, 0}).size() == 1);
            CHECK(vertices_at(node, {1, 1 + t, 0}).size() == 1);
        }
    }
}

TEST_CASE("welded refined: a coarse triangle next to refined triangles", "[output]") {
    // The unit square as two triangles sharing the diagonal (1, 0)–(0, 1).
    std::vector<mesh::Element> elements = {element({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}),
                                           element({{1, 0, 0}, {1, 1, 0}, {0, 1, 0}})};
    refine(elements, 1);
    SECTION("one level") {
        const output::WeldedNode node = weld_one(elements);
        check_crack_free(node, rectangle_outline(0, 0, 1, 1), 1.0);
        CHECK(node.triangle_count() == 2 + 4);
        CHECK(vertices_at(node, {0.5, 0.5, 0}).size() == 1);
    }
    SECTION("two levels") {
        refine(elements, element_at(elements, {1, 0, 0}));  // the child at (1, 0)
        const output::WeldedNode node = weld_one(elements);
        check_crack_free(node, rectangle_outline(0, 0, 1, 1), 1.0);
        CHECK(vertices_at(node, {0.75, 0.25, 0}).size() == 1);
        // The coarse triangle gets (0.75, 0.25) and (0.5, 0.5) on its diagonal: 3 triangles.
        // The middle child gets (0.75, 0.5): 2; the other two children 1 each; 4 grandchildren.
        CHECK(node.triangle_count() == 3 + 2 + 2 * 1 + 4);
    }
    SECTION("every edge of the coarse triangle refined around, two levels") {
        // A big triangle with the coarse one as its middle child, the three corner children
        // refined twice along the coarse one's edges.
        std::vector<mesh::Element> big = children(element({{0, 0, 0}, {4, 0, 0}, {0, 4, 0}}));
        for (int k = 0; k < 3; ++k) refine(big, 0);  // the three corner children
        // The middle triangle (2,0) (2,2) (0,2) is big[0]; refine the children with an edge on its outline.
        auto on_middle = [](const dvec3& p) {
            return (p.x == 2 && p.y <= 2) || (p.y == 2 && p.x <= 2) || (p.x + p.y == 2);
        };
        std::vector<dvec3> near_middle;
        for (std::size_t i = 1; i < big.size(); ++i) {
            int on = 0;
            for (int k = 0; k < 3; ++k) on += on_middle(big[i].poly.v[std::size_t(k)]) ? 1 : 0;
            if (on >= 2) near_middle.push_back(big[i].poly.v[0]);
        }
        REQUIRE(near_middle.size() == 6);
        for (const dvec3& corner : near_middle) refine(big, element_at(big, corner));
        const output::WeldedNode node = weld_one(big);
        check_crack_free(
            node,
            [](dvec3 p, dvec3 q) {
                return (p.x == 0 && q.x == 0) || (p.y == 0 && q.y == 0) || (p.x + p.y == 4 && q.x + q.y == 4);
            },
            8.0);
    }
}

TEST_CASE("welded refined: both sides of a doubleSided strip are mended apart", "[output]") {
    // The front and, as its reversed twin, the back of each element; the right quad refined on both.
    auto twin = [](mesh::Element e) {
        std::swap(e.poly.v[1], e.poly.v[3]);
        e.normal = -e.normal;
        e.back = true;
        return e;
    };
    std::vector<mesh::Element> front = {square(0, 0, 1, 1), square(1, 0, 2, 1)};
    for (auto& e : front) e.has_twin = true;
    refine(front, 1);
    std::vector<mesh::Element> elements = front;
    std::vector<double> values(front.size(), 1.0);
    for (const auto& e : front) elements.push_back(twin(e));
    values.insert(values.end(), {2, 3, 3, 3, 3});  // the back: coarse 2, children 3
    const output::WeldedNode node = weld_one(elements, values);

    CHECK(node.positions.size() == 2 * 11);
    CHECK(node.triangle_count() == 2 * 11);
    const auto hanging = vertices_at(node, {1, 0.5, 0});
    REQUIRE(hanging.size() == 2);
    for (std::size_t v : hanging) {
        const bool back = node.normals[v].z < 0;
        // Each side interpolates its own coarse edge: (1·1 + 1·0.25) / 1.25 = 1 at both ends on
        // the front, (2·1 + 3·0.25) / 1.25 = 2.2 on the back.
        CHECK(node.radiosity[v].x == Approx(back ? 2.2 : 1.0));
    }
    // Every triangle faces its side's way.
    for (std::size_t t = 0; t < node.triangle_count(); ++t) {
        const std::uint32_t* ids = &node.indices[3 * t];
        const dvec3 n = glm::cross(node.positions[ids[1]] - node.positions[ids[0]],
                                   node.positions[ids[2]] - node.positions[ids[0]]);
        CHECK(glm::dot(n, node.normals[ids[0]]) > 0.0);
    }
}

TEST_CASE("welded refined: random refinement of meshed faces stays crack free", "[output]") {
    // A trapezoid (a bilinear lattice of quads) and a lone triangle (a lattice of triangles),
    // both facing +Z, each its own node; a third of the elements split, three times over.
    scene::Scene s;
    const std::uint32_t grey = scene::add_material(s, dvec3(0.5), dvec3(0.0));
    const std::vector<dvec3> trapezoid = {{0, 0, 0}, {3, 0, 0}, {2.5, 1.7, 0}, {0.4, 1.7, 0}};
    const std::vector<dvec3> lone = {{0, 0, 1}, {2.3, 0.4, 1}, {0.7, 1.9, 1}};
    scene::add_quad(s, trapezoid[0], trapezoid[1], trapezoid[2], trapezoid[3], grey, "trapezoid");
    test::add_triangle(s, lone[0], lone[1], lone[2], grey, "triangle");
    scene::finish(s);
    const mesh::Mesh built = mesh::build(s, mesh::Settings{0.6, 0.3});
    std::vector<mesh::Element> elements = built.elements;
    std::uint32_t state = 12345;
    const auto next_random = [&state] { return next_lcg(state); };
    elements = split_at_random(std::move(elements), 3, state);
    std::vector<dvec3> radiosity;
    for (std::size_t i = 0; i < elements.size(); ++i) radiosity.emplace_back(double(next_random() % 100) / 100.0);
    mesh::Mesh refined;
    refined.elements = elements;
    const output::WeldedMesh welded = output::weld(2, refined, radiosity);

    // On the outline: both ends on one side of the face's polygon (to rounding).
    auto outline_of = [](std::vector<dvec3> corners) {
        return [corners](dvec3 p, dvec3 q) {
            for (std::size_t k = 0; k < corners.size(); ++k) {
                const dvec3 a = corners[k], b = corners[(k + 1) % corners.size()];
                auto on = [&](dvec3 x) {
                    return glm::length(glm::cross(b - a, x - a)) <= 1e-12 * glm::dot(b - a, b - a);
                };
                if (on(p) && on(q)) return true;
            }
            return false;
        };
    };
    double areas[2] = {0.0, 0.0};
    for (const mesh::Element& e : elements) areas[e.node] += e.area;
    for (std::uint32_t n = 0; n < 2; ++n) {
        INFO("node " << n);
        const output::WeldedNode& node = welded.nodes[n];
        check_crack_free(node, outline_of(n == 0 ? trapezoid : lone), areas[n]);
        // Some elements really were cut through hanging vertices.
        std::size_t drawn = 0;
        for (const mesh::Element& e : elements) drawn += e.node == n ? std::size_t(e.poly.n - 2) : 0;
        CHECK(node.triangle_count() > drawn);
    }
}

TEST_CASE("welded refined: a hanging vertex takes the mean of its coarse edge's ends", "[output]") {
    std::vector<mesh::Element> elements = {square(0, 0, 1, 1), square(1, 0, 2, 1)};
    refine(elements, 1);
    // Coarse 1; children (1,0) 2, (1.5,0) 3, (1.5,0.5) 4, (1,0.5) 5.
    const std::vector<double> values = {1, 2, 3, 4, 5};
    SECTION("one level") {
        const output::WeldedNode node = weld_one(elements, values);
        const double low = node.radiosity[vertex_at(node, {1, 0, 0})].x;
        const double high = node.radiosity[vertex_at(node, {1, 1, 0})].x;
        CHECK(low == Approx((1 * 1.0 + 2 * 0.25) / 1.25));
        CHECK(high == Approx((1 * 1.0 + 5 * 0.25) / 1.25));
        const std::size_t hanging = vertex_at(node, {1, 0.5, 0});
        CHECK(node.radiosity[hanging].x == Approx(0.5 * (low + high)));
        // Not the children's mean (2 + 5) / 2 it would otherwise have.
        CHECK(node.radiosity[hanging].x != Approx(3.5));
        // Every channel, and the normal, follow.
        CHECK(node.radiosity[hanging].z == Approx(0.5 * (low + high)));
        CHECK(node.normals[hanging] == dvec3(0, 0, 1));
    }
    SECTION("nested: a hanging vertex on a hanging vertex's half edge") {
        std::vector<mesh::Element> deeper = elements;
        std::vector<double> deeper_values = {1, 3, 4, 5, 6, 7, 8, 9};  // the (1,0) child replaced by 4
        refine(deeper, element_at(deeper, {1, 0, 0}));
        REQUIRE(deeper.size() == deeper_values.size());
        const output::WeldedNode node = weld_one(deeper, deeper_values);
        const double low = node.radiosity[vertex_at(node, {1, 0, 0})].x;
        const double high = node.radiosity[vertex_at(node, {1, 1, 0})].x;
        const double mid = node.radiosity[vertex_at(node, {1, 0.5, 0})].x;
        const double quarter = node.radiosity[vertex_at(node, {1, 0.25, 0})].x;
        CHECK(mid == Approx(0.5 * (low + high)));
        CHECK(quarter == Approx(0.5 * (low + mid)));  // linear along the coarse edge: 3/4 low + 1/4 high
        CHECK(quarter == Approx(0.75 * low + 0.25 * high));
        // (1.25, 0.5) hangs on the edge (1, 0.5)–(1.5, 0.5) of the child above the grandchildren.
        const double right = node.radiosity[vertex_at(node, {1.5, 0.5, 0})].x;
        CHECK(node.radiosity[vertex_at(node, {1.25, 0.5, 0})].x == Approx(0.5 * (mid + right)));
    }
}

TEST_CASE("welded refined: a refined wall across a crease splits the coarse floor's edge", "[output]") {
    // Floor facing +Z and wall facing +Y meet at 90° along y = 0; the wall is refined.
    std::vector<mesh::Element> elements = {element({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}),
                                           element({{0, 0, 0}, {0, 0, 1}, {1, 0, 1}, {1, 0, 0}})};
    refine(elements, 1);
    const output::WeldedNode node = weld_one(elements, {1, 2, 2, 2, 2});
    // Each side keeps its own vertex at the edge's midpoint (no blur across the crease)...
    const auto at_mid = vertices_at(node, {0.5, 0, 0});
    REQUIRE(at_mid.size() == 2);
    // ...and the floor is cut there: 3 triangles, none spanning the whole edge.
    std::size_t floor_triangles = 0;
    for (std::size_t t = 0; t < node.triangle_count(); ++t) {
        const std::uint32_t* ids = &node.indices[3 * t];
        const dvec3 n = glm::cross(node.positions[ids[1]] - node.positions[ids[0]],
                                   node.positions[ids[2]] - node.positions[ids[0]]);
        if (n.z > 0) ++floor_triangles;
    }
    CHECK(floor_triangles == 3);
    for (std::size_t v : at_mid) {
        if (node.normals[v].z > 0.5)
            CHECK(node.radiosity[v].x == Approx(1.0));  // the floor's, interpolated
        else
            CHECK(node.radiosity[v].x == Approx(2.0));
    }
}

TEST_CASE("welded refined: an unrefined mesh welds exactly as before", "[output]") {
    scene::Scene base;
    const std::uint32_t grey = scene::add_material(base, dvec3(0.5), dvec3(0.0));
    const std::uint32_t sheet = scene::add_material(base, dvec3(0.3), dvec3(0.0), true);
    scene::Scene s = test::closed_box(
        dvec3(2.0, 1.0, 1.5), [&](int) { return grey; }, base);
    test::add_triangle(s, {0, 0, 3}, {2, 0.2, 3}, {0.3, 1.7, 3.5}, grey, "slanted triangle");
    test::add_triangle(s, {0, 0, 5}, {1, 0, 5}, {0, 1, 5}, sheet, "two-sided triangle");
    scene::add_quad(s, {0, 0, 6}, {2, 0, 6}, {2.5, 1, 6}, {0.5, 1, 6}, sheet, "two-sided quad");
    scene::finish(s);
    const mesh::Mesh m = mesh::build(s, mesh::Settings{0.5, 0.25});
    REQUIRE(m.elements.size() > 100);
    std::vector<dvec3> radiosity;
    for (std::size_t i = 0; i < m.elements.size(); ++i) radiosity.emplace_back(0.01 * double(i % 37), 1.0, 0.5);

    const output::WeldedMesh welded = output::weld(s.nodes.size(), m, radiosity);
    const output::WeldedMesh expected = old_weld(s.nodes.size(), m, radiosity);
    REQUIRE(welded.nodes.size() == expected.nodes.size());
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        INFO("node " << n);
        const output::WeldedNode& got = welded.nodes[n];
        const output::WeldedNode& want = expected.nodes[n];
        CHECK(got.positions == want.positions);
        CHECK(got.indices == want.indices);
        CHECK(got.radiosity == want.radiosity);
        CHECK(got.normals == want.normals);
    }
    // Independently of the reference: a box face of nu × nv quads is 2·nu·nv triangles on
    // (nu + 1)(nv + 1) lattice points; the 2 × 1 face x0 (y ∈ [0, 1], z ∈ [0, 1.5]) is 4 × 6.
    std::size_t face_elements = 0;
    for (const mesh::Element& e : m.elements) face_elements += e.node == 0 ? 1 : 0;
    CHECK(face_elements == 4 * 6);
    CHECK(welded.nodes[0].triangle_count() == 2 * 4 * 6);
    CHECK(welded.nodes[0].positions.size() == 5 * 7);
}

TEST_CASE("welded refined: one weld carries any per-element values to its vertices as welding them would",
          "[output]") {
    // A randomly refined mesh (hanging vertices, nested ones) beside a box's crease: weld's own
    // values for several quantities are vertex_values' on one weld, bit for bit.
    scene::Scene s;
    const std::uint32_t grey = scene::add_material(s, dvec3(0.5), dvec3(0.0));
    scene::add_quad(s, {0, 0, 0}, {3, 0, 0}, {3, 0, 2}, {0, 0, 2}, grey, "floor");
    scene::add_quad(s, {0, 0, 0}, {0, 0, 2}, {0, 2, 2}, {0, 2, 0}, grey, "wall");  // a crease
    test::add_triangle(s, {0, 1, 1}, {2.3, 1.4, 1}, {0.7, 1.9, 1}, grey, "triangle");
    scene::finish(s);
    const mesh::Mesh built = mesh::build(s, mesh::Settings{0.6, 0.3});
    std::vector<mesh::Element> elements = built.elements;
    std::uint32_t state = 777;
    const auto next_random = [&state] { return next_lcg(state); };
    elements = split_at_random(std::move(elements), 4, state);
    elements[elements.size() / 2].area = 0.0;  // a vertex weighed by no area takes the plain mean
    mesh::Mesh refined;
    refined.elements = elements;
    const auto random_values = [&] {
        std::vector<dvec3> v;
        for (std::size_t i = 0; i < elements.size(); ++i)
            v.emplace_back(double(next_random() % 1000) / 7.0, double(next_random() % 100) / 3.0, 1e-3 * double(i));
        return v;
    };
    const output::WeldedMesh one = output::weld(s.nodes.size(), refined, random_values());
    std::size_t halfway = 0;
    for (const output::WeldedNode& n : one.nodes) halfway += n.halfway.size();
    CHECK(halfway > 10);  // the case this is for: hanging vertices set from their edges
    for (int quantity = 0; quantity < 3; ++quantity) {
        const std::vector<dvec3> values = random_values();
        const output::WeldedMesh expected = output::weld(s.nodes.size(), refined, values);
        const output::VertexValues got = output::vertex_values(one, refined, values);
        REQUIRE(got.size() == expected.nodes.size());
        for (std::size_t n = 0; n < got.size(); ++n) {
            REQUIRE(got[n].size() == expected.nodes[n].radiosity.size());
            for (std::size_t v = 0; v < got[n].size(); ++v)
                REQUIRE(std::memcmp(&got[n][v], &expected.nodes[n].radiosity[v], sizeof(dvec3)) == 0);
        }
    }
    CHECK_THROWS_AS(output::vertex_values(one, refined, std::vector<dvec3>(3)), InternalError);
}
