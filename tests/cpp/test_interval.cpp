// interval.hpp: the Student-t probability and quantile and the interval factor. The probability
// against closed forms (1 and 2 degrees of freedom), a numerical integral of the density and the
// normal limit; the quantile as its inverse; the factor's coverage against a Monte Carlo of block
// means, where x +- 1.96 sigma falls short by the amount the t law says.
#include <doctest/doctest.h>

#include <modaluq/errors.hpp>
#include <modaluq/interval.hpp>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_interval {

namespace {

constexpr double pi = 3.14159265358979323846;

// P(|T| <= t) by Simpson's rule on the density, written from its definition (not the sums).
double probability_by_quadrature(double t, std::int64_t dof) {
    const double nu = double(dof);
    const double scale = std::exp(std::lgamma(0.5 * (nu + 1)) - std::lgamma(0.5 * nu)) / std::sqrt(nu * pi);
    const int n = 20000;  // even
    const double h = t / n;
    double s = 0.0;
    for (int i = 0; i <= n; ++i) {
        const double x = i * h;
        const double w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
        s += w * scale * std::pow(1.0 + x * x / nu, -0.5 * (nu + 1));
    }
    return 2.0 * s * h / 3.0;
}

}  // namespace

TEST_CASE("student_t_probability equals closed forms, the integral of the density and the normal limit") {
    using modaluq::student_t_probability;
    for (double t : {0.0, 0.3, 1.0, 1.96, 4.0, 30.0}) {
        // 1 degree of freedom: Cauchy, 2 atan(t) / pi; 2: t / sqrt(2 + t^2)
        CHECK(student_t_probability(t, 1) == doctest::Approx(2.0 * std::atan(t) / pi).epsilon(1e-14));
        CHECK(student_t_probability(t, 2) == doctest::Approx(t / std::sqrt(2.0 + t * t)).epsilon(1e-14));
    }
    for (std::int64_t dof : {3, 4, 7, 12, 14, 24, 49}) {
        for (double t : {0.5, 1.0, 1.96, 2.5, 6.0}) {
            CHECK(std::abs(student_t_probability(t, dof) - probability_by_quadrature(t, dof)) < 1e-12);
        }
    }
    // many degrees of freedom: the normal law, P(|Z| <= t) = erf(t / sqrt 2), to O(1/dof)
    for (double t : {0.5, 1.0, 1.96, 3.0}) {
        CHECK(std::abs(student_t_probability(t, 1000000) - std::erf(t / std::sqrt(2.0))) < 1e-6);
    }
    CHECK(student_t_probability(INFINITY, 5) == 1.0);
    CHECK_THROWS_AS(student_t_probability(1.0, 0), modaluq::invalid_argument);
    CHECK_THROWS_AS(student_t_probability(-1.0, 3), modaluq::invalid_argument);
    CHECK_THROWS_AS(student_t_probability(NAN, 3), modaluq::invalid_argument);
}

TEST_CASE("student_t_quantile inverts the probability; interval_factor uses n_blocks - 1 degrees of freedom") {
    using modaluq::student_t_probability;
    using modaluq::student_t_quantile;
    // closed forms: tan(pi level / 2) at 1 degree of freedom, level sqrt(2 / (1 - level^2)) at 2
    for (double level : {0.1, 0.5, 0.9, 0.95, 0.99}) {
        CHECK(student_t_quantile(level, 1) == doctest::Approx(std::tan(pi * level / 2)).epsilon(1e-12));
        CHECK(student_t_quantile(level, 2) == doctest::Approx(level * std::sqrt(2.0 / (1 - level * level))).epsilon(1e-12));
    }
    for (std::int64_t dof : {1, 3, 5, 14, 49, 199, 1000, 1001, 5000}) {
        for (double level : {0.01, 0.5, 0.9, 0.95, 0.99, 0.999}) {
            const double t = student_t_quantile(level, dof);
            // the exact sums invert to 1e-13; above 1000 dof the quantile is the Cornish-Fisher
            // expansion, the probability still the sums
            CHECK(student_t_probability(t, dof) == doctest::Approx(level).epsilon(dof > 1000 ? 1e-11 : 1e-13));
        }
        // it falls with the degrees of freedom towards the normal 1.959964
        CHECK(student_t_quantile(0.95, dof) > student_t_quantile(0.95, dof + 1));
        CHECK(student_t_quantile(0.95, dof) > 1.959963984540054);
    }
    CHECK(student_t_quantile(0.95, 1000000) == doctest::Approx(1.959963984540054).epsilon(1e-5));
    // huge degrees of freedom return at once, at the normal limit (1.959963984540054: erfc's root)
    CHECK(student_t_quantile(0.95, 1000000000000) == doctest::Approx(1.959963984540054).epsilon(1e-12));
    CHECK(std::abs(student_t_probability(1.959963984540054, 1000000000000) - 0.95) < 1e-12);
    CHECK(std::abs(0.5 * std::erfc(modaluq::interval_factor(0) / std::sqrt(2.0)) - 0.025) < 1e-16);
    CHECK(modaluq::interval_factor(0, modaluq::max_interval_level) > 6.1);
    CHECK(modaluq::interval_factor(15) == student_t_quantile(0.95, 14));
    CHECK(modaluq::interval_factor(50, 0.9) == student_t_quantile(0.9, 49));
    CHECK_THROWS_AS(modaluq::interval_factor(1), modaluq::invalid_argument);
    CHECK_THROWS_AS(modaluq::interval_factor(-2), modaluq::invalid_argument);
    CHECK_THROWS_AS(modaluq::interval_factor(10, 1.0), modaluq::invalid_argument);
    CHECK_THROWS_AS(student_t_quantile(1.0 - 1e-10, 3), modaluq::invalid_argument);
    CHECK_THROWS_AS(student_t_quantile(0.0, 3), modaluq::invalid_argument);
    CHECK_THROWS_AS(student_t_quantile(NAN, 3), modaluq::invalid_argument);
    CHECK_THROWS_AS(student_t_quantile(0.95, 0), modaluq::invalid_argument);
}

TEST_CASE("the interval x +- interval_factor sigma covers its level where x +- 1.96 sigma falls short") {
    // sigma as the core forms it: the sample std of n_b block values over sqrt(n_b) (uq-math §3),
    // for the mean of Gaussian blocks. 20,000 records: a coverage is known to +-0.15 % (1 SE).
    std::mt19937_64 g(27);
    std::normal_distribution<double> nd;
    for (std::int64_t n_b : {5, 15, 50}) {
        const double factor = modaluq::interval_factor(n_b);
        const int records = 20000;
        int inside_t = 0, inside_normal = 0;
        std::vector<double> blocks(static_cast<std::size_t>(n_b));
        for (int r = 0; r < records; ++r) {
            double mean = 0.0;
            for (double& b : blocks) mean += (b = nd(g));
            mean /= double(n_b);
            double ss = 0.0;
            for (double b : blocks) ss += (b - mean) * (b - mean);
            const double sigma = std::sqrt(ss / double(n_b - 1) / double(n_b));
            inside_t += std::abs(mean) <= factor * sigma;
            inside_normal += std::abs(mean) <= 1.96 * sigma;
        }
        const double se = std::sqrt(0.95 * 0.05 / records);
        CHECK(std::abs(double(inside_t) / records - 0.95) < 4 * se);
        // +-1.96 sigma covers P(|t_{n_b-1}| <= 1.96): 87.9 %, 93.0 %, 94.4 %
        CHECK(std::abs(double(inside_normal) / records - modaluq::student_t_probability(1.96, n_b - 1)) < 4 * se);
    }
}

}  // namespace test_interval
