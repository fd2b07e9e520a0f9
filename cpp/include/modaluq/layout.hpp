#pragma once
/// @file layout.hpp
/// The shape of the Hankel covariances: channels, horizons and reference outputs
/// (conventions.md, "Horizons and covariance matrices").

#include <Eigen/Core>

#include <algorithm>
#include <vector>

#include "detail/checks.hpp"
#include "errors.hpp"

namespace modaluq {

using Index = Eigen::Index;

/// Which channels and horizons form R1..R4 (the paper's Eq. 18).
struct HankelLayout {
    static constexpr Index kMaxHorizon = Index(1) << 24;   ///< bound on p and q (validate)
    static constexpr Index kMaxChannels = Index(1) << 20;  ///< bound on l and m (validate)
    Index n_outputs = 0;             ///< l: outputs y (>= 1)
    Index n_inputs = 0;              ///< m: known inputs u (0 = output-only)
    Index block_rows = 0;            ///< p: future block rows (>= 2)
    Index past_block_rows = 0;       ///< q: past block rows; 0 means q = p
    std::vector<Index> references;   ///< outputs in the past matrix Y-; empty = all outputs

    Index p() const { return block_rows; }
    Index q() const { return past_block_rows > 0 ? past_block_rows : block_rows; }
    Index n_references() const {
        return references.empty() ? n_outputs : static_cast<Index>(references.size());
    }
    /// Output index of reference j (0 <= j < r).
    Index reference(Index j) const { return references.empty() ? j : references[j]; }
    Index n_channels() const { return n_outputs + n_inputs; }
    /// Largest lag between two samples of one Hankel column, p + q - 1.
    Index max_lag() const { return p() + q() - 1; }
    /// Samples one Hankel column spans, p + q.
    Index window() const { return p() + q(); }
    Index rows_future() const { return p() * n_outputs; }      ///< a = p l
    Index rows_past() const { return q() * n_references(); }   ///< b = q r
    Index rows_input() const { return p() * n_inputs; }        ///< p m
    /// Length of r = [vec R1; vec R2; vec R3; vec R4].
    Index n_covariance_entries() const {
        const Index a = rows_future(), b = rows_past(), c = rows_input();
        return a * b + a * c + c * c + b * c;
    }
    /// Largest model order the horizons support: min((p-1) l, q r).
    Index max_order() const {
        return std::min((p() - 1) * n_outputs, rows_past());
    }

    void validate() const {
        detail::require(n_outputs >= 1, "n_outputs must be >= 1, got ", n_outputs);
        detail::require(n_inputs >= 0, "n_inputs must be >= 0, got ", n_inputs);
        detail::require(block_rows >= 2, "block_rows must be >= 2, got ", block_rows);
        detail::require(past_block_rows >= 0, "past_block_rows must be >= 1 (or 0 for block_rows), got ",
                        past_block_rows);
        // Every size below is formed from these as Index products: bound them first (in
        // double) so none can overflow.
        detail::require(block_rows <= kMaxHorizon, "block_rows must be <= ", kMaxHorizon, ", got ", block_rows);
        detail::require(past_block_rows <= kMaxHorizon, "past_block_rows must be <= ", kMaxHorizon, ", got ",
                        past_block_rows);
        detail::require(n_outputs <= kMaxChannels, "n_outputs must be <= ", kMaxChannels, ", got ", n_outputs);
        detail::require(n_inputs <= kMaxChannels, "n_inputs must be <= ", kMaxChannels, ", got ", n_inputs);
        const double a = double(p()) * double(n_outputs), c = double(p()) * double(n_inputs);
        const double b = double(q()) * double(references.empty() ? n_outputs : Index(references.size()));
        detail::require_size(a * b + a * c + c * c + b * c, "the covariances R1..R4 for these horizons");
        std::vector<Index> seen;
        for (Index ref : references) {
            detail::require(ref >= 0 && ref < n_outputs, "references: index ", ref,
                            " is out of range for ", n_outputs, " outputs");
            detail::require(std::find(seen.begin(), seen.end(), ref) == seen.end(),
                            "references: index ", ref, " is repeated");
            seen.push_back(ref);
        }
    }
};

}  // namespace modaluq
