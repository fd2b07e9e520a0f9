// Stabilization diagram (stabilization.hpp) and mode selection (selection.hpp): statuses and
// reasons from hand-made poles whose outcome follows from the documented rules, the clustering
// against the naive O(n^3) agglomerative definition, and an end-to-end run on a simulation.
#include <doctest/doctest.h>

#include <algorithm>
#include <map>
#include <set>

#include "support.hpp"

using namespace support;
using modaluq::PoleStatus;

namespace {

struct P {
    double f, xi = 0.02;
    int shape = 0;           // index into kShapes
    double sf = -1, sxi = -1;  // default: 0.1 % of f, 5 % of xi
    bool coupled = false;
};

// 0 and 3 have MAC 0.88: one mode whose shape varies with the order, or two close modes
const std::vector<std::vector<double>> kShapes = {{1.0, 0.5, -0.3}, {0.2, -0.7, 1.0}, {0.6, 1.0, 0.4}, {1.0, 0.5, 0.1}};

// Poles of the given orders (each order's poles sorted by frequency, as identify gives them).
modaluq::Poles make_poles(const std::map<Index, std::vector<P>>& by_order, bool with_std = true) {
    Index n = 0;
    for (const auto& kv : by_order) n += Index(kv.second.size());
    modaluq::Poles p;
    p.order.resize(n);
    p.frequency_hz.resize(n);
    p.damping_ratio.resize(n);
    p.frequency_std.resize(n);
    p.damping_std.resize(n);
    p.mode_shape.resize(3, n);
    p.mode_shape_std_real.setConstant(3, n, 1e-3);
    p.mode_shape_std_imag.setConstant(3, n, 1e-3);
    p.close_singular_values.setConstant(n, false);
    p.noise_coupled.setConstant(n, false);
    p.has_uncertainty = with_std;
    Index i = 0;
    for (const auto& [order, list] : by_order) {
        p.orders.push_back(order);
        std::vector<P> sorted = list;
        std::sort(sorted.begin(), sorted.end(), [](const P& a, const P& b) { return a.f < b.f; });
        for (const P& q : sorted) {
            p.order(i) = order;
            p.frequency_hz(i) = q.f;
            p.damping_ratio(i) = q.xi;
            const double nan = std::numeric_limits<double>::quiet_NaN();
            p.frequency_std(i) = with_std ? (q.sf < 0 ? 1e-3 * q.f : q.sf) : nan;
            p.damping_std(i) = with_std ? (q.sxi < 0 ? 0.05 * std::abs(q.xi) : q.sxi) : nan;
            for (Index r = 0; r < 3; ++r) p.mode_shape(r, i) = kShapes[q.shape][r];
            p.noise_coupled(i) = q.coupled;
            ++i;
        }
    }
    return p;
}

Index find(const modaluq::Diagram& d, Index order, double f) {
    for (Index i = 0; i < d.size(); ++i)
        if (d.poles.order(i) == order && std::abs(d.poles.frequency_hz(i) - f) < 1e-12) return i;
    FAIL("no pole at order ", order, " and ", f, " Hz");
    return -1;
}

// A diagram whose poles are all stable: selection tests independent of the stability rules.
modaluq::Diagram all_stable(const std::map<Index, std::vector<P>>& by_order) {
    modaluq::Diagram d;
    d.poles = make_poles(by_order);
    d.status.assign(std::size_t(d.poles.size()), PoleStatus::stable);
    return d;
}

}  // namespace

TEST_CASE("stabilization: statuses and reasons follow the documented rules") {
    const auto p = make_poles({
        {2, {{10.0}, {20.0, 0.30}}},
        {4, {{10.01}, {27.0}, {20.0, 0.02, 0, 1.2}}},             // 27 Hz: nothing within 5 % at order 2
        {6, {{10.01, 0.025}, {10.3, 0.02, 1}, {40.0, -0.01}}},   // damping +25 %; 10.3 Hz: 2.9 % off
        {8, {{10.06, 0.025, 1}}},  // nearer in frequency to 10.01 Hz, but only 10.3 Hz has its shape
    });
    const auto d = modaluq::stabilization_diagram(p);
    REQUIRE(d.size() == 9);
    auto status = [&](Index order, double f) { return d.status[find(d, order, f)]; };
    auto reason = [&](Index order, double f) { return d.reason[find(d, order, f)]; };

    CHECK(status(2, 10.0) == PoleStatus::unstable);
    CHECK(reason(2, 10.0) == "lowest order: no previous order to compare");
    CHECK(status(2, 20.0) == PoleStatus::rejected);
    CHECK(reason(2, 20.0) == "damping ratio 30 % > 20 %");

    CHECK(status(4, 10.01) == PoleStatus::stable);
    CHECK(reason(4, 10.01).empty());
    CHECK(d.matched_pole(find(d, 4, 10.01)) == find(d, 2, 10.0));
    CHECK(d.frequency_change(find(d, 4, 10.01)) == doctest::Approx(0.001));
    CHECK(status(4, 27.0) == PoleStatus::unstable);
    CHECK(reason(4, 27.0) == "no match: no pole within 5 % in frequency at the previous order 2");
    CHECK(d.matched_pole(find(d, 4, 27.0)) == -1);
    CHECK(status(4, 20.0) == PoleStatus::rejected);  // sigma_f / f = 6 %
    CHECK(reason(4, 20.0) == "frequency std/f 6 % > 5 %");

    CHECK(status(6, 10.01) == PoleStatus::stable_frequency);
    // default: the damping change against 2 combined sigma (sigma_xi = 5 % of xi here)
    CHECK(reason(6, 10.01) == "damping change 0.005 > 2 x combined std 0.0016 (vs order 4)");
    modaluq::StabilityCriteria relative;
    relative.damping_std_factor.reset();
    const auto d_rel = modaluq::stabilization_diagram(p, relative);
    CHECK(d_rel.reason[find(d_rel, 6, 10.01)] == "damping change 25 % > 10 % (vs order 4)");
    // 10.3 Hz matches the 10.01 Hz pole (within the window) but moves 2.9 %, 20 combined sigma
    CHECK(status(6, 10.3) == PoleStatus::unstable);
    const Index i103 = find(d, 6, 10.3);
    CHECK(d.matched_pole(i103) == find(d, 4, 10.01));
    CHECK(reason(6, 10.3).rfind("frequency change 2.9 % > 1 %; frequency change 0.29 Hz > 2 x combined std", 0) == 0);
    CHECK(d.frequency_change_std(i103) == doctest::Approx(0.29 / std::hypot(10.3e-3, 10.01e-3)));
    CHECK(status(6, 40.0) == PoleStatus::rejected);
    CHECK(reason(6, 40.0) == "damping ratio -1 % < 0 %");

    // order 8: best match is the 10.3 Hz pole of the same shape (MAC 1), not the 10.01 Hz one
    CHECK(d.matched_pole(find(d, 8, 10.06)) == i103);
    CHECK(status(8, 10.06) == PoleStatus::unstable);
}

TEST_CASE("stabilization: sigma tests, a band, and no uncertainty") {
    SUBCASE("a frequency change within 1 % but beyond 2 combined sigma is unstable") {
        const auto p = make_poles({{2, {{10.0, 0.02, 0, 1e-4}}}, {4, {{10.01, 0.02, 0, 1e-4}}}});
        const auto d = modaluq::stabilization_diagram(p);
        CHECK(d.status[1] == PoleStatus::unstable);
        CHECK(d.frequency_change_std(1) == doctest::Approx(0.01 / std::hypot(1e-4, 1e-4)));
        modaluq::StabilityCriteria loose;
        loose.frequency_std_factor.reset();
        CHECK(modaluq::stabilization_diagram(p, loose).status[1] == PoleStatus::stable);
    }
    SUBCASE("damping judged against its sigma replaces the fixed 10 %") {
        const auto p = make_poles({{2, {{10.0, 0.020, 0, -1, 0.004}}}, {4, {{10.0, 0.026, 0, -1, 0.004}}}});
        modaluq::StabilityCriteria c;
        c.damping_std_factor.reset();  // the relative test: +30 % > 10 %
        CHECK(modaluq::stabilization_diagram(p, c).status[1] == PoleStatus::stable_frequency);
        c.damping_std_factor = 2.0;  // the default: |dxi| = 0.006 < 2 * 0.0057
        auto d = modaluq::stabilization_diagram(p, c);
        CHECK(d.status[1] == PoleStatus::stable);
        c.max_damping_change_with_std = 0.25;  // the backstop
        d = modaluq::stabilization_diagram(p, c);
        CHECK(d.status[1] == PoleStatus::stable_frequency);
        CHECK(d.reason[1] == "damping change 30 % > 25 % (vs order 2)");
    }
    SUBCASE("poles outside the band are rejected with the band in the reason") {
        modaluq::StabilityCriteria c;
        c.frequency_range = std::make_pair(5.0, 15.0);
        const auto d = modaluq::stabilization_diagram(make_poles({{2, {{3.0}, {10.0}}}}), c);
        CHECK(d.status[0] == PoleStatus::rejected);
        CHECK(d.reason[0] == "outside the band 5-15 Hz");
        CHECK(d.status[1] == PoleStatus::unstable);
    }
    SUBCASE("without uncertainty the sigma tests are skipped") {
        const auto p = make_poles({{2, {{10.0}}}, {4, {{10.01}}}}, /*with_std=*/false);
        const auto d = modaluq::stabilization_diagram(p);
        CHECK(d.status[1] == PoleStatus::stable);
        CHECK(std::isnan(d.frequency_change_std(1)));
    }
    SUBCASE("an order with no accepted pole breaks the chain") {
        const auto d = modaluq::stabilization_diagram(make_poles({{2, {{10.0, 0.5}}}, {4, {{10.0}}}}));
        CHECK(d.reason[1] == "no accepted pole at the previous order 2");
    }
    SUBCASE("bad criteria and inconsistent poles are refused by name") {
        modaluq::StabilityCriteria c;
        c.min_mac = 1.5;
        CHECK_THROWS_WITH_AS(modaluq::stabilization_diagram(make_poles({{2, {{10.0}}}}), c),
                             doctest::Contains("min_mac"), modaluq::invalid_argument);
        auto p = make_poles({{2, {{10.0}}}});
        p.damping_ratio.resize(0);
        CHECK_THROWS_AS(modaluq::stabilization_diagram(p), modaluq::invalid_argument);
        c = {};
        c.frequency_range = std::make_pair(5.0, 1.0);
        CHECK_THROWS_WITH_AS(c.validate(), doctest::Contains("frequency_range"), modaluq::invalid_argument);
    }
}

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

TEST_CASE("stabilization and selection end to end find the simulated modes") {
    const Sim s = simulate(3, {0, 1, 2}, 30000, 5, true, 0.3, 0.05);
    std::vector<Index> orders;
    for (Index n = 2; n <= 30; n += 2) orders.push_back(n);
    const auto id = modaluq::identify(s.y, s.u, options(s.fs, 12, 12, orders, true, 30));
    const auto d = modaluq::stabilization_diagram(id);
    CHECK(d.size() == modaluq::poles_of(id).size());
    const auto sel = modaluq::select_modes(d);
    REQUIRE(sel.n_modes() == 3);
    for (Index k = 0; k < 3; ++k) {
        CAPTURE(k);
        CHECK(std::abs(sel.frequency_hz(k) - s.f_true(k)) < 4.0 * sel.frequency_std(k));
        CHECK(std::abs(sel.damping_ratio(k) - 0.02) < 4.0 * sel.damping_std(k) + 0.005);
    }
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
    modaluq::ClusteringOptions o;
    o.max_frequency_std_per_bandwidth.reset();
    CHECK(modaluq::select_modes(d, o).n_modes() == 2);
    o.max_frequency_std_per_bandwidth = 3.0;
    CHECK(modaluq::select_modes(d, o).n_modes() == 2);
    // a too-small cluster says so
    o = {};
    o.min_cluster_size = 11;
    s = modaluq::select_modes(d, o);
    CHECK(s.n_modes() == 0);
    REQUIRE(s.dropped_reason.size() == 2);
    CHECK(s.dropped_reason[0] == "10 poles, fewer than 11");
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
    o.drop_doublets = false;
    CHECK(modaluq::select_modes(d, o).n_modes() == 3);
    o.drop_doublets = true;
    o.doublet_window = 0.02;
    CHECK(modaluq::select_modes(d, o).n_modes() == 3);
}
