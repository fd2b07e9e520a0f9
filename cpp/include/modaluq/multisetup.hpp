#pragma once
/// @file multisetup.hpp
/// Campaigns in several setups (issue 23): the modular merge of Doehler & Mevel (IEEE TAC 2012)
/// with the first-order covariance of Doehler, Lam & Mevel (MSSP 2013), output-only and
/// input/output, at every order of a stabilization diagram (docs/uq-math.md §13).
///
/// Each setup brings its own covariances (its channels, its inputs, its record length and
/// blocks); a few reference channels are common to all setups and are each setup's past
/// channels. Per setup: H, T_H, one SVD at n_max and the per-block dGamma (5.3)-(5.7), exactly as
/// for one record. Per order n: every setup's Gamma is brought into setup 0's state basis
/// through the reference rows (12.3), the global Gamma_g stacks the references once and every
/// setup's other ("moving") rows (12.4), and (A, C) and the modes follow as for one record
/// with l_g global outputs. The setups are independent records, so the covariance factor of a
/// global mode is the concatenation of each setup's block columns (12.7): memory and time are
/// linear in the number of setups.
///
/// The noise floor of §5.5 applies setup by setup (§13.4): each setup's k*_j from its own T_H, and
/// its singular directions from k*_j on held fixed (frozen). That is the exact derivative of the
/// merge of the setups' frozen maps, so at every order where some setup has a frozen column the
/// merge is propagated twice, frozen and unfrozen, and each pole keeps the frozen sigma unless
/// its noise coupling rho (5.14) exceeds IdentifyOptions::noise_coupling_limit, exactly as for
/// one record (IdentifyOptions::freeze_noise = false propagates every direction). Without the
/// freeze, sigma above the true order is the unfrozen one: 2-5x the Monte Carlo scatter of the
/// poles an engineer selects there (docs/multisetup.md). Modes::singular_value_gap is NaN (no
/// single H).

#include <Eigen/Core>
#include <Eigen/Cholesky>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "covariance.hpp"
#include "detail/eigen_perturbation.hpp"
#include "detail/gemm.hpp"
#include "detail/noise_floor.hpp"
#include "detail/parallel.hpp"
#include "detail/svd_perturbation.hpp"
#include "identify.hpp"
#include "modal.hpp"
#include "realization.hpp"
#include "subspace.hpp"
#include "uncertainty.hpp"

namespace modaluq {

/// One setup of a campaign.
struct SetupData {
    /// R1..R4 of this setup and, with uncertainty, its blocks (>= 2), e.g. from
    /// compute_covariances or a CovarianceAccumulator. Its layout's references (past channels)
    /// must be `references`; its p and q those of the campaign.
    Covariances covariances;
    /// Output indices (in this setup) of the r common reference channels, in the same global
    /// order in every setup. Every other output of the setup is a moving channel.
    std::vector<Index> references;
    /// This setup's sampling frequency in Hz; 0 = the campaign's (IdentifyOptions::fs). Any
    /// other value must equal it.
    double fs = 0.0;
};

/// A merged identification: the modes at every order over the l_g global DOFs (the references
/// once, as measured in setup 0, then each setup's moving channels in setup and column order),
/// with their covariance exactly as for one record, so poles_of, stabilization_diagram and
/// select_modes take it unchanged. Fields of Identification that belong to one H are those of
/// the basis setup 0 (singular_values, channel_mean) or the most cautious over the setups
/// (numerical_rank, signal_to_noise: the smallest); n_samples, n_columns and n_blocks are sums.
struct SetupsIdentification : Identification {
    std::vector<Index> dof_setup;    ///< per global DOF, the setup it is measured in (references: 0)
    std::vector<Index> dof_channel;  ///< per global DOF, its output index in that setup
    std::vector<Eigen::VectorXd> setup_singular_values;  ///< per setup, the singular values of its H
    std::vector<Index> setup_n_blocks;                   ///< per setup, its blocks (factor columns)
    std::vector<double> setup_signal_to_noise;           ///< per setup, s_1 / std(s_1) (NaN without uncertainty)
    /// per setup, its noise floor k*_j (§5.5; its directions from k*_j on are frozen); n_max + 1
    /// when nothing is frozen (no uncertainty, freeze_noise off, or no noise below n_max + 1).
    /// Identification::significant_singular_values is the smallest.
    std::vector<Index> setup_significant_singular_values;
};

namespace detail {

/// One setup after its SVD: Gamma at n_max split into reference rows X and moving rows M (rows
/// ordered block row by block row, i w + c), and the same rows of dGamma for every block
/// (columns k n_max .. k n_max + n_max - 1 are block k's).
struct SetupGamma {
    Index l = 0, r = 0, w = 0, nb = 0, n_max = 0;
    Index k_star = std::numeric_limits<Index>::max();  ///< noise floor: columns j >= k_star are frozen
    std::vector<Index> moving;
    Eigen::MatrixXd x, m;    ///< p r x n_max, p w x n_max
    Eigen::MatrixXd dx, dm;  ///< p r x (n_max nb), p w x (n_max nb)
    /// The frozen dGamma's first k_star columns without its scale term (columns k_star k ..
    /// k_star k + k_star - 1 are block k's; empty if nothing is frozen): its other columns only
    /// scale, and scaling Gamma's columns changes the state basis, which moves no mode (§13.4).
    Eigen::MatrixXd dxf, dmf;  ///< p r x (k_star nb), p w x (k_star nb)
    /// Per block k (columns k n_max ..), for the unfrozen pass of a setup j >= 1 (§13.3): the
    /// order-n terms are these matrices' leading n x n blocks (column i of dGamma does not depend
    /// on the order), so the p w-row products are formed once, not at every order.
    /// sa = M_up^T dM_dw + dM_up^T M_dw, sb = M_up^T dM_up + dM_up^T M_up, cx = X^T dX,
    /// dxb = dX^T X_0 (X_0: setup 0's reference rows); up/dw = all but the last/first block row.
    Eigen::MatrixXd sa, sb, cx, dxb;  ///< n_max x (n_max nb) each
    Eigen::MatrixXd guu, gud;         ///< M_up^T M_up, M_up^T M_dw (n_max x n_max)
    bool freezes() const { return k_star < n_max; }
    /// Whether order n is propagated with this setup's noise columns frozen in the frozen pass.
    bool frozen_at(Index n, bool frozen) const { return frozen && freezes() && n > k_star; }
    /// dGamma's reference and moving rows of block k at order n: all n columns, or, frozen, the
    /// k_star columns that are not 0 (the others are dropped, see dxf).
    auto dX(Index k, Index n, bool frozen) const {
        return frozen_at(n, frozen) ? dxf.middleCols(k * k_star, k_star) : dx.middleCols(k * n_max, n);
    }
    auto dM(Index k, Index n, bool frozen) const {
        return frozen_at(n, frozen) ? dmf.middleCols(k * k_star, k_star) : dm.middleCols(k * n_max, n);
    }
};

/// Row i w + c of the result is row i l + rows[c] of g (block rows of l rows).
inline Eigen::MatrixXd block_rows_of(const Eigen::Ref<const Eigen::MatrixXd>& g, Index l,
                                     const std::vector<Index>& rows) {
    const Index p = g.rows() / l, w = static_cast<Index>(rows.size());
    Eigen::MatrixXd out(p * w, g.cols());
    for (Index i = 0; i < p; ++i)
        for (Index c = 0; c < w; ++c) out.row(i * w + c) = g.row(i * l + rows[c]);
    return out;
}

/// dGamma = D S^{1/2} + U_n diag(d s_j / (2 sqrt s_j)), D = U Omega + dH V_n S^-1 (5.3)-(5.7),
/// every direction free (unfrozen); d s_1 in `ds1`. With `frozen`, also the same with D's
/// columns j >= frozen_from set to 0 (5.13): a frozen column only scales, d gamma_j = u_j d s_j / (2 sqrt s_j).
/// With `frozen_free`, the first frozen_from columns of that frozen dGamma without the scale term
/// U_n diag(...) = Gamma_n diag(...): a change of the state basis, which moves no mode.
inline Eigen::MatrixXd gamma_perturbation_setup(const Realization& re, const Eigen::Ref<const Eigen::MatrixXd>& dh,
                                                Index n, double& ds1, Index frozen_from = 0,
                                                Eigen::MatrixXd* frozen = nullptr,
                                                Eigen::MatrixXd* frozen_free = nullptr) {
    const Eigen::VectorXd& s = re.singular_values();
    const SvdPerturbation sp = svd_perturbation(re.U(), re.V(), s, dh, n, n);
    ds1 = sp.Ua(0, 0);
    const Eigen::VectorXd sq = s.head(n).cwiseSqrt();
    Eigen::MatrixXd d(re.U().rows(), n);
    gemm(d, re.U(), Op::N, sp.omega, Op::N);
    d += sp.P.leftCols(n) * s.head(n).cwiseInverse().asDiagonal();
    d *= sq.asDiagonal();
    const Index k = std::clamp<Index>(frozen_from, 0, n);
    if (frozen_free) *frozen_free = d.leftCols(k);
    const Eigen::VectorXd e = sp.Ua.diagonal().head(n).cwiseQuotient(2.0 * sq);
    const Eigen::MatrixXd scale = re.U().leftCols(n) * e.asDiagonal();
    if (frozen) {
        *frozen = scale;
        frozen->leftCols(k) += d.leftCols(k);
    }
    return d + scale;
}

/// Group sums of the Q matrices of §13.3 for one group (rows p w, up = all but the last block
/// row, dw = all but the first): Q1 += G_up^T dG_up, Q2 += G_dw^T dG_up, Q3 += G_up^T dG_dw.
inline void add_group_q(const Eigen::Ref<const Eigen::MatrixXd>& g, const Eigen::Ref<const Eigen::MatrixXd>& dg,
                        Index w, Eigen::Ref<Eigen::MatrixXd> q1, Eigen::Ref<Eigen::MatrixXd> q2,
                        Eigen::Ref<Eigen::MatrixXd> q3) {
    const Index rows = g.rows() - w;
    if (rows <= 0) return;
    gemm(q1, g.topRows(rows), Op::T, dg.topRows(rows), Op::N, 1.0, 1.0);
    gemm(q2, g.bottomRows(rows), Op::T, dg.topRows(rows), Op::N, 1.0, 1.0);
    gemm(q3, g.topRows(rows), Op::T, dg.bottomRows(rows), Op::N, 1.0, 1.0);
}

/// Seed of the noise-coupling test's sketch (IdentifyOptions::coupling_sketch): setup j draws its
/// signs from kCouplingSketchSeed + j, so the sketch depends on the data's layout only.
inline constexpr std::uint64_t kCouplingSketchSeed = 0x736b65746368ull;  ///< "sketch"

/// Blocks combined by the columns of s (n_b x c): m holds n_b equal blocks side by side
/// (rows x (w n_b), block k in columns k w ..), the result c blocks, block t = sum_k s(k, t) block k.
inline Eigen::MatrixXd combine_blocks(const Eigen::MatrixXd& m, const Eigen::MatrixXd& s) {
    const Index nb = s.rows();
    Eigen::MatrixXd out(m.rows(), nb > 0 ? m.cols() / nb * s.cols() : 0);
    if (m.size() == 0 || out.size() == 0) return out;
    const Index per = m.size() / nb;  // a block, read as one column (column-major)
    Eigen::Map<Eigen::MatrixXd> o(out.data(), per, s.cols());
    gemm(o, Eigen::Map<const Eigen::MatrixXd>(m.data(), per, nb), Op::N, s, Op::N);
    return out;
}

/// The setup as the unfrozen pass of the noise-coupling test sees it through the sketch s
/// (n_b x c): its c blocks are the combinations of its blocks by the columns of s. Every per-block
/// term of that pass is linear in the block's dGamma, so this is the pass on the combined blocks.
inline SetupGamma sketched_setup(const SetupGamma& g, const Eigen::MatrixXd& s) {
    SetupGamma out;
    out.l = g.l;
    out.r = g.r;
    out.w = g.w;
    out.nb = s.cols();
    out.n_max = g.n_max;
    out.moving = g.moving;
    out.x = g.x;
    out.m = g.m;
    out.guu = g.guu;
    out.gud = g.gud;
    out.dx = combine_blocks(g.dx, s);
    out.dm = combine_blocks(g.dm, s);
    out.sa = combine_blocks(g.sa, s);
    out.sb = combine_blocks(g.sb, s);
    out.cx = combine_blocks(g.cx, s);
    out.dxb = combine_blocks(g.dxb, s);
    return out;  // k_star stays "nothing frozen": this pass is the unfrozen one
}

}  // namespace detail

/// Identify a campaign of setups by the modular merge (docs/uq-math.md §13.2-13.3).
///
/// Uses from `options`: fs, block_rows, past_block_rows (each setup's covariances must have
/// them), orders, uncertainty, input_rcond, threads, freeze_noise, noise_floor_factor and
/// noise_coupling_limit (per setup, see the file comment). The references, blocks and demeaning
/// are each setup's (in its covariances).
///
/// Throws invalid_argument for: no setups; a setup whose number of references differs from
/// setup 0's, whose references are out of range, repeated, or not its covariances' past
/// channels; a sampling frequency or horizons that differ from the campaign's; an order above
/// min(p r, q r, (p - 1) l_g, min(p l_j, q r)) (the reference rows must determine the state
/// basis: p r >= n); uncertainty with fewer than two blocks in a setup.
inline SetupsIdentification identify_setups(const std::vector<SetupData>& setups, IdentifyOptions options) {
    using detail::gemm;
    using detail::Op;
    using detail::cd;
    options.validate();
    detail::require(!setups.empty(), "setups must hold at least one setup");
    detail::require(!options.block_correlation_correction,
                    "block_correlation_correction applies to one record (identify), not to a campaign's merge");
    detail::require(options.bootstrap_draws == 0,
                    "bootstrap_draws applies to one record (identify), not yet to a campaign's merge");
    std::sort(options.orders.begin(), options.orders.end());
    options.orders.erase(std::unique(options.orders.begin(), options.orders.end()), options.orders.end());
    const Index ns = static_cast<Index>(setups.size());
    const Index p = options.block_rows, q = options.past_block_rows > 0 ? options.past_block_rows : p;
    const Index r = static_cast<Index>(setups[0].references.size());
    detail::require(r >= 1, "setup 0: references must name at least one reference channel");
    const bool unc = options.uncertainty;

    // Layout (12.1) and checks.
    SetupsIdentification out;
    Index l_g = r;
    for (Index j = 0; j < ns; ++j) {
        const SetupData& s = setups[j];
        const HankelLayout& L = s.covariances.layout;
        detail::require(s.fs == 0.0 || s.fs == options.fs, "setup ", j, ": fs = ", s.fs,
                        " Hz differs from the campaign's fs = ", options.fs, " Hz (all setups must share one rate)");
        detail::require(static_cast<Index>(s.references.size()) == r, "setup ", j, " has ", s.references.size(),
                        " references, setup 0 has ", r, ": every setup must measure the same reference channels");
        for (Index c = 0; c < r; ++c) {
            const Index ref = s.references[c];
            detail::require(ref >= 0 && ref < L.n_outputs, "setup ", j, ": reference ", c, " is output ", ref,
                            ", out of range for its ", L.n_outputs, " outputs (the setup lacks this reference)");
            for (Index d = 0; d < c; ++d)
                detail::require(s.references[d] != ref, "setup ", j, ": output ", ref, " is given as references ",
                                d, " and ", c);
        }
        detail::require(L.n_references() == r, "setup ", j, ": its covariances have ", L.n_references(),
                        " past channels (layout.references) but ", r, " references were given; the references must "
                        "be the past channels");
        for (Index c = 0; c < r; ++c)
            detail::require(L.reference(c) == s.references[c], "setup ", j, ": past channel ", c, " of its covariances is output ",
                            L.reference(c), " but reference ", c, " is output ", s.references[c],
                            "; the references must be the past channels, in the same order");
        detail::require(L.p() == p && L.q() == q, "setup ", j, ": its covariances have block_rows = ", L.p(),
                        ", past_block_rows = ", L.q(), " but the campaign has ", p, ", ", q);
        if (unc)
            detail::require(s.covariances.blocks.cols() >= 2, "setup ", j, ": n_blocks must be >= 2 for the uncertainty, ",
                            "its covariances have ", s.covariances.blocks.cols(), " complete blocks");
        l_g += L.n_outputs - r;
    }
    const Index n_max = options.orders.back();
    Index limit = std::min({p * r, q * r, (p - 1) * l_g});
    for (const SetupData& s : setups) limit = std::min(limit, s.covariances.layout.max_order());
    detail::require(n_max <= limit, "order ", n_max, " is above what the merge supports: min(block_rows * n_references, "
                    "past_block_rows * n_references, (block_rows - 1) * n_global_dofs, each setup's max order) = ",
                    limit, " (the reference rows must determine the state: use more block_rows or references)");

    // Per setup: H, T_H, SVD at n_max, Gamma and dGamma split into reference and moving rows.
    std::vector<detail::SetupGamma> sg(ns);
    Index n_real = n_max;  // the largest order every setup realises (numerical rank)
    Index min_block = std::numeric_limits<Index>::max();
    out.numerical_rank = std::numeric_limits<Index>::max();
    out.signal_to_noise = std::numeric_limits<double>::infinity();
    for (Index j = 0; j < ns; ++j) {
        const SetupData& s = setups[j];
        const Covariances& cov = s.covariances;
        const HankelLayout& L = cov.layout;
        detail::SetupGamma& g = sg[j];
        g.l = L.n_outputs;
        g.r = r;
        for (Index c = 0; c < g.l; ++c)
            if (std::find(s.references.begin(), s.references.end(), c) == s.references.end()) g.moving.push_back(c);
        g.w = static_cast<Index>(g.moving.size());
        for (Index c : g.moving) {
            out.dof_setup.push_back(j);
            out.dof_channel.push_back(c);
        }
        const SubspaceMatrix sub = subspace_matrix(cov, options.input_rcond);
        detail::require(cov.R1.allFinite() && sub.H.allFinite(), "setup ", j,
                        ": the covariances are not finite (rescale the data)");
        detail::require(sub.H.norm() > detail::kNumericallyZero * cov.R1.norm(), "setup ", j,
                        ": the subspace matrix H is numerically zero (no dynamics left to identify)");
        const Realization re(sub.H, g.l, n_max);
        out.setup_singular_values.push_back(re.singular_values());
        out.numerical_rank = std::min(out.numerical_rank, re.numerical_rank());
        n_real = std::min(n_real, re.max_order());
        g.n_max = re.max_order();
        if (j == 0) {
            out.singular_values = re.singular_values();
            out.channel_mean = cov.channel_mean;
            if (cov.has_inputs()) {
                out.input_rank = sub.input_rank;
                out.input_condition = sub.input_condition;
            }
        }
        if (cov.has_inputs() && sub.input_rank_deficient) out.input_rank_deficient = true;
        out.n_samples += cov.n_samples;
        out.n_columns += cov.n_columns;
        const Eigen::MatrixXd& gam = re.observability();
        g.x = detail::block_rows_of(gam, g.l, s.references);
        g.m = detail::block_rows_of(gam, g.l, g.moving);
        double snr = std::numeric_limits<double>::quiet_NaN();
        if (unc && g.n_max > 0) {
            const Eigen::MatrixXd t_h = propagate_to_subspace(sub, cov, cov.covariance_factor());
            const Index a = L.rows_future(), b = L.rows_past(), nm = g.n_max;
            g.nb = t_h.cols();
            if (options.freeze_noise)  // this setup's own noise floor (§5.5, §13.4)
                g.k_star = detail::noise_floor(re, t_h, b, options.noise_floor_factor, nm + 1, options.threads).k;
            g.dx.resize(p * r, nm * g.nb);
            g.dm.resize(p * g.w, nm * g.nb);
            const Index kf = g.freezes() ? g.k_star : 0;
            g.dxf.resize(p * r, kf * g.nb);
            g.dmf.resize(p * g.w, kf * g.nb);
            Eigen::VectorXd ds1(g.nb);
            detail::parallel_for(g.nb, options.threads, [&](Index k) {
                Eigen::Map<const Eigen::MatrixXd> dh(t_h.col(k).data(), a, b);
                Eigen::MatrixXd dgf;
                const Eigen::MatrixXd dg = detail::gamma_perturbation_setup(re, dh, nm, ds1(k), kf, nullptr,
                                                                            kf > 0 ? &dgf : nullptr);
                g.dx.middleCols(k * nm, nm) = detail::block_rows_of(dg, g.l, s.references);
                g.dm.middleCols(k * nm, nm) = detail::block_rows_of(dg, g.l, g.moving);
                if (kf > 0) {
                    g.dxf.middleCols(k * kf, kf) = detail::block_rows_of(dgf, g.l, s.references);
                    g.dmf.middleCols(k * kf, kf) = detail::block_rows_of(dgf, g.l, g.moving);
                }
            });
            if (j > 0 && g.w > 0) {  // the unfrozen pass's per-block products (SetupGamma::sa ...)
                const Index rw = (p - 1) * g.w, n0 = sg[0].n_max;
                const auto m_up = g.m.topRows(rw), m_dw = g.m.bottomRows(rw);
                g.guu.resize(nm, nm);
                g.gud.resize(nm, nm);
                gemm(g.guu, m_up, Op::T, m_up, Op::N);
                gemm(g.gud, m_up, Op::T, m_dw, Op::N);
                g.sa.resize(nm, nm * g.nb);
                g.sb.resize(nm, nm * g.nb);
                g.cx.resize(nm, nm * g.nb);
                g.dxb = Eigen::MatrixXd::Zero(nm, nm * g.nb);
                detail::parallel_for(g.nb, options.threads, [&](Index k) {
                    const auto dm = g.dm.middleCols(k * nm, nm);
                    const auto dx = g.dx.middleCols(k * nm, nm);
                    auto sa = g.sa.middleCols(k * nm, nm);
                    auto sb = g.sb.middleCols(k * nm, nm);
                    gemm(sa, m_up, Op::T, dm.bottomRows(rw), Op::N);
                    gemm(sa, dm.topRows(rw), Op::T, m_dw, Op::N, 1.0, 1.0);
                    gemm(sb, m_up, Op::T, dm.topRows(rw), Op::N);
                    sb += sb.transpose().eval();
                    gemm(g.cx.middleCols(k * nm, nm), g.x, Op::T, dx, Op::N);
                    const Index c = std::min(nm, n0);
                    gemm(g.dxb.middleCols(k * nm, c), dx, Op::T, sg[0].x.leftCols(c), Op::N);
                });
            }
            snr = re.singular_values()(0) / ds1.norm();
            out.n_blocks += g.nb;
            min_block = std::min(min_block, cov.block_length);
        }
        out.setup_signal_to_noise.push_back(snr);
        out.setup_n_blocks.push_back(g.nb);
        out.setup_significant_singular_values.push_back(std::min(g.k_star, n_max + 1));
        if (unc) out.signal_to_noise = std::min(out.signal_to_noise, snr);
    }
    // Global DOFs: references first (setup 0's channels), then the moving ones gathered above.
    {
        std::vector<Index> ds(r, 0), dc(setups[0].references.begin(), setups[0].references.end());
        ds.insert(ds.end(), out.dof_setup.begin(), out.dof_setup.end());
        dc.insert(dc.end(), out.dof_channel.begin(), out.dof_channel.end());
        out.dof_setup = std::move(ds);
        out.dof_channel = std::move(dc);
    }
    if (!unc) out.signal_to_noise = std::numeric_limits<double>::quiet_NaN();
    out.significant_singular_values =
        *std::min_element(out.setup_significant_singular_values.begin(), out.setup_significant_singular_values.end());
    const double block_seconds = unc ? static_cast<double>(min_block) / options.fs : 0.0;
    out.block_length = unc ? min_block : 0;
    if (unc) {
        out.too_few_blocks = out.n_blocks - ns < 2 + 2 * l_g;
        if (out.too_few_blocks)
            out.warn(IdentificationWarning::too_few_blocks, detail::concat(
                "the setups have ", out.n_blocks, " blocks in all, too few for the joint covariance of the ", 2 + 2 * l_g,
                " parameters of a global mode (sum of n_blocks - 1 over the setups must be >= ", 2 + 2 * l_g,
                "); the standard deviations of f and xi alone are still estimated"));
        out.low_signal_to_noise = out.signal_to_noise < detail::kMinSignalToNoise;
        if (out.low_signal_to_noise)
            out.warn(IdentificationWarning::low_signal_to_noise, detail::concat(
                "the subspace matrix H of a setup is at the level of its own estimation noise (s_1 is ",
                out.signal_to_noise, " standard deviations from zero): the modes cannot be told from noise there"));
    }
    if (out.input_rank_deficient)
        out.warn(IdentificationWarning::input_rank_deficient,
                 "the input covariance R3 of a setup is rank deficient: its inputs are constant, duplicated or not "
                 "exciting enough; the uncertainty is not reliable");

    // Block columns of the concatenated factor: setup j's blocks start at col0[j].
    std::vector<Index> col0(ns + 1, 0);
    for (Index j = 0; j < ns; ++j) col0[j + 1] = col0[j] + sg[j].nb;
    const Index nb_total = col0[ns];
    // The noise-coupling test's sketch (IdentifyOptions::coupling_sketch, §13.4): setup j's n_b,j
    // blocks combined into s_j = min(s, n_b,j) columns by Rademacher signs / sqrt(s_j) (a setup
    // with at most s blocks keeps them), so the unfrozen pass, needed only for rho where a setup
    // freezes, costs about s / n_b of the frozen one. `sketch` (nb_total x its columns) carries
    // the frozen factor rows into the same combinations, so rho compares like with like. When no
    // setup has more than s blocks, nothing is sketched: the exact pass.
    const bool sketch_on =
        unc && options.coupling_sketch > 0 &&
        std::any_of(sg.begin(), sg.end(), [](const detail::SetupGamma& g) { return g.freezes(); }) &&
        std::any_of(sg.begin(), sg.end(), [&](const detail::SetupGamma& g) { return g.nb > options.coupling_sketch; });
    std::vector<detail::SetupGamma> sk;
    std::vector<Index> col0s(ns + 1, 0);
    Eigen::MatrixXd sketch;
    if (sketch_on) {
        std::vector<Eigen::MatrixXd> signs(ns);
        for (Index j = 0; j < ns; ++j) {
            const Index nbj = sg[j].nb, sj = std::min(options.coupling_sketch, nbj);
            signs[j] = sj < nbj ? Eigen::MatrixXd(detail::rademacher_signs(nbj, sj, detail::kCouplingSketchSeed + j) /
                                                  std::sqrt(static_cast<double>(sj)))
                                : Eigen::MatrixXd(Eigen::MatrixXd::Identity(nbj, nbj));
            col0s[j + 1] = col0s[j] + sj;
        }
        sketch = Eigen::MatrixXd::Zero(nb_total, col0s[ns]);
        sk.resize(ns);
        for (Index j = 0; j < ns; ++j) {
            sketch.block(col0[j], col0s[j], sg[j].nb, signs[j].cols()) = signs[j];
            sk[j] = detail::sketched_setup(sg[j], signs[j]);
        }
    }
    // Row offset of each group in C (l_g rows): references, then the moving rows of each setup.
    std::vector<Index> c0(ns + 1, r);
    for (Index j = 0; j < ns; ++j) c0[j + 1] = c0[j] + sg[j].w;

    const Index n_orders = static_cast<Index>(options.orders.size());
    out.modes.resize(n_orders);
    // Every order's Q matrices and stage-4 products in storage made once, for the largest order
    // (both passes of an order use it in turn): no allocation and page faults of tens of MB per order.
    detail::BlockQ q_store;
    detail::PerturbationBuffers z_store;
    if (unc) q_store = detail::BlockQ(nb_total, std::min(n_max, n_real), l_g, true);
    for (Index oi = 0; oi < n_orders; ++oi) {
        const Index n = options.orders[oi];
        Modes modes = detail::degenerate_modes(n, l_g, unc);
        if (n > n_real) {
            modes.note = detail::concat("order ", n, " is above the numerical rank of a setup's H (", n_real, ")");
            out.modes[oi] = std::move(modes);
            continue;
        }
        try {
            // The merge (12.3)-(12.4).
            const Eigen::MatrixXd B = sg[0].x.leftCols(n);
            std::vector<Eigen::MatrixXd> T(ns), E(ns), Xp(ns), Wj(ns), G(ns);  // G: moving group rows
            for (Index j = 0; j < ns; ++j) {
                const auto X = sg[j].x.leftCols(n);
                Eigen::MatrixXd xtx(n, n);
                gemm(xtx, X, Op::T, X, Op::N);
                const Eigen::LLT<Eigen::MatrixXd> llt(xtx);
                if (llt.info() != Eigen::Success)
                    throw numerical_error(detail::concat("setup ", j, ": the reference rows of Gamma do not have full "
                                                         "column rank at order ", n));
                Wj[j] = llt.solve(Eigen::MatrixXd::Identity(n, n));
                Xp[j] = llt.solve(X.transpose());  // X^+ = W X^T, n x p r
                T[j] = j == 0 ? Eigen::MatrixXd::Identity(n, n) : Eigen::MatrixXd(Xp[j] * B);
                E[j] = B - X * T[j];
                G[j] = sg[j].m.leftCols(n) * T[j];
            }
            // (A, C) from Gamma_g: the least squares of the shifts is row-order free, so the
            // groups are stacked (references, then each setup's moving rows).
            const Index rows_up = (p - 1) * l_g;
            Eigen::MatrixXd up(rows_up, n), dw(rows_up, n);
            {
                Index at = 0;
                const auto put = [&](const Eigen::MatrixXd& g, Index w) {
                    if (w == 0) return;
                    up.middleRows(at, (p - 1) * w) = g.topRows((p - 1) * w);
                    dw.middleRows(at, (p - 1) * w) = g.bottomRows((p - 1) * w);
                    at += (p - 1) * w;
                };
                put(B, r);
                for (Index j = 0; j < ns; ++j) put(G[j], sg[j].w);
            }
            Eigen::HouseholderQR<Eigen::MatrixXd> qr(up);
            const Eigen::MatrixXd R = qr.matrixQR().topRows(n).triangularView<Eigen::Upper>();
            const Eigen::MatrixXd qtdw = (qr.householderQ().transpose() * dw).topRows(n);
            StateSpace ss;
            ss.A = R.triangularView<Eigen::Upper>().solve(qtdw);
            ss.C.resize(l_g, n);
            ss.C.topRows(r) = B.topRows(r);
            for (Index j = 0; j < ns; ++j) ss.C.middleRows(c0[j], sg[j].w) = G[j].topRows(sg[j].w);
            Eigenstructure eig;
            modes = modes_from_system(ss, options.fs, unc ? &eig : nullptr);
            if (unc) {
                // Setup 0's blocks reach every group j >= 1 through P_j dX_0, P_j = M_j X_j^+:
                // the n x p r sums K_XY = sum_j G_j,X^T P_j,Y are formed once per order (§13.3).
                const Index pr = p * r;
                Eigen::MatrixXd k1 = Eigen::MatrixXd::Zero(n, pr), k2 = k1, k3 = k1;
                std::vector<Eigen::MatrixXd> P(ns);
                for (Index j = 1; j < ns; ++j) {
                    const Index w = sg[j].w;
                    if (w == 0) continue;
                    P[j] = sg[j].m.leftCols(n) * Xp[j];
                    const Index rw = (p - 1) * w;
                    gemm(k1, G[j].topRows(rw), Op::T, P[j].topRows(rw), Op::N, 1.0, 1.0);
                    gemm(k2, G[j].bottomRows(rw), Op::T, P[j].topRows(rw), Op::N, 1.0, 1.0);
                    gemm(k3, G[j].topRows(rw), Op::T, P[j].bottomRows(rw), Op::N, 1.0, 1.0);
                }
                // The Q matrices of every block of every setup, with each setup's noise columns
                // frozen or not (§13.4).
                // M_j W_j's first k*_j columns, for the frozen pass of a setup with frozen columns;
                // T_j^T Gud, T_j^T Gud^T, T_j^T Guu at order n for its unfrozen pass.
                std::vector<Eigen::MatrixXd> MW(ns), ygud(ns), ygdu(ns), yguu(ns);
                for (Index j = 1; j < ns; ++j) {
                    if (sg[j].w == 0) continue;
                    if (sg[j].frozen_at(n, true)) MW[j] = sg[j].m.leftCols(n) * Wj[j].leftCols(sg[j].k_star);
                    ygud[j] = T[j].transpose() * sg[j].gud.topLeftCorner(n, n);
                    ygdu[j] = T[j].transpose() * sg[j].gud.topLeftCorner(n, n).transpose();
                    yguu[j] = T[j].transpose() * sg[j].guu.topLeftCorner(n, n);
                }
                // The Q matrices of every block of every setup, with each setup's noise columns
                // frozen or not (§13.4). A block's dX and dM have c <= n columns, the others 0:
                // frozen, only the first k*_j move (the rest only scale, a change of basis).
                const auto block_q = [&](bool frozen, const std::vector<detail::SetupGamma>& setups_q,
                                         const std::vector<Index>& first) -> const detail::BlockQ& {
                    detail::BlockQ& bq = q_store;  // formed at this order only: blocked, in reused storage
                    bq.reshape(first[ns], n);
                    for (Index j = 0; j < ns; ++j) {
                        const detail::SetupGamma& g = setups_q[j];
                        detail::parallel_for(g.nb, options.threads, [&](Index k) {
                            const auto dX = g.dX(k, n, frozen);
                            const auto dM = g.dM(k, n, frozen);
                            const Index c = dX.cols();
                            Eigen::MatrixXd q1(n, n), q2(n, n), q3(n, n);
                            Eigen::MatrixXd q4 = Eigen::MatrixXd::Zero(l_g, n);
                            if (j == 0 || g.w == 0) {
                                q1.setZero();
                                q2.setZero();
                                q3.setZero();
                            }
                            if (j == 0) {  // (12.6)
                                detail::add_group_q(B, dX, r, q1.leftCols(c), q2.leftCols(c), q3.leftCols(c));
                                detail::add_group_q(G[0], dM, g.w, q1.leftCols(c), q2.leftCols(c), q3.leftCols(c));
                                // (P_j dX)_up = P_j,up dX: the row selection falls on P_j
                                q1.leftCols(c).noalias() += k1 * dX;
                                q2.leftCols(c).noalias() += k2 * dX;
                                q3.leftCols(c).noalias() += k3 * dX;
                                q4.topRows(r).leftCols(c) = dX.topRows(r);
                                q4.middleRows(c0[0], g.w).leftCols(c) = dM.topRows(g.w);
                                for (Index i = 1; i < ns; ++i) {
                                    const Index wi = sg[i].w;
                                    if (wi > 0) q4.middleRows(c0[i], wi).leftCols(c).noalias() = P[i].topRows(wi) * dX;
                                }
                            } else if (g.w > 0 && c < n) {
                                // (12.5) with dX = [dX_c 0]: dT = -(X^+ dX_c) T_c + W_c (dX_c^T E), so
                                // dG = dM_c T_c + M dT = [dM_c - P_j dX_c, M W_c] [T_c; dX_c^T E], rank 2c.
                                Eigen::MatrixXd lg(p * g.w, 2 * c), rg(2 * c, n);
                                lg.leftCols(c) = dM;
                                lg.leftCols(c).noalias() -= P[j] * dX;
                                lg.rightCols(c) = MW[j];
                                rg.topRows(c) = T[j].topRows(c);
                                gemm(rg.bottomRows(c), dX, Op::T, E[j], Op::N);
                                const Index rw = (p - 1) * g.w;
                                Eigen::MatrixXd h(n, 2 * c);
                                gemm(h, G[j].topRows(rw), Op::T, lg.topRows(rw), Op::N);
                                gemm(q1, h, Op::N, rg, Op::N);
                                gemm(h, G[j].bottomRows(rw), Op::T, lg.topRows(rw), Op::N);
                                gemm(q2, h, Op::N, rg, Op::N);
                                gemm(h, G[j].topRows(rw), Op::T, lg.bottomRows(rw), Op::N);
                                gemm(q3, h, Op::N, rg, Op::N);
                                q4.middleRows(c0[j], g.w).noalias() = lg.topRows(g.w) * rg;
                            } else if (g.w > 0) {
                                // (12.5): dT = -X^+ dX T + W dX^T E = W (dX^T B - (X^T dX + dX^T X) T),
                                // dG = dM T + M dT, and with G = M T the Q sums in n x n terms:
                                // Q3 + Q2^T = T^T sa T + (T^T Gud) dT + ((T^T Gud^T) dT)^T,
                                // Q1 + Q1^T = T^T sb T + (T^T Guu) dT + (...)^T (SetupGamma::sa ...).
                                const Index nm = g.n_max;
                                const auto lead = [&](const Eigen::MatrixXd& m) {
                                    return m.block(0, k * nm, n, n);
                                };
                                Eigen::MatrixXd s = lead(g.cx) + lead(g.cx).transpose();
                                Eigen::MatrixXd rhs = lead(g.dxb);
                                gemm(rhs, s, Op::N, T[j], Op::N, -1.0, 1.0);
                                Eigen::MatrixXd dT(n, n), tmp(n, n), a(n, n), b(n, n);
                                gemm(dT, Wj[j], Op::N, rhs, Op::N);
                                gemm(tmp, lead(g.sa), Op::N, T[j], Op::N);
                                gemm(a, T[j], Op::T, tmp, Op::N);
                                gemm(a, ygud[j], Op::N, dT, Op::N, 1.0, 1.0);
                                gemm(tmp, ygdu[j], Op::N, dT, Op::N);
                                a += tmp.transpose();
                                gemm(tmp, lead(g.sb), Op::N, T[j], Op::N);
                                gemm(b, T[j], Op::T, tmp, Op::N);
                                gemm(tmp, yguu[j], Op::N, dT, Op::N);
                                b += tmp + tmp.transpose();
                                auto q4j = q4.middleRows(c0[j], g.w);
                                q4j.noalias() = dM.topRows(g.w) * T[j];
                                q4j.noalias() += g.m.topRows(g.w).leftCols(n) * dT;
                                bq.set(first[j] + k, a, b, q4);
                                
                                
                                return;
                            }
                            
                            bq.set(first[j] + k, q3 + q2.transpose(), q1 + q1.transpose(), q4);
                        });
                    }
                    return q_store;
                };
                // Stages 4-5 (§9) unchanged on Gamma_g, all blocks of all setups at once; where a
                // setup has a frozen column among the first n, frozen in full and unfrozen for rho
                // (5.14), as UncertaintyPropagator::modes does: on every block (coupling_sketch 0),
                // with the flagged poles' shapes, or on the sketch, a flagged pole's rows then being
                // its frozen rows times rho.
                const detail::OrderContext ctx(eig, ss, R);
                const Index nm = modes.n_modes();
                const bool frozen = std::any_of(sg.begin(), sg.end(), [&](const detail::SetupGamma& g) {
                    return g.freezes() && n > g.k_star;
                });
                detail::resize_mode_uncertainty(modes, l_g, nb_total, options.keep_shape_factor);
                Eigen::MatrixXcd dlam;
                std::vector<Eigen::MatrixXcd> dshape;
                std::vector<Eigen::MatrixXd> ut_f;
                const bool sketched = frozen && sketch_on;
                if (frozen) {
                    Eigen::MatrixXcd dlam_f;
                    std::vector<Eigen::MatrixXcd> dshape_f;
                    detail::eigen_perturbation_blocks(ctx, block_q(true, sg, col0), dlam_f, dshape_f, {}, &z_store);
                    for (Index i = 0; i < nm; ++i)
                        ut_f.push_back(detail::modal_perturbation(ctx.lambda(i), options.fs,
                                                                  ss.C.cast<cd>() * ctx.phi.col(i),
                                                                  modes.reference_component(i), dlam_f.row(i),
                                                                  dshape_f[i]));
                    detail::eigen_perturbation_blocks(
                        ctx, sketched ? block_q(false, sk, col0s) : block_q(false, sg, col0), dlam, dshape, [&](Index i) {
                            const Eigen::MatrixXd plain =
                                detail::frequency_damping_perturbation(ctx.lambda(i), options.fs, dlam.row(i));
                            const double rho =
                                sketched ? detail::noise_coupling(plain, ut_f[i].topRows(2) * sketch)
                                         : detail::noise_coupling(plain, ut_f[i]);
                            modes.noise_coupling(i) = rho;
                            modes.noise_coupled(i) = !(rho <= options.noise_coupling_limit);
                            return !sketched && bool(modes.noise_coupled(i));
                        }, &z_store);
                } else {
                    detail::eigen_perturbation_blocks(ctx, block_q(false, sg, col0), dlam, dshape, {}, &z_store);
                }
                // The factor rows of each pole (the frozen or the plain, by its flag), as for one record.
                for (Index i = 0; i < nm; ++i) {
                    const Eigen::MatrixXd ut =
                        !frozen ? detail::modal_perturbation(ctx.lambda(i), options.fs, ss.C.cast<cd>() * ctx.phi.col(i),
                                                             modes.reference_component(i), dlam.row(i), dshape[i])
                        : !modes.noise_coupled(i) ? ut_f[i]
                        : sketched ? Eigen::MatrixXd(std::min(modes.noise_coupling(i), 1e150) * ut_f[i])  // inf rho: inf sigma
                                   : detail::modal_perturbation(ctx.lambda(i), options.fs, ss.C.cast<cd>() * ctx.phi.col(i),
                                                                modes.reference_component(i), dlam.row(i), dshape[i]);
                    detail::set_mode_uncertainty(modes, i, ut, block_seconds);
                }
            }
        } catch (const numerical_error& e) {
            modes = detail::degenerate_modes(n, l_g, unc);
            modes.note = e.what();
        }
        out.modes[oi] = std::move(modes);
    }

    const std::string degenerate = detail::degenerate_order_list(out.modes);
    if (!degenerate.empty())
        out.warn(IdentificationWarning::degenerate_orders, detail::concat(
            "no modes at order(s) ", degenerate, ": above the numerical rank of a setup's H (", n_real,
            ") or no usable merge or eigen-decomposition there"));
    Index shortest = std::numeric_limits<Index>::max();
    for (const SetupData& s : setups) shortest = std::min(shortest, s.covariances.n_columns);
    out.slow_decay = detail::count_slow_decay(out.modes, block_seconds, static_cast<double>(shortest) / options.fs);
    const SlowDecay& slow = out.slow_decay;
    if (slow.n_poles > 0) {
        out.warn(IdentificationWarning::slow_decay, detail::concat(
            slow.n_poles, " pole(s) decay more slowly than the shortest setup's blocks are long (", block_seconds,
            " s, less than half of the decay time, up to ", slow.longest_decay_s,
            " s); their standard deviations are less reliable"));
    }
    return out;
}

}  // namespace modaluq
