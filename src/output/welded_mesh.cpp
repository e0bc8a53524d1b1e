// Builds the welded, per-vertex-radiosity triangle mesh shared by the baked glTF and the renderer.
#include "output/welded_mesh.h"

#include <fmt/format.h>

#include <cmath>
#include <cstring>
#include <unordered_map>

#include "core/error.h"
#include "core/rng.h"

namespace hemirad::output {
namespace {

// Elements whose normals differ by less than this share vertices (smooth shading); at a
// sharper angle, such as a box edge, each side keeps its own. Tessellated curved surfaces
// (a 16-segment cylinder turns 22.5° per facet) then shade smoothly while 45° chamfers and
// 90° corners stay crisp.
constexpr double kCreaseAngle = 40.0 * 3.14159265358979323846 / 180.0;  // radians
const double kCreaseCos = std::cos(kCreaseAngle);

std::uint64_t bits_of(double v) {
    v += 0.0;  // −0 and +0 are the same position
    std::uint64_t b = 0;
    std::memcpy(&b, &v, sizeof b);
    return b;
}

struct PositionKey {
    std::uint64_t x, y, z;
    bool back;
    bool operator==(const PositionKey& o) const { return x == o.x && y == o.y && z == o.z && back == o.back; }
};

struct PositionKeyHash {
    std::size_t operator()(const PositionKey& k) const {
        return static_cast<std::size_t>(mix64(k.x ^ mix64(k.y ^ mix64(k.z ^ (k.back ? 1u : 0u)))));
    }
};

// Collects one node's vertices and triangles as its elements are added.
class NodeWelder {
public:
    void add(const mesh::Element& element, const glm::dvec3& radiosity) {
        std::uint32_t ids[4];
        for (int i = 0; i < element.poly.n; ++i) {
            ids[i] = vertex(element.poly.v[i], element.normal, element.back);
            accumulate(ids[i], element, radiosity);
        }
        triangle(ids[0], ids[1], ids[2], element.has_twin);
        if (element.poly.n == 4) triangle(ids[0], ids[2], ids[3], element.has_twin);
    }

    WeldedNode finish() {
        node_.radiosity.resize(node_.positions.size());
        node_.normals.resize(node_.positions.size());
        for (std::size_t v = 0; v < node_.positions.size(); ++v) {
            const double length = glm::length(normal_sum_[v]);
            node_.normals[v] = length > 0.0 ? normal_sum_[v] / length : cluster_normal_[v];
            // Zero-area elements carry no weight; a vertex touched only by such gets their mean.
            node_.radiosity[v] = weight_[v] > 0.0 ? weighted_sum_[v] / weight_[v] : plain_sum_[v] / double(count_[v]);
        }
        return std::move(node_);
    }

private:
    // The vertex at `p` on this side with a normal matching `normal`, created when none is.
    std::uint32_t vertex(const glm::dvec3& p, const glm::dvec3& normal, bool back) {
        const PositionKey key{bits_of(p.x), bits_of(p.y), bits_of(p.z), back};
        const auto [it, inserted] = first_at_.try_emplace(key, kNone);
        for (std::uint32_t v = it->second; v != kNone; v = next_at_same_position_[v]) {
            if (glm::dot(cluster_normal_[v], normal) >= kCreaseCos) return v;
        }
        const auto id = static_cast<std::uint32_t>(node_.positions.size());
        node_.positions.push_back(p);
        cluster_normal_.push_back(normal);
        normal_sum_.emplace_back(0.0);
        next_at_same_position_.push_back(it->second);
        it->second = id;
        weighted_sum_.emplace_back(0.0);
        weight_.push_back(0.0);
        plain_sum_.emplace_back(0.0);
        count_.push_back(0);
        return id;
    }

    void accumulate(std::uint32_t v, const mesh::Element& element, const glm::dvec3& radiosity) {
        const double area = element.area;
        normal_sum_[v] += area * element.normal;
        weighted_sum_[v] += area * radiosity;
        weight_[v] += area;
        plain_sum_[v] += radiosity;
        ++count_[v];
    }

    void triangle(std::uint32_t a, std::uint32_t b, std::uint32_t c, bool has_twin) {
        if (a == b || b == c || a == c) return;  // collapsed: nothing to draw, and validators warn
        node_.indices.insert(node_.indices.end(), {a, b, c});
        node_.has_twin.push_back(has_twin ? 1 : 0);
    }

    static constexpr std::uint32_t kNone = ~std::uint32_t{0};
    WeldedNode node_;
    std::unordered_map<PositionKey, std::uint32_t, PositionKeyHash> first_at_;
    std::vector<std::uint32_t> next_at_same_position_;  // vertices on different sides of a crease
    std::vector<glm::dvec3> cluster_normal_;            // the first element's: what others match
    std::vector<glm::dvec3> normal_sum_;                // Σ area × normal
    std::vector<glm::dvec3> weighted_sum_;              // Σ area × B
    std::vector<double> weight_;                        // Σ area
    std::vector<glm::dvec3> plain_sum_;
    std::vector<std::uint32_t> count_;
};

}  // namespace

WeldedMesh weld(std::size_t node_count, const mesh::Mesh& mesh, const std::vector<glm::dvec3>& radiosity) {
    if (radiosity.size() != mesh.elements.size()) {
        throw InternalError(
            fmt::format("output: {} radiosity values for {} elements", radiosity.size(), mesh.elements.size()));
    }
    std::vector<NodeWelder> welders(node_count);
    for (std::size_t i = 0; i < mesh.elements.size(); ++i) {
        const mesh::Element& element = mesh.elements[i];
        if (element.node >= node_count) {
            throw InternalError(fmt::format("output: element {} names node {} of {}", i, element.node, node_count));
        }
        welders[element.node].add(element, radiosity[i]);
    }
    WeldedMesh welded;
    welded.nodes.reserve(node_count);
    for (NodeWelder& welder : welders) welded.nodes.push_back(welder.finish());
    return welded;
}

}  // namespace hemirad::output
