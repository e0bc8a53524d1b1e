// FormFactorEngine: shoot(shooter) → the sparse row F[shooter → element] over the elements it
// reaches, one shot or a batch of shots at a time. Implemented by the scalar reference hemicube, the OpenCL
// engine, and decorators (near field, verification).
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace hemirad::formfactor {

struct Settings {
    int hemicube = 256;       // resolution N: top face N×N, four half faces N×N/2; even, >= 8
    std::uint64_t seed = 1;   // drives the per-shot rotation of the hemicube about the normal
};

// What one shot sees, as a sparse row: the elements it reaches, ascending, with their form
// factors (F[i] for element[i]; every unlisted element has F = 0). A pass costs what the shot
// touched, not the mesh: engines list only elements they reached, solvers walk only the list.
// `blocked` is the part of the hemisphere covered by the backs of one-sided surfaces (opaque,
// absorbing); the rest, 1 − ΣF − blocked, escapes the scene.
struct ShotResult {
    std::vector<std::uint32_t> element;
    std::vector<double> F;
    double blocked = 0.0;

    void clear() {
        element.clear();
        F.clear();
        blocked = 0.0;
    }
    std::size_t size() const { return element.size(); }
    void push(std::uint32_t k, double f) {
        element.push_back(k);
        F.push_back(f);
    }
    double sum() const {
        double s = 0.0;
        for (const double f : F) s += f;
        return s;
    }
    // One entry per element of a mesh of `elements` (for tests and comparisons).
    std::vector<double> dense(std::size_t elements) const {
        std::vector<double> out(elements, 0.0);
        for (std::size_t i = 0; i < element.size(); ++i) out[element[i]] = F[i];
        return out;
    }
    // The row of a dense per-element array: its nonzero entries.
    template <class Value, class Scale>
    void assign_nonzero(const Value* values, std::size_t elements, Scale scale) {
        element.clear();
        F.clear();
        for (std::size_t k = 0; k < elements; ++k)
            if (values[k] != Value(0)) push(static_cast<std::uint32_t>(k), scale(values[k]));
    }
    bool operator==(const ShotResult& o) const { return element == o.element && F == o.F && blocked == o.blocked; }
    bool operator!=(const ShotResult& o) const { return !(*this == o); }
};

// Walks the union of two rows' elements, ascending: fn(element, F in a, F in b), 0 where a row
// does not list the element.
template <class Fn>
void for_each_in_union(const ShotResult& a, const ShotResult& b, Fn fn) {
    std::size_t i = 0, j = 0;
    while (i < a.size() || j < b.size()) {
        const std::uint32_t ka = i < a.size() ? a.element[i] : UINT32_MAX;
        const std::uint32_t kb = j < b.size() ? b.element[j] : UINT32_MAX;
        const std::uint32_t k = ka < kb ? ka : kb;
        const double fa = ka == k ? a.F[i++] : 0.0;
        const double fb = kb == k ? b.F[j++] : 0.0;
        fn(k, fa, fb);
    }
}

// What shoots, as data: every engine takes a Shooter, so that new kinds of shooter come as new
// kinds here, not as new engine interfaces. Four kinds:
// - a patch of the mesh, shooting its hemicube from its centre along its normal (a planar cell
//   skips its own elements and its twin's; a cluster draws its own, see shot_skips); the row
//   holds form factors;
// - one hemicube of a punctual light (mesh::Mesh::lights), from the light along its axis,
//   skipping nothing; the row holds each element's visible solid angle over 4π (Weights);
// - a final gather's point (mesh::Mesh::gather_points), a hemicube from the point along its
//   normal, skipping nothing (its own surface lies in the base plane); the row holds the point's
//   form factors to the elements, F(dA → element), so that Σ F·B is its irradiance;
// - a directional light (mesh::Mesh::directions: a sun), a parallel shot across its direction
//   (formfactor/parallel.h: shoot_parallel, drawn by the engine's own raster, which gives the
//   host's bits), no hemicube; the row holds each element's cos θ times its lit share (an element
//   receives E × that), `blocked` the area its one-sided backs shade, in scene units².
// The shot counter turns a hemicube about its axis, and a parallel shot's grid about its direction.
struct Shooter {
    enum class Kind : std::uint8_t { patch, light, point, directional };
    Kind kind = Kind::patch;
    // Kind::patch: the patch; Kind::light: the index in mesh::Mesh::lights; Kind::point: in
    // mesh::Mesh::gather_points; Kind::directional: in mesh::Mesh::directions.
    std::uint32_t patch = 0;

    static Shooter of_patch(std::uint32_t patch) { return {Kind::patch, patch}; }
    static Shooter of_light(std::uint32_t light) { return {Kind::light, light}; }
    static Shooter of_point(std::uint32_t point) { return {Kind::point, point}; }
    static Shooter of_directional(std::uint32_t direction) { return {Kind::directional, direction}; }
    bool operator==(const Shooter& o) const { return kind == o.kind && patch == o.patch; }
};

// One shot: who shoots, and the global shot counter, which with the seed fixes the hemicube's
// rotation, so that any engine reproduces the same shot.
struct ShotRequest {
    Shooter shooter;
    std::uint64_t shot = 0;

    static ShotRequest of_patch(std::uint32_t patch, std::uint64_t shot) { return {Shooter::of_patch(patch), shot}; }
    static ShotRequest of_light(std::uint32_t light, std::uint64_t shot) { return {Shooter::of_light(light), shot}; }
    static ShotRequest of_point(std::uint32_t point, std::uint64_t shot) { return {Shooter::of_point(point), shot}; }
    static ShotRequest of_directional(std::uint32_t direction, std::uint64_t shot) {
        return {Shooter::of_directional(direction), shot};
    }
};

// The patches whose elements a shot leaves out (mesh::kNoPatch: none): a planar cell's own
// surface, both sides, which cannot see itself; a cluster draws its own elements (the rim of a
// concave one blocks and receives). Every engine skips exactly these.
struct ShotSkips {
    std::uint32_t own = mesh::kNoPatch, twin = mesh::kNoPatch;
    bool skips(std::uint32_t patch) const { return patch == own || patch == twin; }
};
inline ShotSkips shot_skips(const mesh::Mesh& mesh, const Shooter& shooter) {
    if (shooter.kind != Shooter::Kind::patch) return {};
    const mesh::Patch& p = mesh.patches.at(shooter.patch);
    if (p.cluster()) return {};
    return {shooter.patch, p.twin};
}

class Engine {
public:
    virtual ~Engine() = default;
    virtual std::string name() const = 0;  // "ref", "opencl"
    // Form factors from a shooter to every element, as a sparse row.
    virtual void shoot(const ShotRequest& request, ShotResult& out) = 0;
    // A patch's shot: shoot(ShotRequest::of_patch(patch, shot), out).
    void shoot(std::uint32_t patch, std::uint64_t shot, ShotResult& out) {
        shoot(ShotRequest::of_patch(patch, shot), out);
    }
    // Several shots at once, with exactly the results of shoot() one at a time (out[i] for
    // shots[i]). Engines that can run them together (the OpenCL engine: one launch per stage)
    // override it; this one shoots in turn.
    virtual void shoot_batch(const std::vector<ShotRequest>& shots, std::vector<ShotResult>& out) {
        out.resize(shots.size());
        for (std::size_t i = 0; i < shots.size(); ++i) shoot(shots[i], out[i]);
    }
    // The shots one shoot_batch should carry to keep the engine busy, for callers whose results
    // do not depend on how they batch (the gather's points, refinement's re-gathers, the matrix
    // solver's rows; not the progressive solver, whose batch picks its shooters): the OpenCL
    // engine's from its device, kDefaultBatch otherwise.
    static constexpr std::size_t kDefaultBatch = 64;
    virtual std::size_t preferred_batch() const { return kDefaultBatch; }
    // Shots a call for a caller that asks for `batch` (at least one) and, where `engine_batch`,
    // also takes the engine's preferred batch when that is larger.
    std::size_t batch_for(int batch, bool engine_batch) const {
        const std::size_t asked = static_cast<std::size_t>(batch > 1 ? batch : 1);
        return engine_batch ? std::max(asked, preferred_batch()) : asked;
    }
    // The id buffer of shot i of the last shoot_batch (a shoot() is a batch of one): element
    // index, −1 empty, −2 blocker, cells in DeltaFormFactors order; for a directional shot the
    // owner of each cell of its grid (parallel.h: a record, −1 none), row-major. nullptr where the
    // engine does not keep it. Used by verification.
    virtual const std::vector<std::int32_t>* last_ids(std::size_t i = 0) const {
        (void)i;
        return nullptr;
    }
};

}  // namespace hemirad::formfactor
