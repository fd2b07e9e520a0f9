#include <doctest/doctest.h>

#include "support/support.hpp"

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_identify {

using namespace support;


TEST_CASE("noise-free 2-DOF systems are identified exactly") {
    SUBCASE("input/output, white input, no unknown input or noise") {
        const Sim s = simulate(2, {0, 1}, 4000, 3, true, 0.0, 0.0);
        auto o = options(s.fs, 4, 4, {4});
        o.demean = false;
        const auto id = modaluq::identify(s.y, s.u, o);
        const auto& m = id.at_order(4);
        REQUIRE(m.n_modes() == 2);
        for (Index i = 0; i < 2; ++i) {
            CHECK(std::abs(m.frequency_hz(i) / s.f_true(i) - 1) < 1e-6);
            CHECK(std::abs(m.damping_ratio(i) - 0.02) < 1e-6);
        }
    }
    SUBCASE("output-only free decay") {
        const Sim s = simulate(2, {0, 1}, 600, 9, false, 0.0, 0.0, 20.0, /*free_decay=*/true, 1.0, 0.01);
        auto o = options(s.fs, 3, 3, {4});
        o.demean = false;
        const auto id = modaluq::identify(s.y, MatrixXd(), o);
        const auto& m = id.at_order(4);
        REQUIRE(m.n_modes() == 2);
        for (Index i = 0; i < 2; ++i) {
            CHECK(std::abs(m.frequency_hz(i) / s.f_true(i) - 1) < 1e-6);
            CHECK(std::abs(m.damping_ratio(i) - 0.01) < 1e-6);
        }
        // Normalised mode shapes: largest component exactly 1.
        for (Index i = 0; i < 2; ++i) CHECK(m.mode_shape(m.reference_component(i), i) == std::complex<double>(1.0, 0.0));
    }
}

TEST_CASE("all orders come from one SVD and match separate runs") {
    const Sim s = simulate(3, {0, 1, 2}, 6000, 21, true, 0.2, 0.05);
    const auto multi = modaluq::identify(s.y, s.u, options(s.fs, 5, 6, {2, 4, 6, 8, 10}, true));
    REQUIRE(multi.modes.size() == 5);
    for (Index n : {4, 6, 10}) {
        const auto single = modaluq::identify(s.y, s.u, options(s.fs, 5, 6, {n}, true));
        const auto& a = multi.at_order(n);
        const auto& b = single.at_order(n);
        REQUIRE(a.n_modes() == b.n_modes());
        CHECK(rel(a.frequency_hz, b.frequency_hz) < 1e-12);
        CHECK(rel(a.frequency_std, b.frequency_std) < 1e-9);
    }
    // sorted by frequency, one per conjugate pair
    const auto& m = multi.at_order(6);
    for (Index i = 1; i < m.n_modes(); ++i) CHECK(m.frequency_hz(i) >= m.frequency_hz(i - 1));
    for (Index i = 0; i < m.n_modes(); ++i) CHECK(m.eigenvalue(i).imag() > 0);
}

TEST_CASE("threads do not change the result") {
    const Sim s = simulate(3, {0, 1, 2}, 6000, 21, true, 0.2, 0.05);
    auto o = options(s.fs, 5, 6, {2, 4, 6, 8, 10}, true);
    const auto one = modaluq::identify(s.y, s.u, o);
    for (Index t : {2, 3, 16}) {
        CAPTURE(t);
        o.threads = t;
        const auto many = modaluq::identify(s.y, s.u, o);
        REQUIRE(many.modes.size() == one.modes.size());
        for (size_t k = 0; k < one.modes.size(); ++k) {
            CHECK(many.modes[k].order == one.modes[k].order);
            CHECK((many.modes[k].frequency_hz - one.modes[k].frequency_hz).cwiseAbs().maxCoeff() == 0.0);
            CHECK((many.modes[k].covariance - one.modes[k].covariance).cwiseAbs().maxCoeff() == 0.0);
        }
    }
    o.threads = 0;
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, o), "threads must be >= 1, got 0", modaluq::invalid_argument);
}

TEST_CASE("identification from an accumulator fed in chunks equals the batch call") {
    const Sim s = simulate(3, {0, 2}, 5000, 4, true, 0.3, 0.05);
    auto o = options(s.fs, 5, 5, {6}, true, 20);
    const auto batch = modaluq::identify(s.y, s.u, o);
    modaluq::CovarianceAccumulator acc(o.layout(2, 1), batch.block_length);
    for (Index pos = 0; pos < 5000; pos += 333) {
        const Index n = std::min<Index>(333, 5000 - pos);
        acc.push(s.y.middleCols(pos, n), s.u.middleCols(pos, n));
    }
    const auto streamed = modaluq::identify(acc.finish(), o);
    CHECK(rel(streamed.at_order(6).frequency_hz, batch.at_order(6).frequency_hz) < 1e-10);
    CHECK(rel(streamed.at_order(6).damping_std, batch.at_order(6).damping_std) < 1e-8);
}

TEST_CASE("a rank-deficient input covariance is reported, not silently used") {
    const Sim s = simulate(2, {0, 1}, 3000, 8, true, 0.3, 0.05);
    MatrixXd u2(2, s.u.cols());
    u2 << s.u, s.u;  // duplicated input channel
    const auto id = modaluq::identify(s.y, u2, options(s.fs, 4, 4, {4}));
    CHECK(id.input_rank_deficient);
    CHECK(id.input_rank == 4);
    CHECK_FALSE(id.warnings.empty());
    REQUIRE(id.warning_codes.size() == id.warnings.size());
    CHECK(id.warning_codes[0] == modaluq::IdentificationWarning::input_rank_deficient);
    MatrixXd uc = MatrixXd::Constant(1, s.u.cols(), 2.5);  // constant input: zero after demeaning
    const auto id2 = modaluq::identify(s.y, uc, options(s.fs, 4, 4, {4}));
    CHECK(id2.input_rank_deficient);
    CHECK(id2.input_rank == 0);
    const auto ok = modaluq::identify(s.y, s.u, options(s.fs, 4, 4, {4}));
    CHECK_FALSE(ok.input_rank_deficient);
    CHECK(ok.input_condition < 2.0);
}

TEST_CASE("identify errors name the argument and the rule") {
    const Sim s = simulate(2, {0, 1}, 2000, 1, true, 0.3, 0.05);
    using modaluq::invalid_argument;
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, options(0.0, 4, 4, {4})), doctest::Contains("fs"), invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, options(std::nan(""), 4, 4, {4})), doctest::Contains("fs"),
                         invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, options(20, 1, 4, {4})), doctest::Contains("block_rows must be >= 2"),
                         invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, options(20, 4, 4, {7})),
                         doctest::Contains("min((block_rows - 1) * n_outputs, past_block_rows * n_references) = 6"),
                         invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, options(20, 4, 4, {4}, true, 1)), doctest::Contains("n_blocks must be >= 2"),
                         invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, options(20, 4, 4, {0})), doctest::Contains("orders must be >= 1"),
                         invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, options(20, 4, 4, {})), doctest::Contains("orders"), invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u.leftCols(1999), options(20, 4, 4, {4})),
                         doctest::Contains("u must have as many samples"), invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y.leftCols(100), s.u.leftCols(100), options(20, 4, 4, {4}, true, 50)),
                         doctest::Contains("record too short"), invalid_argument);
    auto o = options(20, 4, 4, {4});
    o.references = {0, 5};
    CHECK_THROWS_WITH_AS(modaluq::identify(s.y, s.u, o), doctest::Contains("references: index 5"), invalid_argument);
    MatrixXd y = s.y;
    y(0, 17) = std::numeric_limits<double>::infinity();
    CHECK_THROWS_WITH_AS(modaluq::identify(y, s.u, options(20, 4, 4, {4})), doctest::Contains("y: sample 17, channel 0"),
                         invalid_argument);
    const auto id = modaluq::identify(s.y, s.u, options(20, 4, 4, {4}));
    CHECK_THROWS_WITH_AS(id.at_order(6), doctest::Contains("order 6 was not identified"), invalid_argument);
}

TEST_CASE("the slow-decay finding is reported in numbers, each warning with its code") {
    // 2-DOF chain (1.3 and 2.8 Hz), 300 s at 20 Hz, output-only
    auto run = [](double xi, Index n_blocks) {
        const Sim s = simulate(2, {0, 1}, 6000, 5, false, 1.0, 0.05, 20.0, false, 1.0, xi);
        return std::make_pair(s.fs, modaluq::identify(s.y, MatrixXd(), options(s.fs, 4, 4, {4}, true, n_blocks)));
    };
    auto check_numbers = [](double fs, const modaluq::Identification& id) {
        const modaluq::SlowDecay& slow = id.slow_decay;
        Index n = 0;
        double longest = 0.0;
        for (const auto& m : id.modes)
            for (Index i = 0; i < m.n_modes(); ++i)
                if (m.block_too_short(i)) {
                    ++n;
                    longest = std::max(longest, 1.0 / (2.0 * modaluq::detail::pi * m.frequency_hz(i) * m.damping_ratio(i)));
                }
        CHECK(slow.n_poles == n);
        CHECK(slow.longest_decay_s == longest);
        CHECK(slow.block_seconds == double(id.block_length) / fs);
        CHECK(slow.record_seconds == double(id.n_columns) / fs);
        REQUIRE(id.warning_codes.size() == id.warnings.size());
        Index coded = 0;
        for (std::size_t k = 0; k < id.warnings.size(); ++k) {
            const bool is_slow = id.warning_codes[k] == modaluq::IdentificationWarning::slow_decay;
            CHECK(is_slow == (id.warnings[k].find("decay more slowly than the blocks are long") != std::string::npos));
            coded += is_slow;
        }
        CHECK(coded == (n > 0 ? 1 : 0));
        if (n > 0) CHECK(slow.fitting_n_blocks == Index(slow.record_seconds / (0.5 * longest)));
    };
    // blocks of 30 s against half decay times of 3 s and 1.4 s: nothing slow
    const auto [fs, long_blocks] = run(0.02, 10);
    check_numbers(fs, long_blocks);
    CHECK(long_blocks.slow_decay.n_poles == 0);
    // blocks of 1.5 s: the 1.3 Hz mode is slow; 300 s hold 100 blocks of half its decay time
    const auto short_blocks = run(0.02, 200).second;
    check_numbers(fs, short_blocks);
    CHECK(short_blocks.slow_decay.n_poles == 1);
    CHECK_FALSE(short_blocks.slow_decay.record_too_short());
    CHECK(short_blocks.warnings.back().find(
              "use n_blocks <= " + std::to_string(short_blocks.slow_decay.fitting_n_blocks)) != std::string::npos);
    // xi = 0.02 %: half the decay time of the 1.3 Hz mode is longer than the record
    const auto too_short = run(0.0002, 10).second;
    check_numbers(fs, too_short);
    CHECK(too_short.slow_decay.n_poles >= 1);
    CHECK(too_short.slow_decay.record_too_short());
    CHECK(too_short.warnings.back().find("the record is too short") != std::string::npos);
}

TEST_CASE("each mode's f-xi correlation comes from its covariance") {
    const Sim s = simulate(3, {0, 1, 2}, 6000, 21, true, 0.2, 0.05);
    const auto id = modaluq::identify(s.y, s.u, options(s.fs, 5, 6, {2, 4, 6, 8, 10}, true));
    for (const auto& m : id.modes) {
        REQUIRE(m.frequency_damping_correlation.size() == m.n_modes());
        const Index np = 2 + 2 * m.mode_shape.rows();
        for (Index i = 0; i < m.n_modes(); ++i) {
            const Eigen::Map<const MatrixXd> cov(m.covariance.col(i).data(), np, np);
            CHECK(m.frequency_damping_correlation(i) == cov(1, 0) / std::sqrt(cov(0, 0) * cov(1, 1)));
            CHECK(std::abs(m.frequency_damping_correlation(i)) <= 1.0 + 1e-12);
        }
    }
    // the flattened poles carry it and the block-length flag
    const modaluq::Poles p = modaluq::poles_of(id);
    Index at = 0;
    for (const auto& m : id.modes)
        for (Index i = 0; i < m.n_modes(); ++i, ++at) {
            CHECK(p.frequency_damping_correlation(at) == m.frequency_damping_correlation(i));
            CHECK(p.block_too_short(at) == m.block_too_short(i));
        }
    // without uncertainty: NaN
    const auto plain = modaluq::poles_of(modaluq::identify(s.y, s.u, options(s.fs, 5, 6, {4}, false)));
    CHECK(plain.frequency_damping_correlation.size() == plain.size());
    CHECK(plain.frequency_damping_correlation.array().isNaN().all());
    CHECK(plain.frequency_damping_factor.size() == 0);  // no factor rows: the selection's median
}

TEST_CASE("each mode's factor rows of f and xi reproduce its covariance's [f, xi] block") {
    const Sim s = simulate(3, {0, 1, 2}, 6000, 21, true, 0.2, 0.05);
    for (bool freeze : {false, true}) {
        CAPTURE(freeze);
        auto o = options(s.fs, 5, 6, {2, 4, 6, 8, 10}, true);
        o.freeze_noise = freeze;
        const auto id = modaluq::identify(s.y, s.u, o);
        const Index nb = id.n_blocks;
        for (const auto& m : id.modes) {
            REQUIRE(m.frequency_damping_factor.rows() == 2 * nb);
            REQUIRE(m.frequency_damping_factor.cols() == m.n_modes());
            for (Index i = 0; i < m.n_modes(); ++i) {
                CHECK(support::factor_rows_covariance_error(m, i) <= 1e-12);
                const MatrixXd u = support::factor_rows(m, i);
                CHECK(u.row(0).norm() == doctest::Approx(m.frequency_std(i)).epsilon(1e-12));
                CHECK(u.row(1).norm() == doctest::Approx(m.damping_std(i)).epsilon(1e-12));
            }
        }
        // the flattened poles carry them, column by column
        const modaluq::Poles p = modaluq::poles_of(id);
        REQUIRE(p.frequency_damping_factor.rows() == 2 * nb);
        REQUIRE(p.frequency_damping_factor.cols() == p.size());
        Index at = 0;
        for (const auto& m : id.modes)
            for (Index i = 0; i < m.n_modes(); ++i, ++at)
                CHECK(p.frequency_damping_factor.col(at) == m.frequency_damping_factor.col(i));
        p.validate();
    }
}


TEST_CASE("the shape factor is kept only when asked and reproduces the covariance's shape block") {
    const Sim s = simulate(3, {0, 1, 2}, 6000, 21, true, 0.2, 0.05);
    auto o = options(s.fs, 5, 6, {2, 4, 6, 8, 10}, true);
    const auto plain = modaluq::identify(s.y, s.u, o);
    for (const auto& m : plain.modes) CHECK(m.mode_shape_factor.size() == 0);
    o.keep_shape_factor = true;
    for (bool correction : {false, true}) {
        for (Index draws : {Index(0), Index(20)}) {
            CAPTURE(correction);
            CAPTURE(draws);
            o.block_correlation_correction = correction;
            o.bootstrap_draws = draws;  // rescales f and xi only: the shape rows stay first-order
            const auto id = modaluq::identify(s.y, s.u, o);
            const Index nb = id.n_blocks;
            for (std::size_t k = 0; k < id.modes.size(); ++k) {
                const auto& m = id.modes[k];
                if (m.degenerate) continue;
                const Index l = m.mode_shape.rows();
                REQUIRE(m.mode_shape_factor.rows() == 2 * l * nb);
                REQUIRE(m.mode_shape_factor.cols() == m.n_modes());
                for (Index i = 0; i < m.n_modes(); ++i) {
                    CHECK(support::shape_factor_covariance_error(m, i) <= 1e-12);
                    const MatrixXd v = support::shape_factor(m, i);
                    CHECK(v.row(0).norm() == doctest::Approx(m.mode_shape_std_real(0, i)).epsilon(1e-12));
                    CHECK(v.row(l).norm() == doctest::Approx(m.mode_shape_std_imag(0, i)).epsilon(1e-12));
                }
                // keeping it changes nothing else
                CHECK(m.covariance == modaluq::identify(s.y, s.u, [&] {
                          auto p = o;
                          p.keep_shape_factor = false;
                          return p;
                      }()).modes[k].covariance);
            }
        }
    }
}

TEST_CASE("the block-correlation correction scales each mode by sqrt(c) from its own f and xi block terms") {
    // c by hand (docs/uq-math.md §3.1): rho_r = sum u(k) u(k+1) / sum u(k)^2, rho = mean + 1/n_b,
    // applied where |rho| > 2 / sqrt(n_b) = 1/2 here
    const Eigen::RowVectorXd ones = Eigen::RowVectorXd::Ones(16), alternating =
        Eigen::RowVectorXd::NullaryExpr(16, [](Index k) { return k % 2 ? -1.0 : 1.0; });
    MatrixXd ut = MatrixXd::Zero(4, 16);
    ut.row(0) = ones;  // rho_f = 15/16
    ut.row(1) = ones;  // rho = 15/16 + 1/16 = 1
    CHECK(modaluq::detail::block_correlation_scale(ut) == doctest::Approx(3.0));
    ut.row(1) = alternating;  // rho_xi = -15/16: rho = 1/16, inside the gate
    CHECK(modaluq::detail::block_correlation_scale(ut) == 1.0);
    ut.row(0) = alternating;  // rho = -15/16 + 1/16: c = -3/4, floored at 1/4
    CHECK(modaluq::detail::block_correlation_scale(ut) == 0.25);
    ut.row(0).setZero();  // only xi's row defines rho
    CHECK(modaluq::detail::block_correlation_scale(ut) == 0.25);
    ut.row(1).setZero();
    CHECK(modaluq::detail::block_correlation_scale(ut) == 1.0);

    // identify: the corrected run is the plain one with each mode's factor, covariance and std
    // scaled by sqrt(c) or c, c recomputed here from the plain run's factor rows. The case where
    // the gate opens: the measured input is the only force, 200 short blocks (docs/validation.md).
    const Sim s = simulate(3, {0, 1, 2}, 20000, 21, true, 0.0, 0.01);
    auto o = options(s.fs, 5, 6, {2, 4, 6, 8, 10}, true, 200);
    const auto plain = modaluq::identify(s.y, s.u, o);
    o.block_correlation_correction = true;
    const auto corrected = modaluq::identify(s.y, s.u, o);
    const Index nb = plain.n_blocks;
    Index scaled = 0;
    for (std::size_t k = 0; k < plain.modes.size(); ++k) {
        const auto &a = plain.modes[k], &b = corrected.modes[k];
        REQUIRE(a.n_modes() == b.n_modes());
        CHECK((a.block_correlation_scale.array() == 1.0).all());
        CHECK(b.frequency_hz == a.frequency_hz);
        for (Index i = 0; i < a.n_modes(); ++i) {
            MatrixXd u(2, nb);
            u.row(0) = a.frequency_damping_factor.col(i).head(nb).transpose();
            u.row(1) = a.frequency_damping_factor.col(i).tail(nb).transpose();
            double rho = 0.0;
            for (Index r : {0, 1}) rho += u.row(r).head(nb - 1).dot(u.row(r).tail(nb - 1)) / u.row(r).squaredNorm();
            rho = rho / 2.0 + 1.0 / double(nb);
            const double c = std::abs(rho) > 2.0 / std::sqrt(double(nb)) ? std::max(0.25, 1.0 + 2.0 * rho) : 1.0;
            CHECK(b.block_correlation_scale(i) == doctest::Approx(c).epsilon(1e-12));
            CHECK(b.frequency_std(i) == doctest::Approx(std::sqrt(c) * a.frequency_std(i)).epsilon(1e-12));
            CHECK(b.damping_std(i) == doctest::Approx(std::sqrt(c) * a.damping_std(i)).epsilon(1e-12));
            CHECK((b.covariance.col(i) - c * a.covariance.col(i)).norm() <= 1e-12 * c * a.covariance.col(i).norm());
            CHECK((b.frequency_damping_factor.col(i) - std::sqrt(c) * a.frequency_damping_factor.col(i)).norm() <=
                  1e-12 * a.frequency_damping_factor.col(i).norm());
            scaled += std::abs(c - 1.0) > 0.05;
        }
    }
    CHECK(scaled > 0);  // the gate let the correction act on some poles of this record
}


TEST_CASE("the bootstrap of sigma above the noise floor follows its definition (docs/uq-math.md §5.6)") {
    // 1.4826 MAD by hand: odd and even counts
    std::vector<double> x{1, 2, 3, 4, 100};
    CHECK(modaluq::detail::mad_std(x) == doctest::Approx(1.482602218505602));  // median 3, deviations' median 1
    x = {1, 2, 3, 4};
    CHECK(modaluq::detail::mad_std(x) == doctest::Approx(1.482602218505602));  // 2.5; (0.5 + 1.5) / 2

    // A 3-DOF chain (true order 6) identified up to order 12: orders above k* are bootstrapped.
    const Sim s = simulate(3, {0, 1, 2}, 12000, 5, false, 1.0, 0.05);
    auto o = options(s.fs, 5, 5, {4, 6, 8, 10, 12}, true, 20);
    const auto plain = modaluq::identify(s.y, MatrixXd(), o);
    o.bootstrap_draws = 40;
    const auto boot = modaluq::identify(s.y, MatrixXd(), o);
    const Index ks = boot.significant_singular_values;
    REQUIRE(ks == plain.significant_singular_values);
    REQUIRE(ks < 12);

    // The definition again, from the public API only: draw d perturbs R1 (output-only: H = R1, T_H = T_R)
    // by unvec(T_R eps_d) with the documented Rademacher stream, identifies it without uncertainty,
    // and each pole follows the nearest pole of its order in |df|/f + |dxi|, within 5 % in f.
    const auto cov = modaluq::compute_covariances(s.y, MatrixXd(), o.layout(3, 0), 20, true);
    const MatrixXd t_r = cov.covariance_factor();
    const MatrixXd eps = modaluq::detail::bootstrap_signs(t_r.cols(), 40);
    std::vector<Index> above;
    for (Index n : o.orders)
        if (n > ks) above.push_back(n);
    auto od = options(s.fs, 5, 5, above, false);
    std::vector<modaluq::Identification> draws;
    for (Index d = 0; d < 40; ++d) {
        modaluq::Covariances c = cov;
        c.blocks.resize(0, 0);
        const VectorXd dr = t_r * eps.col(d);
        c.R1 += Eigen::Map<const MatrixXd>(dr.data(), c.R1.rows(), c.R1.cols());
        draws.push_back(modaluq::identify(c, od));
    }
    auto mad = [](std::vector<double> v) {
        auto med = [](std::vector<double> w) {
            std::sort(w.begin(), w.end());
            const std::size_t m = w.size() / 2;
            return w.size() % 2 ? w[m] : 0.5 * (w[m - 1] + w[m]);
        };
        const double c = med(v);
        for (double& e : v) e = std::abs(e - c);
        return 1.482602218505602 * med(v);
    };
    Index n_boot = 0;
    for (std::size_t k = 0; k < boot.modes.size(); ++k) {
        const auto &a = plain.modes[k], &b = boot.modes[k];
        REQUIRE(a.n_modes() == b.n_modes());
        CHECK(b.frequency_hz == a.frequency_hz);
        CHECK(b.mode_shape_std_real == a.mode_shape_std_real);  // the shapes stay first-order
        if (b.order <= ks) {  // untouched, bit for bit
            CHECK(!b.bootstrapped.any());
            CHECK(b.frequency_std == a.frequency_std);
            CHECK(b.covariance == a.covariance);
            continue;
        }
        for (Index i = 0; i < b.n_modes(); ++i) {
            std::vector<double> fs_, xs_;
            for (const auto& id : draws) {
                const auto& m = id.at_order(b.order);
                Index best = -1;
                double dbest = 1e300;
                for (Index j = 0; j < m.n_modes(); ++j) {
                    const double dist = std::abs(m.frequency_hz(j) / b.frequency_hz(i) - 1) +
                                        std::abs(m.damping_ratio(j) - b.damping_ratio(i));
                    if (dist < dbest) dbest = dist, best = j;
                }
                if (best >= 0 && std::abs(m.frequency_hz(best) / b.frequency_hz(i) - 1) <= 0.05) {
                    fs_.push_back(m.frequency_hz(best));
                    xs_.push_back(m.damping_ratio(best));
                }
            }
            const bool expect = !a.noise_coupled(i) && fs_.size() >= 32;  // 80 % of 40
            CHECK(b.bootstrapped(i) == expect);
            if (!expect) {
                CHECK(b.frequency_std(i) == a.frequency_std(i));
                CHECK(b.damping_std(i) == a.damping_std(i));
                continue;
            }
            ++n_boot;
            const double sf = mad(fs_), sx = mad(xs_);
            CHECK(b.frequency_std(i) == doctest::Approx(sf).epsilon(1e-9));
            CHECK(b.damping_std(i) == doctest::Approx(sx).epsilon(1e-9));
            // covariance: f and xi rows/columns rescaled, correlation and shape block kept
            const Index np = 8;
            Eigen::Map<const MatrixXd> ca(a.covariance.col(i).data(), np, np), cb(b.covariance.col(i).data(), np, np);
            CHECK(cb(0, 0) == doctest::Approx(sf * sf).epsilon(1e-12));
            CHECK(cb(1, 1) == doctest::Approx(sx * sx).epsilon(1e-12));
            CHECK(b.frequency_damping_correlation(i) == a.frequency_damping_correlation(i));
            CHECK(cb(0, 1) / std::sqrt(cb(0, 0) * cb(1, 1)) ==
                  doctest::Approx(ca(0, 1) / std::sqrt(ca(0, 0) * ca(1, 1))).epsilon(1e-12));
            CHECK(cb.bottomRightCorner(6, 6) == ca.bottomRightCorner(6, 6));
            CHECK(factor_rows_covariance_error(b, i) < 1e-10);  // the factor rows still give [f, xi]
        }
    }
    CHECK(n_boot > 0);

    o.threads = 2;  // the draws on two threads: the same
    const auto two = modaluq::identify(s.y, MatrixXd(), o);
    for (std::size_t k = 0; k < boot.modes.size(); ++k) CHECK(two.modes[k].frequency_std == boot.modes[k].frequency_std);

    o.bootstrap_draws = 5;
    CHECK_THROWS_AS(modaluq::identify(s.y, MatrixXd(), o), modaluq::invalid_argument);
}

}  // namespace test_identify
