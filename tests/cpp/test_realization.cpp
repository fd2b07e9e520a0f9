// realization.hpp: A and C from Gamma (least squares on the shifted observability matrix) and
// their sensitivity to Gamma, with the residual term.
#include <doctest/doctest.h>

#include "support/uncertainty_cases.hpp"

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_realization {

using namespace support;

TEST_CASE("stage dA, dC: explicit J_{A,Gamma} (with the residual term) equals finite differences") {
    const Case c = make_case(false);
    const Index n = 6, l = 2;
    const auto sub = modaluq::subspace_matrix(c.cov);
    const modaluq::Realization re(sub.H, l, n);
    const MatrixXd G = re.observability();
    const MatrixXd J = jacobian_AC_Gamma(G, l);
    auto ac = [&](const MatrixXd& g) {
        const Index a = g.rows();
        MatrixXd A = g.topRows(a - l).colPivHouseholderQr().solve(g.bottomRows(a - l));
        // [vec A; vec C] (a comma initializer must be given every coefficient: assertions check it)
        const MatrixXd C = g.topRows(l);
        VectorXd v(n * n + l * n);
        v << Eigen::Map<const VectorXd>(A.data(), n * n), Eigen::Map<const VectorXd>(C.data(), l * n);
        return v;
    };
    std::mt19937_64 rng(5);
    std::normal_distribution<double> g01;
    MatrixXd dG(G.rows(), G.cols());
    for (Index i = 0; i < dG.size(); ++i) dG(i) = g01(rng);
    const double h = 1e-6 * G.norm() / dG.norm();
    const VectorXd fd = (ac(G + h * dG) - ac(G - h * dG)) / (2 * h);
    CHECK(rel(J * Eigen::Map<const VectorXd>(dG.data(), dG.size()), fd) < 1e-6);
    // The production A (QR at the largest order) equals the least-squares solution.
    CHECK(rel(re.system(n).A, G.topRows(G.rows() - l).colPivHouseholderQr().solve(G.bottomRows(G.rows() - l))) < 1e-10);
}

}  // namespace test_realization
