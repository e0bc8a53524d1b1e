// Delta-form-factor table, face mapping and per-shot frame shared by every hemicube engine.
#include "formfactor/hemicube.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>
#include <utility>

#include "core/error.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "formfactor/analytic.h"
#include "formfactor/engine.h"

namespace hemirad::formfactor {

glm::dvec3 to_face(int face, const glm::dvec3& p) {
    switch (face) {
        case 0: return {p.x, p.y, p.z};    // top: looks along +z
        case 1: return {p.y, p.z, p.x};    // +x
        case 2: return {-p.y, p.z, -p.x};  // −x
        case 3: return {-p.x, p.z, p.y};   // +y
        default: return {p.x, p.z, -p.y};  // −y
    }
}

glm::dvec3 from_face(int face, const glm::dvec3& q) {
    switch (face) {
        case 0: return {q.x, q.y, q.z};
        case 1: return {q.z, q.x, q.y};
        case 2: return {-q.z, -q.x, q.y};
        case 3: return {-q.x, q.z, q.y};
        default: return {q.x, -q.z, q.y};
    }
}

namespace {

// Table (n, weights), as DeltaFormFactors describes: cell by cell, so the rows may be filled in
// any order on any number of threads with the same bits.
std::vector<double> delta_table(int n, Weights weights) {
    std::vector<double> table(3u * static_cast<std::size_t>(n) * n);
    const double cell = 2.0 / n;  // cell size on the unit-distance face plane
    const glm::dvec3 up{0.0, 0.0, 1.0};
    std::vector<std::pair<int, int>> all_rows;  // (face, j)
    for (int face = 0; face < kFaces; ++face)
        for (int j = 0; j < DeltaFormFactors::face_rows(n, face); ++j) all_rows.push_back({face, j});
    parallel::for_each(all_rows.size(), 8, [&](std::size_t r) {
        const auto [face, j] = all_rows[r];
        const double t0 = face == 0 ? -1.0 : 0.0;  // side faces start at the base plane
        for (int i = 0; i < n; ++i) {
            const double s_lo = -1.0 + i * cell, s_hi = -1.0 + (i + 1) * cell;
            const double t_lo = t0 + j * cell, t_hi = t0 + (j + 1) * cell;
            const glm::dvec3 corners[4] = {from_face(face, {s_lo, t_lo, 1.0}), from_face(face, {s_hi, t_lo, 1.0}),
                                           from_face(face, {s_hi, t_hi, 1.0}), from_face(face, {s_lo, t_hi, 1.0})};
            table[DeltaFormFactors::face_offset(n, face) + static_cast<std::size_t>(j) * n + i] =
                weights == Weights::form_factor
                    ? point_to_polygon(up, corners, 4)
                    : (solid_angle(corners[0], corners[1], corners[2]) + solid_angle(corners[0], corners[2], corners[3])) /
                          (4.0 * M_PI);
        }
    });
    return table;
}

}  // namespace

DeltaFormFactors::DeltaFormFactors(int n, Weights weights) : n_(n) {
    // Made once per process and kept up to N = 1024 (25 MB); a larger one (400 MB at N = 4096) is
    // made for each engine that asks, and goes with it.
    constexpr int kKeptUpTo = 1024;
    if (n > kKeptUpTo) {
        table_ = std::make_shared<const std::vector<double>>(delta_table(n, weights));
        return;
    }
    static std::mutex mutex;
    static std::map<std::pair<int, Weights>, std::shared_ptr<const std::vector<double>>> made;
    const std::lock_guard<std::mutex> lock(mutex);
    auto& table = made[{n, weights}];
    if (!table) table = std::make_shared<const std::vector<double>>(delta_table(n, weights));
    table_ = table;
}

double DeltaFormFactors::sum() const {
    // Kahan summation: the table has millions of tiny terms at large N.
    double s = 0.0, c = 0.0;
    for (double x : *table_) {
        const double y = x - c;
        const double t = s + y;
        c = (t - s) - y;
        s = t;
    }
    return s;
}

double base_plane_epsilon(const mesh::Mesh& mesh) {
    double extent = 0.0;
    for (const auto& e : mesh.elements)
        for (int k = 0; k < e.poly.n; ++k)
            extent = std::max({extent, std::abs(e.poly.v[k].x), std::abs(e.poly.v[k].y), std::abs(e.poly.v[k].z)});
    return 1e-9 * std::max(extent, 1e-30);
}

Frame make_frame(const mesh::Patch& shooter, std::uint64_t seed, std::uint64_t shot) {
    return make_frame(shooter.centroid, shooter.normal, seed, shot);
}

Frame make_frame(const mesh::Mesh& mesh, const Shooter& shooter, std::uint64_t seed, std::uint64_t shot) {
    if (shooter.kind == Shooter::Kind::light) {
        const mesh::LightShooter& light = mesh.lights.at(shooter.patch);
        return make_frame(light.position, light.axis, seed, shot);
    }
    if (shooter.kind == Shooter::Kind::point) {
        const mesh::GatherPoint& point = mesh.gather_points.at(shooter.patch);
        return make_frame(point.position, point.normal, seed, shot);
    }
    if (shooter.kind == Shooter::Kind::directional)  // engines answer it with shoot_directional (parallel.h)
        throw InternalError("a directional light takes a parallel shot, not a hemicube");
    return make_frame(mesh.patches.at(shooter.patch), seed, shot);
}

Weights weights_of(const Shooter& shooter) {
    return shooter.kind == Shooter::Kind::light ? Weights::solid_angle : Weights::form_factor;
}

Frame make_frame(const glm::dvec3& origin, const glm::dvec3& normal, std::uint64_t seed, std::uint64_t shot) {
    // Orthonormal basis from the normal (Duff et al. 2017, branchless), then a seeded rotation
    // about the normal: the same (seed, shot) gives the same frame in every engine.
    const glm::dvec3 n = normal;
    const double sign = std::copysign(1.0, n.z);
    const double a = -1.0 / (sign + n.z);
    const double b = n.x * n.y * a;
    const glm::dvec3 t1{1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x};
    const glm::dvec3 t2{b, sign + n.y * n.y * a, -n.y};
    constexpr std::uint64_t kRotationStream = 0x68656d6963756265ull;  // "hemicube"
    const double angle = 2.0 * M_PI * uniform01(seed, kRotationStream, shot);
    const double c = std::cos(angle), s = std::sin(angle);
    Frame f;
    f.origin = origin;
    f.u = c * t1 + s * t2;
    f.v = -s * t1 + c * t2;
    f.w = n;
    return f;
}

}  // namespace hemirad::formfactor
