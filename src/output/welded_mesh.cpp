// Builds the welded, per-vertex-radiosity triangle mesh shared by the baked glTF and the renderer.
#include "output/welded_mesh.h"

#include <fmt/format.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <unordered_map>

#include "core/error.h"
#include "core/parallel.h"
#include "core/rng.h"

namespace hemirad::output {
namespace {

// Elements whose normals differ by less than the crease angle (mesh::kCreaseAngle) share
// vertices (smooth shading); at a sharper angle, such as a box edge, each side keeps its own.
const double kCreaseCos = std::cos(mesh::kCreaseAngle);

// Hanging vertices are looked for this many halvings deep into an element edge; refinement
// never goes near it (each level halves the edge), it only bounds the recursion.
constexpr int kMaxHangingDepth = 48;

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

std::uint64_t position_hash(const PositionKey& k) {
    return mix64(k.x ^ mix64(k.y ^ mix64(k.z ^ (k.back ? 1u : 0u))));
}

struct PositionKeyHash {
    std::size_t operator()(const PositionKey& k) const { return static_cast<std::size_t>(position_hash(k)); }
};

// Collects one node's vertices as its elements are added; finish() then triangulates them,
// once every vertex is known, so that an element's edges can pick up the hanging vertices
// (T-junctions) of finer neighbours added after it.
class NodeWelder {
public:
    void add(const mesh::Element& element, std::uint32_t index) {
        Placed placed{&element, index, {}};
        for (int i = 0; i < element.poly.n; ++i) {
            placed.ids[i] = vertex(element.poly.v[i], element.normal, element.back);
            normal_sum_[placed.ids[i]] += element.area * element.normal;
            corners_.push_back({placed.ids[i], index});
        }
        placed_.push_back(placed);
    }

    WeldedNode finish() {
        build_filter();
        for (const Placed& placed : placed_) triangulate(placed);
        node_.normals.resize(node_.positions.size());
        for (std::size_t v = 0; v < node_.positions.size(); ++v) {
            const double length = glm::length(normal_sum_[v]);
            node_.normals[v] = length > 0.0 ? normal_sum_[v] / length : cluster_normal_[v];
        }
        apply_constraints();
        record_corners();
        return std::move(node_);
    }

private:
    static constexpr std::uint32_t kNone = ~std::uint32_t{0};

    struct Placed {
        const mesh::Element* element;
        std::uint32_t index;  // in the mesh
        std::uint32_t ids[4];
    };

    // A point of an element's outline: a corner or a hanging vertex on one of its edges.
    // `edges` has bit e set when the point lies on element edge e (v[e] → v[e+1]); three
    // points of the outline are collinear exactly when they share a bit (the element is
    // strictly convex), which the triangulation uses instead of a rounding-prone predicate.
    struct OutlinePoint {
        std::uint32_t id;
        unsigned edges;
    };

    static PositionKey key_of(const glm::dvec3& p, bool back) {
        return {bits_of(p.x), bits_of(p.y), bits_of(p.z), back};
    }

    // Exactly how refinement makes its midpoints, so a neighbour's is found bit for bit.
    glm::dvec3 midpoint(std::uint32_t a, std::uint32_t b) const {
        return 0.5 * (node_.positions[a] + node_.positions[b]);
    }

    // The vertex at `p` on this side with a normal matching `normal`, created when none is.
    std::uint32_t vertex(const glm::dvec3& p, const glm::dvec3& normal, bool back) {
        const PositionKey key = key_of(p, back);
        const auto [it, inserted] = first_at_.try_emplace(key, kNone);
        for (std::uint32_t v = it->second; v != kNone; v = next_at_same_position_[v]) {
            if (glm::dot(cluster_normal_[v], normal) >= kCreaseCos) return v;
        }
        const auto id = static_cast<std::uint32_t>(node_.positions.size());
        node_.positions.push_back(p);
        cluster_normal_.push_back(normal);
        back_.push_back(back ? 1 : 0);
        normal_sum_.emplace_back(0.0);
        next_at_same_position_.push_back(it->second);
        it->second = id;
        return id;
    }

    // The vertex a finer neighbour has at `p`, the midpoint of an element edge, in the crease
    // cluster of `normal`; kNone when no vertex of this side is there (no T-junction). When
    // only vertices of other clusters are there (the neighbour across a crease was refined),
    // this cluster gets its own vertex at that point, so the edge is split there too.
    std::uint32_t hanging_vertex(const glm::dvec3& p, const glm::dvec3& normal, bool back) {
        const PositionKey key = key_of(p, back);
        if (!maybe_vertex_at(key)) return kNone;
        const auto it = first_at_.find(key);
        if (it == first_at_.end()) return kNone;
        for (std::uint32_t v = it->second; v != kNone; v = next_at_same_position_[v]) {
            if (glm::dot(cluster_normal_[v], normal) >= kCreaseCos) return v;
        }
        const glm::dvec3 at = node_.positions[it->second];  // vertex() grows positions
        return vertex(at, normal, back);
    }

    // A filter of the vertex positions (a one-word-per-probe Bloom filter, 8 bits per position,
    // about 5% false positives) so that the midpoint of every element edge can be looked for
    // without a hash map miss each time: in an unrefined mesh none is there, and the map's
    // misses, scattered over a million vertices, would double the time weld takes.
    void build_filter() {
        std::size_t words = 1;
        while (words * 8 < node_.positions.size()) words *= 2;
        filter_.assign(words, 0);
        for (std::size_t v = 0; v < node_.positions.size(); ++v) {
            const std::uint64_t h = position_hash(key_of(node_.positions[v], back_[v] != 0));
            filter_[h & (words - 1)] |= filter_bits(h);
        }
    }

    static std::uint64_t filter_bits(std::uint64_t h) {
        return (std::uint64_t{1} << ((h >> 52) & 63)) | (std::uint64_t{1} << ((h >> 58) & 63));
    }

    bool maybe_vertex_at(const PositionKey& key) const {
        const std::uint64_t h = position_hash(key);
        const std::uint64_t bits = filter_bits(h);
        return (filter_[h & (filter_.size() - 1)] & bits) == bits;
    }

    void triangle(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
        if (a == b || b == c || a == c) return;  // collapsed: nothing to draw, and validators warn
        node_.indices.insert(node_.indices.end(), {a, b, c});
        node_.element.push_back(element_);
    }

    // An element's triangles: a quad as two (v0 v1 v2, v0 v2 v3), a triangle as itself, as
    // long as no finer neighbour left a hanging vertex on its edges; otherwise its outline
    // with those vertices, cut into triangles by ear clipping (see clip_ears).
    void triangulate(const Placed& placed) {
        const mesh::Element& e = *placed.element;
        element_ = placed.index;
        const int n = e.poly.n;
        const std::uint32_t* ids = placed.ids;
        // Fast path: no vertex may be at any edge's midpoint (the four filter probes are
        // independent, so their memory accesses overlap): the element's old triangles.
        bool maybe_hanging = false;
        for (int i = 0; i < n; ++i) {
            maybe_hanging |= maybe_vertex_at(key_of(midpoint(ids[i], ids[(i + 1) % n]), e.back));
        }
        bool distinct = true;  // a collapsed element draws at most its one proper triangle, as ever
        for (int i = 0; i < n; ++i) {
            for (int j = i + 1; j < n; ++j) distinct = distinct && ids[i] != ids[j];
        }
        if (maybe_hanging && distinct) {
            outline_.clear();
            for (int i = 0; i < n; ++i) {
                const int prev = (i + n - 1) % n;
                outline_.push_back({ids[i], (1u << prev) | (1u << i)});
                split_edge(ids[i], ids[(i + 1) % n], 1u << i, e, 0);
            }
            if (outline_.size() > std::size_t(n)) {
                clip_ears();
                return;
            }
        }
        triangle(ids[0], ids[1], ids[2]);
        if (n == 4) triangle(ids[0], ids[2], ids[3]);
    }

    // Appends the hanging vertices strictly inside the edge a → b, in order from a: the one at
    // the midpoint, if any, and recursively those inside its two halves.
    void split_edge(std::uint32_t a, std::uint32_t b, unsigned edge, const mesh::Element& e, int depth) {
        if (depth >= kMaxHangingDepth) return;
        const std::uint32_t m = hanging_vertex(midpoint(a, b), e.normal, e.back);
        if (m == kNone || m == a || m == b) return;  // a too short edge rounds onto its end
        constrain(m, a, b);
        split_edge(a, m, edge, e, depth + 1);
        outline_.push_back({m, edge});
        split_edge(m, b, edge, e, depth + 1);
    }

    // Hanging vertex m lies halfway along a → b: the coarse side draws the edge as a line
    // from a to b, so m must take the mean of their values. When several edges claim m (it
    // can only be the midpoint of collinear ones), the longest (coarsest) wins.
    void constrain(std::uint32_t m, std::uint32_t a, std::uint32_t b) {
        if (constraint_.size() <= m) constraint_.resize(node_.positions.size(), {kNone, kNone, 0.0});
        const double length2 =
            glm::dot(node_.positions[b] - node_.positions[a], node_.positions[b] - node_.positions[a]);
        Constraint& c = constraint_[m];
        if (c.a == kNone) constrained_.push_back(m);
        if (c.a == kNone || length2 > c.length2) c = {a, b, length2};
    }

    // Cuts the outline (convex, counter-clockwise, with 180° points on its edges) into
    // triangles without zero-area ones and without new vertices: repeatedly cut off the ear
    // (prev, p, next) at a point p that is a true corner of what is left, choosing the ear
    // with the shortest new edge prev–next (well-shaped triangles; for one midpoint this is
    // the fan from it), skipping an ear whose removal would leave only collinear points (the
    // apex of a triangle whose other points are all on one side). A convex outline always
    // has such an ear, and its last three points are never collinear. O(k²) for k points,
    // k = corners + hanging vertices: small, and only refined elements' neighbours get here.
    void clip_ears() {
        std::size_t size = outline_.size();
        int on_edge[4] = {0, 0, 0, 0};  // points left on each element edge
        for (const OutlinePoint& p : outline_) {
            for (int e = 0; e < 4; ++e) on_edge[e] += (p.edges >> e) & 1u;
        }
        while (size > 3) {
            std::size_t best = size;
            double best_length2 = std::numeric_limits<double>::infinity();
            for (std::size_t i = 0; i < size; ++i) {
                const OutlinePoint& prev = outline_[(i + size - 1) % size];
                const OutlinePoint& p = outline_[i];
                const OutlinePoint& next = outline_[(i + 1) % size];
                if (prev.edges & p.edges & next.edges) continue;  // a 180° point: flat ear
                bool rest_flat = false;
                for (int e = 0; e < 4; ++e) {
                    rest_flat = rest_flat || on_edge[e] - int((p.edges >> e) & 1u) == int(size) - 1;
                }
                if (rest_flat) continue;
                const glm::dvec3 d = node_.positions[next.id] - node_.positions[prev.id];
                const double length2 = glm::dot(d, d);
                if (length2 < best_length2) {
                    best = i;
                    best_length2 = length2;
                }
            }
            if (best == size) break;  // only for an element that is not convex: draw no more
            const OutlinePoint p = outline_[best];
            triangle(outline_[(best + size - 1) % size].id, p.id, outline_[(best + 1) % size].id);
            for (int e = 0; e < 4; ++e) on_edge[e] -= int((p.edges >> e) & 1u);
            outline_.erase(outline_.begin() + std::ptrdiff_t(best));
            --size;
        }
        if (size == 3) triangle(outline_[0].id, outline_[1].id, outline_[2].id);
    }

    // Sets each hanging vertex's normal to the normalized mean of its edge's ends', after the ends'
    // own constraints (a nested hanging vertex's end may be hanging itself), and records it in
    // `halfway` in that order, so that vertex_values gives it the mean of their values: then the
    // shading is continuous across the T-junction.
    void apply_constraints() {
        if (constrained_.empty()) return;
        std::vector<std::uint8_t> state(node_.positions.size(), 0);  // 0 to do, 1 in progress, 2 done
        std::vector<std::uint32_t> stack;
        auto pending = [&](std::uint32_t v) {
            return v < constraint_.size() && constraint_[v].a != kNone && state[v] == 0;
        };
        for (std::uint32_t root : constrained_) {
            if (state[root] != 0) continue;
            stack.push_back(root);
            while (!stack.empty()) {
                const std::uint32_t v = stack.back();
                const Constraint& c = constraint_[v];
                if (state[v] == 2) {
                    stack.pop_back();
                } else if (state[v] == 0) {
                    state[v] = 1;  // ends first; an end in progress (a cycle) keeps its value
                    if (pending(c.a)) stack.push_back(c.a);
                    if (pending(c.b)) stack.push_back(c.b);
                } else {
                    node_.halfway.push_back({v, c.a, c.b});  // its value: vertex_values
                    const glm::dvec3 normal = node_.normals[c.a] + node_.normals[c.b];
                    const double length = glm::length(normal);
                    if (length > 0.0) node_.normals[v] = normal / length;
                    state[v] = 2;
                    stack.pop_back();
                }
            }
        }
    }

    // Each vertex's elements, in the order accumulate() took them (a stable counting sort of
    // corners_ by vertex), for vertex_values.
    void record_corners() {
        const std::size_t vertices = node_.positions.size();
        node_.corner_start.assign(vertices + 1, 0);
        for (const Corner& c : corners_) ++node_.corner_start[c.vertex + 1];
        for (std::size_t v = 0; v < vertices; ++v) node_.corner_start[v + 1] += node_.corner_start[v];
        node_.corner_element.resize(corners_.size());
        std::vector<std::uint32_t> next(node_.corner_start.begin(), node_.corner_start.end() - 1);
        for (const Corner& c : corners_) node_.corner_element[next[c.vertex]++] = c.element;
        corners_.clear();
        corners_.shrink_to_fit();
    }

    struct Corner {
        std::uint32_t vertex, element;
    };

    struct Constraint {
        std::uint32_t a, b;  // the edge m halves
        double length2;
    };

    WeldedNode node_;
    std::uint32_t element_ = 0;  // the element being triangulated
    std::unordered_map<PositionKey, std::uint32_t, PositionKeyHash> first_at_;
    std::vector<std::uint32_t> next_at_same_position_;  // vertices on different sides of a crease
    std::vector<glm::dvec3> cluster_normal_;            // the first element's: what others match
    std::vector<std::uint8_t> back_;                    // the side: part of the position's key
    std::vector<glm::dvec3> normal_sum_;                // Σ area × normal
    std::vector<std::uint64_t> filter_;       // see build_filter
    std::vector<Placed> placed_;              // the elements, in order, with their corners' vertices
    std::vector<Corner> corners_;             // every corner, in the order accumulated
    std::vector<OutlinePoint> outline_;       // scratch: the element being triangulated
    std::vector<Constraint> constraint_;      // per vertex; empty until a hanging vertex is found
    std::vector<std::uint32_t> constrained_;  // the hanging vertices, in the order found
};

}  // namespace

WeldedMesh weld(std::size_t node_count, const mesh::Mesh& mesh, const std::vector<glm::dvec3>& radiosity,
                const VertexValues* vertex_values) {
    if (radiosity.size() != mesh.elements.size()) {
        throw InternalError(
            fmt::format("output: {} radiosity values for {} elements", radiosity.size(), mesh.elements.size()));
    }
    // Each node's elements in mesh order, then the nodes welded on the host's threads.
    std::vector<std::uint32_t> count(node_count + 1, 0);
    for (std::size_t i = 0; i < mesh.elements.size(); ++i) {
        const mesh::Element& element = mesh.elements[i];
        if (element.node >= node_count) {
            throw InternalError(fmt::format("output: element {} names node {} of {}", i, element.node, node_count));
        }
        ++count[element.node + 1];
    }
    for (std::size_t n = 0; n < node_count; ++n) count[n + 1] += count[n];
    std::vector<std::uint32_t> of_node(mesh.elements.size());
    {
        std::vector<std::uint32_t> next(count.begin(), count.end() - 1);
        for (std::size_t i = 0; i < mesh.elements.size(); ++i)
            of_node[next[mesh.elements[i].node]++] = static_cast<std::uint32_t>(i);
    }
    WeldedMesh welded;
    welded.nodes.resize(node_count);
    parallel::for_each(node_count, 1, [&](std::size_t n) {
        NodeWelder welder;
        for (std::uint32_t j = count[n]; j < count[n + 1]; ++j) welder.add(mesh.elements[of_node[j]], of_node[j]);
        welded.nodes[n] = welder.finish();
    });
    set_vertex_values(welded, vertex_values ? *vertex_values : output::vertex_values(welded, mesh, radiosity));
    return welded;
}

VertexValues vertex_values(const WeldedMesh& welded, const mesh::Mesh& mesh, const std::vector<glm::dvec3>& values) {
    if (values.size() != mesh.elements.size()) {
        throw InternalError(fmt::format("output: {} values for {} elements", values.size(), mesh.elements.size()));
    }
    VertexValues out(welded.nodes.size());
    parallel::for_each(welded.nodes.size(), 1, [&](std::size_t n) {
        const WeldedNode& node = welded.nodes[n];
        std::vector<glm::dvec3>& at = out[n];
        at.resize(node.positions.size());
        // The area-weighted mean of the elements around each vertex. Zero-area elements carry no
        // weight; a vertex touched only by such gets their mean. (A vertex touched by none was made
        // for a hanging vertex across a crease: its value is its edge's, set below.)
        for (std::size_t v = 0; v < node.positions.size(); ++v) {
            glm::dvec3 weighted(0.0), plain(0.0);
            double weight = 0.0;
            const std::uint32_t first = node.corner_start[v], last = node.corner_start[v + 1];
            for (std::uint32_t i = first; i < last; ++i) {
                const std::uint32_t k = node.corner_element[i];
                const double area = mesh.elements[k].area;
                weighted += area * values[k];
                weight += area;
                plain += values[k];
            }
            at[v] = weight > 0.0 ? weighted / weight : last > first ? plain / double(last - first) : glm::dvec3(0.0);
        }
        for (const WeldedNode::Halfway& h : node.halfway) at[h.vertex] = 0.5 * (at[h.a] + at[h.b]);
    });
    return out;
}

void set_vertex_values(WeldedMesh& welded, const VertexValues& values) {
    if (values.size() != welded.nodes.size()) {
        throw InternalError(fmt::format("output: vertex values for {} nodes of {}", values.size(), welded.nodes.size()));
    }
    for (std::size_t n = 0; n < welded.nodes.size(); ++n) {
        if (values[n].size() != welded.nodes[n].positions.size()) {
            throw InternalError(fmt::format("output: node {}: {} vertex values for {} vertices", n, values[n].size(),
                                            welded.nodes[n].positions.size()));
        }
        welded.nodes[n].radiosity = values[n];
    }
}

}  // namespace hemirad::output
