#pragma once
/// @file svd_perturbation.hpp
/// Stages 2-3 of the propagation (docs/uq-math.md §5, §9): the perturbation of the SVD of H in its own
/// basis and, fused with it, the Q matrices of every block at the largest order (QStage,
/// BlockQ). The reference forms (dGamma, then Q) are in tests/cpp/support/reference_stages.hpp.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <complex>
#include <functional>
#include <limits>
#include <stdexcept>
#include <vector>

#include "../modal.hpp"
#include "../realization.hpp"
#include "gemm.hpp"

namespace modaluq {
namespace detail {

using cd = std::complex<double>;

/// dH in the SVD basis, what stage 2 needs (docs/uq-math.md §5.1-5.3) for singular vectors j < n:
/// P = dH V_{n1} (dH v_j, n1 >= n columns), Ua = U^T P (u_i^T dH v_j), and Omega (r x n) with
/// du_j = U Omega_j + dH v_j / s_j:
/// Omega_ij = (s_j Ua_ij + s_i u_j^T dH v_i) / (s_j^2 - s_i^2) for i != j, Omega_jj = 0, then
/// minus Ua_ij / s_j (the part of dH v_j / s_j inside span U).
struct SvdPerturbation {
    Eigen::MatrixXd P, Ua, omega;
};

inline SvdPerturbation svd_perturbation(const Eigen::MatrixXd& U, const Eigen::MatrixXd& V, const Eigen::VectorXd& s,
                                        const Eigen::Ref<const Eigen::MatrixXd>& dh, Index n, Index n1) {
    const Index r = s.size(), a = U.rows();
    SvdPerturbation sp;
    sp.P.resize(a, n1);
    sp.Ua.resize(r, n1);
    Eigen::MatrixXd W(n, dh.cols()), Ub(n, V.cols());
    gemm(sp.P, dh, Op::N, V.leftCols(n1), Op::N);  // dH v_j
    gemm(sp.Ua, U, Op::T, sp.P, Op::N);            // u_i^T dH v_j
    gemm(W, U.leftCols(n), Op::T, dh, Op::N);
    gemm(Ub, W, Op::N, V, Op::N);                  // u_j^T dH v_i
    sp.omega.resize(r, n);
    for (Index j = 0; j < n; ++j) {
        for (Index i = 0; i < r; ++i)
            sp.omega(i, j) = (i == j) ? 0.0 : (s(j) * sp.Ua(i, j) + s(i) * Ub(j, i)) / (s(j) * s(j) - s(i) * s(i));
        sp.omega.col(j) -= sp.Ua.col(j) / s(j);
    }
    return sp;
}

/// Stages 2 and 3 fused, the production path (equal to q_matrices of gamma_perturbation;
/// tested): the Q matrices at n_max straight from the SVD-basis perturbation, without
/// forming dGamma. With Gamma = U_n S^{1/2} and dGamma = D S^{1/2} + U_n E,
/// D = U Omega + P_n S^-1, E = diag(d s_j / (2 sqrt s_j)), for row selections X, Y:
///   Gamma_X^T dGamma_Y = S^{1/2} [(K_XY Omega + U_{n,X}^T P_{n,Y} S^-1) S^{1/2} + K_XY[:, :n] E],
/// K_XY = U_{n,X}^T U_Y computed once. For X = Y = up (all rows but the last l), U^T U = I
/// gives K = [I 0] - U_{n,bot}^T U_bot over the last l rows only, so Q1 is almost free and
/// the a x r x n product U Omega is not needed: 8 n^2 a flops per block instead of 14.
///
/// Frozen columns (docs/uq-math.md §5.5): every X above is, column by column, linear in column j of Omega
/// and of P, so freezing columns j >= k* (D_j = 0) is zeroing those columns of the X's and of
/// D_top; the E term keeps d s_j. Both sets of Q matrices come from one pass.
struct QBlock {
    Eigen::MatrixXd qa, qb, q4;  ///< Q3 + Q2^T, Q1 + Q1^T (n x n), dC (l x n)
};

class QStage {
public:
    /// @param frozen_from  k*: columns j >= k* are frozen in the second set of Q matrices
    QStage(const Realization& re, Index n_sigma, Index frozen_from = std::numeric_limits<Index>::max())
        : u_(re.U()), v_(re.V()), s_(re.singular_values()), n_(re.max_order()), l_(re.n_outputs()),
          n_sigma_(n_sigma), frozen_from_(frozen_from) {
        const Eigen::MatrixXd& U = u_;
        const Index rows = U.rows() - l_, r = U.cols();
        k_.resize(2 * n_, r);  // [K_dw,up; K_up,dw]
        gemm(k_.topRows(n_), U.block(l_, 0, rows, n_), Op::T, U.topRows(rows), Op::N);
        gemm(k_.bottomRows(n_), U.topLeftCorner(rows, n_), Op::T, U.bottomRows(rows), Op::N);
        gram_up_ = Eigen::MatrixXd::Identity(n_, n_);
        gemm(gram_up_, U.bottomLeftCorner(l_, n_), Op::T, U.bottomLeftCorner(l_, n_), Op::N, -1.0, 1.0);
    }

    /// Qa = Q3 + Q2^T, Qb = Q1 + Q1^T (n x n), Q4 = dC (l x n) of one block from its dH, and
    /// d sigma_j for j < n_sigma.
    void compute(const Eigen::Ref<const Eigen::MatrixXd>& dh, Eigen::Ref<Eigen::MatrixXd> qa,
                 Eigen::Ref<Eigen::MatrixXd> qb, Eigen::Ref<Eigen::MatrixXd> q4,
                 Eigen::Ref<Eigen::VectorXd> dsigma) const {
        QBlock base;
        compute(dh, base, nullptr, dsigma);
        qa = base.qa;
        qb = base.qb;
        q4 = base.q4;
    }

    /// Whether a frozen set differs from the plain one (some column j < n_max is frozen).
    bool freezes() const { return frozen_from_ < n_; }

    /// The plain Q matrices in `base` and, if `frozen` is given and freezes(), those with the
    /// columns j >= k* frozen.
    void compute(const Eigen::Ref<const Eigen::MatrixXd>& dh, QBlock& base, QBlock* frozen,
                 Eigen::Ref<Eigen::VectorXd> dsigma) const {
        const Eigen::MatrixXd& U = u_;
        const Eigen::VectorXd& s = s_;
        const Index n = n_, l = l_, r = s.size(), rows = U.rows() - l;
        const SvdPerturbation sp = svd_perturbation(U, v_, s, dh, n, std::max(n, std::min(n_sigma_, r)));
        dsigma = sp.Ua.diagonal().head(dsigma.size());
        const Eigen::VectorXd sinv = s.head(n).cwiseInverse(), sq = s.head(n).cwiseSqrt();
        const Eigen::VectorXd e = sp.Ua.diagonal().head(n).cwiseQuotient(2.0 * sq);

        // Rows of D: the first l (dC) and the last l (for Q1).
        Eigen::MatrixXd d_top(l, n), d_bot(l, n);
        gemm(d_top, U.topRows(l), Op::N, sp.omega, Op::N);
        d_top += sp.P.topLeftCorner(l, n) * sinv.asDiagonal();
        gemm(d_bot, U.bottomRows(l), Op::N, sp.omega, Op::N);
        d_bot += sp.P.bottomLeftCorner(l, n) * sinv.asDiagonal();

        // X_up,up = Omega[:n] + Ua[:n, :n] S^-1 - U_{n,bot}^T D_bot
        Eigen::MatrixXd x1 = sp.omega.topRows(n) + sp.Ua.topLeftCorner(n, n) * sinv.asDiagonal();
        gemm(x1, U.bottomLeftCorner(l, n), Op::T, d_bot, Op::N, -1.0, 1.0);
        // [X_dw,up; X_up,dw] = [K_dw,up; K_up,dw] Omega + [U_{n,dw}^T P_{n,up}; U_{n,up}^T P_{n,dw}] S^-1
        Eigen::MatrixXd x23(2 * n, n), pp(n, n);
        gemm(x23, k_, Op::N, sp.omega, Op::N);
        gemm(pp, U.block(l, 0, rows, n), Op::T, sp.P.topLeftCorner(rows, n), Op::N);
        x23.topRows(n) += pp * sinv.asDiagonal();
        gemm(pp, U.topLeftCorner(rows, n), Op::T, sp.P.block(l, 0, rows, n), Op::N);
        x23.bottomRows(n) += pp * sinv.asDiagonal();

        // Q_XY = S^{1/2} (X_XY S^{1/2} + Gram_XY E)
        const auto finish = [&](const Eigen::MatrixXd& x, const Eigen::Ref<const Eigen::MatrixXd>& gram) {
            return Eigen::MatrixXd(sq.asDiagonal() * (x * sq.asDiagonal() + gram * e.asDiagonal()));
        };
        const auto assemble = [&](QBlock& out) {
            const Eigen::MatrixXd q1 = finish(x1, gram_up_);
            const Eigen::MatrixXd q2 = finish(x23.topRows(n), k_.topLeftCorner(n, n));
            const Eigen::MatrixXd q3 = finish(x23.bottomRows(n), k_.bottomLeftCorner(n, n));
            out.qa = q3 + q2.transpose();
            out.qb = q1 + q1.transpose();
            out.q4 = d_top * sq.asDiagonal() + U.topLeftCorner(l, n) * e.asDiagonal();
        };
        assemble(base);
        if (frozen && freezes()) {
            const Index k = std::max<Index>(frozen_from_, 0), m = n - k;
            x1.rightCols(m).setZero();
            x23.rightCols(m).setZero();
            d_top.rightCols(m).setZero();
            assemble(*frozen);
        }
    }

private:
    Eigen::MatrixXd u_, v_;    ///< singular vectors of H (a copy: the stage owns what it reads)
    Eigen::VectorXd s_;        ///< singular values of H
    Index n_, l_, n_sigma_, frozen_from_;
    Eigen::MatrixXd k_;        ///< [U_{n,dw}^T U_up; U_{n,up}^T U_dw], 2 n x r
    Eigen::MatrixXd gram_up_;  ///< U_{n,up}^T U_{n,up} = I - U_{n,bot}^T U_{n,bot}
};

/// Q matrices of every block at n_max, stored so that one order's leading blocks of all
/// blocks are one contiguous sub-matrix: row k + n_b i of `qa` is row i of block k's Qa.
/// Order n then needs qa.topLeftCorner(n_b n, n): stage 4 is one GEMM for all blocks
/// instead of n_b small ones. `blocked` stores block k's rows contiguously instead (row
/// k n_max + i), for Q matrices formed anew at each order (the merge of setups): those are
/// used at n = n_max only, and each block is then written in columns of n_max doubles rather
/// than one scattered element per row.
struct BlockQ {
    Index nb = 0, n_max = 0, l = 0;
    bool blocked = false;
    Eigen::MatrixXd qa;  ///< (n_b n_max) x n_max: Q3 + Q2^T
    Eigen::MatrixXd qb;  ///< (n_b n_max) x n_max: Q1 + Q1^T
    Eigen::MatrixXd q4;  ///< (n_b l) x n_max: dC
    using View = Eigen::Map<Eigen::MatrixXd, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
    using ConstView = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

    BlockQ() = default;
    BlockQ(Index n_blocks, Index n_max_, Index n_outputs, bool blocked_ = false)
        : nb(n_blocks), n_max(n_max_), l(n_outputs), blocked(blocked_), qa(nb * n_max, n_max),
          qb(nb * n_max, n_max), q4(nb * l, n_max) {}

    /// Reuse this storage (blocked only) for n_blocks blocks at order n: a merge forms the Q
    /// matrices of every order anew, and reusing one BlockQ made at the largest order spares the
    /// allocation and first touch (page faults) of tens of MB per order. Rows beyond n_blocks n
    /// and columns beyond n are left unused (the views keep the storage's row stride).
    void reshape(Index n_blocks, Index n) {
        if (!blocked || n_blocks * n > qa.rows() || n > qa.cols() || n_blocks * l > q4.rows())
            throw std::logic_error("BlockQ::reshape: needs blocked storage made at least as large");
        nb = n_blocks;
        n_max = n;
    }

    /// Block k's matrices (n_max x n_max, l x n_max) as strided views.
    ConstView qa_block(Index k) const { return view(qa, k, n_max); }
    ConstView qb_block(Index k) const { return view(qb, k, n_max); }
    ConstView q4_block(Index k) const { return view(q4, k, l); }

    /// Store block k's Q matrices (blocks write disjoint elements).
    void set(Index k, const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, const Eigen::MatrixXd& c) {
        view(qa, k, n_max) = a;
        view(qb, k, n_max) = b;
        view(q4, k, l) = c;
    }

    /// A column z of a product (qa, qb or q4 restricted to order n's rows) * X, nb rows of
    /// `rows` (n or l) per block, as the nb x rows matrix whose row k is block k's.
    ConstView blocks_of(const double* z, Index rows) const {
        using S = Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>;
        return blocked ? ConstView(z, nb, rows, S(1, rows)) : ConstView(z, nb, rows, S(nb, 1));
    }

private:
    /// Block k of m (rows x n_max): interleaved, every n_b-th row from row k; blocked, rows
    /// k rows .. k rows + rows - 1.
    Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic> stride(const Eigen::MatrixXd& m) const {
        return blocked ? Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(m.rows(), 1)
                       : Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(m.rows(), nb);
    }
    const double* start(const Eigen::MatrixXd& m, Index k, Index rows) const {
        return m.data() + (blocked ? k * rows : k);
    }
    ConstView view(const Eigen::MatrixXd& m, Index k, Index rows) const {
        return ConstView(start(m, k, rows), rows, n_max, stride(m));
    }
    View view(Eigen::MatrixXd& m, Index k, Index rows) {
        return View(const_cast<double*>(start(m, k, rows)), rows, n_max, stride(m));
    }
};

}  // namespace detail
}  // namespace modaluq
