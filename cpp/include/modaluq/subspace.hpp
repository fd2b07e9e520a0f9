#pragma once
/// @file subspace.hpp
/// The subspace matrix H (paper Eq. 11) and the first step of the uncertainty,
/// T_H = J_{H,R} T_R, applied matrix-free (docs/uq-math.md §4).

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include <limits>

#include "covariance.hpp"
#include "detail/gemm.hpp"

namespace modaluq {

/// H and what its sensitivity needs.
struct SubspaceMatrix {
    Eigen::MatrixXd H;               ///< a x b; output-only H = R1, input/output H = R1 - R2 R3+ R4^T
    Eigen::MatrixXd input_gain;      ///< G = R2 R3+ (a x p m); empty when output-only
    Eigen::MatrixXd input_transfer;  ///< M = R3+ R4^T (p m x b); empty when output-only
    Index input_rank = 0;            ///< numerical rank of R3 (p m when full)
    double input_condition = 0.0;    ///< largest / smallest eigenvalue of R3 (inf when singular)
    bool input_rank_deficient = false;  ///< R3 has eigenvalues below rcond * largest
};

/// H from the covariances. R3+ is the pseudo-inverse that drops eigenvalues of R3 below
/// `input_rcond` times the largest one (a rank-deficient R3 is reported, not hidden).
inline SubspaceMatrix subspace_matrix(const Covariances& c, double input_rcond = 1e-10) {
    SubspaceMatrix s;
    if (!c.has_inputs()) {
        s.H = c.R1;
        return s;
    }
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(c.R3);
    const Eigen::VectorXd& ev = eig.eigenvalues();  // ascending
    const double top = ev.size() ? ev(ev.size() - 1) : 0.0;
    const double cut = input_rcond * std::max(top, 0.0);
    Eigen::VectorXd inv = Eigen::VectorXd::Zero(ev.size());
    for (Index i = 0; i < ev.size(); ++i)
        if (top > 0.0 && ev(i) > cut) {
            inv(i) = 1.0 / ev(i);
            ++s.input_rank;
        }
    s.input_rank_deficient = s.input_rank < ev.size();
    s.input_condition = (ev.size() && ev(0) > 0.0) ? top / ev(0) : std::numeric_limits<double>::infinity();
    const Eigen::MatrixXd r3_pinv = eig.eigenvectors() * inv.asDiagonal() * eig.eigenvectors().transpose();
    s.input_gain = c.R2 * r3_pinv;
    s.input_transfer = r3_pinv * c.R4.transpose();
    s.H = c.R1 - s.input_gain * c.R4.transpose();
    return s;
}

/// T_H = J_{H,R} T_R, column by column (docs/uq-math.md §4.3):
/// dH = dR1 - dR2 M + G dR3 M - G dR4^T. Output-only: T_H = T_R.
inline Eigen::MatrixXd propagate_to_subspace(const SubspaceMatrix& s, const Covariances& c, Eigen::MatrixXd t_r) {
    if (!c.has_inputs()) return t_r;
    const HankelLayout& L = c.layout;
    const Index a = L.rows_future(), b = L.rows_past(), pm = L.rows_input();
    Eigen::MatrixXd t_h(a * b, t_r.cols());
    Eigen::MatrixXd dh(a, b), dr3m(pm, b);
    using detail::gemm;
    using detail::Op;
    for (Index k = 0; k < t_r.cols(); ++k) {
        const double* col = t_r.col(k).data();
        Eigen::Map<const Eigen::MatrixXd> dr1(col, a, b);
        Eigen::Map<const Eigen::MatrixXd> dr2(col + a * b, a, pm);
        Eigen::Map<const Eigen::MatrixXd> dr3(col + a * b + a * pm, pm, pm);
        Eigen::Map<const Eigen::MatrixXd> dr4(col + a * b + a * pm + pm * pm, b, pm);
        dh = dr1;
        gemm(dh, dr2, Op::N, s.input_transfer, Op::N, -1.0, 1.0);
        gemm(dr3m, dr3, Op::N, s.input_transfer, Op::N);
        gemm(dh, s.input_gain, Op::N, dr3m, Op::N, 1.0, 1.0);
        gemm(dh, s.input_gain, Op::N, dr4, Op::T, -1.0, 1.0);
        t_h.col(k) = Eigen::Map<const Eigen::VectorXd>(dh.data(), a * b);
    }
    return t_h;
}

}  // namespace modaluq
