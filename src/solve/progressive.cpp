// Progressive refinement: shoot the patch with the most unshot flux, let elements receive and
// send what they reflect up to their patch, keep exact flux books, stand in for the unshot
// flux with a measured ambient term, and stop once that estimate or a round's change is small.
#include "solve/progressive.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>

namespace hemirad::solve {
namespace {

double mean(const glm::dvec3& v) { return (v.x + v.y + v.z) / 3.0; }
double sum(const glm::dvec3& v) { return v.x + v.y + v.z; }

}  // namespace

Progressive::Progressive(const mesh::Mesh& mesh, formfactor::Engine& engine, const Settings& settings,
                         const std::vector<glm::dvec3>* direct)
    : mesh_(mesh),
      engine_(engine),
      settings_(settings),
      H_(mesh.elements.size(), glm::dvec3(0.0)),
      shot_(mesh.patches.size(), glm::dvec3(0.0)),
      hit_(mesh.patches.size(), 1.0),
      round_unshot_(mesh.patches.size(), 0.0),
      rotations_(static_cast<std::size_t>(std::max(0, settings.rotations))),
      shots_(mesh.patches.size(), 0),
      counters_(mesh.patches.size() * rotations_, kNotShot) {
    unshot_.reserve(mesh.patches.size());
    for (const auto& p : mesh.patches) {
        unshot_.push_back(p.emission);
        emitted_ += p.emission * p.area;
    }
    if (direct) {
        if (direct->size() != mesh.elements.size())
            throw std::invalid_argument("progressive: direct light for another mesh");
        // As if the lights had shot: what lands is emitted and received, its reflection unshot.
        for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
            const mesh::Element& e = mesh.elements[k];
            const glm::dvec3 received = (*direct)[k] * e.area;
            H_[k] = (*direct)[k];
            emitted_ += received;
            const glm::dvec3 back = e.rho * received;
            unshot_[e.patch] += back / mesh.patches[e.patch].area;
            absorbed_ += received - back;
        }
    }
    glm::dvec3 rho_area{0.0};
    for (const auto& e : mesh.elements) {
        total_area_ += e.area;
        rho_area += e.rho * e.area;
    }
    if (total_area_ > 0.0) rho_area_mean_ = rho_area / total_area_;
    is_touched_.assign(mesh.patches.size(), false);
    recompute_sums();
    start_round(irradiance(/*ambient=*/true));
    round_change_ = std::numeric_limits<double>::infinity();
    update_convergence();
}

void Progressive::start_round(std::vector<glm::dvec3> snapshot) {
    snapshot_ = std::move(snapshot);
    snapshot_pass_ = passes_;
    round_held_ = 0.0;
    for (std::size_t p = 0; p < unshot_.size(); ++p) {
        round_unshot_[p] = sum(unshot_[p]) * mesh_.patches[p].area;
        round_held_ += round_unshot_[p];
    }
}

bool Progressive::done() const {
    return converged_ || (settings_.max_passes > 0 && passes_ >= settings_.max_passes);
}

long flux_holders(std::vector<double> flux, double share) {
    std::sort(flux.begin(), flux.end(), std::greater<>());
    double total = 0.0;
    for (double f : flux) total += f;
    long count = 0;
    for (double held = 0.0; count < long(flux.size()) && flux[count] > 0.0 && held < (1.0 - share) * total; ++count)
        held += flux[count];
    return count;
}

long Progressive::holders(double share) const {
    std::vector<double> keys(unshot_.size());
    for (std::size_t p = 0; p < unshot_.size(); ++p) keys[p] = flux_key(p);
    return flux_holders(std::move(keys), share);
}

double Progressive::flux_key(std::size_t patch) const { return sum(unshot_[patch]) * mesh_.patches[patch].area; }

void Progressive::reset_pick() {
    std::vector<double> keys(unshot_.size());
    for (std::size_t p = 0; p < unshot_.size(); ++p) keys[p] = flux_key(p);
    pick_.reset(std::move(keys));
}

void Progressive::recompute_sums() {
    incident_flux_ = unshot_flux_ = landing_ = glm::dvec3(0.0);
    for (std::size_t k = 0; k < H_.size(); ++k) incident_flux_ += H_[k] * mesh_.elements[k].area;
    for (std::size_t p = 0; p < unshot_.size(); ++p) {
        unshot_flux_ += unshot_[p] * mesh_.patches[p].area;
        landing_ += hit_[p] * unshot_[p] * mesh_.patches[p].area;
    }
    reset_pick();
}

bool Progressive::step() {
    if (done()) return false;

    // The patches with the most unshot flux, most first; ties go to the lower index. Each is taken
    // off the tree while the next is found, then put back: apply() updates it when it shoots.
    // With batch_share, those after the first only while they hold that share of its flux.
    long count = std::max(1, settings_.batch);
    if (settings_.max_passes > 0) count = std::min(count, settings_.max_passes - passes_);
    std::vector<formfactor::ShotRequest> requests;
    double first_flux = 0.0;
    while (static_cast<long>(requests.size()) < count) {
        if (nothing_unshot()) break;
        const std::size_t best = pick_.top();
        if (requests.empty()) {
            first_flux = flux_key(best);
        } else if (settings_.batch_share > 0.0 && !(flux_key(best) >= settings_.batch_share * first_flux)) {
            break;
        }
        // The k-th shot of a patch takes the counter (the hemicube's rotation) of its
        // (k mod rotations)-th: the first are the passes' own, later ones repeat those rows.
        const std::uint64_t pass = static_cast<std::uint64_t>(passes_) + requests.size();
        std::uint64_t counter = pass;
        if (rotations_ > 0) {
            std::uint64_t& slot = counters_[best * rotations_ + shots_[best] % rotations_];
            if (slot == kNotShot) slot = pass;
            counter = slot;
        }
        requests.push_back(formfactor::ShotRequest::of_patch(static_cast<std::uint32_t>(best), counter));
        pick_.set(best, -1.0);
    }
    for (const formfactor::ShotRequest& r : requests) pick_.set(r.shooter.patch, flux_key(r.shooter.patch));
    if (requests.empty()) {
        converged_ = true;
        return false;
    }
    engine_.shoot_batch(requests, batch_results_);
    // In order; a batch cut short by convergence leaves the rest unshot, the books exact.
    for (std::size_t i = 0; i < requests.size() && !done(); ++i) apply(requests[i].shooter.patch, batch_results_[i]);
    return true;
}

void Progressive::apply(std::size_t best, const formfactor::ShotResult& shot) {
    const mesh::Patch& shooter = mesh_.patches[best];
    const glm::dvec3 u = unshot_[best];
    const glm::dvec3 flux = u * shooter.area;
    landing_ -= hit_[best] * flux;
    unshot_flux_ -= flux;
    unshot_[best] = glm::dvec3(0.0);
    shot_[best] += u;
    ++shots_[best];
    round_unshot_[best] = 0.0;  // what it held at the round's start has now been shot

    // ΔH_j = ΔB_i F_ij A_i / A_j; what element j reflects, ρ_j ΔH_j A_j, joins its patch's pool.
    glm::dvec3 reflected{0.0};
    double f_sum = 0.0;
    touched_.clear();
    for (std::size_t i = 0; i < shot.size(); ++i) {
        const double f = shot.F[i];
        if (f == 0.0) continue;
        const mesh::Element& e = mesh_.elements[shot.element[i]];
        const glm::dvec3 received = flux * f;  // flux arriving at the element
        H_[shot.element[i]] += received / e.area;
        incident_flux_ += received;
        const glm::dvec3 back = e.rho * received;
        const mesh::Patch& parent = mesh_.patches[e.patch];
        unshot_[e.patch] += back / parent.area;
        unshot_flux_ += back;
        landing_ += hit_[e.patch] * back;
        if (!is_touched_[e.patch]) {
            is_touched_[e.patch] = true;
            touched_.push_back(e.patch);
        }
        absorbed_ += received - back;
        reflected += back;
        f_sum += f;
    }
    absorbed_ += flux * shot.blocked;
    escaped_ += flux * (1.0 - f_sum - shot.blocked);  // may be −1e-16: books stay exact
    const double hit = std::clamp(f_sum + shot.blocked, 0.0, 1.0);
    landing_ += (hit - hit_[best]) * unshot_[best] * shooter.area;  // light its own elements sent back
    hit_[best] = hit;
    pick_.set(best, flux_key(best));
    for (const std::uint32_t p : touched_) {
        is_touched_[p] = false;
        pick_.set(p, flux_key(p));
    }

    // Recent reflectance of the scene, flux-weighted, forgetting over about one round of patches.
    const double keep = 1.0 - 1.0 / std::max<double>(16.0, static_cast<double>(mesh_.patches.size()));
    recent_shot_ = recent_shot_ * keep + flux;
    recent_reflected_ = recent_reflected_ * keep + reflected;

    ++passes_;
    update_convergence();
}

glm::dvec3 Progressive::effective_reflectance() const {
    // Share of shot flux that comes back into the unshot pool, per channel: reflectance of
    // what is hit, times the share that hits anything. Before any shot: the area mean.
    glm::dvec3 r = rho_area_mean_;
    for (int c = 0; c < 3; ++c)
        if (recent_shot_[c] > 0.0) r[c] = recent_reflected_[c] / recent_shot_[c];
    return glm::clamp(r, glm::dvec3(0.0), glm::dvec3(scene::kMaxReflectance));
}

glm::dvec3 Progressive::ambient() const {
    // Cohen et al. 1988, with measured reflectance and hit shares: the unshot flux U_p of each
    // patch will land on the scene in the share h_p its last shot did (1 for a patch that has not
    // shot yet: nothing is known of where its light goes, so none of it is assumed to escape),
    // spread evenly, and come back with factor ρ_eff every bounce: H_amb = Σ h_p U_p / A / (1 −
    // ρ_eff). A share measured on other patches' shots is not used for a patch's own light: a
    // lamp's side facing the open sky says nothing of its side facing the floor.
    if (total_area_ <= 0.0) return glm::dvec3(0.0);
    return glm::max(landing_, glm::dvec3(0.0)) / total_area_ / (glm::dvec3(1.0) - effective_reflectance());
}

void Progressive::update_convergence() {
    // A round is one pass per patch: by then every patch that holds light has had its turn.
    const long round = std::max<long>(1, static_cast<long>(mesh_.patches.size()));
    if (passes_ - snapshot_pass_ >= round) {
        recompute_sums();
        std::vector<glm::dvec3> now = irradiance(/*ambient=*/true);
        glm::dvec3 change{0.0}, total{0.0};
        for (std::size_t k = 0; k < now.size(); ++k) {
            change += glm::abs(now[k] - snapshot_[k]) * mesh_.elements[k].area;
            total += now[k] * mesh_.elements[k].area;
        }
        round_change_ = 0.0;
        for (int c = 0; c < 3; ++c)
            if (total[c] > 0.0) round_change_ = std::max(round_change_, change[c] / total[c]);
        // "Nothing changed this round" says the ambient term predicted the round well only if the
        // round shot the light it was predicting: the patches that held the unshot flux at its
        // start. Otherwise the change is not evidence, and the measure stays infinite.
        double left = 0.0;
        for (const double flux : round_unshot_) left += flux;
        if (left > settings_.threshold * round_held_) round_change_ = std::numeric_limits<double>::infinity();
        start_round(std::move(now));
    }
    converged_ = nothing_unshot() || error() <= settings_.threshold;
}

double Progressive::ambient_share() const {
    // Incident light, not radiosity: with ρ = 0 radiosity is just E, yet the irradiance the
    // report gives still needs every lamp shot. Flux-weighted per channel.
    const glm::dvec3 ambient_flux = ambient() * total_area_;
    const glm::dvec3 total = incident_flux_ + ambient_flux;
    double share = 0.0;
    for (int c = 0; c < 3; ++c)
        if (total[c] > 0.0) share = std::max(share, ambient_flux[c] / total[c]);
    return share;
}

bool Progressive::nothing_unshot() const {
    const std::size_t best = pick_.top();
    return best >= pick_.size() || !(pick_.key(best) > 0.0);
}

std::string Progressive::convergence_rule() const {
    if (!converged_) return "";
    if (nothing_unshot() || ambient_share() <= settings_.threshold) return "unshot light";
    return "a round without change";
}

double Progressive::unshot_fraction() const {
    const glm::dvec3 unshot_flux = unshot_total();
    const double emitted = mean(emitted_);
    return emitted > 0.0 ? mean(unshot_flux) / emitted : 0.0;
}

std::vector<glm::dvec3> Progressive::irradiance(bool with_ambient) const {
    const glm::dvec3 amb = with_ambient ? ambient() : glm::dvec3(0.0);
    std::vector<glm::dvec3> out(H_.size());
    for (std::size_t k = 0; k < H_.size(); ++k) out[k] = H_[k] + amb;
    return out;
}

std::vector<glm::dvec3> Progressive::radiosity(bool with_ambient) const {
    std::vector<glm::dvec3> out = irradiance(with_ambient);
    for (std::size_t k = 0; k < out.size(); ++k) {
        const mesh::Element& e = mesh_.elements[k];
        out[k] = e.emission + e.rho * out[k];
    }
    return out;
}

glm::dvec3 Progressive::unshot_total() const { return glm::max(unshot_flux_, glm::dvec3(0.0)); }

void Progressive::save(std::ostream& out) const {
    using namespace state_io;
    put_vector(out, H_);
    put_vector(out, unshot_);
    put_vector(out, shot_);
    put_vector(out, snapshot_);
    put_vector(out, hit_);
    put_vector(out, round_unshot_);
    put_vector(out, shots_);
    put_vector(out, counters_);
    for (const glm::dvec3& v :
         {emitted_, absorbed_, escaped_, recent_shot_, recent_reflected_, incident_flux_, unshot_flux_, landing_})
        put(out, v);
    put(out, static_cast<std::int64_t>(passes_));
    put(out, static_cast<std::int64_t>(snapshot_pass_));
    put(out, round_held_);
    put(out, round_change_);
    put(out, static_cast<std::uint8_t>(converged_ ? 1 : 0));
}

void Progressive::load(std::istream& in) {
    using namespace state_io;
    get_vector(in, H_, H_.size());
    get_vector(in, unshot_, unshot_.size());
    get_vector(in, shot_, shot_.size());
    get_vector(in, snapshot_, snapshot_.size());
    get_vector(in, hit_, hit_.size());
    get_vector(in, round_unshot_, round_unshot_.size());
    get_vector(in, shots_, shots_.size());
    get_vector(in, counters_, counters_.size());
    for (glm::dvec3* v : {&emitted_, &absorbed_, &escaped_, &recent_shot_, &recent_reflected_, &incident_flux_,
                          &unshot_flux_, &landing_})
        get(in, *v);
    std::int64_t passes = 0, snapshot_pass = 0;
    get(in, passes);
    get(in, snapshot_pass);
    get(in, round_held_);
    get(in, round_change_);
    std::uint8_t converged = 0;
    get(in, converged);
    passes_ = static_cast<long>(passes);
    snapshot_pass_ = static_cast<long>(snapshot_pass);
    converged_ = converged != 0;
    reset_pick();
}

Energy Progressive::energy() const {
    const glm::dvec3 unshot_flux = unshot_total();
    return {mean(emitted_), mean(absorbed_), mean(escaped_), mean(unshot_flux)};
}

}  // namespace hemirad::solve
