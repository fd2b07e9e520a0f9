#pragma once
/// @file covariance.hpp
/// Streaming, sans-IO accumulation of the Hankel covariances R1..R4 (paper Eq. 18) over the
/// whole record and over each block (paper Eq. 19-21, conventions.md "Blocks").
///
/// Why lag sums: R_i^k is a sub-matrix of the Gram matrix of the stacked window
/// w_c = [z_c; ...; z_{c+p+q-1}] over block k's columns. Its (s1, s2) block is a lag sum
/// sum_t z_{t+l} z_t^T (l = s1 - s2) over a range shifted by s2, so it equals the block's lag
/// sum over its own columns plus two short edge corrections at the block's boundaries.
/// The state is therefore per block O((p+q) d^2) numbers plus p+q-1 samples per boundary:
/// no data Hankel matrix, nothing proportional to the record length.
///
/// Why a shift: products are accumulated on z - a, with a the first sample. The mean is
/// removed exactly at the end (products of sums), and because z - a is of the order of the
/// signal, a DC offset of 1e4 standard deviations costs no precision.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <map>
#include <sstream>
#include <vector>

#include "detail/checks.hpp"
#include "detail/lag_sums.hpp"
#include "detail/parallel.hpp"
#include "errors.hpp"
#include "layout.hpp"

namespace modaluq {

/// R1..R4 of a record and of each of its blocks.
struct Covariances {
    HankelLayout layout;            ///< channels, horizons, references
    Index n_samples = 0;            ///< samples in the record
    Index n_columns = 0;            ///< N = n_samples - p - q + 1 Hankel columns
    Index block_length = 0;         ///< N_b, Hankel columns per block
    Index n_blocks = 0;             ///< n_b = floor(N / N_b); trailing columns enter R only
    Eigen::VectorXd channel_mean;   ///< mean removed per channel [y; u] (zeros when demean = false)
    Eigen::MatrixXd R1;             ///< Y+ Y-^T / N   (p l x q r)
    Eigen::MatrixXd R2;             ///< Y+ U+^T / N   (p l x p m), empty when output-only
    Eigen::MatrixXd R3;             ///< U+ U+^T / N   (p m x p m)
    Eigen::MatrixXd R4;             ///< Y- U+^T / N   (q r x p m)
    /// Column k = r^k = [vec R1^k; vec R2^k; vec R3^k; vec R4^k] (column-major vec, / N_b).
    Eigen::MatrixXd blocks;

    bool has_inputs() const { return layout.n_inputs > 0; }

    /// T_R = [r^1 - rbar, ..., r^nb - rbar] / sqrt(nb (nb - 1)), so that T_R T_R^T estimates
    /// the covariance of r (conventions.md). Needs at least two blocks.
    Eigen::MatrixXd covariance_factor() const& { return centre_blocks(blocks); }
    /// The same, reusing the memory of `blocks` (left empty): the per-block matrices are the
    /// largest object of a run (d_r x n_b doubles), so a large run holds them once.
    Eigen::MatrixXd covariance_factor() && { return centre_blocks(std::move(blocks)); }

private:
    static Eigen::MatrixXd centre_blocks(Eigen::MatrixXd t) {
        detail::require(t.cols() >= 2, "n_blocks must be >= 2 for the uncertainty, got ", t.cols());
        const double nb = static_cast<double>(t.cols());
        const Eigen::VectorXd mean = t.rowwise().mean();
        t.colwise() -= mean;
        t /= std::sqrt(nb * (nb - 1.0));
        return t;
    }
};

/// Everything a CovarianceAccumulator holds, as plain data (sans-IO): export_state() gives it and
/// CovarianceAccumulator::from_state() rebuilds an accumulator that continues bit for bit, so a
/// caller can checkpoint a stream in any format it likes (the Python package: pickle, .npz).
/// With d = layout.n_channels(), L = layout.max_lag() and n = end_sample - first_sample samples,
/// and samples stored shifted (x = z - shift, see the file comment):
struct CovarianceAccumulatorState {
    using IndexVector = Eigen::Matrix<Index, Eigen::Dynamic, 1>;
    HankelLayout layout;
    Index block_length = 0;          ///< N_b
    bool demean = true;
    Index first_sample = 0;          ///< first sample of the span
    Index end_sample = 0;            ///< one past the last sample pushed
    Eigen::VectorXd shift;           ///< d: the first sample (zeros while n = 0)
    Eigen::VectorXd total_sum;       ///< d: sum of the shifted samples
    Eigen::MatrixXd head;            ///< d x min(L, n): the first shifted samples
    Eigen::MatrixXd tail;            ///< d x min(L, n): the last ones (their base times wait for more samples)
    /// Blocks k that meet the base times summed so far, [first_sample, max(first_sample, end_sample - L)),
    /// increasing; block_count holds how many of those base times each block has.
    IndexVector block_index, block_count;
    /// ((L+1) d (c+1)) x blocks: column j is the column-major vec of block block_index[j]'s lag sums,
    /// the ((L+1) d) x (c+1) matrix whose rows l d .. l d + d - 1 are [sum x_{t+l} x_{t,cols}^T | sum x_{t+l}].
    /// The columns are all d channels (c = d), or, output-only with references other than all
    /// outputs in order, the r references in their order (c = r): R1 needs no other products.
    Eigen::MatrixXd block_sums;
    /// Boundaries b = k N_b in [first_sample, end_sample), increasing, and (d L) x boundaries: column j
    /// is the vec of the d x L shifted samples from window_start[j] (the first min(L, end_sample - b) are
    /// set, the others are placeholders overwritten as samples arrive).
    IndexVector window_start;
    Eigen::MatrixXd window_samples;
};

/// Accumulates R1..R4 from chunks of samples of any length. Any chunking of a record gives
/// the batch result; accumulators over consecutive spans can be merged.
class CovarianceAccumulator {
public:
    using State = CovarianceAccumulatorState;

    /// Largest magnitude of a sample that push accepts. The covariances hold sums of products of
    /// two samples over up to 2^63 columns, and identify forms products of two covariances (H with
    /// inputs, its norm): fourth powers of the samples. 1e60^4 = 1e240 leaves room for the counts
    /// below DBL_MAX (1.8e308), so nothing an accepted sample enters can overflow. A glitch of 1e90
    /// made every later identify on the accumulator fail (|H| not finite); no unit of a measurement
    /// comes near 1e60.
    static constexpr double kMaxSampleMagnitude = 1e60;

    /// @param layout        channels and horizons (validated)
    /// @param block_length  N_b, Hankel columns per block (>= p + q)
    /// @param demean        remove each channel's mean over the whole record
    /// @param first_sample  index in the record of the first sample this accumulator sees;
    ///                      non-zero only for a span that will be merged after another one
    CovarianceAccumulator(HankelLayout layout, Index block_length, bool demean = true,
                          Index first_sample = 0)
        : layout_(std::move(layout)), block_length_(block_length), demean_(demean),
          first_(first_sample), end_(first_sample) {
        layout_.validate();
        detail::require(block_length_ >= layout_.window(), "block_length must be >= p + q = ",
                        layout_.window(), ", got ", block_length_);
        detail::require(block_length_ <= kMaxBlockLength, "block_length must be <= ", kMaxBlockLength, ", got ",
                        block_length_);
        detail::require(first_ >= 0, "first_sample must be >= 0, got ", first_);
        d_ = layout_.n_channels();
        lag_ = layout_.max_lag();
        // Output-only with references: R1 needs the lag products with the reference channels
        // only (d r per lag, not d^2): the sums keep those columns. Inputs need every column.
        if (layout_.n_inputs == 0 && !layout_.references.empty()) {
            bool identity = static_cast<Index>(layout_.references.size()) == d_;
            for (size_t j = 0; identity && j < layout_.references.size(); ++j)
                identity = layout_.references[j] == static_cast<Index>(j);
            if (!identity) cols_ = layout_.references;
        }
        c_ = cols_.empty() ? d_ : static_cast<Index>(cols_.size());
        total_sum_ = Eigen::VectorXd::Zero(d_);
        shift_ = Eigen::VectorXd::Zero(d_);
        head_.resize(d_, 0);
        tail_.resize(d_, 0);
    }

    // A copy is a real copy: the state is values (Eigen matrices, std::maps), nothing is shared.
    CovarianceAccumulator(const CovarianceAccumulator&) = default;
    CovarianceAccumulator(CovarianceAccumulator&&) = default;
    CovarianceAccumulator& operator=(const CovarianceAccumulator&) = default;
    CovarianceAccumulator& operator=(CovarianceAccumulator&&) = default;

    /// The whole state as plain data (see CovarianceAccumulatorState).
    State export_state() const {
        State s;
        s.layout = layout_;
        s.block_length = block_length_;
        s.demean = demean_;
        s.first_sample = first_;
        s.end_sample = end_;
        s.shift = shift_;
        s.total_sum = total_sum_;
        s.head = head_;
        s.tail = tail_;
        const Index per_block = (lag_ + 1) * d_ * (c_ + 1), nb = static_cast<Index>(blocks_.size());
        s.block_index.resize(nb);
        s.block_count.resize(nb);
        s.block_sums.resize(per_block, nb);
        Index j = 0;
        for (const auto& [k, blk] : blocks_) {
            s.block_index(j) = k;
            s.block_count(j) = blk.count;
            s.block_sums.col(j++) = Eigen::Map<const Eigen::VectorXd>(blk.sums.data(), per_block);
        }
        const Index nw = static_cast<Index>(windows_.size());
        s.window_start.resize(nw);
        s.window_samples.resize(d_ * lag_, nw);
        j = 0;
        for (const auto& [b, w] : windows_) {
            s.window_start(j) = b;
            s.window_samples.col(j++) = Eigen::Map<const Eigen::VectorXd>(w.x.data(), d_ * lag_);
        }
        return s;
    }

    /// The accumulator whose export_state() is `state`: pushing into it continues the stream
    /// exactly as the exported accumulator would. The state is validated first (shapes against
    /// its layout, the blocks and counts against its sample range, finite values): a
    /// modaluq::invalid_argument names the field that is wrong.
    static CovarianceAccumulator from_state(const State& state) {
        CovarianceAccumulator acc(state.layout, state.block_length, state.demean, state.first_sample);
        acc.import_state(state);
        return acc;
    }

    const HankelLayout& layout() const { return layout_; }
    Index block_length() const { return block_length_; }
    Index first_sample() const { return first_; }
    Index end_sample() const { return end_; }       ///< one past the last sample seen
    Index n_samples() const { return end_ - first_; }
    bool demean() const { return demean_; }

    /// Feed samples. `y` is n_outputs x n (a column is one sample), `u` is n_inputs x n
    /// (ignored, and may be empty, when the layout has no inputs). A sample that is not finite
    /// or beyond kMaxSampleMagnitude throws invalid_argument naming it (sample index in the
    /// stream, channel) before anything changes: the accumulator goes on as if not called.
    void push(const Eigen::Ref<const Eigen::MatrixXd>& y,
              const Eigen::Ref<const Eigen::MatrixXd>& u = Eigen::MatrixXd()) {
        const Index n = y.cols();
        detail::require(y.rows() == layout_.n_outputs, "y must have ", layout_.n_outputs,
                        " channels (rows), got ", y.rows());
        if (layout_.n_inputs > 0) {
            detail::require(u.rows() == layout_.n_inputs, "u must have ", layout_.n_inputs,
                            " channels (rows), got ", u.rows());
            detail::require(u.cols() == n, "u must have as many samples as y (", n, "), got ",
                            u.cols());
        }
        detail::require_finite(y, "y", end_);
        if (layout_.n_inputs > 0) detail::require_finite(u, "u", end_);
        // Before any state changes: a refused push leaves the accumulator as it was.
        require_magnitude(y, "y");
        if (layout_.n_inputs > 0) require_magnitude(u, "u");
        if (n == 0) return;

        if (!has_shift_) {
            shift_.head(layout_.n_outputs) = y.col(0);
            if (layout_.n_inputs > 0) shift_.tail(layout_.n_inputs) = u.col(0);
            has_shift_ = true;
        }
        // Work through the samples in pieces: the buffer [pending tail | shifted samples] is
        // then reused and stays in cache, instead of a copy of the whole push (a batch push
        // of 10^6 samples spent a quarter of its time writing and faulting in that copy).
        const Index l = layout_.n_outputs, m = layout_.n_inputs;
        Eigen::MatrixXd work;
        for (Index c0 = 0; c0 < n; c0 += kPiece) {
            const Index nn = std::min(kPiece, n - c0), nt = tail_.cols();
            work.resize(d_, nt + nn);
            work.leftCols(nt) = tail_;
            work.block(0, nt, l, nn) = y.middleCols(c0, nn).colwise() - shift_.head(l);
            if (m > 0) work.block(l, nt, m, nn) = u.middleCols(c0, nn).colwise() - shift_.tail(m);
            append_shifted(work);
        }
    }

    /// Append the state of `next`, an accumulator over the span that directly follows this
    /// one (next.first_sample() == end_sample(), same layout, block length and demean).
    void merge(const CovarianceAccumulator& next) {
        detail::require(next.first_ == end_, "merge: the next span must start at sample ", end_,
                        ", got ", next.first_);
        detail::require(next.block_length_ == block_length_, "merge: block_length differs (",
                        block_length_, " vs ", next.block_length_, ")");
        detail::require(next.demean_ == demean_, "merge: demean differs");
        detail::require(same_layout(next.layout_), "merge: the layouts differ");
        if (next.n_samples() == 0) return;
        if (!has_shift_) {
            *this = next;
            first_ = next.first_;  // (equal to the old end_)
            return;
        }
        CovarianceAccumulator b = next;
        b.rebase(shift_);

        // Base times of this span that waited for the next span's samples.
        const Index buf_start = end_ - tail_.cols();
        Eigen::MatrixXd buf(d_, tail_.cols() + b.head_.cols());
        buf << tail_, b.head_;
        const Index t_to = std::min(end_, buf_start + buf.cols() - lag_);
        process(buf, buf_start, buf_start, std::max(buf_start, t_to));
        record_windows(b.head_, b.first_, /*create=*/false);

        for (auto& [k, blk] : b.blocks_) {
            auto it = blocks_.find(k);
            if (it == blocks_.end()) blocks_.emplace(k, blk);
            else {
                it->second.sums += blk.sums;
                it->second.count += blk.count;
            }
        }
        for (auto& [bnd, w] : b.windows_) windows_.insert_or_assign(bnd, w);

        if (head_.cols() < lag_) {
            const Index take = std::min(lag_ - head_.cols(), b.head_.cols());
            Eigen::MatrixXd h(d_, head_.cols() + take);
            h << head_, b.head_.leftCols(take);
            head_ = std::move(h);
        }
        if (b.n_samples() >= lag_) tail_ = b.tail_;
        else {
            Eigen::MatrixXd t(d_, tail_.cols() + b.tail_.cols());
            t << tail_, b.tail_;
            tail_ = t.rightCols(std::min(lag_, t.cols())).eval();
        }
        total_sum_ += b.total_sum_;
        end_ = b.end_;
    }

    /// Bytes of state held now. It grows with the number of blocks, not with the samples: per
    /// block ((L+1) d (c+1) + d L) doubles, L = p + q - 1, d = l + m, c = d or r (the lag sums and the
    /// samples after its boundary), so a record cut into n_b blocks holds about n_b times that
    /// whatever its length. Choose block_length from the expected record length to bound it.
    std::size_t state_bytes() const {
        std::size_t doubles = static_cast<std::size_t>(head_.size() + tail_.size() + 2 * d_);
        for (const auto& kv : blocks_) doubles += static_cast<std::size_t>(kv.second.sums.size());
        for (const auto& kv : windows_) doubles += static_cast<std::size_t>(kv.second.x.size());
        return doubles * sizeof(double) +
               (blocks_.size() + windows_.size()) * (sizeof(Index) + sizeof(BlockSums) + 4 * sizeof(void*));
    }

    /// Number of complete blocks so far.
    Index n_complete_blocks() const {
        const Index n_cols = std::max<Index>(0, end_ - lag_);
        return first_ == 0 ? n_cols / block_length_ : 0;
    }

    /// R1..R4 over all Hankel columns and over each complete block. The accumulator is left
    /// unchanged (more samples can be pushed afterwards). Requires the accumulator to cover
    /// the record from its first sample (first_sample() == 0).
    /// @param with_blocks  compute the per-block matrices (needed for the uncertainty)
    Covariances finish(bool with_blocks = true) const {
        detail::require(first_ == 0,
                        "finish: the accumulator starts at sample ", first_,
                        "; merge it after the spans before it first");
        const Index n_cols = end_ - lag_;
        detail::require(n_cols >= layout_.window(), "record too short: ", n_samples(),
                        " samples give ", std::max<Index>(0, n_cols),
                        " Hankel columns; at least ", 2 * layout_.window() - 1,
                        " samples are needed for block_rows + past_block_rows = ",
                        layout_.window());
        Covariances out;
        out.layout = layout_;
        out.n_samples = n_samples();
        out.n_columns = n_cols;
        out.block_length = block_length_;
        out.n_blocks = n_cols / block_length_;

        const double count = static_cast<double>(n_samples());
        const Eigen::VectorXd centre =
            demean_ ? Eigen::VectorXd(total_sum_ / count) : Eigen::VectorXd(-shift_);
        out.channel_mean =
            demean_ ? Eigen::VectorXd(shift_ + total_sum_ / count) : Eigen::VectorXd::Zero(d_);

        // Whole record: all time blocks, boundaries 0 and N (the pending tail).
        Eigen::MatrixXd sums = Eigen::MatrixXd::Zero((lag_ + 1) * d_, c_ + 1);
        for (const auto& [k, blk] : blocks_) sums += blk.sums;
        Targets whole = make_targets(out);
        assemble(sums, window_at(0), tail_, static_cast<double>(n_cols), centre, whole);

        if (with_blocks && out.n_blocks > 0) {
            out.blocks.resize(layout_.n_covariance_entries(), out.n_blocks);
            Targets t = make_targets(out);
            for (Index k = 0; k < out.n_blocks; ++k) {
                const Index c0 = k * block_length_, c1 = c0 + block_length_;
                const Eigen::MatrixXd& w1 = (c1 == n_cols) ? tail_ : window_at(c1);
                assemble(blocks_.at(k).sums, window_at(c0), w1,
                         static_cast<double>(block_length_), centre, t);
                vectorise(t, out.blocks.col(k));
            }
        }
        out.R1 = std::move(whole.R1);
        out.R2 = std::move(whole.R2);
        out.R3 = std::move(whole.R3);
        out.R4 = std::move(whole.R4);
        return out;
    }

private:
    struct BlockSums {
        Eigen::MatrixXd sums;  ///< ((L+1) d) x (c+1): rows l*d.. = [sum x_{t+l} x_{t,cols}^T | sum x_{t+l}]
        Index count = 0;       ///< base times summed
    };
    struct Window {
        Eigen::MatrixXd x;     ///< d x L: shifted samples [b, b + L) after boundary b
        Index filled = 0;
    };
    struct Targets {
        Eigen::MatrixXd R1, R2, R3, R4;
    };

    static constexpr Index kPiece = 1 << 15;  // samples per piece of a push
    static constexpr Index kMaxBlockLength = Index(1) << 50;  // sample indices stay far from overflow
    static constexpr Index kMaxSampleIndex = Index(1) << 62;  // end_sample of an imported state

    HankelLayout layout_;
    Index block_length_;
    bool demean_;
    Index first_, end_;
    Index d_ = 0, lag_ = 0;
    bool has_shift_ = false;
    Eigen::VectorXd shift_;
    Eigen::VectorXd total_sum_;
    std::map<Index, BlockSums> blocks_;   // keyed by block index k: base times [k N_b, (k+1) N_b)
    std::map<Index, Window> windows_;     // keyed by boundary sample b = k N_b
    Eigen::MatrixXd head_;                // first min(L, n) shifted samples
    Eigen::MatrixXd tail_;                // last min(L, n) shifted samples (pending base times)
    detail::ColumnChannels cols_;         // column channels of the lag sums; empty = all d
    Index c_ = 0;                         // their number

    /// The entries of a d-vector at the column channels (the vector itself when all are).
    Eigen::VectorXd columns(const Eigen::Ref<const Eigen::VectorXd>& v) const {
        if (cols_.empty()) return v;
        Eigen::VectorXd out(c_);
        for (Index j = 0; j < c_; ++j) out(j) = v(cols_[static_cast<size_t>(j)]);
        return out;
    }

    /// Refuse a push holding a sample beyond kMaxSampleMagnitude, naming it (x is channels x
    /// samples, finite; its first sample is sample end_ of the stream).
    void require_magnitude(const Eigen::Ref<const Eigen::MatrixXd>& x, const char* what) const {
        if (x.size() == 0 || x.cwiseAbs().maxCoeff() <= kMaxSampleMagnitude) return;
        for (Index s = 0; s < x.cols(); ++s)
            for (Index c = 0; c < x.rows(); ++c)
                if (std::abs(x(c, s)) > kMaxSampleMagnitude) {
                    std::ostringstream value;
                    value.precision(10);
                    value << x(c, s);
                    detail::fail(what, ": sample ", end_ + s, ", channel ", c, " is ", value.str(),
                                 ": samples beyond 1e60 in magnitude are refused, as their products in the "
                                 "covariances and in the identification would overflow (not finite); rescale the data "
                                 "(e.g. to SI units) or remove the glitch (nothing of this push was added)");
                }
    }

    /// Fill a freshly constructed accumulator (layout, block length, demean and first sample
    /// set and validated) from `s`, after checking that `s` is a state such an accumulator can
    /// reach: push and merge keep exactly the blocks and boundaries checked here.
    void import_state(const State& s) {
        using detail::require;
        const Index first = first_, end = s.end_sample, nb = block_length_;
        require(end >= first, "state: end_sample (", end, ") is before first_sample (", first, ")");
        require(end <= kMaxSampleIndex, "state: end_sample must be <= 2^62, got ", end);
        const Index n = end - first, kept = std::min(lag_, n);
        const auto shape = [&](const char* name, Index rows, Index cols, Index want_rows, Index want_cols) {
            require(rows == want_rows && cols == want_cols, "state: ", name, " has shape ", rows, " x ", cols,
                    ", expected ", want_rows, " x ", want_cols, " for ", d_, " channels, block_rows + past_block_rows = ",
                    layout_.window(), ", block_length = ", nb, " and ", n, " samples");
        };
        const auto values = [&](const char* name, const Eigen::MatrixXd& m, double bound) {
            require(m.allFinite() && (m.size() == 0 || m.cwiseAbs().maxCoeff() <= bound), "state: ", name,
                    " holds a value that is not finite or beyond ", bound, " in magnitude");
        };
        // Samples: raw ones up to the push limit, shifted ones (differences of two, re-shifted by
        // merges) up to twice it, with room for rounding.
        const double raw = kMaxSampleMagnitude, shifted = 4 * kMaxSampleMagnitude;
        shape("shift", s.shift.rows(), s.shift.cols(), d_, 1);
        shape("total_sum", s.total_sum.rows(), s.total_sum.cols(), d_, 1);
        shape("head", s.head.rows(), s.head.cols(), d_, kept);
        shape("tail", s.tail.rows(), s.tail.cols(), d_, kept);
        values("shift", s.shift, raw);
        values("total_sum", s.total_sum, std::numeric_limits<double>::max());
        values("head", s.head, shifted);
        values("tail", s.tail, shifted);
        if (n == 0)
            require(s.shift.isZero(0.0) && s.total_sum.isZero(0.0),
                    "state: shift and total_sum must be zero when no sample was pushed");

        // Lag sums: one block per block meeting the base times [first, t_end), with its count.
        const Index t_end = std::max(first, end - lag_);
        const Index k0 = first / nb, n_blocks = t_end > first ? (t_end - 1) / nb - k0 + 1 : 0;
        require(s.block_index.size() == n_blocks && s.block_count.size() == n_blocks, "state: block_index and ",
                "block_count have ", s.block_index.size(), " and ", s.block_count.size(), " entries, expected ",
                n_blocks, " (the blocks of ", nb, " base times meeting [", first, ", ", t_end, "))");
        shape("block_sums", s.block_sums.rows(), s.block_sums.cols(), (lag_ + 1) * d_ * (c_ + 1), n_blocks);
        values("block_sums", s.block_sums, std::numeric_limits<double>::max());
        for (Index j = 0; j < n_blocks; ++j) {
            const Index k = k0 + j, count = std::min((k + 1) * nb, t_end) - std::max(k * nb, first);
            require(s.block_index(j) == k, "state: block_index[", j, "] is ", s.block_index(j), ", expected ", k);
            require(s.block_count(j) == count, "state: block_count[", j, "] is ", s.block_count(j), ", but block ",
                    k, " holds ", count, " of the base times [", first, ", ", t_end, ")");
        }
        // Boundary windows: one per boundary k N_b in [first, end).
        const Index w0 = detail::ceil_div(first, nb), n_windows = end > first ? std::max<Index>(0, (end - 1) / nb - w0 + 1) : 0;
        require(s.window_start.size() == n_windows, "state: window_start has ", s.window_start.size(),
                " entries, expected ", n_windows, " (the block boundaries in [", first, ", ", end, "))");
        shape("window_samples", s.window_samples.rows(), s.window_samples.cols(), d_ * lag_, n_windows);
        values("window_samples", s.window_samples, shifted);
        for (Index j = 0; j < n_windows; ++j)
            require(s.window_start(j) == (w0 + j) * nb, "state: window_start[", j, "] is ", s.window_start(j),
                    ", expected ", (w0 + j) * nb);

        end_ = end;
        has_shift_ = n > 0;
        shift_ = s.shift;
        total_sum_ = s.total_sum;
        head_ = s.head;
        tail_ = s.tail;
        for (Index j = 0; j < n_blocks; ++j) {
            BlockSums blk{Eigen::Map<const Eigen::MatrixXd>(s.block_sums.col(j).data(), (lag_ + 1) * d_, c_ + 1),
                          s.block_count(j)};
            blocks_.emplace_hint(blocks_.end(), s.block_index(j), std::move(blk));
        }
        for (Index j = 0; j < n_windows; ++j) {
            const Index b = s.window_start(j);
            Window w{Eigen::Map<const Eigen::MatrixXd>(s.window_samples.col(j).data(), d_, lag_),
                     std::min(lag_, end - b)};
            windows_.emplace_hint(windows_.end(), b, std::move(w));
        }
    }

    bool same_layout(const HankelLayout& o) const {
        return o.n_outputs == layout_.n_outputs && o.n_inputs == layout_.n_inputs &&
               o.p() == layout_.p() && o.q() == layout_.q() && o.references == layout_.references;
    }

    const Eigen::MatrixXd& window_at(Index b) const {
        auto it = windows_.find(b);
        if (it == windows_.end() || it->second.filled < lag_)
            throw numerical_error("covariance accumulator: missing boundary samples (internal error)");
        return it->second.x;
    }

    /// `buf` = [tail_ | new shifted samples].
    void append_shifted(const Eigen::MatrixXd& buf) {
        const Index n = buf.cols() - tail_.cols();
        const auto x = buf.rightCols(n);
        total_sum_ += x.rowwise().sum();
        if (head_.cols() < lag_) {
            const Index take = std::min(lag_ - head_.cols(), n);
            Eigen::MatrixXd h(d_, head_.cols() + take);
            h << head_, x.leftCols(take);
            head_ = std::move(h);
        }
        record_windows(x, end_, /*create=*/true);
        const Index buf_start = end_ - tail_.cols();
        const Index t_to = buf_start + buf.cols() - lag_;  // base times with all lags present
        if (t_to > buf_start) process(buf, buf_start, buf_start, t_to);
        tail_ = buf.rightCols(std::min(lag_, buf.cols())).eval();
        end_ += n;
    }

    /// Copy the samples x (global indices [s0, s0 + n)) into the boundary windows they touch.
    void record_windows(const Eigen::Ref<const Eigen::MatrixXd>& x, Index s0, bool create) {
        const Index n = x.cols();
        if (n == 0) return;
        const Index lo = std::max(first_, s0 - lag_ + 1);
        for (Index k = detail::ceil_div(lo, block_length_); k * block_length_ < s0 + n; ++k) {
            const Index b = k * block_length_;
            auto it = windows_.find(b);
            if (it == windows_.end()) {
                if (!create || b < s0) continue;
                it = windows_.emplace(b, Window{Eigen::MatrixXd::Zero(d_, lag_), 0}).first;
            }
            Window& w = it->second;
            for (Index j = std::max(b + w.filled, s0); j < std::min(b + lag_, s0 + n); ++j) {
                w.x.col(j - b) = x.col(j - s0);
                w.filled = j - b + 1;
            }
        }
    }

    /// Add the lag sums of base times [t_from, t_to); buf holds samples from buf_start and
    /// covers [t_from, t_to + L).
    void process(const Eigen::MatrixXd& buf, Index buf_start, Index t_from, Index t_to) {
        for (Index t = t_from; t < t_to;) {
            const Index k = t / block_length_;
            const Index stop = std::min(t_to, (k + 1) * block_length_);
            BlockSums& blk = blocks_[k];
            if (blk.sums.size() == 0) blk.sums = Eigen::MatrixXd::Zero((lag_ + 1) * d_, c_ + 1);
            detail::add_lag_sums(buf.data(), d_, lag_, t - buf_start, stop - t, blk.sums, 0, cols_);
            blk.count += stop - t;
            t = stop;
        }
    }

    /// Re-express the state on another shift (exact): x' = x + (shift_ - new_shift).
    void rebase(const Eigen::VectorXd& new_shift) {
        if (!has_shift_) return;
        const Eigen::VectorXd delta = shift_ - new_shift;
        if (delta.isZero(0.0)) return;
        const Eigen::VectorXd delta_c = columns(delta);
        for (auto& [k, blk] : blocks_) {
            const double n = static_cast<double>(blk.count);
            const Eigen::VectorXd m0 = columns(blk.sums.block(0, c_, d_, 1));
            for (Index l = 0; l <= lag_; ++l) {
                auto lam = blk.sums.block(l * d_, 0, d_, c_);
                auto ml = blk.sums.block(l * d_, c_, d_, 1);
                lam += ml * delta_c.transpose() + delta * m0.transpose() + n * delta * delta_c.transpose();
                ml += n * delta;
            }
        }
        for (auto& [b, w] : windows_) w.x.colwise() += delta;
        head_.colwise() += delta;
        tail_.colwise() += delta;
        total_sum_ += static_cast<double>(n_samples()) * delta;
        shift_ = new_shift;
    }

    Targets make_targets(const Covariances& c) const {
        Targets t;
        const Index a = layout_.rows_future(), b = layout_.rows_past(), pm = layout_.rows_input();
        t.R1.resize(a, b);
        if (c.has_inputs()) {
            t.R2.resize(a, pm);
            t.R3.resize(pm, pm);
            t.R4.resize(b, pm);
        }
        return t;
    }

    static void vectorise(const Targets& t, Eigen::Ref<Eigen::VectorXd> out) {
        Index pos = 0;
        for (const Eigen::MatrixXd* m : {&t.R1, &t.R2, &t.R3, &t.R4}) {
            out.segment(pos, m->size()) = Eigen::Map<const Eigen::VectorXd>(m->data(), m->size());
            pos += m->size();
        }
    }

    /// Build R1..R4 / n over columns [c0, c1) from the lag sums over those base times and the
    /// samples after both boundaries (w0 after c0, w1 after c1).
    void assemble(const Eigen::MatrixXd& sums, const Eigen::MatrixXd& w0, const Eigen::MatrixXd& w1,
                  double n, const Eigen::VectorXd& centre, Targets& t) const {
        const Index l = layout_.n_outputs, m = layout_.n_inputs, q = layout_.q();
        const Index r = layout_.n_references();
        Eigen::MatrixXd e0 = Eigen::MatrixXd::Zero((lag_ + 1) * d_, c_);
        Eigen::MatrixXd e1 = Eigen::MatrixXd::Zero((lag_ + 1) * d_, c_);
        Eigen::MatrixXd g(d_, c_);
        const Eigen::VectorXd centre_c = columns(centre);
        for (Index s2 = 0; s2 <= lag_; ++s2) {
            // e0, e1 hold sum_{t in [b, b+s2)} x_{t+l} x_t^T for both boundaries.
            for (Index lg = 0; s2 + lg <= lag_; ++lg) {
                const Index s1 = s2 + lg;
                const bool past_future = s2 < q && s1 >= q;
                const bool future_future = m > 0 && s2 >= q;
                if (!past_future && !future_future) continue;
                g = sums.block(lg * d_, 0, d_, c_) + e1.block(lg * d_, 0, d_, c_) -
                    e0.block(lg * d_, 0, d_, c_);
                const auto m1 = sums.block(s1 * d_, c_, d_, 1);                  // sum_c x_{c+s1}
                const Eigen::VectorXd m2 = columns(sums.block(s2 * d_, c_, d_, 1));  // sum_c x_{c+s2}
                g -= m1 * centre_c.transpose() + centre * m2.transpose() - n * centre * centre_c.transpose();
                g /= n;
                if (past_future) {
                    const Index i = s1 - q, j = s2;
                    for (Index jr = 0; jr < r; ++jr) {
                        const Index ref = cols_.empty() ? layout_.reference(jr) : jr;  // column of g
                        t.R1.block(i * l, j * r + jr, l, 1) = g.block(0, ref, l, 1);
                        if (m > 0) t.R4.block(j * r + jr, i * m, 1, m) = g.block(l, ref, m, 1).transpose();
                    }
                } else {
                    const Index i = s1 - q, i2 = s2 - q;
                    t.R2.block(i * l, i2 * m, l, m) = g.block(0, l, l, m);
                    t.R3.block(i * m, i2 * m, m, m) = g.block(l, l, m, m);
                    if (i != i2) {
                        t.R2.block(i2 * l, i * m, l, m) = g.block(l, 0, m, l).transpose();
                        t.R3.block(i2 * m, i * m, m, m) = g.block(l, l, m, m).transpose();
                    }
                }
            }
            if (s2 < lag_) {
                const Index len = (lag_ - s2) * d_;  // lags 0 .. L-s2-1 still needed
                e0.topRows(len).noalias() +=
                    Eigen::Map<const Eigen::VectorXd>(w0.data() + s2 * d_, len) * columns(w0.col(s2)).transpose();
                e1.topRows(len).noalias() +=
                    Eigen::Map<const Eigen::VectorXd>(w1.data() + s2 * d_, len) * columns(w1.col(s2)).transpose();
            }
        }
    }
};

namespace detail {

/// How many consecutive spans compute_covariances cuts a record of n samples into: spans of
/// at least 2^15 samples, at most 8. It depends on the record only, so the summation order,
/// and with it every rounding, is the same whatever the number of threads.
inline Index covariance_spans(Index n_samples) {
    constexpr Index kMinSpan = Index(1) << 15, kMaxSpans = 8;
    return std::max<Index>(1, std::min<Index>(kMaxSpans, n_samples / kMinSpan));
}

}  // namespace detail

/// Batch covariances of a whole record. y is n_outputs x n_samples, u is n_inputs x n_samples
/// (empty for output-only). N_b = floor(N / n_blocks); n_blocks = 1 gives no uncertainty data.
/// The record is accumulated in detail::covariance_spans consecutive spans, merged in order;
/// `threads` > 1 accumulates the spans concurrently (the result does not depend on it).
inline Covariances compute_covariances(const Eigen::Ref<const Eigen::MatrixXd>& y,
                                       const Eigen::Ref<const Eigen::MatrixXd>& u,
                                       HankelLayout layout, Index n_blocks, bool demean = true,
                                       bool with_blocks = true, Index threads = 1) {
    layout.n_outputs = y.rows();
    layout.n_inputs = u.size() == 0 ? 0 : u.rows();
    layout.validate();
    detail::require(n_blocks >= 1, "n_blocks must be >= 1, got ", n_blocks);
    detail::require(threads >= 1, "threads must be >= 1, got ", threads);
    if (layout.n_inputs > 0)
        detail::require(u.cols() == y.cols(), "u must have as many samples as y (", y.cols(),
                        "), got ", u.cols());
    const Index w = layout.window();
    // In double: n_blocks * w could overflow an Index (n_blocks is the caller's number).
    const double min_samples = double(n_blocks) * double(w) + double(w - 1);
    if (!(double(y.cols()) >= min_samples)) {
        std::ostringstream need;
        need.precision(17);
        need << min_samples;
        detail::fail("record too short: ", y.cols(), " samples; n_blocks = ", n_blocks, " blocks of at least p + q = ",
                     w, " Hankel columns need at least ", need.str(), " samples");
    }
    const Index n = y.cols(), n_cols = n - layout.max_lag(), block_length = n_cols / n_blocks;
    const Index n_spans = detail::covariance_spans(n);
    const auto start = [&](Index s) { return n * s / n_spans; };
    std::vector<CovarianceAccumulator> acc;
    acc.reserve(static_cast<size_t>(n_spans));
    for (Index s = 0; s < n_spans; ++s) acc.emplace_back(layout, block_length, demean, start(s));
    detail::parallel_for(n_spans, threads, [&](Index s) {
        const Index s0 = start(s), len = start(s + 1) - s0;
        if (layout.n_inputs > 0) acc[s].push(y.middleCols(s0, len), u.middleCols(s0, len));
        else acc[s].push(y.middleCols(s0, len));
    });
    for (Index s = 1; s < n_spans; ++s) acc[0].merge(acc[s]);
    return acc[0].finish(with_blocks);
}

}  // namespace modaluq
