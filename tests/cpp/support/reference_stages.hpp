#pragma once
/// @file reference_stages.hpp
/// Test-only reference paths of the propagation: dGamma formed explicitly (stage 2), the Q
/// matrices from it (stage 3) and stage 4 block by block. The production code fuses these
/// (detail/svd_perturbation.hpp, detail/eigen_perturbation.hpp); the tests check both agree.

#include <modaluq/detail/eigen_perturbation.hpp>
#include <modaluq/detail/svd_perturbation.hpp>

namespace modaluq {
namespace detail {

/// Stage 2: dGamma (a x n) for one perturbation dH of H, and d sigma_j for j < n_sigma:
/// dGamma = (U Omega + P_n S^-1) S^{1/2} + U_n diag(d s_j / (2 sqrt s_j)), d s_j = Ua_jj
/// (docs/uq-math.md §5.1-5.3). The reference for the fused QStage below.
/// With `frozen_from` = k < n, the columns j >= k are frozen (docs/uq-math.md §5.5, eq. 5.13): D_j = 0,
/// so only their scale moves, d gamma_j = u_j d s_j / (2 sqrt s_j).
inline Eigen::MatrixXd gamma_perturbation(const Realization& re, const Eigen::Ref<const Eigen::MatrixXd>& dh,
                                          Index n, Eigen::VectorXd* dsigma = nullptr, Index n_sigma = 0,
                                          Index frozen_from = std::numeric_limits<Index>::max()) {
    const Eigen::MatrixXd& U = re.U();
    const Eigen::VectorXd& s = re.singular_values();
    const Index r = s.size();
    const SvdPerturbation sp = svd_perturbation(U, re.V(), s, dh, n, std::max(n, std::min(n_sigma, r)));
    if (dsigma) *dsigma = sp.Ua.diagonal().head(std::min(n_sigma, r));
    const Eigen::ArrayXd sq = s.head(n).array().sqrt();
    Eigen::MatrixXd dg(U.rows(), n);
    gemm(dg, U, Op::N, sp.omega, Op::N);
    dg += sp.P.leftCols(n) * s.head(n).cwiseInverse().asDiagonal();
    if (frozen_from < n) dg.rightCols(n - std::max<Index>(frozen_from, 0)).setZero();
    dg = dg * sq.matrix().asDiagonal();
    dg += U.leftCols(n) * (sp.Ua.diagonal().head(n).array() / (2.0 * sq)).matrix().asDiagonal();
    return dg;
}

/// Stage 3 for one block: Qa = Q3 + Q2^T, Qb = Q1 + Q1^T, Q4 = dC, with
/// Q1 = Gamma_up^T dGamma_up, Q2 = Gamma_dw^T dGamma_up, Q3 = Gamma_up^T dGamma_dw (docs/uq-math.md §9).
inline void q_matrices(const Eigen::MatrixXd& gamma, const Eigen::MatrixXd& dgamma, Index l,
                       Eigen::Ref<Eigen::MatrixXd> qa, Eigen::Ref<Eigen::MatrixXd> qb,
                       Eigen::Ref<Eigen::MatrixXd> q4) {
    const Index rows = gamma.rows() - l;
    const auto g_up = gamma.topRows(rows), g_dw = gamma.bottomRows(rows);
    const auto d_up = dgamma.topRows(rows), d_dw = dgamma.bottomRows(rows);
    Eigen::MatrixXd q1(gamma.cols(), dgamma.cols());
    gemm(q1, g_up, Op::T, d_up, Op::N);
    gemm(qa, g_up, Op::T, d_dw, Op::N);
    gemm(qa, d_up, Op::T, g_dw, Op::N, 1.0, 1.0);
    qb = q1 + q1.transpose();
    q4 = dgamma.topRows(l);
}

/// Stage 4 for one block: d lambda_i (nm) and d(C phi_i) (l x nm) from that block's Q
/// matrices restricted to the order (leading n x n blocks):
/// Z = Qa phi - lambda Qb phi, dA phi = W Z, d lambda = chi^H dA phi / chi^H phi,
/// d phi = sum_{j != i} phi_j chi_j^H (dA phi - phi d lambda) / (lambda_i - lambda_j)
/// (a particular solution; the normalised mode shape does not depend on which, docs/uq-math.md §7).
inline void eigen_perturbation(const OrderContext& ctx, const Eigen::Ref<const Eigen::MatrixXd>& qa,
                               const Eigen::Ref<const Eigen::MatrixXd>& qb,
                               const Eigen::Ref<const Eigen::MatrixXd>& q4, Eigen::Ref<Eigen::VectorXcd> dlambda,
                               Eigen::Ref<Eigen::MatrixXcd> dshape) {
    const Eigenstructure& e = *ctx.eig;
    const Index n = ctx.phi.rows(), nm = ctx.phi.cols();
    Eigen::MatrixXcd z = qa.cast<cd>() * ctx.phi;
    z.noalias() -= (qb.cast<cd>() * ctx.phi) * ctx.lambda.asDiagonal();
    ctx.rn.transpose().triangularView<Eigen::Lower>().solveInPlace(z);
    ctx.rn.triangularView<Eigen::Upper>().solveInPlace(z);
    const Eigen::MatrixXcd proj = e.left_h * z;  // chi_j^H dA phi_i
    Eigen::VectorXcd coef(n);
    for (Index i = 0; i < nm; ++i) {
        const Index ki = e.kept[i];
        dlambda(i) = proj(ki, i) / ctx.den(i);
        for (Index j = 0; j < n; ++j) coef(j) = (j == ki) ? cd(0.0) : proj(j, i) / (ctx.lambda(i) - e.values(j));
        dshape.col(i) = ctx.cv * coef + q4.cast<cd>() * ctx.phi.col(i);
    }
}

}  // namespace detail
}  // namespace modaluq
