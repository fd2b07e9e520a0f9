#pragma once
/// @file poser.hpp
/// PoSER ("post separate estimation re-scaling") merge of a campaign in several setups
/// (issue 23, docs/uq-math.md §13.5 and §13.9): each setup is identified alone and its modes
/// selected as for one record; this header matches the modes across setups, combines f and xi
/// by inverse-variance weights, rescales each setup's shape onto the reference components of
/// one basis setup and assembles the global shape (references once), with the first-order
/// covariance propagated from each setup's own covariance of [f, xi, Re shape, Im shape] (the
/// setups are independent records). It also tests, per setup and mode, whether the setup's
/// reference components agree with the basis setup's up to one complex scale within their
/// propagated covariance: a mislabelled or moved reference fails that test.
///
/// Sans-IO: the input is each setup's modes with their covariance (Modes at one order, or the
/// representative poles of select_modes), whatever produced them.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <vector>

#include "errors.hpp"
#include "modal.hpp"

namespace modaluq {

/// One setup's modes, the input of poser_merge.
struct PoserSetupModes {
    Eigen::VectorXd frequency_hz;   ///< m, Hz
    Eigen::VectorXd damping_ratio;  ///< m, fraction
    /// l_j x m, each column normalised as the setup's identification gives it (any complex
    /// scale: the merge does not depend on it)
    Eigen::MatrixXcd mode_shape;
    /// (2 + 2 l_j)^2 x m: column i is mode i's covariance of [f, xi, Re shape, Im shape] in
    /// column-major order (Modes::covariance). Empty (0 columns): no uncertainty.
    Eigen::MatrixXd covariance;
    /// Output indices (rows of mode_shape) of the r common reference channels, in the same
    /// global order in every setup. Every other row is a moving channel.
    std::vector<Index> references;
};

/// How poser_merge matches and tests.
struct PoserOptions {
    /// Two modes of different setups may be one mode when their frequencies differ by at most
    /// this fraction of the target's frequency.
    double frequency_tolerance = 0.05;
    /// ... and the MAC of their reference components is at least this. 0 (default): no gate,
    /// the MAC only ranks candidates. A mislabelled reference lowers this MAC; with the gate off
    /// the mode stays matched and the reference test below names the setup.
    double min_reference_mac = 0.0;
    /// A mode is reported when matched in at least this many setups; 0: in every setup. DOFs of
    /// setups that miss it are NaN (shape, std, covariance).
    Index min_setups = 0;
    /// Family-wise level of the reference-consistency test over every (setup, mode) pair
    /// tested (Bonferroni): a pair is rejected when its p-value is below
    /// reference_test_level / (number of pairs tested). Strict, so that a correct campaign
    /// stays silent: the first-order covariance is itself accurate to some 10-20 %, which the
    /// far tail of chi2 magnifies (on the simulated deck campaigns of 2-minute setups, 1e-3 gave a
    /// false alarm in 1 of 20 correct campaigns, largest chi2 22; a swapped pair of references
    /// gives chi2 > 300 in every mode; 1e-6 puts the threshold at chi2(2) = 34.5 for 30 pairs).
    double reference_test_level = 1e-6;

    void validate() const {
        detail::require(std::isfinite(frequency_tolerance) && frequency_tolerance > 0.0,
                        "frequency_tolerance must be finite and > 0, got ", frequency_tolerance);
        detail::require(min_reference_mac >= 0.0 && min_reference_mac <= 1.0,
                        "min_reference_mac must be in [0, 1], got ", min_reference_mac);
        detail::require(min_setups >= 0, "min_setups must be >= 0 (0: every setup), got ", min_setups);
        detail::require(reference_test_level > 0.0 && reference_test_level < 1.0,
                        "reference_test_level must be in (0, 1), got ", reference_test_level);
    }
};

/// The merged modes, sorted by frequency, over the l_g global DOFs: the r references once (as
/// measured in each mode's basis setup), then each setup's moving channels in setup and row
/// order (the layout of identify_setups).
struct PoserResult {
    Eigen::VectorXd frequency_hz;         ///< inverse-variance weighted mean, Hz
    Eigen::VectorXd damping_ratio;        ///< inverse-variance weighted mean, fraction
    Eigen::MatrixXcd mode_shape;          ///< l_g x n_modes, largest finite component 1
    Eigen::VectorXi reference_component;  ///< per mode, the component scaled to exactly 1
    // Uncertainty (empty without): first order, setups independent.
    Eigen::VectorXd frequency_std;        ///< Hz
    Eigen::VectorXd damping_std;          ///< fraction
    Eigen::MatrixXd mode_shape_std_real;  ///< l_g x n_modes
    Eigen::MatrixXd mode_shape_std_imag;  ///< l_g x n_modes
    Eigen::MatrixXd covariance;           ///< (2 + 2 l_g)^2 x n_modes, as Modes::covariance
    // Provenance.
    std::vector<Index> dof_setup;    ///< per global DOF, its setup (references: -1, the basis setup's per mode)
    std::vector<Index> dof_channel;  ///< per global DOF, its row in that setup (references: the reference index)
    Eigen::MatrixXi mode_index;      ///< n_setups x n_modes: the setup's mode merged, -1 if none
    Eigen::VectorXi basis_setup;     ///< per mode, the setup whose references are kept (the first that has it)
    Eigen::MatrixXcd scale;          ///< n_setups x n_modes: alpha_j (12.9) (basis: 1; none: NaN)
    // Reference consistency (NaN where not tested: the basis, a setup without the mode, r < 2,
    // no uncertainty).
    Index reference_dof = 0;         ///< degrees of freedom of reference_chi2, 2 r - 2
    Eigen::MatrixXd reference_chi2;  ///< n_setups x n_modes: e^T Sigma_e^-1 e (12.13)
    Eigen::MatrixXd reference_p_value;  ///< n_setups x n_modes: P(chi2_{2r-2} > reference_chi2)
    /// per setup, r x n_modes: |e_c| / sqrt(var Re e_c + var Im e_c), the residual of each
    /// reference channel in units of its own std (about 1 on a consistent setup)
    std::vector<Eigen::MatrixXd> reference_z;
    /// n_setups x n_modes: p-value below reference_test_level / n_tests (Bonferroni)
    Eigen::Array<bool, Eigen::Dynamic, Eigen::Dynamic> reference_rejected;
    Index n_reference_tests = 0;     ///< (setup, mode) pairs tested
    bool has_uncertainty = true;

    Index n_modes() const { return frequency_hz.size(); }
};

namespace detail {

/// MAC of two complex vectors (0 when either is zero).
inline double poser_mac(const Eigen::VectorXcd& a, const Eigen::VectorXcd& b) {
    const double na = a.squaredNorm(), nb = b.squaredNorm();
    return na > 0.0 && nb > 0.0 ? std::norm(a.dot(b)) / (na * nb) : 0.0;
}

/// P(X > x) for X ~ chi-square with an even number of degrees of freedom k = 2m:
/// exp(-x/2) sum_{i<m} (x/2)^i / i!.
inline double chi2_survival_even(double x, Index k) {
    if (!(x >= 0.0)) return std::numeric_limits<double>::quiet_NaN();
    const double h = 0.5 * x;
    double term = 1.0, sum = 1.0;
    for (Index i = 1; i < k / 2; ++i) {
        term *= h / static_cast<double>(i);
        sum += term;
    }
    return std::exp(-h) * sum;
}

/// The real directions of a setup's parameters theta_j = [f, xi, Re phi (l), Im phi (l)]:
/// direction a as (df, dxi, dphi).
struct PoserDirection {
    double df = 0.0, dxi = 0.0;
    Index c = -1;                    ///< perturbed shape row, -1 for f / xi
    std::complex<double> v{0.0, 0.0};  ///< its perturbation (1 or i)
};

inline PoserDirection poser_direction(Index a, Index l) {
    PoserDirection d;
    if (a == 0) d.df = 1.0;
    else if (a == 1) d.dxi = 1.0;
    else if (a < 2 + l) { d.c = a - 2; d.v = 1.0; }
    else { d.c = a - 2 - l; d.v = std::complex<double>(0.0, 1.0); }
    return d;
}

}  // namespace detail

/// The complex least-squares scale of `phi` onto `b` (12.9): alpha = phi^H b / phi^H phi.
inline std::complex<double> poser_scale(const Eigen::VectorXcd& phi, const Eigen::VectorXcd& b) {
    return phi.dot(b) / phi.squaredNorm();  // Eigen's dot conjugates its first argument
}

/// Merge each setup's modes by PoSER (docs/uq-math.md §13.5, §13.9).
///
/// Matching (one rule, deterministic): setups are taken in order; setup 0's modes are the first
/// targets; each later setup's modes are matched to the targets so far, greedily by increasing
/// distance d = |f - f_t| / f_t + (1 - MAC of the reference components), among the pairs with
/// |f - f_t| <= frequency_tolerance f_t and reference MAC >= min_reference_mac, at most one mode
/// per setup and target; a mode left unmatched becomes a new target. A target's frequency and
/// reference components are those of its first setup (its basis). A target found in fewer than
/// min_setups setups (default: all) is not reported.
///
/// Throws invalid_argument (naming the setup) for: no setups; references that differ in number
/// from setup 0's, are empty, out of range or repeated; arrays of inconsistent sizes; a
/// non-finite or non-positive frequency; covariance given for some setups and not others, or
/// of the wrong size.
inline PoserResult poser_merge(const std::vector<PoserSetupModes>& setups, const PoserOptions& options = {}) {
    using cd = std::complex<double>;
    options.validate();
    detail::require(!setups.empty(), "setups must hold at least one setup");
    const Index ns = static_cast<Index>(setups.size());
    const Index r = static_cast<Index>(setups[0].references.size());
    detail::require(r >= 1, "setup 0: references must name at least one reference channel");
    bool any_cov = false, all_cov = true;
    std::vector<std::vector<Index>> moving(ns);
    PoserResult out;
    for (Index j = 0; j < ns; ++j) {
        const PoserSetupModes& s = setups[j];
        const Index l = s.mode_shape.rows(), m = s.frequency_hz.size();
        detail::require(static_cast<Index>(s.references.size()) == r, "setup ", j, " has ", s.references.size(),
                        " references, setup 0 has ", r, ": every setup must measure the same reference channels");
        for (Index c = 0; c < r; ++c) {
            const Index ref = s.references[c];
            detail::require(ref >= 0 && ref < l, "setup ", j, ": reference ", c, " is row ", ref,
                            ", out of range for its ", l, " shape rows (the setup lacks this reference)");
            for (Index d = 0; d < c; ++d)
                detail::require(s.references[d] != ref, "setup ", j, ": row ", ref, " is given as references ", d,
                                " and ", c);
        }
        detail::require(s.damping_ratio.size() == m && s.mode_shape.cols() == m, "setup ", j,
                        ": frequency_hz, damping_ratio and mode_shape must have one entry per mode (", m, ")");
        for (Index i = 0; i < m; ++i)
            detail::require(std::isfinite(s.frequency_hz(i)) && s.frequency_hz(i) > 0.0 &&
                                std::isfinite(s.damping_ratio(i)) && s.mode_shape.col(i).allFinite(),
                            "setup ", j, ": mode ", i, " has a frequency, damping ratio or shape that is not finite "
                            "(or f <= 0)");
        if (m > 0) {
            const bool has = s.covariance.cols() > 0;
            any_cov = any_cov || has;
            all_cov = all_cov && has;
            if (has)
                detail::require(s.covariance.cols() == m && s.covariance.rows() == (2 + 2 * l) * (2 + 2 * l), "setup ", j,
                                ": covariance must be (2 + 2 l)^2 = ", (2 + 2 * l) * (2 + 2 * l), " x ", m,
                                " (one column per mode), got ", s.covariance.rows(), " x ", s.covariance.cols());
        }
        for (Index c = 0; c < l; ++c)
            if (std::find(s.references.begin(), s.references.end(), c) == s.references.end()) {
                moving[j].push_back(c);
                out.dof_setup.push_back(j);
                out.dof_channel.push_back(c);
            }
    }
    detail::require(!any_cov || all_cov, "covariance must be given for every setup's modes or for none");
    const bool with_unc = any_cov;
    out.has_uncertainty = with_unc;
    {
        std::vector<Index> ds(r, -1), dc(r);
        for (Index c = 0; c < r; ++c) dc[c] = c;
        ds.insert(ds.end(), out.dof_setup.begin(), out.dof_setup.end());
        dc.insert(dc.end(), out.dof_channel.begin(), out.dof_channel.end());
        out.dof_setup = std::move(ds);
        out.dof_channel = std::move(dc);
    }
    const Index l_g = static_cast<Index>(out.dof_setup.size());
    std::vector<Index> off(ns + 1, r);  // global row of each setup's first moving DOF
    for (Index j = 0; j < ns; ++j) off[j + 1] = off[j] + static_cast<Index>(moving[j].size());
    auto ref_part = [&](Index j, Index i) {
        Eigen::VectorXcd v(r);
        for (Index c = 0; c < r; ++c) v(c) = setups[j].mode_shape(setups[j].references[c], i);
        return v;
    };

    // Matching.
    struct Target {
        Index basis, mode;
        std::vector<Index> of;  // per setup, its mode or -1
    };
    std::vector<Target> targets;
    for (Index i = 0; i < setups[0].frequency_hz.size(); ++i) {
        Target t{0, i, std::vector<Index>(ns, -1)};
        t.of[0] = i;
        targets.push_back(t);
    }
    for (Index j = 1; j < ns; ++j) {
        struct Pair {
            double d;
            std::size_t t;
            Index i;
        };
        std::vector<Pair> pairs;
        const PoserSetupModes& s = setups[j];
        for (std::size_t t = 0; t < targets.size(); ++t) {
            const double ft = setups[targets[t].basis].frequency_hz(targets[t].mode);
            const Eigen::VectorXcd bt = ref_part(targets[t].basis, targets[t].mode);
            for (Index i = 0; i < s.frequency_hz.size(); ++i) {
                const double df = std::abs(s.frequency_hz(i) - ft) / ft;
                const double mac = detail::poser_mac(ref_part(j, i), bt);
                if (df <= options.frequency_tolerance && mac >= options.min_reference_mac)
                    pairs.push_back({df + (1.0 - mac), t, i});
            }
        }
        std::stable_sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) { return a.d < b.d; });
        std::vector<bool> used(static_cast<std::size_t>(s.frequency_hz.size()), false);
        for (const Pair& p : pairs)
            if (targets[p.t].of[j] < 0 && !used[p.i]) {
                targets[p.t].of[j] = p.i;
                used[p.i] = true;
            }
        for (Index i = 0; i < s.frequency_hz.size(); ++i)
            if (!used[i]) {
                Target t{j, i, std::vector<Index>(ns, -1)};
                t.of[j] = i;
                targets.push_back(t);
            }
    }
    const Index need = options.min_setups == 0 ? ns : std::min(options.min_setups, ns);
    std::vector<Target> kept;
    for (Target& t : targets)
        if (std::count_if(t.of.begin(), t.of.end(), [](Index i) { return i >= 0; }) >= need) kept.push_back(t);

    // Combine each kept target.
    const Index nm = static_cast<Index>(kept.size()), np = 2 + 2 * l_g;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    out.frequency_hz.resize(nm);
    out.damping_ratio.resize(nm);
    out.mode_shape.resize(l_g, nm);
    out.reference_component.resize(nm);
    out.mode_index.setConstant(ns, nm, -1);
    out.basis_setup.resize(nm);
    out.scale.setConstant(ns, nm, cd(nan, nan));
    out.reference_dof = 2 * r - 2;
    out.reference_chi2.setConstant(ns, nm, nan);
    out.reference_p_value.setConstant(ns, nm, nan);
    out.reference_z.assign(ns, Eigen::MatrixXd::Constant(r, nm, nan));
    out.reference_rejected.setConstant(ns, nm, false);
    if (with_unc) {
        out.frequency_std.resize(nm);
        out.damping_std.resize(nm);
        out.mode_shape_std_real.resize(l_g, nm);
        out.mode_shape_std_imag.resize(l_g, nm);
        out.covariance.resize(np * np, nm);
    }
    for (Index t = 0; t < nm; ++t) {
        const Target& T = kept[t];
        const Index b0 = T.basis;
        for (Index j = 0; j < ns; ++j) out.mode_index(j, t) = T.of[j];
        out.basis_setup(t) = static_cast<int>(b0);
        auto cov_of = [&](Index j) {
            const Index l = setups[j].mode_shape.rows();
            return Eigen::Map<const Eigen::MatrixXd>(setups[j].covariance.col(T.of[j]).data(), 2 + 2 * l, 2 + 2 * l);
        };
        // f and xi (12.8): weights 1/sigma^2, equal weights without uncertainty (or a zero sigma).
        std::vector<double> wf(ns, 0.0), wx(ns, 0.0);
        bool equal_f = !with_unc, equal_x = !with_unc;
        for (Index j = 0; j < ns; ++j) {
            if (T.of[j] < 0 || !with_unc) continue;
            const auto C = cov_of(j);
            if (!(C(0, 0) > 0.0 && std::isfinite(C(0, 0)))) equal_f = true;
            if (!(C(1, 1) > 0.0 && std::isfinite(C(1, 1)))) equal_x = true;
            wf[j] = 1.0 / C(0, 0);
            wx[j] = 1.0 / C(1, 1);
        }
        double sf = 0.0, sx = 0.0, f = 0.0, x = 0.0;
        for (Index j = 0; j < ns; ++j) {
            if (T.of[j] < 0) continue;
            if (equal_f) wf[j] = 1.0;
            if (equal_x) wx[j] = 1.0;
            sf += wf[j];
            sx += wx[j];
        }
        for (Index j = 0; j < ns; ++j) {
            if (T.of[j] < 0) continue;
            wf[j] /= sf;
            wx[j] /= sx;
            f += wf[j] * setups[j].frequency_hz(T.of[j]);
            x += wx[j] * setups[j].damping_ratio(T.of[j]);
        }
        out.frequency_hz(t) = f;
        out.damping_ratio(t) = x;
        // Shapes (12.9): b = the basis setup's reference components, alpha_j = phi_j^H b / |phi_j|^2.
        const Eigen::VectorXcd b = ref_part(b0, T.of[b0]);
        std::vector<Eigen::VectorXcd> phi(ns);
        std::vector<double> nrm(ns, 0.0);
        std::vector<cd> alpha(ns, cd(nan, nan));
        Eigen::VectorXcd psi = Eigen::VectorXcd::Constant(l_g, cd(nan, nan));
        psi.head(r) = b;
        for (Index j = 0; j < ns; ++j) {
            if (T.of[j] < 0) continue;
            phi[j] = ref_part(j, T.of[j]);
            nrm[j] = phi[j].squaredNorm();
            detail::require(nrm[j] > 0.0, "setup ", j, ": mode ", T.of[j],
                            " has zero reference components (a reference on a node of the mode): it cannot be scaled");
            alpha[j] = j == b0 ? cd(1.0, 0.0) : poser_scale(phi[j], b);
            out.scale(j, t) = alpha[j];
            for (std::size_t c = 0; c < moving[j].size(); ++c)
                psi(off[j] + static_cast<Index>(c)) = alpha[j] * setups[j].mode_shape(moving[j][c], T.of[j]);
        }
        Index k = 0;
        double big = -1.0;
        for (Index g = 0; g < l_g; ++g)
            if (std::isfinite(std::abs(psi(g))) && std::abs(psi(g)) > big) {
                big = std::abs(psi(g));
                k = g;
            }
        const cd pk = psi(k);
        out.mode_shape.col(t) = psi / pk;
        out.reference_component(t) = static_cast<int>(k);
        if (!with_unc) continue;

        // Covariance (12.10)-(12.12): Sigma = sum_j J_j Sigma_j J_j^T over the setups that have the mode.
        Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(np, np);
        const Eigen::VectorXcd psit = psi / pk;
        for (Index j = 0; j < ns; ++j) {
            if (T.of[j] < 0) continue;
            const Index l = setups[j].mode_shape.rows(), nj = 2 + 2 * l;
            Eigen::MatrixXd J = Eigen::MatrixXd::Zero(np, nj);
            for (Index a = 0; a < nj; ++a) {
                const detail::PoserDirection d = detail::poser_direction(a, l);
                J(0, a) = wf[j] * d.df;
                J(1, a) = wx[j] * d.dxi;
                if (d.c < 0) continue;
                Eigen::VectorXcd dpsi = Eigen::VectorXcd::Zero(l_g);
                std::vector<cd> dalpha(ns, cd(0.0, 0.0));
                const auto rit = std::find(setups[j].references.begin(), setups[j].references.end(), d.c);
                if (rit != setups[j].references.end()) {
                    const Index rc = static_cast<Index>(rit - setups[j].references.begin());
                    if (j == b0) {  // db: the references' rows, and every other setup's alpha
                        dpsi(rc) = d.v;
                        for (Index i = 0; i < ns; ++i)
                            if (T.of[i] >= 0 && i != b0) dalpha[i] += std::conj(phi[i](rc)) * d.v / nrm[i];
                    } else {  // dphi_j: alpha_j only (non-holomorphic: the conjugate enters)
                        dalpha[j] += (std::conj(d.v) * b(rc) -
                                      alpha[j] * (std::conj(d.v) * phi[j](rc) + std::conj(phi[j](rc)) * d.v)) /
                                     nrm[j];
                    }
                } else {  // a moving row of setup j
                    const Index c = static_cast<Index>(std::find(moving[j].begin(), moving[j].end(), d.c) - moving[j].begin());
                    dpsi(off[j] + c) += alpha[j] * d.v;
                }
                for (Index i = 0; i < ns; ++i)
                    if (dalpha[i] != cd(0.0, 0.0))
                        for (std::size_t c = 0; c < moving[i].size(); ++c)
                            dpsi(off[i] + static_cast<Index>(c)) += dalpha[i] * setups[i].mode_shape(moving[i][c], T.of[i]);
                // (7.6): normalised at component k
                Eigen::VectorXcd dt = (dpsi - psit * dpsi(k)) / pk;
                dt(k) = 0.0;
                for (Index g = 0; g < l_g; ++g)
                    if (!std::isfinite(std::abs(psi(g)))) dt(g) = 0.0;
                J.block(2, a, l_g, 1) = dt.real();
                J.block(2 + l_g, a, l_g, 1) = dt.imag();
            }
            cov.noalias() += J * cov_of(j) * J.transpose();
        }
        for (Index g = 0; g < l_g; ++g)
            if (!std::isfinite(std::abs(psi(g)))) {
                for (Index h : {2 + g, 2 + l_g + g}) {
                    cov.row(h).setConstant(nan);
                    cov.col(h).setConstant(nan);
                }
            }
        out.covariance.col(t) = Eigen::Map<const Eigen::VectorXd>(cov.data(), np * np);
        const Eigen::VectorXd sd = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
        out.frequency_std(t) = sd(0);
        out.damping_std(t) = sd(1);
        out.mode_shape_std_real.col(t) = sd.segment(2, l_g);
        out.mode_shape_std_imag.col(t) = sd.segment(2 + l_g, l_g);

        // Reference consistency (12.13): e_j = b - alpha_j phi_j, with its covariance from the
        // basis setup's and setup j's, tested on the 2r - 2 real directions orthogonal to phi_j.
        if (r < 2) continue;
        for (Index j = 0; j < ns; ++j) {
            if (T.of[j] < 0 || j == b0) continue;
            const Eigen::VectorXcd e = b - alpha[j] * phi[j];
            Eigen::MatrixXd se = Eigen::MatrixXd::Zero(2 * r, 2 * r);
            for (Index src : {b0, j}) {
                const Index l = setups[src].mode_shape.rows(), nj = 2 + 2 * l;
                Eigen::MatrixXd Je = Eigen::MatrixXd::Zero(2 * r, nj);
                for (Index a = 2; a < nj; ++a) {
                    const detail::PoserDirection d = detail::poser_direction(a, l);
                    const auto rit = std::find(setups[src].references.begin(), setups[src].references.end(), d.c);
                    if (rit == setups[src].references.end()) continue;
                    const Index rc = static_cast<Index>(rit - setups[src].references.begin());
                    Eigen::VectorXcd de = Eigen::VectorXcd::Zero(r);
                    cd dal;
                    if (src == b0) {
                        de(rc) = d.v;
                        dal = std::conj(phi[j](rc)) * d.v / nrm[j];
                    } else {
                        dal = (std::conj(d.v) * b(rc) -
                               alpha[j] * (std::conj(d.v) * phi[j](rc) + std::conj(phi[j](rc)) * d.v)) /
                              nrm[j];
                        de(rc) -= alpha[j] * d.v;
                    }
                    de -= dal * phi[j];
                    Je.block(0, a, r, 1) = de.real();
                    Je.block(r, a, r, 1) = de.imag();
                }
                se.noalias() += Je * cov_of(src) * Je.transpose();
            }
            for (Index c = 0; c < r; ++c) {
                const double v = se(c, c) + se(r + c, r + c);
                out.reference_z[j](c, t) = v > 0.0 ? std::abs(e(c)) / std::sqrt(v) : nan;
            }
            // Orthonormal basis of phi_j's complement (columns 1..r-1 of a Householder Q), as a
            // real map M: [Re e; Im e] -> [Re Q^H e; Im Q^H e].
            const Eigen::HouseholderQR<Eigen::MatrixXcd> qr(phi[j]);
            const Eigen::MatrixXcd Q = qr.householderQ() * Eigen::MatrixXcd::Identity(r, r);
            const Eigen::MatrixXcd Qh = Q.rightCols(r - 1).adjoint();
            Eigen::MatrixXd M(2 * (r - 1), 2 * r);
            M << Qh.real(), -Qh.imag(), Qh.imag(), Qh.real();
            Eigen::VectorXd er(2 * r);
            er << e.real(), e.imag();
            const Eigen::VectorXd ep = M * er;
            const Eigen::MatrixXd sp = M * se * M.transpose();
            const Eigen::LDLT<Eigen::MatrixXd> ldlt(sp);
            if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) continue;
            const double chi2 = ep.dot(ldlt.solve(ep));
            out.reference_chi2(j, t) = chi2;
            out.reference_p_value(j, t) = detail::chi2_survival_even(chi2, 2 * r - 2);
            ++out.n_reference_tests;
        }
    }
    if (out.n_reference_tests > 0) {
        const double level = options.reference_test_level / static_cast<double>(out.n_reference_tests);
        out.reference_rejected = out.reference_p_value.array() < level;  // NaN compares false
    }

    // Sorted by frequency.
    std::vector<Index> by_f(nm);
    for (Index t = 0; t < nm; ++t) by_f[t] = t;
    std::stable_sort(by_f.begin(), by_f.end(), [&](Index a, Index b) { return out.frequency_hz(a) < out.frequency_hz(b); });
    PoserResult s = out;
    for (Index t = 0; t < nm; ++t) {
        const Index o = by_f[t];
        s.frequency_hz(t) = out.frequency_hz(o);
        s.damping_ratio(t) = out.damping_ratio(o);
        s.mode_shape.col(t) = out.mode_shape.col(o);
        s.reference_component(t) = out.reference_component(o);
        s.mode_index.col(t) = out.mode_index.col(o);
        s.basis_setup(t) = out.basis_setup(o);
        s.scale.col(t) = out.scale.col(o);
        s.reference_chi2.col(t) = out.reference_chi2.col(o);
        s.reference_p_value.col(t) = out.reference_p_value.col(o);
        s.reference_rejected.col(t) = out.reference_rejected.col(o);
        for (Index j = 0; j < ns; ++j) s.reference_z[j].col(t) = out.reference_z[j].col(o);
        if (with_unc) {
            s.frequency_std(t) = out.frequency_std(o);
            s.damping_std(t) = out.damping_std(o);
            s.mode_shape_std_real.col(t) = out.mode_shape_std_real.col(o);
            s.mode_shape_std_imag.col(t) = out.mode_shape_std_imag.col(o);
            s.covariance.col(t) = out.covariance.col(o);
        }
    }
    return s;
}

}  // namespace modaluq
