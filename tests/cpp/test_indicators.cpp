// indicators.hpp: MPC, MPD and MAC with their std. Values against shapes whose indicators are
// known by hand; gradients and Hessians against central differences; the second-order moments
// at the maximum against a Monte Carlo of Gaussian perturbations drawn here.
#include "eigen_instances.hpp"

#include <doctest/doctest.h>

#include <modaluq/indicators.hpp>

#include <cmath>
#include <complex>
#include <random>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_indicators {

namespace {

using modaluq::Index;
using cd = std::complex<double>;

Eigen::VectorXcd random_shape(Index l, unsigned seed, double imag_scale) {
    std::mt19937_64 g(seed);
    std::normal_distribution<double> nd;
    Eigen::VectorXcd phi(l);
    for (Index i = 0; i < l; ++i) phi(i) = cd(nd(g), imag_scale * nd(g));
    return phi;
}

// Central differences of a scalar function of z: gradient, and the Hessian from differences of
// the analytic gradient (so the Hessian check does not depend on a second difference).
template <class F>
Eigen::VectorXd fd_gradient(F f, const Eigen::VectorXd& z, double h) {
    Eigen::VectorXd g(z.size());
    for (Index i = 0; i < z.size(); ++i) {
        Eigen::VectorXd zp = z, zm = z;
        zp(i) += h;
        zm(i) -= h;
        g(i) = (f(zp, nullptr) - f(zm, nullptr)) / (2 * h);
    }
    return g;
}

template <class F>
Eigen::MatrixXd fd_hessian(F f, const Eigen::VectorXd& z, double h) {
    Eigen::MatrixXd hess(z.size(), z.size());
    for (Index i = 0; i < z.size(); ++i) {
        Eigen::VectorXd zp = z, zm = z, gp, gm;
        zp(i) += h;
        zm(i) -= h;
        f(zp, &gp);
        f(zm, &gm);
        hess.col(i) = (gp - gm) / (2 * h);
    }
    return hess;
}

}  // namespace

TEST_CASE("MPC, MPD and MAC of shapes whose values are known") {
    Eigen::VectorXcd real(3), circular(2);
    real << 1.0, -0.5, 0.25;
    circular << cd(1, 0), cd(0, 1);
    const cd rot = std::polar(2.0, 0.7);  // a complex scale changes none of them
    CHECK(modaluq::modal_phase_collinearity(real) == doctest::Approx(1.0).epsilon(1e-14));
    CHECK(modaluq::modal_phase_collinearity(Eigen::VectorXcd(rot * real)) == doctest::Approx(1.0).epsilon(1e-14));
    CHECK(modaluq::modal_phase_collinearity(circular) == doctest::Approx(0.0).epsilon(1e-14));
    CHECK(modaluq::mean_phase_deviation(Eigen::VectorXcd(rot * real)).value == doctest::Approx(0.0).scale(1.0).epsilon(1e-10));
    // two components 90 degrees apart, equal moduli: principal line at 45 degrees, both 45 degrees off
    CHECK(modaluq::mean_phase_deviation(circular).value == doctest::Approx(45.0).epsilon(1e-12));
    // components at +-20 degrees around the real axis: MPD 20
    Eigen::VectorXcd fan(2);
    fan << std::polar(1.0, 20.0 * modaluq::detail::pi / 180), std::polar(1.0, -20.0 * modaluq::detail::pi / 180);
    CHECK(modaluq::mean_phase_deviation(fan).value == doctest::Approx(20.0).epsilon(1e-12));
    CHECK(modaluq::modal_assurance(real, Eigen::VectorXcd(rot * real)) == doctest::Approx(1.0).epsilon(1e-14));
    Eigen::VectorXcd a(2), b(2);
    a << 1.0, 0.0;
    b << 1.0, 1.0;
    CHECK(modaluq::modal_assurance(a, b) == doctest::Approx(0.5).epsilon(1e-14));
}

TEST_CASE("MPC and MAC gradients and Hessians equal central differences") {
    for (unsigned seed : {1u, 2u, 3u}) {
        const Eigen::VectorXcd a = random_shape(5, seed, 0.4), b = random_shape(5, seed + 10, 0.3);
        const Eigen::VectorXd za = modaluq::detail::realify(a);
        Eigen::VectorXd zab(20);
        zab << za, modaluq::detail::realify(b);
        auto mpc = [](const Eigen::VectorXd& z, Eigen::VectorXd* g) {
            Eigen::MatrixXd h;
            return modaluq::detail::mpc_derivatives(z, g, g ? &h : nullptr);
        };
        auto mac = [](const Eigen::VectorXd& z, Eigen::VectorXd* g) {
            Eigen::MatrixXd h;
            return modaluq::detail::mac_derivatives(z, g, g ? &h : nullptr);
        };
        for (auto [f, z] : {std::pair<double (*)(const Eigen::VectorXd&, Eigen::VectorXd*), Eigen::VectorXd>{+mpc, za},
                            {+mac, zab}}) {
            Eigen::VectorXd g;
            Eigen::MatrixXd h;
            if (z.size() == za.size())
                modaluq::detail::mpc_derivatives(z, &g, &h);
            else
                modaluq::detail::mac_derivatives(z, &g, &h);
            const Eigen::VectorXd g_fd = fd_gradient(f, z, 1e-6);
            const Eigen::MatrixXd h_fd = fd_hessian(f, z, 1e-6);
            CHECK((g - g_fd).norm() <= 1e-7 * (1.0 + g.norm()));
            CHECK((h - h_fd).norm() <= 1e-6 * (1.0 + h.norm()));
            CHECK((h - h.transpose()).norm() <= 1e-12 * (1.0 + h.norm()));
        }
    }
}

TEST_CASE("MPD's first-order std is the norm of its gradient, checked component by component") {
    const Eigen::VectorXcd phi = random_shape(6, 7, 0.3);
    const Index l = phi.size();
    const double h = 1e-7;
    for (Index i = 0; i < 2 * l; ++i) {
        Eigen::VectorXcd p = phi, m = phi;
        const cd step = i < l ? cd(h, 0) : cd(0, h);
        p(i % l) += step;
        m(i % l) -= step;
        const double d = (modaluq::mean_phase_deviation(p).value - modaluq::mean_phase_deviation(m).value) / (2 * h);
        Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(2 * l, 2 * l);
        cov(i, i) = 1.0;
        CHECK(modaluq::mean_phase_deviation(phi, cov).std == doctest::Approx(std::abs(d)).epsilon(1e-5));
    }
}

TEST_CASE("second-order moments of MAC and MPC at their maximum equal a Monte Carlo") {
    // Independent check: draw Gaussian perturbations of known covariance around a real shape and
    // around the shape itself (MAC of two estimates of one mode), and compare the mean and std of
    // the loss 1 - q with loss_at_maximum_mean/std and with std (at the truth, g = 0).
    const Index l = 6;
    const Eigen::VectorXcd phi = random_shape(l, 11, 0.0);
    std::mt19937_64 g(5);
    std::normal_distribution<double> nd;
    Eigen::MatrixXd f = Eigen::MatrixXd::Zero(2 * l, 2 * l);  // cov = f f'
    for (Index i = 0; i < 2 * l; ++i)
        for (Index j = 0; j <= i; ++j) f(i, j) = 0.01 * nd(g);
    const Eigen::MatrixXd cov = f * f.transpose();
    const auto mpc = modaluq::modal_phase_collinearity_statistics(phi, cov);
    const auto mac = modaluq::modal_assurance_statistics(phi, cov, phi, cov);
    const int n = 40000;
    double s_mpc = 0, ss_mpc = 0, s_mac = 0, ss_mac = 0;
    for (int k = 0; k < n; ++k) {
        Eigen::VectorXd e1(2 * l), e2(2 * l);
        for (Index i = 0; i < 2 * l; ++i) {
            e1(i) = nd(g);
            e2(i) = nd(g);
        }
        const Eigen::VectorXd d1 = f * e1, d2 = f * e2;
        Eigen::VectorXcd p1 = phi, p2 = phi;
        p1.real() += d1.head(l);
        p1.imag() += d1.tail(l);
        p2.real() += d2.head(l);
        p2.imag() += d2.tail(l);
        const double lm = 1.0 - modaluq::modal_phase_collinearity(p1), la = 1.0 - modaluq::modal_assurance(p1, p2);
        s_mpc += lm;
        ss_mpc += lm * lm;
        s_mac += la;
        ss_mac += la * la;
    }
    const double m_mpc = s_mpc / n, sd_mpc = std::sqrt(ss_mpc / n - m_mpc * m_mpc);
    const double m_mac = s_mac / n, sd_mac = std::sqrt(ss_mac / n - m_mac * m_mac);
    CHECK(mpc.value == doctest::Approx(1.0));
    CHECK(mpc.loss_at_maximum_mean == doctest::Approx(m_mpc).epsilon(0.03));
    CHECK(mpc.loss_at_maximum_std == doctest::Approx(sd_mpc).epsilon(0.05));
    CHECK(mpc.std == doctest::Approx(sd_mpc).epsilon(0.05));  // g = 0 at the truth
    CHECK(mac.loss_at_maximum_mean == doctest::Approx(m_mac).epsilon(0.03));
    CHECK(mac.loss_at_maximum_std == doctest::Approx(sd_mac).epsilon(0.05));
    CHECK(mac.std == doctest::Approx(sd_mac).epsilon(0.05));
}

TEST_CASE("the std of a MAC with correlated shapes (a joint covariance) equals a Monte Carlo") {
    // Two modes of one identification: the errors of both shapes come from one factor F (4l x k),
    // so the joint covariance F F^T has off-diagonal blocks. Checked near the maximum (two
    // estimates of one mode, second order) and far from it (two modes, first order).
    const Index l = 5, k = 12;
    std::mt19937_64 g(9);
    std::normal_distribution<double> nd;
    Eigen::MatrixXd f(4 * l, k);  // b's errors mostly follow a's: a strong cross term
    for (Index i = 0; i < f.size(); ++i) f(i) = 0.01 * nd(g);
    f.bottomRows(2 * l) = 0.9 * f.topRows(2 * l) + 0.3 * f.bottomRows(2 * l);
    const Eigen::MatrixXd joint = f * f.transpose();
    const Eigen::VectorXcd a = random_shape(l, 31, 0.0);
    for (const Eigen::VectorXcd& b : {Eigen::VectorXcd(a), random_shape(l, 32, 0.1)}) {
        const auto st = modaluq::modal_assurance_statistics(a, b, joint);
        // the independent overload is the joint one with the cross blocks zeroed
        Eigen::MatrixXd diag = joint;
        diag.topRightCorner(2 * l, 2 * l).setZero();
        diag.bottomLeftCorner(2 * l, 2 * l).setZero();
        const auto ind = modaluq::modal_assurance_statistics(a, joint.topLeftCorner(2 * l, 2 * l), b,
                                                             joint.bottomRightCorner(2 * l, 2 * l));
        CHECK(ind.std == modaluq::modal_assurance_statistics(a, b, diag).std);
        const int n = 40000;
        double s1 = 0, s2 = 0;
        Eigen::VectorXd e(k);
        for (int r = 0; r < n; ++r) {
            for (Index i = 0; i < k; ++i) e(i) = nd(g);
            const Eigen::VectorXd d = f * e;
            Eigen::VectorXcd pa = a, pb = b;
            pa.real() += d.segment(0, l);
            pa.imag() += d.segment(l, l);
            pb.real() += d.segment(2 * l, l);
            pb.imag() += d.segment(3 * l, l);
            const double v = modaluq::modal_assurance(pa, pb);
            s1 += v;
            s2 += v * v;
        }
        const double mean = s1 / n, sd = std::sqrt(s2 / n - mean * mean);
        CHECK(st.std == doctest::Approx(sd).epsilon(0.05));
        CAPTURE(ind.std / sd);
        // the cross term matters: 1.5x and more near the maximum, about 10 % for these two shapes
        CHECK(std::abs(ind.std / sd - 1.0) > (b == a ? 0.5 : 0.05));
    }
    // the independent overload takes the shape covariances as given, as it always did
    Eigen::MatrixXd cov_a = joint.topLeftCorner(2 * l, 2 * l);
    cov_a(0, 1) *= 1.0 + 1e-6;
    CHECK_NOTHROW(modaluq::modal_assurance_statistics(a, cov_a, a, cov_a));
    Eigen::MatrixXd asym = joint;
    asym(0, 1) += 1e-6 * joint.cwiseAbs().maxCoeff();
    CHECK_THROWS_AS(modaluq::modal_assurance_statistics(a, a, asym), modaluq::invalid_argument);
    CHECK_THROWS_AS(modaluq::modal_assurance_statistics(a, a, Eigen::MatrixXd(joint.topLeftCorner(4 * l - 1, 4 * l - 1))),
                    modaluq::invalid_argument);
}

TEST_CASE("far from the maximum, the std of MAC is the first-order one") {
    const Index l = 4;
    const Eigen::VectorXcd a = random_shape(l, 21, 0.2), b = random_shape(l, 22, 0.2);
    const Eigen::MatrixXd cov = 1e-8 * Eigen::MatrixXd::Identity(2 * l, 2 * l);
    Eigen::VectorXd z(4 * l), g;
    z << modaluq::detail::realify(a), modaluq::detail::realify(b);
    modaluq::detail::mac_derivatives(z, &g, nullptr);
    const auto s = modaluq::modal_assurance_statistics(a, cov, b, cov);
    CHECK(s.std == doctest::Approx(std::sqrt(1e-8) * g.norm()).epsilon(1e-4));
}

TEST_CASE("indicators refuse what is not a shape or its covariance") {
    Eigen::VectorXcd phi(3), zero = Eigen::VectorXcd::Zero(3), nan(3);
    phi << 1.0, 2.0, 3.0;
    nan << 1.0, std::nan(""), 3.0;
    CHECK_THROWS_AS(modaluq::modal_phase_collinearity(zero), modaluq::invalid_argument);
    CHECK_THROWS_AS(modaluq::modal_phase_collinearity(nan), modaluq::invalid_argument);
    CHECK_THROWS_AS(modaluq::modal_phase_collinearity_statistics(phi, Eigen::MatrixXd::Identity(3, 3)),
                    modaluq::invalid_argument);
    CHECK_THROWS_AS(modaluq::modal_assurance(phi, Eigen::VectorXcd::Ones(2)), modaluq::invalid_argument);
    CHECK_THROWS_AS(modaluq::mean_phase_deviation(phi, Eigen::MatrixXd::Identity(4, 4)), modaluq::invalid_argument);
}

}  // namespace test_indicators
