#pragma once
/// @file detail/lag_sums.hpp
/// Lag sums sum_c [x_{c+l} x_{c,cols}^T | x_{c+l}], l = 0..L (cols: all channels, or the references), over a range of base times c: the only
/// pass over the samples, so it decides the covariance stage's speed.
///
/// Direct form: the stacked lags [x_c; ...; x_{c+L}] are a strided view of the column-major
/// samples, times [x_c^T 1]. Its product has only d + 1 columns, so the GEMM re-packs the
/// (L+1) d-row view for very little work per element (for 3 channels, 4 flops per packed double).
///
/// Segmented form: cut the base times into segments of S samples. With rows s of
///   A (segments x (S+L) d):  x_{sS}, ..., x_{sS+S+L-1}   (overlapping rows, still a view)
///   X (segments x S d):      x_{sS}, ..., x_{sS+S-1}     (a reshape)
/// G = A^T X holds every product x_{sS+i} x_{sS+t}^T summed over segments, and the lag-l sum
/// is the sum of G's d x d blocks (t + l, t), t < S. The GEMM now has S d columns and works at
/// the machine's rate, for (S + L) / (L + 1) times the direct flops.
///
/// Both forms multiply views whose columns overlap (outer stride below the row count), which a
/// BLAS rejects, so they are Eigen's products even in a MODALUQ_USE_BLAS build (gemm.hpp).

#include <Eigen/Core>

#include <algorithm>
#include <vector>

namespace modaluq::detail {

using Index = Eigen::Index;

/// Column channels of the lag sums: the channels x_c is restricted to. Empty means all d
/// channels. With references and no inputs only the reference columns are needed (R1 holds
/// y_{c+l} y_ref,c^T only), which takes the pass from d^2 to d r products per lag.
using ColumnChannels = std::vector<Index>;

/// Add the lag sums of base times [off, off + nc) of the column-major samples `x` (d x n,
/// needs columns up to off + nc + lag) to `sums` ((lag + 1) d x (c + 1), c the column
/// channels: all d when `cols` is empty).
inline void add_lag_sums_direct(const double* x, Index d, Index lag, Index off, Index nc,
                                Eigen::MatrixXd& sums, const ColumnChannels& cols = {}) {
    using Strided = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
    constexpr Index kChunk = 2048;  // base times per GEMM: keeps the rhs copy small
    const Index c = cols.empty() ? d : static_cast<Index>(cols.size());
    Eigen::MatrixXd rhs;
    for (Index c0 = off; c0 < off + nc; c0 += kChunk) {
        const Index n = std::min(kChunk, off + nc - c0);
        const Strided stack(x + c0 * d, (lag + 1) * d, n, Eigen::OuterStride<>(d));
        rhs.resize(n, c + 1);
        if (cols.empty()) {
            rhs.leftCols(d) = Eigen::Map<const Eigen::MatrixXd>(x + c0 * d, d, n).transpose();
        } else {
            for (Index j = 0; j < c; ++j)
                for (Index i = 0; i < n; ++i) rhs(i, j) = x[(c0 + i) * d + cols[static_cast<size_t>(j)]];
        }
        rhs.col(c).setOnes();
        sums.noalias() += stack * rhs;
    }
}

/// Segment length for d channels: S d >= 32 columns is wide enough for the GEMM to run near
/// its rate, and longer segments only add flops ((S + L) / (L + 1)). Measured with Eigen 3.4
/// (AVX2, one thread) on 1-32 channels and 20-80 lags: 1.0-4x faster than the direct form,
/// most for few channels (3 channels, 80 lags: 1.65x).
inline Index lag_segment_length(Index d) { return std::max<Index>(2, (32 + d - 1) / d); }

/// Same result as add_lag_sums_direct (to rounding), by the segmented form. `segment` > 0
/// sets the segment length (tests), 0 picks lag_segment_length of the column channels. Base
/// times that do not fill a segment go the direct way.
inline void add_lag_sums(const double* x, Index d, Index lag, Index off, Index nc,
                         Eigen::MatrixXd& sums, Index segment = 0, const ColumnChannels& cols = {}) {
    const Index c = cols.empty() ? d : static_cast<Index>(cols.size());
    const Index s = segment > 0 ? segment : lag_segment_length(c);
    const Index n_seg = nc / s;
    if (n_seg < 2) return add_lag_sums_direct(x, d, lag, off, nc, sums, cols);
    using Strided = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
    const double* x0 = x + off * d;
    const Strided a(x0, (s + lag) * d, n_seg, Eigen::OuterStride<>(s * d));  // A^T
    Eigen::MatrixXd g(a.rows(), s * c);
    if (cols.empty()) {
        const Eigen::Map<const Eigen::MatrixXd> xs(x0, s * d, n_seg);  // X^T
        g.noalias() = a * xs.transpose();
    } else {
        Eigen::MatrixXd xs(s * c, n_seg);  // X^T of the column channels (a gather: n c doubles)
        for (Index j = 0; j < n_seg; ++j)
            for (Index t = 0; t < s; ++t)
                for (Index k = 0; k < c; ++k)
                    xs(t * c + k, j) = x0[(j * s + t) * d + cols[static_cast<size_t>(k)]];
        g.noalias() = a * xs.transpose();
    }
    // Column sums of A^T (sum over segments of x_{sS+m}, m < S + L) from contiguous adds of
    // the first S (a reduction over a strided view is several times slower), then
    // cs[m] = cs[m - S] - x_m' + x_{n_seg S + m'} with m' = m - S for the last L.
    Eigen::VectorXd col_sums = Eigen::VectorXd::Zero((s + lag) * d);
    auto head = col_sums.head(s * d);
    for (Index j = 0; j < n_seg; ++j) head += Eigen::Map<const Eigen::VectorXd>(x0 + j * s * d, s * d);
    for (Index m = s; m < s + lag; ++m)
        col_sums.segment(m * d, d) = col_sums.segment((m - s) * d, d) -
                                     Eigen::Map<const Eigen::VectorXd>(x0 + (m - s) * d, d) +
                                     Eigen::Map<const Eigen::VectorXd>(x0 + (n_seg * s + m - s) * d, d);
    for (Index l = 0; l <= lag; ++l)
        for (Index t = 0; t < s; ++t) {
            sums.block(l * d, 0, d, c) += g.block((t + l) * d, t * c, d, c);
            sums.block(l * d, c, d, 1) += col_sums.segment((t + l) * d, d);
        }
    if (nc > n_seg * s) add_lag_sums_direct(x, d, lag, off + n_seg * s, nc - n_seg * s, sums, cols);
}

}  // namespace modaluq::detail
