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
    const Vec *f, *xi, *re, *im, *f_std, *xi_std, *std_re, *std_im, *cov, *rho;
};

#define MODALUQ_MS_REF(tag, n)                                                                                     \
    Reference {                                                                                                     \
        mc::tag##_modes##n, &mc::tag##_f##n, &mc::tag##_xi##n, &mc::tag##_shape_re##n, &mc::tag##_shape_im##n,       \
            &mc::tag##_f_std##n, &mc::tag##_xi_std##n, &mc::tag##_shape_std_re##n, &mc::tag##_shape_std_im##n,       \
            &mc::tag##_cov##n, &mc::tag##_rho##n                                                                    \
    }

Reference reference(bool io, Index n) {
    REQUIRE((n == 6 || n == 12 || n == 14));
    if (io) return n == 6 ? MODALUQ_MS_REF(io, 6) : n == 12 ? MODALUQ_MS_REF(io, 12) : MODALUQ_MS_REF(io, 14);
    return n == 6 ? MODALUQ_MS_REF(oo, 6) : n == 12 ? MODALUQ_MS_REF(oo, 12) : MODALUQ_MS_REF(oo, 14);
}
#undef MODALUQ_MS_REF

}  // namespace

TEST_CASE("the modular merge equals the NumPy reference (oracle_multisetup), output-only and input/output") {
    // Orders 6 and 12 (the true order) are below every setup's noise floor; at 14 some setups'
    // columns are frozen (§13.4), and each pole's sigma is the frozen or the unfrozen one by its rho.
    for (bool io : {false, true}) {
        CAPTURE(io);
        Campaign c = make_campaign(io);
        c.options.coupling_sketch = 0;  // the reference's rho is from every block
        const modaluq::SetupsIdentification id = modaluq::identify_setups(c.setups, c.options);
        REQUIRE(id.dof_setup.size() == size_t(mc::n_global));
        CHECK(id.n_blocks == 3 * mc::n_blocks);
        CHECK(id.setup_significant_singular_values == (io ? mc::io_k_star : mc::oo_k_star));
        CHECK(id.significant_singular_values == 12);
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
            worst_sigma = std::max(worst_sigma, max_rel(m.noise_coupling.transpose(), as_matrix(*r.rho, 1)));
            if (n <= 12) CHECK((m.noise_coupling.array() == 1.0).all());
            MESSAGE("io=", io, " order ", n, ": max relative difference, point ", worst_point, ", sigma ", worst_sigma);
            // Above the true order (12) some poles are noise: their point estimates are as well
            // conditioned as the gaps between noise singular values allow (1.7e-10 seen).
            CHECK(worst_point < (n <= 12 ? 1e-10 : 1e-9));
            CHECK(worst_sigma < 1e-10);
        }
    }
}

TEST_CASE("a setup's frozen dGamma equals finite differences of its Gamma with the noise directions held") {
    // gamma_perturbation_setup (§13.4): columns j >= k* only scale, d gamma_j = u_j d s_j / (2 sqrt s_j)
    // (5.13), the exact derivative of Gamma~(H) = [u_j(H) sqrt s_j(H) for j < k*, u0_j sqrt s_j(H) beyond].
    const Campaign c = make_campaign(false);
    const modaluq::Covariances& cov = c.setups[0].covariances;
    const Index n = 14, kf = mc::oo_k_star[0], l = mc::n_channels;
    REQUIRE(kf < n);
    const auto sub = modaluq::subspace_matrix(cov);
    const modaluq::Realization re(sub.H, l, n);
    const MatrixXd TH = modaluq::propagate_to_subspace(sub, cov, cov.covariance_factor());
    const auto gamma_tilde = [&](const MatrixXd& H) {
        const modaluq::Realization rp(H, l, n);
        MatrixXd g = rp.observability();
        for (Index j = 0; j < n; ++j) {  // the SVD's sign convention may flip a column: align it
            if (g.col(j).dot(re.observability().col(j)) < 0) g.col(j) *= -1.0;
            if (j >= kf) g.col(j) = re.U().col(j) * std::sqrt(rp.singular_values()(j));
        }
        return g;
    };
    for (Index k : {Index(0), Index(5)}) {
        CAPTURE(k);
        const Eigen::Map<const MatrixXd> dH(TH.col(k).data(), sub.H.rows(), sub.H.cols());
        double ds1 = 0.0;
        MatrixXd frozen;
        const MatrixXd plain = modaluq::detail::gamma_perturbation_setup(re, dH, n, ds1, kf, &frozen);
        const double h = 1e-6 * sub.H.norm() / dH.norm();
        const MatrixXd fd = (gamma_tilde(sub.H + h * dH) - gamma_tilde(sub.H - h * dH)) / (2 * h);
        CHECK(rel(frozen, fd) < 1e-6);
        CHECK(rel(frozen.leftCols(kf), plain.leftCols(kf)) < 1e-14);  // the significant columns are the plain ones
        CHECK(rel(frozen.rightCols(n - kf), plain.rightCols(n - kf)) > 1e-3);  // and the freeze does change the rest
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

TEST_CASE("a one-setup campaign equals identify, unfrozen and frozen above the noise floor") {
    // Two implementations of one definition: the per-setup freeze of §13.4 with one setup is the
    // freeze of §5.5 (QStage's fused path in identify, gamma_perturbation_setup here).
    for (bool freeze : {false, true})
    for (bool io : {false, true}) {
        CAPTURE(io);
        CAPTURE(freeze);
        Campaign c = make_campaign(io);
        c.setups.resize(1);
        c.options.orders = {4, 8, 10, 13, 14};
        c.options.freeze_noise = freeze;
        c.options.coupling_sketch = 0;  // identify's rho is from every block
        const auto merged = modaluq::identify_setups(c.setups, c.options);
        const auto single = modaluq::identify(c.setups[0].covariances, c.options);
        CHECK(rel(merged.singular_values, single.singular_values) < 1e-14);
        if (freeze) {
            CHECK(merged.significant_singular_values == single.significant_singular_values);
            if (!io) CHECK(merged.significant_singular_values == 12);  // orders 13 and 14 have frozen columns
        }
        for (Index n : c.options.orders) {
            CAPTURE(n);
            const auto &a = merged.at_order(n), &b = single.at_order(n);
            REQUIRE(a.n_modes() == b.n_modes());
            CHECK((a.noise_coupled == b.noise_coupled).all());
            CHECK(rel(a.noise_coupling, b.noise_coupling) < 1e-8);
            CHECK(rel(a.frequency_hz, b.frequency_hz) < 1e-11);
            CHECK(rel(a.damping_ratio, b.damping_ratio) < 1e-9);
            CHECK(max_rel(a.mode_shape.real(), b.mode_shape.real()) < 1e-9);
            CHECK(rel(a.frequency_std, b.frequency_std) < 1e-8);
            CHECK(rel(a.damping_std, b.damping_std) < 1e-8);
            CHECK(rel(a.covariance, b.covariance) < 1e-8);
            CHECK(rel(a.frequency_damping_factor, b.frequency_damping_factor) < 1e-8);
        }
    }
}

TEST_CASE("the sketched noise-coupling test follows its definition") {
    // coupling_sketch = s (§13.4): rho from s combinations of each setup's blocks; a flagged pole's
    // rows are its frozen rows times rho; an unflagged pole's are the frozen rows, as without the
    // sketch; a sketch as large as every setup's blocks is no sketch (the exact test). The sketch
    // itself (signs, scaling) is checked against the NumPy reference (test_multisetup_core.py).
    for (bool io : {false, true}) {
        CAPTURE(io);
        Campaign c = make_campaign(io);
        const auto run = [&](Index sketch, double limit) {
            Campaign d = c;
            d.options.coupling_sketch = sketch;
            d.options.noise_coupling_limit = limit;
            return modaluq::identify_setups(d.setups, d.options);
        };
        // nothing flagged: every pole's rows are its frozen ones; then a limit between its rhos
        const auto frozen_rows = run(3, 1e300);
        const auto& top = frozen_rows.at_order(14);
        const double limit = std::sqrt(top.noise_coupling.minCoeff() * top.noise_coupling.maxCoeff());
        REQUIRE(top.noise_coupling.maxCoeff() > 1.01 * top.noise_coupling.minCoeff());
        const auto exact = run(0, limit), sketched = run(3, limit);
        const auto whole = run(mc::n_blocks, limit);  // s >= n_b: every setup keeps its blocks
        Index flagged = 0, unflagged_above = 0;
        for (Index n : c.options.orders) {
            CAPTURE(n);
            const auto &e = exact.at_order(n), &s = sketched.at_order(n), &f = frozen_rows.at_order(n),
                       &w = whole.at_order(n);
            REQUIRE(s.n_modes() == e.n_modes());
            CHECK(rel(s.frequency_hz, e.frequency_hz) == 0.0);  // the point estimates do not depend on it
            CHECK(rel(w.noise_coupling, e.noise_coupling) < 1e-12);
            CHECK((w.noise_coupled == e.noise_coupled).all());
            CHECK(rel(w.covariance, e.covariance) < 1e-12);
            CHECK(rel(f.noise_coupling, s.noise_coupling) == 0.0);  // the limit does not move rho
            CHECK((f.noise_coupled == false).all());
            for (Index i = 0; i < s.n_modes(); ++i) {
                CAPTURE(i);
                CHECK(s.noise_coupled(i) == !(s.noise_coupling(i) <= limit));
                if (n <= 12) CHECK(s.noise_coupling(i) == 1.0);  // below every floor: no test, no sketch
                if (s.noise_coupled(i)) {
                    ++flagged;
                    const double rho = s.noise_coupling(i);
                    CHECK(rel(s.covariance.col(i), rho * rho * f.covariance.col(i)) < 1e-12);
                    CHECK(s.frequency_std(i) == doctest::Approx(rho * f.frequency_std(i)).epsilon(1e-12));
                } else {
                    if (n > 12) ++unflagged_above;
                    CHECK(rel(s.covariance.col(i), f.covariance.col(i)) == 0.0);
                    if (!e.noise_coupled(i)) CHECK(rel(s.covariance.col(i), e.covariance.col(i)) < 1e-12);
                }
            }
        }
        MESSAGE("io=", io, ": ", flagged, " poles flagged by the sketch, ", unflagged_above, " unflagged above order 12");
        CHECK(flagged > 0);
        CHECK(unflagged_above > 0);
    }
    Campaign c = make_campaign(false);
    c.options.coupling_sketch = -1;
    CHECK_THROWS_AS(modaluq::identify_setups(c.setups, c.options), modaluq::invalid_argument);
}

TEST_CASE("each merged pole's factor rows of f and xi reproduce its covariance's [f, xi] block") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Campaign c = make_campaign(io);
        const auto id = modaluq::identify_setups(c.setups, c.options);
        const Index nb = id.n_blocks;  // every setup's blocks, setup by setup
        CHECK(nb == mc::n_blocks * mc::n_setups);
        for (const auto& m : id.modes) {
            REQUIRE(m.frequency_damping_factor.rows() == 2 * nb);
            REQUIRE(m.frequency_damping_factor.cols() == m.n_modes());
            REQUIRE(m.mode_shape.rows() == mc::n_global);
            for (Index i = 0; i < m.n_modes(); ++i) CHECK(support::factor_rows_covariance_error(m, i) <= 1e-12);
            CHECK(m.mode_shape_factor.size() == 0);  // not asked for
        }
        // asked for: each merged pole's global-shape factor over every setup's blocks
        auto o = c.options;
        o.keep_shape_factor = true;
        const auto kept = modaluq::identify_setups(c.setups, o);
        for (const auto& m : kept.modes) {
            if (m.degenerate) continue;
            REQUIRE(m.mode_shape_factor.rows() == 2 * mc::n_global * nb);
            REQUIRE(m.mode_shape_factor.cols() == m.n_modes());
            for (Index i = 0; i < m.n_modes(); ++i) CHECK(support::shape_factor_covariance_error(m, i) <= 1e-12);
        }
        const modaluq::Poles p = modaluq::poles_of(id);
        CHECK(p.frequency_damping_factor.rows() == 2 * nb);
        CHECK(p.frequency_damping_factor.cols() == p.size());
    }
}

TEST_CASE("the merge feeds the stabilization diagram and the selection unchanged") {
    const Campaign c = make_campaign(false);
    const auto id = modaluq::identify_setups(c.setups, c.options);
    const modaluq::Identification& base = id;
    CHECK(base.modes.size() == mc::orders.size());
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

TEST_CASE("a campaign refuses the block-correlation correction and the bootstrap (one record's blocks only)") {
    Campaign c = make_campaign(false);
    c.options.block_correlation_correction = true;
    CHECK_THROWS_WITH_AS(modaluq::identify_setups(c.setups, c.options),
                         doctest::Contains("block_correlation_correction applies to one record"),
                         modaluq::invalid_argument);
    c.options.block_correlation_correction = false;
    c.options.bootstrap_draws = 20;  // the bootstrap of sigma (docs/uq-math.md §5.6) is one record's too
    CHECK_THROWS_WITH_AS(modaluq::identify_setups(c.setups, c.options),
                         doctest::Contains("bootstrap_draws applies to one record"), modaluq::invalid_argument);
}

}  // namespace test_multisetup
