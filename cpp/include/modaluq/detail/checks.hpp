#pragma once
/// @file detail/checks.hpp
/// Input validation shared by the public entry points.

#include <Eigen/Core>

#include <cmath>
#include <string>

#include "../errors.hpp"

namespace modaluq::detail {

/// Throw invalid_argument naming `what`, the first non-finite sample (index offset by
/// `first_sample`) and its channel. Channels are rows, samples are columns.
inline void require_finite(const Eigen::Ref<const Eigen::MatrixXd>& x, const char* what,
                           Eigen::Index first_sample = 0) {
    if (x.allFinite()) return;
    for (Eigen::Index s = 0; s < x.cols(); ++s)
        for (Eigen::Index c = 0; c < x.rows(); ++c)
            if (!std::isfinite(x(c, s)))
                fail(what, ": sample ", first_sample + s, ", channel ", c, " is ",
                     std::isnan(x(c, s)) ? "NaN" : "infinite", " (samples must be finite)");
}

/// ceil(a / b) for b > 0, without the overflow of (a + b - 1) / b near the top of the range.
inline Eigen::Index ceil_div(Eigen::Index a, Eigen::Index b) {
    const Eigen::Index q = a / b;
    return (a % b > 0) ? q + 1 : q;
}

/// Largest size any modaluq array may have (2^50 elements, 8 PiB of doubles). Sizes are
/// checked against it in floating point before they are formed, so no Index product of
/// validated sizes can overflow (signed overflow is undefined behaviour).
inline constexpr double max_elements = 1125899906842624.0;  // 2^50

/// Throw invalid_argument naming `what` when `size` (computed in double) exceeds max_elements.
inline void require_size(double size, const char* what) {
    if (!(size <= max_elements))
        fail(what, " would need ", size, " elements, more than the limit of 2^50: the settings are too large");
}

}  // namespace modaluq::detail
