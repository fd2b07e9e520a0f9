#pragma once
/// @file realization.hpp
/// One SVD of H, then the observability matrix Gamma and (A, C) at every model order
/// (docs/uq-math.md §2.2). Order n uses the leading n columns of the largest order's quantities, so
/// a stabilisation diagram costs one SVD and one QR.

#include <Eigen/Core>
#include <Eigen/QR>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <limits>

#include "errors.hpp"
#include "layout.hpp"

namespace modaluq {

/// A state-space pair at one order.
struct StateSpace {
    Eigen::MatrixXd A;  ///< n x n state transition matrix
    Eigen::MatrixXd C;  ///< l x n output matrix
};

/// SVD of H and the shift-invariance least squares, computed once at the largest order.
class Realization {
public:
    /// @param H          subspace matrix (a x b), a = p l
    /// @param n_outputs  l
    /// @param max_order  largest order that will be asked for, <= min((p-1) l, q r). Orders above
    ///                   the numerical rank of H have no realization: max_order() is then the rank.
    Realization(const Eigen::MatrixXd& H, Index n_outputs, Index max_order)
        : l_(n_outputs), n_max_(max_order) {
        detail::require(n_outputs >= 1 && H.rows() % n_outputs == 0 && H.rows() >= 2 * n_outputs,
                        "H must have a multiple of n_outputs rows and at least two block rows");
        detail::require(max_order >= 1, "orders must be >= 1, got ", max_order);
        detail::require(max_order <= std::min(H.rows() - n_outputs, H.cols()),
                        "order ", max_order, " is above the largest order the horizons support, min((p-1)*l, q*r) = ",
                        std::min(H.rows() - n_outputs, H.cols()));
        // Eigen's SVD returns without filling its outputs on non-finite input; never read them then.
        detail::require(H.allFinite(), "H has non-finite entries: the covariances overflowed (rescale the data)");
        Eigen::BDCSVD<Eigen::MatrixXd> svd(H, Eigen::ComputeThinU | Eigen::ComputeThinV);
        if (svd.info() != Eigen::Success) throw numerical_error("the SVD of H did not converge");
        s_ = svd.singularValues();
        // Numerical rank as NumPy's matrix_rank: singular values above max(a, b) eps s_1. Beyond
        // it, Gamma has zero columns and A is undefined, so the realization stops there.
        const double tol = static_cast<double>(std::max(H.rows(), H.cols())) *
                           std::numeric_limits<double>::epsilon() * (s_.size() ? s_(0) : 0.0);
        rank_ = 0;
        while (rank_ < s_.size() && s_(rank_) > tol) ++rank_;
        requested_max_ = n_max_;
        n_max_ = std::min(n_max_, rank_);
        u_ = svd.matrixU();
        v_ = svd.matrixV();
        // Sign convention (docs/uq-math.md §5.4): largest-modulus entry of each u_j positive.
        for (Index j = 0; j < u_.cols(); ++j) {
            Index imax;
            u_.col(j).cwiseAbs().maxCoeff(&imax);
            if (u_(imax, j) < 0) {
                u_.col(j) = -u_.col(j);
                v_.col(j) = -v_.col(j);
            }
        }
        if (n_max_ == 0) return;  // H is zero: nothing to realise (identify reports it)
        gamma_ = u_.leftCols(n_max_) * s_.head(n_max_).cwiseSqrt().asDiagonal();
        const Index rows = H.rows() - l_;
        Eigen::HouseholderQR<Eigen::MatrixXd> qr(gamma_.topRows(rows));
        r_ = qr.matrixQR().topRows(n_max_).triangularView<Eigen::Upper>();
        qt_dw_ = (qr.householderQ().transpose() * gamma_.bottomRows(rows)).topRows(n_max_);
    }

    Index n_outputs() const { return l_; }
    /// Largest order realised: the requested one, or the numerical rank of H if that is lower.
    Index max_order() const { return n_max_; }
    Index requested_max_order() const { return requested_max_; }
    /// Singular values of H above max(a, b) eps s_1 (orders above it have no realization).
    Index numerical_rank() const { return rank_; }
    const Eigen::VectorXd& singular_values() const { return s_; }  ///< all min(a, b)
    const Eigen::MatrixXd& U() const { return u_; }                ///< a x min(a, b)
    const Eigen::MatrixXd& V() const { return v_; }                ///< b x min(a, b)
    /// Gamma at the largest order, U_1 S_1^{1/2} (a x n_max); order n is its first n columns.
    const Eigen::MatrixXd& observability() const { return gamma_; }
    /// R of Gamma_up = Q R at the largest order; W_n = (R_n^T R_n)^{-1}.
    const Eigen::MatrixXd& gamma_up_r() const { return r_; }

    /// (A, C) at order n: C = first l rows of Gamma, A = Gamma_up^+ Gamma_dw (least squares).
    StateSpace system(Index n) const {
        detail::require(n >= 1 && n <= n_max_, "order ", n, " is outside 1..", n_max_,
                        n > n_max_ && n <= requested_max_ ? " (above the numerical rank of H)" : "");
        StateSpace ss;
        ss.C = gamma_.topLeftCorner(l_, n);
        ss.A = r_.topLeftCorner(n, n).triangularView<Eigen::Upper>().solve(qt_dw_.topLeftCorner(n, n));
        return ss;
    }

private:
    Index l_, n_max_, requested_max_ = 0, rank_ = 0;
    Eigen::VectorXd s_;
    Eigen::MatrixXd u_, v_, gamma_, r_, qt_dw_;
};

}  // namespace modaluq
