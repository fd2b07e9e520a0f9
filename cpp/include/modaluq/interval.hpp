#pragma once
/// @file interval.hpp
/// Confidence intervals from a sigma estimated on n_b blocks (docs/uq-math.md §14).
///
/// Every sigma of modaluq is the sample standard deviation of n_b block values, scaled (uq-math
/// §3): for a Gaussian statistic linear in the blocks, (x - x_true) / sigma follows Student's t
/// with n_b - 1 degrees of freedom, not the normal law. x +- 1.96 sigma then covers
/// P(|t_{n_b-1}| <= 1.96): 93.0 % with 15 blocks, 94.4 % with 50. The interval that covers the
/// level asked is x +- t sigma with t the quantile below, 2.14 with 15 blocks, 2.01 with 50. The
/// sigma themselves are left as they are: they estimate the standard deviation, the quantile
/// belongs to the interval.

#include "errors.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace modaluq {

namespace detail {

/// Above these many degrees of freedom the quantile is the Cornish-Fisher expansion about the normal
/// one (A&S 26.7.5, four terms: error O(dof^-5), below 1e-11 relative from 1000 up, also at the
/// largest level) and the probability the normal law with the first term of Fisher's expansion
/// (error O(dof^-2), below 1e-13 from 1e7 up): the exact sums cost O(dof) and lose digits there.
inline constexpr std::int64_t large_dof_quantile = 1000;
inline constexpr std::int64_t large_dof_probability = 10000000;

/// The z >= 0 with P(Z > z) = p for a standard normal Z (0 < p <= 0.5): Newton on erfc, which keeps
/// the tail's relative accuracy where 1 - p rounds to 1.
inline double normal_upper_quantile(double p) {
    const double sqrt2 = std::sqrt(2.0), inv_sqrt_2pi = 0.3989422804014327;
    double z = p > 0.3 ? 0.0 : std::sqrt(-2.0 * std::log(p));  // a start above the root in the tail
    for (int it = 0; it < 100; ++it) {
        const double tail = 0.5 * std::erfc(z / sqrt2), density = inv_sqrt_2pi * std::exp(-0.5 * z * z);
        if (!(density > 0)) break;
        const double step = (tail - p) / density;
        z += step;
        if (std::abs(step) <= 1e-15 * std::max(1.0, z)) break;
    }
    return std::max(z, 0.0);
}

}  // namespace detail

/// P(|T| <= t) for T Student-t with `dof` degrees of freedom (dof >= 1, t >= 0; +inf gives 1).
/// Exact finite sums for integer dof (Abramowitz & Stegun 26.7.3, 26.7.4), O(dof) operations, to
/// about 1e-10; above 1e7 degrees of freedom the normal law with Fisher's 1/dof term.
inline double student_t_probability(double t, std::int64_t dof) {
    detail::require(dof >= 1, "student_t_probability: dof must be >= 1; got ", dof);
    detail::require(!std::isnan(t) && t >= 0, "student_t_probability: t must be >= 0; got ", t);
    if (std::isinf(t)) return 1.0;
    const double nu = double(dof);
    if (dof > detail::large_dof_probability) {
        const double density = 0.3989422804014327 * std::exp(-0.5 * t * t);
        return std::min(1.0, std::erf(t / std::sqrt(2.0)) - 2.0 * density * (t * t * t + t) / (4.0 * nu));
    }
    const double theta = std::atan(t / std::sqrt(nu));
    const double c2 = nu / (nu + t * t);  // cos^2 theta, without cancellation for large t
    double sum = 1.0, term = 1.0;
    if (dof % 2 == 0) {
        for (std::int64_t k = 1; k <= (dof - 2) / 2; ++k) {
            term *= c2 * double(2 * k - 1) / double(2 * k);
            sum += term;
        }
        return std::min(1.0, std::sin(theta) * sum);
    }
    if (dof == 1) return 2.0 * theta / detail::pi;
    for (std::int64_t k = 1; k <= (dof - 3) / 2; ++k) {
        term *= c2 * double(2 * k) / double(2 * k + 1);
        sum += term;
    }
    return std::min(1.0, 2.0 / detail::pi * (theta + std::sin(theta) * std::cos(theta) * sum));
}

/// The largest level the quantile takes: closer to 1, P(|T| <= t) rounds towards 1 and the sums
/// above lose the tail's digits (relative accuracy of t about 2e-8 at this level, dof <= 1000).
inline constexpr double max_interval_level = 1.0 - 1e-9;

/// The t >= 0 with P(|T| <= t) = level for T Student-t with `dof` degrees of freedom: the
/// (1 + level) / 2 quantile (0 < level <= max_interval_level, dof >= 1). Newton on the exact
/// probability, safeguarded by bisection (relative accuracy about 3e-11 for level <= 0.999999);
/// above 1000 degrees of freedom the Cornish-Fisher expansion about the normal quantile.
inline double student_t_quantile(double level, std::int64_t dof) {
    detail::require(dof >= 1, "student_t_quantile: dof must be >= 1; got ", dof);
    detail::require(level > 0 && level <= max_interval_level, "student_t_quantile: level must be in (0, 1 - 1e-9]; got ",
                    level);
    const double nu = double(dof);
    if (dof > detail::large_dof_quantile) {  // A&S 26.7.5
        const double z = detail::normal_upper_quantile(0.5 * (1.0 - level)), z2 = z * z;
        const double g1 = (z2 + 1) * z / 4, g2 = ((5 * z2 + 16) * z2 + 3) * z / 96,
                     g3 = (((3 * z2 + 19) * z2 + 17) * z2 - 15) * z / 384,
                     g4 = ((((79 * z2 + 776) * z2 + 1482) * z2 - 1920) * z2 - 945) * z / 92160;
        return z + g1 / nu + g2 / (nu * nu) + g3 / (nu * nu * nu) + g4 / (nu * nu * nu * nu);
    }
    // density of |T|: 2 Gamma((nu+1)/2) / (Gamma(nu/2) sqrt(nu pi)) (1 + t^2/nu)^(-(nu+1)/2)
    const double log_scale = std::log(2.0) + std::lgamma(0.5 * (nu + 1)) - std::lgamma(0.5 * nu) -
                             0.5 * std::log(nu * detail::pi);
    double lo = 0.0, hi = 2.0;
    while (student_t_probability(hi, dof) < level) {
        lo = hi;
        hi *= 2.0;
    }
    double t = 0.5 * (lo + hi);
    for (int it = 0; it < 200; ++it) {
        const double excess = student_t_probability(t, dof) - level;
        if (excess > 0) hi = t; else lo = t;
        const double density = std::exp(log_scale - 0.5 * (nu + 1) * std::log1p(t * t / nu));
        double next = t - excess / density;
        if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);  // Newton left the bracket: bisect
        const bool done = std::abs(next - t) <= 1e-14 * std::max(1.0, t) || hi - lo <= 1e-15 * hi;
        t = next;
        if (done) break;
    }
    return t;
}

/// The factor of a `level` interval x +- factor sigma for a sigma from `n_blocks` blocks: the
/// Student-t quantile with n_blocks - 1 degrees of freedom (n_blocks >= 2; 0.95 -> 2.14 at 15
/// blocks, 2.01 at 50, 1.96 in the limit). n_blocks = 0 means unknown: the normal quantile.
inline double interval_factor(std::int64_t n_blocks, double level = 0.95) {
    detail::require(n_blocks >= 2 || n_blocks == 0,
                    "interval_factor: n_blocks must be >= 2 (a sigma needs two blocks) or 0 (unknown); got ", n_blocks);
    detail::require(level > 0 && level <= max_interval_level, "interval_factor: level must be in (0, 1 - 1e-9]; got ",
                    level);
    if (n_blocks == 0) return detail::normal_upper_quantile(0.5 * (1.0 - level));
    return student_t_quantile(level, n_blocks - 1);
}

}  // namespace modaluq
