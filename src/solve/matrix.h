// Full-matrix gathering (the article's first approach): one hemicube per patch gives its
// form-factor row, then the linear system B = E + K·B over patch radiosities is solved by
// Gauss–Seidel. Patches shoot (are the rows), elements receive. No ambient term is needed:
// once the error bound is small the solution is complete, not an estimate of the rest.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <vector>

#include "formfactor/engine.h"
#include "mesh/mesh.h"
#include "solve/progressive.h"
#include "solve/resumable.h"

namespace hemirad::solve {

struct MatrixSettings {
    // Stop the sweeps once the patch radiosities are provably within this of the solution, by
    // flux (Σ A |B − B*| / Σ A B, worst channel; see error_bound()).
    double tolerance = 1e-6;
    int max_iterations = 1000;  // Gauss–Seidel sweeps at most
    // Rows shot per engine call: one launch per kernel stage on the OpenCL engine.
    int batch = 64;
    bool engine_batch = false;  // rows per engine call: batch, or the engine's preferred batch where larger
    // Every ρ and E has r = g = b: solve one channel (a third of K's memory and time) and copy
    // it to the other two. The constructor throws std::invalid_argument if the scene is not grey.
    bool grey = false;
    // false: direct light only. Only emitting patches are shot (the time saving) and they shoot
    // their emission; what the receivers reflect goes nowhere (it is the books' `unshot`).
    bool interreflection = true;
    // Checked between batches of rows and between sweeps: once true, solve() stops early,
    // leaving converged() false. nullptr: never.
    const std::atomic<bool>* cancel = nullptr;
};

// A bake's settings: iterate to an error bound of min(1e-4, threshold / 100) and shoot rows in
// batches of at least 64 (one launch per kernel stage on OpenCL, what fills a GPU).
MatrixSettings matrix_settings(double threshold, int batch);

class Matrix final : public Resumable {
public:
    // Throws std::invalid_argument when settings.grey is set and some element's ρ or E is not grey.
    // `direct`, if set, is the irradiance per element the punctual lights have already shot
    // (solve/lights.h): its reflection is a source like emission, B = E + ρ·H_direct + K·B.
    Matrix(const mesh::Mesh& mesh, formfactor::Engine& engine, const MatrixSettings& settings,
           const std::vector<glm::dvec3>* direct = nullptr);

    // An estimate of the memory solve() needs, P being the patches that get rows: the dense K
    // exactly (none for direct light), the sparse rows at a quarter of their worst case (every
    // row holding all E elements, 12 bytes each: P·E·12), and the engine's results for one
    // batch (batch·E doubles). The second form counts before a mesh is built.
    static std::size_t estimate_bytes(const mesh::Mesh& mesh, const MatrixSettings& settings);
    static double estimate_bytes(double rows, double elements, const MatrixSettings& settings);

    // Gauss–Seidel sweeps expected to bring the error bound to `tolerance` where K's norm is q
    // (at most the largest reflectance): the bound starts near 1 / (1 − q) times the residual,
    // and a sweep shrinks it by about q², the square of Jacobi's rate q (the rate Young's theorem
    // gives for consistently ordered systems, which K is not: a model, checked against the solver's
    // own sweeps in test_budget), so ln(tolerance (1 − q)) / (2 ln q); infinite for q >= 1.
    static double expected_sweeps(double q, double tolerance);

    // Computes the rows not yet computed (calling `progress(rows_done, rows_total)` after each
    // batch if set) and solves. Does its work once: later calls return at once.
    void solve(const std::function<void(long, long)>& progress = {});

    // Resumable: the rows computed so far (a checkpoint written from `progress`); a loaded
    // solver computes the others and then solves exactly as the saved one would have.
    void save(std::ostream& out) const override;
    void load(std::istream& in) override;

    long rows() const { return rows_done_; }        // rows computed (hemicubes shot)
    int iterations() const { return iterations_; }  // Gauss–Seidel sweeps
    // A bound on the flux-weighted relative error of the final patch radiosities, Σ A |B − B*| /
    // Σ A B (worst channel): the residual's flux over (1 − q), q = contraction(); as for
    // `tolerance`. 0 for direct light, infinite when cancelled before every row was shot.
    double error_bound() const { return error_bound_; }
    // The norm of K in flux, q = max_i Σ_j ρ_j F_ij ≤ the largest reflectance: each sweep's error
    // shrinks by at least this (0 before the sweeps).
    double contraction() const { return contraction_; }
    bool converged() const { return converged_; }  // error_bound <= tolerance; direct light: all rows shot

    std::vector<glm::dvec3> radiosity() const { return B_; }         // per element B_j = E_j + ρ_j H_j
    std::vector<glm::dvec3> irradiance() const { return H_; }        // per element H_j
    std::vector<glm::dvec3> patch_radiosity() const { return Bp_; }  // per patch: what it shot

    // emitted Σ E_j A_j; absorbed Σ_j (1 − ρ_j) H_j A_j + Σ_i blocked_i B_i A_i; escaped
    // Σ_i B_i A_i (1 − ΣF_i − blocked_i); unshot = emitted − absorbed − escaped, which is the
    // residual's flux Σ_p A_p (E_p + Σ_i K_pi B_i − B_p) (with direct light only: the reflected
    // flux Σ ρ_j H_j A_j). Averaged over r, g, b like Progressive::energy().
    Energy energy() const;

private:
    // One patch's form factors, sparse: the elements it sees and F to each.
    struct Row {
        std::vector<std::uint32_t> element;
        std::vector<double> F;
        double f_sum = 0.0;
        double blocked = 0.0;
        bool shot = false;
    };

    const mesh::Mesh& mesh_;
    formfactor::Engine& engine_;
    MatrixSettings settings_;
    int channels_ = 3;                   // 1 when grey
    std::vector<std::uint32_t> active_;  // patches that get rows, ascending
    std::vector<Row> rows_;              // per patch; empty where not active
    long rows_done_ = 0;
    int iterations_ = 0;
    double error_bound_ = 0.0;
    double contraction_ = 0.0;
    bool converged_ = false;
    bool solved_ = false;

    std::vector<glm::dvec3> Bp_;  // per patch
    std::vector<glm::dvec3> B_;   // per element
    std::vector<glm::dvec3> H_;   // per element
    std::vector<glm::dvec3> direct_;  // per element, the lights' irradiance (empty: none)
    std::vector<glm::dvec3> source_;  // per patch, E: its emission, and with interreflection ρ·H_direct

    bool cancelled() const;
    bool shoot_rows(const std::function<void(long, long)>& progress);  // false when cancelled
    void gauss_seidel();
    void gather();  // H_j and B_j from the rows and Bp_
};

}  // namespace hemirad::solve
