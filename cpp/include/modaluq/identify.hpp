#pragma once
/// @file identify.hpp
/// The whole pipeline: samples (or accumulated covariances) -> H -> one SVD -> modes and their
/// standard deviations at every requested order.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "covariance.hpp"
#include "detail/bootstrap.hpp"
#include "detail/parallel.hpp"
#include "modal.hpp"
#include "realization.hpp"
#include "subspace.hpp"
#include "uncertainty.hpp"

namespace modaluq {

/// Settings of an identification. Defaults follow conventions.md.
struct IdentifyOptions {
    double fs = 0.0;                ///< sampling frequency in Hz (required, finite, > 0)
    Index block_rows = 0;           ///< p, future block rows (required, >= 2)
    Index past_block_rows = 0;      ///< q, past block rows; 0 means q = p
    std::vector<Index> orders;      ///< model orders (required, >= 1); sorted, duplicates dropped
    Index n_blocks = 50;            ///< blocks of the uncertainty (>= 2 when uncertainty is on)
    std::vector<Index> references;  ///< outputs forming the past data matrix; empty = all
    bool uncertainty = true;        ///< propagate the covariance; false skips all of it
    bool demean = true;             ///< remove each channel's mean over the record
    double input_rcond = 1e-10;     ///< R3 eigenvalues below this times the largest are dropped
    /// Threads for the covariance pass (identify from samples), the per-block and the per-order
    /// work (1 = the calling thread only). Results do not depend on it. Each thread's linear
    /// algebra is single-threaded, unless a BLAS with threads of its own is linked (gemm.hpp).
    Index threads = 1;
    /// Freeze the directions of singular vectors from the noise floor k* on (docs/uq-math.md §5.5).
    bool freeze_noise = true;
    double noise_floor_factor = 1.5;    ///< c of (5.12), > 0
    /// rho_max of (5.14), >= 1: poles whose sigma_f or sigma_xi the noise directions inflate by
    /// more are flagged noise_coupled and keep the unfrozen sigma.
    double noise_coupling_limit = 20.0;
    /// Correct each mode's block covariance for the correlation of adjacent blocks (docs/uq-math.md
    /// §3.1): where |rho| > 2 / sqrt(n_b), its factor is scaled by sqrt(c), c = max(1/4, 1 + 2 rho),
    /// rho the lag-1 autocorrelation of its f and xi block terms plus 1/n_b. For one record
    /// (identify_setups refuses it). Off by default: it helps with many blocks (100-200) and a
    /// measured input carrying the excitation, and changes nothing measurable elsewhere
    /// (docs/validation.md, "Issue 27", (d)).
    bool block_correlation_correction = false;
    /// Draws B of the bootstrap of sigma_f and sigma_xi above the noise floor k* (docs/uq-math.md
    /// §5.6): at every order above k*, each pole not noise_coupled gets the robust spread of its
    /// frequency and damping over B identifications of H perturbed by its own estimation error
    /// (Modes::bootstrapped). 0 turns it off (the first-order sigma everywhere); orders up to k*
    /// are never touched. Each draw costs an SVD of H and the eigenvalues of every order above k*.
    Index bootstrap_draws = 0;
    /// For a campaign's merge (identify_setups) only: the sketch size s of its noise-coupling
    /// test (docs/uq-math.md §13.4). Where a setup's noise floor freezes columns, rho (5.14) of
    /// each merged pole is computed from s signed combinations of each setup's blocks instead of
    /// every block, and a flagged pole's factor rows are its frozen rows times rho. 0 = every
    /// block (the exact unfrozen pass, which costs as much as the frozen one again). One record
    /// computes rho exactly at no extra cost and ignores it.
    Index coupling_sketch = 4;
    /// Keep each pole's first-order factor of its shape (Modes::mode_shape_factor, 2 l n_b doubles
    /// per pole), so that the cross-covariance of two poles' shapes is known: the exact sigma of
    /// the MAC between two modes of one identification (an AutoMAC). Off by default for the
    /// memory: with l = 30 outputs and 50 blocks, 24 kB per pole, about 60 MB over orders 2..100.
    bool keep_shape_factor = false;

    void validate() const {
        detail::require(std::isfinite(fs) && fs > 0.0, "fs must be a finite sampling frequency > 0 Hz, got ", fs);
        detail::require(block_rows >= 2, "block_rows must be >= 2, got ", block_rows);
        detail::require(past_block_rows >= 0, "past_block_rows must be >= 1, got ", past_block_rows);
        detail::require(!orders.empty(), "orders must name at least one model order");
        for (Index n : orders) detail::require(n >= 1, "orders must be >= 1, got ", n);
        if (uncertainty) detail::require(n_blocks >= 2, "n_blocks must be >= 2, got ", n_blocks);
        detail::require(input_rcond >= 0.0 && input_rcond < 1.0, "input_rcond must be in [0, 1), got ", input_rcond);
        detail::require(std::isfinite(noise_floor_factor) && noise_floor_factor > 0.0,
                        "noise_floor_factor must be finite and > 0, got ", noise_floor_factor);
        detail::require(noise_coupling_limit >= 1.0, "noise_coupling_limit must be >= 1, got ", noise_coupling_limit);
        detail::require(bootstrap_draws >= 0, "bootstrap_draws must be >= 0, got ", bootstrap_draws);
        detail::require(bootstrap_draws == 0 || bootstrap_draws >= kMinBootstrapDraws,
                        "bootstrap_draws must be 0 (off) or >= ", kMinBootstrapDraws, ", got ", bootstrap_draws);
        detail::require(coupling_sketch >= 0, "coupling_sketch must be >= 0 (0 = every block), got ", coupling_sketch);
        detail::require(threads >= 1, "threads must be >= 1, got ", threads);
        detail::require(threads <= kMaxThreads, "threads must be <= ", kMaxThreads, ", got ", threads);
    }
    static constexpr Index kMaxThreads = 1024;  ///< more is a mistake, not a machine
    static constexpr Index kMinBootstrapDraws = 10;  ///< fewer leave the spread of a pole to chance

    HankelLayout layout(Index n_outputs, Index n_inputs) const {
        HankelLayout L;
        L.n_outputs = n_outputs;
        L.n_inputs = n_inputs;
        L.block_rows = block_rows;
        L.past_block_rows = past_block_rows;
        L.references = references;
        return L;
    }
};

/// What an entry of Identification::warnings is about; the flags and numbers it words are in
/// the Identification (the words are for C++ users; Python words the numbers itself).
enum class IdentificationWarning : int {
    input_rank_deficient = 0,  ///< input_rank_deficient, input_rank
    too_few_blocks = 1,        ///< too_few_blocks, n_blocks
    low_signal_to_noise = 2,   ///< low_signal_to_noise, signal_to_noise
    degenerate_orders = 3,     ///< Modes::degenerate of some orders, numerical_rank
    slow_decay = 4,            ///< slow_decay
};

/// Poles whose decay outlasts the blocks (Modes::block_too_short, over every order): their
/// sigma are less reliable. n_poles 0: none (and no warning).
struct SlowDecay {
    Index n_poles = 0;               ///< poles flagged block_too_short, every order
    double block_seconds = 0.0;      ///< length of one block N_b / fs, s
    double longest_decay_s = 0.0;    ///< largest decay time 1/(2 pi f xi) of the flagged poles, s
    double record_seconds = 0.0;     ///< the record's Hankel columns N / fs, s
    /// record_seconds / (longest_decay_s / 2): the most blocks each as long as half the longest
    /// decay time; below 2 the record is too short for these poles' decay.
    Index fitting_n_blocks = 0;

    bool record_too_short() const { return fitting_n_blocks < 2; }
};

/// Everything an identification returns.
struct Identification {
    std::vector<Modes> modes;            ///< one entry per requested order, ascending order
    Eigen::VectorXd singular_values;     ///< of H, all min(p l, q r)
    Index n_samples = 0;                 ///< samples in the record
    Index n_columns = 0;                 ///< Hankel columns N
    Index block_length = 0;              ///< N_b (0 without uncertainty)
    Index n_blocks = 0;                  ///< blocks used for the uncertainty (0 without)
    Eigen::VectorXd channel_mean;        ///< mean removed per channel [y; u]
    Index input_rank = 0;                ///< numerical rank of R3 (input/output only)
    double input_condition = 0.0;        ///< condition number of R3 (input/output only)
    bool input_rank_deficient = false;   ///< R3 singular: inputs constant, duplicated or not exciting
    bool too_few_blocks = false;         ///< n_b - 1 < 2 + 2 l: a mode's joint covariance is rank deficient
    Index numerical_rank = 0;            ///< singular values of H above max(a, b) eps s_1; higher orders are degenerate
    /// s_1 / std(s_1): how far the largest singular value of H stands above its own estimation
    /// noise (NaN without uncertainty); identify refuses a record where it is below 3.
    double signal_to_noise = std::numeric_limits<double>::quiet_NaN();
    bool low_signal_to_noise = false;    ///< signal_to_noise < 3: the modes cannot be told from estimation noise
    /// k*, the noise floor (docs/uq-math.md eq. 5.12): singular values of H above the size of the
    /// estimation error of their trailing block; an estimate of the model order. At most the
    /// largest order + 1 (that value also means "none below"). 0 without uncertainty.
    Index significant_singular_values = 0;
    SlowDecay slow_decay;                ///< poles decaying more slowly than the blocks are long
    std::vector<std::string> warnings;   ///< what the flags above mean for this run, in words
    std::vector<IdentificationWarning> warning_codes;  ///< per entry of warnings, what it is about

    /// Add a warning and its code.
    void warn(IdentificationWarning code, std::string text) {
        warning_codes.push_back(code);
        warnings.push_back(std::move(text));
    }

    /// The modes at model order n (throws invalid_argument if n was not requested).
    const Modes& at_order(Index n) const {
        for (const Modes& m : modes)
            if (m.order == n) return m;
        detail::fail("order ", n, " was not identified; the identified orders are ",
                     modes.empty() ? Index(0) : modes.front().order, "..",
                     modes.empty() ? Index(0) : modes.back().order);
    }
};

namespace detail {
/// |H| / |R1| at or below which H is numerically zero (its entries are rounding errors of R1's).
inline constexpr double kNumericallyZero = 1e-8;
/// s_1 / std(s_1) below which H is indistinguishable from its estimation noise.
inline constexpr double kMinSignalToNoise = 3.0;

/// An order without modes: every array empty but with the shapes of zero modes (l rows for the
/// shapes), the uncertainty arrays present when the run has uncertainty, so that code reading
/// all orders alike needs no special case.
/// The orders whose modes are degenerate, as "4, 6, 8" (empty when there is none).
inline std::string degenerate_order_list(const std::vector<Modes>& modes) {
    std::ostringstream list;
    const char* sep = "";
    for (const Modes& m : modes)
        if (m.degenerate) {
            list << sep << m.order;
            sep = ", ";
        }
    return list.str();
}

/// SlowDecay of an identification: the poles flagged block_too_short at every order, their
/// longest decay time and the most blocks that would each last half of it.
inline SlowDecay count_slow_decay(const std::vector<Modes>& modes, double block_seconds, double record_seconds) {
    SlowDecay slow;
    slow.block_seconds = block_seconds;
    slow.record_seconds = record_seconds;
    for (const Modes& m : modes)
        for (Index i = 0; i < m.block_too_short.size(); ++i)
            if (m.block_too_short(i)) {
                ++slow.n_poles;
                slow.longest_decay_s = std::max(slow.longest_decay_s,
                                                1.0 / (2.0 * pi * m.frequency_hz(i) * m.damping_ratio(i)));
            }
    if (slow.n_poles > 0)
        slow.fitting_n_blocks = static_cast<Index>(slow.record_seconds / (0.5 * slow.longest_decay_s));
    return slow;
}

inline Modes degenerate_modes(Index order, Index n_outputs, bool with_uncertainty) {
    Modes m;
    m.order = order;
    m.degenerate = true;
    m.eigenvalue.resize(0);
    m.frequency_hz.resize(0);
    m.damping_ratio.resize(0);
    m.mode_shape.resize(n_outputs, 0);
    m.reference_component.resize(0);
    if (with_uncertainty) {
        const Index np = 2 + 2 * n_outputs;
        m.frequency_std.resize(0);
        m.damping_std.resize(0);
        m.mode_shape_std_real.resize(n_outputs, 0);
        m.mode_shape_std_imag.resize(n_outputs, 0);
        m.covariance.resize(np * np, 0);
        m.frequency_damping_factor.resize(0, 0);
        m.block_too_short.resize(0);
        m.frequency_damping_correlation.resize(0);
        m.noise_coupling.resize(0);
        m.noise_coupled.resize(0);
        m.block_correlation_scale.resize(0);
        m.bootstrapped.resize(0);
    }
    return m;
}

/// The identification proper; `t_r` is the covariance factor (empty without uncertainty).
inline Identification identify_with_factor(const Covariances& cov, Eigen::MatrixXd t_r, IdentifyOptions options) {
    std::sort(options.orders.begin(), options.orders.end());
    options.orders.erase(std::unique(options.orders.begin(), options.orders.end()), options.orders.end());
    const HankelLayout& L = cov.layout;
    const Index n_max = options.orders.back();
    detail::require(n_max <= L.max_order(), "order ", n_max,
                    " is above what the horizons support: min((block_rows - 1) * n_outputs, past_block_rows * n_references) = ",
                    L.max_order());

    Identification out;
    out.n_samples = cov.n_samples;
    out.n_columns = cov.n_columns;
    out.channel_mean = cov.channel_mean;
    const SubspaceMatrix sub = subspace_matrix(cov, options.input_rcond);
    if (cov.has_inputs()) {
        out.input_rank = sub.input_rank;
        out.input_condition = sub.input_condition;
        out.input_rank_deficient = sub.input_rank_deficient;
        if (sub.input_rank_deficient)
            out.warn(IdentificationWarning::input_rank_deficient, detail::concat(
                "the input covariance R3 is rank deficient (rank ", sub.input_rank, " of ", L.rows_input(),
                "): inputs are constant, duplicated or not exciting enough for block_rows = ", L.p(),
                "; their effect was removed only in the subspace they span and the uncertainty is not reliable"));
    }
    // A record that cannot be identified is refused with the reason; an order that cannot is a
    // flag on that order (below).
    detail::require(cov.R1.allFinite() && sub.H.allFinite(),
                    "the covariances of the data are not finite: the samples are so large that their products "
                    "overflow; rescale the data (e.g. to SI units)");
    const double r1_norm = cov.R1.norm(), h_norm = sub.H.norm();
    detail::require(r1_norm > 0.0,
                    "y has no dynamics: its covariances are zero (is y constant or all zero after removing the mean?)");
    detail::require(h_norm > kNumericallyZero * r1_norm, "the subspace matrix H is numerically zero (|H| / |R1| = ",
                    h_norm / r1_norm, "): the inputs u explain the outputs y exactly, so nothing is left to "
                    "identify (were outputs passed as inputs?)");
    const Realization re(sub.H, L.n_outputs, n_max);
    out.singular_values = re.singular_values();
    out.numerical_rank = re.numerical_rank();
    detail::require(re.numerical_rank() >= 2, "the subspace matrix H has numerical rank ", re.numerical_rank(),
                    ": the record holds no oscillation to identify (is y constant, a step or an impulse?)");

    std::unique_ptr<UncertaintyPropagator> prop;
    Eigen::MatrixXd t_h;
    double block_seconds = 0.0;
    if (options.uncertainty) {
        out.n_blocks = t_r.cols();
        out.block_length = cov.block_length;
        block_seconds = static_cast<double>(cov.block_length) / options.fs;
        out.too_few_blocks = out.n_blocks - 1 < 2 + 2 * L.n_outputs;
        if (out.too_few_blocks)
            out.warn(IdentificationWarning::too_few_blocks, detail::concat(
                "n_blocks = ", out.n_blocks, " is too few for the joint covariance of the ", 2 + 2 * L.n_outputs,
                " parameters of a mode: use n_blocks >= ", 3 + 2 * L.n_outputs,
                " (the standard deviations of f and xi alone are still estimated, but from few blocks)"));
        // T_H lives only while the propagator takes what it needs from it (and the bootstrap).
        NoiseOptions noise;
        noise.freeze = options.freeze_noise;
        noise.floor_factor = options.noise_floor_factor;
        noise.coupling_limit = options.noise_coupling_limit;
        t_h = propagate_to_subspace(sub, cov, std::move(t_r));
        prop = std::make_unique<UncertaintyPropagator>(re, t_h, L.rows_past(), options.threads, noise,
                                                       options.block_correlation_correction,
                                                       options.keep_shape_factor);
        if (options.bootstrap_draws == 0) t_h.resize(0, 0);  // only the bootstrap needs it again
        out.significant_singular_values = prop->significant_singular_values();
        out.signal_to_noise = re.singular_values()(0) / prop->singular_value_std(0);
        // A statistic of the blocks, so a warning, not a refusal: a short record with real
        // dynamics can fall below it by chance (H numerically zero is refused above).
        out.low_signal_to_noise = out.signal_to_noise < kMinSignalToNoise;
        if (out.low_signal_to_noise)
            out.warn(IdentificationWarning::low_signal_to_noise, detail::concat(
                "the subspace matrix H is at the level of its own estimation noise (its largest singular value is ",
                out.signal_to_noise, " standard deviations from zero, fewer than ", kMinSignalToNoise,
                "): the modes cannot be told from noise; use a longer record or check the channels "
                "(outputs passed as inputs? a disconnected sensor?)"));
    }
    // Orders are independent: highest (most expensive) first, on options.threads threads.
    const Index n_orders = static_cast<Index>(options.orders.size());
    out.modes.resize(options.orders.size());
    detail::parallel_for(n_orders, options.threads, [&](Index i) {
        const Index k = n_orders - 1 - i, n = options.orders[k];
        Modes m = degenerate_modes(n, L.n_outputs, prop != nullptr);
        if (n > re.max_order()) {
            m.note = detail::concat("order ", n, " is above the numerical rank of H (", re.numerical_rank(), ")");
        } else {
            try {
                const StateSpace ss = re.system(n);
                Eigenstructure eig;
                m = modes_from_system(ss, options.fs, prop ? &eig : nullptr);
                if (prop) prop->apply(m, eig, ss, options.fs, block_seconds);
            } catch (const numerical_error& e) {
                m = degenerate_modes(n, L.n_outputs, prop != nullptr);
                m.note = e.what();
            }
        }
        out.modes[k] = std::move(m);
    });
    if (prop && options.bootstrap_draws > 0)
        apply_bootstrap(out.modes, sub.H, t_h, L.n_outputs, options.fs, out.significant_singular_values,
                        options.bootstrap_draws, options.threads);
    const std::string degenerate = degenerate_order_list(out.modes);
    if (!degenerate.empty())
        out.warn(IdentificationWarning::degenerate_orders, detail::concat(
            "no modes at order(s) ", degenerate, ": above the numerical rank of H (", re.numerical_rank(),
            ") or no usable eigen-decomposition of A there; use orders <= ", re.max_order()));
    out.slow_decay = count_slow_decay(out.modes, block_seconds, static_cast<double>(cov.n_columns) / options.fs);
    const SlowDecay& slow = out.slow_decay;
    if (slow.n_poles > 0) {
        out.warn(IdentificationWarning::slow_decay, detail::concat(
            slow.n_poles, " pole(s) decay more slowly than the blocks are long (blocks of ", block_seconds,
            " s, less than half of the decay time 1/(2 pi f xi), up to ", slow.longest_decay_s,
            " s); their standard deviations are less reliable: ",
            !slow.record_too_short()
                ? detail::concat("use n_blocks <= ", slow.fitting_n_blocks)
                : std::string("the record is too short for these poles' decay (a longer record is needed)")));
    }
    return out;
}
}  // namespace detail

/// Identify from accumulated covariances (for example from a CovarianceAccumulator fed in
/// chunks). `cov` must carry per-block matrices (at least two) when options.uncertainty is on.
inline Identification identify(const Covariances& cov, IdentifyOptions options) {
    options.validate();
    if (options.uncertainty)
        detail::require(cov.blocks.cols() >= 2, "n_blocks must be >= 2 for the uncertainty, the covariances have ",
                        cov.blocks.cols(), " complete blocks");
    return detail::identify_with_factor(cov, options.uncertainty ? cov.covariance_factor() : Eigen::MatrixXd(),
                                        std::move(options));
}

/// The same, taking the covariances over: their per-block matrices become the covariance
/// factor in place, so the largest object of a run is held once.
inline Identification identify(Covariances&& cov, IdentifyOptions options) {
    options.validate();
    if (options.uncertainty)
        detail::require(cov.blocks.cols() >= 2, "n_blocks must be >= 2 for the uncertainty, the covariances have ",
                        cov.blocks.cols(), " complete blocks");
    Eigen::MatrixXd t_r = options.uncertainty ? std::move(cov).covariance_factor() : Eigen::MatrixXd();
    return detail::identify_with_factor(cov, std::move(t_r), std::move(options));
}

/// Identify from samples. y is n_outputs x n_samples (a column is one sample: the memory of a
/// C-contiguous NumPy (n_samples, n_outputs) array); u is n_inputs x n_samples or empty.
inline Identification identify(const Eigen::Ref<const Eigen::MatrixXd>& y,
                               const Eigen::Ref<const Eigen::MatrixXd>& u, IdentifyOptions options) {
    options.validate();
    detail::require(y.rows() >= 1, "y must have at least one output channel");
    detail::require(u.size() == 0 || u.cols() == y.cols(), "u must have as many samples as y (", y.cols(),
                    "), got ", u.cols());
    detail::require_finite(y, "y");
    if (u.size() > 0) detail::require_finite(u, "u");
    HankelLayout L = options.layout(y.rows(), u.size() == 0 ? 0 : u.rows());
    L.validate();
    if (!options.orders.empty()) {
        const Index n_max = *std::max_element(options.orders.begin(), options.orders.end());
        detail::require(n_max <= L.max_order(), "order ", n_max,
                        " is above what the horizons support: min((block_rows - 1) * n_outputs, past_block_rows * n_references) = ",
                        L.max_order());
    }
    const Index n_blocks = options.uncertainty ? options.n_blocks : 1;
    return identify(compute_covariances(y, u, L, n_blocks, options.demean, options.uncertainty, options.threads),
                    options);
}

}  // namespace modaluq
