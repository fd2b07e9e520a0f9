// modal.hpp: frequencies, damping ratios and normalised shapes of (A, C), against values
// computed by hand from chosen continuous-time poles.
#include <doctest/doctest.h>

#include <modaluq/modal.hpp>

#include <cmath>
#include <complex>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_modal {

namespace {

// A real 2 x 2 block with eigenvalues exp(mu dt), mu = -xi w + i w sqrt(1 - xi^2), w = 2 pi f.
Eigen::Matrix2d rotation_block(double f, double xi, double fs) {
    const double w = 2.0 * modaluq::detail::pi * f;
    const std::complex<double> lambda = std::exp(std::complex<double>(-xi * w, w * std::sqrt(1.0 - xi * xi)) / fs);
    Eigen::Matrix2d b;
    b << lambda.real(), -lambda.imag(), lambda.imag(), lambda.real();
    return b;
}

}  // namespace

TEST_CASE("modes of a block-diagonal A are the chosen poles, sorted by frequency") {
    const double fs = 50.0;
    modaluq::StateSpace ss;
    ss.A = Eigen::MatrixXd::Zero(4, 4);
    ss.A.block<2, 2>(0, 0) = rotation_block(7.5, 0.03, fs);  // the higher mode first: sorting is checked
    ss.A.block<2, 2>(2, 2) = rotation_block(2.0, 0.01, fs);
    ss.C = Eigen::MatrixXd::Zero(2, 4);
    ss.C << 1.0, 0.0, 0.5, 0.0,
            -2.0, 0.0, 1.0, 0.0;
    modaluq::Eigenstructure eig;
    const modaluq::Modes m = modaluq::modes_from_system(ss, fs, &eig);
    REQUIRE(m.n_modes() == 2);
    CHECK(m.order == 4);
    CHECK(m.frequency_hz(0) == doctest::Approx(2.0).epsilon(1e-12));
    CHECK(m.frequency_hz(1) == doctest::Approx(7.5).epsilon(1e-12));
    CHECK(m.damping_ratio(0) == doctest::Approx(0.01).epsilon(1e-12));
    CHECK(m.damping_ratio(1) == doctest::Approx(0.03).epsilon(1e-12));
    // shapes: largest-modulus component exactly 1, the others in the ratio C gives (real here)
    CHECK(m.reference_component(0) == 1);               // mode 2 Hz: C column 2 is (0.5, 1)
    CHECK(std::abs(m.mode_shape(1, 0) - 1.0) == 0.0);
    CHECK(std::abs(m.mode_shape(0, 0) - 0.5) < 1e-12);
    CHECK(m.reference_component(1) == 1);               // mode 7.5 Hz: C column 0 is (1, -2)
    CHECK(std::abs(m.mode_shape(0, 1) + 0.5) < 1e-12);
    // the eigenstructure kept for the uncertainty decomposes A
    const Eigen::MatrixXcd a = eig.right * eig.values.asDiagonal() * eig.left_h;
    CHECK((a.real() - ss.A).norm() < 1e-12);
    CHECK(eig.kept.size() == 2u);
}

TEST_CASE("a real eigenvalue is no mode, and a non-finite A is a numerical error") {
    modaluq::StateSpace ss;
    ss.A = Eigen::MatrixXd::Zero(3, 3);
    ss.A.block<2, 2>(0, 0) = rotation_block(4.0, 0.02, 40.0);
    ss.A(2, 2) = 0.5;  // a real pole: no oscillation, dropped
    ss.C = Eigen::MatrixXd::Identity(1, 3);
    CHECK(modaluq::modes_from_system(ss, 40.0).n_modes() == 1);
    ss.A(0, 1) = std::nan("");
    CHECK_THROWS_AS(modaluq::modes_from_system(ss, 40.0), modaluq::numerical_error);
}

}  // namespace test_modal
