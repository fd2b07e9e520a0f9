// Regression tests of the reliability audit (issue 13): nothing silently wrong, no undefined
// behaviour on huge sizes, degenerate data refused or flagged with the reason.
#include <doctest/doctest.h>

#include <limits>
#include <string>

#include <modaluq/detail/parallel.hpp>

#include "support/support.hpp"

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_reliability {

using namespace support;

namespace {

modaluq::IdentifyOptions opts(double fs, Index p, std::vector<Index> orders) {
    return options(fs, p, 0, std::move(orders), /*unc=*/true, /*nb=*/10);
}

template <class Fn>
std::string error_of(Fn&& fn) {
    try {
        fn();
    } catch (const modaluq::invalid_argument& e) {
        return e.what();
    }
    return "(no invalid_argument thrown)";
}

bool contains(const std::string& s, const char* part) { return s.find(part) != std::string::npos; }

}  // namespace

TEST_CASE("samples whose products overflow are refused, never identified from stale SVD output") {
    const Sim s = simulate(3, {0, 1, 2}, 6000, 1, false, 1.0, 0.05);
    MatrixXd y = s.y;
    y(0, 5) = 1e300;  // finite, but its square is not
    const std::string e = error_of([&] { modaluq::identify(y, MatrixXd(), opts(s.fs, 8, {4, 6})); });
    CHECK(contains(e, "not finite"));
    // The realization itself refuses a non-finite H (Eigen's SVD would leave its outputs unset).
    MatrixXd H = MatrixXd::Ones(6, 4);
    H(1, 1) = std::numeric_limits<double>::infinity();
    CHECK(contains(error_of([&] { modaluq::Realization(H, 2, 2); }), "non-finite"));
    // A large but finite scale is identified, with the same frequencies as unscaled data.
    MatrixXd big = s.y * 1e12;
    const auto a = modaluq::identify(big, MatrixXd(), opts(s.fs, 8, {6}));
    const auto b = modaluq::identify(s.y, MatrixXd(), opts(s.fs, 8, {6}));
    REQUIRE(a.at_order(6).n_modes() == b.at_order(6).n_modes());
    CHECK((a.at_order(6).frequency_hz - b.at_order(6).frequency_hz).norm() < 1e-8);
}

TEST_CASE("outputs passed as inputs: H is numerically zero and the record is refused") {
    const Sim s = simulate(3, {0, 1, 2}, 6000, 2, true, 0.2, 0.05);
    const MatrixXd u = s.y;  // the inputs explain the outputs exactly
    const std::string e = error_of([&] { modaluq::identify(s.y, u, opts(s.fs, 8, {4, 6})); });
    CHECK(contains(e, "numerically zero"));
    // With genuine inputs H stands far above its estimation noise.
    const auto id = modaluq::identify(s.y, s.u, opts(s.fs, 8, {4, 6}));
    CHECK(id.signal_to_noise > 5.0);
    CHECK(!id.low_signal_to_noise);
}

TEST_CASE("order 1 alone is a valid request; a short record near its noise is a warning, not a refusal") {
    const Sim s = simulate(3, {0, 1, 2}, 6000, 4, false, 1.0, 0.05);
    const auto one = modaluq::identify(s.y, MatrixXd(), opts(s.fs, 8, {1}));
    CHECK(one.at_order(1).n_modes() == 0);  // one real eigenvalue: no oscillating mode
    CHECK(!one.at_order(1).degenerate);
    const Sim short_rec = simulate(3, {0, 1, 2}, 300, 2, false, 1.0, 0.05);
    auto o = opts(short_rec.fs, 4, {4, 6});
    const auto id = modaluq::identify(short_rec.y, MatrixXd(), o);
    if (id.low_signal_to_noise) {
        bool warned = false;
        for (const auto& w : id.warnings) warned = warned || contains(w, "estimation noise");
        CHECK(warned);
    }
    CHECK(id.signal_to_noise > 0.0);
}

TEST_CASE("degenerate records are refused with the reason; degenerate orders are flags") {
    const Index n = 6000;
    SUBCASE("all zero and constant") {
        for (double c : {0.0, 3.5}) {
            const MatrixXd y = MatrixXd::Constant(3, n, c);
            CHECK(contains(error_of([&] { modaluq::identify(y, MatrixXd(), opts(50.0, 8, {4})); }), "no dynamics"));
        }
    }
    SUBCASE("an impulse has rank 1: nothing to identify") {
        MatrixXd y = MatrixXd::Zero(3, n);
        y.col(3000).setOnes();
        CHECK(contains(error_of([&] { modaluq::identify(y, MatrixXd(), opts(50.0, 8, {2, 4})); }), "numerical rank"));
    }
    SUBCASE("a sine with 1e-9 noise: order 2 identified, higher orders flagged, not an exception") {
        const Sim noise = simulate(3, {0, 1, 2}, n, 3, false, 1.0, 0.05);
        MatrixXd y(3, n);
        for (Index t = 0; t < n; ++t) y.col(t).setConstant(std::sin(2 * modaluq::detail::pi * 3.0 * t / 50.0));
        y += 1e-9 * noise.y / noise.y.norm() * std::sqrt(double(y.size()));
        const auto id = modaluq::identify(y, MatrixXd(), opts(50.0, 8, {2, 4, 6, 8}));
        CHECK(id.numerical_rank == 2);
        REQUIRE(id.at_order(2).n_modes() == 1);
        CHECK(std::abs(id.at_order(2).frequency_hz(0) - 3.0) < 1e-6);
        CHECK(!id.at_order(2).degenerate);
        for (Index o : {4, 6, 8}) {
            CHECK(id.at_order(o).degenerate);
            CHECK(id.at_order(o).n_modes() == 0);
            CHECK(contains(id.at_order(o).note, "numerical rank"));
            // Shaped like zero modes of a run with uncertainty: l rows, std arrays present.
            CHECK(id.at_order(o).mode_shape.rows() == 3);
            CHECK(id.at_order(o).covariance.rows() == (2 + 2 * 3) * (2 + 2 * 3));
            CHECK(id.at_order(o).frequency_std.size() == 0);
        }
        bool warned = false;
        for (const auto& w : id.warnings) warned = warned || contains(w, "use orders <= 2");
        CHECK(warned);
    }
}

TEST_CASE("huge sizes are refused before any product can overflow") {
    modaluq::HankelLayout L;
    L.n_outputs = 3;
    L.block_rows = Index(1) << 62;
    CHECK(contains(error_of([&] { L.validate(); }), "block_rows must be <="));
    L.block_rows = Index(1) << 24;  // within the horizon bound, but R1 would be 2^50+ entries
    L.n_outputs = 1 << 10;
    CHECK(contains(error_of([&] { L.validate(); }), "limit of 2^50"));
    L.block_rows = 4;
    L.n_outputs = 3;
    CHECK(contains(error_of([&] { modaluq::CovarianceAccumulator(L, Index(1) << 62); }), "block_length must be <="));
    const MatrixXd y = MatrixXd::Random(3, 1000);
    CHECK(contains(error_of([&] { modaluq::compute_covariances(y, MatrixXd(), L, Index(1) << 61); }),
                   "record too short"));
    const Index top = std::numeric_limits<Index>::max();
    CHECK(modaluq::detail::ceil_div(top, 2) == top / 2 + 1);
    CHECK(modaluq::detail::ceil_div(top - 1, top) == 1);
    CHECK(modaluq::detail::ceil_div(-5, 2) == -2);
    auto o = opts(50.0, 8, {4});
    o.threads = modaluq::IdentifyOptions::kMaxThreads + 1;
    CHECK(contains(error_of([&] { o.validate(); }), "threads must be <= 1024"));
}

TEST_CASE("parallel_for: every item once whatever the thread count, errors rethrown") {
    for (Index threads : {1, 2, 7, 64}) {
        std::vector<int> hits(100, 0);
        modaluq::detail::parallel_for(100, threads, [&](Index i) { ++hits[static_cast<size_t>(i)]; });
        for (int h : hits) CHECK(h == 1);
    }
    CHECK_THROWS_AS(modaluq::detail::parallel_for(10, 3, [](Index i) {
                        if (i == 4) throw modaluq::numerical_error("item 4");
                    }),
                    modaluq::numerical_error);
}

TEST_CASE("accumulator state grows with the number of blocks, not with the samples") {
    modaluq::HankelLayout L;
    L.n_outputs = 4;
    L.block_rows = 12;
    const MatrixXd y = MatrixXd::Random(4, 400000);
    // The same 20 blocks over 40,000 and 400,000 samples hold the same state.
    modaluq::CovarianceAccumulator short_blocks(L, 2000), long_blocks(L, 20000);
    short_blocks.push(y.leftCols(40000));
    long_blocks.push(y);
    CHECK(short_blocks.n_complete_blocks() == 19);
    CHECK(long_blocks.n_complete_blocks() == 19);
    CHECK(long_blocks.state_bytes() == short_blocks.state_bytes());
    // Ten times the blocks: about ten times the state.
    modaluq::CovarianceAccumulator many(L, 2000);
    many.push(y);
    const double ratio = double(many.state_bytes()) / double(short_blocks.state_bytes());
    CHECK(ratio > 9.0);
    CHECK(ratio < 11.0);
}

}  // namespace test_reliability
