#pragma once
/// @file modal.hpp
/// Modal parameters from (A, C) (paper Eq. 5, conventions.md "Modes").

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "realization.hpp"

namespace modaluq {

/// The modes identified at one model order, sorted by frequency. One mode per complex
/// conjugate pair of eigenvalues (Im lambda > 0); real eigenvalues are dropped.
struct Modes {
    Index order = 0;                     ///< model order n
    Eigen::VectorXcd eigenvalue;         ///< discrete-time eigenvalue lambda of A
    Eigen::VectorXd frequency_hz;        ///< |mu| / (2 pi), mu = ln(lambda) fs, in Hz
    Eigen::VectorXd damping_ratio;       ///< -Re(mu) / |mu|, a fraction (0.02 = 2 %)
    Eigen::MatrixXcd mode_shape;         ///< l x n_modes, C phi scaled so its largest-modulus component is 1
    Eigen::VectorXi reference_component; ///< per mode, the component scaled to exactly 1

    // Uncertainty (empty when not computed); first-order, from the block covariance.
    Eigen::VectorXd frequency_std;       ///< Hz
    Eigen::VectorXd damping_std;         ///< fraction
    Eigen::MatrixXd mode_shape_std_real; ///< l x n_modes, std of Re of the normalised shape
    Eigen::MatrixXd mode_shape_std_imag; ///< l x n_modes, std of Im of the normalised shape
    /// (2 + 2l)^2 x n_modes; column i is mode i's covariance of [f, xi, Re shape, Im shape]
    /// (symmetric, so row- and column-major readings agree).
    Eigen::MatrixXd covariance;
    /// 2 n_b x n_modes; column i is [u_f^T; u_xi^T], the rows of f (Hz) and xi (fraction) of mode
    /// i's first-order factor U (covariance = U U^T), one entry per block of the covariance factor
    /// T (docs/uq-math.md §3; for identify_setups the blocks of every setup, setup by setup,
    /// (12.7)): var f = |u_f|^2, cov(f, xi) = u_f . u_xi, exactly `covariance`'s [f, xi] block.
    /// What the selection's sigma of a cluster's mean is formed from (ClusteringOptions::cluster_std,
    /// docs/uq-math.md §13.10): 2 n_b doubles per mode.
    Eigen::MatrixXd frequency_damping_factor;
    /// (2 l n_b) x n_modes, empty unless IdentifyOptions::keep_shape_factor: column i is mode i's
    /// first-order factor V of [Re shape; Im shape] (2l x n_b, stored column-major, so block k's
    /// 2l entries are contiguous): the shape rows of the U whose U U^T is `covariance`. Two poles of
    /// one identification share the blocks, so V_i V_j^T is the cross-covariance of their shapes,
    /// which the sigma of their MAC needs (modal_assurance_statistics with a joint covariance).
    Eigen::MatrixXd mode_shape_factor;
    /// Per mode, the correlation of f and xi, cov(f, xi) / sqrt(var f var xi) from `covariance`
    /// (NaN where a variance is 0).
    Eigen::VectorXd frequency_damping_correlation;
    /// Per mode: the block is shorter than half the mode's decay time constant
    /// 1/(2 pi f xi), so the blocks are not independent enough for its covariance (docs/uq-math.md §10.7).
    Eigen::Array<bool, Eigen::Dynamic, 1> block_too_short;
    /// (sigma_n - sigma_{n+1}) / std(sigma_n - sigma_{n+1}); NaN without uncertainty.
    double singular_value_gap = std::numeric_limits<double>::quiet_NaN();
    /// The order cuts between two significant singular values (order < k*, the noise floor)
    /// that are closer than three times the std of their difference: a pair of modes may be
    /// split, and the first-order uncertainty of this order is not meaningful (docs/uq-math.md §5.4).
    /// Cuts inside the noise (order >= k*) are not flagged: those directions are frozen (§5.5).
    bool close_singular_values = false;
    /// Per mode, rho of docs/uq-math.md (5.14): sigma_f or sigma_xi with the noise singular vectors free
    /// to rotate, over the same with them frozen (1 at orders <= k*, where nothing is frozen).
    Eigen::VectorXd noise_coupling;
    /// Per mode, noise_coupling > IdentifyOptions::noise_coupling_limit: the pole depends mostly
    /// on noise directions (a spurious pole, or a physical one mixed with a spurious one), no
    /// first-order value is meaningful, and its std are the unfrozen, conservative ones.
    Eigen::Array<bool, Eigen::Dynamic, 1> noise_coupled;
    /// Per mode, the variance factor c of the block-correlation correction (docs/uq-math.md §3.1,
    /// IdentifyOptions::block_correlation_correction): its factor, covariance and std are sqrt(c)
    /// and c times the uncorrected ones; 1 when the correction is off.
    Eigen::VectorXd block_correlation_scale;
    /// Per mode: its sigma_f and sigma_xi are the bootstrap's (IdentifyOptions::bootstrap_draws,
    /// docs/uq-math.md §5.6), not the first-order ones: an order above the noise floor k*, a pole
    /// not noise_coupled and followed in enough draws. Its covariance's f and xi rows and columns
    /// and its frequency_damping_factor rows are rescaled to them (correlations kept); the shape
    /// entries stay first-order.
    Eigen::Array<bool, Eigen::Dynamic, 1> bootstrapped;
    /// No modes at this order: it is above the numerical rank of H, or (A, C) has no usable
    /// eigen-decomposition there (`note` says which). The other orders are unaffected.
    bool degenerate = false;
    std::string note;                    ///< why the order is degenerate (empty otherwise)

    Index n_modes() const { return frequency_hz.size(); }
};

/// The eigen-decomposition of A behind one order's modes, what the uncertainty propagation
/// (UncertaintyPropagator::apply) needs besides the modes: A = V diag(values) V^{-1}; the rows
/// of V^{-1} are left eigenvectors chi^H with chi_i^H phi_i = 1.
struct Eigenstructure {
    Eigen::VectorXcd values;
    Eigen::MatrixXcd right;      ///< V
    Eigen::MatrixXcd left_h;     ///< V^{-1}
    std::vector<Index> kept;     ///< index into values of each reported mode, in frequency order
};

/// Modes of (A, C) sampled at fs Hz. If `eig` is given, the eigen-decomposition is stored
/// there for the uncertainty propagation.
inline Modes modes_from_system(const StateSpace& ss, double fs, Eigenstructure* eig = nullptr) {
    using cd = std::complex<double>;
    const Index n = ss.A.rows();
    if (!ss.A.allFinite() || !ss.C.allFinite())
        throw numerical_error("A or C is not finite (Gamma_up is numerically singular at this order)");
    Eigen::EigenSolver<Eigen::MatrixXd> es(ss.A, /*computeEigenvectors=*/true);
    if (es.info() != Eigen::Success) throw numerical_error("eigen-decomposition of A did not converge");
    const Eigen::VectorXcd values = es.eigenvalues();
    std::vector<Index> kept;
    for (Index i = 0; i < n; ++i)
        if (values(i).imag() > 0.0) kept.push_back(i);
    std::vector<double> freq(n, 0.0);
    for (Index i : kept) freq[i] = std::abs(std::log(values(i)) * fs) / (2.0 * detail::pi);
    std::stable_sort(kept.begin(), kept.end(), [&](Index a, Index b) { return freq[a] < freq[b]; });

    const Index nm = static_cast<Index>(kept.size());
    const Eigen::MatrixXcd vectors = es.eigenvectors();
    Modes m;
    m.order = n;
    m.eigenvalue.resize(nm);
    m.frequency_hz.resize(nm);
    m.damping_ratio.resize(nm);
    m.mode_shape.resize(ss.C.rows(), nm);
    m.reference_component.resize(nm);
    for (Index i = 0; i < nm; ++i) {
        const cd lambda = values(kept[i]);
        const cd mu = std::log(lambda) * fs;
        m.eigenvalue(i) = lambda;
        m.frequency_hz(i) = std::abs(mu) / (2.0 * detail::pi);
        m.damping_ratio(i) = -mu.real() / std::abs(mu);
        Eigen::VectorXcd shape = ss.C * vectors.col(kept[i]);
        Index k;
        shape.cwiseAbs().maxCoeff(&k);
        const cd pivot = shape(k);
        shape /= pivot;
        shape(k) = 1.0;
        m.mode_shape.col(i) = shape;
        m.reference_component(i) = static_cast<int>(k);
    }
    if (eig) {
        eig->values = values;
        eig->right = vectors;
        eig->left_h = vectors.partialPivLu().inverse();
        eig->kept = kept;
    }
    return m;
}

}  // namespace modaluq
