// What every hemicube engine shares: the delta-form-factor table and the per-shot frame.
// Algorithm code (clipping, rasterization) is deliberately not shared: the reference is a check.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <glm/glm.hpp>

#include "mesh/mesh.h"

namespace hemirad::formfactor {

struct Shooter;

// Face order: 0 top (+z), 1 +x, 2 −x, 3 +y, 4 −y in the hemicube frame.
inline constexpr int kFaces = 5;

// Maps hemicube-frame coordinates (x, y, z; z along the normal) to face coordinates (u, v, d):
// d is depth along the face's axis, (u/d, v/d) the position on the face, v/d ∈ [0, 1] on the
// side faces (height above the base plane).
glm::dvec3 to_face(int face, const glm::dvec3& frame_point);
glm::dvec3 from_face(int face, const glm::dvec3& face_point);

// Exact delta form factors: each cell's value is the differential-area-to-polygon form factor
// of the cell's square (Lambert's formula), in double precision. They sum to 1 to rounding.
// A light's shots weigh each cell by its solid angle instead (Weights::solid_angle): the share
// of a point light's power that leaves through it, ΔΩ / 4π, so that a hemicube's cells sum to
// one half and a light's two hemicubes (the whole cube) to one.
enum class Weights { form_factor, solid_angle };

// A table is computed once per (n, weights) in a process, over the host's threads, and shared by
// every engine and copy that asks for it (engines are made per refinement level and gather).
class DeltaFormFactors {
public:
    explicit DeltaFormFactors(int n, Weights weights = Weights::form_factor);  // n even, >= 2
    int n() const { return n_; }
    // Cell (i, j) of a face: i along u (0..n−1), j along v (0..n−1 on top, 0..n/2−1 on sides).
    int rows(int face) const { return face_rows(n_, face); }
    double at(int face, int i, int j) const { return (*table_)[offset(face) + static_cast<std::size_t>(j) * n_ + i]; }
    std::size_t offset(int face) const { return face_offset(n_, face); }
    // The same at resolution n.
    static int face_rows(int n, int face) { return face == 0 ? n : n / 2; }
    static std::size_t face_offset(int n, int face) {
        return face == 0 ? 0 : static_cast<std::size_t>(n) * n + static_cast<std::size_t>(face - 1) * n * (n / 2);
    }
    std::size_t cells() const { return 3u * static_cast<std::size_t>(n_) * n_; }
    const std::vector<double>& table() const { return *table_; }
    double sum() const;

private:
    int n_;
    std::shared_ptr<const std::vector<double>> table_;
};

// Projected polygons are snapped to a fixed-point grid of kSubcell units per cell before the
// inside test, so that edge functions are exact 64-bit integers: two polygons sharing an edge
// get exactly opposite values, and any evaluation order (per cell, incremental, vectorized)
// gives the same answer. 2^16 units per cell keep |edge function| < 2^58 up to N = 4096.
inline constexpr std::int64_t kSubcell = std::int64_t{1} << 16;
inline constexpr int kMaxHemicube = 4096;

// Distance above the shooter's plane below which geometry is clipped (the base plane), relative
// to the scene's coordinates so that geometry in the shooter's plane is clipped however far the
// scene lies from the origin. Every engine must use exactly this value to agree cell for cell.
double base_plane_epsilon(const mesh::Mesh& mesh);

// Orthonormal frame of one shot: origin at the shooter's centroid, w its normal, (u, v)
// rotated about w by an angle drawn from (seed, shot) so that aliasing becomes noise.
struct Frame {
    glm::dvec3 origin{0.0};
    glm::dvec3 u{1, 0, 0}, v{0, 1, 0}, w{0, 0, 1};
    glm::dvec3 to_local(const glm::dvec3& p) const {
        const glm::dvec3 d = p - origin;
        return {glm::dot(d, u), glm::dot(d, v), glm::dot(d, w)};
    }
};
Frame make_frame(const glm::dvec3& origin, const glm::dvec3& normal, std::uint64_t seed, std::uint64_t shot);
Frame make_frame(const mesh::Patch& shooter, std::uint64_t seed, std::uint64_t shot);
// The frame of any shooter: a patch's, a light's hemicube from the light along its axis, or a
// gather point's along its normal.
Frame make_frame(const mesh::Mesh& mesh, const Shooter& shooter, std::uint64_t seed, std::uint64_t shot);
// Which cell weights a shooter's shot sums: form factors for a patch or a gather point, solid
// angles for a light.
Weights weights_of(const Shooter& shooter);

}  // namespace hemirad::formfactor
