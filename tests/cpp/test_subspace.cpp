// subspace.hpp: H from R1..R4 and its sensitivity J_{H,R} (stage 1 of the propagation).
#include <doctest/doctest.h>

#include "support/uncertainty_cases.hpp"

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_subspace {

using namespace support;

TEST_CASE("stage J_{H,R}: matrix-free T_H equals finite differences and the Kronecker form") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case c = make_case(io);
        const auto sub = modaluq::subspace_matrix(c.cov);
        const MatrixXd TR = c.cov.covariance_factor();
        const MatrixXd TH = modaluq::propagate_to_subspace(sub, c.cov, TR);
        const MatrixXd J = jacobian_H_R(c.cov, sub);
        CHECK(rel(TH, J * TR) < 1e-12);
        for (Index k : {0, 7, 19}) {
            const VectorXd d = TR.col(k);
            const double h = step(stack_r(c.cov), d);
            const MatrixXd Hp = modaluq::subspace_matrix(perturb(c.cov, d, h)).H;
            const MatrixXd Hm = modaluq::subspace_matrix(perturb(c.cov, d, -h)).H;
            const MatrixXd fd = (Hp - Hm) / (2 * h);
            CHECK(rel(Eigen::Map<const MatrixXd>(TH.col(k).data(), fd.rows(), fd.cols()), fd) < 1e-6);
        }
    }
}

}  // namespace test_subspace
