#pragma once
/// @file indicators.hpp
/// Mode indicators with their uncertainty: the modal phase collinearity (MPC), the mean phase
/// deviation (MPD) and the modal assurance criterion (MAC) between two shapes, each with the
/// standard deviation that follows from the shapes' covariance (docs/uq-math.md §12).
///
/// MPC and MAC sit at their maximum (1) for a real mode and for two estimates of one mode: there
/// the gradient vanishes and a first-order (delta-method) std would be 0, while the estimates
/// scatter by O(sigma^2). Both are therefore propagated to second order (value, gradient and
/// Hessian in the real coordinates [Re phi; Im phi]); for a Gaussian perturbation d with
/// covariance S,  E[q(z + d)] = q + tr(H S)/2  and  Var = g' S g + tr(H S H S)/2.
/// The shapes are estimates, and the gradient at an estimate is itself O(sigma) even where the
/// true one is 0: E[g(z^)' S g(z^)] = g' S g + tr(H S H S). The std reported removes that bias
/// (clipped at 0), so it is right both far from and at the maximum. MPD's deviations are
/// absolute angles, not smooth at 0: its std is first order, of the signed angles.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>

#include "detail/checks.hpp"
#include "layout.hpp"

namespace modaluq {

/// A scalar indicator of estimated shapes and its uncertainty.
struct IndicatorStatistics {
    double value = std::numeric_limits<double>::quiet_NaN();  ///< at the estimated shape(s)
    /// std of the indicator's estimate (second order for MPC and MAC, first order for MPD);
    /// NaN when no covariance was given
    double std = std::numeric_limits<double>::quiet_NaN();
    /// Where the indicator is at its maximum in truth (a real mode; two estimates of one mode),
    /// what its estimate loses on average, tr(-H S)/2, and that loss's std, sqrt(tr(H S H S)/2):
    /// 1 - value is consistent with that maximum when it is of the size of these (the "same
    /// mode?" and "real mode?" tests; Python: modaluq.mac_test)
    double loss_at_maximum_mean = std::numeric_limits<double>::quiet_NaN();
    double loss_at_maximum_std = std::numeric_limits<double>::quiet_NaN();
};

namespace detail {

/// Real coordinates [Re phi; Im phi] of a complex vector.
inline Eigen::VectorXd realify(const Eigen::VectorXcd& phi) {
    Eigen::VectorXd z(2 * phi.size());
    z << phi.real(), phi.imag();
    return z;
}

/// MPC = ((Syy - Sxx)^2 + 4 Sxy^2) / (Sxx + Syy)^2 of phi = x + i y, with its gradient and Hessian
/// in z = [x; y] (for the second-order propagation; finite-difference tested).
inline double mpc_derivatives(const Eigen::VectorXd& z, Eigen::VectorXd* grad, Eigen::MatrixXd* hess) {
    const Index l = z.size() / 2;
    const auto x = z.head(l), y = z.tail(l);
    const double sxx = x.squaredNorm(), syy = y.squaredNorm(), sxy = x.dot(y);
    const double s = sxx + syy, t = syy - sxx, nn = t * t + 4.0 * sxy * sxy;
    const double v = nn / (s * s);
    if (!grad) return v;
    Eigen::VectorXd ds = 2.0 * z, dt(2 * l), dsxy(2 * l);
    dt << -2.0 * x, 2.0 * y;
    dsxy << y, x;
    const Eigen::VectorXd dn = 2.0 * t * dt + 8.0 * sxy * dsxy;
    *grad = dn / (s * s) - 2.0 * nn * ds / (s * s * s);
    if (!hess) return v;
    Eigen::MatrixXd ddn = 2.0 * dt * dt.transpose() + 8.0 * dsxy * dsxy.transpose();
    ddn.diagonal().head(l).array() -= 4.0 * t;  // 2 t d2t, d2t = diag(-2 I, 2 I)
    ddn.diagonal().tail(l).array() += 4.0 * t;
    for (Index i = 0; i < l; ++i) {            // 8 sxy d2Sxy, d2Sxy = [0 I; I 0]
        ddn(i, l + i) += 8.0 * sxy;
        ddn(l + i, i) += 8.0 * sxy;
    }
    const double s3 = s * s * s;
    *hess = ddn / (s * s) - 2.0 * (dn * ds.transpose() + ds * dn.transpose()) / s3 +
            6.0 * nn * ds * ds.transpose() / (s3 * s);
    hess->diagonal().array() -= 2.0 * nn * 2.0 / s3;  // -2 N d2s / s^3, d2s = 2 I
    return v;
}

/// MAC = |a^H b|^2 / (|a|^2 |b|^2) with its gradient and Hessian in z = [Re a; Im a; Re b; Im b].
inline double mac_derivatives(const Eigen::VectorXd& z, Eigen::VectorXd* grad, Eigen::MatrixXd* hess) {
    const Index l = z.size() / 4;
    const auto xa = z.segment(0, l), ya = z.segment(l, l), xb = z.segment(2 * l, l), yb = z.segment(3 * l, l);
    const double p = xa.dot(xb) + ya.dot(yb);  // Re a^H b
    const double q = xa.dot(yb) - ya.dot(xb);  // Im a^H b
    const double da = z.head(2 * l).squaredNorm(), db = z.tail(2 * l).squaredNorm();
    const double nn = p * p + q * q, d = da * db, v = nn / d;
    if (!grad) return v;
    const Index m = 4 * l;
    Eigen::VectorXd dp(m), dq(m), dda = Eigen::VectorXd::Zero(m), ddb = Eigen::VectorXd::Zero(m);
    dp << xb, yb, xa, ya;
    dq << yb, -xb, -ya, xa;
    dda.head(2 * l) = 2.0 * z.head(2 * l);
    ddb.tail(2 * l) = 2.0 * z.tail(2 * l);
    const Eigen::VectorXd dn = 2.0 * p * dp + 2.0 * q * dq;
    const Eigen::VectorXd dd = db * dda + da * ddb;
    *grad = (dn - v * dd) / d;
    if (!hess) return v;
    Eigen::MatrixXd ddn = 2.0 * dp * dp.transpose() + 2.0 * dq * dq.transpose();
    for (Index i = 0; i < 2 * l; ++i) {  // 2 p d2p: d2p = [0 I; I 0] between a and b
        ddn(i, 2 * l + i) += 2.0 * p;
        ddn(2 * l + i, i) += 2.0 * p;
    }
    for (Index i = 0; i < l; ++i) {  // 2 q d2q: d2q pairs (xa, yb) with +1 and (ya, xb) with -1
        ddn(i, 3 * l + i) += 2.0 * q;
        ddn(3 * l + i, i) += 2.0 * q;
        ddn(l + i, 2 * l + i) -= 2.0 * q;
        ddn(2 * l + i, l + i) -= 2.0 * q;
    }
    Eigen::MatrixXd ddd = dda * ddb.transpose() + ddb * dda.transpose();
    ddd.diagonal().head(2 * l).array() += 2.0 * db;
    ddd.diagonal().tail(2 * l).array() += 2.0 * da;
    // MAC = N / D: H = (d2N - MAC d2D - g dD' - dD g') / D
    *hess = (ddn - v * ddd - (*grad) * dd.transpose() - dd * grad->transpose()) / d;
    return v;
}

/// Second-order statistics of a smooth indicator q at an estimate, for a perturbation of
/// covariance `cov` (see the file comment).
inline IndicatorStatistics second_order(double value, const Eigen::VectorXd& g, const Eigen::MatrixXd& h,
                                        const Eigen::MatrixXd& cov) {
    IndicatorStatistics out;
    out.value = value;
    const Eigen::MatrixXd hs = h * cov;
    const double tr1 = hs.trace();
    const double tr2 = hs.cwiseProduct(hs.transpose()).sum();  // tr(H S H S)
    const double gsg = g.dot(cov * g);
    out.std = std::sqrt(std::max(gsg - tr2, 0.0) + 0.5 * tr2);
    out.loss_at_maximum_mean = -0.5 * tr1;
    out.loss_at_maximum_std = std::sqrt(0.5 * std::max(tr2, 0.0));
    return out;
}

inline void require_shape_covariance(const char* name, const Eigen::MatrixXd& cov, Index l) {
    require(cov.rows() == 2 * l && cov.cols() == 2 * l, name, " must be the 2l x 2l covariance of [Re shape; Im shape] (l = ",
            l, "), got ", cov.rows(), " x ", cov.cols());
    require(cov.allFinite(), name, " must be finite");
}

inline void require_shape(const char* name, const Eigen::VectorXcd& phi) {
    require(phi.size() >= 1, name, " must have at least one component");
    require(phi.allFinite(), name, " must be finite");
    require(phi.squaredNorm() > 0.0, name, " must not be zero");
}

/// MAC of a and b with its second-order statistics for the joint covariance of
/// [Re a; Im a; Re b; Im b] (checked by the callers).
inline IndicatorStatistics mac_statistics(const Eigen::VectorXcd& a, const Eigen::VectorXcd& b,
                                          const Eigen::MatrixXd& joint) {
    Eigen::VectorXd z(2 * (a.size() + b.size())), g;  // [Re a; Im a; Re b; Im b]
    z << realify(a), realify(b);
    Eigen::MatrixXd h;
    const double v = mac_derivatives(z, &g, &h);
    return second_order(v, g, h, joint);
}

}  // namespace detail

/// Modal phase collinearity of a shape: 1 for a real (monophase) shape, 0 for a circular one.
inline double modal_phase_collinearity(const Eigen::VectorXcd& shape) {
    detail::require_shape("shape", shape);
    return detail::mpc_derivatives(detail::realify(shape), nullptr, nullptr);
}

/// MPC with its std from `cov`, the 2l x 2l covariance of [Re shape; Im shape] (the lower-right
/// block of Modes::covariance).
inline IndicatorStatistics modal_phase_collinearity_statistics(const Eigen::VectorXcd& shape,
                                                               const Eigen::MatrixXd& cov) {
    detail::require_shape("shape", shape);
    detail::require_shape_covariance("cov", cov, shape.size());
    Eigen::VectorXd g;
    Eigen::MatrixXd h;
    const double v = detail::mpc_derivatives(detail::realify(shape), &g, &h);
    return detail::second_order(v, g, h, cov);
}

/// MAC between two shapes of equal length: 1 for collinear shapes (modal_assurance_criterion
/// for matrices of shapes).
inline double modal_assurance(const Eigen::VectorXcd& a, const Eigen::VectorXcd& b) {
    detail::require_shape("a", a);
    detail::require_shape("b", b);
    detail::require(a.size() == b.size(), "the shapes must have equal length, got ", a.size(), " and ", b.size());
    Eigen::VectorXd z(4 * a.size());
    z << detail::realify(a), detail::realify(b);
    return detail::mac_derivatives(z, nullptr, nullptr);
}

/// MAC with its std from the joint covariance `joint` (4l x 4l) of [Re a; Im a; Re b; Im b]: for
/// two modes of one identification, whose shapes share the data, the off-diagonal blocks are
/// their cross-covariance V_a V_b^T (Modes::mode_shape_factor).
inline IndicatorStatistics modal_assurance_statistics(const Eigen::VectorXcd& a, const Eigen::VectorXcd& b,
                                                      const Eigen::MatrixXd& joint) {
    detail::require_shape("a", a);
    detail::require_shape("b", b);
    const Index l = a.size();
    detail::require(b.size() == l, "the shapes must have equal length, got ", l, " and ", b.size());
    detail::require(joint.rows() == 4 * l && joint.cols() == 4 * l, "joint must be the ", 4 * l, " x ", 4 * l,
                    " covariance of [Re a; Im a; Re b; Im b], got ", joint.rows(), " x ", joint.cols());
    detail::require(joint.allFinite(), "joint must be finite");
    // relative: a covariance formed as V V^T is symmetric to rounding, whatever its scale
    detail::require((joint - joint.transpose()).cwiseAbs().maxCoeff() <= 1e-10 * joint.cwiseAbs().maxCoeff(),
                    "joint must be symmetric");
    return detail::mac_statistics(a, b, joint);
}

/// MAC with its std, for shapes estimated independently (two records, two setups, or an
/// estimate against a fixed reference: pass a zero covariance for that one). For two modes of
/// one identification, which are correlated, use the overload with their joint covariance.
inline IndicatorStatistics modal_assurance_statistics(const Eigen::VectorXcd& a, const Eigen::MatrixXd& cov_a,
                                                      const Eigen::VectorXcd& b, const Eigen::MatrixXd& cov_b) {
    detail::require_shape("a", a);
    detail::require_shape("b", b);
    const Index l = a.size();
    detail::require(b.size() == l, "the shapes must have equal length, got ", l, " and ", b.size());
    detail::require_shape_covariance("cov_a", cov_a, l);
    detail::require_shape_covariance("cov_b", cov_b, l);
    Eigen::MatrixXd joint = Eigen::MatrixXd::Zero(4 * l, 4 * l);
    joint.topLeftCorner(2 * l, 2 * l) = cov_a;
    joint.bottomRightCorner(2 * l, 2 * l) = cov_b;
    return detail::mac_statistics(a, b, joint);
}

/// Mean phase deviation (Reynders et al. 2012) in degrees: the |shape|-weighted mean angle between
/// each component and the shape's principal phase line; 0 for a real shape, up to 90.
/// @param cov  optional 2l x 2l covariance of [Re shape; Im shape]; empty gives std = NaN
inline IndicatorStatistics mean_phase_deviation(const Eigen::VectorXcd& shape, const Eigen::MatrixXd& cov = {}) {
    detail::require_shape("shape", shape);
    const Index l = shape.size();
    const bool with_std = cov.size() > 0;
    if (with_std) detail::require_shape_covariance("cov", cov, l);
    const Eigen::VectorXd x = shape.real(), y = shape.imag();
    const double sxx = x.squaredNorm(), syy = y.squaredNorm(), sxy = x.dot(y);
    // principal axis of the points (x_o, y_o): theta = atan2(2 Sxy, Sxx - Syy) / 2
    const double u = sxx - syy, w = 2.0 * sxy, r2 = u * u + w * w;
    const double theta = 0.5 * std::atan2(w, u);
    const double c = std::cos(theta), s = std::sin(theta);
    double sum_w = 0.0, sum_wd = 0.0;
    Eigen::VectorXd psi = Eigen::VectorXd::Zero(l), mag = Eigen::VectorXd::Zero(l);
    for (Index o = 0; o < l; ++o) {
        mag(o) = std::abs(shape(o));
        if (mag(o) == 0.0) continue;
        double a = std::atan2(-x(o) * s + y(o) * c, x(o) * c + y(o) * s);  // signed, (-pi, pi]
        if (a > 0.5 * detail::pi) a -= detail::pi;                                      // fold onto the line
        if (a <= -0.5 * detail::pi) a += detail::pi;
        psi(o) = a;
        sum_w += mag(o);
        sum_wd += mag(o) * std::abs(a);
    }
    IndicatorStatistics out;
    const double mpd = sum_wd / sum_w;
    out.value = mpd * 180.0 / detail::pi;
    if (!with_std || !(r2 > 0.0)) return out;  // a circular shape has no principal line
    // gradient in z = [x; y]: dtheta = (u dw - w du) / (2 r2), du = 2x dx - 2y dy, dw = 2(y dx + x dy)
    Eigen::VectorXd dtheta(2 * l);
    dtheta << (u * 2.0 * y - w * 2.0 * x) / (2.0 * r2), (u * 2.0 * x + w * 2.0 * y) / (2.0 * r2);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(2 * l);
    for (Index o = 0; o < l; ++o) {
        if (mag(o) == 0.0) continue;
        const double m2 = mag(o) * mag(o), sg = psi(o) >= 0.0 ? 1.0 : -1.0;
        // d|psi_o| = sign (x dy - y dx) / |phi_o|^2 - sign dtheta;  d|phi_o| = (x dx + y dy) / |phi_o|
        Eigen::VectorXd dd = -sg * dtheta;
        dd(o) += -sg * y(o) / m2;
        dd(l + o) += sg * x(o) / m2;
        g += mag(o) * dd;
        g(o) += (std::abs(psi(o)) - mpd) * x(o) / mag(o);
        g(l + o) += (std::abs(psi(o)) - mpd) * y(o) / mag(o);
    }
    g /= sum_w;
    out.std = std::sqrt(std::max(g.dot(cov * g), 0.0)) * 180.0 / detail::pi;
    return out;
}

}  // namespace modaluq
