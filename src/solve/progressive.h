// Progressive refinement radiosity (Cohen, Chen, Wallace & Greenberg 1988): each pass shoots
// the patch with the most unshot flux; elements receive, their reflected flux goes up to the
// parent patch. An ambient term stands in for the flux not yet shot. A pass costs what its shot
// touched: the pick is a max-tree over the patches, and the sums the ambient term and the
// convergence measure need are kept running (recomputed exactly once a round).
#pragma once

#include <algorithm>
#include <cstdint>
#include <istream>
#include <ostream>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "formfactor/engine.h"
#include "mesh/mesh.h"
#include "solve/max_tree.h"
#include "solve/resumable.h"

namespace hemirad::solve {

struct Settings {
    // Stop when the ambient term's share of the incident light, or the change of the
    // ambient-corrected incident light over the last round (a round that shot all but this share
    // of the unshot flux it started with), falls below this (flux-weighted).
    double threshold = 1e-3;
    long max_passes = 0;       // 0: no limit but the threshold
    // Shooters per step: the `batch` patches with the most unshot flux go to the engine
    // together (one launch on the OpenCL engine), then are applied in turn, each shooting
    // the unshot flux it holds by then. 1 is Southwell's order exactly.
    int batch = 1;
    // With batch_share > 0, a step takes after its first shooter only the patches that hold at
    // least this share of the first's unshot flux (still `batch` at most): where many patches
    // hold about as much (a scene's lamps, a lit wall's patches) they go together, and where one
    // holds most, it goes alone, as Southwell's order would have it. The rule reads only the
    // solve's state, so the shooters, and the bytes, are the same on every device and number of
    // devices or ranks.
    double batch_share = 0.0;
    // Rotations of a patch's hemicube: its k-th shot takes the shot counter (the rotation) of its
    // (k mod rotations)-th, so that a patch which shoots again and again (light trapped between a
    // few patches) cycles through this many rows, which an engine may keep
    // (formfactor::RowCacheEngine), while its light still averages the aliasing of that many
    // rotations. Patches that shoot at most this many times shoot as with a new rotation every
    // pass. 0: a new rotation every pass.
    int rotations = 8;
};

// Flux bookkeeping, as radiosity × area summed over elements, averaged over r, g, b.
// emitted = absorbed + escaped + unshot, to rounding, at every pass.
struct Energy {
    double emitted = 0.0;
    double absorbed = 0.0;
    double escaped = 0.0;
    double unshot = 0.0;
};

// How many of `flux` (one value per patch, ≥ 0), taken largest first, hold all but `share` of
// their sum: 0 where the sum is 0.
long flux_holders(std::vector<double> flux, double share);

class Progressive final : public Resumable {
public:
    // `direct`, if set, is the irradiance per element the punctual lights have already shot
    // (solve/lights.h): the solve starts from it, its reflection unshot, the flux counted as
    // emitted.
    Progressive(const mesh::Mesh& mesh, formfactor::Engine& engine, const Settings& settings,
                const std::vector<glm::dvec3>* direct = nullptr);

    // Shoots one batch of patches (one pass each). Returns false (and does nothing) once
    // converged or out of passes.
    bool step();
    bool done() const;
    bool converged() const { return converged_; }
    long passes() const { return passes_; }

    // The convergence measure compared against `threshold`: the smaller of ambient_share()
    // and round_change(); 0 once no patch holds unshot flux (nothing left to change: the share
    // of an ambient term of nothing over an incident flux of nothing is no measure). unshot_fraction()
    // is the raw unshot share of the emitted flux.
    double error() const { return nothing_unshot() ? 0.0 : std::min(ambient_share(), round_change_); }
    // Share of the incident flux Σ H·A that is still the ambient estimate, not shot light.
    double ambient_share() const;
    // Flux-weighted change Σ|ΔH|·A / Σ H·A of the ambient-corrected incident light over the
    // last round (one pass per patch); infinite until a round has passed, and after a round that
    // left more than `threshold` of the unshot flux it started with unshot.
    double round_change() const { return round_change_; }
    double unshot_fraction() const;
    // The patches, taken by most unshot flux first, that hold all but `share` of the unshot flux
    // now (flux_holders): the passes that shooting it once would take.
    long holders(double share) const;
    // Which rule ended the solve: "unshot light" (the ambient share, or nothing left to shoot),
    // "a round without change", or "" while not converged.
    std::string convergence_rule() const;

    // Radiosity B = E + ρ·H and incident H per element; with `ambient`, the ambient term
    // (the unshot flux spread as if the scene were closed, with the measured reflectance
    // of the scene) is added to H.
    std::vector<glm::dvec3> radiosity(bool ambient) const;
    std::vector<glm::dvec3> irradiance(bool ambient) const;
    glm::dvec3 ambient() const;

    Energy energy() const;
    // Per patch, the radiosity it has shot in all (the sum of its passes' unshot radiosity):
    // what a re-gather shoots again onto a refined mesh.
    const std::vector<glm::dvec3>& shot() const { return shot_; }

    // Resumable: the whole state (every per-patch and per-element vector, the books, the passes).
    void save(std::ostream& out) const override;
    void load(std::istream& in) override;

private:
    const mesh::Mesh& mesh_;
    formfactor::Engine& engine_;
    Settings settings_;
    std::vector<formfactor::ShotResult> batch_results_;  // the last step's shots

    void apply(std::size_t patch, const formfactor::ShotResult& shot);  // one pass

    std::vector<glm::dvec3> H_;        // incident per element, shot so far
    std::vector<glm::dvec3> unshot_;   // unshot radiosity per patch
    std::vector<glm::dvec3> shot_;     // radiosity shot so far per patch
    glm::dvec3 emitted_{0.0};          // flux per channel
    glm::dvec3 absorbed_{0.0};
    glm::dvec3 escaped_{0.0};
    double total_area_ = 0.0;
    glm::dvec3 rho_area_mean_{0.0};    // prior for the scene's reflectance before any shot
    // Recent shots: flux shot, flux sent back into the unshot pool.
    glm::dvec3 recent_shot_{0.0}, recent_reflected_{0.0};
    // Per patch, the share of its last shot that landed on the scene (ΣF + blocked); 1 until it
    // has shot. The ambient term lands each patch's unshot flux in this share.
    std::vector<double> hit_;
    // Running sums, per channel: Σ H·A over elements, Σ U·A and Σ h·U·A over patches. Updated by
    // each pass for what it touched, recomputed in index order at each round's start (so they
    // cannot drift), and saved with the state (a resumed bake continues with the same bits).
    glm::dvec3 incident_flux_{0.0}, unshot_flux_{0.0}, landing_{0.0};
    // Per patch, its unshot flux sum(U)·A: the key of the pick.
    MaxTree pick_;
    std::vector<std::uint32_t> touched_;  // parents a pass sent light to (scratch)
    std::vector<bool> is_touched_;

    void recompute_sums();
    void reset_pick();  // the max-tree's keys from unshot_
    double flux_key(std::size_t patch) const;
    long passes_ = 0;
    bool converged_ = false;

    glm::dvec3 effective_reflectance() const;
    glm::dvec3 unshot_total() const;  // unshot flux per channel
    bool nothing_unshot() const;      // every patch has shot all it holds
    void start_round(std::vector<glm::dvec3> snapshot);  // snapshot: ambient-corrected H now
    void update_convergence();

    std::vector<glm::dvec3> snapshot_;  // ambient-corrected incident light at the last round's start
    long snapshot_pass_ = 0;
    // Per patch, the unshot flux (r + g + b) it held at the round's start, zeroed once it shoots,
    // and their total at the start: what the round has not yet shot of the light it began with.
    std::vector<double> round_unshot_;
    double round_held_ = 0.0;
    double round_change_ = 0.0;
    // Per patch, its shots so far, and the shot counters of its first settings_.rotations shots,
    // kNotShot until taken (Settings::rotations).
    static constexpr std::uint64_t kNotShot = ~std::uint64_t{0};
    std::size_t rotations_ = 0;
    std::vector<std::uint32_t> shots_;
    std::vector<std::uint64_t> counters_;
};

}  // namespace hemirad::solve
