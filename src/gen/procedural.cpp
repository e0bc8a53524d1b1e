// Procedural benchmark scenes: a closed room, a ceiling light and a grid of boxes and ellipsoids,
// tessellated so the whole scene has about the requested number of triangles.
#include "gen/procedural.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <numeric>
#include <tuple>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/rng.h"

namespace hemirad::gen {

using namespace hemirad::scene;
namespace {

using glm::dvec3;

// The room, metres, y up: x in [-5, 5], y in [0, 4], z in [-5, 5].
constexpr double kRoomHalfWidth = 5.0;
constexpr double kRoomHeight = 4.0;
// Objects stand on [-4, 4]² so a 1 m walkway is left along the walls and nothing touches them.
constexpr double kGridHalfWidth = 4.0;
// The light: a 2.5 m square panel just below the ceiling, facing down. The gap keeps it off the
// ceiling's plane (coplanar faces would fight in the hemicube's depth test).
constexpr double kLightHalfWidth = 1.25;
constexpr double kLightGap = 0.02;
constexpr double kLightEmission = 10.0;

// Object sizes as fractions of the grid cell: footprints are fixed so the floor area covered is
// the same for every grid size; heights vary with the seed.
constexpr double kFootprint = 0.6;  // box side, ellipsoid diameter
constexpr double kJitter = 0.1;     // largest centre offset, each way
constexpr double kBoxHeightMin = 0.4, kBoxHeightRange = 0.4;
constexpr double kEllipsoidHeightMin = 0.25, kEllipsoidHeightRange = 0.15;  // vertical semi-axis
// Boxes stand this far (metres) above the floor. A bottom face lying in the floor's plane would
// look straight out of the room (its hemisphere is all below the floor), so a shot from it
// would see nothing; lifted, it sees the floor and every shot has a closed surround.
constexpr double kBoxLift = 0.001;
// A third of the objects are boxes: flat faces the mesher can pair into quads, and sharp
// contact shadows; the rest are ellipsoids, whose curvature makes every quad its own patch.
constexpr int kBoxShare = 3;

constexpr std::size_t kShellTriangles = 14;  // 6 walls and the light, 2 triangles each
constexpr int kMinGrid = 2;
constexpr int kMaxGrid = 99;  // at most 99² object nodes
// Cells are emitted in kTile × kTile blocks so runs of consecutive triangles stay compact.
constexpr int kTile = 4;

enum MaterialIndex : std::uint32_t { kGrey, kRed, kGreen, kLight };
enum NodeIndex : std::uint32_t { kRoomNode, kLightNode, kFirstObjectNode };
constexpr std::uint32_t kLightPrimitive = 6;  // after the 6 walls
constexpr std::uint32_t kFirstObjectPrimitive = 7;

// Streams for uniform01: one per kind of random choice, so adding one never shifts another.
enum Stream : std::uint64_t { kStreamKind = 1, kStreamColour, kStreamJitterX, kStreamJitterZ, kStreamHeight };

// How many objects and how finely each is tessellated.
struct Plan {
    int grid = kMinGrid;    // G: G × G objects
    std::size_t boxes = 0;  // how many of them are boxes; the rest are ellipsoids
    int box_cuts = 1;       // k: each box face is a k × k grid of quads
    int segments = 4;       // ellipsoid: quads around (>= 4)
    int rings = 2;          // ellipsoid: bands from pole to pole (>= 2; the polar bands are fans)
    std::size_t total = 0;  // triangles in all
};

std::size_t box_triangles(int cuts) {
    return 12 * std::size_t(cuts) * std::size_t(cuts);
}

std::size_t ellipsoid_triangles(int segments, int rings) {
    return 2 * std::size_t(segments) * std::size_t(rings - 1);
}

// Segments and rings whose triangle count is nearest `budget`, with segments kept within
// [1.5, 2.5] × rings so quads stay roughly square at the equator; ties go to the squarest.
std::pair<int, int> fit_ellipsoid(double budget) {
    int best_s = 4, best_r = 2;
    double best_err = std::abs(double(ellipsoid_triangles(4, 2)) - budget);
    int best_skew = 0;
    for (int r = 2; r < 100000; ++r) {
        const int s_min = std::max(4, (3 * r + 1) / 2), s_max = std::max(s_min, 5 * r / 2);
        if (double(ellipsoid_triangles(s_min, r)) - budget > best_err) break;  // counts only grow with r
        for (int s = s_min; s <= s_max; ++s) {
            const double err = std::abs(double(ellipsoid_triangles(s, r)) - budget);
            const int skew = std::abs(s - 2 * r);
            if (err < best_err || (err == best_err && skew < best_skew)) {
                best_s = s, best_r = r, best_err = err, best_skew = skew;
            }
        }
    }
    return {best_s, best_r};
}

// Boxes take at most the average share (a k × k grid only comes in coarse steps); the
// ellipsoids, whose counts come in fine steps, absorb the rest.
Plan plan_for_grid(std::size_t triangles, int grid) {
    Plan p;
    p.grid = grid;
    const std::size_t objects = std::size_t(grid) * std::size_t(grid);
    p.boxes = objects / kBoxShare;
    const std::size_t ellipsoids = objects - p.boxes;
    const double available = triangles > kShellTriangles ? double(triangles - kShellTriangles) : 0.0;
    p.box_cuts = std::max(1, int(std::floor(std::sqrt(available / double(objects) / 12.0))));
    const double left = available - double(p.boxes * box_triangles(p.box_cuts));
    std::tie(p.segments, p.rings) = fit_ellipsoid(left / double(ellipsoids));
    p.total =
        kShellTriangles + p.boxes * box_triangles(p.box_cuts) + ellipsoids * ellipsoid_triangles(p.segments, p.rings);
    return p;
}

// G near the fourth root of the count, so the number of objects and the triangles per object
// both grow as its square root (1M: ~32² objects of ~1000 triangles); a neighbouring G is taken
// only when it comes strictly closer to the request.
Plan make_plan(std::size_t triangles) {
    const int g0 = std::clamp(int(std::lround(std::pow(double(triangles), 0.25))), kMinGrid, kMaxGrid);
    Plan best = plan_for_grid(triangles, g0);
    const auto error = [triangles](const Plan& p) {
        return p.total > triangles ? p.total - triangles : triangles - p.total;
    };
    for (const int g : {g0 - 1, g0 + 1}) {
        if (g < kMinGrid || g > kMaxGrid) continue;
        const Plan p = plan_for_grid(triangles, g);
        if (error(p) < error(best)) best = p;
    }
    return best;
}

std::vector<Material> make_materials() {
    std::vector<Material> m(4);
    m[kGrey].name = "grey";
    m[kGrey].base_color = dvec3(0.65);
    m[kRed].name = "red";
    m[kRed].base_color = dvec3(0.63, 0.065, 0.05);
    m[kGreen].name = "green";
    m[kGreen].base_color = dvec3(0.14, 0.45, 0.09);
    m[kLight].name = "light";
    m[kLight].base_color = dvec3(0.78);
    m[kLight].emission = dvec3(kLightEmission);
    return m;
}

// Calls f(i, j) for every cell of an nu × nv grid, kTile × kTile blocks at a time.
template <typename F>
void for_each_cell_tiled(int nu, int nv, F&& f) {
    for (int j0 = 0; j0 < nv; j0 += kTile)
        for (int i0 = 0; i0 < nu; i0 += kTile)
            for (int j = j0; j < std::min(j0 + kTile, nv); ++j)
                for (int i = i0; i < std::min(i0 + kTile, nu); ++i) f(i, j);
}

// Appends triangles that share material, node and primitive.
struct Emitter {
    std::vector<Triangle>& out;
    Triangle proto;

    Emitter(std::vector<Triangle>& triangles, const std::vector<Material>& materials, std::uint32_t material,
            std::uint32_t node, std::uint32_t primitive)
        : out(triangles) {
        const dvec3 rho = materials[material].base_color;
        proto.rho = {rho, rho, rho};
        proto.material = material;
        proto.node = node;
        proto.primitive = primitive;
    }

    void triangle(const dvec3& a, const dvec3& b, const dvec3& c) {
        proto.p = {a, b, c};
        out.push_back(proto);
    }
    // A planar convex quad, counter-clockwise from the front, split along a–c.
    void quad(const dvec3& a, const dvec3& b, const dvec3& c, const dvec3& d) {
        triangle(a, b, c);
        triangle(a, c, d);
    }
};

// Coordinates of cuts + 1 evenly spaced planes from lo to hi, the ends exact, so faces that
// meet at a box edge take bit-identical vertices from the same table.
std::vector<double> cut_planes(double lo, double hi, int cuts) {
    std::vector<double> t(std::size_t(cuts) + 1);
    for (int i = 0; i <= cuts; ++i) t[std::size_t(i)] = lo + (hi - lo) * (double(i) / double(cuts));
    t.front() = lo;
    t.back() = hi;
    return t;
}

// One face of the box [lo, hi] (axis `axis`, at hi when `high`), as a cuts × cuts grid of quads
// facing out of the box, or into it when `inward`.
void box_face(Emitter& e, const std::array<std::vector<double>, 3>& planes, int axis, bool high, bool inward) {
    // u × v must point along the outward normal: cyclic axis order on the high side, swapped on the low.
    int u = (axis + 1) % 3, v = (axis + 2) % 3;
    if (!high) std::swap(u, v);
    const double w = high ? planes[std::size_t(axis)].back() : planes[std::size_t(axis)].front();
    const std::vector<double>& pu = planes[std::size_t(u)];
    const std::vector<double>& pv = planes[std::size_t(v)];
    const auto at = [&](int i, int j) {
        dvec3 p;
        p[axis] = w;
        p[u] = pu[std::size_t(i)];
        p[v] = pv[std::size_t(j)];
        return p;
    };
    for_each_cell_tiled(int(pu.size()) - 1, int(pv.size()) - 1, [&](int i, int j) {
        if (inward)
            e.quad(at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j));
        else
            e.quad(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
    });
}

void add_room(Scene& scene) {
    const dvec3 lo(-kRoomHalfWidth, 0.0, -kRoomHalfWidth), hi(kRoomHalfWidth, kRoomHeight, kRoomHalfWidth);
    const std::array<std::vector<double>, 3> planes{cut_planes(lo.x, hi.x, 1), cut_planes(lo.y, hi.y, 1),
                                                    cut_planes(lo.z, hi.z, 1)};
    std::uint32_t primitive = 0;
    for (int axis = 0; axis < 3; ++axis) {
        for (const bool high : {false, true}) {
            // One coloured wall (x = -5) so colour bleeding shows up in renders.
            const std::uint32_t material = axis == 0 && !high ? kRed : kGrey;
            Emitter e(scene.triangles, scene.materials, material, kRoomNode, primitive++);
            box_face(e, planes, axis, high, /*inward=*/true);
        }
    }
    Emitter light(scene.triangles, scene.materials, kLight, kLightNode, kLightPrimitive);
    const double y = kRoomHeight - kLightGap, h = kLightHalfWidth;
    light.quad({-h, y, -h}, {h, y, -h}, {h, y, h}, {-h, y, h});  // x × z = -y: faces the floor
}

// A unit sphere's vertices, poles on the y axis: north pole, rings 1 … rings-1 of `segments`
// each, south pole. Shared by every ellipsoid, which scale and move it.
std::vector<dvec3> unit_sphere(int segments, int rings) {
    std::vector<dvec3> v;
    v.reserve(std::size_t(segments) * std::size_t(rings - 1) + 2);
    v.emplace_back(0.0, 1.0, 0.0);
    for (int b = 1; b < rings; ++b) {
        const double theta = glm::pi<double>() * double(b) / double(rings);
        for (int j = 0; j < segments; ++j) {
            const double phi = 2.0 * glm::pi<double>() * double(j) / double(segments);
            v.emplace_back(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
        }
    }
    v.emplace_back(0.0, -1.0, 0.0);
    return v;
}

// How much to widen a coarse UV sphere so the polygon it shows from above has the area of the
// circle it stands for: a 6-segment one would otherwise cover 17% less floor than a fine one,
// and coverage would change with the count. At most ~1.33 (5 segments, 3 rings), which keeps
// even a jittered ellipsoid inside its cell.
double footprint_correction(int segments, int rings) {
    double widest = 0.0;  // the equator when rings is even, else the two rings beside it
    for (int b = 1; b < rings; ++b) widest = std::max(widest, std::sin(glm::pi<double>() * double(b) / double(rings)));
    const double polygon = 0.5 * double(segments) * std::sin(2.0 * glm::pi<double>() / double(segments));
    return std::sqrt(glm::pi<double>() / polygon) / widest;
}

// An ellipsoid from a UV sphere: lat-long quads stay planar isosceles trapezoids under the
// axis scaling, so the mesher can pair them; polar bands are triangle fans.
void add_ellipsoid(Emitter& e, const std::vector<dvec3>& unit, int segments, int rings, const dvec3& centre,
                   const dvec3& radii, std::vector<dvec3>& scratch) {
    scratch.resize(unit.size());
    for (std::size_t k = 0; k < unit.size(); ++k) scratch[k] = centre + radii * unit[k];
    const dvec3& north = scratch.front();
    const dvec3& south = scratch.back();
    // Ring b (1 … rings-1), segment j, wrapping around so the seam shares vertices exactly.
    const auto at = [&](int b, int j) -> const dvec3& {
        return scratch[1 + std::size_t(b - 1) * std::size_t(segments) + std::size_t(j % segments)];
    };
    // Band b lies between rings b and b + 1; with φ growing towards +z and θ towards -y,
    // (b, j), (b, j+1), (b+1, j+1), (b+1, j) is counter-clockwise seen from outside.
    for_each_cell_tiled(segments, rings, [&](int j, int b) {
        if (b == 0)
            e.triangle(north, at(1, j + 1), at(1, j));
        else if (b == rings - 1)
            e.triangle(at(b, j), at(b, j + 1), south);
        else
            e.quad(at(b, j), at(b, j + 1), at(b + 1, j + 1), at(b + 1, j));
    });
}

void add_objects(Scene& scene, const Plan& plan, std::uint64_t seed) {
    const int g = plan.grid;
    const std::size_t count = std::size_t(g) * std::size_t(g);
    const double cell = 2.0 * kGridHalfWidth / double(g);

    // Exactly plan.boxes boxes, at seeded places: the count must not depend on the seed.
    std::vector<std::size_t> order(count);
    std::iota(order.begin(), order.end(), std::size_t(0));
    std::vector<double> key(count);
    for (std::size_t k = 0; k < count; ++k) key[k] = uniform01(seed, kStreamKind, k);
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return key[a] != key[b] ? key[a] < key[b] : a < b; });
    std::vector<char> is_box(count, 0);
    for (std::size_t k = 0; k < plan.boxes; ++k) is_box[order[k]] = 1;

    const std::vector<dvec3> unit = unit_sphere(plan.segments, plan.rings);
    const double widen = footprint_correction(plan.segments, plan.rings);
    std::vector<dvec3> scratch;
    for (int row = 0; row < g; ++row) {
        for (int col = 0; col < g; ++col) {
            const std::size_t k = std::size_t(row) * std::size_t(g) + std::size_t(col);
            const double colour = uniform01(seed, kStreamColour, k);
            const std::uint32_t material = colour < 0.5 ? kGrey : colour < 0.75 ? kGreen : kRed;
            const double jitter_x = kJitter * (2.0 * uniform01(seed, kStreamJitterX, k) - 1.0);
            const double jitter_z = kJitter * (2.0 * uniform01(seed, kStreamJitterZ, k) - 1.0);
            const double x = -kGridHalfWidth + cell * (col + 0.5 + jitter_x);
            const double z = -kGridHalfWidth + cell * (row + 0.5 + jitter_z);
            const double height = uniform01(seed, kStreamHeight, k);
            const double half = 0.5 * kFootprint * cell;

            const auto node = std::uint32_t(scene.nodes.size());
            scene.nodes.push_back({fmt::format("object_{}_{}", row, col), -1});
            Emitter e(scene.triangles, scene.materials, material, node, kFirstObjectPrimitive + std::uint32_t(k));
            if (is_box[k]) {
                const double top = kBoxLift + cell * (kBoxHeightMin + kBoxHeightRange * height);
                const std::array<std::vector<double>, 3> planes{cut_planes(x - half, x + half, plan.box_cuts),
                                                                cut_planes(kBoxLift, top, plan.box_cuts),
                                                                cut_planes(z - half, z + half, plan.box_cuts)};
                for (int axis = 0; axis < 3; ++axis)
                    for (const bool high : {false, true}) box_face(e, planes, axis, high, /*inward=*/false);
            } else {
                // Resting on the floor at its south pole: a point contact, no face in the floor's plane.
                const double ry = cell * (kEllipsoidHeightMin + kEllipsoidHeightRange * height);
                const double r = widen * half;
                add_ellipsoid(e, unit, plan.segments, plan.rings, dvec3(x, ry, z), dvec3(r, ry, r), scratch);
            }
        }
    }
}

// From the middle of the +z wall, eye height, looking across the objects to the red wall's corner.
Camera make_camera() {
    Camera c;
    c.name = "overview";
    const dvec3 eye(0.0, 2.2, kRoomHalfWidth - 0.1), target(0.0, 0.6, -1.0);
    c.camera_to_world = glm::inverse(glm::lookAt(eye, target, dvec3(0.0, 1.0, 0.0)));
    c.yfov = 1.0;
    c.aspect = 1.5;
    return c;
}

}  // namespace

std::string count_label(std::size_t n) {
    if (n % 1'000'000 == 0) return fmt::format("{}M", n / 1'000'000);
    if (n % 1'000 == 0) return fmt::format("{}k", n / 1'000);
    return fmt::format("{}", n);
}

Scene procedural_scene(std::size_t triangles, std::uint64_t seed) {
    const Plan plan = make_plan(triangles);
    Scene scene;
    scene.path = "procedural:" + count_label(triangles);
    scene.materials = make_materials();
    scene.nodes.reserve(std::size_t(kFirstObjectNode) + std::size_t(plan.grid) * std::size_t(plan.grid));
    scene.nodes.push_back({"room", -1});
    scene.nodes.push_back({"light", -1});
    scene.triangles.reserve(plan.total);
    add_room(scene);
    add_objects(scene, plan, seed);
    scene.cameras.push_back(make_camera());
    // The room encloses everything.
    scene.bbox_min = dvec3(-kRoomHalfWidth, 0.0, -kRoomHalfWidth);
    scene.bbox_max = dvec3(kRoomHalfWidth, kRoomHeight, kRoomHalfWidth);
    return scene;
}

Scene procedural_with_clutter(std::size_t room, std::size_t clutter, Clutter where) {
    Scene s = procedural_scene(room);
    const Scene objects = procedural_scene(clutter);
    const auto nodes = static_cast<std::uint32_t>(s.nodes.size());
    std::uint32_t primitives = 0;
    for (const auto& t : s.triangles) primitives = std::max(primitives, t.primitive + 1);
    for (Triangle t : objects.triangles) {
        if (t.node < 2) continue;  // its room and light stay out
        for (auto& p : t.p) (where == Clutter::beyond ? p.x : p.y) += where == Clutter::beyond ? 20.0 : -20.0;
        t.node += nodes;
        t.primitive += primitives;
        s.triangles.push_back(t);
    }
    s.nodes.insert(s.nodes.end(), objects.nodes.begin(), objects.nodes.end());
    if (where == Clutter::beyond) s.bbox_max.x += 20.0;
    else s.bbox_min.y -= 20.0;
    return s;
}

std::optional<std::size_t> parse_procedural_spec(const std::string& spec) {
    return parse_count_spec(spec, "procedural:");
}

std::optional<std::size_t> parse_count_spec(const std::string& spec, const std::string& prefix) {
    if (spec.compare(0, prefix.size(), prefix) != 0) return std::nullopt;
    const std::string text = spec.substr(prefix.size());
    const auto fail = [&spec](const std::string& problem) -> InputError {
        return InputError(fmt::format("{}: {}", spec, problem));
    };
    const std::string malformed = fmt::format("triangle count '{}' is not a number like 100, 100k or 2.5M", text);

    // whole[.fraction][k|M]: the fraction only with a suffix, since triangles come whole.
    std::size_t pos = 0;
    const auto digits = [&]() {
        const std::size_t start = pos;
        while (pos < text.size() && text[pos] >= '0' && text[pos] <= '9') ++pos;
        return text.substr(start, pos - start);
    };
    std::string whole = digits(), fraction;
    if (pos < text.size() && text[pos] == '.') {
        ++pos;
        fraction = digits();
        if (fraction.empty()) throw fail(malformed);
    }
    std::uint64_t scale = 1;
    int scale_digits = 0;
    if (pos < text.size() && (text[pos] == 'k' || text[pos] == 'K')) {
        scale = 1'000, scale_digits = 3, ++pos;
    } else if (pos < text.size() && (text[pos] == 'M' || text[pos] == 'm')) {
        scale = 1'000'000, scale_digits = 6, ++pos;
    }
    if (whole.empty() || pos != text.size() || (!fraction.empty() && scale == 1)) throw fail(malformed);

    // Exact integer arithmetic; more than 9 significant whole digits is over any limit anyway.
    whole.erase(0, std::min(whole.find_first_not_of('0'), whole.size()));
    while (!fraction.empty() && fraction.back() == '0') fraction.pop_back();
    const std::string too_large = fmt::format("triangle count {} is above the limit of {} ({})", text,
                                              kMaxProceduralTriangles, count_label(kMaxProceduralTriangles));
    if (whole.size() > 9) throw fail(too_large);
    if (int(fraction.size()) > scale_digits) throw fail(fmt::format("triangle count {} is not a whole number", text));
    std::uint64_t count = (whole.empty() ? 0 : std::stoull(whole)) * scale;
    if (!fraction.empty()) {
        std::uint64_t part = std::stoull(fraction);
        for (int d = int(fraction.size()); d < scale_digits; ++d) part *= 10;
        count += part;
    }
    if (count == 0) throw fail("triangle count must be at least 1");
    if (count > kMaxProceduralTriangles) throw fail(too_large);
    return std::size_t(count);
}

}  // namespace hemirad::gen
