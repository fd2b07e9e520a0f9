#pragma once
/// @file selection.hpp
/// Automatic mode selection: the stable poles of a Diagram grouped into physical modes by
/// hierarchical clustering on frequency and MAC, each mode reported with a sigma that does not
/// depend on the order it is read at and with the spread of its cluster beside it.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "detail/linkage.hpp"
#include "errors.hpp"
#include "stabilization.hpp"

namespace modaluq {

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
    std::vector<PoleStatus> statuses{PoleStatus::stable};  ///< which poles are clustered
    Linkage linkage = Linkage::average;  ///< see detail/linkage.hpp

    void validate() const {
        detail::require(std::isfinite(distance_threshold) && distance_threshold > 0.0,
                        "distance_threshold must be finite and > 0, got ", distance_threshold);
        detail::require(min_cluster_size >= 0, "min_cluster_size must be >= 1 (or 0 for the default), got ",
                        min_cluster_size);
        detail::require(min_cluster_fraction > 0.0 && min_cluster_fraction <= 1.0,
                        "min_cluster_fraction must be in (0, 1], got ", min_cluster_fraction);
        detail::require(!statuses.empty(), "statuses must not be empty");
        if (max_frequency_std_per_bandwidth)
            detail::require(*max_frequency_std_per_bandwidth > 0.0, "max_frequency_std_per_bandwidth must be > 0, got ",
                            *max_frequency_std_per_bandwidth);
    }
};

/// Modes chosen from a Diagram, sorted by frequency. f, xi and the shape are those of one
/// representative pole; frequency_std and damping_std are the median over the cluster's
/// reliable poles (not at a close cut, not noise-coupled); *_spread is the sample std (ddof 1)
/// across the cluster, how much the estimate moves with the order.
struct SelectedModes {
    Eigen::VectorXd frequency_hz;           ///< Hz
    Eigen::VectorXd damping_ratio;          ///< fraction
    Eigen::MatrixXcd mode_shape;            ///< l x n_modes, largest component 1
    Eigen::VectorXd frequency_std;          ///< Hz, analytic, median over the reliable poles
    Eigen::VectorXd damping_std;            ///< fraction
    Eigen::MatrixXd mode_shape_std_real;    ///< l x n_modes, of the representative
    Eigen::MatrixXd mode_shape_std_imag;    ///< l x n_modes
    Eigen::VectorXd frequency_spread;       ///< Hz, std across the cluster
    Eigen::VectorXd damping_spread;         ///< fraction
    Eigen::MatrixXd mode_shape_spread_real; ///< l x n_modes, shapes scaled to the representative's reference
    Eigen::MatrixXd mode_shape_spread_imag; ///< l x n_modes
    Eigen::VectorXd min_mac;                ///< smallest MAC between the representative and a member
    IndexVector representative_order;       ///< model order of the representative
    IndexVector representative_pole;        ///< its index in the diagram
    IndexVector n_poles;                    ///< members of each cluster
    IndexVector order_min, order_max;       ///< lowest / highest order in each cluster
    std::vector<std::vector<Index>> members;  ///< per mode, the diagram indices of its poles (ascending)
    IndexVector mode_of_pole;               ///< per diagram pole, its mode, -1 if none
    Eigen::VectorXd dropped_frequency_hz;   ///< median frequency of each dropped cluster, Hz
    IndexVector dropped_n_poles;            ///< size of each dropped cluster
    std::vector<std::string> dropped_reason;  ///< why each cluster was dropped, in words
    /// per mode, median sigma_f / (f xi) over its cluster (NaN without uncertainty)
    Eigen::VectorXd frequency_std_per_bandwidth;
    Index min_cluster_size = 0;             ///< the size threshold applied (the smallest, per cluster)

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

}  // namespace detail

/// Group the poles of `diagram` whose status is in options.statuses into modes:
/// 1. agglomerative clustering on d_ij = |f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij), cut at
///    distance_threshold;
/// 2. one pole per order in each cluster (the nearest to the cluster's median frequency: a mode
///    doubled by a spurious twin stays one cluster);
/// 3. clusters smaller than the minimum size dropped (kept in dropped_*);
/// 4. representative: the member nearest to the median frequency among those whose sigma is
///    meaningful (not at a close cut, not noise-coupled), or among all; ties to the higher order.
/// Deterministic: no random start, ties broken by order and index.
inline SelectedModes select_modes(const Diagram& diagram, const ClusteringOptions& options = {}) {
    options.validate();
    const Poles& P = diagram.poles;
    const Index n = P.size();
    detail::require(Index(diagram.status.size()) == n, "diagram: status must have one entry per pole");
    const Eigen::VectorXd &f = P.frequency_hz, &xi = P.damping_ratio;

    std::vector<Index> idx;
    for (Index i = 0; i < n; ++i)
        if (std::find(options.statuses.begin(), options.statuses.end(), diagram.status[i]) != options.statuses.end())
            idx.push_back(i);
    Index min_size = options.min_cluster_size;
    if (min_size == 0) {
        min_size = 3;
        if (!idx.empty()) {
            Index first = P.order(idx[0]);
            for (Index i : idx) first = std::min(first, P.order(i));
            const auto n_after = std::count_if(P.orders.begin(), P.orders.end(), [&](Index o) { return o >= first; });
            min_size = std::max<Index>(3, Index(std::ceil(options.min_cluster_fraction * double(n_after) - 1e-9)));
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
    // The minimum size: a fraction of the orders from the first one that holds the cluster (or
    // any clustered pole) upwards, at least 3.
    auto orders_from = [&](Index first) {
        return Index(std::count_if(P.orders.begin(), P.orders.end(), [&](Index o) { return o >= first; }));
    };
    auto min_size_from = [&](Index first) {
        return std::max<Index>(3, Index(std::ceil(options.min_cluster_fraction * double(orders_from(first)) - 1e-9)));
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
    struct Dropped {
        double f;
        Index n;
        std::string reason;
        bool operator<(const Dropped& o) const { return f < o.f || (f == o.f && n < o.n); }
    };
    std::vector<Dropped> dropped;
    for (const std::vector<Index>& all : clusters) {
        const double med = median_f(all);
        std::vector<Index> one_per_order;  // all ascends in index, hence in order
        for (std::size_t a = 0; a < all.size();) {
            std::size_t b = a;
            Index best = all[a];
            for (; b < all.size() && P.order(all[b]) == P.order(all[a]); ++b)
                if (std::abs(f(all[b]) - med) < std::abs(f(best) - med)) best = all[b];
            one_per_order.push_back(best);
            a = b;
        }
        const Index size = Index(one_per_order.size());
        Index need = min_size;
        if (options.min_cluster_size == 0 && options.per_cluster_min_size) {
            Index first = P.order(one_per_order.front());
            for (Index i : one_per_order) first = std::min(first, P.order(i));
            need = min_size_from(first);
            smallest_min_size = std::min(smallest_min_size, need);
        }
        const double q = check_bandwidth ? std_per_bandwidth(one_per_order) : 0.0;
        if (size < need)
            dropped.push_back({median_f(one_per_order), size,
                               std::to_string(size) + " poles, fewer than " + std::to_string(need)});
        else if (check_bandwidth && !(q <= *options.max_frequency_std_per_bandwidth))
            dropped.push_back({median_f(one_per_order), size,
                               "frequency std " + detail::format_number("%.3g", q) +
                                   " x the half-power bandwidth f xi (more than " +
                                   detail::format_number("%g", *options.max_frequency_std_per_bandwidth) + ")"});
        else
            kept.push_back(std::move(one_per_order));
    }
    std::vector<double> kept_median;
    for (const auto& k : kept) kept_median.push_back(median_f(k));
    std::vector<std::size_t> by_f(kept.size());
    for (std::size_t k = 0; k < by_f.size(); ++k) by_f[k] = k;
    std::stable_sort(by_f.begin(), by_f.end(), [&](std::size_t a, std::size_t b) { return kept_median[a] < kept_median[b]; });
    std::sort(dropped.begin(), dropped.end());

    const Index l = P.mode_shape.rows(), nm = Index(kept.size());
    const double nan = std::numeric_limits<double>::quiet_NaN();
    SelectedModes s;
    s.min_cluster_size = smallest_min_size;
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
    s.n_poles.resize(nm);
    s.order_min.resize(nm);
    s.order_max.resize(nm);
    s.mode_of_pole.setConstant(n, -1);
    for (Index k = 0; k < nm; ++k) {
        std::vector<Index> members = kept[by_f[k]];
        std::sort(members.begin(), members.end());
        const double med = kept_median[by_f[k]];
        for (Index i : members) s.mode_of_pole(i) = k;
        auto reliable = [&](Index i) { return !(P.close_singular_values(i) || P.noise_coupled(i)); };
        std::vector<Index> candidates;
        for (Index i : members)
            if (reliable(i)) candidates.push_back(i);
        if (candidates.empty()) candidates = members;
        Index rep = candidates[0];
        for (Index i : candidates)  // ascending order: ">=" hands ties to the higher order
            if (std::abs(f(i) - med) <= std::abs(f(rep) - med)) rep = i;
        std::vector<double> sf, sxi, fv, xv;
        for (Index i : members) {
            fv.push_back(f(i));
            xv.push_back(xi(i));
            if (reliable(i) && std::isfinite(P.frequency_std(i))) {
                sf.push_back(P.frequency_std(i));
                sxi.push_back(P.damping_std(i));
            }
        }
        s.frequency_std(k) = sf.empty() ? P.frequency_std(rep) : detail::median(sf);
        s.damping_std(k) = sxi.empty() ? P.damping_std(rep) : detail::median(sxi);
        const int ddof = members.size() > 1 ? 1 : 0;
        s.frequency_spread(k) = detail::sample_std(fv, ddof);
        s.damping_spread(k) = detail::sample_std(xv, ddof);
        Index ref = 0;
        P.mode_shape.col(rep).cwiseAbs().maxCoeff(&ref);
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
        for (Index i : members) min_mac = std::min(min_mac, detail::mac_pair(P.mode_shape.col(rep), P.mode_shape.col(i)));
        s.min_mac(k) = min_mac;
        if (P.has_uncertainty) s.frequency_std_per_bandwidth(k) = std_per_bandwidth(members);
        s.frequency_hz(k) = f(rep);
        s.damping_ratio(k) = xi(rep);
        s.mode_shape.col(k) = P.mode_shape.col(rep);
        s.mode_shape_std_real.col(k) = P.mode_shape_std_real.col(rep);
        s.mode_shape_std_imag.col(k) = P.mode_shape_std_imag.col(rep);
        s.representative_order(k) = P.order(rep);
        s.representative_pole(k) = rep;
        s.n_poles(k) = Index(members.size());
        s.order_min(k) = P.order(members.front());
        s.order_max(k) = P.order(members.back());
        s.members.push_back(std::move(members));
    }
    s.dropped_frequency_hz.resize(Index(dropped.size()));
    s.dropped_n_poles.resize(Index(dropped.size()));
    for (std::size_t k = 0; k < dropped.size(); ++k) {
        s.dropped_frequency_hz(Index(k)) = dropped[k].f;
        s.dropped_n_poles(Index(k)) = dropped[k].n;
        s.dropped_reason.push_back(dropped[k].reason);
    }
    return s;
}

}  // namespace modaluq
