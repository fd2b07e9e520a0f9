#pragma once
/// @file eigen_perturbation.hpp
/// Stages 4-5 of the propagation (docs/uq-math.md §7, §9): from the Q matrices of every block to d lambda
/// and d(C phi) of every mode of one order, then to f, xi and the normalised mode shape.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <complex>
#include <functional>
#include <limits>
#include <vector>

#include "../modal.hpp"
#include "../realization.hpp"
#include "gemm.hpp"
#include "svd_perturbation.hpp"

namespace modaluq {
namespace detail {

using cd = std::complex<double>;

/// What one order's eigenstructure needs for stage 4.
struct OrderContext {
    Eigen::MatrixXcd phi;        ///< n x nm right eigenvectors of the reported modes
    Eigen::VectorXcd lambda;     ///< their eigenvalues
    Eigen::VectorXcd den;        ///< chi^H phi
    Eigen::MatrixXcd rn;         ///< R_n of Gamma_up = Q R (complex copy), W_n = (R_n^T R_n)^{-1}
    Eigen::MatrixXcd cv;         ///< C_n V
    const Eigenstructure* eig = nullptr;

    /// @param gamma_up_r  R of Gamma_up = Q R at the largest order (Realization::gamma_up_r)
    OrderContext(const Eigenstructure& e, const StateSpace& ss, const Eigen::MatrixXd& gamma_up_r) : eig(&e) {
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
        rn = gamma_up_r.topLeftCorner(n, n).cast<cd>();
        cv = ss.C.cast<cd>() * e.right;
    }
};

/// Buffers eigen_perturbation_blocks can reuse from call to call (a merge calls it twice at every
/// order): grown to the largest order's size, never shrunk, so their pages are touched once.
struct PerturbationBuffers {
    Eigen::VectorXd za, zb, z4;
};

/// Stage 4 for all blocks at once, the production path (equal to eigen_perturbation per
/// block; tested). Restructured so that the work is three GEMMs for all blocks:
///   Z_k = Qa_k [Re phi, Im phi] - (Qb_k [Re phi, Im phi]) Lambda   (leading n x n of Qa_k)
///   M = chi^H W (n x n, once per order),   d lambda_i = M_{k_i,:} Z_i / (chi_i^H phi_i),
///   d(C phi_i) = G_i Z_i + Q4 phi_i   with G_i = C V diag(1 / (lambda_i - lambda_j))_{j != k_i} M,
/// where Z_i (n x nb) gathers column i of every block's Z. With BlockQ's interleaved layout,
/// column i of the stacked product read as an n_b x n matrix is Z_i^T, and with the blocked
/// one, read as n x n_b, Z_i: no gathering copy either way.
/// `with_shape(i)`, called once every d lambda is known, selects the modes whose d(C phi) is
/// formed (all when empty); the others get an empty dshape (the unfrozen pass of §5.5 needs the
/// shapes of flagged poles only).
inline void eigen_perturbation_blocks(const OrderContext& ctx, const BlockQ& q, Eigen::MatrixXcd& dlambda,
                                      std::vector<Eigen::MatrixXcd>& dshape,
                                      const std::function<bool(Index)>& with_shape = {},
                                      PerturbationBuffers* buffers = nullptr) {
    const Eigen::Index n = ctx.phi.rows(), nm = ctx.phi.cols(), l = q.l, nb = q.nb;
    const Eigenstructure& e = *ctx.eig;
    Eigen::MatrixXd ph(n, 2 * nm);
    ph << ctx.phi.real(), ctx.phi.imag();
    require(!q.blocked || n == q.n_max, "eigen_perturbation_blocks: a blocked BlockQ holds one order");
    Eigen::VectorXd own_a, own_b, own_4;
    const auto buffer = [&](Eigen::VectorXd PerturbationBuffers::*member, Eigen::VectorXd& own, Index rows,
                            Index cols) {
        Eigen::VectorXd& v = buffers ? buffers->*member : own;
        if (v.size() < rows * cols) v.resize(rows * cols);  // grown, never shrunk
        return Eigen::Map<Eigen::MatrixXd>(v.data(), rows, cols);
    };
    auto za = buffer(&PerturbationBuffers::za, own_a, nb * n, 2 * nm);
    auto zb = buffer(&PerturbationBuffers::zb, own_b, nb * n, 2 * nm);
    gemm(za, q.qa.topLeftCorner(nb * n, n), Op::N, ph, Op::N);
    gemm(zb, q.qb.topLeftCorner(nb * n, n), Op::N, ph, Op::N);

    // M^T = W chi-bar = R^{-1} R^{-T} (chi^H)^T.
    Eigen::MatrixXcd mt = e.left_h.transpose();
    ctx.rn.transpose().triangularView<Eigen::Lower>().solveInPlace(mt);
    ctx.rn.triangularView<Eigen::Upper>().solveInPlace(mt);
    const Eigen::MatrixXcd M = mt.transpose();

    // Z_i (n x nb) = (a_re + i a_im) - lambda (b_re + i b_im), a and b column i of za and zb
    // seen block by block: interleaved, as its transpose Z_i^T (nb x n) read in place; blocked,
    // as Z_i itself, which is then contiguous (z_of returns what the products below take).
    Eigen::MatrixXcd zt(q.blocked ? n : nb, q.blocked ? nb : n);
    const auto fill_z = [&](Index i) {
        const cd lam = ctx.lambda(i);
        if (q.blocked) {
            using Map = Eigen::Map<const Eigen::MatrixXd>;
            const Map a_re(za.col(i).data(), n, nb), a_im(za.col(nm + i).data(), n, nb);
            const Map b_re(zb.col(i).data(), n, nb), b_im(zb.col(nm + i).data(), n, nb);
            zt.real() = a_re - lam.real() * b_re + lam.imag() * b_im;
            zt.imag() = a_im - lam.real() * b_im - lam.imag() * b_re;
        } else {
            const auto a_re = q.blocks_of(za.col(i).data(), n), a_im = q.blocks_of(za.col(nm + i).data(), n);
            const auto b_re = q.blocks_of(zb.col(i).data(), n), b_im = q.blocks_of(zb.col(nm + i).data(), n);
            zt.real() = a_re - lam.real() * b_re + lam.imag() * b_im;
            zt.imag() = a_im - lam.real() * b_im - lam.imag() * b_re;
        }
    };
    const Op z_op = q.blocked ? Op::N : Op::T;  // Z_i = op(zt)
    dlambda.resize(nm, nb);
    for (Index i = 0; i < nm; ++i) {
        fill_z(i);
        if (q.blocked) dlambda.row(i).noalias() = M.row(e.kept[i]) * zt;
        else dlambda.row(i).noalias() = M.row(e.kept[i]) * zt.transpose();
        dlambda.row(i) /= ctx.den(i);
    }

    std::vector<Index> wanted;
    for (Index i = 0; i < nm; ++i)
        if (!with_shape || with_shape(i)) wanted.push_back(i);
    dshape.assign(nm, Eigen::MatrixXcd());
    if (wanted.empty()) return;
    const Index nw = static_cast<Index>(wanted.size());
    auto z4 = buffer(&PerturbationBuffers::z4, own_4, nb * l, 2 * nm);
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
        fill_z(i);
        dshape[i].resize(l, nb);
        if (q.blocked) {
            dshape[i].real() = Eigen::Map<const Eigen::MatrixXd>(z4.col(i).data(), l, nb);
            dshape[i].imag() = Eigen::Map<const Eigen::MatrixXd>(z4.col(nm + i).data(), l, nb);
        } else {
            dshape[i].real() = q.blocks_of(z4.col(i).data(), l).transpose();
            dshape[i].imag() = q.blocks_of(z4.col(nm + i).data(), l).transpose();
        }
        gemm(dshape[i], g_all.middleRows(w * l, l), Op::N, zt, z_op, 1.0, 1.0);
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

/// The noise coupling rho of a pole (docs/uq-math.md eq. 5.14): max(1, sigma_f plain / frozen,
/// sigma_xi plain / frozen) from the [f, xi] rows of its plain and frozen factors (extra rows are
/// ignored); infinite when a frozen sigma is 0 and the plain one is not.
inline double noise_coupling(const Eigen::Ref<const Eigen::MatrixXd>& plain, const Eigen::Ref<const Eigen::MatrixXd>& frozen) {
    double rho = 1.0;
    for (Index row : {0, 1}) {
        const double p = plain.row(row).norm(), f = frozen.row(row).norm();
        rho = std::max(rho, f > 0.0 ? p / f : (p > 0.0 ? std::numeric_limits<double>::infinity() : 1.0));
    }
    return rho;
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
}  // namespace modaluq
