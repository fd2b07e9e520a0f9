#include <doctest/doctest.h>

#include "support/support.hpp"

#include <limits>
#include <string>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_covariance {

using namespace support;
using modaluq::CovarianceAccumulator;
using modaluq::HankelLayout;

namespace {

HankelLayout layout(Index l, Index m, Index p, Index q, std::vector<Index> refs = {}) {
    HankelLayout L;
    L.n_outputs = l;
    L.n_inputs = m;
    L.block_rows = p;
    L.past_block_rows = q;
    L.references = std::move(refs);
    return L;
}

void check_against_naive(const modaluq::Covariances& c, const Naive& nv, double tol) {
    CHECK(rel(c.R1, nv.R1) < tol);
    if (c.has_inputs()) {
        CHECK(rel(c.R2, nv.R2) < tol);
        CHECK(rel(c.R3, nv.R3) < tol);
        CHECK(rel(c.R4, nv.R4) < tol);
    }
    REQUIRE(c.blocks.cols() == static_cast<Index>(nv.b1.size()));
    for (Index k = 0; k < c.blocks.cols(); ++k) {
        Eigen::VectorXd expect(c.blocks.rows());
        Index pos = 0;
        auto put = [&](const MatrixXd& m) {
            expect.segment(pos, m.size()) = Eigen::Map<const VectorXd>(m.data(), m.size());
            pos += m.size();
        };
        put(nv.b1[k]);
        if (c.has_inputs()) { put(nv.b2[k]); put(nv.b3[k]); put(nv.b4[k]); }
        CHECK(rel(c.blocks.col(k), expect) < tol);
    }
}

}  // namespace

TEST_CASE("batch covariances equal the explicit data-matrix definition") {
    const Sim s = simulate(3, {0, 2}, 1500, 7, true, 0.3, 0.05);
    SUBCASE("output-only, p != q, references") {
        const auto L = layout(2, 0, 4, 6, {1});
        const auto c = modaluq::compute_covariances(s.y, MatrixXd(), L, 7);
        check_against_naive(c, naive_covariances(s.y, MatrixXd(), L, 7, true), 1e-12);
    }
    SUBCASE("input/output, p != q") {
        const auto L = layout(2, 1, 5, 3);
        const auto c = modaluq::compute_covariances(s.y, s.u, L, 5);
        check_against_naive(c, naive_covariances(s.y, s.u, L, 5, true), 1e-12);
        CHECK(c.n_columns == 1500 - 5 - 3 + 1);
        CHECK(c.block_length == c.n_columns / 5);
    }
    SUBCASE("without mean removal") {
        MatrixXd y = s.y.array() + 3.0;
        const auto L = layout(2, 1, 3, 3);
        const auto c = modaluq::compute_covariances(y, s.u, L, 4, false);
        check_against_naive(c, naive_covariances(y, s.u, L, 4, false), 1e-12);
    }
}

TEST_CASE("segmented lag sums equal the direct lag sums and their definition") {
    for (const Index d : {1, 2, 3, 5}) {
        for (const Index lag : {0, 1, 7, 30}) {
            const Index n = 500;
            const MatrixXd x = MatrixXd::Random(d, n + lag);
            // Definition: sum_c [x_{c+l} x_c^T | x_{c+l}] over base times [off, off + nc).
            const Index off = 3, nc = n - 17;
            MatrixXd expect = MatrixXd::Zero((lag + 1) * d, d + 1);
            for (Index c = off; c < off + nc; ++c)
                for (Index l = 0; l <= lag; ++l) {
                    expect.block(l * d, 0, d, d) += x.col(c + l) * x.col(c).transpose();
                    expect.block(l * d, d, d, 1) += x.col(c + l);
                }
            MatrixXd direct = MatrixXd::Zero((lag + 1) * d, d + 1);
            modaluq::detail::add_lag_sums_direct(x.data(), d, lag, off, nc, direct);
            CHECK(rel(direct, expect) < 1e-13);
            // Segment lengths dividing nc, leaving a remainder, longer than the lag, and so long
            // that fewer than two segments fit (direct fallback); 0 = automatic choice.
            for (const Index seg : {0, 1, 2, 7, 40, 300}) {
                MatrixXd got = MatrixXd::Zero((lag + 1) * d, d + 1);
                modaluq::detail::add_lag_sums(x.data(), d, lag, off, nc, got, seg);
                CAPTURE(d);
                CAPTURE(lag);
                CAPTURE(seg);
                CHECK(rel(got, expect) < 1e-13);
            }
        }
    }
}

TEST_CASE("lag sums restricted to column channels equal those columns of the full sums") {
    for (const Index d : {3, 7}) {
        for (const Index lag : {0, 5, 30}) {
            const Index n = 400, off = 2, nc = n - 11;
            const MatrixXd x = MatrixXd::Random(d, n + lag);
            MatrixXd full = MatrixXd::Zero((lag + 1) * d, d + 1);
            modaluq::detail::add_lag_sums_direct(x.data(), d, lag, off, nc, full);
            const std::vector<Index> cols = {d - 1, 0};  // out of order on purpose
            MatrixXd expect((lag + 1) * d, 3);
            expect << full.col(d - 1), full.col(0), full.col(d);
            MatrixXd direct = MatrixXd::Zero((lag + 1) * d, 3);
            modaluq::detail::add_lag_sums_direct(x.data(), d, lag, off, nc, direct, cols);
            CHECK(rel(direct, expect) < 1e-13);
            for (const Index seg : {0, 1, 3, 40, 300}) {
                MatrixXd got = MatrixXd::Zero((lag + 1) * d, 3);
                modaluq::detail::add_lag_sums(x.data(), d, lag, off, nc, got, seg, cols);
                CAPTURE(d);
                CAPTURE(lag);
                CAPTURE(seg);
                CHECK(rel(got, expect) < 1e-13);
            }
        }
    }
}

TEST_CASE("references: chunked pushes, merged spans and a state round trip give the batch result") {
    const Sim s = simulate(4, {0, 1, 2, 3}, 1800, 5, false, 0.3, 0.05);
    const auto L = layout(4, 0, 3, 5, {3, 1});
    const auto batch = modaluq::compute_covariances(s.y, MatrixXd(), L, 6);
    check_against_naive(batch, naive_covariances(s.y, MatrixXd(), L, 6, true), 1e-12);
    const Index nb = batch.block_length;
    CovarianceAccumulator first(L, nb), second(L, nb, true, 700);
    first.push(s.y.leftCols(300));
    first.push(s.y.middleCols(300, 400));
    second.push(s.y.rightCols(1100));
    CovarianceAccumulator restored = CovarianceAccumulator::from_state(first.export_state());
    restored.merge(second);
    const auto c = restored.finish();
    CHECK(rel(c.R1, batch.R1) < 1e-12);
    CHECK(rel(c.blocks, batch.blocks) < 1e-12);
}

TEST_CASE("any chunking gives the batch result") {
    const Sim s = simulate(3, {0, 1, 2}, 2300, 11, true, 0.3, 0.05);
    const auto L = layout(3, 1, 4, 5, {0, 2});
    const Index N = 2300 - L.max_lag(), Nb = N / 6;
    CovarianceAccumulator whole(L, Nb);
    whole.push(s.y, s.u);
    const auto ref = whole.finish();
    std::mt19937 rng(3);
    for (int trial = 0; trial < 12; ++trial) {
        CovarianceAccumulator acc(L, Nb);
        Index pos = 0;
        std::uniform_int_distribution<Index> len(0, trial < 6 ? 9 : 400);
        while (pos < s.y.cols()) {
            const Index n = std::min<Index>(len(rng), s.y.cols() - pos);
            acc.push(s.y.middleCols(pos, n), s.u.middleCols(pos, n));
            pos += n;
        }
        const auto c = acc.finish();
        CHECK(rel(c.R1, ref.R1) < 1e-12);
        CHECK(rel(c.R3, ref.R3) < 1e-12);
        CHECK(rel(c.blocks, ref.blocks) < 1e-12);
    }
}

TEST_CASE("the batch pass in spans equals one accumulator, and threads do not change it") {
    // 3.5 spans' worth of samples: compute_covariances cuts the record into 3 spans.
    const Index n = 3 * (Index(1) << 15) + 20000;
    REQUIRE(modaluq::detail::covariance_spans(n) == 3);
    const Sim s = simulate(3, {0, 1, 2}, n, 13, true, 0.3, 0.05);
    const auto L = layout(3, 1, 4, 5, {0, 2});
    const Index nb = 7, Nb = (n - L.max_lag()) / nb;
    CovarianceAccumulator whole(L, Nb);
    whole.push(s.y, s.u);
    const auto ref = whole.finish();
    const auto one = modaluq::compute_covariances(s.y, s.u, L, nb);
    CHECK(rel(one.R1, ref.R1) < 1e-12);
    CHECK(rel(one.R2, ref.R2) < 1e-12);
    CHECK(rel(one.R3, ref.R3) < 1e-12);
    CHECK(rel(one.R4, ref.R4) < 1e-12);
    CHECK(rel(one.blocks, ref.blocks) < 1e-12);
    // The mean is near zero: compare it on the scale of the samples.
    CHECK((one.channel_mean - ref.channel_mean).cwiseAbs().maxCoeff() < 1e-13 * s.y.cwiseAbs().maxCoeff());
    for (Index t : {2, 3, 8}) {
        CAPTURE(t);
        const auto many = modaluq::compute_covariances(s.y, s.u, L, nb, true, true, t);
        CHECK((many.R1 - one.R1).cwiseAbs().maxCoeff() == 0.0);
        CHECK((many.R3 - one.R3).cwiseAbs().maxCoeff() == 0.0);
        CHECK((many.blocks - one.blocks).cwiseAbs().maxCoeff() == 0.0);
    }
    // Output-only, and a NaN in a later span is still reported with its sample index.
    const auto oo = modaluq::compute_covariances(s.y, MatrixXd(), layout(3, 0, 4, 4), nb, true, true, 2);
    CovarianceAccumulator oo_whole(layout(3, 0, 4, 4), (n - 7) / nb);
    oo_whole.push(s.y);
    CHECK(rel(oo.blocks, oo_whole.finish().blocks) < 1e-12);
    MatrixXd bad = s.y;
    bad(1, n - 5) = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_WITH_AS(modaluq::compute_covariances(bad, MatrixXd(), layout(3, 0, 4, 4), nb, true, true, 2),
                         doctest::Contains(std::to_string(n - 5).c_str()), modaluq::invalid_argument);
}

TEST_CASE("a large DC offset changes nothing") {
    const Sim s = simulate(2, {0, 1}, 3000, 5, true, 0.3, 0.05);
    const auto L = layout(2, 1, 4, 4);
    const auto c0 = modaluq::compute_covariances(s.y, s.u, L, 10);
    const double sd = std::sqrt((s.y.array().colwise() - s.y.rowwise().mean().array()).square().mean());
    const MatrixXd y = s.y.array() + 1e4 * sd;
    const MatrixXd u = s.u.array() - 1e4;
    // Also chunked, so that the shift comes from the first chunk only.
    CovarianceAccumulator acc(L, c0.block_length);
    for (Index pos = 0; pos < y.cols(); pos += 777) {
        const Index n = std::min<Index>(777, y.cols() - pos);
        acc.push(y.middleCols(pos, n), u.middleCols(pos, n));
    }
    const auto c1 = acc.finish();
    CHECK(rel(c1.R1, c0.R1) < 1e-9);
    CHECK(rel(c1.R2, c0.R2) < 1e-9);
    CHECK(rel(c1.R3, c0.R3) < 1e-9);
    CHECK(rel(c1.blocks, c0.blocks) < 1e-9);
    CHECK(std::abs(c1.channel_mean(0) - (c0.channel_mean(0) + 1e4 * sd)) < 1e-9 * 1e4 * sd);
}

TEST_CASE("accumulators over consecutive spans merge into the whole") {
    const Sim s = simulate(3, {0, 2}, 2000, 13, true, 0.3, 0.05);
    const auto L = layout(2, 1, 3, 4);
    const Index Nb = (2000 - L.max_lag()) / 8;
    CovarianceAccumulator whole(L, Nb);
    whole.push(s.y, s.u);
    const auto ref = whole.finish();
    for (Index split : {Index(1), Index(4), Index(250), Index(Nb), Index(3 * Nb + 5), Index(1996), Index(1999)}) {
        CAPTURE(split);
        CovarianceAccumulator a(L, Nb), b(L, Nb, true, split);
        a.push(s.y.leftCols(split), s.u.leftCols(split));
        b.push(s.y.middleCols(split, 2000 - split), s.u.middleCols(split, 2000 - split));
        a.merge(b);
        const auto c = a.finish();
        CHECK(rel(c.R1, ref.R1) < 1e-12);
        CHECK(rel(c.R2, ref.R2) < 1e-12);
        CHECK(rel(c.blocks, ref.blocks) < 1e-12);
    }
    SUBCASE("three spans, merged left to right") {
        CovarianceAccumulator a(L, Nb), b(L, Nb, true, 700), c(L, Nb, true, 703);
        a.push(s.y.leftCols(700), s.u.leftCols(700));
        b.push(s.y.middleCols(700, 3), s.u.middleCols(700, 3));
        c.push(s.y.rightCols(1297), s.u.rightCols(1297));
        a.merge(b);
        a.merge(c);
        CHECK(rel(a.finish().blocks, ref.blocks) < 1e-12);
    }
}

TEST_CASE("memory does not grow with the samples of a block") {
    // The state is per block, not per sample: pushing 10x more samples into the same number of
    // blocks leaves the result's size unchanged.
    const auto L = layout(2, 0, 3, 3);
    const Sim s = simulate(2, {0, 1}, 20000, 2, false, 1.0, 0.0);
    const auto small = modaluq::compute_covariances(s.y.leftCols(2000), MatrixXd(), L, 5);
    const auto large = modaluq::compute_covariances(s.y, MatrixXd(), L, 5);
    CHECK(small.blocks.size() == large.blocks.size());
}

TEST_CASE("covariance errors name the argument") {
    const auto L = layout(2, 1, 3, 3);
    CHECK_THROWS_AS(CovarianceAccumulator(L, 5), modaluq::invalid_argument);  // block_length < p + q
    CHECK_THROWS_WITH_AS(CovarianceAccumulator(layout(2, 0, 1, 3), 50), doctest::Contains("block_rows"),
                         modaluq::invalid_argument);
    CHECK_THROWS_WITH_AS(CovarianceAccumulator(layout(2, 0, 3, 3, {2}), 50), doctest::Contains("references"),
                         modaluq::invalid_argument);
    CovarianceAccumulator acc(L, 50);
    CHECK_THROWS_WITH_AS(acc.push(MatrixXd::Zero(3, 10), MatrixXd::Zero(1, 10)), doctest::Contains("y must have 2"),
                         modaluq::invalid_argument);
    CHECK_THROWS_WITH_AS(acc.push(MatrixXd::Zero(2, 10), MatrixXd::Zero(1, 9)), doctest::Contains("u must have as many"),
                         modaluq::invalid_argument);
    MatrixXd bad = MatrixXd::Zero(2, 10);
    bad(1, 6) = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_WITH_AS(acc.push(bad, MatrixXd::Zero(1, 10)), doctest::Contains("sample 6, channel 1 is NaN"),
                         modaluq::invalid_argument);
    MatrixXd inf = MatrixXd::Zero(1, 10);
    inf(0, 2) = std::numeric_limits<double>::infinity();
    CHECK_THROWS_WITH_AS(acc.push(MatrixXd::Zero(2, 10), inf), doctest::Contains("u: sample 2"), modaluq::invalid_argument);
    CHECK(acc.n_samples() == 0);  // nothing half-applied
    acc.push(MatrixXd::Random(2, 8), MatrixXd::Random(1, 8));
    CHECK_THROWS_WITH_AS(acc.finish(), doctest::Contains("record too short"), modaluq::invalid_argument);
    CovarianceAccumulator wrong(L, 50, true, 7);
    CHECK_THROWS_WITH_AS(acc.merge(wrong), doctest::Contains("must start at sample 8"), modaluq::invalid_argument);
    CHECK_THROWS_WITH_AS(wrong.finish(), doctest::Contains("starts at sample 7"), modaluq::invalid_argument);
    CHECK_THROWS_WITH_AS(modaluq::compute_covariances(MatrixXd::Random(2, 100), MatrixXd(), layout(2, 0, 3, 3), 50),
                         doctest::Contains("at least 305 samples"), modaluq::invalid_argument);
}

namespace {

template <class A, class B>
bool same(const Eigen::MatrixBase<A>& a, const Eigen::MatrixBase<B>& b) {
    return a.rows() == b.rows() && a.cols() == b.cols() && (a.size() == 0 || a == b);
}

bool same_state(const CovarianceAccumulator::State& a, const CovarianceAccumulator::State& b) {
    return a.block_length == b.block_length && a.demean == b.demean && a.first_sample == b.first_sample &&
           a.end_sample == b.end_sample && same(a.shift, b.shift) && same(a.total_sum, b.total_sum) &&
           same(a.head, b.head) && same(a.tail, b.tail) && same(a.block_index, b.block_index) &&
           same(a.block_count, b.block_count) && same(a.block_sums, b.block_sums) &&
           same(a.window_start, b.window_start) && same(a.window_samples, b.window_samples);
}

/// Bit for bit: R1..R4, the per-block covariances and the mean.
bool same_covariances(const modaluq::Covariances& a, const modaluq::Covariances& b) {
    return same(a.R1, b.R1) && same(a.R2, b.R2) && same(a.R3, b.R3) && same(a.R4, b.R4) && same(a.blocks, b.blocks) &&
           same(a.channel_mean, b.channel_mean) && a.n_blocks == b.n_blocks;
}

/// Push columns [from, to) of y, u in chunks of `step`.
void push_range(CovarianceAccumulator& acc, const Sim& s, Index from, Index to, Index step = 333) {
    for (Index pos = from; pos < to; pos += step) {
        const Index n = std::min(step, to - pos);
        acc.push(s.y.middleCols(pos, n), s.u.middleCols(pos, n));
    }
}

}  // namespace

TEST_CASE("export_state then from_state continues the stream bit for bit; a copy is a copy") {
    const Sim s = simulate(3, {0, 1, 2}, 3000, 17, true, 0.3, 0.05);
    const auto L = layout(3, 1, 4, 5, {0, 2});  // max_lag 8
    const Index Nb = 250;
    CovarianceAccumulator whole(L, Nb);
    push_range(whole, s, 0, 3000);
    const auto ref = whole.finish();
    // Cut before any sample, within the first max_lag samples, mid-block, at a block boundary
    // and at the boundary plus max_lag.
    for (Index cut : {Index(0), Index(3), Index(1111), Index(4 * Nb), Index(4 * Nb + 8)}) {
        CAPTURE(cut);
        CovarianceAccumulator acc(L, Nb);
        push_range(acc, s, 0, cut);
        const auto state = acc.export_state();
        CovarianceAccumulator resumed = CovarianceAccumulator::from_state(state);
        CHECK(same_state(resumed.export_state(), state));
        CovarianceAccumulator copy = acc;  // a real copy: pushing into it leaves acc alone
        copy.push(s.y.leftCols(50), s.u.leftCols(50));
        CHECK(same_state(acc.export_state(), state));
        push_range(acc, s, cut, 3000);
        push_range(resumed, s, cut, 3000);
        CHECK(same_state(resumed.export_state(), acc.export_state()));
        CHECK(same_covariances(resumed.finish(), acc.finish()));
        CHECK(rel(resumed.finish().blocks, ref.blocks) < 1e-12);
    }
    SUBCASE("spans and merged accumulators") {
        CovarianceAccumulator a(L, Nb), b(L, Nb, true, 1300), a2(L, Nb), b2(L, Nb, true, 1300);
        push_range(a, s, 0, 1300);
        push_range(b, s, 1300, 2000);
        push_range(a2, s, 0, 1300);
        push_range(b2, s, 1300, 2000);
        CovarianceAccumulator b_resumed = CovarianceAccumulator::from_state(b.export_state());
        a.merge(b);
        a2.merge(b_resumed);
        CHECK(same_state(a.export_state(), a2.export_state()));
        // The state of a merged accumulator is one from_state accepts, and it continues.
        CovarianceAccumulator merged = CovarianceAccumulator::from_state(a.export_state());
        push_range(a, s, 2000, 3000);
        push_range(merged, s, 2000, 3000);
        CHECK(same_covariances(merged.finish(), a.finish()));
        // A span shorter than max_lag, merged.
        CovarianceAccumulator c(L, Nb), d(L, Nb, true, 5);
        push_range(c, s, 0, 5);
        push_range(d, s, 5, 7);
        c.merge(CovarianceAccumulator::from_state(d.export_state()));
        CHECK(same_state(CovarianceAccumulator::from_state(c.export_state()).export_state(), c.export_state()));
    }
}

TEST_CASE("from_state refuses a state that no accumulator can reach, naming the field") {
    const Sim s = simulate(3, {0, 1, 2}, 1500, 19, true, 0.3, 0.05);
    const auto L = layout(3, 1, 4, 5);
    CovarianceAccumulator acc(L, 200);
    push_range(acc, s, 0, 1111);
    const auto good = acc.export_state();
    const auto refused = [&](auto change, const char* says) {
        CAPTURE(says);
        auto bad = good;
        change(bad);
        CHECK_THROWS_WITH_AS(CovarianceAccumulator::from_state(bad), doctest::Contains(says), modaluq::invalid_argument);
    };
    using State = CovarianceAccumulator::State;
    refused([](State& b) { b.layout.block_rows = 5; }, "head has shape 4 x 8, expected 4 x 9");
    refused([](State& b) { b.layout.n_inputs = 0; }, "shift has shape 4 x 1, expected 3 x 1");
    refused([](State& b) { b.layout.block_rows = 1; }, "block_rows must be >= 2");
    refused([](State& b) { b.block_length = 300; }, "block_index and block_count have 6 and 6 entries, expected 4");
    refused([](State& b) { b.end_sample += 1; }, "block_count[5] is 103, but block 5 holds 104");
    refused([](State& b) { b.end_sample = -1; }, "end_sample (-1) is before first_sample (0)");
    refused([](State& b) { b.first_sample = 3; }, "block_count[0] is 200, but block 0 holds 197");
    refused([](State& b) { b.block_index(2) = 7; }, "block_index[2] is 7, expected 2");
    refused([](State& b) { b.block_sums.conservativeResize(b.block_sums.rows() - 1, Eigen::NoChange); },
            "block_sums has shape");
    refused([](State& b) { b.block_sums(3, 1) = std::numeric_limits<double>::infinity(); }, "block_sums holds");
    refused([](State& b) { b.tail(1, 2) = std::numeric_limits<double>::quiet_NaN(); }, "tail holds");
    refused([](State& b) { b.shift(0) = 1e70; }, "shift holds");
    refused([](State& b) { b.window_start(1) += 1; }, "window_start[1] is 201, expected 200");
    refused([](State& b) { b.window_samples.resize(0, 0); }, "window_samples has shape 0 x 0");
    refused([](State& b) { b.head.resize(4, 3); }, "head has shape 4 x 3");
    // An empty accumulator has no shift yet.
    auto empty = CovarianceAccumulator(L, 200).export_state();
    CHECK(CovarianceAccumulator::from_state(empty).n_samples() == 0);
    empty.shift(1) = 2.0;
    CHECK_THROWS_WITH_AS(CovarianceAccumulator::from_state(empty), doctest::Contains("must be zero when no sample"),
                         modaluq::invalid_argument);
}

TEST_CASE("a sample whose products would overflow is refused at push, and the accumulator goes on") {
    const Sim s = simulate(3, {0, 1, 2}, 3000, 23, true, 0.3, 0.05);
    const auto L = layout(3, 1, 4, 4);
    CovarianceAccumulator clean(L, 300), acc(L, 300);
    push_range(clean, s, 0, 1000);
    push_range(clean, s, 1000, 3000);
    push_range(acc, s, 0, 1000);
    const auto before = acc.export_state();
    MatrixXd y = s.y.middleCols(1000, 500), u = s.u.middleCols(1000, 500);
    y(1, 7) = 1e200;  // finite, but its square is not
    CHECK_THROWS_WITH_AS(acc.push(y, u), doctest::Contains("y: sample 1007, channel 1 is 1e+200"),
                         modaluq::invalid_argument);
    y(1, 7) = s.y(1, 1007);
    u(0, 499) = -1e61;
    CHECK_THROWS_WITH_AS(acc.push(y, u), doctest::Contains("u: sample 1499, channel 0 is -1e+61"),
                         modaluq::invalid_argument);
    CHECK(same_state(acc.export_state(), before));  // nothing of the refused pushes went in
    push_range(acc, s, 1000, 3000);
    CHECK(same_covariances(acc.finish(), clean.finish()));
    // The limit itself is accepted, as the first sample (the shift) too; the batch pass refuses the same.
    CovarianceAccumulator edge(layout(1, 0, 2, 2), 4);
    edge.push(MatrixXd::Constant(1, 3, -CovarianceAccumulator::kMaxSampleMagnitude));
    CHECK(edge.n_samples() == 3);
    MatrixXd big = s.y;
    big(2, 2500) = 2e60;
    CHECK_THROWS_WITH_AS(modaluq::compute_covariances(big, MatrixXd(), layout(3, 0, 4, 4), 5),
                         doctest::Contains("y: sample 2500, channel 2 is 2e+60"), modaluq::invalid_argument);
}

}  // namespace test_covariance
