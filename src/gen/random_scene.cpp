// Random real-shaped glTF scenes for the seeded random-scene test and the bake fuzzer.
#include "gen/random_scene.h"

#include <fmt/format.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <glm/glm.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <stdexcept>
#include <utility>

#include "core/rng.h"
#include "scene/gltf_views.h"

namespace hemirad::gen {

using namespace hemirad::scene;

// ---------------------------------------------------------------------------------------------
// Choices

Choices Choices::from_seed(std::uint64_t seed) {
    std::vector<std::uint8_t> bytes(kSeedBytes);
    for (std::size_t i = 0; i < bytes.size(); i += 8) {
        const std::uint64_t word = mix64(mix64(seed) ^ i);
        for (std::size_t k = 0; k < 8 && i + k < bytes.size(); ++k) bytes[i + k] = std::uint8_t(word >> (8 * k));
    }
    return Choices(std::move(bytes));
}

Choices::Choices(std::vector<std::uint8_t> bytes) : bytes_(std::move(bytes)) {
    tail_seed_ = mix64(bytes_.size());
    for (const std::uint8_t b : bytes_) tail_seed_ = mix64(tail_seed_ ^ b);
}

std::uint8_t Choices::byte() {
    const std::uint8_t b = next_ < bytes_.size() ? bytes_[next_] : std::uint8_t(mix64(tail_seed_ + next_));
    ++next_;
    return b;
}

std::uint32_t Choices::below(std::uint32_t n) {
    if (n <= 1) return 0;
    std::uint32_t v = byte();
    if (n > 256) v = v << 8 | byte();
    if (n > 65536) v = v << 8 | byte();
    return v % n;
}

int Choices::between(int lo, int hi) {
    return hi <= lo ? lo : lo + int(below(std::uint32_t(hi - lo) + 1));
}

double Choices::unit() {
    const std::uint32_t v = std::uint32_t(byte()) << 8 | byte();
    return double(v) / 65535.0;
}

double Choices::uniform(double lo, double hi) { return lo + (hi - lo) * unit(); }

double Choices::log_uniform(double lo, double hi) { return lo * std::pow(hi / lo, unit()); }

bool Choices::chance(double p) { return unit() < p; }

namespace {

using glm::dmat4;
using glm::dvec3;

// ---------------------------------------------------------------------------------------------
// Shapes, in local coordinates within [-1, 1]³, fronts facing out unless flipped afterwards.

struct Part {
    std::string shape;                   // for the summary
    std::vector<dvec3> positions;
    std::vector<std::uint32_t> indices;  // triangles
    std::size_t degenerate = 0;          // triangles added deliberately degenerate or duplicated
    bool closed = false;                 // a closed surface (before anything is added to it)

    std::uint32_t vertex(const dvec3& p) {
        positions.push_back(p);
        return std::uint32_t(positions.size() - 1);
    }
    std::size_t triangles() const { return indices.size() / 3; }
    // A triangle whose front faces `out` (its winding is flipped when it does not).
    void outward(std::uint32_t a, std::uint32_t b, std::uint32_t c, const dvec3& out) {
        const dvec3 n = glm::cross(positions[b] - positions[a], positions[c] - positions[a]);
        if (glm::dot(n, out) < 0.0) std::swap(b, c);
        indices.insert(indices.end(), {a, b, c});
    }
    void raw(std::uint32_t a, std::uint32_t b, std::uint32_t c) { indices.insert(indices.end(), {a, b, c}); }
    dvec3 centroid(std::size_t t) const {
        return (positions[indices[3 * t]] + positions[indices[3 * t + 1]] + positions[indices[3 * t + 2]]) / 3.0;
    }
};

dvec3 on_circle(double angle, double radius, double y) {
    return {radius * std::cos(angle), y, radius * std::sin(angle)};
}

// A UV sphere of `segments` × `rings`. Blender-style options: the seam's vertices duplicated
// (same position, other index), and the polar bands as quads on a pole vertex repeated per
// segment, which makes one zero-area triangle per segment.
Part uv_sphere(int segments, int rings, bool seam, bool pole_quads) {
    Part p;
    p.shape = fmt::format("sphere {}x{}{}{}", segments, rings, seam ? " seam" : "", pole_quads ? " pole-quads" : "");
    p.closed = true;  // the pole quads' extra triangles have no area
    const int columns = seam ? segments + 1 : segments;
    std::vector<std::uint32_t> ring_start;
    for (int b = 1; b < rings; ++b) {
        ring_start.push_back(std::uint32_t(p.positions.size()));
        const double theta = glm::pi<double>() * b / rings;
        for (int j = 0; j < segments; ++j)
            p.vertex({std::sin(theta) * std::cos(2.0 * glm::pi<double>() * j / segments), std::cos(theta),
                      std::sin(theta) * std::sin(2.0 * glm::pi<double>() * j / segments)});
        if (seam) p.vertex(p.positions[ring_start.back()]);  // the seam: column 0 again, bit for bit
    }
    const auto at = [&](int b, int j) { return ring_start[std::size_t(b - 1)] + std::uint32_t(seam ? j : j % segments); };
    const auto pole = [&](double y, int copies) {
        std::vector<std::uint32_t> v;
        for (int k = 0; k < copies; ++k) v.push_back(p.vertex({0.0, y, 0.0}));
        return v;
    };
    const std::vector<std::uint32_t> north = pole(1.0, pole_quads ? columns : 1);
    const std::vector<std::uint32_t> south = pole(-1.0, pole_quads ? columns : 1);
    for (int j = 0; j < segments; ++j) {
        const auto centre = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
            return (p.positions[a] + p.positions[b] + p.positions[c]) / 3.0;
        };
        // North band.
        if (pole_quads) {
            const std::uint32_t n0 = north[std::size_t(j)], n1 = north[std::size_t((j + 1) % columns)];
            p.raw(n0, n1, at(1, j + 1));  // zero area: n0 and n1 coincide
            ++p.degenerate;
            p.outward(n0, at(1, j + 1), at(1, j), centre(n0, at(1, j + 1), at(1, j)));
        } else {
            p.outward(north[0], at(1, j + 1), at(1, j), centre(north[0], at(1, j + 1), at(1, j)));
        }
        for (int b = 1; b + 1 < rings; ++b) {
            const std::uint32_t a = at(b, j), c = at(b, j + 1), d = at(b + 1, j + 1), e = at(b + 1, j);
            p.outward(a, c, d, centre(a, c, d));
            p.outward(a, d, e, centre(a, d, e));
        }
        const int last = rings - 1;
        if (pole_quads) {
            const std::uint32_t s0 = south[std::size_t(j)], s1 = south[std::size_t((j + 1) % columns)];
            p.outward(at(last, j), at(last, j + 1), s1, centre(at(last, j), at(last, j + 1), s1));
            p.raw(at(last, j), s1, s0);  // zero area
            ++p.degenerate;
        } else {
            p.outward(at(last, j), at(last, j + 1), south[0], centre(at(last, j), at(last, j + 1), south[0]));
        }
    }
    return p;
}

enum class Caps { none, centre_fan, ngon_fan, one_end };

// A cylinder of radius 1 along y from -1 to 1: `segments` around, `stacks` bands of side quads,
// caps as a fan from a centre vertex, as an n-gon fanned from its first vertex (Blender's
// triangulation of an n-gon), open at both ends or at one.
Part cylinder(int segments, int stacks, Caps caps) {
    static const char* const kCaps[] = {"open", "centre-fan caps", "ngon caps", "one cap"};
    Part p;
    p.shape = fmt::format("cylinder {}x{} {}", segments, stacks, kCaps[int(caps)]);
    p.closed = caps == Caps::centre_fan || caps == Caps::ngon_fan;
    std::vector<std::uint32_t> ring_start;
    for (int k = 0; k <= stacks; ++k) {
        ring_start.push_back(std::uint32_t(p.positions.size()));
        for (int j = 0; j < segments; ++j)
            p.vertex(on_circle(2.0 * glm::pi<double>() * j / segments, 1.0, -1.0 + 2.0 * k / stacks));
    }
    const auto at = [&](int k, int j) { return ring_start[std::size_t(k)] + std::uint32_t(j % segments); };
    for (int k = 0; k < stacks; ++k)
        for (int j = 0; j < segments; ++j) {
            const dvec3 mid = on_circle(2.0 * glm::pi<double>() * (j + 0.5) / segments, 1.0, 0.0);
            p.outward(at(k, j), at(k, j + 1), at(k + 1, j + 1), mid);
            p.outward(at(k, j), at(k + 1, j + 1), at(k + 1, j), mid);
        }
    for (const int end : {0, stacks}) {
        if (caps == Caps::none || (caps == Caps::one_end && end == 0)) continue;
        const dvec3 out(0.0, end == 0 ? -1.0 : 1.0, 0.0);
        if (caps == Caps::ngon_fan) {
            for (int j = 1; j + 1 < segments; ++j) p.outward(at(end, 0), at(end, j), at(end, j + 1), out);
        } else {
            const std::uint32_t centre = p.vertex(out);
            for (int j = 0; j < segments; ++j) p.outward(centre, at(end, j), at(end, j + 1), out);
        }
    }
    return p;
}

// A torus about the y axis: tube centre radius 0.7, tube radius `tube` (< 0.3).
Part torus(int major, int minor, double tube) {
    Part p;
    p.shape = fmt::format("torus {}x{} r{:.2f}", major, minor, tube);
    p.closed = true;
    constexpr double kCore = 0.7;
    const auto index = [&](int i, int j) { return std::uint32_t((i % major) * minor + (j % minor)); };
    for (int i = 0; i < major; ++i)
        for (int j = 0; j < minor; ++j) {
            const double u = 2.0 * glm::pi<double>() * i / major, v = 2.0 * glm::pi<double>() * j / minor;
            p.vertex(on_circle(u, kCore + tube * std::cos(v), tube * std::sin(v)));
        }
    for (int i = 0; i < major; ++i)
        for (int j = 0; j < minor; ++j) {
            const double u = 2.0 * glm::pi<double>() * (i + 0.5) / major;
            const double v = 2.0 * glm::pi<double>() * (j + 0.5) / minor;
            const dvec3 out = on_circle(u, kCore + tube * std::cos(v), tube * std::sin(v)) - on_circle(u, kCore, 0.0);
            p.outward(index(i, j), index(i + 1, j), index(i + 1, j + 1), out);
            p.outward(index(i, j), index(i + 1, j + 1), index(i, j + 1), out);
        }
    return p;
}

// The box [-1, 1]³, each face a cuts × cuts grid of quads with its own vertices.
Part box(int cuts) {
    Part p;
    p.shape = fmt::format("box {}", cuts);
    p.closed = true;
    for (int axis = 0; axis < 3; ++axis)
        for (const double side : {-1.0, 1.0}) {
            const int u = (axis + 1) % 3, v = (axis + 2) % 3;
            const auto corner = [&](int i, int j) {
                dvec3 q;
                q[axis] = side;
                q[u] = -1.0 + 2.0 * i / cuts;
                q[v] = -1.0 + 2.0 * j / cuts;
                return q;
            };
            dvec3 out(0.0);
            out[axis] = side;
            const std::uint32_t first = std::uint32_t(p.positions.size());
            for (int j = 0; j <= cuts; ++j)
                for (int i = 0; i <= cuts; ++i) p.vertex(corner(i, j));
            const auto at = [&](int i, int j) { return first + std::uint32_t(j * (cuts + 1) + i); };
            for (int j = 0; j < cuts; ++j)
                for (int i = 0; i < cuts; ++i) {
                    p.outward(at(i, j), at(i + 1, j), at(i + 1, j + 1), out);
                    p.outward(at(i, j), at(i + 1, j + 1), at(i, j + 1), out);
                }
        }
    return p;
}

// The square [-1, 1]² at y = `y`, a cuts × cuts grid facing `up` (+y or -y).
void add_plane(Part& p, int cuts, double y, double up) {
    const std::uint32_t first = std::uint32_t(p.positions.size());
    for (int j = 0; j <= cuts; ++j)
        for (int i = 0; i <= cuts; ++i) p.vertex({-1.0 + 2.0 * i / cuts, y, -1.0 + 2.0 * j / cuts});
    const auto at = [&](int i, int j) { return first + std::uint32_t(j * (cuts + 1) + i); };
    for (int j = 0; j < cuts; ++j)
        for (int i = 0; i < cuts; ++i) {
            p.outward(at(i, j), at(i + 1, j), at(i + 1, j + 1), {0.0, up, 0.0});
            p.outward(at(i, j), at(i + 1, j + 1), at(i, j + 1), {0.0, up, 0.0});
        }
}

// Two parallel squares `gap` apart: back to back (a wall with two faces and no edges), or
// both facing the same way (a panel just in front of another).
Part thin_wall(double gap, bool back_to_back, int cuts) {
    Part p;
    p.shape = fmt::format("thin wall {:.1e} {}", gap, back_to_back ? "back-to-back" : "same-facing");
    add_plane(p, cuts, 0.5 * gap, 1.0);
    add_plane(p, cuts, -0.5 * gap, back_to_back ? -1.0 : 1.0);
    return p;
}

// A closed room [-1, 1]³ facing in, or a floor facing up.
Part room(int cuts) {
    Part p = box(cuts);
    p.shape = fmt::format("room {}", cuts);  // closed, facing in
    for (std::size_t t = 0; t < p.indices.size(); t += 3) std::swap(p.indices[t + 1], p.indices[t + 2]);
    return p;
}
Part floor_plane(int cuts) {
    Part p;
    p.shape = fmt::format("floor {}", cuts);
    add_plane(p, cuts, 0.0, 1.0);
    return p;
}

// Appends `count` deliberately bad triangles made from the part's own vertices: zero-area
// (collinear), points, needles (1e-9 wide), a repeated index, and coplanar duplicates of
// existing triangles (the same indices, the same winding reversed, or new vertices at the same
// positions).
void add_degenerate(Part& p, Choices& c, int count) {
    if (p.positions.empty() || p.indices.empty()) return;
    const std::size_t n = p.positions.size(), triangles = p.triangles();
    p.closed = false;  // duplicates change the enclosed volume
    for (int k = 0; k < count; ++k) {
        const std::uint32_t a = c.below(std::uint32_t(n)), b = c.below(std::uint32_t(n));
        const std::size_t t = c.below(std::uint32_t(triangles));
        const std::uint32_t i0 = p.indices[3 * t], i1 = p.indices[3 * t + 1], i2 = p.indices[3 * t + 2];
        switch (c.below(7)) {
            case 0: p.raw(a, p.vertex(0.5 * (p.positions[a] + p.positions[b])), b); break;  // collinear
            case 1: p.raw(a, a, a); break;                                                 // a point
            case 2: {                                                                      // a needle
                const dvec3 d = p.positions[b] - p.positions[a];
                const dvec3 side = glm::length(d) > 0.0 ? glm::normalize(glm::cross(d, dvec3(0.3, 0.9, 0.1))) : dvec3(0.0);
                p.raw(a, b, p.vertex(p.positions[b] + 1e-9 * glm::length(d) * side));
                break;
            }
            case 3: p.raw(a, b, a); break;      // a repeated index
            case 4: p.raw(i0, i1, i2); break;   // the same triangle again
            case 5: p.raw(i0, i2, i1); break;   // its back, coplanar
            default: {                          // again, on vertices of its own
                const std::uint32_t j0 = p.vertex(p.positions[i0]), j1 = p.vertex(p.positions[i1]);
                p.raw(j0, j1, p.vertex(p.positions[i2]));
            }
        }
        ++p.degenerate;
    }
}

// ---------------------------------------------------------------------------------------------
// Transforms

// A node transform: T·R·S or a matrix, as glTF writes them.
struct Transform {
    bool use_matrix = false;
    dvec3 translation{0.0};
    glm::dquat rotation{1.0, 0.0, 0.0, 0.0};
    dvec3 scale{1.0};
    std::string tag;  // for the summary: R rotated, S scaled, M mirrored, X matrix

    dmat4 matrix() const {
        return glm::translate(dmat4(1.0), translation) * glm::mat4_cast(rotation) * glm::scale(dmat4(1.0), scale);
    }
};

// A rotation: none, Blender's Z-up to Y-up turn (-90° about x), a quarter turn about y, or any
// (uniform on the sphere of unit quaternions, Shoemake's method).
glm::dquat random_rotation(Choices& c) {
    switch (c.below(4)) {
        case 0: return {1.0, 0.0, 0.0, 0.0};
        case 1: return glm::angleAxis(-0.5 * glm::pi<double>(), dvec3(1.0, 0.0, 0.0));
        case 2: return glm::angleAxis(0.5 * glm::pi<double>() * c.between(1, 3), dvec3(0.0, 1.0, 0.0));
        default: {
            const double u1 = c.unit(), u2 = 2.0 * glm::pi<double>() * c.unit(), u3 = 2.0 * glm::pi<double>() * c.unit();
            const double a = std::sqrt(1.0 - u1), b = std::sqrt(u1);
            return glm::normalize(glm::dquat(b * std::cos(u3), a * std::sin(u2), a * std::cos(u2), b * std::sin(u3)));
        }
    }
}

// A transform with a rotation, a scale between lo and hi (uniform or per axis), a translation
// within `reach`, and with probability `mirror` one or three axes negated.
Transform random_transform(Choices& c, double reach, double lo, double hi, double mirror) {
    Transform t;
    t.use_matrix = c.chance(0.3);
    if (c.chance(0.7)) t.translation = dvec3(c.uniform(-reach, reach), c.uniform(-reach, reach), c.uniform(-reach, reach));
    if (c.chance(0.7)) {
        t.rotation = random_rotation(c);
        t.tag += "R";
    }
    if (c.chance(0.6)) {
        t.scale = c.chance(0.5) ? dvec3(c.log_uniform(lo, hi))
                                : dvec3(c.log_uniform(lo, hi), c.log_uniform(lo, hi), c.log_uniform(lo, hi));
        t.tag += "S";
    }
    if (c.chance(mirror)) {
        if (c.chance(0.7))
            t.scale[int(c.below(3))] *= -1.0;
        else
            t.scale = -t.scale;
        t.tag += "M";
    }
    if (t.use_matrix) t.tag += "X";
    return t;
}

// ---------------------------------------------------------------------------------------------
// glTF writing

struct Writer {
    tinygltf::Model model;

    Writer() {
        model.asset.version = "2.0";
        model.asset.generator = "hemirad random_scene";
        model.buffers.emplace_back();
    }

    int view(const void* data, std::size_t size, int target) { return append_view(model, data, size, target); }

    int accessor(int view_index, int component, int type, std::size_t count, bool normalized = false) {
        tinygltf::Accessor a;
        a.bufferView = view_index;
        a.componentType = component;
        a.type = type;
        a.count = count;
        a.normalized = normalized;
        model.accessors.push_back(a);
        return int(model.accessors.size() - 1);
    }

    int positions(const std::vector<dvec3>& p) {
        std::vector<float> f;
        for (const dvec3& v : p) f.insert(f.end(), {float(v.x), float(v.y), float(v.z)});
        const int a = accessor(view(f.data(), f.size() * sizeof(float), TINYGLTF_TARGET_ARRAY_BUFFER),
                               TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, p.size());
        std::vector<double> lo(3, 1e300), hi(3, -1e300);
        for (std::size_t i = 0; i < f.size(); ++i) {
            lo[i % 3] = std::min(lo[i % 3], double(f[i]));
            hi[i % 3] = std::max(hi[i % 3], double(f[i]));
        }
        model.accessors[std::size_t(a)].minValues = lo;
        model.accessors[std::size_t(a)].maxValues = hi;
        return a;
    }

    // Per-vertex colours in [0.2, 1]: float RGB, or normalized unsigned-byte RGBA.
    int colours(Choices& c, std::size_t count) {
        if (c.chance(0.5)) {
            std::vector<float> f(3 * count);
            for (float& v : f) v = float(c.uniform(0.2, 1.0));
            return accessor(view(f.data(), f.size() * sizeof(float), TINYGLTF_TARGET_ARRAY_BUFFER),
                            TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, count);
        }
        std::vector<std::uint8_t> b(4 * count);
        for (std::size_t i = 0; i < b.size(); ++i) b[i] = i % 4 == 3 ? 255 : std::uint8_t(c.between(51, 255));
        return accessor(view(b.data(), b.size(), TINYGLTF_TARGET_ARRAY_BUFFER), TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE,
                        TINYGLTF_TYPE_VEC4, count, /*normalized=*/true);
    }

    int indices(Choices& c, const std::vector<std::uint32_t>& idx, std::size_t vertices) {
        if (vertices <= 65535 && c.chance(0.5)) {
            std::vector<std::uint16_t> s(idx.begin(), idx.end());
            return accessor(view(s.data(), s.size() * 2, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                            TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_SCALAR, s.size());
        }
        return accessor(view(idx.data(), idx.size() * 4, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                        TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, idx.size());
    }

    // One primitive of `part`: indexed, or (sometimes) its triangles' vertices written out.
    tinygltf::Primitive primitive(Choices& c, const Part& part, int material, bool colour) {
        tinygltf::Primitive prim;
        prim.material = material;
        prim.mode = TINYGLTF_MODE_TRIANGLES;  // tinygltf's writer cannot leave it out
        if (c.chance(0.15)) {
            std::vector<dvec3> flat;
            for (const std::uint32_t i : part.indices) flat.push_back(part.positions[i]);
            prim.attributes["POSITION"] = positions(flat);
            if (colour) prim.attributes["COLOR_0"] = colours(c, flat.size());
        } else {
            prim.attributes["POSITION"] = positions(part.positions);
            if (colour) prim.attributes["COLOR_0"] = colours(c, part.positions.size());
            prim.indices = indices(c, part.indices, part.positions.size());
        }
        return prim;
    }

    int node(const Transform& t, const std::string& name) {
        tinygltf::Node n;
        n.name = name;
        if (t.use_matrix) {
            const dmat4 m = t.matrix();
            n.matrix.assign(glm::value_ptr(m), glm::value_ptr(m) + 16);
        } else {
            if (t.translation != dvec3(0.0)) n.translation = {t.translation.x, t.translation.y, t.translation.z};
            if (t.rotation != glm::dquat(1.0, 0.0, 0.0, 0.0))
                n.rotation = {t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w};
            if (t.scale != dvec3(1.0)) n.scale = {t.scale.x, t.scale.y, t.scale.z};
        }
        model.nodes.push_back(n);
        return int(model.nodes.size() - 1);
    }
};

struct MaterialChoice {
    bool emits = false, double_sided = false;
    std::string tag;
};

// A material: reflectance grey or coloured anywhere in [0, 0.999], sometimes 0 or 1 (which the
// loader clamps, with a warning); emission a colour times a strength from 0.01 to 1000.
MaterialChoice add_material(Writer& w, Choices& c, bool emissive, int index) {
    tinygltf::Material m;
    m.name = fmt::format("material{}", index);
    MaterialChoice out;
    std::array<double, 3> rho{};
    switch (c.below(5)) {
        case 0: rho.fill(0.0); break;
        case 1: rho.fill(c.chance(0.5) ? 0.999 : 1.0); break;
        case 2: rho.fill(c.uniform(0.0, 0.999)); break;
        default:
            for (double& r : rho) r = c.uniform(0.0, 0.999);
    }
    m.pbrMetallicRoughness.baseColorFactor = {rho[0], rho[1], rho[2], 1.0};
    m.pbrMetallicRoughness.metallicFactor = 0.0;
    out.tag = fmt::format("rho {:.3f}", std::max({rho[0], rho[1], rho[2]}));
    if (emissive) {
        std::array<double, 3> e{};
        if (c.chance(0.5)) {
            e.fill(c.uniform(0.05, 1.0));
        } else {
            for (double& v : e) v = c.unit();
            e[c.below(3)] = c.uniform(0.05, 1.0);  // some channel emits
        }
        m.emissiveFactor = {e[0], e[1], e[2]};
        if (c.chance(0.6)) {
            const double strength = c.log_uniform(0.01, 1000.0);
            tinygltf::Value::Object ext;
            ext["emissiveStrength"] = tinygltf::Value(strength);
            m.extensions["KHR_materials_emissive_strength"] = tinygltf::Value(ext);
            out.tag += fmt::format(" E x{:.3g}", strength);
        } else {
            out.tag += " E";
        }
        out.emits = true;
    }
    m.doubleSided = out.double_sided = c.chance(0.5);
    if (out.double_sided) out.tag += " 2-sided";
    w.model.materials.push_back(m);
    return out;
}

// The triangles of a shape chosen from `choices`, at most about `budget` of them.
Part random_shape(Choices& c, int budget, bool lamp) {
    // Segment counts shrink until the shape fits the budget (the smallest always fits).
    const auto fit = [budget](int& a, int& b, int min_a, int min_b, auto count) {
        while (count(a, b) > budget && (a > min_a || b > min_b)) {
            if (a > min_a) --a;
            if (b > min_b && count(a, b) > budget) --b;
        }
    };
    switch (c.below(lamp ? 5 : 6)) {
        case 0: {
            int s = c.between(3, 32), r = c.between(2, 16);
            fit(s, r, 3, 2, [](int a, int b) { return 2 * a * (b - 1); });
            const bool pole_quads = c.chance(0.3);
            return uv_sphere(s, r, c.chance(0.3), pole_quads);
        }
        case 1: {
            int s = c.between(3, 48), k = c.between(1, 4);
            fit(s, k, 3, 1, [](int a, int b) { return 2 * a * b + 2 * a; });
            return cylinder(s, k, Caps(c.below(4)));
        }
        case 2: {
            int major = c.between(3, 32), minor = c.between(3, 16);
            fit(major, minor, 3, 3, [](int a, int b) { return 2 * a * b; });
            return torus(major, minor, c.uniform(0.02, 0.3));
        }
        case 3: {
            int cuts = c.between(1, 4), one = 1;
            fit(cuts, one, 1, 1, [](int a, int) { return 12 * a * a; });
            return box(cuts);
        }
        case 4: return thin_wall(c.log_uniform(1e-6, 0.1), c.chance(0.6), c.between(1, 3));
        default: {
            // Only degenerate triangles and duplicates, on a small quad: a mesh that meshes to nothing
            // or to a coplanar pile.
            Part p;
            p.shape = "degenerate soup";
            add_plane(p, 1, 0.0, 1.0);
            add_degenerate(p, c, c.between(1, 12));
            return p;
        }
    }
}

}  // namespace

RandomSceneInfo write_random_scene(Choices& c, const std::filesystem::path& file, const RandomSceneLimits& limits) {
    Writer w;
    RandomSceneInfo info;
    std::vector<std::string> summary;

    // Scene units from 1e-3 to 1e3: a root node's scale, or baked into every position and translation.
    const double unit = std::pow(10.0, c.uniform(-3.0, 3.0));
    const bool unit_in_root = c.chance(0.5);
    const double baked = unit_in_root ? 1.0 : unit;
    summary.push_back(fmt::format("units {:.3g} ({})", unit, unit_in_root ? "root node" : "in positions"));

    // Materials: the first emits; the others sometimes.
    const int material_count = c.between(2, 5);
    std::vector<MaterialChoice> materials;
    for (int m = 0; m < material_count; ++m) materials.push_back(add_material(w, c, m == 0 || c.chance(0.2), m));
    for (const MaterialChoice& m : materials) info.double_sided = info.double_sided || m.double_sided;
    bool uses_strength = false;
    for (const tinygltf::Material& m : w.model.materials) uses_strength = uses_strength || !m.extensions.empty();
    if (uses_strength) w.model.extensionsUsed.push_back("KHR_materials_emissive_strength");

    std::vector<int> roots;
    // Per mesh written so far: what its nodes are (a node copies it, adding its own transform).
    std::vector<RandomObject> mesh_objects;
    // A mesh node under `parent` (its world transform, for the mirror flag).
    const auto add_mesh_node = [&](int mesh, const Transform& t, const dmat4& parent, const std::string& name) {
        Transform scaled = t;
        scaled.translation *= baked;
        const int n = w.node(scaled, name);
        w.model.nodes[std::size_t(n)].mesh = mesh;
        RandomObject object = mesh_objects[std::size_t(mesh)];
        object.node = name;
        object.mirrored = glm::determinant(glm::dmat3(parent * t.matrix())) < 0.0;
        info.mirrored = info.mirrored || object.mirrored;
        info.triangles += object.triangles;
        info.objects.push_back(object);
        return n;
    };
    // A chain of 0 to 3 ancestors (rotated, scaled, mirrored, near the origin) ending in the node
    // `leaf` returns: the chain's top is a root; returns the leaf's index.
    const auto add_under_chain = [&](int mesh, const Transform& leaf, const std::string& name, std::string& tags) {
        int parent = -1;
        dmat4 world(1.0);
        const int depth = c.between(0, 3);
        for (int d = 0; d < depth; ++d) {
            Transform t = random_transform(c, 1.0, 0.5, 2.0, 0.3);
            tags += t.tag.empty() ? "-" : t.tag;
            tags += "/";
            world = world * t.matrix();
            t.translation *= baked;
            const int n = w.node(t, fmt::format("{}_parent{}", name, d));
            if (parent < 0)
                roots.push_back(n);
            else
                w.model.nodes[std::size_t(parent)].children.push_back(n);
            parent = n;
        }
        tags += leaf.tag.empty() ? "-" : leaf.tag;
        const int n = add_mesh_node(mesh, leaf, world, name);
        if (parent < 0)
            roots.push_back(n);
        else
            w.model.nodes[std::size_t(parent)].children.push_back(n);
        return n;
    };
    const auto add_mesh = [&](Part& part, int material, const std::string& name, bool inward) {
        RandomObject object;
        object.shape = part.shape;
        object.triangles = part.triangles();
        object.closed = part.closed;
        object.inward = inward;
        object.emits = materials[std::size_t(material)].emits;
        mesh_objects.push_back(object);
        for (dvec3& p : part.positions) p *= baked;
        tinygltf::Mesh mesh;
        mesh.name = name;
        const bool colour = c.chance(0.3);
        mesh.primitives.push_back(w.primitive(c, part, material, colour));
        w.model.meshes.push_back(mesh);
        return int(w.model.meshes.size() - 1);
    };

    // Around the objects: nothing (open to the sky), a floor, or a closed room.
    const int surround = int(c.below(3));
    if (surround > 0) {
        Part p = surround == 1 ? floor_plane(c.between(1, 3)) : room(c.between(1, 2));
        const int material = 1 + int(c.below(std::uint32_t(material_count - 1)));
        Transform t;
        t.scale = dvec3(8.0, surround == 1 ? 1.0 : 5.0, 8.0);
        t.translation = dvec3(0.0, surround == 1 ? -2.0 : 3.0, 0.0);
        t.tag = "S";
        summary.push_back(fmt::format("{} m{}", p.shape, material));
        const int mesh = add_mesh(p, material, surround == 1 ? "floor" : "room", surround == 2);
        std::string tags;
        add_under_chain(mesh, t, surround == 1 ? "floor" : "room", tags);
    }

    const int objects = c.between(1, std::max(1, limits.max_objects));
    const int budget = std::max(8, limits.max_triangles / objects);
    for (int k = 0; k < objects; ++k) {
        const bool lamp = k == 0;
        Part part = random_shape(c, budget, lamp);
        if (!lamp && c.chance(0.3)) add_degenerate(part, c, c.between(1, 8));
        const bool flipped = !lamp && c.chance(0.15);  // an exporter's inside-out normals
        if (flipped)
            for (std::size_t t = 0; t < part.indices.size(); t += 3) std::swap(part.indices[t + 1], part.indices[t + 2]);
        const int material = lamp ? 0 : int(c.below(std::uint32_t(material_count)));
        const std::string name = fmt::format("object{}", k);
        info.degenerate += part.degenerate;
        std::string entry = fmt::format("{}: {}{} m{} [{}]", name, part.shape, flipped ? " flipped" : "", material,
                                        materials[std::size_t(material)].tag);
        const int mesh = add_mesh(part, material, name, flipped);
        Transform leaf = random_transform(c, 3.0, 0.2, 1.5, 0.3);
        std::string tags;
        add_under_chain(mesh, leaf, name, tags);
        entry += " " + tags;
        // The same mesh under a second node elsewhere (an instance).
        if (!lamp && c.chance(0.2)) {
            std::string instance_tags;
            add_under_chain(mesh, random_transform(c, 3.0, 0.2, 1.5, 0.3), name + "_instance", instance_tags);
            entry += " +instance " + instance_tags;
        }
        summary.push_back(entry);
    }

    // A camera, sometimes, looking at the middle of the scene from in front; sometimes as a
    // mirroring matrix under a mirrored parent (the loader keeps a camera's frame rigid).
    if (c.chance(0.5)) {
        tinygltf::Camera cam;
        cam.type = "perspective";
        cam.name = "camera";
        cam.perspective.yfov = c.uniform(0.3, 1.5);
        cam.perspective.aspectRatio = c.chance(0.5) ? c.uniform(0.5, 2.0) : 0.0;
        cam.perspective.znear = c.log_uniform(1e-3, 0.1) * unit;
        w.model.cameras.push_back(cam);
        const dvec3 eye(c.uniform(-2.0, 2.0), c.uniform(0.0, 3.0), c.uniform(4.0, 9.0));
        const dmat4 camera_to_world = glm::inverse(glm::lookAt(eye, dvec3(0.0), dvec3(0.0, 1.0, 0.0)));
        Transform t;
        t.translation = eye * baked;
        t.rotation = glm::quat_cast(glm::dmat3(camera_to_world));
        if (c.chance(0.3)) {
            Transform mirror;
            mirror.scale = dvec3(-1.0, 1.0, 1.0);
            mirror.use_matrix = true;
            const int parent = w.node(mirror, "camera_mirror");
            Transform child = t;  // the mirror again, so the two cancel: child = M · T · R
            child.use_matrix = true;
            tinygltf::Node& n = w.model.nodes.emplace_back();
            n.name = "camera";
            const dmat4 m = mirror.matrix() * child.matrix();
            n.matrix.assign(glm::value_ptr(m), glm::value_ptr(m) + 16);
            n.camera = 0;
            w.model.nodes[std::size_t(parent)].children.push_back(int(w.model.nodes.size() - 1));
            roots.push_back(parent);
            summary.push_back("camera (mirrored twice)");
        } else {
            const int n = w.node(t, "camera");
            w.model.nodes[std::size_t(n)].camera = 0;
            roots.push_back(n);
            summary.push_back("camera");
        }
    }

    tinygltf::Scene scene;
    if (unit_in_root) {
        Transform t;
        t.scale = dvec3(unit);
        const int root = w.node(t, "units");
        w.model.nodes[std::size_t(root)].children = roots;
        scene.nodes = {root};
    } else {
        scene.nodes = roots;
    }
    w.model.scenes.push_back(scene);
    w.model.defaultScene = 0;

    std::string line;
    for (const std::string& s : summary) line += (line.empty() ? "" : "; ") + s;
    info.summary = line;

    tinygltf::TinyGLTF gltf;
    if (!gltf.WriteGltfSceneToFile(&w.model, file.string(), /*embedImages=*/true, /*embedBuffers=*/true,
                                   /*prettyPrint=*/false, /*writeBinary=*/false))
        throw std::runtime_error(fmt::format("{}: cannot write the random scene", file.string()));
    return info;
}

}  // namespace hemirad::gen
