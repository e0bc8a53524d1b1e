// Full-matrix gathering: shoot every patch that can hold light once, keep its form factors
// sparse, fold them with the receivers' reflectance into a dense patch-to-patch K, and solve
// B = E + K·B by Gauss–Seidel. Elements then gather their incident light from the rows.
#include "solve/matrix.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace hemirad::solve {
namespace {

double mean(const glm::dvec3& v) {
    return (v.x + v.y + v.z) / 3.0;
}
bool any_positive(const glm::dvec3& v) {
    return v.x > 0.0 || v.y > 0.0 || v.z > 0.0;
}
bool is_grey(const glm::dvec3& v) {
    return v.x == v.y && v.x == v.z;
}

// The patches that get rows, ascending. With interreflection, every patch that can hold
// light: one that emits, or has an element that reflects (a patch with neither keeps B = 0).
// Direct light only: the emitters.
std::vector<std::uint32_t> active_patches(const mesh::Mesh& mesh, const MatrixSettings& settings) {
    std::vector<std::uint32_t> active;
    for (std::size_t p = 0; p < mesh.patches.size(); ++p) {
        const mesh::Patch& patch = mesh.patches[p];
        bool holds = false;
        for (std::uint32_t k = 0; k < patch.element_count && !holds; ++k) {
            const mesh::Element& e = mesh.elements[patch.first_element + k];
            holds = any_positive(e.emission) || (settings.interreflection && any_positive(e.rho));
        }
        if (holds) active.push_back(static_cast<std::uint32_t>(p));
    }
    return active;
}

}  // namespace

Matrix::Matrix(const mesh::Mesh& mesh, formfactor::Engine& engine, const MatrixSettings& settings,
               const std::vector<glm::dvec3>* direct)
    : mesh_(mesh), engine_(engine), settings_(settings), channels_(settings.grey ? 1 : 3) {
    source_.reserve(mesh.patches.size());
    for (const auto& p : mesh.patches) source_.push_back(p.emission);
    if (direct) {
        if (direct->size() != mesh.elements.size()) throw std::invalid_argument("matrix: direct light for another mesh");
        direct_ = *direct;
        // The lights' reflected light is a source of its patch, as emission is; without
        // interreflection it goes no further.
        if (settings.interreflection)
            for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
                const mesh::Element& e = mesh.elements[k];
                source_[e.patch] += e.rho * direct_[k] * (e.area / mesh.patches[e.patch].area);
            }
    }
    if (settings_.grey) {
        for (std::size_t k = 0; k < mesh.elements.size(); ++k) {
            const mesh::Element& e = mesh.elements[k];
            if (!is_grey(e.rho) || !is_grey(e.emission))
                throw std::invalid_argument("grey matrix solve: element " + std::to_string(k) +
                                            " has a coloured reflectance or emission");
        }
    }
    active_ = active_patches(mesh, settings_);
    rows_.resize(mesh.patches.size());
    // Before any solve, and if the rows are cancelled: each patch holds its own emission only.
    Bp_.reserve(mesh.patches.size());
    for (const auto& p : mesh.patches) Bp_.push_back(p.emission);
    H_.assign(mesh.elements.size(), glm::dvec3(0.0));
    B_.reserve(mesh.elements.size());
    for (const auto& e : mesh.elements) B_.push_back(e.emission);
}

MatrixSettings matrix_settings(double threshold, int batch) {
    MatrixSettings s;
    s.tolerance = std::min(1e-4, threshold * 1e-2);
    s.batch = std::max(batch, 64);
    s.engine_batch = true;
    return s;
}

std::size_t Matrix::estimate_bytes(const mesh::Mesh& mesh, const MatrixSettings& settings) {
    return static_cast<std::size_t>(estimate_bytes(static_cast<double>(active_patches(mesh, settings).size()),
                                                   static_cast<double>(mesh.elements.size()), settings));
}

double Matrix::estimate_bytes(double rows, double elements, const MatrixSettings& settings) {
    const double channels = settings.grey ? 1.0 : 3.0;
    const double dense = settings.interreflection ? channels * rows * rows * sizeof(double) : 0.0;
    // An estimate, not a bound: a row holds at most every element (uint32 + double, 12 bytes),
    // but a hemicube sees a fraction of the scene, so a quarter of that worst case is charged.
    const double sparse = rows * elements * 12.0 / 4.0;
    // The engine's dense results for one batch, one double per element per shot.
    const double batch = std::max(1, settings.batch) * elements * sizeof(double);
    return dense + sparse + batch;
}

double Matrix::expected_sweeps(double q, double tolerance) {
    if (!(q < 1.0)) return std::numeric_limits<double>::infinity();
    if (q <= 0.0) return 1.0;
    return std::max(1.0, std::ceil(std::log(tolerance * (1.0 - q)) / (2.0 * std::log(q))));
}

bool Matrix::cancelled() const {
    return settings_.cancel != nullptr && settings_.cancel->load();
}

void Matrix::solve(const std::function<void(long, long)>& progress) {
    if (solved_) return;
    solved_ = true;
    if (!shoot_rows(progress)) {
        // The rows are incomplete, so K and its residual are undefined: keep B_p = E_p and
        // gather what the rows done so far deliver.
        error_bound_ = std::numeric_limits<double>::infinity();
        converged_ = false;
        gather();
        return;
    }
    if (settings_.interreflection) {
        gauss_seidel();
    } else {
        error_bound_ = 0.0;  // B_p = E_p is exact for direct light
        converged_ = true;
    }
    gather();
}

bool Matrix::shoot_rows(const std::function<void(long, long)>& progress) {
    // Rows do not depend on the batching: as many as the engine likes in flight.
    const std::size_t batch = engine_.batch_for(settings_.batch, settings_.engine_batch);
    const long total = static_cast<long>(active_.size());
    std::vector<std::uint32_t> pending;  // all active patches, or those a loaded state lacks
    for (std::uint32_t p : active_)
        if (!rows_[p].shot) pending.push_back(p);
    std::vector<formfactor::ShotRequest> requests;
    std::vector<formfactor::ShotResult> results;
    for (std::size_t first = 0; first < pending.size(); first += batch) {
        if (cancelled()) return false;
        requests.clear();
        // Shot counter = patch index: a row does not depend on the batching or on which other
        // patches are active.
        for (std::size_t k = first; k < std::min(first + batch, pending.size()); ++k)
            requests.push_back(formfactor::ShotRequest::of_patch(pending[k], pending[k]));
        engine_.shoot_batch(requests, results);
        for (std::size_t k = 0; k < requests.size(); ++k) {
            const formfactor::ShotResult& shot = results[k];
            Row& row = rows_[requests[k].shooter.patch];
            row.element.reserve(shot.size());
            row.F.reserve(shot.size());
            for (std::size_t i = 0; i < shot.size(); ++i) {
                if (shot.F[i] == 0.0) continue;
                row.element.push_back(shot.element[i]);
                row.F.push_back(shot.F[i]);
                row.f_sum += shot.F[i];
            }
            row.blocked = shot.blocked;
            row.shot = true;
            ++rows_done_;
        }
        if (progress) progress(rows_done_, total);
    }
    return true;
}

void Matrix::save(std::ostream& out) const {
    using namespace state_io;
    put(out, static_cast<std::uint64_t>(active_.size()));
    put(out, static_cast<std::int64_t>(rows_done_));
    for (std::uint32_t p : active_) {
        const Row& row = rows_[p];
        put(out, static_cast<std::uint8_t>(row.shot ? 1 : 0));
        if (!row.shot) continue;
        put_vector(out, row.element);
        put_vector(out, row.F);
        put(out, row.f_sum);
        put(out, row.blocked);
    }
}

void Matrix::load(std::istream& in) {
    using namespace state_io;
    std::uint64_t active = 0;
    std::int64_t done = 0;
    get(in, active);
    get(in, done);
    if (active != active_.size() || solved_) throw std::runtime_error("the checkpoint is for another mesh");
    long shot = 0;
    for (std::uint32_t p : active_) {
        Row& row = rows_[p];
        std::uint8_t flag = 0;
        get(in, flag);
        row = Row{};
        if (flag == 0) continue;
        get_vector(in, row.element, kAny, mesh_.elements.size());
        get_vector(in, row.F, row.element.size());
        for (std::uint32_t j : row.element)
            if (j >= mesh_.elements.size()) throw std::runtime_error("a row names an element the mesh does not have");
        get(in, row.f_sum);
        get(in, row.blocked);
        row.shot = true;
        ++shot;
    }
    if (shot != done) throw std::runtime_error("its row count does not match its rows");
    rows_done_ = shot;
}

void Matrix::gauss_seidel() {
    // Unknowns are the active patches only: the others have E = 0 and ρ = 0, so B = 0.
    const std::size_t n = active_.size();
    const int C = channels_;
    constexpr std::uint32_t kInactive = std::numeric_limits<std::uint32_t>::max();
    std::vector<std::uint32_t> index(mesh_.patches.size(), kInactive);
    for (std::size_t a = 0; a < n; ++a) index[active_[a]] = static_cast<std::uint32_t>(a);

    // K_pi = Σ_{j∈p} ρ_j F_ij A_i / A_p: patch p's share of what patch i shoots, reflected.
    // One dense n×n block per channel, row-major, so a row's dot product runs contiguously.
    std::vector<std::vector<double>> K(static_cast<std::size_t>(C), std::vector<double>(n * n, 0.0));
    for (std::size_t a = 0; a < n; ++a) {
        const std::uint32_t i = active_[a];
        const Row& row = rows_[i];
        const double A_i = mesh_.patches[i].area;
        for (std::size_t k = 0; k < row.element.size(); ++k) {
            const mesh::Element& e = mesh_.elements[row.element[k]];
            const std::uint32_t p = index[e.patch];
            if (p == kInactive) continue;  // ρ = 0 there
            const double w = row.F[k] * A_i / mesh_.patches[e.patch].area;
            for (int c = 0; c < C; ++c) K[static_cast<std::size_t>(c)][p * n + a] += e.rho[c] * w;
        }
    }

    std::vector<std::vector<double>> E(static_cast<std::size_t>(C), std::vector<double>(n));
    for (std::size_t a = 0; a < n; ++a)
        for (int c = 0; c < C; ++c) E[static_cast<std::size_t>(c)][a] = source_[active_[a]][c];
    std::vector<std::vector<double>> B = E;  // start from the emission: the first sweep is direct light

    const auto dot = [n](const double* k, const std::vector<double>& b) {
        double s = 0.0;
        for (std::size_t i = 0; i < n; ++i) s += k[i] * b[i];
        return s;
    };
    // How far B can be from the solution B*, by flux: with A the patch areas, B − B* = (I − K)⁻¹ r
    // for the residual r = E + K B − B, and in the flux norm ‖x‖ = Σ_p A_p |x_p| the norm of K is
    // its largest column sum q = max_i Σ_p A_p K_pi / A_i = max_i Σ_j ρ_j F_ij ≤ ρ_max: each shot
    // sends out at most what it holds (ΣF ≤ 1), exactly, whatever the rows' noise. So
    // Σ A |B − B*| ≤ Σ A |r| / (1 − q), relative to Σ A B: the bound the sweeps stop on. (A bound
    // on the residual alone stopped a box at ρ = 0.999 at 952 instead of 1000: 1 / (1 − ρ)
    // amplifies it.) One full product per check, so it is that of the B returned.
    std::vector<double> area(n);
    for (std::size_t a = 0; a < n; ++a) area[a] = mesh_.patches[active_[a]].area;
    double q = 0.0;
    for (std::size_t c = 0; c < static_cast<std::size_t>(C); ++c) {
        std::vector<double> column(n, 0.0);  // Σ_p A_p K_pa, summed row by row (K is row-major)
        for (std::size_t p = 0; p < n; ++p)
            for (std::size_t a = 0; a < n; ++a) column[a] += area[p] * K[c][p * n + a];
        for (std::size_t a = 0; a < n; ++a) q = std::max(q, column[a] / area[a]);
    }
    contraction_ = q;
    const auto bound_now = [&]() {
        double worst = 0.0;
        for (std::size_t c = 0; c < static_cast<std::size_t>(C); ++c) {
            double r = 0.0, flux = 0.0;
            for (std::size_t p = 0; p < n; ++p) {
                r += area[p] * std::abs(E[c][p] + dot(&K[c][p * n], B[c]) - B[c][p]);
                flux += area[p] * B[c][p];
            }
            if (r > 0.0)
                worst = std::max(worst, flux > 0.0 && q < 1.0 ? r / ((1.0 - q) * flux)
                                                              : std::numeric_limits<double>::infinity());
        }
        return worst;
    };

    error_bound_ = bound_now();
    while (error_bound_ > settings_.tolerance && iterations_ < settings_.max_iterations && !cancelled()) {
        for (std::size_t c = 0; c < static_cast<std::size_t>(C); ++c) {
            std::vector<double>& b = B[c];
            for (std::size_t p = 0; p < n; ++p) {
                const double* k = &K[c][p * n];
                // Row p of (I − K) B = E solved for B_p, the rest at their latest values. K_pp is
                // zero for a planar patch but kept so any mesh gives the exact row solve.
                const double others = dot(k, b) - k[p] * b[p];
                b[p] = (E[c][p] + others) / (1.0 - k[p]);
            }
        }
        ++iterations_;
        error_bound_ = bound_now();
    }
    converged_ = error_bound_ <= settings_.tolerance;

    for (std::size_t a = 0; a < n; ++a) {
        glm::dvec3& out = Bp_[active_[a]];
        for (int c = 0; c < 3; ++c) out[c] = B[static_cast<std::size_t>(std::min(c, C - 1))][a];
    }
}

void Matrix::gather() {
    // H_j = Σ_i F_ij A_i B_i / A_j over the rows shot; accumulate flux, then divide.
    if (direct_.empty())
        std::fill(H_.begin(), H_.end(), glm::dvec3(0.0));
    else
        for (std::size_t j = 0; j < H_.size(); ++j) H_[j] = direct_[j] * mesh_.elements[j].area;
    for (std::size_t i = 0; i < rows_.size(); ++i) {
        const Row& row = rows_[i];
        if (!row.shot) continue;
        const glm::dvec3 flux = Bp_[i] * mesh_.patches[i].area;
        for (std::size_t k = 0; k < row.element.size(); ++k) H_[row.element[k]] += flux * row.F[k];
    }
    for (std::size_t j = 0; j < H_.size(); ++j) {
        const mesh::Element& e = mesh_.elements[j];
        H_[j] /= e.area;
        B_[j] = e.emission + e.rho * H_[j];
    }
}

Energy Matrix::energy() const {
    glm::dvec3 emitted{0.0}, absorbed{0.0}, escaped{0.0};
    for (std::size_t j = 0; j < mesh_.elements.size(); ++j) {
        const mesh::Element& e = mesh_.elements[j];
        emitted += e.emission * e.area;
        if (!direct_.empty()) emitted += direct_[j] * e.area;  // the lights' flux that landed
        absorbed += (glm::dvec3(1.0) - e.rho) * H_[j] * e.area;
    }
    for (std::size_t i = 0; i < rows_.size(); ++i) {
        const Row& row = rows_[i];
        if (!row.shot) continue;
        const glm::dvec3 flux = Bp_[i] * mesh_.patches[i].area;
        absorbed += flux * row.blocked;
        escaped += flux * (1.0 - row.f_sum - row.blocked);  // may be −1e-16: the books stay exact
    }
    // What is neither absorbed nor escaped is the residual's flux: light the solution has not
    // yet (or, for direct light only, will never) send on.
    const glm::dvec3 unshot = emitted - absorbed - escaped;
    return {mean(emitted), mean(absorbed), mean(escaped), mean(unshot)};
}

}  // namespace hemirad::solve
