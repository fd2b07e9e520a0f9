#pragma once
/// @file uncertainty.hpp
/// First-order propagation of the block covariance of R1..R4 to the modal parameters at
/// every order (docs/uq-math.md §5-§9; Doehler & Mevel 2013). The covariance is carried as its
/// factor T (Sigma = T T^T), one column per block: no h x h matrix is ever formed.
///
/// Stages (each a function in `detail`, each finite-difference tested):
///  1. T_H = J_{H,R} T_R                               subspace.hpp
///  2. dGamma for j <= n_max, once                      gamma_perturbation
///     (columns at or above the noise floor k* frozen, docs/uq-math.md §5.5: noise_floor)
///     (the singular system B_j [du; dv] = C_j vec dH of docs/uq-math.md §5.1 solved in the SVD
///     basis, where it is diagonal: same minimum-norm solution, no b x b solve per j)
///  3. Q1..Q4 once at n_max; order n uses their leading n x n blocks    q_matrices
///     (the production path fuses 2 and 3 in QStage, which never forms dGamma)
///  4. per order and block: dA phi, d lambda, d phi, d(C phi)           eigen_perturbation
///  5. per mode: f, xi and the normalised mode shape                    modal_perturbation

#include <Eigen/Core>

#include <cmath>
#include <complex>
#include <functional>
#include <limits>
#include <vector>

#include "detail/gemm.hpp"
#include "detail/noise_floor.hpp"
#include "detail/parallel.hpp"
#include "modal.hpp"
#include "realization.hpp"

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

inline SvdPerturbation svd_perturbation(const Realization& re, const Eigen::Ref<const Eigen::MatrixXd>& dh, Index n,
                                        Index n1) {
    const Eigen::MatrixXd& U = re.U();
    const Eigen::MatrixXd& V = re.V();
    const Eigen::VectorXd& s = re.singular_values();
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
    const SvdPerturbation sp = svd_perturbation(re, dh, n, std::max(n, std::min(n_sigma, r)));
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
        : re_(re), n_(re.max_order()), l_(re.n_outputs()), n_sigma_(n_sigma), frozen_from_(frozen_from) {
        const Eigen::MatrixXd& U = re.U();
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
        const Eigen::MatrixXd& U = re_.U();
        const Eigen::VectorXd& s = re_.singular_values();
        const Index n = n_, l = l_, r = s.size(), rows = U.rows() - l;
        const SvdPerturbation sp = svd_perturbation(re_, dh, n, std::max(n, std::min(n_sigma_, r)));
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
    const Realization& re_;
    Index n_, l_, n_sigma_, frozen_from_;
    Eigen::MatrixXd k_;        ///< [U_{n,dw}^T U_up; U_{n,up}^T U_dw], 2 n x r
    Eigen::MatrixXd gram_up_;  ///< U_{n,up}^T U_{n,up} = I - U_{n,bot}^T U_{n,bot}
};

/// Q matrices of every block at n_max, stored so that one order's leading blocks of all
/// blocks are one contiguous sub-matrix: row k + n_b i of `qa` is row i of block k's Qa.
/// Order n then needs qa.topLeftCorner(n_b n, n): stage 4 is one GEMM for all blocks
/// instead of n_b small ones.
struct BlockQ {
    Index nb = 0, n_max = 0, l = 0;
    Eigen::MatrixXd qa;  ///< (n_b n_max) x n_max: Q3 + Q2^T
    Eigen::MatrixXd qb;  ///< (n_b n_max) x n_max: Q1 + Q1^T
    Eigen::MatrixXd q4;  ///< (n_b l) x n_max: dC
    using View = Eigen::Map<Eigen::MatrixXd, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
    using ConstView = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

    BlockQ() = default;
    BlockQ(Index n_blocks, Index n_max_, Index n_outputs)
        : nb(n_blocks), n_max(n_max_), l(n_outputs), qa(nb * n_max, n_max), qb(nb * n_max, n_max),
          q4(nb * l, n_max) {}

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

private:
    /// Block k of m (rows x n_max): every n_b-th row from row k.
    Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic> stride(const Eigen::MatrixXd& m) const {
        return {m.rows(), nb};
    }
    ConstView view(const Eigen::MatrixXd& m, Index k, Index rows) const {
        return ConstView(m.data() + k, rows, n_max, stride(m));
    }
    View view(Eigen::MatrixXd& m, Index k, Index rows) { return View(m.data() + k, rows, n_max, stride(m)); }
};

/// What one order's eigenstructure needs for stage 4.
struct OrderContext {
    Eigen::MatrixXcd phi;        ///< n x nm right eigenvectors of the reported modes
    Eigen::VectorXcd lambda;     ///< their eigenvalues
    Eigen::VectorXcd den;        ///< chi^H phi
    Eigen::MatrixXcd rn;         ///< R_n of Gamma_up = Q R (complex copy), W_n = (R_n^T R_n)^{-1}
    Eigen::MatrixXcd cv;         ///< C_n V
    const Eigenstructure* eig = nullptr;

    OrderContext(const Eigenstructure& e, const StateSpace& ss, const Realization& re) : eig(&e) {
        const Index n = ss.A.rows(), nm = static_cast<Index>(e.kept.size());
        phi.resize(n, nm);
        lambda.resize(nm);
        den.resize(nm);
        for (Index i = 0; i < nm; ++i) {
            const Index ki = e.kept[i];
            phi.col(i) = e.right.col(ki);
            lambda(i) = e.values(ki);
            den(i) = (e.left_h.row(ki) * e.right.col(ki))(0, 0);  // = 1 up to rounding
        }
        rn = re.gamma_up_r().topLeftCorner(n, n).cast<cd>();
        cv = ss.C.cast<cd>() * e.right;
    }
};

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

/// Stage 4 for all blocks at once, the production path (equal to eigen_perturbation per
/// block; tested). Restructured so that the work is three GEMMs for all blocks:
///   Z_k = Qa_k [Re phi, Im phi] - (Qb_k [Re phi, Im phi]) Lambda   (leading n x n of Qa_k)
///   M = chi^H W (n x n, once per order),   d lambda_i = M_{k_i,:} Z_i / (chi_i^H phi_i),
///   d(C phi_i) = G_i Z_i + Q4 phi_i   with G_i = C V diag(1 / (lambda_i - lambda_j))_{j != k_i} M,
/// where Z_i (n x nb) gathers column i of every block's Z. With BlockQ's layout, column i of
/// the stacked product read as an n_b x n matrix is Z_i^T: no gathering copy.
/// `with_shape(i)`, called once every d lambda is known, selects the modes whose d(C phi) is
/// formed (all when empty); the others get an empty dshape (the unfrozen pass of §5.5 needs the
/// shapes of flagged poles only).
inline void eigen_perturbation_blocks(const OrderContext& ctx, const BlockQ& q, Eigen::MatrixXcd& dlambda,
                                      std::vector<Eigen::MatrixXcd>& dshape,
                                      const std::function<bool(Index)>& with_shape = {}) {
    const Eigen::Index n = ctx.phi.rows(), nm = ctx.phi.cols(), l = q.l, nb = q.nb;
    const Eigenstructure& e = *ctx.eig;
    Eigen::MatrixXd ph(n, 2 * nm);
    ph << ctx.phi.real(), ctx.phi.imag();
    Eigen::MatrixXd za(nb * n, 2 * nm), zb(nb * n, 2 * nm);
    gemm(za, q.qa.topLeftCorner(nb * n, n), Op::N, ph, Op::N);
    gemm(zb, q.qb.topLeftCorner(nb * n, n), Op::N, ph, Op::N);

    // M^T = W chi-bar = R^{-1} R^{-T} (chi^H)^T.
    Eigen::MatrixXcd mt = e.left_h.transpose();
    ctx.rn.transpose().triangularView<Eigen::Lower>().solveInPlace(mt);
    ctx.rn.triangularView<Eigen::Upper>().solveInPlace(mt);
    const Eigen::MatrixXcd M = mt.transpose();

    using Cols = Eigen::Map<const Eigen::MatrixXd>;
    Eigen::MatrixXcd zt(nb, n);
    const auto z_transposed = [&](Index i) {  // Z_i^T = (a_re + i a_im) - lambda (b_re + i b_im)
        const cd lam = ctx.lambda(i);
        const Cols a_re(za.col(i).data(), nb, n), a_im(za.col(nm + i).data(), nb, n);
        const Cols b_re(zb.col(i).data(), nb, n), b_im(zb.col(nm + i).data(), nb, n);
        zt.real() = a_re - lam.real() * b_re + lam.imag() * b_im;
        zt.imag() = a_im - lam.real() * b_im - lam.imag() * b_re;
    };
    dlambda.resize(nm, nb);
    for (Index i = 0; i < nm; ++i) {
        z_transposed(i);
        dlambda.row(i).noalias() = M.row(e.kept[i]) * zt.transpose();
        dlambda.row(i) /= ctx.den(i);
    }

    std::vector<Index> wanted;
    for (Index i = 0; i < nm; ++i)
        if (!with_shape || with_shape(i)) wanted.push_back(i);
    dshape.assign(nm, Eigen::MatrixXcd());
    if (wanted.empty()) return;
    const Index nw = static_cast<Index>(wanted.size());
    Eigen::MatrixXd z4(nb * l, 2 * nm);
    gemm(z4, q.q4.leftCols(n), Op::N, ph, Op::N);
    // G_i for every wanted mode in one complex GEMM: rows w l .. w l + l - 1 of
    // [C V diag(c_1); C V diag(c_2); ...] M (l-row products one by one run at a fraction of
    // the rate when l is small).
    Eigen::MatrixXcd cvc(nw * l, n);
    for (Index w = 0; w < nw; ++w) {
        const Index i = wanted[w], ki = e.kept[i];
        for (Index j = 0; j < n; ++j) {
            auto col = cvc.block(w * l, j, l, 1);
            if (j == ki) col.setZero();
            else col = ctx.cv.col(j) * (cd(1.0) / (ctx.lambda(i) - e.values(j)));
        }
    }
    Eigen::MatrixXcd g_all(nw * l, n);
    gemm(g_all, cvc, Op::N, M, Op::N);
    for (Index w = 0; w < nw; ++w) {
        const Index i = wanted[w];
        z_transposed(i);
        dshape[i].resize(l, nb);
        dshape[i].real() = Cols(z4.col(i).data(), nb, l).transpose();
        dshape[i].imag() = Cols(z4.col(nm + i).data(), nb, l).transpose();
        gemm(dshape[i], g_all.middleRows(w * l, l), Op::N, zt, Op::T, 1.0, 1.0);
    }
}

/// Rows [f, xi] of stage 5 (docs/uq-math.md §7) from d lambda (1 x nb): d mu = fs d lambda / lambda,
/// df = Re(conj(mu) d mu) / (2 pi |mu|), d xi = Im(mu) Im(conj(mu) d mu) / |mu|^3 (signs below).
inline Eigen::MatrixXd frequency_damping_perturbation(cd lambda, double fs,
                                                      const Eigen::Ref<const Eigen::RowVectorXcd>& dlambda) {
    const cd mu = std::log(lambda) * fs;
    const double amu = std::abs(mu);
    const Eigen::RowVectorXcd dmu = dlambda * (fs / lambda);
    const Eigen::ArrayXd dre = dmu.real().transpose().array(), dim = dmu.imag().transpose().array();
    Eigen::MatrixXd ut(2, dlambda.size());
    ut.row(0) = ((mu.real() * dre + mu.imag() * dim) / (2.0 * pi * amu)).matrix().transpose();
    ut.row(1) = ((-mu.imag() * mu.imag() * dre + mu.real() * mu.imag() * dim) / (amu * amu * amu)).matrix().transpose();
    return ut;
}

/// Stage 5 for one mode: rows [f, xi, Re shape (l), Im shape (l)] of the perturbation factor
/// from d lambda (1 x nb) and d(C phi) (l x nb) (docs/uq-math.md §7, normalised shape with the
/// reference component fixed at its nominal index).
inline Eigen::MatrixXd modal_perturbation(cd lambda, double fs, const Eigen::VectorXcd& raw_shape, Index kref,
                                          const Eigen::Ref<const Eigen::RowVectorXcd>& dlambda,
                                          const Eigen::Ref<const Eigen::MatrixXcd>& dshape) {
    const Index l = raw_shape.size(), nb = dlambda.size();
    Eigen::MatrixXd ut(2 + 2 * l, nb);
    ut.topRows(2) = frequency_damping_perturbation(lambda, fs, dlambda);
    const cd pivot = raw_shape(kref);
    const Eigen::VectorXcd shape = raw_shape / pivot;
    Eigen::MatrixXcd dn = (dshape - shape * dshape.row(kref)) / pivot;
    dn.row(kref).setZero();
    ut.middleRows(2, l) = dn.real();
    ut.middleRows(2 + l, l) = dn.imag();
    return ut;
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
    UncertaintyPropagator(const Realization& re, const Eigen::MatrixXd& t_h, Index b, Index threads = 1,
                          NoiseOptions noise = {})
        : re_(re), nb_(t_h.cols()), noise_(noise) {
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
    const detail::NoiseFloor& noise_floor() const { return floor_; }

    /// Fill the uncertainty fields of `modes` (order n) from its eigenstructure.
    /// @param block_seconds  duration of one block, N_b / fs, for the block-length check
    void apply(Modes& modes, const detail::Eigenstructure& eig, const StateSpace& ss, double fs,
               double block_seconds) const {
        using detail::cd;
        const Index n = modes.order, nm = modes.n_modes(), l = re_.n_outputs();
        const Index np = 2 + 2 * l;
        modes.frequency_std.resize(nm);
        modes.damping_std.resize(nm);
        modes.mode_shape_std_real.resize(l, nm);
        modes.mode_shape_std_imag.resize(l, nm);
        modes.covariance.resize(np * np, nm);
        modes.block_too_short.resize(nm);
        modes.noise_coupling = Eigen::VectorXd::Ones(nm);
        modes.noise_coupled = Eigen::Array<bool, Eigen::Dynamic, 1>::Constant(nm, false);

        // Singular-value gap at this order, judged against its own uncertainty. Only a cut
        // between significant singular values matters: one in the noise is frozen (§5.5).
        const Eigen::VectorXd& s = re_.singular_values();
        const double sd_gap = (n < dsigma_.rows()) ? (dsigma_.row(n - 1) - dsigma_.row(n)).norm()
                                                   : dsigma_.row(n - 1).norm();
        modes.singular_value_gap = ((n < s.size()) ? s(n - 1) - s(n) : s(n - 1)) / sd_gap;
        modes.close_singular_values = n < floor_.k && !(modes.singular_value_gap >= 3.0);
        if (nm == 0) return;

        const detail::OrderContext ctx(eig, ss, re_);
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
                const Eigen::MatrixXd plain = detail::frequency_damping_perturbation(ctx.lambda(i), fs, dlam.row(i));
                double rho = 1.0;  // how much of sigma_f or sigma_xi the noise directions carry
                for (Index row : {0, 1}) {
                    const double p = plain.row(row).norm(), f = ut_f[i].row(row).norm();
                    rho = std::max(rho, f > 0.0 ? p / f : (p > 0.0 ? std::numeric_limits<double>::infinity() : 1.0));
                }
                modes.noise_coupling(i) = rho;
                modes.noise_coupled(i) = !(rho <= noise_.coupling_limit);
                return bool(modes.noise_coupled(i));
            });
        } else {
            detail::eigen_perturbation_blocks(ctx, q_, dlam, dshape);
        }
        for (Index i = 0; i < nm; ++i) {
            const Eigen::MatrixXd ut =
                (frozen && !modes.noise_coupled(i))
                    ? ut_f[i]
                    : detail::modal_perturbation(ctx.lambda(i), fs, ss.C.cast<cd>() * ctx.phi.col(i),
                                                 modes.reference_component(i), dlam.row(i), dshape[i]);
            const Eigen::MatrixXd cov = ut * ut.transpose();
            modes.covariance.col(i) = Eigen::Map<const Eigen::VectorXd>(cov.data(), np * np);
            const Eigen::VectorXd sd = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
            modes.frequency_std(i) = sd(0);
            modes.damping_std(i) = sd(1);
            modes.mode_shape_std_real.col(i) = sd.segment(2, l);
            modes.mode_shape_std_imag.col(i) = sd.segment(2 + l, l);
            const double decay_s = 1.0 / (2.0 * detail::pi * modes.frequency_hz(i) * modes.damping_ratio(i));
            modes.block_too_short(i) = modes.damping_ratio(i) > 0.0 && block_seconds < 0.5 * decay_s;
        }
    }

private:
    const Realization& re_;
    Index nb_;
    NoiseOptions noise_;
    detail::NoiseFloor floor_;
    Eigen::MatrixXd dsigma_;  ///< d sigma_j per block, j < n_max + 1
    detail::BlockQ q_;        ///< Q1..Q4 of every block at n_max
    detail::BlockQ qf_;       ///< the same with the noise columns frozen (empty if none is)
};

}  // namespace modaluq
