// Content-like benchmark scenes (city, furniture, foliage): builders run once per candidate
// layout and detail level in counting mode to fit the requested triangle count, then once for real.
#include "gen/content_scenes.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <vector>

#include "core/error.h"
#include "core/rng.h"
#include "gen/procedural.h"

namespace hemirad::gen {

using namespace hemirad::scene;
namespace {

using glm::dvec3;

constexpr double kPi = glm::pi<double>();

// Appends triangles, or only counts them (scene == nullptr): fitting a 3M-triangle scene runs
// the builder ~30 times, and storing 160-byte triangles each time would dominate.
class Builder {
public:
    explicit Builder(Scene* scene) : scene_(scene) {}

    // Starts a new object (a node); its name is only made when building.
    void object(const char* kind, std::size_t index) {
        ++primitive_;
        if (!scene_) return;
        node_ = std::uint32_t(scene_->nodes.size());
        scene_->nodes.push_back({index == kNoIndex ? std::string(kind) : fmt::format("{}_{}", kind, index), -1});
    }
    // Following triangles use this material, as a primitive of their own (the mesher pairs quads
    // within a primitive only).
    void material(std::uint32_t m) {
        ++primitive_;
        material_ = m;
    }

    void triangle(const dvec3& a, const dvec3& b, const dvec3& c) {
        ++count_;
        if (!scene_) return;
        Triangle t;
        t.p = {a, b, c};
        const dvec3 rho = scene_->materials[material_].base_color;
        t.rho = {rho, rho, rho};
        t.material = material_;
        t.node = node_;
        t.primitive = primitive_;
        scene_->triangles.push_back(t);
    }
    // A planar convex quad, counter-clockwise from the front, split along a–c.
    void quad(const dvec3& a, const dvec3& b, const dvec3& c, const dvec3& d) {
        triangle(a, b, c);
        triangle(a, c, d);
    }
    // The same, turned to face `out` whichever way its corners were listed.
    void quad_facing(const dvec3& a, const dvec3& b, const dvec3& c, const dvec3& d, const dvec3& out) {
        if (glm::dot(glm::cross(b - a, c - a), out) >= 0.0)
            quad(a, b, c, d);
        else
            quad(a, d, c, b);
    }
    void triangle_facing(const dvec3& a, const dvec3& b, const dvec3& c, const dvec3& out) {
        if (glm::dot(glm::cross(b - a, c - a), out) >= 0.0)
            triangle(a, b, c);
        else
            triangle(a, c, b);
    }

    std::size_t count() const { return count_; }
    // Counting only: a caller may then add a known number of triangles without making them.
    bool counting() const { return scene_ == nullptr; }
    void add_count(std::size_t triangles) { count_ += triangles; }

    static constexpr std::size_t kNoIndex = ~std::size_t(0);

private:
    Scene* scene_;
    std::size_t count_ = 0;
    std::uint32_t material_ = 0, node_ = 0, primitive_ = 0;
};

// The rectangle o, o+u, o+u+v, o+v as an nu × nv grid of quads facing u × v.
void quad_grid(Builder& b, const dvec3& o, const dvec3& u, const dvec3& v, int nu, int nv) {
    for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
            const auto at = [&](int a, int c) { return o + u * (double(a) / nu) + v * (double(c) / nv); };
            b.quad(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
        }
}

// Face bits for box(): which of the six faces to emit.
enum Face : unsigned { kLowX = 1, kHighX = 2, kBottom = 4, kTop = 8, kLowZ = 16, kHighZ = 32, kAllFaces = 63 };

// An axis-aligned box facing out; faces not in `faces` are left off (those resting on or against
// another surface, which would be coplanar with it). Each face a cuts × cuts grid.
void box(Builder& b, const dvec3& lo, const dvec3& hi, unsigned faces = kAllFaces, int cuts = 1) {
    const dvec3 d = hi - lo;
    const dvec3 x(d.x, 0, 0), y(0, d.y, 0), z(0, 0, d.z);
    if (faces & kLowX) quad_grid(b, lo, z, y, cuts, cuts);
    if (faces & kHighX) quad_grid(b, lo + x, y, z, cuts, cuts);
    if (faces & kBottom) quad_grid(b, lo, x, z, cuts, cuts);
    if (faces & kTop) quad_grid(b, lo + y, z, x, cuts, cuts);
    if (faces & kLowZ) quad_grid(b, lo, y, x, cuts, cuts);
    if (faces & kHighZ) quad_grid(b, lo + z, x, y, cuts, cuts);
}

// A box with its 12 edges chamfered by c (the bevel of modelled furniture): 6 inset faces
// (cuts × cuts each), 12 edge strips and 8 corner triangles; `bottom` false leaves the bottom face off.
void chamfered_box(Builder& b, const dvec3& lo, const dvec3& hi, double c, int cuts = 1, bool bottom = true) {
    const dvec3 centre = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
    c = std::min({c, 0.45 * half.x, 0.45 * half.y, 0.45 * half.z});
    // A point on the box: s picks the side per axis (±1), inset pulls it in by c along that axis.
    const auto at = [&](const dvec3& s, const dvec3& inset) { return centre + s * (half - inset); };
    for (int a = 0; a < 3; ++a) {
        const int u = (a + 1) % 3, v = (a + 2) % 3;
        for (const double sa : {-1.0, 1.0}) {
            // Face a at side sa.
            if (!(a == 1 && sa < 0.0 && !bottom)) {
                dvec3 s(0.0), in(c);
                s[a] = sa, in[a] = 0.0;
                s[u] = -1, s[v] = -1;
                const dvec3 p0 = at(s, in);
                s[u] = 1;
                const dvec3 p1 = at(s, in);
                s[v] = 1, s[u] = -1;
                const dvec3 p3 = at(s, in);
                dvec3 out(0.0);
                out[a] = sa;
                const dvec3 e1 = p1 - p0, e2 = p3 - p0;
                if (glm::dot(glm::cross(e1, e2), out) >= 0.0)
                    quad_grid(b, p0, e1, e2, cuts, cuts);
                else
                    quad_grid(b, p0, e2, e1, cuts, cuts);
            }
            // Edges between axis a and axis u, running along v.
            for (const double su : {-1.0, 1.0}) {
                dvec3 s(0.0), in1(c), in2(c);
                s[a] = sa, s[u] = su;
                in1[a] = 0.0;  // on face a
                in2[u] = 0.0;  // on face u
                dvec3 out(0.0);
                out[a] = sa, out[u] = su;
                s[v] = -1;
                const dvec3 a0 = at(s, in1), b0 = at(s, in2);
                s[v] = 1;
                const dvec3 a1 = at(s, in1), b1 = at(s, in2);
                b.quad_facing(a0, a1, b1, b0, out);
            }
        }
    }
    for (const double sx : {-1.0, 1.0})
        for (const double sy : {-1.0, 1.0})
            for (const double sz : {-1.0, 1.0}) {
                const dvec3 s(sx, sy, sz);
                b.triangle_facing(at(s, {0, c, c}), at(s, {c, 0, c}), at(s, {c, c, 0}), s);
            }
}

// A vertical frustum from `base` up `height`, radii r0 (bottom) and r1 (top), `segments` planar
// trapezoids around; caps as fans, each optional (a leg standing on the floor has no bottom).
void frustum(Builder& b, const dvec3& base, double r0, double r1, double height, int segments, bool bottom_cap,
             bool top_cap) {
    const auto ring = [&](double r, double y, int j) {
        const double phi = 2.0 * kPi * double(j % segments) / double(segments);
        return base + dvec3(r * std::cos(phi), y, r * std::sin(phi));
    };
    const dvec3 top = base + dvec3(0, height, 0);
    for (int j = 0; j < segments; ++j) {
        // φ grows towards +z: (j, bottom), (j, top), (j+1, top), (j+1, bottom) faces out.
        b.quad(ring(r0, 0, j), ring(r1, height, j), ring(r1, height, j + 1), ring(r0, 0, j + 1));
        if (top_cap) b.triangle(top, ring(r1, height, j + 1), ring(r1, height, j));
        if (bottom_cap) b.triangle(base, ring(r0, 0, j), ring(r0, 0, j + 1));
    }
}

void cylinder(Builder& b, const dvec3& base, double r, double height, int segments, bool bottom_cap = true,
              bool top_cap = true) {
    frustum(b, base, r, r, height, segments, bottom_cap, top_cap);
}

// Seeded random numbers, one stream per use so adding a draw never shifts another.
struct Random {
    std::uint64_t seed;
    double operator()(std::uint64_t stream, std::uint64_t counter) const { return uniform01(seed, stream, counter); }
    double range(std::uint64_t stream, std::uint64_t counter, double lo, double hi) const {
        return lo + (hi - lo) * (*this)(stream, counter);
    }
};

Material material(const char* name, const dvec3& colour, const dvec3& emission = dvec3(0.0), bool two_sided = false) {
    Material m;
    m.name = name;
    m.base_color = colour;
    m.emission = emission;
    m.double_sided = two_sided;
    return m;
}

// A level of detail per object: floor(level + u) with u its seeded uniform, so raising the level
// upgrades objects one at a time and the count grows in steps of one object's increment.
int detail_of(double level, double u) {
    return int(std::floor(level + u));
}

// ---------------------------------------------------------------------------------------------
// City: metres, y up; blocks of kBlock² on a kBlock + kStreet pitch.

constexpr double kBlock = 60.0, kStreet = 16.0, kPitch = kBlock + kStreet;
constexpr double kStorey = 3.5, kCurb = 0.15;
constexpr double kWindowInset = 0.25, kLedgeDepth = 0.25, kLedgeHeight = 0.2;
constexpr double kParapetHeight = 1.0, kParapetThickness = 0.3;

enum CityMaterial : std::uint32_t { kAsphalt, kPavement, kConcrete, kBrick, kSandstone, kGlass, kRoof, kSky };
enum CityStream : std::uint64_t { kLotW = 1, kLotD, kFloors, kFacade, kCityDetail, kUnits, kUnitSize, kTank };

std::vector<Material> city_materials() {
    return {material("asphalt", dvec3(0.12)),
            material("pavement", dvec3(0.45, 0.44, 0.42)),
            material("concrete", dvec3(0.6, 0.6, 0.58)),
            material("brick", dvec3(0.5, 0.27, 0.2)),
            material("sandstone", dvec3(0.7, 0.6, 0.45)),
            material("glass", dvec3(0.08, 0.1, 0.12)),
            material("roof", dvec3(0.35, 0.34, 0.33)),
            material("sky", dvec3(0.0), dvec3(1.0))};
}

// One facade of a building: the wall's plane spans o + u·[0, 1] + y·[0, height]; `out` is its
// outward normal. Detail 0 is a plain wall, one quad per storey; from 1, each storey has
// `columns` window cells (frame quads around an inset pane: 18 triangles a cell).
void facade(Builder& b, const dvec3& o, const dvec3& u, const dvec3& out, int floors, int columns,
            std::uint32_t wall) {
    const dvec3 up(0, kStorey, 0);
    if (columns == 0) {
        b.material(wall);
        quad_grid(b, o, u, up * double(floors), 1, floors);
        return;
    }
    const dvec3 cu = u / double(columns), in = -out * kWindowInset;
    // The pane's corners as fractions of its cell.
    constexpr double u0 = 0.25, u1 = 0.75, v0 = 0.22, v1 = 0.78;
    for (int f = 0; f < floors; ++f)
        for (int c = 0; c < columns; ++c) {
            const dvec3 cell = o + up * double(f) + cu * double(c);
            const auto p = [&](double s, double t) { return cell + cu * s + up * t; };
            b.material(wall);
            b.quad(p(0, 0), p(1, 0), p(1, v0), p(0, v0));    // sill band
            b.quad(p(0, v1), p(1, v1), p(1, 1), p(0, 1));    // lintel band
            b.quad(p(0, v0), p(u0, v0), p(u0, v1), p(0, v1));  // left pier
            b.quad(p(u1, v0), p(1, v0), p(1, v1), p(u1, v1));  // right pier
            // The reveal: four sides of the recess, facing into the opening.
            b.quad_facing(p(u0, v0), p(u0, v0) + in, p(u0, v1) + in, p(u0, v1), cu);
            b.quad_facing(p(u1, v0), p(u1, v1), p(u1, v1) + in, p(u1, v0) + in, -cu);
            b.quad_facing(p(u0, v0), p(u1, v0), p(u1, v0) + in, p(u0, v0) + in, up);
            b.quad_facing(p(u0, v1), p(u0, v1) + in, p(u1, v1) + in, p(u1, v1), -up);
            b.material(kGlass);
            b.quad(p(u0, v0) + in, p(u1, v0) + in, p(u1, v1) + in, p(u0, v1) + in);
        }
}

// A band around the footprint [lo, hi] (x, z) from y0 to y1, standing `depth` out of it (a ledge)
// or in from it (a parapet, depth < 0). The x-side slabs run the full length; the z-side ones fit
// between them, so no two faces overlap. Faces against the wall, or resting on a roof, are left off.
void band(Builder& b, const dvec3& lo, const dvec3& hi, double y0, double y1, double depth, bool bottom) {
    const unsigned under = bottom ? kBottom : 0u;
    if (depth > 0.0) {
        const double d = depth;
        box(b, {lo.x - d, y0, lo.z - d}, {lo.x, y1, hi.z + d}, kLowX | kTop | kLowZ | kHighZ | under);
        box(b, {hi.x, y0, lo.z - d}, {hi.x + d, y1, hi.z + d}, kHighX | kTop | kLowZ | kHighZ | under);
        box(b, {lo.x, y0, lo.z - d}, {hi.x, y1, lo.z}, kLowZ | kTop | under);
        box(b, {lo.x, y0, hi.z}, {hi.x, y1, hi.z + d}, kHighZ | kTop | under);
    } else {
        const double d = -depth;
        box(b, {lo.x, y0, lo.z}, {lo.x + d, y1, hi.z}, kAllFaces & ~kBottom);
        box(b, {hi.x - d, y0, lo.z}, {hi.x, y1, hi.z}, kAllFaces & ~kBottom);
        box(b, {lo.x + d, y0, lo.z}, {hi.x - d, y1, lo.z + d}, kTop | kLowZ | kHighZ);
        box(b, {lo.x + d, y0, hi.z - d}, {hi.x - d, y1, hi.z}, kTop | kLowZ | kHighZ);
    }
}

struct CityLayout {
    int blocks;    // n: n × n blocks
    double level;  // detail level (see detail_of)
    // Quads of the street grid; 0 for the coarsest, one a block pitch. Finer paving takes up what
    // the level cannot reach: one building's upgrade is thousands of triangles.
    int ground_u = 0, ground_v = 0;
};

void build_city(Builder& b, const CityLayout& l, const Random& rnd, double* sky_height) {
    const int n = l.blocks;
    const double extent = n * kPitch + kStreet;  // streets on every side
    const double o = -0.5 * extent;              // the city is centred on the origin
    double tallest = 0.0;

    // Ground: streets everywhere, one quad per block pitch (the pads cover the rest).
    b.object("ground", Builder::kNoIndex);
    b.material(kAsphalt);
    const double margin = kPitch;
    quad_grid(b, {o - margin, 0, o - margin}, {0, 0, extent + 2 * margin}, {extent + 2 * margin, 0, 0},
              std::max(l.ground_u, n + 2), std::max(l.ground_v, n + 2));

    // The sky lid's node; its two triangles come after the buildings' heights are known (add_sky).
    b.object("sky", Builder::kNoIndex);

    std::size_t building = 0;
    for (int bz = 0; bz < n; ++bz)
        for (int bx = 0; bx < n; ++bx) {
            const double x0 = o + kStreet + bx * kPitch, z0 = o + kStreet + bz * kPitch;
            b.object("block", std::size_t(bz * n + bx));
            b.material(kPavement);
            box(b, {x0, 0, z0}, {x0 + kBlock, kCurb, z0 + kBlock}, kAllFaces & ~kBottom, 2);
            // Four lots of kBlock/2 each, a building per lot, towers near the centre.
            const double centre_bonus = 1.0 - std::hypot(bx + 0.5 - 0.5 * n, bz + 0.5 - 0.5 * n) / (0.75 * n + 1.0);
            for (int lot = 0; lot < 4; ++lot, ++building) {
                const std::uint64_t k = building;
                const double w = rnd.range(kLotW, k, 14.0, 26.0), d = rnd.range(kLotD, k, 14.0, 26.0);
                const double cx = x0 + kBlock * (0.25 + 0.5 * (lot % 2)), cz = z0 + kBlock * (0.25 + 0.5 * (lot / 2));
                const int floors = 3 + int(std::floor(rnd(kFloors, k) * (6.0 + 16.0 * std::max(0.0, centre_bonus))));
                const std::uint32_t wall = kConcrete + std::uint32_t(rnd(kFacade, k) * 3.0);
                const int detail = detail_of(l.level, rnd(kCityDetail, k));
                const dvec3 lo(cx - 0.5 * w, kCurb, cz - 0.5 * d), hi(cx + 0.5 * w, kCurb + floors * kStorey, cz + 0.5 * d);
                tallest = std::max(tallest, hi.y + kParapetHeight);

                b.object("building", building);
                // Window columns per face: about one per 6 m at detail 1, one more per 6 m a level.
                const auto columns = [&](double length) {
                    return detail == 0 ? 0 : std::max(1, int(std::lround(length / 6.0 * (1.0 + 0.5 * (detail - 1)))));
                };
                const dvec3 X(w, 0, 0), Z(0, 0, d);
                facade(b, lo, Z, {-1, 0, 0}, floors, columns(d), wall);
                facade(b, {hi.x, lo.y, hi.z}, -Z, {1, 0, 0}, floors, columns(d), wall);
                facade(b, {hi.x, lo.y, lo.z}, -X, {0, 0, -1}, floors, columns(w), wall);
                facade(b, {lo.x, lo.y, hi.z}, X, {0, 0, 1}, floors, columns(w), wall);
                b.material(wall);
                if (detail >= 1)  // a ledge at every storey line above the ground floor
                    for (int f = 1; f < floors; ++f) {
                        const double y = lo.y + f * kStorey;
                        band(b, lo, hi, y - 0.5 * kLedgeHeight, y + 0.5 * kLedgeHeight, kLedgeDepth, true);
                    }
                b.material(kRoof);
                const int roof_cuts = 1 + detail;
                quad_grid(b, {lo.x, hi.y, lo.z}, Z, X, roof_cuts, roof_cuts);
                if (detail >= 1) {
                    b.material(wall);
                    band(b, lo, hi, hi.y, hi.y + kParapetHeight, -kParapetThickness, false);
                    // Roof units (plant rooms, vents) and a water tank, resting on the roof.
                    b.material(kRoof);
                    const int units = 1 + int(rnd(kUnits, k) * 3.0);
                    for (int u = 0; u < units; ++u) {
                        const double s = rnd.range(kUnitSize, k * 8 + u, 1.5, 3.5);
                        const double ux = lo.x + 2.0 + (w - 4.0 - s) * rnd(kUnitSize, k * 8 + u + 4);
                        const double uz = lo.z + 2.0 + (d - 4.0 - s) * (u + 0.5) / units;
                        box(b, {ux, hi.y, uz}, {ux + s, hi.y + 0.6 * s, uz + s}, kAllFaces & ~kBottom, detail);
                    }
                    if (rnd(kTank, k) < 0.5) {
                        b.material(kConcrete);
                        cylinder(b, {hi.x - 3.0, hi.y, hi.z - 3.0}, 1.2, 2.5, 8 + 4 * detail, false, true);
                    }
                }
            }
        }
    *sky_height = tallest + 20.0;
}

// The lid: one emissive quad over the city and its margin, facing down; a grid of cells so its
// patches are square.
void add_sky(Scene& scene, std::uint32_t node, double height, std::uint32_t primitive) {
    const double half = std::max(std::abs(scene.bbox_min.x), std::abs(scene.bbox_max.x));
    Triangle t;
    t.material = kSky;
    t.node = node;
    t.primitive = primitive;
    t.rho = {dvec3(0.0), dvec3(0.0), dvec3(0.0)};
    const dvec3 a(-half, height, -half), bb(half, height, -half), c(half, height, half), d(-half, height, half);
    t.p = {a, bb, c};  // x × z = -y: faces the ground
    scene.triangles.push_back(t);
    t.p = {a, c, d};
    scene.triangles.push_back(t);
}

// ---------------------------------------------------------------------------------------------
// Furniture: a hall of kCell² cells, 3 m high, 1 m of floor around them.

constexpr double kCell = 5.0, kHallHeight = 3.0, kHallMargin = 1.0;

enum FurnitureMaterial : std::uint32_t {
    kWall, kWood, kCeiling, kFabricBlue, kFabricRed, kFabricBeige, kDarkWood, kMetal, kBookA, kBookB, kBookC, kLamp
};
enum FurnitureStream : std::uint64_t { kCellKind = 1, kCellDetail, kFabric, kRound, kBooks, kBookH };

std::vector<Material> furniture_materials() {
    return {material("wall", dvec3(0.7, 0.68, 0.62)),
            material("floor", dvec3(0.45, 0.3, 0.18)),
            material("ceiling", dvec3(0.8)),
            material("fabric_blue", dvec3(0.18, 0.26, 0.5)),
            material("fabric_red", dvec3(0.55, 0.18, 0.13)),
            material("fabric_beige", dvec3(0.62, 0.56, 0.42)),
            material("dark_wood", dvec3(0.3, 0.18, 0.1)),
            material("metal", dvec3(0.5)),
            material("book_a", dvec3(0.6, 0.1, 0.1)),
            material("book_b", dvec3(0.12, 0.35, 0.15)),
            material("book_c", dvec3(0.75, 0.7, 0.55)),
            material("lamp", dvec3(0.8), dvec3(40.0, 34.0, 26.0))};
}

struct RoomLayout {
    int cells;     // n: n × n cells
    double level;  // detail level
};

// Closed room [lo, hi] with walls facing in, a grid of quads per wall (about one per `cell`).
void room_shell(Builder& b, const dvec3& lo, const dvec3& hi, double cell, std::uint32_t wall, std::uint32_t floor,
                std::uint32_t ceiling) {
    const dvec3 d = hi - lo;
    const dvec3 x(d.x, 0, 0), y(0, d.y, 0), z(0, 0, d.z);
    const int nx = std::max(1, int(std::lround(d.x / cell))), nz = std::max(1, int(std::lround(d.z / cell)));
    const int ny = std::max(1, int(std::lround(d.y / cell)));
    b.material(floor);
    quad_grid(b, lo, z, x, nz, nx);  // z × x = +y: up
    b.material(ceiling);
    quad_grid(b, lo + y, x, z, nx, nz);
    b.material(wall);
    quad_grid(b, lo, y, z, ny, nz);  // y × z = +x: into the room from x = lo
    quad_grid(b, lo + x, z, y, nz, ny);
    quad_grid(b, lo, x, y, nx, ny);  // x × y = +z
    quad_grid(b, lo + z, y, x, ny, nx);
}

// A chair at (cx, cz) facing +z when `turn` is 0, else rotated by quarter turns (sign of the back).
void chair(Builder& b, double cx, double cz, int facing, int segments, int cuts, std::uint32_t fabric) {
    // facing: 0 +z, 1 -z, 2 +x, 3 -x; the back stands on the opposite side.
    const double s = 0.22;  // half seat
    b.material(kDarkWood);
    for (const double lx : {-1.0, 1.0})
        for (const double lz : {-1.0, 1.0}) cylinder(b, {cx + lx * (s - 0.04), 0, cz + lz * (s - 0.04)}, 0.02, 0.43, segments, false, false);
    b.material(fabric);
    chamfered_box(b, {cx - s, 0.43, cz - s}, {cx + s, 0.49, cz + s}, 0.015, cuts);
    const double t = 0.03;
    dvec3 lo, hi;
    switch (facing) {
        case 0: lo = {cx - s, 0.49, cz - s}, hi = {cx + s, 0.95, cz - s + t}; break;
        case 1: lo = {cx - s, 0.49, cz + s - t}, hi = {cx + s, 0.95, cz + s}; break;
        case 2: lo = {cx - s, 0.49, cz - s}, hi = {cx - s + t, 0.95, cz + s}; break;
        default: lo = {cx + s - t, 0.49, cz - s}, hi = {cx + s, 0.95, cz + s}; break;
    }
    b.material(kDarkWood);
    chamfered_box(b, lo, hi, 0.01, cuts, false);  // the back rests on the seat
}

void dining_set(Builder& b, double cx, double cz, bool round, int segments, int cuts, std::uint32_t fabric) {
    b.material(kWood);
    if (round) {
        cylinder(b, {cx, 0.72, cz}, 0.6, 0.04, 2 * segments);
        b.material(kMetal);
        cylinder(b, {cx, 0.0, cz}, 0.05, 0.72, segments, false, false);
        cylinder(b, {cx, 0.0, cz}, 0.3, 0.02, 2 * segments, false, true);
    } else {
        chamfered_box(b, {cx - 0.8, 0.72, cz - 0.5}, {cx + 0.8, 0.76, cz + 0.5}, 0.012, cuts);
        b.material(kDarkWood);
        for (const double lx : {-1.0, 1.0})
            for (const double lz : {-1.0, 1.0})
                cylinder(b, {cx + lx * 0.72, 0, cz + lz * 0.42}, 0.03, 0.72, segments, false, false);
    }
    const double r = round ? 0.85 : 0.95;
    chair(b, cx, cz - r, 0, segments, cuts, fabric);
    chair(b, cx, cz + r, 1, segments, cuts, fabric);
    chair(b, cx - r - (round ? 0 : 0.25), cz, 2, segments, cuts, fabric);
    chair(b, cx + r + (round ? 0 : 0.25), cz, 3, segments, cuts, fabric);
}

void lounge(Builder& b, double cx, double cz, int segments, int cuts, std::uint32_t fabric) {
    // Sofa along -z, facing +z: base on short feet, back, arms, three seat cushions.
    const double z0 = cz - 1.4, w = 1.1;
    b.material(kDarkWood);
    for (const double fx : {-w + 0.08, w - 0.08})
        for (const double fz : {z0 + 0.08, z0 + 0.82}) cylinder(b, {cx + fx, 0, fz}, 0.03, 0.08, segments, false, false);
    b.material(fabric);
    chamfered_box(b, {cx - w, 0.08, z0}, {cx + w, 0.3, z0 + 0.9}, 0.03, cuts);
    chamfered_box(b, {cx - w, 0.3, z0}, {cx + w, 0.85, z0 + 0.22}, 0.05, cuts, false);
    for (const double side : {-1.0, 1.0})
        chamfered_box(b, {cx + side * w - (side > 0 ? 0.2 : 0), 0.3, z0 + 0.22},
                      {cx + side * w + (side < 0 ? 0.2 : 0), 0.6, z0 + 0.9}, 0.05, cuts, false);
    for (int c = 0; c < 3; ++c) {
        const double x = cx - w + 0.2 + c * (2 * w - 0.4) / 3.0;
        chamfered_box(b, {x + 0.01, 0.3, z0 + 0.23}, {x + (2 * w - 0.4) / 3.0 - 0.01, 0.42, z0 + 0.88}, 0.04, cuts, false);
    }
    // Coffee table: chamfered top on four legs.
    b.material(kWood);
    chamfered_box(b, {cx - 0.5, 0.4, cz - 0.1}, {cx + 0.5, 0.44, cz + 0.5}, 0.01, cuts);
    b.material(kMetal);
    for (const double lx : {-0.44, 0.44})
        for (const double lz : {-0.04, 0.44}) cylinder(b, {cx + lx, 0, cz + lz}, 0.015, 0.4, segments, false, false);
    // Armchair to the side, facing -x.
    const double ax = cx + 1.6, az = cz + 0.3;
    b.material(fabric);
    chamfered_box(b, {ax - 0.4, 0.0, az - 0.4}, {ax + 0.4, 0.4, az + 0.4}, 0.05, cuts, false);
    chamfered_box(b, {ax + 0.2, 0.4, az - 0.4}, {ax + 0.4, 0.9, az + 0.4}, 0.05, cuts, false);
    cylinder(b, {ax - 0.5, 0.0, az}, 0.12, 0.5, 2 * segments, false, true);  // a round side table (pouf)
}

void shelving(Builder& b, double cx, double cz, int segments, int cuts, int books, const Random& rnd,
              std::uint64_t k) {
    (void)segments;
    // Two units back to back along x, each 1.8 m wide, 2 m high, 0.35 m deep, 5 shelves.
    for (const double side : {-1.0, 1.0}) {
        const double z0 = side < 0 ? cz - 0.37 : cz + 0.02, z1 = z0 + 0.35;
        const double x0 = cx - 0.9, x1 = cx + 0.9;
        b.material(kDarkWood);
        chamfered_box(b, {x0, 0, z0}, {x0 + 0.03, 2.0, z1}, 0.005, cuts, false);
        chamfered_box(b, {x1 - 0.03, 0, z0}, {x1, 2.0, z1}, 0.005, cuts, false);
        for (int s = 0; s < 5; ++s) {
            const double y = 0.05 + s * 0.45;
            b.material(kDarkWood);
            chamfered_box(b, {x0 + 0.03, y, z0}, {x1 - 0.03, y + 0.025, z1}, 0.004, cuts);
            if (s == 4) break;  // the top shelf holds nothing
            // Books standing on the shelf, left to right, seeded heights and colours.
            double x = x0 + 0.05;
            const double width = (x1 - x0 - 0.1) / double(books);
            for (int i = 0; i < books; ++i, x += width) {
                const std::uint64_t id = (k * 16 + std::uint64_t(s) * 2 + (side > 0)) * 4096 + std::uint64_t(i);
                b.material(kBookA + std::uint32_t(rnd(kBooks, id) * 3.0));
                const double h = 0.2 + 0.18 * rnd(kBookH, id);
                box(b, {x + 0.003, y + 0.025, z0 + 0.04}, {x + width - 0.003, y + 0.025 + h, z1 - 0.02},
                    kAllFaces & ~kBottom);
            }
        }
    }
}

void build_furniture(Builder& b, const RoomLayout& l, const Random& rnd) {
    const int n = l.cells;
    const double half = 0.5 * n * kCell + kHallMargin;
    b.object("room", Builder::kNoIndex);
    room_shell(b, {-half, 0, -half}, {half, kHallHeight, half}, kCell, kWall, kWood, kCeiling);
    b.object("lamps", Builder::kNoIndex);
    // One lamp per cell: a puck below the ceiling with its underside emitting, on a cord.
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const double cx = -0.5 * n * kCell + (i + 0.5) * kCell, cz = -0.5 * n * kCell + (j + 0.5) * kCell;
            const int detail = detail_of(l.level, rnd(kCellDetail, std::uint64_t(j * n + i)));
            const int segments = 8 + 4 * detail;
            b.material(kLamp);
            const dvec3 base(cx, kHallHeight - 0.6, cz);
            for (int s = 0; s < segments; ++s) {  // the underside, facing down
                const double a0 = 2 * kPi * s / segments, a1 = 2 * kPi * (s + 1) / segments;
                b.triangle(base, base + dvec3(0.35 * std::cos(a0), 0, 0.35 * std::sin(a0)),
                           base + dvec3(0.35 * std::cos(a1), 0, 0.35 * std::sin(a1)));
            }
            b.material(kMetal);
            cylinder(b, base, 0.35, 0.08, segments, false, true);
            cylinder(b, base + dvec3(0, 0.08, 0), 0.006, 0.52, 6, false, false);  // the cord, to the ceiling
        }
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const std::uint64_t k = std::uint64_t(j * n + i);
            const double cx = -0.5 * n * kCell + (i + 0.5) * kCell, cz = -0.5 * n * kCell + (j + 0.5) * kCell;
            const int detail = detail_of(l.level, rnd(kCellDetail, k));
            const int segments = 8 + 4 * detail, cuts = 1 + detail / 3;
            const std::uint32_t fabric = kFabricBlue + std::uint32_t(rnd(kFabric, k) * 3.0);
            const double kind = rnd(kCellKind, k);
            b.object("furniture", k);
            if (kind < 0.45)
                dining_set(b, cx, cz, rnd(kRound, k) < 0.5, segments, cuts, fabric);
            else if (kind < 0.8)
                lounge(b, cx, cz, segments, cuts, fabric);
            else
                shelving(b, cx, cz, segments, cuts, 10 + 3 * detail, rnd, k);
        }
}

// ---------------------------------------------------------------------------------------------
// Foliage: a walled courtyard of kPlot² cells, 7 m high, skylight panels in the ceiling.

constexpr double kPlot = 6.0, kCourtHeight = 7.0, kCourtMargin = 1.5;

enum FoliageMaterial : std::uint32_t { kStone, kPaving, kCourtCeiling, kBark, kLeafDark, kLeafLight, kGrass, kPlanter, kSkylight };
enum FoliageStream : std::uint64_t {
    kTreeHeight = 1, kCardsWeight, kCardPos, kCardDir, kCardSpin, kBushPos, kTuftPos, kLeafShade, kFoliageDetail
};

std::vector<Material> foliage_materials() {
    return {material("stone", dvec3(0.55, 0.52, 0.48)),
            material("paving", dvec3(0.5, 0.47, 0.42)),
            material("ceiling", dvec3(0.6)),
            material("bark", dvec3(0.25, 0.17, 0.1)),
            material("leaf_dark", dvec3(0.1, 0.3, 0.07), dvec3(0.0), true),
            material("leaf_light", dvec3(0.25, 0.5, 0.12), dvec3(0.0), true),
            material("grass", dvec3(0.2, 0.42, 0.1), dvec3(0.0), true),
            material("planter", dvec3(0.45, 0.28, 0.2)),
            material("skylight", dvec3(0.8), dvec3(12.0))};
}

// A unit direction from two uniforms (uniform on the sphere).
dvec3 direction(double u, double v) {
    const double y = 2.0 * u - 1.0, r = std::sqrt(std::max(0.0, 1.0 - y * y)), phi = 2.0 * kPi * v;
    return {r * std::cos(phi), y, r * std::sin(phi)};
}

// `count` square cards of side `size` at seeded points of the ellipsoid (centre, radii), each
// turned to a seeded normal and spun about it; draws come from `id`'s range of counters.
void cards(Builder& b, const Random& rnd, std::uint64_t id, const dvec3& centre, const dvec3& radii, int count,
           double size) {
    if (b.counting()) return b.add_count(2 * std::size_t(std::max(count, 0)));
    for (int c = 0; c < count; ++c) {
        const std::uint64_t k = id * 65536 + std::uint64_t(c);
        // A point in the unit ball: a direction times the cube root of a uniform radius.
        const dvec3 at = centre + radii * direction(rnd(kCardPos, 3 * k), rnd(kCardPos, 3 * k + 1)) *
                                      std::cbrt(rnd(kCardPos, 3 * k + 2));
        const dvec3 nrm = direction(rnd(kCardDir, 2 * k), rnd(kCardDir, 2 * k + 1));
        const dvec3 helper = std::abs(nrm.y) < 0.9 ? dvec3(0, 1, 0) : dvec3(1, 0, 0);
        const dvec3 t0 = glm::normalize(glm::cross(helper, nrm)), t1 = glm::cross(nrm, t0);
        const double spin = 2.0 * kPi * rnd(kCardSpin, k);
        const dvec3 u = 0.5 * size * (std::cos(spin) * t0 + std::sin(spin) * t1);
        const dvec3 v = glm::cross(nrm, u);
        b.material(rnd(kLeafShade, k) < 0.5 ? kLeafDark : kLeafLight);
        b.quad(at - u - v, at + u - v, at + u + v, at - u + v);
    }
}

// A grass tuft: three vertical cards crossing at (x, z), standing on the ground.
void tuft(Builder& b, double x, double z, double h, double w, double turn) {
    b.material(kGrass);
    for (int c = 0; c < 3; ++c) {
        const double a = turn + c * kPi / 3.0;
        const dvec3 d(0.5 * w * std::cos(a), 0, 0.5 * w * std::sin(a));
        const dvec3 base(x, 0, z), top(0, h, 0);
        b.quad(base - d, base + d, base + d + top, base - d + top);
    }
}

void build_foliage(Builder& b, const RoomLayout& l, const Random& rnd) {
    const int n = l.cells;
    const double half = 0.5 * n * kPlot + kCourtMargin;
    b.object("courtyard", Builder::kNoIndex);
    room_shell(b, {-half, 0, -half}, {half, kCourtHeight, half}, kPlot, kStone, kPaving, kCourtCeiling);
    b.object("skylights", Builder::kNoIndex);
    b.material(kSkylight);
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            // A 3 m square panel just below the ceiling over every cell, facing down.
            const double cx = -0.5 * n * kPlot + (i + 0.5) * kPlot, cz = -0.5 * n * kPlot + (j + 0.5) * kPlot;
            const double y = kCourtHeight - 0.02, h = 1.5;
            b.quad({cx - h, y, cz - h}, {cx + h, y, cz - h}, {cx + h, y, cz + h}, {cx - h, y, cz + h});
        }
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const std::uint64_t k = std::uint64_t(j * n + i);
            const double cx = -0.5 * n * kPlot + (i + 0.5) * kPlot, cz = -0.5 * n * kPlot + (j + 0.5) * kPlot;
            // Cards per plant grow with the level; continuous, so the count fits finely.
            const double weight = 0.7 + 0.6 * rnd(kCardsWeight, k);
            const double cards_per = 20.0 * l.level * weight;
            // Larger cards when there are few, so the canopies look about as full at any count.
            const double shrink = std::clamp(std::sqrt(200.0 / std::max(cards_per, 1.0)), 0.3, 1.0);
            const int segments = 8 + 2 * std::min(24, int(l.level / 4.0));
            b.object("plant", k);
            // Planter (chamfered, open at the bottom), trunk from its soil up, three branches' worth
            // of canopy clusters.
            b.material(kPlanter);
            chamfered_box(b, {cx - 0.6, 0, cz - 0.6}, {cx + 0.6, 0.5, cz + 0.6}, 0.04, 1, false);
            // At most 4.8 m, so the crown (1.1 m, cards up to 0.64 m from their centres) stays
            // below the skylights.
            const double height = 2.8 + 2.0 * rnd(kTreeHeight, k);
            b.material(kBark);
            frustum(b, {cx, 0.5, cz}, 0.14, 0.07, height - 0.5, segments, false, true);
            const dvec3 crown(cx, height, cz);
            const int tree_cards = int(std::lround(cards_per * 0.6));
            cards(b, rnd, k * 8, crown, dvec3(1.6, 1.1, 1.6), tree_cards, 0.9 * shrink);
            // Two bushes in opposite corners of the cell and a ring of grass tufts.
            for (int bush = 0; bush < 2; ++bush) {
                const double bx = cx + (bush ? 1.0 : -1.0) * (1.6 + 0.5 * rnd(kBushPos, 4 * k + bush));
                const double bz = cz + (bush ? -1.0 : 1.0) * (1.6 + 0.5 * rnd(kBushPos, 4 * k + bush + 2));
                // Centred high enough that no card reaches through the floor.
                cards(b, rnd, k * 8 + 1 + bush, {bx, 0.95, bz}, dvec3(0.7, 0.45, 0.7),
                      int(std::lround(cards_per * 0.15)), 0.6 * shrink);
            }
            const int tufts = 4 + int(std::lround(cards_per * 0.02));
            for (int t = 0; t < tufts; ++t) {
                const double a = 2.0 * kPi * (t + rnd(kTuftPos, 3 * (k * 1024 + t))) / tufts;
                const double r = 0.9 + 0.4 * rnd(kTuftPos, 3 * (k * 1024 + t) + 1);
                tuft(b, cx + r * std::cos(a), cz + r * std::sin(a), 0.3 + 0.2 * rnd(kTuftPos, 3 * (k * 1024 + t) + 2),
                     0.25, a);
            }
        }
}

// ---------------------------------------------------------------------------------------------
// Fitting: the layout size n from the count, then the level by bisection on the counting builder.

// The level range searched; every kind's count grows steadily with the level over it.
double max_level(ContentKind kind) {
    return kind == ContentKind::kFoliage ? 4000.0 : 40.0;
}

// Triangles of kind at (n, level), counted without building.
using Counter = std::function<std::size_t(int, double)>;

struct Fit {
    int n = 1;
    double level = 0.0;  // the level whose count comes nearest the target
    double below = 0.0;  // the highest level found whose count is at most the target
};

Fit fit(std::size_t target, int n0, double top, const Counter& count) {
    int n = std::max(1, n0);
    while (n > 1 && count(n, 0.0) > target) --n;
    while (count(n, top) < target) ++n;
    double lo = 0.0, hi = top;
    for (int i = 0; i < 30; ++i) {
        const double mid = 0.5 * (lo + hi);
        (count(n, mid) <= target ? lo : hi) = mid;
    }
    const auto miss = [target](std::size_t got) { return got > target ? got - target : target - got; };
    return {n, miss(count(n, lo)) <= miss(count(n, hi)) ? lo : hi, lo};
}

int initial_layout(ContentKind kind, std::size_t triangles) {
    const double root = std::pow(double(triangles), 0.25);
    return std::max(1, int(std::lround(kind == ContentKind::kCity ? root / 3.0 : root / 2.5)));
}

void set_bounds(Scene& s) {
    s.bbox_min = dvec3(1e300), s.bbox_max = dvec3(-1e300);
    for (const Triangle& t : s.triangles)
        for (const dvec3& p : t.p) s.bbox_min = glm::min(s.bbox_min, p), s.bbox_max = glm::max(s.bbox_max, p);
}

Camera look(const char* name, const dvec3& eye, const dvec3& target, double yfov) {
    Camera c;
    c.name = name;
    c.camera_to_world = glm::inverse(glm::lookAt(eye, target, dvec3(0.0, 1.0, 0.0)));
    c.yfov = yfov;
    c.aspect = 1.5;
    return c;
}

}  // namespace

const char* content_kind_name(ContentKind kind) {
    switch (kind) {
        case ContentKind::kCity: return "city";
        case ContentKind::kFurniture: return "furniture";
        case ContentKind::kFoliage: return "foliage";
    }
    return "?";
}

bool content_kind_closed(ContentKind kind) {
    return kind != ContentKind::kCity;
}

Scene content_scene(ContentKind kind, std::size_t triangles, std::uint64_t seed) {
    const Random rnd{seed};
    const auto build = [&](Builder& b, int n, double level) {
        double sky = 0.0;
        switch (kind) {
            case ContentKind::kCity: build_city(b, {n, level}, rnd, &sky); break;
            case ContentKind::kFurniture: build_furniture(b, {n, level}, rnd); break;
            case ContentKind::kFoliage: build_foliage(b, {n, level}, rnd); break;
        }
        // The city's sky lid: two triangles, added after the buildings' heights are known.
        return kind == ContentKind::kCity ? std::size_t(2) : std::size_t(0);
    };
    const Fit f = fit(triangles, initial_layout(kind, triangles), max_level(kind), [&](int n, double level) {
        Builder counter(nullptr);
        const std::size_t extra = build(counter, n, level);
        return counter.count() + extra;
    });

    Scene scene;
    scene.path = fmt::format("{}:{}", content_kind_name(kind), count_label(triangles));
    switch (kind) {
        case ContentKind::kCity: scene.materials = city_materials(); break;
        case ContentKind::kFurniture: scene.materials = furniture_materials(); break;
        case ContentKind::kFoliage: scene.materials = foliage_materials(); break;
    }
    Builder builder(&scene);
    if (kind == ContentKind::kCity) {
        // The level from below, then finer street paving for the rest (within 2 × its rows).
        CityLayout layout{f.n, f.below};
        Builder counter(nullptr);
        double sky = 0.0;
        build_city(counter, layout, rnd, &sky);
        const std::size_t coarse = std::size_t(f.n + 2) * std::size_t(f.n + 2);
        const std::size_t short_by = triangles > counter.count() + 2 ? triangles - counter.count() - 2 : 0;
        const std::size_t quads = coarse + short_by / 2;
        layout.ground_u = int(std::ceil(std::sqrt(double(quads))));
        layout.ground_v = int(std::lround(double(quads) / layout.ground_u));
        build_city(builder, layout, rnd, &sky);
        set_bounds(scene);
        add_sky(scene, 1, sky, 1'000'000'000u);
    } else {
        build(builder, f.n, f.level);
    }
    set_bounds(scene);

    const dvec3 lo = scene.bbox_min, hi = scene.bbox_max, mid = 0.5 * (lo + hi);
    switch (kind) {
        case ContentKind::kCity: {
            // Over the ground's margin by a corner, below the lid, looking down the diagonal over
            // the rooftops (the ground reaches a block pitch past the outer streets).
            const double edge = hi.x - 0.9 * kPitch;
            scene.cameras.push_back(
                look("aerial", {-edge, 0.85 * hi.y, -edge}, {0.2 * edge, 0.0, 0.2 * edge}, 0.9));
            break;
        }
        case ContentKind::kFurniture:
        case ContentKind::kFoliage: {
            // Near a corner, head height, looking across to the opposite corner.
            const double h = 0.5 * (hi.x - lo.x), eye_y = kind == ContentKind::kFurniture ? 1.7 : 2.2;
            scene.cameras.push_back(
                look("overview", {lo.x + 0.3, eye_y, lo.z + 0.3}, {mid.x + 0.2 * h, 0.6, mid.z + 0.2 * h}, 1.0));
            break;
        }
    }
    return scene;
}

std::optional<ContentSpec> parse_content_spec(const std::string& spec) {
    for (const ContentKind kind : {ContentKind::kCity, ContentKind::kFurniture, ContentKind::kFoliage})
        if (const auto n = parse_count_spec(spec, std::string(content_kind_name(kind)) + ":")) return ContentSpec{kind, *n};
    return std::nullopt;
}

std::optional<Scene> generated_scene(const std::string& spec, bool* closed, std::uint64_t seed) {
    if (const auto n = parse_procedural_spec(spec)) {
        if (closed) *closed = true;
        return procedural_scene(*n, seed);
    }
    if (const auto c = parse_content_spec(spec)) {
        if (closed) *closed = content_kind_closed(c->kind);
        return content_scene(c->kind, c->triangles, seed);
    }
    return std::nullopt;
}

}  // namespace hemirad::gen
