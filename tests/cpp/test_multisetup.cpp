#include <doctest/doctest.h>

#include <modaluq/multisetup.hpp>

#include <algorithm>

#include "support/multisetup_case.hpp"
#include "support/support.hpp"

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_multisetup {

using namespace support;
namespace mc = multisetup_case;

namespace {

using Vec = std::vector<double>;

MatrixXd as_matrix(const Vec& v, Index rows) {
    return Eigen::Map<const MatrixXd>(v.data(), rows, static_cast<Index>(v.size()) / rows);
}

// Largest column-wise relative difference |a_i - b_i| / |b_i| (columns: modes).
double max_rel(const MatrixXd& a, const MatrixXd& b) {
    REQUIRE(a.rows() == b.rows());
    REQUIRE(a.cols() == b.cols());
    double worst = 0.0;
    for (Index i = 0; i < b.cols(); ++i)
        worst = std::max(worst, (a.col(i) - b.col(i)).norm() / std::max(b.col(i).norm(), 1e-300));
    return worst;
}

struct Campaign {
    std::vector<modaluq::SetupData> setups;
    modaluq::IdentifyOptions options;
};

Campaign make_campaign(bool io, bool uncertainty = true) {
    const Vec* ys[] = {io ? &mc::io_y0 : &mc::oo_y0, io ? &mc::io_y1 : &mc::oo_y1, io ? &mc::io_y2 : &mc::oo_y2};
    const Vec* us[] = {&mc::io_u0, &mc::io_u1, &mc::io_u2};
    const Index ns[] = {io ? mc::io_n0 : mc::oo_n0, io ? mc::io_n1 : mc::oo_n1, io ? mc::io_n2 : mc::oo_n2};
    Campaign c;
    c.options.fs = mc::fs;
    c.options.block_rows = mc::p;
    c.options.past_block_rows = mc::p;
    c.options.orders = mc::orders;
    c.options.n_blocks = mc::n_blocks;
    c.options.uncertainty = uncertainty;
    for (Index j = 0; j < mc::n_setups; ++j) {
        const MatrixXd y = Eigen::Map<const MatrixXd>(ys[j]->data(), mc::n_channels, ns[j]);
        const MatrixXd u = io ? MatrixXd(Eigen::Map<const MatrixXd>(us[j]->data(), 1, ns[j])) : MatrixXd();
        modaluq::HankelLayout L;
        L.block_rows = mc::p;
        L.past_block_rows = mc::p;
        L.references = {0, 1};
        modaluq::SetupData s;
        s.covariances = modaluq::compute_covariances(y, u, L, mc::n_blocks, true, uncertainty);
        s.references = {0, 1};
        c.setups.push_back(std::move(s));
    }
    return c;
}

struct Reference {
    Index modes;
    const Vec *f, *xi, *re, *im, *f_std, *xi_std, *std_re, *std_im, *cov;
};

Reference reference(bool io, Index n) {
    if (io)
        return n == 6 ? Reference{mc::io_modes6, &mc::io_f6, &mc::io_xi6, &mc::io_shape_re6, &mc::io_shape_im6,
                                  &mc::io_f_std6, &mc::io_xi_std6, &mc::io_shape_std_re6, &mc::io_shape_std_im6, &mc::io_cov6}
                      : Reference{mc::io_modes12, &mc::io_f12, &mc::io_xi12, &mc::io_shape_re12, &mc::io_shape_im12,
                                  &mc::io_f_std12, &mc::io_xi_std12, &mc::io_shape_std_re12, &mc::io_shape_std_im12,
                                  &mc::io_cov12};
    return n == 6 ? Reference{mc::oo_modes6, &mc::oo_f6, &mc::oo_xi6, &mc::oo_shape_re6, &mc::oo_shape_im6,
                              &mc::oo_f_std6, &mc::oo_xi_std6, &mc::oo_shape_std_re6, &mc::oo_shape_std_im6, &mc::oo_cov6}
                  : Reference{mc::oo_modes12, &mc::oo_f12, &mc::oo_xi12, &mc::oo_shape_re12, &mc::oo_shape_im12,
                              &mc::oo_f_std12, &mc::oo_xi_std12, &mc::oo_shape_std_re12, &mc::oo_shape_std_im12,
                              &mc::oo_cov12};
}

}  // namespace

TEST_CASE("the modular merge equals the NumPy reference (oracle_multisetup), output-only and input/output") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Campaign c = make_campaign(io);
        const modaluq::SetupsIdentification id = modaluq::identify_setups(c.setups, c.options);
        REQUIRE(id.dof_setup.size() == size_t(mc::n_global));
        CHECK(id.n_blocks == 3 * mc::n_blocks);
        for (Index n : mc::orders) {
            CAPTURE(n);
            const Reference r = reference(io, n);
            const modaluq::Modes& m = id.at_order(n);
            REQUIRE(m.n_modes() == r.modes);
            const Index l = mc::n_global;
            double worst_point = 0.0, worst_sigma = 0.0;
            worst_point = std::max(worst_point, max_rel(m.frequency_hz.transpose(), as_matrix(*r.f, 1)));
            worst_point = std::max(worst_point, max_rel(m.damping_ratio.transpose(), as_matrix(*r.xi, 1)));
            worst_point = std::max(worst_point, max_rel(m.mode_shape.real(), as_matrix(*r.re, l)));
            worst_point = std::max(worst_point, max_rel(m.mode_shape.imag(), as_matrix(*r.im, l)));
            worst_sigma = std::max(worst_sigma, max_rel(m.frequency_std.transpose(), as_matrix(*r.f_std, 1)));
            worst_sigma = std::max(worst_sigma, max_rel(m.damping_std.transpose(), as_matrix(*r.xi_std, 1)));
            worst_sigma = std::max(worst_sigma, max_rel(m.mode_shape_std_real, as_matrix(*r.std_re, l)));
            worst_sigma = std::max(worst_sigma, max_rel(m.mode_shape_std_imag, as_matrix(*r.std_im, l)));
            worst_sigma = std::max(worst_sigma, max_rel(m.covariance, as_matrix(*r.cov, (2 + 2 * l) * (2 + 2 * l))));
            MESSAGE("io=", io, " order ", n, ": max relative difference, point ", worst_point, ", sigma ", worst_sigma);
            CHECK(worst_point < 1e-10);
            CHECK(worst_sigma < 1e-10);
        }
    }
}

TEST_CASE("without uncertainty the merge gives the same point estimates") {
    const Campaign a = make_campaign(false), b = make_campaign(false, false);
    const auto ia = modaluq::identify_setups(a.setups, a.options), ib = modaluq::identify_setups(b.setups, b.options);
    for (Index n : mc::orders) {
        const auto &ma = ia.at_order(n), &mb = ib.at_order(n);
        REQUIRE(ma.n_modes() == mb.n_modes());
        CHECK(rel(ma.frequency_hz, mb.frequency_hz) < 1e-13);
        CHECK(mb.frequency_std.size() == 0);
    }
    CHECK(std::isnan(ib.signal_to_noise));
}

TEST_CASE("a one-setup campaign equals identify (unfrozen)") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        Campaign c = make_campaign(io);
        c.setups.resize(1);
        c.options.orders = {4, 8, 10};
        c.options.freeze_noise = false;
        const auto merged = modaluq::identify_setups(c.setups, c.options);
        const auto single = modaluq::identify(c.setups[0].covariances, c.options);
        CHECK(rel(merged.singular_values, single.singular_values) < 1e-14);
        for (Index n : c.options.orders) {
            CAPTURE(n);
            const auto &a = merged.at_order(n), &b = single.at_order(n);
            REQUIRE(a.n_modes() == b.n_modes());
            CHECK(rel(a.frequency_hz, b.frequency_hz) < 1e-11);
            CHECK(rel(a.damping_ratio, b.damping_ratio) < 1e-9);
            CHECK(max_rel(a.mode_shape.real(), b.mode_shape.real()) < 1e-9);
            CHECK(rel(a.frequency_std, b.frequency_std) < 1e-8);
            CHECK(rel(a.damping_std, b.damping_std) < 1e-8);
            CHECK(rel(a.covariance, b.covariance) < 1e-8);
        }
    }
}

TEST_CASE("the merge feeds the stabilization diagram and the selection unchanged") {
    const Campaign c = make_campaign(false);
    const auto id = modaluq::identify_setups(c.setups, c.options);
    const modaluq::Identification& base = id;
    CHECK(base.modes.size() == 2);
    CHECK(base.modes.back().mode_shape.rows() == mc::n_global);
    CHECK(base.modes.back().covariance.rows() == (2 + 2 * mc::n_global) * (2 + 2 * mc::n_global));
    // Global DOFs: the two references (setup 0), then each setup's two moving channels.
    const std::vector<Index> setup = {0, 0, 0, 0, 1, 1, 2, 2}, channel = {0, 1, 2, 3, 2, 3, 2, 3};
    CHECK(id.dof_setup == setup);
    CHECK(id.dof_channel == channel);
}

TEST_CASE("campaigns that cannot be merged are refused with the reason") {
    using modaluq::invalid_argument;
    SUBCASE("a setup without the references") {
        Campaign c = make_campaign(false);
        c.setups[2].references = {0};
        CHECK_THROWS_WITH_AS(modaluq::identify_setups(c.setups, c.options),
                             doctest::Contains("setup 2 has 1 references, setup 0 has 2"), invalid_argument);
        c.setups[2].references = {0, 7};
        CHECK_THROWS_WITH_AS(modaluq::identify_setups(c.setups, c.options),
                             doctest::Contains("setup 2: reference 1 is output 7, out of range"), invalid_argument);
    }
    SUBCASE("references that are not the past channels") {
        Campaign c = make_campaign(false);
        c.setups[1].references = {1, 0};
        CHECK_THROWS_WITH_AS(modaluq::identify_setups(c.setups, c.options),
                             doctest::Contains("setup 1: past channel 0"), invalid_argument);
    }
    SUBCASE("a different sampling frequency") {
        Campaign c = make_campaign(false);
        c.setups[1].fs = 50.0;
        CHECK_THROWS_WITH_AS(modaluq::identify_setups(c.setups, c.options),
                             doctest::Contains("setup 1: fs = 50 Hz differs"), invalid_argument);
    }
    SUBCASE("an order above what the merge supports") {
        Campaign c = make_campaign(false);
        c.options.orders = {mc::p * 2 + 2};  // p r = 14 < 16
        CHECK_THROWS_WITH_AS(modaluq::identify_setups(c.setups, c.options),
                             doctest::Contains("above what the merge supports"), invalid_argument);
    }
    SUBCASE("different horizons") {
        Campaign c = make_campaign(false);
        c.options.block_rows = mc::p + 1;
        CHECK_THROWS_WITH_AS(modaluq::identify_setups(c.setups, c.options),
                             doctest::Contains("setup 0: its covariances have block_rows = 7"), invalid_argument);
    }
    SUBCASE("no setups") {
        Campaign c = make_campaign(false);
        c.setups.clear();
        CHECK_THROWS_AS(modaluq::identify_setups(c.setups, c.options), invalid_argument);
    }
}

}  // namespace test_multisetup
