#pragma once
/// @file interval.hpp
/// Confidence intervals from a sigma estimated on n_b blocks (docs/uq-math.md §14).
///
/// Every sigma of modaluq is the sample standard deviation of n_b block values, scaled (uq-math
/// §3): for a Gaussian statistic linear in the blocks, (x - x_true) / sigma follows Student's t
/// with n_b - 1 degrees of freedom, not the normal law. x +- 1.96 sigma then covers
/// P(|t_{n_b-1}| <= 1.96): 93.0 % with 15 blocks, 94.5 % with 50. The interval that covers the
/// level asked is x +- t sigma with t the quantile below, 2.14 with 15 blocks, 2.01 with 50. The
/// sigma themselves are left as they are: they estimate the standard deviation, the quantile
/// belongs to the interval.

#include "errors.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace modaluq {

/// P(|T| <= t) for T Student-t with `dof` degrees of freedom (dof >= 1, t >= 0; +inf gives 1).
/// Exact finite sums for integer dof (Abramowitz & Stegun 26.7.3, 26.7.4), O(dof) operations.
inline double student_t_probability(double t, std::int64_t dof) {
    detail::require(dof >= 1, "student_t_probability: dof must be >= 1; got ", dof);
    detail::require(!std::isnan(t) && t >= 0, "student_t_probability: t must be >= 0; got ", t);
    if (std::isinf(t)) return 1.0;
    const double nu = double(dof);
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

/// The t >= 0 with P(|T| <= t) = level for T Student-t with `dof` degrees of freedom: the
/// (1 + level) / 2 quantile (0 < level < 1, dof >= 1). Newton on the exact probability,
/// safeguarded by bisection; relative accuracy about 1e-12 for level <= 0.99 (1e-9 at 1 - 1e-6,
/// where the probability near 1 limits it).
inline double student_t_quantile(double level, std::int64_t dof) {
    detail::require(dof >= 1, "student_t_quantile: dof must be >= 1; got ", dof);
    detail::require(level > 0 && level < 1, "student_t_quantile: level must be in (0, 1); got ", level);
    const double nu = double(dof);
    // density of |T|: 2 Gamma((nu+1)/2) / (Gamma(nu/2) sqrt(nu pi)) (1 + t^2/nu)^(-(nu+1)/2)
    const double log_scale = std::log(2.0) + std::lgamma(0.5 * (nu + 1)) - std::lgamma(0.5 * nu) -
                             0.5 * std::log(nu * detail::pi);
    double lo = 0.0, hi = 2.0;
    while (student_t_probability(hi, dof) < level) {
        lo = hi;
        hi *= 2.0;
        if (!std::isfinite(hi)) return std::numeric_limits<double>::infinity();  // level indistinguishable from 1
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
/// blocks, 2.01 at 50, 1.96 in the limit).
inline double interval_factor(std::int64_t n_blocks, double level = 0.95) {
    detail::require(n_blocks >= 2, "interval_factor: n_blocks must be >= 2 (a sigma needs two blocks); got ",
                    n_blocks);
    detail::require(level > 0 && level < 1, "interval_factor: level must be in (0, 1); got ", level);
    return student_t_quantile(level, n_blocks - 1);
}

}  // namespace modaluq
