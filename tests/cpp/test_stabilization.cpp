// Stabilization diagram (stabilization.hpp) and mode selection (selection.hpp): statuses and
// reasons from hand-made poles whose outcome follows from the documented rules, the clustering
// against the naive O(n^3) agglomerative definition, and an end-to-end run on a simulation.
#include <doctest/doctest.h>

#include <algorithm>
#include <map>
#include <set>

#include "support/stabilization_cases.hpp"

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_stabilization {

using namespace support;
using modaluq::PoleStatus;


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
    SUBCASE("MPC and MPD of every pole; their criteria are off by default and reject complex shapes when set") {
        auto p = make_poles({{2, {{3.0}, {10.0}}}});
        p.mode_shape(1, 1) = std::complex<double>(0.0, 1.0);  // pole at 10 Hz: shape {1, i, -0.3}
        auto d = modaluq::stabilization_diagram(p);
        CHECK(d.mpc(0) == doctest::Approx(1.0));
        CHECK(d.mpd_deg(0) == doctest::Approx(0.0).scale(1.0));
        CHECK(d.mpc(1) == doctest::Approx(modaluq::modal_phase_collinearity(Eigen::VectorXcd(p.mode_shape.col(1)))));
        CHECK(d.mpc(1) < 0.5);
        CHECK(d.status[1] == PoleStatus::unstable);  // kept: no MPC test by default
        modaluq::StabilityCriteria c;
        c.min_mpc = 0.8;
        d = modaluq::stabilization_diagram(p, c);
        CHECK(d.status[0] == PoleStatus::unstable);
        CHECK(d.status[1] == PoleStatus::rejected);
        CHECK(d.reason[1].rfind("MPC ", 0) == 0);
        c = {};
        c.max_mpd_deg = 10.0;
        d = modaluq::stabilization_diagram(p, c);
        CHECK(d.status[1] == PoleStatus::rejected);
        CHECK(d.reason[1].find("deg > 10 deg") != std::string::npos);
        c.max_mpd_deg = 91.0;
        CHECK_THROWS_WITH_AS(c.validate(), doctest::Contains("max_mpd_deg"), modaluq::invalid_argument);
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

}  // namespace test_stabilization
