// selection.hpp: clustering stable poles into modes (detail/linkage.hpp), minimum sizes, the
// representative and its sigma, joined fragments and dropped twins.
#include <doctest/doctest.h>

#include "support/stabilization_cases.hpp"

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_selection {

using namespace support;
using modaluq::PoleStatus;

namespace {

// The definition: merge the closest pair of clusters (by the linkage's cluster distance computed
// from the members' distances) until the closest pair is farther than the threshold.
std::vector<std::set<Index>> naive_clusters(const MatrixXd& d, modaluq::Linkage linkage, double t) {
    std::vector<std::set<Index>> c;
    for (Index i = 0; i < d.rows(); ++i) c.push_back({i});
    auto between = [&](const std::set<Index>& a, const std::set<Index>& b) {
        double lo = 1e300, hi = -1e300, sum = 0;
        for (Index i : a)
            for (Index j : b) { lo = std::min(lo, d(i, j)); hi = std::max(hi, d(i, j)); sum += d(i, j); }
        switch (linkage) {
            case modaluq::Linkage::single: return lo;
            case modaluq::Linkage::complete: return hi;
            default: return sum / double(a.size() * b.size());
        }
    };
    for (;;) {
        double best = 1e300;
        std::size_t ba = 0, bb = 0;
        for (std::size_t a = 0; a < c.size(); ++a)
            for (std::size_t b = a + 1; b < c.size(); ++b)
                if (const double x = between(c[a], c[b]); x < best) { best = x; ba = a; bb = b; }
        if (c.size() < 2 || best > t) break;
        c[ba].insert(c[bb].begin(), c[bb].end());
        c.erase(c.begin() + std::ptrdiff_t(bb));
    }
    return c;
}

}  // namespace

TEST_CASE("clustering: the nearest-neighbour chain equals the naive definition") {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    for (int trial = 0; trial < 40; ++trial) {
        const Index n = 2 + Index(U(rng) * 40);
        MatrixXd x(n, 2);
        for (Index i = 0; i < n; ++i) x.row(i) << U(rng) * 3, U(rng);
        MatrixXd d(n, n);
        for (Index i = 0; i < n; ++i)
            for (Index j = 0; j < n; ++j) d(i, j) = (x.row(i) - x.row(j)).norm();
        const double t = 0.05 + 0.5 * U(rng);
        for (auto linkage : {modaluq::Linkage::single, modaluq::Linkage::complete, modaluq::Linkage::average}) {
            CAPTURE(trial);
            CAPTURE(int(linkage));
            const auto label = modaluq::detail::flat_clusters(d, linkage, t);
            std::map<Index, std::set<Index>> by_label;
            for (Index i = 0; i < n; ++i) by_label[label[i]].insert(i);
            std::set<std::set<Index>> got, want;
            for (auto& kv : by_label) got.insert(kv.second);
            for (auto& s : naive_clusters(d, linkage, t)) want.insert(s);
            CHECK(got == want);
        }
    }
}

TEST_CASE("selection: clusters, one pole per order, minimum size, representative and sigma") {
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 2; n <= 40; n += 2) {  // 20 orders
        std::vector<P> list;
        list.push_back({10.0 + 1e-4 * double(n % 3), 0.02, 0, 0.01 + 1e-4 * double(n)});
        if (n >= 10) list.push_back({25.0 + 1e-4 * double(n % 2), 0.01, 1});  // 16 orders
        if (n == 20 || n == 22) list.push_back({33.0, 0.01, 2});             // 2 orders: dropped
        if (n == 30) list.push_back({10.0005, 0.02, 0});                      // a twin at one order
        if (n == 36) list[1].coupled = true;  // the 25 Hz pole
        by_order[n] = list;
    }
    const modaluq::Diagram d = all_stable(by_order);
    const modaluq::Poles& poles = d.poles;
    const auto s = modaluq::select_modes(d);
    // default minimum: a quarter of the 20 orders from the lowest clustered order, at least 3
    CHECK(s.min_cluster_size == 5);
    REQUIRE(s.n_modes() == 2);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.0).epsilon(1e-4));
    CHECK(s.n_poles(0) == 20);  // the twin at order 30 is not a second member of that order
    CHECK(s.n_poles(1) == 16);
    CHECK(s.order_min(1) == 10);
    CHECK(s.order_max(1) == 40);
    REQUIRE(s.dropped_n_poles.size() == 1);
    CHECK(s.dropped_n_poles(0) == 2);
    CHECK(s.dropped_frequency_hz(0) == doctest::Approx(33.0));
    // the reason as a code and the numbers its words quote
    REQUIRE(s.dropped_code.size() == 1);
    CHECK(s.dropped_code[0] == modaluq::DropReason::too_few_poles);
    CHECK(s.dropped_min_size(0) == 5);
    CHECK(s.dropped_first_order(0) == 20);
    CHECK(s.dropped_twin_mode(0) == -1);
    CHECK(std::isnan(s.dropped_twin_frequency_hz(0)));
    CHECK(std::isnan(s.dropped_twin_mac(0)));
    CHECK(s.dropped_reason[0] == "2 poles, fewer than 5");
    CHECK(std::string(modaluq::to_string(s.dropped_code[0])) == "too_few_poles");
    // the sigma of mode 1 is the median of its members' sigma: 0.01 + 1e-4 n over n = 2..40
    CHECK(s.frequency_std(0) == doctest::Approx(0.01 + 1e-4 * 21.0));
    // the representative is never the noise-coupled pole, and its sigma excludes it
    const Index rep1 = s.representative_pole(1);
    CHECK_FALSE(poles.noise_coupled(rep1));
    CHECK(s.frequency_std(1) == doctest::Approx(25.0e-3).epsilon(1e-5));
    for (Index k = 0; k < 2; ++k)
        for (Index i : s.members[std::size_t(k)]) CHECK(s.mode_of_pole(i) == k);
    CHECK(s.frequency_spread(0) > 0);
    CHECK(s.min_mac(0) == doctest::Approx(1.0));

    modaluq::ClusteringOptions o;
    o.min_cluster_size = 2;
    CHECK(modaluq::select_modes(d, o).n_modes() == 3);
    o.statuses = {PoleStatus::unstable};
    CHECK(modaluq::select_modes(d, o).n_modes() == 0);
    o = {};
    o.distance_threshold = -1;
    CHECK_THROWS_WITH_AS(modaluq::select_modes(d, o), doctest::Contains("distance_threshold"),
                         modaluq::invalid_argument);
}

namespace {

// A mode at orders 4..40 whose frequency drifts with the order (the median member sits at
// order 22); order 12's pole is noise-coupled.
std::map<Index, std::vector<P>> drifting_mode() {
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 4; n <= 40; n += 2) {
        P p{10.0 + 1e-4 * double(n), 0.02, 0, 0.01 + 1e-4 * double(n)};
        p.coupled = n == 12;
        by_order[n] = {p};
    }
    return by_order;
}

// The stable diagram of `by_order` whose order 14 cuts close singular values.
modaluq::Diagram with_close_cut_at_14(const std::map<Index, std::vector<P>>& by_order) {
    modaluq::Diagram d = all_stable(by_order);
    for (Index i = 0; i < d.poles.size(); ++i) d.poles.close_singular_values(i) = d.poles.order(i) == 14;
    return d;
}

}  // namespace

TEST_CASE("selection: the lowest representative is the lowest reliable member at or above max(k*, 2 m)") {
    // drifting_mode(), order 14 at a close cut
    std::map<Index, std::vector<P>> by_order = drifting_mode();
    modaluq::Diagram d = with_close_cut_at_14(by_order);
    modaluq::ClusteringOptions o;
    const auto median = modaluq::select_modes(d, o);
    REQUIRE(median.n_modes() == 1);
    CHECK(median.representative_order(0) == 22);  // nearest to the median frequency (orders 4..40)
    o.representative = modaluq::Representative::lowest;
    auto lowest_at = [&](const modaluq::Diagram& diagram, Index floor) {
        modaluq::Diagram with_floor = diagram;
        with_floor.poles.noise_floor_order = floor;
        const auto s = modaluq::select_modes(with_floor, o);
        const auto m = modaluq::select_modes(with_floor);
        REQUIRE(s.n_modes() == m.n_modes());
        for (Index k = 0; k < s.n_modes(); ++k) {
            // one pole, sigma included; the clusters are those of the default
            const Index rep = s.representative_pole(k);
            CHECK(s.frequency_hz(k) == with_floor.poles.frequency_hz(rep));
            CHECK(s.frequency_std(k) == with_floor.poles.frequency_std(rep));
            CHECK(s.damping_std(k) == with_floor.poles.damping_std(rep));
            CHECK(s.mode_shape_std_real.col(k) == with_floor.poles.mode_shape_std_real.col(rep));
            CHECK(s.members == m.members);
        }
        return s.representative_order(0);
    };
    CHECK(lowest_at(d, 0) == 4);    // unknown floor, one mode (2 m = 2): the lowest reliable member
    CHECK(lowest_at(d, 10) == 10);
    CHECK(lowest_at(d, 11) == 16);  // 12 is noise-coupled, 14 at a close cut: neither is read
    CHECK(lowest_at(d, 40) == 40);
    CHECK(lowest_at(d, 60) == 40);  // no member that high: the highest, the least cut
    // three modes need order 6 at least, whatever k* says
    for (Index n = 4; n <= 40; n += 2) {
        by_order[n].push_back({20.0, 0.02, 1});
        by_order[n].push_back({30.0, 0.02, 2});
    }
    modaluq::Diagram three = with_close_cut_at_14(by_order);
    CHECK(lowest_at(three, 0) == 6);
    CHECK(lowest_at(three, 4) == 6);
    CHECK(lowest_at(three, 8) == 8);
    CHECK(std::string(modaluq::to_string(modaluq::Representative::lowest)) == "lowest");
}

TEST_CASE("selection: the shape pole gives the shape, its sigma and spreads; f and xi stay the representative's") {
    // drifting_mode() with order 14 at a close cut, its shape turning with the order; k* = 11.
    modaluq::Diagram d = with_close_cut_at_14(drifting_mode());
    d.poles.noise_floor_order = 11;
    for (Index i = 0; i < d.poles.size(); ++i) {
        d.poles.mode_shape(1, i) += 1e-3 * double(d.poles.order(i));  // each order's shape differs a little
        d.poles.mode_shape_std_real(1, i) = 1e-4 * double(d.poles.order(i));
    }
    modaluq::ClusteringOptions o;
    const auto s = modaluq::select_modes(d, o);  // the default: shape at the lowest sufficient order
    CHECK(o.shape_representative == modaluq::Representative::lowest);
    o.shape_representative = modaluq::Representative::median;
    const auto median = modaluq::select_modes(d, o);
    o.shape_representative = modaluq::Representative::lowest;
    o.representative = modaluq::Representative::lowest;
    const auto lowest = modaluq::select_modes(d, o);
    REQUIRE(s.n_modes() == 1);
    // f, xi, their sigma and the representative: the default's
    CHECK(s.representative_pole(0) == median.representative_pole(0));
    CHECK(s.frequency_hz(0) == median.frequency_hz(0));
    CHECK(s.frequency_std(0) == median.frequency_std(0));
    CHECK(s.damping_std(0) == median.damping_std(0));
    CHECK(median.shape_pole(0) == median.representative_pole(0));
    // the shape: that of the lowest reliable member at or above max(k*, 2 m) = 11, order 16 (12
    // noise-coupled, 14 at a close cut), as representative lowest reads it
    const Index sp = s.shape_pole(0);
    CHECK(s.shape_order(0) == 16);
    CHECK(sp == lowest.representative_pole(0));
    CHECK(s.mode_shape.col(0) == d.poles.mode_shape.col(sp));
    CHECK(s.mode_shape_std_real.col(0) == d.poles.mode_shape_std_real.col(sp));
    CHECK(s.mode_shape.col(0) == lowest.mode_shape.col(0));
    CHECK(s.min_mac(0) == lowest.min_mac(0));
    CHECK(s.mode_shape_spread_real.col(0) == lowest.mode_shape_spread_real.col(0));
    CHECK(s.mode_shape.col(0) != median.mode_shape.col(0));
    CHECK(s.members == median.members);
    // a noise floor above the representative (order 22): the lowest sufficient member, order 26,
    // is higher, and the shape stays the representative's
    d.poles.noise_floor_order = 25;
    o.representative = modaluq::Representative::median;
    const auto high_floor = modaluq::select_modes(d, o);
    REQUIRE(high_floor.n_modes() == 1);
    CHECK(high_floor.representative_order(0) == 22);
    CHECK(high_floor.shape_pole(0) == high_floor.representative_pole(0));
    o.representative = modaluq::Representative::lowest;
    CHECK(modaluq::select_modes(d, o).representative_order(0) == 26);
}

TEST_CASE("selection: a representative below 2 m never gives the shape") {
    // Four modes over orders 4..40 (2 m = 8, k* = 0). The 10 Hz mode's frequency is the median at
    // order 6, so its representative is order 6, which cannot hold four modes: the shape is the
    // lowest sufficient member's, order 8, though 8 is above the representative.
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 4; n <= 40; n += 2) {
        const double s = n == 6 ? 0.0 : n <= 22 ? -double(n) : double(n);  // 9 below, 9 above order 6's
        by_order[n] = {{10.0 + 1e-4 * s, 0.02, 0}, {20.0, 0.02, 1}, {30.0, 0.02, 2}, {40.0, 0.02, 3}};
    }
    modaluq::Diagram d = all_stable(by_order);
    for (Index i = 0; i < d.poles.size(); ++i) d.poles.mode_shape(1, i) += 1e-3 * double(d.poles.order(i));
    modaluq::ClusteringOptions o;
    o.drop_doublets = false;
    const auto s = modaluq::select_modes(d, o);
    REQUIRE(s.n_modes() == 4);
    CHECK(s.representative_order(0) == 6);
    CHECK(s.shape_order(0) == 8);
    CHECK(s.mode_shape.col(0) == d.poles.mode_shape.col(s.shape_pole(0)));
    o.shape_representative = modaluq::Representative::median;
    CHECK(modaluq::select_modes(d, o).shape_order(0) == 6);
}

TEST_CASE("selection: a mode whose damping moves with the order beyond its sigma has its sigma widened") {
    // One mode over orders 4..40: xi 2 % up to order 20, 0.5 % above (a spurious pole took part of
    // it), sigma_xi 5 % of xi. k* = 10: the lowest sufficient member is order 10, the representative
    // (nearest to the median xi, 0.5 %; ties to the higher order) order 40.
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 4; n <= 40; n += 2) by_order[n] = {{10.0, n <= 20 ? 0.02 : 0.005, 0}};
    modaluq::Diagram d = all_stable(by_order);
    d.poles.noise_floor_order = 10;
    modaluq::ClusteringOptions o;
    CHECK(o.order_discrepancy);
    const auto s = modaluq::select_modes(d, o);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.representative_order(0) == 40);
    CHECK(s.shape_order(0) == 10);
    // the median sigma_xi (ten poles at 2.5e-4, nine at 1e-3) with the difference 0.015 added:
    // 0.015 > 1.96 * hypot(2.5e-4, 1e-3); f does not move and keeps its sigma
    CHECK(s.damping_std(0) == doctest::Approx(std::hypot(2.5e-4, 0.015)).epsilon(1e-12));
    CHECK(s.frequency_std(0) == doctest::Approx(1e-2).epsilon(1e-12));
    CHECK(s.order_discrepancy(0));
    CHECK(s.damping_ratio(0) == 0.005);  // the value is the representative's still
    o.order_discrepancy = false;
    const auto off = modaluq::select_modes(d, o);
    CHECK(off.damping_std(0) == doctest::Approx(2.5e-4).epsilon(1e-12));
    CHECK_FALSE(off.order_discrepancy(0));
    CHECK(off.representative_pole(0) == s.representative_pole(0));
    // the mode read at the lowest sufficient order has nothing to compare with
    o.order_discrepancy = true;
    o.representative = modaluq::Representative::lowest;
    const auto lowest = modaluq::select_modes(d, o);
    CHECK_FALSE(lowest.order_discrepancy(0));
    CHECK(lowest.damping_std(0) == doctest::Approx(1e-3).epsilon(1e-12));
    // judged on the two poles' own sigma, not the cluster's: a representative whose own sigma_xi
    // (1 %) covers the difference is not widened, though the median sigma (now 1e-3) would not cover it
    o = modaluq::ClusteringOptions{};
    by_order[40] = {{10.0, 0.005, 0, -1, 0.01}};
    modaluq::Diagram loose = all_stable(by_order);
    loose.poles.noise_floor_order = 10;
    const auto own = modaluq::select_modes(loose, o);
    REQUIRE(own.n_modes() == 1);
    CHECK(own.representative_order(0) == 40);
    CHECK_FALSE(own.order_discrepancy(0));
    CHECK(own.damping_std(0) == doctest::Approx(1e-3).epsilon(1e-12));  // 9 x 2.5e-4, 9 x 1e-3, 1 x 1e-2
    // without uncertainty nothing is judged
    modaluq::Diagram bare = d;
    bare.poles.damping_std.setConstant(std::numeric_limits<double>::quiet_NaN());
    bare.poles.frequency_std.setConstant(std::numeric_limits<double>::quiet_NaN());
    bare.poles.has_uncertainty = false;
    const auto none = modaluq::select_modes(bare, o);
    REQUIRE(none.n_modes() == 1);
    CHECK_FALSE(none.order_discrepancy(0));
    // a difference within the two sigma is the estimates' own scatter: nothing widened
    for (Index n = 22; n <= 40; n += 2) by_order[n] = {{10.0, 0.0195, 0}};
    modaluq::Diagram close = all_stable(by_order);
    close.poles.noise_floor_order = 10;
    const auto within = modaluq::select_modes(close);
    REQUIRE(within.n_modes() == 1);
    CHECK_FALSE(within.order_discrepancy(0));
    CHECK(within.damping_std(0) == doctest::Approx(0.05 * 0.0195).epsilon(1e-12));
}

TEST_CASE("selection: a cluster most of whose poles are noise-coupled takes the sigma of all of them") {
    // Orders 4..40 (19 poles) of one mode. The noise-coupled poles carry their unfrozen sigma_f
    // 0.1 Hz; the others the frozen 0.01 Hz.
    auto diagram = [](auto coupled) {
        std::map<Index, std::vector<P>> by_order;
        for (Index n = 4; n <= 40; n += 2) {
            P p{10.0, 0.02, 0, coupled(n) ? 0.1 : 0.01};
            p.coupled = coupled(n);
            by_order[n] = {p};
        }
        return all_stable(by_order);
    };
    // all but order 24 coupled: that one pole's frozen sigma is not the mode's
    const auto most = modaluq::select_modes(diagram([](Index n) { return n != 24; }));
    REQUIRE(most.n_modes() == 1);
    CHECK(most.frequency_std(0) == doctest::Approx(0.1).epsilon(1e-12));
    CHECK(most.representative_order(0) == 40);  // every pole a candidate; ties to the higher order
    // nine of nineteen coupled: the ten others are the mode's reliable poles
    const auto some = modaluq::select_modes(diagram([](Index n) { return n <= 20; }));
    REQUIRE(some.n_modes() == 1);
    CHECK(some.frequency_std(0) == doctest::Approx(0.01).epsilon(1e-12));
    CHECK(some.representative_order(0) == 40);
}

TEST_CASE("selection: a mode none of whose reliable poles is free of the frozen noise directions takes their rho sigma") {
    // Orders 4..40 (19 poles) of one mode, sigma_f 0.01 Hz and sigma_xi 1e-3 (frozen); rho of pole
    // i is 3 + 0.1 i, above the default limit 2 at every order: the median rho is 3.9.
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 4; n <= 40; n += 2) by_order[n] = {{10.0, 0.02, 0}};
    modaluq::Diagram d = all_stable(by_order);
    const Index np = d.poles.size();
    REQUIRE(np == 19);
    d.poles.noise_coupling = Eigen::VectorXd::LinSpaced(np, 3.0, 3.0 + 0.1 * double(np - 1));
    modaluq::ClusteringOptions o;
    REQUIRE(o.unanchored_noise_coupling);
    CHECK(*o.unanchored_noise_coupling == 2.0);
    const auto s = modaluq::select_modes(d, o);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.unanchored(0));
    CHECK(s.frequency_std(0) == doctest::Approx(3.9 * 0.01).epsilon(1e-12));
    CHECK(s.damping_std(0) == doctest::Approx(3.9 * 1e-3).epsilon(1e-12));
    CHECK(s.frequency_hz(0) == 10.0);  // the value does not move
    // one pole free of the frozen directions (rho 1: an order <= k*) anchors the mode
    modaluq::Diagram anchored = d;
    anchored.poles.noise_coupling(5) = 1.0;
    const auto a = modaluq::select_modes(anchored, o);
    CHECK_FALSE(a.unanchored(0));
    CHECK(a.frequency_std(0) == doctest::Approx(0.01).epsilon(1e-12));
    // a pole whose rho is unknown (NaN) is not judged unanchored
    anchored.poles.noise_coupling(5) = std::numeric_limits<double>::quiet_NaN();
    CHECK_FALSE(modaluq::select_modes(anchored, o).unanchored(0));
    // a noise-coupled pole is not a reliable one: its rho does not anchor the rest
    modaluq::Diagram flagged = d;
    flagged.poles.noise_coupling(5) = 1.0;
    flagged.poles.noise_coupled(5) = true;
    const auto fl = modaluq::select_modes(flagged, o);
    CHECK(fl.unanchored(0));
    CHECK(fl.frequency_std(0) == doctest::Approx(0.01 * 0.5 * (3.9 + 4.0)).epsilon(1e-12));  // 18 reliable poles
    // a larger limit, no limit, or no rho: the frozen median
    o.unanchored_noise_coupling = 5.0;
    CHECK_FALSE(modaluq::select_modes(d, o).unanchored(0));
    o.unanchored_noise_coupling.reset();
    const auto off = modaluq::select_modes(d, o);
    CHECK_FALSE(off.unanchored(0));
    CHECK(off.frequency_std(0) == doctest::Approx(0.01).epsilon(1e-12));
    modaluq::Diagram unknown = d;
    unknown.poles.noise_coupling.resize(0);
    CHECK_FALSE(modaluq::select_modes(unknown).unanchored(0));
    // rho is at least 1: a limit below it is refused, and so is a noise_coupling of the wrong size
    o.unanchored_noise_coupling = 0.5;
    CHECK_THROWS_WITH_AS(modaluq::select_modes(d, o), doctest::Contains("unanchored_noise_coupling"),
                         modaluq::invalid_argument);
    unknown.poles.noise_coupling = Eigen::VectorXd::Ones(3);
    CHECK_THROWS_WITH_AS(unknown.poles.validate(), doctest::Contains("noise_coupling"), modaluq::invalid_argument);
}

TEST_CASE("selection: a cluster whose frequency is less certain than its peak's bandwidth is dropped") {
    // Two stable columns over 10 orders: a 2 %-damped mode with sigma_f = 0.1 % of f
    // (sigma_f / (f xi) = 0.05) and a 0.5 %-damped column with sigma_f = 1 % of f (ratio 2).
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 2; n <= 20; n += 2) by_order[n] = {{5.0, 0.02, 0}, {12.0, 0.005, 1, 0.12}};
    const modaluq::Diagram d = all_stable(by_order);
    auto s = modaluq::select_modes(d);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(5.0));
    CHECK(s.frequency_std_per_bandwidth(0) == doctest::Approx(0.005 / (5.0 * 0.02)));
    REQUIRE(s.dropped_reason.size() == 1);
    CHECK(s.dropped_frequency_hz(0) == doctest::Approx(12.0));
    CHECK(s.dropped_reason[0] == "frequency std 2 x the half-power bandwidth f xi (more than 1)");
    REQUIRE(s.dropped_code.size() == 1);
    CHECK(s.dropped_code[0] == modaluq::DropReason::frequency_std_above_bandwidth);
    CHECK(s.dropped_frequency_std_per_bandwidth(0) == doctest::Approx(0.12 / (12.0 * 0.005)));
    CHECK(s.max_frequency_std_per_bandwidth == 1.0);
    CHECK(s.dropped_min_size(0) == 3);
    CHECK(s.dropped_first_order(0) == 2);
    CHECK(s.dropped_twin_mode(0) == -1);
    modaluq::ClusteringOptions o;
    o.max_frequency_std_per_bandwidth.reset();
    CHECK(modaluq::select_modes(d, o).n_modes() == 2);
    CHECK(std::isnan(modaluq::select_modes(d, o).max_frequency_std_per_bandwidth));  // no such test
    o.max_frequency_std_per_bandwidth = 3.0;
    CHECK(modaluq::select_modes(d, o).n_modes() == 2);
    // a too-small cluster says so
    o = {};
    o.min_cluster_size = 11;
    s = modaluq::select_modes(d, o);
    CHECK(s.n_modes() == 0);
    REQUIRE(s.dropped_reason.size() == 2);
    CHECK(s.dropped_reason[0] == "10 poles, fewer than 11");
    for (Index k = 0; k < 2; ++k) {  // the size test comes first; the bandwidth is still reported
        CHECK(s.dropped_code[std::size_t(k)] == modaluq::DropReason::too_few_poles);
        CHECK(s.dropped_min_size(k) == 11);
        CHECK(s.dropped_n_poles(k) == 10);
    }
    CHECK(s.dropped_frequency_std_per_bandwidth(1) == doctest::Approx(2.0));
}

TEST_CASE("selection: the per-cluster minimum size counts the orders from the cluster's first order") {
    // orders 2..40 (20); a mode from order 2 on, and one that appears only from order 30 on (6 orders)
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 2; n <= 40; n += 2) {
        by_order[n] = {{5.0, 0.02, 0}};
        if (n >= 30) by_order[n].push_back({12.0, 0.02, 1});
    }
    const modaluq::Diagram d = all_stable(by_order);
    modaluq::ClusteringOptions o;
    o.min_cluster_fraction = 0.5;  // global: 10 poles needed, the late mode has 6
    CHECK(modaluq::select_modes(d, o).n_modes() == 1);
    o.per_cluster_min_size = true;  // per cluster: half of its 6 orders
    const auto s = modaluq::select_modes(d, o);
    CHECK(s.n_modes() == 2);
    CHECK(s.min_cluster_size == 3);
}

TEST_CASE("selection: pieces of one mode are joined, two modes at the same orders are not") {
    auto select = [](const std::map<Index, std::vector<P>>& by_order, bool merge) {
        const modaluq::Diagram d = all_stable(by_order);
        modaluq::ClusteringOptions o;
        o.merge_fragments = merge;
        o.drop_doublets = false;  // tested below
        o.min_cluster_size = 12;
        return modaluq::select_modes(d, o);
    };
    // one mode at 10 Hz whose shape changes between orders 20 and 22: two pieces of 10 poles
    std::map<Index, std::vector<P>> pieces;
    for (Index n = 2; n <= 40; n += 2) pieces[n] = {{10.0 + 1e-3 * double(n % 4), 0.02, n <= 20 ? 0 : 3}};
    CHECK(select(pieces, false).n_modes() == 0);  // each piece alone is too small
    const auto joined = select(pieces, true);
    REQUIRE(joined.n_modes() == 1);
    CHECK(joined.n_poles(0) == 20);
    // two modes 0.05 % apart with the same shapes, present at the same orders: never joined
    std::map<Index, std::vector<P>> pair;
    for (Index n = 2; n <= 40; n += 2) pair[n] = {{10.0, 0.02, 0}, {10.005, 0.02, 3}};
    const auto two = select(pair, true);
    CHECK(two.n_modes() == 2);
    // a piece farther than 3 combined sigma is another mode
    std::map<Index, std::vector<P>> apart;
    for (Index n = 2; n <= 40; n += 2) apart[n] = {{n <= 20 ? 10.0 : 10.1, 0.02, n <= 20 ? 0 : 3}};
    CHECK(select(apart, true).n_modes() == 0);
}

TEST_CASE("selection: the later of two alike clusters a few per cent apart is dropped as a twin") {
    // a mode at 10 Hz from order 2; from order 20 a twin at 10.3 Hz with a shape of MAC 0.88,
    // lightly damped; and a mode at 10.2 Hz of another shape (MAC 0.10) from order 10
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 2; n <= 40; n += 2) {
        by_order[n] = {{10.0, 0.02, 0}};
        if (n >= 10) by_order[n].push_back({10.2, 0.02, 1});
        if (n >= 20) by_order[n].push_back({10.3, 0.003, 3});
    }
    const modaluq::Diagram d = all_stable(by_order);
    modaluq::ClusteringOptions o;
    o.min_cluster_size = 5;
    const auto s = modaluq::select_modes(d, o);
    REQUIRE(s.n_modes() == 2);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.0));
    CHECK(s.frequency_hz(1) == doctest::Approx(10.2));
    REQUIRE(s.dropped_reason.size() == 1);
    CHECK(s.dropped_frequency_hz(0) == doctest::Approx(10.3));
    CHECK(s.dropped_reason[0] == "a twin of the 10 Hz mode: same shape (MAC 0.88), 3 % away, from order 20 "
                                 "(the mode from order 2)");
    REQUIRE(s.dropped_code.size() == 1);
    CHECK(s.dropped_code[0] == modaluq::DropReason::twin);
    CHECK(s.dropped_twin_mode(0) == 0);  // the 10 Hz mode
    CHECK(s.dropped_twin_frequency_hz(0) == 10.0);
    const double mac = modaluq::detail::mac_pair(d.poles.mode_shape.col(0), d.poles.mode_shape.col(find(d, 20, 10.3)));
    CHECK(s.dropped_twin_mac(0) == mac);
    CHECK(s.dropped_first_order(0) == 20);
    CHECK(s.order_min(s.dropped_twin_mode(0)) == 2);
    CHECK(s.dropped_min_size(0) == 5);
    o.drop_doublets = false;
    CHECK(modaluq::select_modes(d, o).n_modes() == 3);
    o.drop_doublets = true;
    o.doublet_window = 0.02;
    CHECK(modaluq::select_modes(d, o).n_modes() == 3);
}

TEST_CASE("selection: a lightly damped cluster born above the noise floor in a mode's half-power band is dropped") {
    // a mode at 10 Hz, xi 2 % (half-power band +-0.2 Hz), from order 2; from order 20 a cluster
    // at 10.1 Hz, xi 0.4 %, of another shape (MAC 0.10: drop_doublets does not see it)
    auto diagram = [](double f_twin, double xi_twin, Index first_twin) {
        std::map<Index, std::vector<P>> by_order;
        for (Index n = 2; n <= 40; n += 2) {
            by_order[n] = {{10.0, 0.02, 0}};
            if (n >= first_twin) by_order[n].push_back({f_twin, xi_twin, 1});
        }
        modaluq::Diagram d = all_stable(by_order);
        d.poles.noise_floor_order = 12;
        return d;
    };
    modaluq::ClusteringOptions o;
    o.min_cluster_size = 5;
    const modaluq::Diagram d = diagram(10.1, 0.004, 20);
    const auto s = modaluq::select_modes(d, o);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.0));
    REQUIRE(s.dropped_reason.size() == 1);
    CHECK(s.dropped_reason[0] == "a lightly damped twin of the 10 Hz mode born of the noise: less than half as "
                                 "damped, inside its half-power band (1 % away), from order 20 above the noise "
                                 "floor (the mode from order 2)");
    CHECK(s.dropped_code[0] == modaluq::DropReason::noise_twin);
    CHECK(std::string(modaluq::to_string(s.dropped_code[0])) == "noise_twin");
    CHECK(s.dropped_twin_mode(0) == 0);
    CHECK(s.dropped_twin_frequency_hz(0) == 10.0);
    CHECK(s.dropped_twin_mac(0) ==
          modaluq::detail::mac_pair(d.poles.mode_shape.col(0), d.poles.mode_shape.col(find(d, 20, 10.1))));
    CHECK(s.dropped_first_order(0) == 20);
    // each condition is needed: the switch, the noise floor below the twin's first order, a
    // later first order, less damping, inside the band, the uncertainty (which gives k*)
    auto kept = [&](const modaluq::Diagram& dd, const modaluq::ClusteringOptions& oo) {
        return modaluq::select_modes(dd, oo).n_modes() == 2;
    };
    modaluq::ClusteringOptions off = o;
    off.drop_noise_twins = false;
    CHECK(kept(d, off));
    modaluq::Diagram high_floor = d;
    high_floor.poles.noise_floor_order = 20;  // born at k*, not above it
    CHECK(kept(high_floor, o));
    CHECK(kept(diagram(10.1, 0.004, 2), o));   // born with the mode
    CHECK(kept(diagram(10.1, 0.03, 20), o));   // more damped
    CHECK(kept(diagram(10.1, 0.011, 20), o));  // not less than half as damped (a close physical pair)
    CHECK(kept(diagram(10.25, 0.004, 20), o)); // outside the band (0.25 Hz > 0.2 Hz)
    modaluq::Diagram no_std = d;
    no_std.poles.has_uncertainty = false;
    CHECK(kept(no_std, o));
    // it does not need drop_doublets
    modaluq::ClusteringOptions no_doublets = o;
    no_doublets.drop_doublets = false;
    CHECK(modaluq::select_modes(d, no_doublets).n_modes() == 1);
}

TEST_CASE("selection: a mode's lowest poles taken by an alike cluster born later are given back") {
    // the mode: 10 Hz, xi 2 %, shape 0; its poles of orders 2-6 (10.01 Hz, shape 3: MAC 0.88) fall
    // into a lightly damped cluster at 10.15 Hz, xi 0.3 %, shape 3, from order 14, and the mode's
    // own cluster starts at order 8
    auto diagram = [](double lead_xi, int main_shape) {
        std::map<Index, std::vector<P>> by_order;
        for (Index n = 2; n <= 40; n += 2) {
            if (n < 8) by_order[n] = {{10.01, lead_xi, main_shape}};
            else by_order[n] = {{10.0, 0.02, 0}};
            if (n >= 14) by_order[n].push_back({10.15, 0.003, main_shape});
        }
        modaluq::Diagram d = all_stable(by_order);
        d.poles.noise_floor_order = 12;
        return d;
    };
    modaluq::ClusteringOptions o;
    o.min_cluster_size = 5;
    const modaluq::Diagram d = diagram(0.02, 3);
    auto s = modaluq::select_modes(d, o);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.0));
    CHECK(s.order_min(0) == 2);  // with the orders 2-6 given back
    CHECK(s.n_poles(0) == 20);
    REQUIRE(s.dropped_code.size() == 1);
    CHECK(s.dropped_code[0] == modaluq::DropReason::noise_twin);  // now born at 14, above k* = 12
    CHECK(s.dropped_first_order(0) == 14);
    CHECK(s.dropped_n_poles(0) == 14);
    CHECK(s.dropped_frequency_hz(0) == doctest::Approx(10.15));
    // the same by drop_doublets alone
    modaluq::ClusteringOptions no_noise = o;
    no_noise.drop_noise_twins = false;
    s = modaluq::select_modes(d, no_noise);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.0));
    REQUIRE(s.dropped_reason.size() == 1);
    CHECK(s.dropped_reason[0] == "a twin of the 10 Hz mode: same shape (MAC 0.88), 1.5 % away, from order 14 "
                                 "(the mode from order 2)");
    // without the option the lightly damped cluster is the earlier one and the mode its twin
    modaluq::ClusteringOptions off = o;
    off.reassign_borrowed_poles = false;
    s = modaluq::select_modes(d, off);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.15));
    CHECK(s.n_poles(0) == 17);
    REQUIRE(s.dropped_code.size() == 1);
    CHECK(s.dropped_code[0] == modaluq::DropReason::twin);
    CHECK(s.dropped_frequency_hz(0) == doctest::Approx(10.0));
    CHECK(s.dropped_first_order(0) == 8);
    // each condition is needed: poles nearer in damping too (xi 0.2 % is the cluster's own), an
    // alike shape (shape 1: MAC 0.10), drop_doublets
    s = modaluq::select_modes(diagram(0.002, 3), o);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.15));
    s = modaluq::select_modes(diagram(0.02, 1), o);
    REQUIRE(s.n_modes() == 2);
    CHECK(s.order_min(0) == 8);
    CHECK(s.n_poles(1) == 17);
    modaluq::ClusteringOptions no_doublets = o;
    no_doublets.drop_doublets = false;
    s = modaluq::select_modes(d, no_doublets);
    REQUIRE(s.n_modes() == 2);
    CHECK(s.n_poles(0) == 17);  // 10 Hz: orders 8-40
    CHECK(s.n_poles(1) == 17);  // 10.15 Hz: orders 2-6 and 14-40
}

TEST_CASE("selection: given-back poles need the frequency too, and the clusters are judged again") {
    // as above: the mode at 10 Hz, xi 2 %, shape 0, orders 8-40; the other cluster's poles of
    // orders 2-6 at lead_f, xi 2 %, shape 3, and its own at 10.15 Hz, xi 0.3 %, shape 3, orders
    // from `from` to 40 (none if from > 40)
    auto diagram = [](double lead_f, Index from) {
        std::map<Index, std::vector<P>> by_order;
        for (Index n = 2; n <= 40; n += 2) {
            if (n < 8) by_order[n] = {{lead_f, 0.02, 3}};
            else by_order[n] = {{10.0, 0.02, 0}};
            if (n >= from) by_order[n].push_back({10.15, 0.003, 3});
        }
        return all_stable(by_order);
    };
    modaluq::ClusteringOptions o;
    o.min_cluster_size = 5;
    o.drop_noise_twins = false;
    // nearer the 10.15 Hz cluster in frequency (10.12 Hz), though not in damping: not given back,
    // and the mode (from order 8) is the twin
    auto s = modaluq::select_modes(diagram(10.12, 14), o);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.15).epsilon(0.005));
    CHECK(s.order_min(0) == 2);
    // a cluster left with 4 poles (orders 34-40) after giving 3 is below the minimum size (5)
    s = modaluq::select_modes(diagram(10.01, 34), o);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.0));
    CHECK(s.order_min(0) == 2);
    CHECK(s.n_poles(0) == 20);
    REQUIRE(s.dropped_code.size() == 1);
    CHECK(s.dropped_code[0] == modaluq::DropReason::too_few_poles);
    CHECK(s.dropped_reason[0] == "4 poles, fewer than 5");
    CHECK(s.dropped_first_order(0) == 34);
    // without the option the 7-pole cluster is the earlier one, and the mode its twin
    modaluq::ClusteringOptions off = o;
    off.reassign_borrowed_poles = false;
    s = modaluq::select_modes(diagram(10.01, 34), off);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.n_poles(0) == 7);
    // a cluster all of whose poles go back (orders 2-6 only) is a piece of the mode: gone whole
    o.min_cluster_size = 3;
    s = modaluq::select_modes(diagram(10.01, 99), o);
    REQUIRE(s.n_modes() == 1);
    CHECK(s.frequency_hz(0) == doctest::Approx(10.0));
    CHECK(s.n_poles(0) == 20);
    CHECK(s.dropped_code.empty());
}

TEST_CASE("selection: each mode carries its representative pole's f-xi correlation and block-length flag") {
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 2; n <= 20; n += 2) by_order[n] = {{5.0 + 1e-4 * double(n), 0.02, 0}, {12.0, 0.01, 1}};
    modaluq::Diagram d = all_stable(by_order);
    // unknown (poles without them): NaN and false
    auto s = modaluq::select_modes(d);
    REQUIRE(s.n_modes() == 2);
    CHECK(std::isnan(s.frequency_damping_correlation(0)));
    CHECK_FALSE(s.block_too_short.any());
    const Index n = d.size();
    d.poles.frequency_damping_correlation = Eigen::VectorXd::LinSpaced(n, -0.9, 0.9);
    d.poles.block_too_short.setConstant(n, false);
    for (Index i = 0; i < n; ++i) d.poles.block_too_short(i) = d.poles.frequency_hz(i) > 10.0;
    s = modaluq::select_modes(d);
    for (Index k = 0; k < 2; ++k) {
        const Index rep = s.representative_pole(k);
        CHECK(s.frequency_damping_correlation(k) == d.poles.frequency_damping_correlation(rep));
        CHECK(s.block_too_short(k) == d.poles.block_too_short(rep));
    }
    CHECK(s.block_too_short(1));
    d.poles.block_too_short.resize(3);  // neither empty nor one per pole
    CHECK_THROWS_WITH_AS(d.poles.validate(), doctest::Contains("block_too_short"), modaluq::invalid_argument);
}

TEST_CASE("selection: cluster_std mean reports the norm of the mean of the reliable members' factor rows") {
    std::map<Index, std::vector<P>> by_order;
    for (Index n = 2; n <= 24; n += 2) by_order[n] = {{5.0 + 1e-4 * double(n % 5), 0.02, 0}, {12.0, 0.01, 1}};
    modaluq::Diagram d = all_stable(by_order);
    modaluq::Poles& poles = d.poles;
    const Index n = d.size(), nb = 7;
    // known factor rows: column i is [u_f; u_xi] of pole i; each pole's std their norms, as identify gives them
    std::mt19937_64 rng(5);
    std::normal_distribution<double> N(0.0, 1.0);
    poles.frequency_damping_factor.resize(2 * nb, n);
    for (Index i = 0; i < n; ++i) {
        for (Index r = 0; r < 2 * nb; ++r) poles.frequency_damping_factor(r, i) = N(rng) * (r < nb ? 1e-3 : 1e-4);
        poles.frequency_std(i) = poles.frequency_damping_factor.col(i).head(nb).norm();
        poles.damping_std(i) = poles.frequency_damping_factor.col(i).tail(nb).norm();
    }
    // one member of the 5 Hz mode at a close cut, one noise-coupled: neither gives the sigma
    const Index close = find(d, 10, 5.0), coupled = find(d, 16, 5.0 + 1e-4);
    poles.close_singular_values(close) = true;
    poles.noise_coupled(coupled) = true;

    modaluq::ClusteringOptions median, mean;
    CHECK(median.cluster_std == modaluq::ClusterStd::median);  // the default: one record's selection
    mean.cluster_std = modaluq::ClusterStd::mean;
    const auto a = modaluq::select_modes(d, median), b = modaluq::select_modes(d, mean);
    REQUIRE(a.n_modes() == 2);
    REQUIRE(b.n_modes() == 2);
    for (Index k = 0; k < 2; ++k) {
        CAPTURE(k);
        // the clusters, the representative and its value do not depend on the option
        CHECK(a.members[std::size_t(k)] == b.members[std::size_t(k)]);
        CHECK(a.representative_pole(k) == b.representative_pole(k));
        CHECK(a.frequency_hz(k) == b.frequency_hz(k));
        CHECK(a.damping_ratio(k) == b.damping_ratio(k));
        CHECK(a.frequency_std_per_bandwidth(k) == b.frequency_std_per_bandwidth(k));
        // the mean of the rows of the reliable members, formed here
        Eigen::VectorXd u = Eigen::VectorXd::Zero(2 * nb);
        std::vector<double> sf;
        Index used = 0;
        for (Index i : b.members[std::size_t(k)]) {
            if (poles.close_singular_values(i) || poles.noise_coupled(i)) continue;
            u += poles.frequency_damping_factor.col(i);
            sf.push_back(poles.frequency_std(i));
            ++used;
        }
        u /= double(used);
        CHECK(used == Index(b.members[std::size_t(k)].size()) - (k == 0 ? 2 : 0));
        const double want_f = u.head(nb).norm(), want_xi = u.tail(nb).norm();
        CHECK(b.frequency_std(k) == doctest::Approx(want_f).epsilon(1e-13));
        CHECK(b.damping_std(k) == doctest::Approx(want_xi).epsilon(1e-13));
        CHECK(b.frequency_damping_correlation(k) ==
              doctest::Approx(u.head(nb).dot(u.tail(nb)) / (want_f * want_xi)).epsilon(1e-12));
        // independent rows: the mean's sigma is about 1/sqrt(K) of one pole's, below the median
        CHECK(b.frequency_std(k) < 0.6 * a.frequency_std(k));
        std::sort(sf.begin(), sf.end());
        CHECK(a.frequency_std(k) == doctest::Approx(sf.size() % 2 ? sf[sf.size() / 2]
                                                                  : 0.5 * (sf[sf.size() / 2 - 1] + sf[sf.size() / 2])));
    }
    // the flagged members would change it: they are left out, not merely rare
    {
        Eigen::VectorXd all = Eigen::VectorXd::Zero(2 * nb);
        for (Index i : b.members[0]) all += poles.frequency_damping_factor.col(i);
        all /= double(b.members[0].size());
        CHECK(std::abs(all.head(nb).norm() - b.frequency_std(0)) > 1e-6 * b.frequency_std(0));
    }
    // identical rows (members perfectly correlated): the mean's sigma is each pole's
    modaluq::Diagram same = d;
    for (Index i = 0; i < n; ++i) {
        same.poles.frequency_damping_factor.col(i) = poles.frequency_damping_factor.col(0);
        same.poles.frequency_std(i) = poles.frequency_std(0);
        same.poles.damping_std(i) = poles.damping_std(0);
    }
    const auto c = modaluq::select_modes(same, mean);
    CHECK(c.frequency_std(0) == doctest::Approx(poles.frequency_std(0)).epsilon(1e-14));
    CHECK(c.damping_std(1) == doctest::Approx(poles.damping_std(0)).epsilon(1e-14));
    // poles without factor rows (may be empty, as frequency_damping_correlation): the median
    d.poles.frequency_damping_factor.resize(0, 0);
    const auto e = modaluq::select_modes(d, mean);
    CHECK(e.frequency_std == a.frequency_std);
    CHECK(e.damping_std == a.damping_std);
    // rows for some poles only: refused (by the poles' check and by the selection)
    d.poles.frequency_damping_factor.resize(2 * nb, 3);
    CHECK_THROWS_WITH_AS(d.poles.validate(), doctest::Contains("frequency_damping_factor"), modaluq::invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::select_modes(d, mean), doctest::Contains("frequency_damping_factor"),
                         modaluq::invalid_argument);
    d.poles.frequency_damping_factor.resize(2 * nb + 1, n);  // not two rows of n_b
    CHECK_THROWS_WITH_AS(d.poles.validate(), doctest::Contains("frequency_damping_factor"), modaluq::invalid_argument);
    CHECK(std::string(modaluq::to_string(modaluq::ClusterStd::mean)) == "mean");
}

}  // namespace test_selection
