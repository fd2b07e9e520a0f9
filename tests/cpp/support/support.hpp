#pragma once
// Test-only helpers: a small exact simulator, the naive covariance definition (explicit data
// matrices) and the explicit full uncertainty path (Kronecker Jacobians, Sigma_H formed),
// against which the efficient production code is checked.

#include "../eigen_instances.hpp"

#include <modaluq/modaluq.hpp>

#include "reference_stages.hpp"
#include <unsupported/Eigen/MatrixFunctions>

#include <random>
#include <vector>

namespace support {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::MatrixXcd;
using Eigen::VectorXd;
using cd = std::complex<double>;

struct Sim {
    MatrixXd y, u;   // channels x samples
    double fs = 0;
    VectorXd f_true; // undamped natural frequencies, Hz (modal damping: |mu| = omega_n)
};

// Chain ground-k-m-k-m..., unit masses, alternating stiffness, modal damping xi; ZOH.
// Outputs: accelerations (or displacements) at out_dofs. Forces: known white force at dof 0
// (std input_std) when with_input, unknown white forces at all dofs (std unknown_std).
// Free decay from a random state when free_decay (no forces at all).
inline Sim simulate(int n_dof, std::vector<int> out_dofs, Index n_samples, unsigned seed, bool with_input,
                    double unknown_std, double noise_rel, double fs = 20.0, bool free_decay = false,
                    double input_std = 1.0, double xi = 0.02, bool displacement = false) {
    const int nd = n_dof;
    MatrixXd M = MatrixXd::Identity(nd, nd), K = MatrixXd::Zero(nd, nd);
    for (int i = 0; i < nd; ++i) {
        const double k = (i % 2 == 0) ? 100.0 : 200.0;
        K(i, i) += k;
        if (i > 0) { K(i - 1, i - 1) += k; K(i - 1, i) -= k; K(i, i - 1) -= k; }
    }
    Eigen::SelfAdjointEigenSolver<MatrixXd> es(K);  // M = I
    const VectorXd w = es.eigenvalues().cwiseSqrt();
    const MatrixXd Phi = es.eigenvectors();
    const MatrixXd Cd = Phi * (2.0 * xi * w).asDiagonal() * Phi.transpose();
    MatrixXd Ac = MatrixXd::Zero(2 * nd, 2 * nd), Bc = MatrixXd::Zero(2 * nd, nd);
    Ac.topRightCorner(nd, nd) = MatrixXd::Identity(nd, nd);
    Ac.bottomLeftCorner(nd, nd) = -K;
    Ac.bottomRightCorner(nd, nd) = -Cd;
    Bc.bottomRows(nd) = MatrixXd::Identity(nd, nd);
    const double tau = 1.0 / fs;
    MatrixXd aug = MatrixXd::Zero(3 * nd, 3 * nd);
    aug.topLeftCorner(2 * nd, 2 * nd) = Ac * tau;
    aug.topRightCorner(2 * nd, nd) = Bc * tau;
    const MatrixXd E = aug.exp();
    const MatrixXd Ad = E.topLeftCorner(2 * nd, 2 * nd), Bd = E.topRightCorner(2 * nd, nd);
    const int l = static_cast<int>(out_dofs.size());
    MatrixXd C(l, 2 * nd), D = MatrixXd::Zero(l, nd);
    for (int o = 0; o < l; ++o) {
        if (displacement) {
            C.row(o).setZero();
            C(o, out_dofs[o]) = 1.0;
        } else {
            C.row(o) << -K.row(out_dofs[o]), -Cd.row(out_dofs[o]);
            D(o, out_dofs[o]) = 1.0;
        }
    }
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> g(0.0, 1.0);
    const Index burn = free_decay ? 0 : 2000;
    Sim s;
    s.fs = fs;
    s.f_true = w / (2.0 * modaluq::detail::pi);
    s.y.resize(l, n_samples);
    if (with_input) s.u.resize(1, n_samples);
    VectorXd x = VectorXd::Zero(2 * nd), f(nd);
    if (free_decay) for (Index i = 0; i < 2 * nd; ++i) x(i) = g(rng);
    for (Index t = -burn; t < n_samples; ++t) {
        f.setZero();
        double known = 0.0;
        if (!free_decay) {
            for (int i = 0; i < nd; ++i) f(i) = unknown_std * g(rng);
            if (with_input) { known = input_std * g(rng); f(0) += known; }
        }
        if (t >= 0) {
            s.y.col(t) = C * x + D * f;
            if (with_input) s.u(0, t) = known;
        }
        x = Ad * x + Bd * f;
    }
    if (noise_rel > 0)
        for (int o = 0; o < l; ++o) {
            const VectorXd row = s.y.row(o).transpose();
            const double sd = std::sqrt((row.array() - row.mean()).square().mean());
            for (Index t = 0; t < n_samples; ++t) s.y(o, t) += noise_rel * sd * g(rng);
        }
    return s;
}

// Naive covariances straight from conventions.md: explicit data matrices.
struct Naive {
    MatrixXd R1, R2, R3, R4;
    std::vector<MatrixXd> b1, b2, b3, b4;
};
inline Naive naive_covariances(MatrixXd y, MatrixXd u, const modaluq::HankelLayout& L, Index n_blocks, bool demean) {
    if (demean) {
        y.colwise() -= y.rowwise().mean();
        if (u.size()) u.colwise() -= u.rowwise().mean();
    }
    const Index p = L.p(), q = L.q(), l = y.rows(), m = u.size() ? u.rows() : 0, r = L.n_references();
    const Index N = y.cols() - p - q + 1;
    MatrixXd Yp(p * l, N), Ym(q * r, N), Up(p * m, N);
    for (Index c = 0; c < N; ++c) {
        for (Index i = 0; i < p; ++i) Yp.block(i * l, c, l, 1) = y.col(q + i + c);
        for (Index j = 0; j < q; ++j)
            for (Index jr = 0; jr < r; ++jr) Ym(j * r + jr, c) = y(L.reference(jr), j + c);
        for (Index i = 0; i < p && m; ++i) Up.block(i * m, c, m, 1) = u.col(q + i + c);
    }
    Naive nv;
    nv.R1 = Yp * Ym.transpose() / double(N);
    if (m) {
        nv.R2 = Yp * Up.transpose() / double(N);
        nv.R3 = Up * Up.transpose() / double(N);
        nv.R4 = Ym * Up.transpose() / double(N);
    }
    const Index Nb = N / n_blocks;
    for (Index k = 0; k < n_blocks; ++k) {
        const auto yp = Yp.middleCols(k * Nb, Nb), ym = Ym.middleCols(k * Nb, Nb);
        nv.b1.push_back(yp * ym.transpose() / double(Nb));
        if (m) {
            const auto up = Up.middleCols(k * Nb, Nb);
            nv.b2.push_back(yp * up.transpose() / double(Nb));
            nv.b3.push_back(up * up.transpose() / double(Nb));
            nv.b4.push_back(ym * up.transpose() / double(Nb));
        }
    }
    return nv;
}

/// IdentifyOptions with the settings the tests vary.
inline modaluq::IdentifyOptions options(double fs, Index p, Index q, std::vector<Index> orders, bool unc = false,
                                        Index nb = 10) {
    modaluq::IdentifyOptions o;
    o.fs = fs;
    o.block_rows = p;
    o.past_block_rows = q;
    o.orders = std::move(orders);
    o.uncertainty = unc;
    o.n_blocks = nb;
    return o;
}

inline double rel(const MatrixXd& a, const MatrixXd& b) { return (a - b).norm() / std::max(b.norm(), 1e-300); }

/// Mode i's rows [u_f; u_xi] of Modes::frequency_damping_factor as a 2 x n_b matrix.
inline MatrixXd factor_rows(const modaluq::Modes& m, Index i) {
    const Index nb = m.frequency_damping_factor.rows() / 2;
    MatrixXd u(2, nb);
    u.row(0) = m.frequency_damping_factor.col(i).head(nb).transpose();
    u.row(1) = m.frequency_damping_factor.col(i).tail(nb).transpose();
    return u;
}

/// max |U U^T - [f, xi] block of mode i's covariance| over sqrt(var f var xi): how far the factor
/// rows are from reproducing the covariance they were reduced to.
inline double factor_rows_covariance_error(const modaluq::Modes& m, Index i) {
    const Index np = 2 + 2 * m.mode_shape.rows();
    const Eigen::Map<const MatrixXd> cov(m.covariance.col(i).data(), np, np);
    const MatrixXd u = factor_rows(m, i);
    return (u * u.transpose() - cov.topLeftCorner(2, 2)).cwiseAbs().maxCoeff() / std::sqrt(cov(0, 0) * cov(1, 1));
}

/// Mode i's shape factor V (2l x n_b) of Modes::mode_shape_factor.
inline MatrixXd shape_factor(const modaluq::Modes& m, Index i) {
    const Index l2 = 2 * m.mode_shape.rows();
    return Eigen::Map<const MatrixXd>(m.mode_shape_factor.col(i).data(), l2, m.mode_shape_factor.rows() / l2);
}

/// max |V V^T - shape block of mode i's covariance| over that block's largest entry.
inline double shape_factor_covariance_error(const modaluq::Modes& m, Index i) {
    const Index l = m.mode_shape.rows(), np = 2 + 2 * l;
    const Eigen::Map<const MatrixXd> cov(m.covariance.col(i).data(), np, np);
    const MatrixXd v = shape_factor(m, i), block = cov.bottomRightCorner(2 * l, 2 * l);
    return (v * v.transpose() - block).cwiseAbs().maxCoeff() / std::max(block.cwiseAbs().maxCoeff(), 1e-300);
}

inline MatrixXd kron(const MatrixXd& A, const MatrixXd& B) {
    MatrixXd K(A.rows() * B.rows(), A.cols() * B.cols());
    for (Index i = 0; i < A.rows(); ++i)
        for (Index j = 0; j < A.cols(); ++j) K.block(i * B.rows(), j * B.cols(), B.rows(), B.cols()) = A(i, j) * B;
    return K;
}
inline MatrixXcd kronc(const MatrixXcd& A, const MatrixXcd& B) {
    MatrixXcd K(A.rows() * B.rows(), A.cols() * B.cols());
    for (Index i = 0; i < A.rows(); ++i)
        for (Index j = 0; j < A.cols(); ++j) K.block(i * B.rows(), j * B.cols(), B.rows(), B.cols()) = A(i, j) * B;
    return K;
}
// P_{m,n} vec(X) = vec(X^T), X m x n.
inline MatrixXd commutation(Index m, Index n) {
    MatrixXd P = MatrixXd::Zero(m * n, m * n);
    for (Index i = 0; i < m; ++i)
        for (Index j = 0; j < n; ++j) P(i * n + j, j * m + i) = 1.0;
    return P;
}
// Pseudo-inverse dropping exactly the `drop` smallest singular values.
template <class Mat>
Mat pinv_drop(const Mat& A, Index drop) {
    Eigen::JacobiSVD<Mat> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
    auto s = svd.singularValues();
    Eigen::VectorXd inv = Eigen::VectorXd::Zero(s.size());
    for (Index i = 0; i < s.size() - drop; ++i) inv(i) = 1.0 / s(i);
    return svd.matrixV() * inv.cast<typename Mat::Scalar>().asDiagonal() * svd.matrixU().adjoint();
}

// Explicit J_{H,R} (docs/uq-math.md §4.2); output-only: identity.
inline MatrixXd jacobian_H_R(const modaluq::Covariances& c, const modaluq::SubspaceMatrix& s) {
    const Index a = c.layout.rows_future(), b = c.layout.rows_past(), pm = c.layout.rows_input();
    const Index h = a * b;
    if (!c.has_inputs()) return MatrixXd::Identity(h, h);
    const MatrixXd& G = s.input_gain;     // a x pm
    const MatrixXd& Mt = s.input_transfer; // pm x b
    MatrixXd J(h, c.layout.n_covariance_entries());
    J.leftCols(h) = MatrixXd::Identity(h, h);
    J.middleCols(h, a * pm) = -kron(Mt.transpose(), MatrixXd::Identity(a, a));
    J.middleCols(h + a * pm, pm * pm) = kron(Mt.transpose(), G);
    J.rightCols(b * pm) = -kron(MatrixXd::Identity(b, b), G) * commutation(b, pm);
    return J;
}

// Explicit J_{Gamma,H} (a n x h) via B_j^+ C_j (docs/uq-math.md §5.2).
// frozen_from = k*: columns j >= k* keep only the scale term (docs/uq-math.md §5.5, eq. 5.13).
inline MatrixXd jacobian_Gamma_H(const modaluq::Realization& re, const MatrixXd& H, Index n,
                                 Index frozen_from = std::numeric_limits<Index>::max()) {
    const Index a = H.rows(), b = H.cols(), h = a * b;
    MatrixXd J(a * n, h);
    const MatrixXd Ia = MatrixXd::Identity(a, a), Ib = MatrixXd::Identity(b, b);
    for (Index j = 0; j < n; ++j) {
        const double s = re.singular_values()(j);
        const VectorXd u = re.U().col(j), v = re.V().col(j);
        MatrixXd B(a + b, a + b);
        B << Ia, -H / s, -H.transpose() / s, Ib;
        MatrixXd Cj(a + b, h);
        Cj.topRows(a) = kron(v.transpose(), Ia - u * u.transpose()) / s;
        Cj.bottomRows(b) = kron(u.transpose(), Ib - v * v.transpose()) * commutation(a, b) / s;
        const MatrixXd sol = pinv_drop<MatrixXd>(B, 1) * Cj;
        J.middleRows(j * a, a) = u * kron(v, u).transpose() / (2.0 * std::sqrt(s));
        if (j < frozen_from) J.middleRows(j * a, a) += std::sqrt(s) * sol.topRows(a);
    }
    return J;
}

// Explicit [J_A; J_C] (n^2 + l n) x (a n) with the least-squares residual term (docs/uq-math.md §6).
inline MatrixXd jacobian_AC_Gamma(const MatrixXd& Gamma, Index l) {
    const Index a = Gamma.rows(), n = Gamma.cols();
    const MatrixXd Gup = Gamma.topRows(a - l), Gdw = Gamma.bottomRows(a - l);
    const MatrixXd W = (Gup.transpose() * Gup).inverse();
    const MatrixXd A = W * Gup.transpose() * Gdw;
    const MatrixXd E = Gdw - Gup * A;
    MatrixXd S1 = MatrixXd::Zero(a - l, a), S2 = MatrixXd::Zero(a - l, a);
    S1.leftCols(a - l) = MatrixXd::Identity(a - l, a - l);
    S2.rightCols(a - l) = MatrixXd::Identity(a - l, a - l);
    const MatrixXd In = MatrixXd::Identity(n, n);
    MatrixXd J(n * n + l * n, a * n);
    J.topRows(n * n) = kron(In, W) * (kron(In, Gup.transpose() * S2) - kron(A.transpose(), Gup.transpose() * S1) +
                                      kron(E.transpose() * S1, In) * commutation(a, n));
    MatrixXd sel = MatrixXd::Zero(l, a);
    sel.leftCols(l) = MatrixXd::Identity(l, l);
    J.bottomRows(l * n) = kron(In, sel);
    return J;
}

// Explicit J_theta,(A,C) for each reported mode: rows [f, xi, Re shape, Im shape] (docs/uq-math.md §7).
inline std::vector<MatrixXd> jacobian_theta_AC(const modaluq::StateSpace& ss, double fs, const modaluq::Modes& md) {
    const Index n = ss.A.rows(), l = ss.C.rows();
    Eigen::EigenSolver<MatrixXd> es(ss.A);
    const MatrixXcd V = es.eigenvectors(), Vi = V.inverse();
    std::vector<MatrixXd> out;
    for (Index i = 0; i < md.n_modes(); ++i) {
        Index ki = 0;
        (es.eigenvalues().array() - md.eigenvalue(i)).abs().minCoeff(&ki);
        const cd lam = es.eigenvalues()(ki);
        const Eigen::VectorXcd phi = V.col(ki);
        const Eigen::RowVectorXcd chi_h = Vi.row(ki);
        const cd den = (chi_h * phi)(0, 0);
        const MatrixXcd Jl = kronc(phi.transpose(), chi_h) / den;  // 1 x n^2
        const double tau = 1.0 / fs;
        Eigen::Matrix2d Jmu;
        Jmu << lam.real(), lam.imag(), -lam.imag(), lam.real();
        Jmu /= tau * std::norm(lam);
        const cd mu = std::log(lam) * fs;
        const double am = std::abs(mu);
        Eigen::Matrix2d Jfx;
        Jfx << mu.real() / (2 * modaluq::detail::pi * am), mu.imag() / (2 * modaluq::detail::pi * am),
            -mu.imag() * mu.imag() / (am * am * am), mu.real() * mu.imag() / (am * am * am);
        MatrixXd Jre(2, n * n);
        Jre << Jl.real(), Jl.imag();
        MatrixXd J = MatrixXd::Zero(2 + 2 * l, n * n + l * n);
        J.topLeftCorner(2, n * n) = Jfx * Jmu * Jre;
        const MatrixXcd In = MatrixXcd::Identity(n, n);
        const MatrixXcd Jphi = pinv_drop<MatrixXcd>(lam * In - ss.A.cast<cd>(), 1) * (In - phi * chi_h / den) *
                               kronc(phi.transpose(), In);
        MatrixXcd Jsh(l, n * n + l * n);
        Jsh.leftCols(n * n) = ss.C.cast<cd>() * Jphi;
        Jsh.rightCols(l * n) = kronc(phi.transpose(), MatrixXcd::Identity(l, l));
        const Eigen::VectorXcd raw = ss.C.cast<cd>() * phi;
        const Index k = md.reference_component(i);
        MatrixXcd Nrm = MatrixXcd::Identity(l, l);
        Nrm.col(k) -= raw / raw(k);
        const MatrixXcd Jn = Nrm * Jsh / raw(k);
        J.middleRows(2, l) = Jn.real();
        J.middleRows(2 + l, l) = Jn.imag();
        out.push_back(J);
    }
    return out;
}

// Explicit full path: covariance of theta per mode at order n (Sigma_R, Sigma_H, Sigma_Gamma formed).
inline std::vector<MatrixXd> explicit_covariances(const modaluq::Covariances& c, double fs, Index n,
                                                  Index frozen_from = std::numeric_limits<Index>::max()) {
    const modaluq::SubspaceMatrix s = modaluq::subspace_matrix(c);
    const modaluq::Realization re(s.H, c.layout.n_outputs, n);
    const MatrixXd TR = c.covariance_factor();
    const MatrixXd SigmaR = TR * TR.transpose();
    const MatrixXd JHR = jacobian_H_R(c, s);
    const MatrixXd SigmaH = JHR * SigmaR * JHR.transpose();
    const MatrixXd JG = jacobian_Gamma_H(re, s.H, n, frozen_from);
    const MatrixXd SigmaG = JG * SigmaH * JG.transpose();
    const MatrixXd JAC = jacobian_AC_Gamma(re.observability().leftCols(n), c.layout.n_outputs);
    const MatrixXd SigmaAC = JAC * SigmaG * JAC.transpose();
    const modaluq::StateSpace ss = re.system(n);
    const modaluq::Modes md = modaluq::modes_from_system(ss, fs);
    std::vector<MatrixXd> covs;
    for (const MatrixXd& J : jacobian_theta_AC(ss, fs, md)) covs.push_back(J * SigmaAC * J.transpose());
    return covs;
}

}  // namespace support
