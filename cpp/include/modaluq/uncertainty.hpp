#pragma once
/// @file uncertainty.hpp
/// First-order propagation of the block covariance of R1..R4 to the modal parameters at
/// every order (docs/uq-math.md §5-§9; Doehler & Mevel 2013). The covariance is carried as its
/// factor T (Sigma = T T^T), one column per block: no h x h matrix is ever formed.
///
/// Stages (internals in `detail/`, each finite-difference tested):
///  1. T_H = J_{H,R} T_R                                        subspace.hpp
///  2-3. dGamma for j <= n_max and the Q matrices at n_max, fused  detail/svd_perturbation.hpp
///     (columns from the noise floor k* on frozen, docs/uq-math.md §5.5: detail/noise_floor.hpp)
///  4. per order, all blocks: d lambda, d(C phi)                detail/eigen_perturbation.hpp
///  5. per mode: f, xi and the normalised mode shape            detail/eigen_perturbation.hpp

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <complex>
#include <functional>
#include <limits>
#include <vector>

#include "detail/eigen_perturbation.hpp"
#include "detail/gemm.hpp"
#include "detail/noise_floor.hpp"
#include "detail/parallel.hpp"
#include "detail/svd_perturbation.hpp"
#include "modal.hpp"
#include "realization.hpp"

namespace modaluq {

namespace detail {

/// Size the uncertainty fields of `modes` (its n_modes modes, l outputs, n_b blocks); the
/// noise-coupling fields start at rho = 1, not flagged. The shape factor is sized (and so kept
/// by set_mode_uncertainty) only with `keep_shape_factor`.
inline void resize_mode_uncertainty(Modes& modes, Index l, Index nb, bool keep_shape_factor = false) {
    const Index nm = modes.n_modes(), np = 2 + 2 * l;
    modes.frequency_std.resize(nm);
    modes.damping_std.resize(nm);
    modes.mode_shape_std_real.resize(l, nm);
    modes.mode_shape_std_imag.resize(l, nm);
    modes.covariance.resize(np * np, nm);
    modes.frequency_damping_factor.resize(2 * nb, nm);
    modes.mode_shape_factor.resize(keep_shape_factor ? 2 * l * nb : 0, keep_shape_factor ? nm : 0);
    modes.block_too_short.resize(nm);
    modes.frequency_damping_correlation.resize(nm);
    modes.noise_coupling = Eigen::VectorXd::Ones(nm);
    modes.noise_coupled = Eigen::Array<bool, Eigen::Dynamic, 1>::Constant(nm, false);
    modes.block_correlation_scale = Eigen::VectorXd::Ones(nm);
    modes.bootstrapped = Eigen::Array<bool, Eigen::Dynamic, 1>::Constant(nm, false);
}

/// The variance factor c of the block-correlation correction (docs/uq-math.md §3.1) of one mode
/// from rows 0 (f) and 1 (xi) of its factor (columns: the blocks in time order):
/// rho_r = sum_k u_r(k) u_r(k+1) / sum_k u_r(k)^2, rho = mean of the defined rho_r + 1/n_b,
/// c = max(1/4, 1 + 2 rho) where |rho| > 2 / sqrt(n_b) (twice rho's sampling std), else 1
/// (and 1 when neither row has a nonzero entry).
inline double block_correlation_scale(const Eigen::Ref<const Eigen::MatrixXd>& ut) {
    const Index nb = ut.cols();
    if (nb < 2) return 1.0;
    double sum = 0.0;
    int defined = 0;
    for (Index r : {0, 1}) {
        const auto u = ut.row(r);
        const double s0 = u.squaredNorm();
        if (!(s0 > 0.0)) continue;
        sum += u.head(nb - 1).dot(u.tail(nb - 1)) / s0;
        ++defined;
    }
    if (defined == 0) return 1.0;
    const double rho = sum / defined + 1.0 / static_cast<double>(nb);
    if (!(std::abs(rho) > 2.0 / std::sqrt(static_cast<double>(nb)))) return 1.0;  // the gate
    return std::max(0.25, 1.0 + 2.0 * rho);
}

/// Mode i's uncertainty from its factor `ut` ((2 + 2l) x n_b, rows f, xi, Re shape, Im shape,
/// stage 5): the covariance U U^T, the std, the f-xi correlation, the factor rows of f and xi (and
/// of the shape, where resize_mode_uncertainty kept room for them), and the block-length flag
/// (blocks of block_seconds).
inline void set_mode_uncertainty(Modes& modes, Index i, const Eigen::MatrixXd& ut, double block_seconds) {
    const Index np = ut.rows(), l = (np - 2) / 2, nb = ut.cols();
    const Eigen::MatrixXd cov = ut * ut.transpose();
    modes.covariance.col(i) = Eigen::Map<const Eigen::VectorXd>(cov.data(), np * np);
    modes.frequency_damping_factor.col(i).head(nb) = ut.row(0).transpose();
    modes.frequency_damping_factor.col(i).tail(nb) = ut.row(1).transpose();
    if (modes.mode_shape_factor.cols() == modes.n_modes())
        Eigen::Map<Eigen::MatrixXd>(modes.mode_shape_factor.col(i).data(), 2 * l, nb) = ut.bottomRows(2 * l);
    const Eigen::VectorXd sd = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
    modes.frequency_std(i) = sd(0);
    modes.damping_std(i) = sd(1);
    modes.frequency_damping_correlation(i) = cov(0, 0) > 0.0 && cov(1, 1) > 0.0
                                                 ? cov(1, 0) / std::sqrt(cov(0, 0) * cov(1, 1))
                                                 : std::numeric_limits<double>::quiet_NaN();
    modes.mode_shape_std_real.col(i) = sd.segment(2, l);
    modes.mode_shape_std_imag.col(i) = sd.segment(2 + l, l);
    const double decay_s = 1.0 / (2.0 * pi * modes.frequency_hz(i) * modes.damping_ratio(i));
    modes.block_too_short(i) = modes.damping_ratio(i) > 0.0 && block_seconds < 0.5 * decay_s;
}

}  // namespace detail

/// How the propagation treats the singular vectors below the noise floor (docs/uq-math.md §5.5).
struct NoiseOptions {
    /// Hold the directions of the singular vectors from the noise floor k* on fixed (their scale
    /// still moves). false propagates every rotation, as first-order theory alone would.
    bool freeze = true;
    double floor_factor = 1.5;    ///< c of (5.12): k* is the first k with s_k < c delta_k
    /// rho_max of (5.14): a pole whose sigma_f or sigma_xi shrinks by more than this factor when
    /// the noise directions are frozen is noise-coupled; it keeps the unfrozen (larger) sigma.
    double coupling_limit = 20.0;
};

/// Sensitivities computed once at the largest order and reused by every order.
class UncertaintyPropagator {
public:
    /// @param re   the realization (SVD of H, Gamma at n_max)
    /// @param t_h  T_H, (a b) x n_b: column k is vec dH^k (column-major)
    /// @param b    columns of H
    /// @param threads  threads for the per-block work (results do not depend on it)
    /// @param block_correlation_correction  scale each mode's factor by sqrt(c) (docs/uq-math.md §3.1)
    /// @param keep_shape_factor  keep each mode's shape factor (Modes::mode_shape_factor)
    UncertaintyPropagator(const Realization& re, const Eigen::MatrixXd& t_h, Index b, Index threads = 1,
                          NoiseOptions noise = {}, bool block_correlation_correction = false,
                          bool keep_shape_factor = false)
        : l_(re.n_outputs()), singular_values_(re.singular_values()), gamma_up_r_(re.gamma_up_r()),
          nb_(t_h.cols()), noise_(noise), block_correction_(block_correlation_correction),
          keep_shape_factor_(keep_shape_factor) {
        const Index a = re.U().rows(), n = re.max_order(), l = re.n_outputs();
        const Index n_sigma = std::min<Index>(n + 1, re.singular_values().size());
        detail::require(t_h.rows() == a * b, "T_H must have a*b rows");
        floor_ = detail::noise_floor(re, t_h, b, noise.floor_factor, n + 1, threads);
        dsigma_.resize(n_sigma, nb_);
        q_ = detail::BlockQ(nb_, n, l);
        const detail::QStage stage(re, n_sigma, noise.freeze ? floor_.k : std::numeric_limits<Index>::max());
        if (stage.freezes()) qf_ = detail::BlockQ(nb_, n, l);
        detail::parallel_for(nb_, threads, [&](Index k) {  // blocks write disjoint elements
            Eigen::Map<const Eigen::MatrixXd> dh(t_h.col(k).data(), a, b);
            detail::QBlock base, frozen;
            stage.compute(dh, base, &frozen, dsigma_.col(k));
            q_.set(k, base.qa, base.qb, base.q4);
            if (stage.freezes()) qf_.set(k, frozen.qa, frozen.qb, frozen.q4);
        });
    }

    Index n_blocks() const { return nb_; }
    /// Standard deviation of the singular value s_{j+1} of H (j < max_order + 1).
    double singular_value_std(Index j) const { return dsigma_.row(j).norm(); }
    /// k*: singular values of H above the noise floor (eq. 5.12), at most max_order + 1.
    Index significant_singular_values() const { return floor_.k; }

    /// Fill the uncertainty fields of `modes` (order n) from its eigenstructure.
    /// @param block_seconds  duration of one block, N_b / fs, for the block-length check
    void apply(Modes& modes, const Eigenstructure& eig, const StateSpace& ss, double fs,
               double block_seconds) const {
        using detail::cd;
        const Index n = modes.order, nm = modes.n_modes();
        detail::resize_mode_uncertainty(modes, l_, nb_, keep_shape_factor_);

        // Singular-value gap at this order, judged against its own uncertainty. Only a cut
        // between significant singular values matters: one in the noise is frozen (§5.5).
        const Eigen::VectorXd& s = singular_values_;
        const double sd_gap = (n < dsigma_.rows()) ? (dsigma_.row(n - 1) - dsigma_.row(n)).norm()
                                                   : dsigma_.row(n - 1).norm();
        modes.singular_value_gap = ((n < s.size()) ? s(n - 1) - s(n) : s(n - 1)) / sd_gap;
        modes.close_singular_values = n < floor_.k && !(modes.singular_value_gap >= 3.0);
        if (nm == 0) return;

        const detail::OrderContext ctx(eig, ss, gamma_up_r_);
        const bool frozen = qf_.nb > 0 && n > floor_.k;  // orders up to k* have nothing frozen
        Eigen::MatrixXcd dlam, dlam_f;
        std::vector<Eigen::MatrixXcd> dshape, dshape_f;
        std::vector<Eigen::MatrixXd> ut_f;
        if (frozen) {
            // Frozen pass in full; the unfrozen one for rho (5.14) and the shapes of flagged poles.
            detail::eigen_perturbation_blocks(ctx, qf_, dlam_f, dshape_f);
            for (Index i = 0; i < nm; ++i)
                ut_f.push_back(detail::modal_perturbation(ctx.lambda(i), fs, ss.C.cast<cd>() * ctx.phi.col(i),
                                                          modes.reference_component(i), dlam_f.row(i), dshape_f[i]));
            detail::eigen_perturbation_blocks(ctx, q_, dlam, dshape, [&](Index i) {
                // how much of sigma_f or sigma_xi the noise directions carry
                const double rho = detail::noise_coupling(
                    detail::frequency_damping_perturbation(ctx.lambda(i), fs, dlam.row(i)), ut_f[i]);
                modes.noise_coupling(i) = rho;
                modes.noise_coupled(i) = !(rho <= noise_.coupling_limit);
                return bool(modes.noise_coupled(i));
            });
        } else {
            detail::eigen_perturbation_blocks(ctx, q_, dlam, dshape);
        }
        for (Index i = 0; i < nm; ++i) {
            Eigen::MatrixXd ut =
                (frozen && !modes.noise_coupled(i))
                    ? ut_f[i]
                    : detail::modal_perturbation(ctx.lambda(i), fs, ss.C.cast<cd>() * ctx.phi.col(i),
                                                 modes.reference_component(i), dlam.row(i), dshape[i]);
            if (block_correction_) {
                modes.block_correlation_scale(i) = detail::block_correlation_scale(ut);
                ut *= std::sqrt(modes.block_correlation_scale(i));
            }
            detail::set_mode_uncertainty(modes, i, ut, block_seconds);
        }
    }

private:
    Index l_;                         ///< outputs
    Eigen::VectorXd singular_values_;  ///< of H
    Eigen::MatrixXd gamma_up_r_;       ///< R of Gamma_up = Q R at n_max (stage 4's W)
    Index nb_;
    NoiseOptions noise_;
    bool block_correction_ = false;
    bool keep_shape_factor_ = false;
    detail::NoiseFloor floor_;
    Eigen::MatrixXd dsigma_;  ///< d sigma_j per block, j < n_max + 1
    detail::BlockQ q_;        ///< Q1..Q4 of every block at n_max
    detail::BlockQ qf_;       ///< the same with the noise columns frozen (empty if none is)
};

}  // namespace modaluq
