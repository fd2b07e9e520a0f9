// detail::gemm equals Eigen's own product, on whichever path this build takes (BLAS or Eigen):
// every transposition, blocks with an outer stride, accumulation (beta), empty operands,
// overlapping views (which a BLAS would reject) and complex operands.
#include <doctest/doctest.h>

#include <modaluq/detail/gemm.hpp>

#include <limits>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_gemm {

using Eigen::MatrixXcd;
using Eigen::MatrixXd;
using modaluq::detail::gemm;
using modaluq::detail::Op;

namespace {
template <class M>
M op(const M& x, Op o) { return o == Op::N ? M(x) : M(x.transpose()); }
}  // namespace

TEST_CASE("gemm equals Eigen's product for every transposition, block and beta") {
    INFO("BLAS path: " << modaluq::detail::gemm_uses_blas());
    for (Op ta : {Op::N, Op::T})
        for (Op tb : {Op::N, Op::T})
            for (double beta : {0.0, 1.0, -0.5}) {
                const int m = 13, k = 7, n = 5;
                // Operands as blocks of larger matrices: outer stride above the row count.
                const MatrixXd big_a = MatrixXd::Random(20, 20), big_b = MatrixXd::Random(20, 20);
                const auto a = ta == Op::N ? big_a.block(2, 3, m, k) : big_a.block(2, 3, k, m);
                const auto b = tb == Op::N ? big_b.block(1, 0, k, n) : big_b.block(1, 0, n, k);
                MatrixXd big_c = MatrixXd::Random(30, 8);
                const MatrixXd c0 = big_c.block(4, 1, m, n);
                gemm(big_c.block(4, 1, m, n), a, ta, b, tb, 2.0, beta);
                const MatrixXd expect = 2.0 * op<MatrixXd>(a, ta) * op<MatrixXd>(b, tb) + beta * c0;
                CHECK((big_c.block(4, 1, m, n) - expect).cwiseAbs().maxCoeff() < 1e-13);
            }
}

TEST_CASE("gemm with beta = 0 ignores NaN in the output, and empty products") {
    const MatrixXd a = MatrixXd::Random(6, 4), b = MatrixXd::Random(4, 3);
    MatrixXd c = MatrixXd::Constant(6, 3, std::numeric_limits<double>::quiet_NaN());
    gemm(c, a, Op::N, b, Op::N);
    CHECK((c - a * b).cwiseAbs().maxCoeff() < 1e-14);

    MatrixXd c2 = MatrixXd::Ones(6, 3);  // k = 0: c = beta c
    gemm(c2, MatrixXd(6, 0), Op::N, MatrixXd(0, 3), Op::N, 1.0, 2.0);
    CHECK((c2.array() == 2.0).all());
    MatrixXd c3(0, 3);  // m = 0: nothing to do, no BLAS error
    gemm(c3, MatrixXd(0, 4), Op::N, b, Op::N);
    CHECK(c3.size() == 0);
}

TEST_CASE("gemm on a view whose columns overlap (outer stride below the rows)") {
    // The segmented lag sums' view: column j starts d samples after column j - 1.
    const Eigen::VectorXd x = Eigen::VectorXd::Random(40);
    using Strided = Eigen::Map<const MatrixXd, 0, Eigen::OuterStride<>>;
    const Strided v(x.data(), 9, 10, Eigen::OuterStride<>(3));
    const MatrixXd b = MatrixXd::Random(4, 10);
    MatrixXd c(9, 4);
    gemm(c, v, Op::N, b, Op::T);
    CHECK((c - MatrixXd(v) * b.transpose()).cwiseAbs().maxCoeff() < 1e-13);
}

TEST_CASE("complex gemm transposes without conjugating") {
    const MatrixXcd a = MatrixXcd::Random(5, 8), b = MatrixXcd::Random(6, 8);
    MatrixXcd c = MatrixXcd::Random(5, 6);
    const MatrixXcd c0 = c;
    gemm(c, a, Op::N, b, Op::T, std::complex<double>(0.5, -1.0), std::complex<double>(1.0));
    const MatrixXcd expect = std::complex<double>(0.5, -1.0) * a * b.transpose() + c0;
    CHECK((c - expect).cwiseAbs().maxCoeff() < 1e-13);
}

}  // namespace test_gemm
