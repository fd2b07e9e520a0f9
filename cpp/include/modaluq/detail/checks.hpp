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

inline Eigen::Index ceil_div(Eigen::Index a, Eigen::Index b) { return a >= 0 ? (a + b - 1) / b : -((-a) / b); }

}  // namespace modaluq::detail
