#pragma once
/// @file selection.hpp
/// Automatic mode selection: the stable poles of a Diagram grouped into physical modes by
/// hierarchical clustering on frequency and MAC, each mode reported with a sigma that does not
/// depend on the order it is read at and with the spread of its cluster beside it.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "detail/linkage.hpp"
#include "errors.hpp"
#include "stabilization.hpp"

namespace modaluq {

/// Which sigma of f and xi select_modes reports for a cluster (ClusteringOptions::cluster_std).
/// Over the cluster's reliable poles (not at a close cut, not noise-coupled, unless most of the
/// cluster is: then the coupled poles too), K of them:
enum class ClusterStd : int {
    /// the median of their sigma: one order's sigma, whichever order the mode is read at
    median = 0,
    /// the sigma of their mean, |(1/K) sum_m u_m| from the rows u_m of Poles::frequency_damping_factor
    /// (docs/uq-math.md §13.10): what the selected value scatters like when the poles of one
    /// identification decorrelate across orders (a multi-setup merge). The median where the poles
    /// carry no factor rows.
    mean = 1,
};

inline const char* to_string(ClusterStd c) {
    switch (c) {
        case ClusterStd::median: return "median";
        case ClusterStd::mean: return "mean";
    }
    return "?";
}

/// Which member of a cluster select_modes reports (ClusteringOptions::representative for its
/// frequency and damping ratio, ClusteringOptions::shape_representative for its shape).
enum class Representative : int {
    /// the candidate nearest to the cluster's median (f, xi), each in its median sigma
    median = 0,
    /// the candidate at the lowest order n >= max(k*, 2 m), k* the noise floor
    /// (Poles::noise_floor_order) and m the number of selected modes (two states each): below
    /// that the model cuts signal and the pole is biased. The highest candidate when none is that
    /// high. The mode is then that pole, sigma included (ClusterStd is not used): at that order
    /// the first-order sigma is calibrated, while higher orders' noise directions make the
    /// shapes' sigma too small and lightly excited modes mix with spurious poles (docs/shapes.md §6)
    lowest = 1,
};

inline const char* to_string(Representative r) {
    switch (r) {
        case Representative::median: return "median";
        case Representative::lowest: return "lowest";
    }
    return "?";
}

/// How select_modes groups poles into modes.
struct ClusteringOptions {
    /// Cut height on d_ij = |f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij) (e.g. 1 % in frequency
    /// plus MAC 0.99).
    double distance_threshold = 0.02;
    /// Clusters with fewer members (one pole per order) are dropped; 0: min_cluster_fraction of
    /// the orders from the lowest order holding a clustered pole upwards, rounded up, at least 3.
    Index min_cluster_size = 0;
    double min_cluster_fraction = 0.25;  ///< in (0, 1], used when min_cluster_size is 0
    /// With min_cluster_size 0: count the orders from each cluster's own lowest order (true) or
    /// from the lowest order of any clustered pole (false).
    bool per_cluster_min_size = false;
    /// Clusters whose median sigma_f / (f xi) exceeds this are dropped: the frequency is less
    /// certain than the half-power half-bandwidth f xi of the peak it claims, which a structural
    /// mode identified from a record of many decay times never is (its ratio is about
    /// 1 / sqrt(2 pi f T xi) for a record of T s), while spurious poles, whose sigma the noise
    /// directions inflate, typically have 2-5. Empty: no such test; skipped without uncertainty.
    std::optional<double> max_frequency_std_per_bandwidth = 1.0;
    /// Join clusters that are pieces of one mode: frequencies within fragment_std_factor combined
    /// sigma, shapes with MAC >= fragment_min_mac, and (a mode has one pole per order) at most
    /// fragment_max_shared of the smaller piece's orders in common. Two modes present at the same
    /// orders, however close, stay apart. Skipped without uncertainty.
    bool merge_fragments = true;
    /// Drop the later of two selected clusters within doublet_window in frequency whose shapes
    /// have MAC >= doublet_min_mac: above the true order one mode is often fitted by a pair of
    /// poles with the same shape (its twin a few per cent away, often lightly damped), and the
    /// twin appears at higher orders than the mode. "Later": the higher first order, then fewer
    /// poles. Two physical modes so close and so alike in shape are not told apart by the
    /// sensors anyway; the dropped twin is listed with its reason.
    bool drop_doublets = true;
    /// Drop a lightly damped twin born of the noise: a cluster that first appears above the noise
    /// floor k* (Poles::noise_floor_order), at a higher order than a kept mode, inside that mode's
    /// half-power band (|f - f_mode| < f_mode xi_mode, median values) and less than half as damped.
    /// Above k* the added states fit the estimation error of the covariances, whose tail at long
    /// lags oscillates at the mode's frequency without decaying; SSI fits it with a lightly damped
    /// pole beside the mode, whose shape need not resemble the mode's with few sensors (so
    /// drop_doublets' MAC does not catch it). Half the damping keeps a close physical pair (two
    /// 1 % modes 1 % apart, one first seen above k*: tests/python/test_hard_cases.py). The
    /// paper's chain, output-only, 400 s: such a twin is selected 47 times in 300 records (xi
    /// 0.1-0.5 % beside modes of 2 %), and reading it as the mode put xi 10-15 of its sigma off
    /// (docs/validation.md, issue 27 (i)). A physical mode has signal singular values, so it is
    /// born at or below k*; a record whose k* is far above the modes' order (measured records:
    /// 34-46) drops nothing. Needs the noise floor (uncertainty).
    bool drop_noise_twins = true;
    /// Before drop_doublets: of two alike clusters (within doublet_window, MAC >= doublet_min_mac),
    /// the earlier one's poles at orders below the later one's first order go to the later one when
    /// every one of them is nearer to its median frequency and to its median damping ratio. A
    /// lightly damped cluster fed by the noise can take a mode's lowest-order poles (the chain's
    /// 15.8 Hz mode, input/output: poles of orders 4-6 at 15.81 Hz, xi 2.0 %, in a 15.99 Hz, xi
    /// 0.3 % cluster born at order 14, the mode from order 8); it is then the earlier of the two,
    /// and drop_doublets would keep it and drop the mode as its twin. The poles moved are of
    /// orders the other cluster lacks, so each keeps one pole per order; a cluster gives or takes
    /// once (ties: first order, then first pole); the clusters that gave or took are judged again
    /// by the size and bandwidth rules (one that gave all its poles is gone). Needs drop_doublets.
    bool reassign_borrowed_poles = true;
    double doublet_window = 0.05;
    double doublet_min_mac = 0.8;
    double fragment_std_factor = 3.0;
    double fragment_min_mac = 0.8;
    double fragment_max_shared = 0.25;
    std::vector<PoleStatus> statuses{PoleStatus::stable};  ///< which poles are clustered
    Linkage linkage = Linkage::average;  ///< see detail/linkage.hpp
    Representative representative = Representative::median;  ///< see Representative
    /// The member that gives each mode's shape and its sigma (SelectedModes::shape_pole). Default
    /// lowest: the lowest reliable member at an order n >= max(k*, 2 m), whose shape sigma is
    /// calibrated where the median member's, often far above the true order, is too small because
    /// the noise directions there are frozen (docs/shapes.md §6); the representative itself when
    /// that member is not below it and the representative's order holds every selected mode
    /// (>= 2 m; a high k* on a measured record). median: the representative. With representative
    /// lowest both are that pole.
    Representative shape_representative = Representative::lowest;
    /// The sigma of f and xi reported per mode (SelectedModes::frequency_std, damping_std,
    /// frequency_damping_correlation); the clusters, the representative and its value, and the
    /// tests on the poles' own sigma (max_frequency_std_per_bandwidth, merge_fragments) do not
    /// depend on it. Default median: one record's poles are nearly collinear across orders, where
    /// the two agree. The Python identify_setups selects with mean: a merge's poles decorrelate
    /// across orders and the median overstates the scatter of the selected value (issue 23).
    ClusterStd cluster_std = ClusterStd::median;
    /// Widen sigma_f and sigma_xi by the model order's own effect where it shows: where the
    /// representative's f (or xi) differs from that of the cluster's lowest sufficient member (the
    /// default shape pole, Representative::lowest) by more than 1.96 of the two poles' combined
    /// sigma, the reported sigma becomes sqrt(sigma^2 + difference^2) (SelectedModes::order_discrepancy).
    /// Above the true order a spurious pole can take part of a mode at every order from some
    /// order on, biasing its damping several sigma (the chain's 14.5 Hz mode: 1.6 % below order
    /// 22, 0.4 % above, sigma 0.1 %); no first-order sigma of one pole sees that, the two orders
    /// do. Fires on about 5 % of the output-only and 2 % of the input/output modes of the
    /// simulations (docs/validation.md, issue 27 (h)).
    bool order_discrepancy = true;
    /// A mode with no order below its own noise floor: when every reliable member of a cluster
    /// (the cluster not mostly noise-coupled) has Poles::noise_coupling rho above this, none of its
    /// poles is free of the frozen noise directions (k* below the mode's own singular values, a
    /// weak mode), and their frozen sigma can be several times too small. The reported sigma_f and
    /// sigma_xi become at least the median over those members of rho sigma, the unfrozen sigma's
    /// bound (SelectedModes::unanchored). A mode read at some order <= k* has rho = 1 there. The
    /// chain's 1.9 Hz input/output mode (k* = 11 < 12: rho 2.5-5.5 at every order, sigma_xi 3.5x
    /// too small) and its 17 Hz output-only mode (k* = 8: rho 6.8-14); it fires on 3-7 % of the
    /// simulations' weakest modes, and the 1.9 Hz xi coverage goes from 0.90 to 0.93
    /// (docs/validation.md, issue 27 (n)). Empty, or poles without noise_coupling: no such rule.
    std::optional<double> unanchored_noise_coupling = 2.0;

    void validate() const {
        detail::require(std::isfinite(distance_threshold) && distance_threshold > 0.0,
                        "distance_threshold must be finite and > 0, got ", distance_threshold);
        detail::require(min_cluster_size >= 0, "min_cluster_size must be >= 1 (or 0 for the default), got ",
                        min_cluster_size);
        detail::require(min_cluster_fraction > 0.0 && min_cluster_fraction <= 1.0,
                        "min_cluster_fraction must be in (0, 1], got ", min_cluster_fraction);
        detail::require(!statuses.empty(), "statuses must not be empty");
        detail::require(std::isfinite(doublet_window) && doublet_window >= 0.0,
                        "doublet_window must be finite and >= 0, got ", doublet_window);
        detail::require(doublet_min_mac >= 0.0 && doublet_min_mac <= 1.0, "doublet_min_mac must be in [0, 1], got ",
                        doublet_min_mac);
        detail::require(std::isfinite(fragment_std_factor) && fragment_std_factor >= 0.0,
                        "fragment_std_factor must be finite and >= 0, got ", fragment_std_factor);
        detail::require(fragment_min_mac >= 0.0 && fragment_min_mac <= 1.0, "fragment_min_mac must be in [0, 1], got ",
                        fragment_min_mac);
        detail::require(fragment_max_shared >= 0.0 && fragment_max_shared <= 1.0,
                        "fragment_max_shared must be in [0, 1], got ", fragment_max_shared);
        if (max_frequency_std_per_bandwidth)
            detail::require(*max_frequency_std_per_bandwidth > 0.0, "max_frequency_std_per_bandwidth must be > 0, got ",
                            *max_frequency_std_per_bandwidth);
        if (unanchored_noise_coupling)
            detail::require(std::isfinite(*unanchored_noise_coupling) && *unanchored_noise_coupling >= 1.0,
                            "unanchored_noise_coupling must be finite and >= 1 (rho is 1 where nothing is frozen), got ",
                            *unanchored_noise_coupling);
    }
};

/// Why select_modes dropped a cluster; the numbers behind each are in SelectedModes::dropped_*.
enum class DropReason : int {
    /// fewer poles (one per order) than the minimum size: dropped_n_poles < dropped_min_size
    too_few_poles = 0,
    /// median sigma_f / (f xi) above the limit: dropped_frequency_std_per_bandwidth >
    /// max_frequency_std_per_bandwidth (the frequency is less certain than the peak's half-power
    /// bandwidth)
    frequency_std_above_bandwidth = 1,
    /// a twin of a kept mode (ClusteringOptions::drop_doublets): dropped_twin_mode, its median
    /// frequency dropped_twin_frequency_hz, the MAC dropped_twin_mac, first orders
    /// dropped_first_order and order_min of the mode
    twin = 2,
    /// a lightly damped twin born of the noise (ClusteringOptions::drop_noise_twins): the same
    /// fields as twin; less than half as damped as the mode, inside its half-power band, first order
    /// dropped_first_order above the noise floor
    noise_twin = 3,
};

inline const char* to_string(DropReason r) {
    switch (r) {
        case DropReason::too_few_poles: return "too_few_poles";
        case DropReason::frequency_std_above_bandwidth: return "frequency_std_above_bandwidth";
        case DropReason::twin: return "twin";
        case DropReason::noise_twin: return "noise_twin";
    }
    return "?";
}

/// Modes chosen from a Diagram, sorted by frequency. f and xi are those of one representative
/// pole, the shape and its sigma those of the shape pole (the representative unless
/// ClusteringOptions::shape_representative says lowest); frequency_std and damping_std are over
/// the cluster's reliable poles (not at a close cut, not noise-coupled unless most of the cluster
/// is): the median of their sigma, or the sigma of their mean (ClusteringOptions::cluster_std),
/// widened where the model order moves the estimate beyond it
/// (ClusteringOptions::order_discrepancy); *_spread is the sample std
/// (ddof 1) across the cluster, how much the estimate moves with the order.
struct SelectedModes {
    Eigen::VectorXd frequency_hz;           ///< Hz
    Eigen::VectorXd damping_ratio;          ///< fraction
    Eigen::MatrixXcd mode_shape;            ///< l x n_modes, largest component 1
    Eigen::VectorXd frequency_std;          ///< Hz, analytic, over the reliable poles (cluster_std)
    Eigen::VectorXd damping_std;            ///< fraction
    Eigen::MatrixXd mode_shape_std_real;    ///< l x n_modes, of the shape pole
    Eigen::MatrixXd mode_shape_std_imag;    ///< l x n_modes
    Eigen::VectorXd frequency_spread;       ///< Hz, std across the cluster
    Eigen::VectorXd damping_spread;         ///< fraction
    Eigen::MatrixXd mode_shape_spread_real; ///< l x n_modes, shapes scaled to the shape pole's reference
    Eigen::MatrixXd mode_shape_spread_imag; ///< l x n_modes
    Eigen::VectorXd min_mac;                ///< smallest MAC between the shape pole and a member
    IndexVector representative_order;       ///< model order of the representative
    IndexVector representative_pole;        ///< its index in the diagram
    /// the member whose shape (and its sigma, spread reference and min_mac) the mode reports
    /// (ClusteringOptions::shape_representative): by default the cluster's lowest sufficient
    /// member, the representative where it is lower and of order >= 2 m
    IndexVector shape_pole;
    IndexVector shape_order;                ///< its model order
    IndexVector n_poles;                    ///< members of each cluster
    IndexVector order_min, order_max;       ///< lowest / highest order in each cluster
    std::vector<std::vector<Index>> members;  ///< per mode, the diagram indices of its poles (ascending)
    IndexVector mode_of_pole;               ///< per diagram pole, its mode, -1 if none
    Eigen::VectorXd dropped_frequency_hz;   ///< median frequency of each dropped cluster, Hz
    IndexVector dropped_n_poles;            ///< size of each dropped cluster
    std::vector<std::string> dropped_reason;  ///< why each cluster was dropped, in words (for C++ users)
    std::vector<DropReason> dropped_code;   ///< why each cluster was dropped
    IndexVector dropped_min_size;           ///< the minimum size that applied to each dropped cluster
    IndexVector dropped_first_order;        ///< lowest order of each dropped cluster
    /// median sigma_f / (f xi) of each dropped cluster (NaN where not judged: no uncertainty or no limit)
    Eigen::VectorXd dropped_frequency_std_per_bandwidth;
    IndexVector dropped_twin_mode;          ///< twin, noise_twin: the mode (index into these) it twins, else -1
    Eigen::VectorXd dropped_twin_frequency_hz;  ///< twin, noise_twin: that mode's median frequency, Hz, else NaN
    Eigen::VectorXd dropped_twin_mac;       ///< twin, noise_twin: MAC between the two shapes, else NaN
    /// per mode, median sigma_f / (f xi) over its cluster (NaN without uncertainty)
    Eigen::VectorXd frequency_std_per_bandwidth;
    /// per mode, the correlation of f and xi: the representative pole's (Poles::frequency_damping_correlation;
    /// NaN without uncertainty or when the poles do not carry it), or with ClusterStd::mean from the
    /// factor rows the sigma are (u_f . u_xi / (|u_f| |u_xi|) of the mean rows)
    Eigen::VectorXd frequency_damping_correlation;
    /// per mode, the representative pole's blocks are shorter than half its decay time
    /// (Modes::block_too_short): its sigma are less reliable
    BoolArray block_too_short;
    /// per mode, frequency_std or damping_std were widened by the difference between the
    /// representative and the lowest sufficient member (ClusteringOptions::order_discrepancy):
    /// the estimate moves with the model order beyond its sigma
    BoolArray order_discrepancy;
    /// per mode, every reliable member depends on the frozen noise directions (noise_coupling above
    /// ClusteringOptions::unanchored_noise_coupling at every order): frequency_std and damping_std
    /// are at least the members' median rho sigma
    BoolArray unanchored;
    Index min_cluster_size = 0;             ///< the size threshold applied (the smallest, per cluster)
    /// the limit on sigma_f / (f xi) applied (NaN: no such test, or no uncertainty)
    double max_frequency_std_per_bandwidth = std::numeric_limits<double>::quiet_NaN();

    Index n_modes() const { return frequency_hz.size(); }
};

namespace detail {

inline double median(std::vector<double> x) {
    const std::size_t n = x.size();
    std::sort(x.begin(), x.end());
    return n % 2 ? x[n / 2] : 0.5 * (x[n / 2 - 1] + x[n / 2]);
}

/// Sample standard deviation with ddof (0 or 1).
inline double sample_std(const std::vector<double>& x, int ddof) {
    double mean = 0.0;
    for (double v : x) mean += v;
    mean /= double(x.size());
    double ss = 0.0;
    for (double v : x) ss += (v - mean) * (v - mean);
    return std::sqrt(ss / double(Index(x.size()) - ddof));
}

/// Join the clusters that are pieces of one mode (ClusteringOptions::merge_fragments): largest
/// first, each absorbs every other cluster that sits within fragment_std_factor combined sigma
/// in frequency (median frequency, median sigma_f), has a shape with MAC >= fragment_min_mac
/// (poles nearest to the medians) and shares at most fragment_max_shared of the smaller
/// piece's orders; repeated until nothing joins. Pieces arise where the shape of a mode varies
/// with the order (close modes, few sensors) and the frequency-and-MAC distance splits its
/// column; each piece alone may be too small to be selected.
template <class Thin>
std::vector<std::vector<Index>> merge_fragments(std::vector<std::vector<Index>> clusters, const Poles& P,
                                                const Thin& thin, const ClusteringOptions& o) {
    struct Summary {
        double f, sigma;
        Index rep;
        std::vector<Index> orders;
    };
    auto summarise = [&](const std::vector<Index>& all) {
        const std::vector<Index> one = thin(all);
        std::vector<double> fv, sv;
        for (Index i : one) {
            fv.push_back(P.frequency_hz(i));
            if (std::isfinite(P.frequency_std(i))) sv.push_back(P.frequency_std(i));
        }
        Summary s{median(fv), sv.empty() ? 0.0 : median(sv), one[0], {}};
        for (Index i : one) {
            if (std::abs(P.frequency_hz(i) - s.f) < std::abs(P.frequency_hz(s.rep) - s.f)) s.rep = i;
            s.orders.push_back(P.order(i));
        }
        return s;
    };
    for (bool joined = true; joined;) {
        joined = false;
        std::sort(clusters.begin(), clusters.end(), [](const auto& a, const auto& b) {
            return a.size() != b.size() ? a.size() > b.size() : a.front() < b.front();
        });
        std::vector<Summary> sum;
        for (const auto& c : clusters) sum.push_back(summarise(c));
        for (std::size_t a = 0; a < clusters.size() && !joined; ++a)
            for (std::size_t b = a + 1; b < clusters.size(); ++b) {
                const Summary &A = sum[a], &B = sum[b];
                if (!(std::abs(A.f - B.f) <= o.fragment_std_factor * std::hypot(A.sigma, B.sigma))) continue;
                if (mac_pair(P.mode_shape.col(A.rep), P.mode_shape.col(B.rep)) < o.fragment_min_mac) continue;
                std::vector<Index> shared;
                std::set_intersection(A.orders.begin(), A.orders.end(), B.orders.begin(), B.orders.end(),
                                      std::back_inserter(shared));
                const double smaller = double(std::min(A.orders.size(), B.orders.size()));
                if (double(shared.size()) > o.fragment_max_shared * smaller) continue;
                std::vector<Index> u;
                std::merge(clusters[a].begin(), clusters[a].end(), clusters[b].begin(), clusters[b].end(),
                           std::back_inserter(u));
                clusters[a] = std::move(u);
                clusters.erase(clusters.begin() + std::ptrdiff_t(b));
                joined = true;
                break;
            }
    }
    return clusters;
}

/// A kept cluster as the twin rules read it: its median frequency and damping ratio, first order,
/// and the pole nearest to the median frequency (the first such in `members`) whose shape they compare.
struct TwinView {
    double f, xi;
    Index first, rep;
};

inline TwinView twin_view(const std::vector<Index>& members, const Poles& P) {
    std::vector<double> fv, xv;
    Index first = P.order(members.front());
    for (Index i : members) {
        fv.push_back(P.frequency_hz(i));
        xv.push_back(P.damping_ratio(i));
        first = std::min(first, P.order(i));
    }
    const double f = median(fv);
    Index rep = members.front();
    for (Index i : members)
        if (std::abs(P.frequency_hz(i) - f) < std::abs(P.frequency_hz(rep) - f)) rep = i;
    return {f, median(xv), first, rep};
}

/// A cluster drop_doublets dropped: its median frequency, size and first order, its index in
/// the clusters given (`at`), and the kept twin's index in the clusters returned, median
/// frequency, first order and MAC.
struct DoubletDrop {
    double f;
    Index n, first;
    std::size_t at, twin;
    double twin_f;
    Index twin_first;
    double mac;
    bool noise_born;  // drop_noise_twins, else drop_doublets
    std::string reason;
};

/// ClusteringOptions::reassign_borrowed_poles on the kept clusters (each one pole per order, in
/// ascending index, hence order), with medians and first orders from before any move; the
/// clusters in order of first order, then first pole (as drop_doublets orders them), each giving
/// to the first alike later cluster that takes all its poles below that cluster's first order;
/// a cluster gives or takes once. A cluster all of whose poles move is left empty (it was a
/// piece of the other). Returns which clusters gave or took.
inline std::vector<bool> reassign_borrowed_poles(std::vector<std::vector<Index>>& kept, const Poles& P,
                                                 const ClusteringOptions& o) {
    std::vector<TwinView> info;
    for (const auto& m : kept) info.push_back(twin_view(m, P));
    std::vector<std::size_t> by_first(kept.size());
    for (std::size_t k = 0; k < by_first.size(); ++k) by_first[k] = k;
    std::sort(by_first.begin(), by_first.end(), [&](std::size_t a, std::size_t b) {
        if (info[a].first != info[b].first) return info[a].first < info[b].first;
        return kept[a].front() < kept[b].front();
    });
    std::vector<bool> involved(kept.size(), false);
    for (std::size_t b : by_first) {
        if (involved[b]) continue;
        const TwinView& B = info[b];
        for (std::size_t a : by_first) {
            const TwinView& A = info[a];
            if (a == b || involved[a] || A.first <= B.first) continue;
            if (std::abs(A.f - B.f) / std::max(A.f, B.f) > o.doublet_window) continue;
            if (mac_pair(P.mode_shape.col(A.rep), P.mode_shape.col(B.rep)) < o.doublet_min_mac) continue;
            std::vector<Index> lead, rest;
            bool nearer = true;
            for (Index i : kept[b]) {
                if (P.order(i) >= A.first) {
                    rest.push_back(i);
                    continue;
                }
                const double fi = P.frequency_hz(i), xi = P.damping_ratio(i);
                nearer = nearer && std::abs(fi - A.f) < std::abs(fi - B.f) && std::abs(xi - A.xi) < std::abs(xi - B.xi);
                lead.push_back(i);
            }
            if (!nearer) continue;
            kept[b] = std::move(rest);
            kept[a].insert(kept[a].end(), lead.begin(), lead.end());
            std::sort(kept[a].begin(), kept[a].end());
            involved[a] = involved[b] = true;
            break;
        }
    }
    return involved;
}

/// ClusteringOptions::drop_doublets and drop_noise_twins on the kept clusters (each one pole per
/// order): in order of first order, then size (larger first), then first pole, a cluster is
/// dropped when an earlier kept one lies within doublet_window in frequency with MAC >=
/// doublet_min_mac between the poles nearest to the two medians (drop_doublets), or when it is a
/// noise twin of one (drop_noise_twins, ClusteringOptions). `drop(DoubletDrop)` records each.
template <class Drop>
std::vector<std::vector<Index>> drop_doublets(std::vector<std::vector<Index>> kept, const Poles& P,
                                              const ClusteringOptions& o, const Drop& drop) {
    struct Item : TwinView {
        Index n;
        std::size_t at;
    };
    std::vector<Item> items;
    for (std::size_t k = 0; k < kept.size(); ++k) items.push_back({twin_view(kept[k], P), Index(kept[k].size()), k});
    // drop_noise_twins needs the noise floor, which the uncertainty propagation estimates
    const bool noise_twins = o.drop_noise_twins && P.has_uncertainty && P.noise_floor_order > 0;
    std::sort(items.begin(), items.end(), [&](const Item& a, const Item& b) {
        if (a.first != b.first) return a.first < b.first;
        if (a.n != b.n) return a.n > b.n;
        return kept[a.at].front() < kept[b.at].front();
    });
    std::vector<Item> survivors;
    std::vector<std::vector<Index>> out;
    for (const Item& it : items) {
        const Item* twin = nullptr;
        double twin_mac = 0.0;
        std::size_t twin_at = 0;  // in survivors, which is in out
        bool noise_born = false;  // which rule: drop_noise_twins, else drop_doublets
        for (std::size_t k = 0; k < survivors.size(); ++k) {
            const Item& s = survivors[k];
            const bool noise = noise_twins && it.first > P.noise_floor_order && it.first > s.first &&
                               it.xi < 0.5 * s.xi && std::abs(it.f - s.f) < s.f * s.xi;
            if (!noise && (!o.drop_doublets || std::abs(it.f - s.f) / std::max(it.f, s.f) > o.doublet_window))
                continue;
            const double m = mac_pair(P.mode_shape.col(it.rep), P.mode_shape.col(s.rep));
            if (noise || m >= o.doublet_min_mac) {
                twin = &s; twin_mac = m; twin_at = k; noise_born = noise;
                break;
            }
        }
        if (twin) {
            const std::string away = percent(std::abs(it.f - twin->f) / twin->f);
            const std::string reason =
                noise_born ? "a lightly damped twin of the " + format_number("%.4g", twin->f) +
                                 " Hz mode born of the noise: less than half as damped, inside its half-power band (" +
                                 away + " away), from order " + std::to_string(it.first) +
                                 " above the noise floor (the mode from order " + std::to_string(twin->first) + ")"
                           : "a twin of the " + format_number("%.4g", twin->f) + " Hz mode: same shape (MAC " +
                                 format_number("%.2f", twin_mac) + "), " + away + " away, from order " +
                                 std::to_string(it.first) + " (the mode from order " + std::to_string(twin->first) +
                                 ")";
            drop(DoubletDrop{it.f, it.n, it.first, it.at, twin_at, twin->f, twin->first, twin_mac, noise_born,
                             reason});
        } else {
            survivors.push_back(it);
            out.push_back(std::move(kept[it.at]));
        }
    }
    return out;
}

}  // namespace detail

/// Group the poles of `diagram` whose status is in options.statuses into modes:
/// 1. agglomerative clustering on d_ij = |f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij), cut at
///    distance_threshold;
/// 2. one pole per order in each cluster (the nearest to the cluster's median frequency: a mode
///    doubled by a spurious twin stays one cluster);
/// 3. clusters smaller than the minimum size dropped (kept in dropped_*);
/// 4. representative: the member nearest to the cluster's median frequency and damping ratio
///    (each in units of its median sigma) among those whose sigma is meaningful (not at a close
///    cut, not noise-coupled unless most of the cluster is), or among all; ties to the higher order;
/// 5. sigma of f and xi over the reliable members: their median, or the sigma of their mean
///    (options.cluster_std), widened by the difference to the lowest sufficient member where it
///    exceeds 1.96 combined sigma (options.order_discrepancy).
/// Deterministic: no random start, ties broken by order and index.
inline SelectedModes select_modes(const Diagram& diagram, const ClusteringOptions& options = {}) {
    options.validate();
    const Poles& P = diagram.poles;
    const Index n = P.size();
    detail::require(Index(diagram.status.size()) == n, "diagram: status must have one entry per pole");
    detail::require(P.frequency_damping_factor.cols() == 0 ||
                        (P.frequency_damping_factor.cols() == n && P.frequency_damping_factor.rows() % 2 == 0),
                    "diagram: poles.frequency_damping_factor must be empty or 2 n_b x ", n, ", got ",
                    P.frequency_damping_factor.rows(), " x ", P.frequency_damping_factor.cols());
    const Eigen::VectorXd &f = P.frequency_hz, &xi = P.damping_ratio;

    std::vector<Index> idx;
    for (Index i = 0; i < n; ++i)
        if (std::find(options.statuses.begin(), options.statuses.end(), diagram.status[i]) != options.statuses.end())
            idx.push_back(i);
    // The minimum size (one rule, for all clusters or per cluster): a fraction of the orders from the first one that holds the cluster (or
    // any clustered pole) upwards, at least 3.
    auto orders_from = [&](Index first) {
        return Index(std::count_if(P.orders.begin(), P.orders.end(), [&](Index o) { return o >= first; }));
    };
    auto min_size_from = [&](Index first) {
        return std::max<Index>(3, Index(std::ceil(options.min_cluster_fraction * double(orders_from(first)) - 1e-9)));
    };
    Index min_size = options.min_cluster_size;
    if (min_size == 0) {
        min_size = 3;
        if (!idx.empty()) {
            Index first = P.order(idx[0]);
            for (Index i : idx) first = std::min(first, P.order(i));
            min_size = min_size_from(first);
        }
    }

    std::vector<std::vector<Index>> clusters;
    if (idx.size() == 1) {
        clusters.push_back(idx);
    } else if (idx.size() > 1) {
        const Index m = Index(idx.size());
        Eigen::MatrixXd dist(m, m);
        for (Index a = 0; a < m; ++a)
            for (Index b = 0; b < m; ++b) {
                const double fa = f(idx[a]), fb = f(idx[b]);
                dist(a, b) = std::abs(fa - fb) / std::max(fa, fb) +
                             (1.0 - detail::mac_pair(P.mode_shape.col(idx[a]), P.mode_shape.col(idx[b])));
            }
        dist = (0.5 * (dist + dist.transpose())).eval();
        dist.diagonal().setZero();
        const std::vector<Index> label = detail::flat_clusters(dist, options.linkage, options.distance_threshold);
        const Index k = label.empty() ? 0 : *std::max_element(label.begin(), label.end()) + 1;
        clusters.resize(k);
        for (Index a = 0; a < m; ++a) clusters[label[a]].push_back(idx[a]);
    }

    auto median_f = [&](const std::vector<Index>& members) {
        std::vector<double> v;
        for (Index i : members) v.push_back(f(i));
        return detail::median(v);
    };
    // Median sigma_f / (f xi) over a cluster: how well the frequency is known against the peak's width.
    auto std_per_bandwidth = [&](const std::vector<Index>& members) {
        std::vector<double> q;
        for (Index i : members)
            q.push_back(xi(i) > 0.0 ? P.frequency_std(i) / (f(i) * xi(i)) : std::numeric_limits<double>::infinity());
        return detail::median(q);
    };
    const bool check_bandwidth = options.max_frequency_std_per_bandwidth && P.has_uncertainty;
    Index smallest_min_size = min_size;
    std::vector<std::vector<Index>> kept;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    struct Dropped {
        double f;
        Index n;
        std::string reason;
        DropReason code;
        Index min_size, first;
        double std_per_bandwidth;
        std::size_t twin = 0;  // DropReason::twin: index into kept after drop_doublets
        double twin_f, twin_mac;
        bool operator<(const Dropped& o) const { return f < o.f || (f == o.f && n < o.n); }
    };
    std::vector<Dropped> dropped;
    // One pole per order: the one nearest to the median frequency (`all` ascends in index,
    // hence in order).
    auto thin = [&](const std::vector<Index>& all) {
        const double med = median_f(all);
        std::vector<Index> one_per_order;
        for (std::size_t a = 0; a < all.size();) {
            std::size_t b = a;
            Index best = all[a];
            for (; b < all.size() && P.order(all[b]) == P.order(all[a]); ++b)
                if (std::abs(f(all[b]) - med) < std::abs(f(best) - med)) best = all[b];
            one_per_order.push_back(best);
            a = b;
        }
        return one_per_order;
    };
    if (options.merge_fragments && P.has_uncertainty) clusters = detail::merge_fragments(clusters, P, thin, options);
    std::vector<Index> kept_need;    // per kept cluster, the minimum size that applied
    std::vector<double> kept_q;      // and its median sigma_f / (f xi) (NaN: not judged)
    // The size and bandwidth rules: kept, or dropped with the reason.
    auto judge = [&](std::vector<Index> one_per_order) {
        const Index size = Index(one_per_order.size());
        Index first = P.order(one_per_order.front());
        for (Index i : one_per_order) first = std::min(first, P.order(i));
        Index need = min_size;
        if (options.min_cluster_size == 0 && options.per_cluster_min_size) {
            need = min_size_from(first);
            smallest_min_size = std::min(smallest_min_size, need);
        }
        const double q = check_bandwidth ? std_per_bandwidth(one_per_order) : 0.0;
        const double q_reported = check_bandwidth ? q : nan;
        if (size < need)
            dropped.push_back({median_f(one_per_order), size,
                               std::to_string(size) + (size == 1 ? " pole" : " poles") + ", fewer than " +
                                   std::to_string(need),
                               DropReason::too_few_poles, need, first, q_reported, 0, nan, nan});
        else if (check_bandwidth && !(q <= *options.max_frequency_std_per_bandwidth))
            dropped.push_back({median_f(one_per_order), size,
                               "frequency std " + detail::format_number("%.3g", q) +
                                   " x the half-power bandwidth f xi (more than " +
                                   detail::format_number("%g", *options.max_frequency_std_per_bandwidth) + ")",
                               DropReason::frequency_std_above_bandwidth, need, first, q_reported, 0, nan, nan});
        else {
            kept.push_back(std::move(one_per_order));
            kept_need.push_back(need);
            kept_q.push_back(q_reported);
        }
    };
    for (const std::vector<Index>& all : clusters) judge(thin(all));
    // After poles moved, the clusters that gave or took are judged again (a giver may be too small now).
    if (options.drop_doublets && options.reassign_borrowed_poles) {
        const std::vector<bool> changed = detail::reassign_borrowed_poles(kept, P, options);
        std::vector<std::vector<Index>> before = std::move(kept);
        std::vector<Index> need_before = std::move(kept_need);
        std::vector<double> q_before = std::move(kept_q);
        kept.clear();
        kept_need.clear();
        kept_q.clear();
        for (std::size_t k = 0; k < before.size(); ++k) {
            if (before[k].empty()) continue;  // joined whole to the other cluster
            if (changed[k]) {
                judge(std::move(before[k]));
            } else {
                kept.push_back(std::move(before[k]));
                kept_need.push_back(need_before[k]);
                kept_q.push_back(q_before[k]);
            }
        }
    }
    if (options.drop_doublets || options.drop_noise_twins)
        kept = detail::drop_doublets(std::move(kept), P, options, [&](detail::DoubletDrop d) {
            dropped.push_back({d.f, d.n, std::move(d.reason), d.noise_born ? DropReason::noise_twin : DropReason::twin,
                               kept_need[d.at], d.first,
                               kept_q[d.at], d.twin, d.twin_f, d.mac});
        });
    std::vector<double> kept_median;
    for (const auto& k : kept) kept_median.push_back(median_f(k));
    std::vector<std::size_t> by_f(kept.size());
    for (std::size_t k = 0; k < by_f.size(); ++k) by_f[k] = k;
    std::stable_sort(by_f.begin(), by_f.end(), [&](std::size_t a, std::size_t b) { return kept_median[a] < kept_median[b]; });
    std::vector<Index> mode_of_kept(kept.size());
    for (std::size_t k = 0; k < by_f.size(); ++k) mode_of_kept[by_f[k]] = Index(k);
    std::sort(dropped.begin(), dropped.end());

    const Index l = P.mode_shape.rows(), nm = Index(kept.size());
    // Representative::lowest reads each mode at the lowest order that can hold every selected
    // mode (two states each) and is not below the noise floor k*
    const Index lowest_floor = std::max(P.noise_floor_order, 2 * nm);
    SelectedModes s;
    s.min_cluster_size = smallest_min_size;
    if (check_bandwidth) s.max_frequency_std_per_bandwidth = *options.max_frequency_std_per_bandwidth;
    s.frequency_damping_correlation.setConstant(nm, nan);
    s.block_too_short.setConstant(nm, false);
    s.order_discrepancy.setConstant(nm, false);
    s.unanchored.setConstant(nm, false);
    s.frequency_std_per_bandwidth.setConstant(nm, nan);
    s.frequency_hz.resize(nm);
    s.damping_ratio.resize(nm);
    s.mode_shape.resize(l, nm);
    s.frequency_std.setConstant(nm, nan);
    s.damping_std.setConstant(nm, nan);
    s.mode_shape_std_real.resize(l, nm);
    s.mode_shape_std_imag.resize(l, nm);
    s.frequency_spread.resize(nm);
    s.damping_spread.resize(nm);
    s.mode_shape_spread_real.resize(l, nm);
    s.mode_shape_spread_imag.resize(l, nm);
    s.min_mac.resize(nm);
    s.representative_order.resize(nm);
    s.representative_pole.resize(nm);
    s.shape_pole.resize(nm);
    s.shape_order.resize(nm);
    s.n_poles.resize(nm);
    s.order_min.resize(nm);
    s.order_max.resize(nm);
    s.mode_of_pole.setConstant(n, -1);
    for (Index k = 0; k < nm; ++k) {
        std::vector<Index> members = kept[by_f[k]];
        std::sort(members.begin(), members.end());
        const double med = kept_median[by_f[k]];
        for (Index i : members) s.mode_of_pole(i) = k;
        // A cluster most of whose poles couple to the noise directions is read like one all of whose
        // poles do: its few poles under the limit are borderline, and their frozen sigma is not the
        // mode's (the chain's 17 Hz mode where k* < the true order: one such pole, sigma 10x too
        // small). Then every pole is a candidate for the representative and the shape pole, and
        // the coupled ones give their unfrozen sigma.
        const bool mostly_coupled =
            2 * std::count_if(members.begin(), members.end(), [&](Index i) { return bool(P.noise_coupled(i)); }) >
            std::ptrdiff_t(members.size());
        auto reliable = [&](Index i) {
            return !(P.close_singular_values(i) || (P.noise_coupled(i) && !mostly_coupled));
        };
        std::vector<Index> candidates;
        for (Index i : members)
            if (reliable(i)) candidates.push_back(i);
        if (candidates.empty()) candidates = members;
        std::vector<double> sf, sxi, sf_all, sxi_all, fv, xv;
        std::vector<Index> with_sigma;  // the reliable members with a finite sigma: those sf holds
        for (Index i : members) {
            fv.push_back(f(i));
            xv.push_back(xi(i));
            if (!std::isfinite(P.frequency_std(i)) || !std::isfinite(P.damping_std(i))) continue;
            sf_all.push_back(P.frequency_std(i));
            sxi_all.push_back(P.damping_std(i));
            if (reliable(i)) {
                sf.push_back(P.frequency_std(i));
                sxi.push_back(P.damping_std(i));
                with_sigma.push_back(i);
            }
        }
        const int ddof = members.size() > 1 ? 1 : 0;
        s.frequency_spread(k) = detail::sample_std(fv, ddof);
        s.damping_spread(k) = detail::sample_std(xv, ddof);
        // The representative is the candidate nearest to the cluster's median (f, xi), each
        // measured in its median sigma (or, without uncertainty, in the cluster's spread): a
        // pole near the median frequency can still carry an outlying damping ratio.
        auto scale = [](const std::vector<double>& reliable_std, const std::vector<double>& all_std, double spread) {
            const double x = !reliable_std.empty() ? detail::median(reliable_std)
                             : !all_std.empty()    ? detail::median(all_std)
                                                   : spread;
            return std::isfinite(x) && x > 0.0 ? x : 1.0;
        };
        const double scale_f = scale(sf, sf_all, s.frequency_spread(k));
        const double scale_xi = scale(sxi, sxi_all, s.damping_spread(k));
        const double med_xi = detail::median(xv);
        auto distance = [&](Index i) {
            const double a = (f(i) - med) / scale_f, b = (xi(i) - med_xi) / scale_xi;
            return a * a + b * b;
        };
        // candidates ascend in order (one pole per order): the first at or above the floor, else
        // the nearest below it
        const auto above = std::find_if(candidates.begin(), candidates.end(),
                                        [&](Index i) { return P.order(i) >= lowest_floor; });
        const Index lowest_member = above != candidates.end() ? *above : candidates.back();
        Index rep = candidates[0];
        const bool lowest = options.representative == Representative::lowest;
        if (lowest) {
            rep = lowest_member;
        } else {
            for (Index i : candidates)  // ascending order: "<=" hands ties to the higher order
                if (distance(i) <= distance(rep)) rep = i;
        }
        // The shape of the lowest sufficient member, except where the representative already holds
        // every selected mode (order >= 2 m) at a lower order: on measured records whose noise
        // floor k* is far above the modes' order the member above k* adds noise states to the
        // shape, not calibration. A representative below 2 m cuts signal and is never kept.
        const bool rep_holds_the_modes = P.order(rep) >= 2 * nm;
        const Index sufficient =
            P.order(lowest_member) < P.order(rep) || !rep_holds_the_modes ? lowest_member : rep;
        const Index shape_rep = options.shape_representative == Representative::lowest ? sufficient : rep;
        // "lowest" reports one order's identification, sigma included; "median" the cluster's sigma
        s.frequency_std(k) = sf.empty() || lowest ? P.frequency_std(rep) : detail::median(sf);
        s.damping_std(k) = sxi.empty() || lowest ? P.damping_std(rep) : detail::median(sxi);
        const bool of_mean = !lowest && options.cluster_std == ClusterStd::mean && !with_sigma.empty() &&
                             P.frequency_damping_factor.cols() == n && P.frequency_damping_factor.rows() > 0;
        if (of_mean) {
            // The mean of the members' estimates has the mean of their factor rows (docs/uq-math.md §13.10).
            const Index nb = P.frequency_damping_factor.rows() / 2;
            Eigen::VectorXd u = Eigen::VectorXd::Zero(2 * nb);
            for (Index i : with_sigma) u += P.frequency_damping_factor.col(i);
            u /= double(with_sigma.size());
            const double uf = u.head(nb).norm(), uxi = u.tail(nb).norm();
            s.frequency_std(k) = uf;
            s.damping_std(k) = uxi;
            s.frequency_damping_correlation(k) = uf > 0.0 && uxi > 0.0 ? u.head(nb).dot(u.tail(nb)) / (uf * uxi) : nan;
        }
        if (options.unanchored_noise_coupling && P.noise_coupling.size() == n && !mostly_coupled && !with_sigma.empty()) {
            // Every reliable member's sigma is frozen where the mode's own directions are: their
            // unfrozen bound rho sigma is the mode's (docs/validation.md, issue 27 (n)).
            const bool unanchored = std::all_of(with_sigma.begin(), with_sigma.end(), [&](Index i) {
                return P.noise_coupling(i) > *options.unanchored_noise_coupling;  // NaN: anchored, not judged
            });
            if (unanchored) {
                std::vector<double> rf, rx;
                for (Index i : with_sigma) {
                    rf.push_back(P.noise_coupling(i) * P.frequency_std(i));
                    rx.push_back(P.noise_coupling(i) * P.damping_std(i));
                }
                s.frequency_std(k) = std::max(s.frequency_std(k), detail::median(rf));
                s.damping_std(k) = std::max(s.damping_std(k), detail::median(rx));
                s.unanchored(k) = true;
            }
        }
        if (options.order_discrepancy && sufficient != rep) {
            // Judged on the two poles' own sigma: one record's orders are positively correlated, so
            // their combined sigma bounds their difference's from above and the test fires only on
            // a clear discrepancy; the reported sigma (the cluster's) takes the difference in.
            auto widen = [&](double& sigma, double difference, double own_rep, double own_low) {
                if (!(std::abs(difference) > 1.96 * std::hypot(own_rep, own_low))) return;  // NaN: not judged
                sigma = std::hypot(sigma, difference);
                s.order_discrepancy(k) = true;
            };
            widen(s.frequency_std(k), f(rep) - f(sufficient), P.frequency_std(rep), P.frequency_std(sufficient));
            widen(s.damping_std(k), xi(rep) - xi(sufficient), P.damping_std(rep), P.damping_std(sufficient));
        }
        Index ref = 0;
        P.mode_shape.col(shape_rep).cwiseAbs().maxCoeff(&ref);
        for (Index r = 0; r < l; ++r) {
            std::vector<double> re, im;
            for (Index i : members) {
                const std::complex<double> v = P.mode_shape(r, i) / P.mode_shape(ref, i);
                re.push_back(v.real());
                im.push_back(v.imag());
            }
            s.mode_shape_spread_real(r, k) = detail::sample_std(re, ddof);
            s.mode_shape_spread_imag(r, k) = detail::sample_std(im, ddof);
        }
        double min_mac = 1.0;
        for (Index i : members)
            min_mac = std::min(min_mac, detail::mac_pair(P.mode_shape.col(shape_rep), P.mode_shape.col(i)));
        s.min_mac(k) = min_mac;
        if (P.has_uncertainty) s.frequency_std_per_bandwidth(k) = std_per_bandwidth(members);
        s.frequency_hz(k) = f(rep);
        s.damping_ratio(k) = xi(rep);
        if (!of_mean && P.frequency_damping_correlation.size() == n)
            s.frequency_damping_correlation(k) = P.frequency_damping_correlation(rep);
        if (P.block_too_short.size() == n) s.block_too_short(k) = P.block_too_short(rep);
        s.mode_shape.col(k) = P.mode_shape.col(shape_rep);
        s.mode_shape_std_real.col(k) = P.mode_shape_std_real.col(shape_rep);
        s.mode_shape_std_imag.col(k) = P.mode_shape_std_imag.col(shape_rep);
        s.representative_order(k) = P.order(rep);
        s.representative_pole(k) = rep;
        s.shape_pole(k) = shape_rep;
        s.shape_order(k) = P.order(shape_rep);
        s.n_poles(k) = Index(members.size());
        s.order_min(k) = P.order(members.front());
        s.order_max(k) = P.order(members.back());
        s.members.push_back(std::move(members));
    }
    const Index nd = Index(dropped.size());
    s.dropped_frequency_hz.resize(nd);
    s.dropped_n_poles.resize(nd);
    s.dropped_min_size.resize(nd);
    s.dropped_first_order.resize(nd);
    s.dropped_frequency_std_per_bandwidth.resize(nd);
    s.dropped_twin_mode.resize(nd);
    s.dropped_twin_frequency_hz.resize(nd);
    s.dropped_twin_mac.resize(nd);
    for (Index k = 0; k < nd; ++k) {
        const Dropped& d = dropped[std::size_t(k)];
        s.dropped_frequency_hz(k) = d.f;
        s.dropped_n_poles(k) = d.n;
        s.dropped_reason.push_back(d.reason);
        s.dropped_code.push_back(d.code);
        s.dropped_min_size(k) = d.min_size;
        s.dropped_first_order(k) = d.first;
        s.dropped_frequency_std_per_bandwidth(k) = d.std_per_bandwidth;
        const bool is_twin = d.code == DropReason::twin || d.code == DropReason::noise_twin;
        s.dropped_twin_mode(k) = is_twin ? mode_of_kept[d.twin] : -1;
        s.dropped_twin_frequency_hz(k) = d.twin_f;
        s.dropped_twin_mac(k) = d.twin_mac;
    }
    return s;
}

}  // namespace modaluq
