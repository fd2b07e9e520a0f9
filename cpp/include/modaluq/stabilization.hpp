#pragma once
/// @file stabilization.hpp
/// The stabilization diagram: every pole of every model order judged on its own and against
/// its match at the previous order, with a status and, unless stable, the reason in words.
/// selection.hpp groups the stable poles into modes.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "errors.hpp"
#include "identify.hpp"
#include "indicators.hpp"
#include "modal.hpp"

namespace modaluq {

/// Outcome of the stability checks for one pole.
enum class PoleStatus : int {
    stable = 0,            ///< passes its own checks and every check against its match
    stable_frequency = 1,  ///< frequency stable, but the damping change or the MAC fails
    unstable = 2,          ///< lowest order, no match at the previous order, or the frequency test fails
    rejected = 3,          ///< implausible on its own (band, damping range, sigma_f / f): never compared
};

inline const char* to_string(PoleStatus s) {
    switch (s) {
        case PoleStatus::stable: return "stable";
        case PoleStatus::stable_frequency: return "stable_frequency";
        case PoleStatus::unstable: return "unstable";
        case PoleStatus::rejected: return "rejected";
    }
    return "?";
}

/// Thresholds of the diagram; fractions unless stated. The Python `StabilityCriteria`
/// documents the reasoning behind each default.
struct StabilityCriteria {
    double max_frequency_change = 0.01;   ///< largest |df| / f_prev between matched poles
    double max_damping_change = 0.10;     ///< largest |dxi| / |xi_prev| (relative test)
    double min_mac = 0.98;                ///< smallest MAC between matched shapes
    /// k of |df| <= k sqrt(sf^2 + sf_prev^2); empty: no sigma test on the frequency
    std::optional<double> frequency_std_factor = 2.0;
    /// largest sigma_f / f of a pole, a loose backstop (the selection judges a cluster's sigma
    /// against its bandwidth f xi); empty: no such test (skipped without uncertainty)
    std::optional<double> max_frequency_cov = 0.05;
    double min_damping_ratio = 0.0;       ///< poles below are rejected
    double max_damping_ratio = 0.20;      ///< poles above are rejected
    /// k of |dxi| <= k sqrt(sxi^2 + sxi_prev^2), replacing the relative damping test (a damping
    /// ratio with sigma_xi = 50 % of xi moves by more than 10 % between orders on noise alone);
    /// empty: the relative test max_damping_change. Skipped without uncertainty.
    std::optional<double> damping_std_factor = 2.0;
    double max_damping_change_with_std = 0.5;  ///< backstop on |dxi| / |xi_prev| with the sigma test
    double match_window = 0.05;           ///< largest |df| / f_prev for a pole to be a match at all
    /// band of interest, Hz (low, high): poles outside are rejected; empty: no band
    std::optional<std::pair<double, double>> frequency_range;
    /// smallest modal phase collinearity of a pole's shape (indicators.hpp), in [0, 1]; poles below
    /// are rejected. Empty (the default): no such test (a complex mode of a non-proportionally
    /// damped structure has a low MPC and is physical)
    std::optional<double> min_mpc;
    /// largest mean phase deviation of a pole's shape, degrees in [0, 90]; poles above are
    /// rejected. Empty (the default): no such test
    std::optional<double> max_mpd_deg;

    void validate() const {
        auto nonneg = [](double x, const char* name) {
            detail::require(std::isfinite(x) && x >= 0.0, name, " must be finite and >= 0, got ", x);
        };
        auto positive = [](const std::optional<double>& x, const char* name) {
            if (x) detail::require(std::isfinite(*x) && *x > 0.0, name, " must be finite and > 0, got ", *x);
        };
        nonneg(max_frequency_change, "max_frequency_change");
        nonneg(max_damping_change, "max_damping_change");
        nonneg(max_damping_change_with_std, "max_damping_change_with_std");
        detail::require(min_mac >= 0.0 && min_mac <= 1.0, "min_mac must be in [0, 1], got ", min_mac);
        positive(frequency_std_factor, "frequency_std_factor");
        positive(max_frequency_cov, "max_frequency_cov");
        positive(damping_std_factor, "damping_std_factor");
        detail::require(std::isfinite(match_window) && match_window > 0.0, "match_window must be finite and > 0, got ",
                        match_window);
        detail::require(min_damping_ratio >= -1.0 && min_damping_ratio <= 1.0,
                        "min_damping_ratio must be in [-1, 1], got ", min_damping_ratio);
        detail::require(max_damping_ratio >= -1.0 && max_damping_ratio <= 1.0,
                        "max_damping_ratio must be in [-1, 1], got ", max_damping_ratio);
        detail::require(max_damping_ratio > min_damping_ratio, "max_damping_ratio must be > min_damping_ratio (",
                        min_damping_ratio, "), got ", max_damping_ratio);
        if (min_mpc) detail::require(*min_mpc >= 0.0 && *min_mpc <= 1.0, "min_mpc must be in [0, 1], got ", *min_mpc);
        if (max_mpd_deg)
            detail::require(*max_mpd_deg >= 0.0 && *max_mpd_deg <= 90.0, "max_mpd_deg must be in [0, 90] degrees, got ",
                            *max_mpd_deg);
        if (frequency_range)
            detail::require(frequency_range->first >= 0.0 && frequency_range->first < frequency_range->second,
                            "frequency_range must be (low, high) Hz with 0 <= low < high, got (",
                            frequency_range->first, ", ", frequency_range->second, ")");
    }
};

using IndexVector = Eigen::Matrix<Index, Eigen::Dynamic, 1>;
using BoolArray = Eigen::Array<bool, Eigen::Dynamic, 1>;

/// Every pole of a multi-order identification in flat arrays, ordered by order then frequency.
struct Poles {
    IndexVector order;                   ///< model order of each pole
    Eigen::VectorXd frequency_hz;        ///< Hz
    Eigen::VectorXd damping_ratio;       ///< fraction
    Eigen::VectorXd frequency_std;       ///< Hz (NaN without uncertainty)
    Eigen::VectorXd damping_std;         ///< fraction (NaN without uncertainty)
    Eigen::MatrixXcd mode_shape;         ///< l x n_poles, largest component 1
    Eigen::MatrixXd mode_shape_std_real; ///< l x n_poles (NaN without uncertainty)
    Eigen::MatrixXd mode_shape_std_imag; ///< l x n_poles
    BoolArray close_singular_values;     ///< the pole's order cuts close significant singular values
    BoolArray noise_coupled;             ///< no first-order sigma (docs/uq-math.md §5.5)
    /// Modes::frequency_damping_correlation of each pole (NaN without uncertainty); may be empty
    /// (unknown: SelectedModes reports NaN).
    Eigen::VectorXd frequency_damping_correlation;
    /// Modes::block_too_short of each pole; may be empty (unknown: taken as false).
    BoolArray block_too_short;
    /// Modes::noise_coupling of each pole (rho: unfrozen over frozen sigma, 1 at orders <= k*; NaN
    /// without uncertainty); may be empty (unknown: the selection's unanchored rule is off).
    Eigen::VectorXd noise_coupling;
    /// Modes::frequency_damping_factor of each pole: 2 n_b x n_poles, column i [u_f^T; u_xi^T] (Hz,
    /// fraction), the first-order factor rows of f and xi (2 n_b doubles per pole). May be empty
    /// (0 columns: unknown; the selection's ClusterStd::mean then falls back to the median).
    Eigen::MatrixXd frequency_damping_factor;
    std::vector<Index> orders;           ///< identified orders, ascending (an order may hold no pole)
    /// k*, the significant singular values of H (Identification::significant_singular_values):
    /// a pole at a lower order comes from a model that cuts signal, and is biased. 0: unknown.
    Index noise_floor_order = 0;
    bool has_uncertainty = true;         ///< the std fields are estimates (false: all NaN)

    Index size() const { return frequency_hz.size(); }

    void validate() const {
        const Index n = size();
        detail::require(order.size() == n && damping_ratio.size() == n && frequency_std.size() == n &&
                            damping_std.size() == n && close_singular_values.size() == n &&
                            noise_coupled.size() == n,
                        "poles: every per-pole array must have ", n, " entries");
        detail::require((frequency_damping_correlation.size() == 0 || frequency_damping_correlation.size() == n) &&
                            (block_too_short.size() == 0 || block_too_short.size() == n) &&
                            (noise_coupling.size() == 0 || noise_coupling.size() == n),
                        "poles: frequency_damping_correlation, block_too_short and noise_coupling must be empty "
                        "or have ", n, " entries");
        detail::require(frequency_damping_factor.cols() == 0 ||
                            (frequency_damping_factor.cols() == n && frequency_damping_factor.rows() % 2 == 0),
                        "poles: frequency_damping_factor must be empty or 2 n_b x ", n, ", got ",
                        frequency_damping_factor.rows(), " x ", frequency_damping_factor.cols());
        detail::require(mode_shape.cols() == n && mode_shape_std_real.cols() == n &&
                            mode_shape_std_imag.cols() == n && mode_shape_std_real.rows() == mode_shape.rows() &&
                            mode_shape_std_imag.rows() == mode_shape.rows(),
                        "poles: mode_shape and its std must be n_outputs x ", n);
        for (std::size_t j = 1; j < orders.size(); ++j)
            detail::require(orders[j] > orders[j - 1], "poles: orders must be strictly ascending");
        for (Index i = 0; i < n; ++i) {
            detail::require(std::isfinite(frequency_hz(i)) && frequency_hz(i) > 0.0 && std::isfinite(damping_ratio(i)),
                            "poles: pole ", i, " has a frequency or damping ratio that is not finite (or f <= 0)");
            detail::require(i == 0 || order(i) >= order(i - 1), "poles: poles must be ordered by model order");
        }
    }
};

/// The poles of an identification, flattened.
inline Poles poles_of(const Identification& id) {
    Index n = 0, l = 0;
    for (const Modes& m : id.modes) {
        n += m.n_modes();
        l = std::max(l, m.mode_shape.rows());
    }
    const double nan = std::numeric_limits<double>::quiet_NaN();
    Poles p;
    p.has_uncertainty = true;
    p.noise_floor_order = id.significant_singular_values;
    // the factor rows when every order with modes has them, all with one n_b (else none)
    Index factor_rows = 0;
    bool factor_known = true;
    for (const Modes& m : id.modes) {
        if (m.n_modes() == 0) continue;
        if (m.frequency_std.size() != m.n_modes()) p.has_uncertainty = false;
        const Eigen::MatrixXd& u = m.frequency_damping_factor;
        if (u.cols() != m.n_modes() || u.rows() == 0 || (factor_rows > 0 && u.rows() != factor_rows))
            factor_known = false;
        else
            factor_rows = u.rows();
    }
    if (!p.has_uncertainty || !factor_known) factor_rows = 0;
    p.frequency_damping_factor.resize(factor_rows, factor_rows > 0 ? n : 0);
    p.order.resize(n);
    p.frequency_hz.resize(n);
    p.damping_ratio.resize(n);
    p.frequency_std.setConstant(n, nan);
    p.damping_std.setConstant(n, nan);
    p.mode_shape.resize(l, n);
    p.mode_shape_std_real.setConstant(l, n, nan);
    p.mode_shape_std_imag.setConstant(l, n, nan);
    p.close_singular_values.setConstant(n, false);
    p.noise_coupled.setConstant(n, false);
    p.frequency_damping_correlation.setConstant(n, nan);
    p.block_too_short.setConstant(n, false);
    p.noise_coupling.setConstant(n, nan);
    Index at = 0;
    for (const Modes& m : id.modes) {
        p.orders.push_back(m.order);
        const Index k = m.n_modes();
        if (k == 0) continue;
        p.order.segment(at, k).setConstant(m.order);
        p.frequency_hz.segment(at, k) = m.frequency_hz;
        p.damping_ratio.segment(at, k) = m.damping_ratio;
        p.mode_shape.middleCols(at, k) = m.mode_shape;
        p.close_singular_values.segment(at, k).setConstant(m.close_singular_values);
        if (p.has_uncertainty) {
            p.frequency_std.segment(at, k) = m.frequency_std;
            p.damping_std.segment(at, k) = m.damping_std;
            p.mode_shape_std_real.middleCols(at, k) = m.mode_shape_std_real;
            p.mode_shape_std_imag.middleCols(at, k) = m.mode_shape_std_imag;
            if (m.noise_coupled.size() == k) p.noise_coupled.segment(at, k) = m.noise_coupled;
            if (m.frequency_damping_correlation.size() == k)
                p.frequency_damping_correlation.segment(at, k) = m.frequency_damping_correlation;
            if (m.block_too_short.size() == k) p.block_too_short.segment(at, k) = m.block_too_short;
            if (m.noise_coupling.size() == k) p.noise_coupling.segment(at, k) = m.noise_coupling;
            if (factor_rows > 0) p.frequency_damping_factor.middleCols(at, k) = m.frequency_damping_factor;
        }
        at += k;
    }
    return p;
}

/// Modal assurance criterion between every column of a and every column of b (m x k), in
/// [0, 1]; 0 where a shape is zero.
inline Eigen::MatrixXd modal_assurance_criterion(const Eigen::Ref<const Eigen::MatrixXcd>& a,
                                                 const Eigen::Ref<const Eigen::MatrixXcd>& b) {
    detail::require(a.rows() == b.rows(), "modal_assurance_criterion: shapes must have the same number of rows, got ",
                    a.rows(), " and ", b.rows());
    const Eigen::MatrixXd cross = (a.adjoint() * b).cwiseAbs2();
    const Eigen::VectorXd na = a.colwise().squaredNorm().transpose(), nb = b.colwise().squaredNorm().transpose();
    Eigen::MatrixXd mac(a.cols(), b.cols());
    for (Index j = 0; j < b.cols(); ++j)
        for (Index i = 0; i < a.cols(); ++i) {
            const double den = na(i) * nb(j);
            mac(i, j) = den > 0.0 ? std::clamp(cross(i, j) / den, 0.0, 1.0) : 0.0;
        }
    return mac;
}

namespace detail {

/// MAC of two shapes (the entry of modal_assurance_criterion, without allocating).
inline double mac_pair(const Eigen::Ref<const Eigen::VectorXcd>& a, const Eigen::Ref<const Eigen::VectorXcd>& b) {
    const double den = a.squaredNorm() * b.squaredNorm();
    return den > 0.0 ? std::clamp(std::norm(a.dot(b)) / den, 0.0, 1.0) : 0.0;
}

}  // namespace detail

/// Every pole with its status and the comparison with its match at the previous order.
struct Diagram {
    Poles poles;                          ///< what was judged
    std::vector<PoleStatus> status;       ///< per pole
    std::vector<std::string> reason;      ///< per pole, "" for stable poles
    IndexVector matched_pole;             ///< index of the match at the previous order, -1 if none
    Eigen::VectorXd frequency_change;     ///< |df| / f_prev (NaN without a match)
    Eigen::VectorXd damping_change;       ///< |dxi| / |xi_prev|
    Eigen::VectorXd mac;                  ///< MAC with the match
    Eigen::VectorXd frequency_change_std; ///< |df| / sqrt(sf^2 + sf_prev^2) (NaN without the sigma test)
    Eigen::VectorXd mpc;                  ///< modal phase collinearity of each pole's shape (indicators.hpp)
    Eigen::VectorXd mpd_deg;              ///< mean phase deviation of each pole's shape, degrees
    StabilityCriteria criteria;           ///< the thresholds applied

    Index size() const { return poles.size(); }
};

namespace detail {

inline std::string format_number(const char* format, double x) {
    char buf[64];
    std::snprintf(buf, sizeof buf, format, x);
    return buf;
}

/// "1.23 %" for 0.0123 (three significant digits, as the Python side prints).
inline std::string percent(double x) { return format_number("%.3g", 100.0 * x) + " %"; }

inline std::string join(const std::vector<std::string>& parts) {
    std::string s;
    for (const std::string& p : parts) s += (s.empty() ? "" : "; ") + p;
    return s;
}

}  // namespace detail

/// Judge every pole (see StabilityCriteria). A pole is first checked on its own (band,
/// damping range, sigma_f / f); the others are compared with the pole of the previous order
/// that minimises |df| / f_prev + (1 - MAC) among that order's non-rejected poles within
/// match_window, and are stable when the frequency (relative and sigma tests), the damping
/// and the MAC pass.
inline Diagram stabilization_diagram(Poles poles, const StabilityCriteria& criteria = {}) {
    criteria.validate();
    poles.validate();
    const StabilityCriteria& c = criteria;
    const Index n = poles.size();
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    const bool has_std = poles.has_uncertainty;
    const Eigen::VectorXd &f = poles.frequency_hz, &xi = poles.damping_ratio, &sf = poles.frequency_std,
                          &sxi = poles.damping_std;
    Diagram d;
    d.criteria = c;
    d.status.assign(n, PoleStatus::rejected);
    d.reason.assign(n, "");
    d.matched_pole.setConstant(n, -1);
    d.frequency_change.setConstant(n, nan);
    d.damping_change.setConstant(n, nan);
    d.mac.setConstant(n, nan);
    d.frequency_change_std.setConstant(n, nan);

    using detail::format_number;
    using detail::percent;
    d.mpc.setConstant(n, nan);
    d.mpd_deg.setConstant(n, nan);
    std::vector<char> valid(n, 0);
    for (Index i = 0; i < n; ++i) {
        const Eigen::VectorXcd shape = poles.mode_shape.col(i);
        if (shape.allFinite() && shape.squaredNorm() > 0.0) {
            d.mpc(i) = modal_phase_collinearity(shape);
            d.mpd_deg(i) = mean_phase_deviation(shape).value;
        }
        std::vector<std::string> why;
        if (c.frequency_range && !(c.frequency_range->first <= f(i) && f(i) <= c.frequency_range->second))
            why.push_back("outside the band " + format_number("%g", c.frequency_range->first) + "-" +
                          format_number("%g", c.frequency_range->second) + " Hz");
        if (xi(i) < c.min_damping_ratio)
            why.push_back("damping ratio " + percent(xi(i)) + " < " + percent(c.min_damping_ratio));
        if (xi(i) > c.max_damping_ratio)
            why.push_back("damping ratio " + percent(xi(i)) + " > " + percent(c.max_damping_ratio));
        if (has_std && c.max_frequency_cov) {
            if (!std::isfinite(sf(i)))
                why.push_back("frequency std not finite");
            else if (sf(i) / f(i) > *c.max_frequency_cov)
                why.push_back("frequency std/f " + percent(sf(i) / f(i)) + " > " + percent(*c.max_frequency_cov));
        }
        if (c.min_mpc && !(d.mpc(i) >= *c.min_mpc))
            why.push_back("MPC " + format_number("%.3g", d.mpc(i)) + " < " + format_number("%.3g", *c.min_mpc));
        if (c.max_mpd_deg && !(d.mpd_deg(i) <= *c.max_mpd_deg))
            why.push_back("MPD " + format_number("%.3g", d.mpd_deg(i)) + " deg > " +
                          format_number("%.3g", *c.max_mpd_deg) + " deg");
        if (why.empty()) valid[i] = 1;
        else d.reason[i] = detail::join(why);
    }

    // The sigma tests run only with uncertainty (0: off; plain doubles keep GCC's
    // maybe-uninitialized analysis of std::optional quiet).
    const double k_std = has_std && c.frequency_std_factor ? *c.frequency_std_factor : 0.0;
    const double k_xi = has_std && c.damping_std_factor ? *c.damping_std_factor : 0.0;
    auto at_order = [&](Index order) {
        std::vector<Index> idx;
        for (Index i = 0; i < n; ++i)
            if (poles.order(i) == order && valid[i]) idx.push_back(i);
        return idx;
    };
    for (std::size_t j = 0; j < poles.orders.size(); ++j) {
        const std::vector<Index> cur = at_order(poles.orders[j]);
        if (j == 0) {
            for (Index i : cur) {
                d.status[i] = PoleStatus::unstable;
                d.reason[i] = "lowest order: no previous order to compare";
            }
            continue;
        }
        const Index prev_order = poles.orders[j - 1];
        const std::string vs = " (vs order " + std::to_string(prev_order) + ")";
        const std::vector<Index> prev = at_order(prev_order);
        if (prev.empty()) {
            for (Index i : cur) {
                d.status[i] = PoleStatus::unstable;
                d.reason[i] = "no accepted pole at the previous order " + std::to_string(prev_order);
            }
            continue;
        }
        for (Index i : cur) {
            Index p = -1;
            double best = inf, best_rel = nan, best_mac = nan;
            for (Index q : prev) {
                const double rel = std::abs(f(i) - f(q)) / f(q);
                if (!(rel <= c.match_window)) continue;
                const double m = detail::mac_pair(poles.mode_shape.col(i), poles.mode_shape.col(q));
                if (rel + (1.0 - m) < best) { best = rel + (1.0 - m); p = q; best_rel = rel; best_mac = m; }
            }
            if (p < 0) {
                d.status[i] = PoleStatus::unstable;
                d.reason[i] = "no match: no pole within " + percent(c.match_window) +
                              " in frequency at the previous order " + std::to_string(prev_order);
                continue;
            }
            d.matched_pole(i) = p;
            d.frequency_change(i) = best_rel;
            d.mac(i) = best_mac;
            d.damping_change(i) = xi(p) != 0.0 ? std::abs(xi(i) - xi(p)) / std::abs(xi(p)) : (xi(i) == 0.0 ? 0.0 : inf);
            std::vector<std::string> why;
            if (best_rel > c.max_frequency_change)
                why.push_back("frequency change " + percent(best_rel) + " > " + percent(c.max_frequency_change));
            if (k_std > 0.0) {
                const double comb = std::hypot(sf(i), sf(p));
                d.frequency_change_std(i) = comb > 0.0 ? std::abs(f(i) - f(p)) / comb : inf;
                if (d.frequency_change_std(i) > k_std)
                    why.push_back("frequency change " + format_number("%.3g", std::abs(f(i) - f(p))) + " Hz > " +
                                  format_number("%g", k_std) + " x combined std " + format_number("%.3g", comb) +
                                  " Hz");
            }
            if (!why.empty()) {
                d.status[i] = PoleStatus::unstable;
            } else {
                const double comb_xi = k_xi > 0.0 ? std::hypot(sxi(i), sxi(p)) : nan;
                if (k_xi > 0.0 && std::isfinite(comb_xi)) {
                    if (std::abs(xi(i) - xi(p)) > k_xi * comb_xi)
                        why.push_back("damping change " + format_number("%.3g", std::abs(xi(i) - xi(p))) + " > " +
                                      format_number("%g", k_xi) + " x combined std " +
                                      format_number("%.3g", comb_xi));
                    else if (d.damping_change(i) > c.max_damping_change_with_std)
                        why.push_back("damping change " + percent(d.damping_change(i)) + " > " +
                                      percent(c.max_damping_change_with_std));
                } else if (d.damping_change(i) > c.max_damping_change) {
                    why.push_back("damping change " + percent(d.damping_change(i)) + " > " +
                                  percent(c.max_damping_change));
                }
                if (best_mac < c.min_mac) why.push_back("MAC " + format_number("%.4f", best_mac) + " < " +
                                                        format_number("%g", c.min_mac));
                d.status[i] = why.empty() ? PoleStatus::stable : PoleStatus::stable_frequency;
            }
            d.reason[i] = why.empty() ? "" : detail::join(why) + vs;
        }
    }
    d.poles = std::move(poles);
    return d;
}

/// The diagram of an identification; `frequency_range` of the criteria limits it to a band.
inline Diagram stabilization_diagram(const Identification& id, const StabilityCriteria& criteria = {}) {
    return stabilization_diagram(poles_of(id), criteria);
}

}  // namespace modaluq
