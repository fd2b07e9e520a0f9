#pragma once
// Compile-time economy for the test executable: Eigen's decompositions used by modaluq are
// instantiated once, in eigen_instances.cpp, instead of in every test file (this more than
// halves the build of each test file). Include before any modaluq header.
#include <Eigen/Dense>

#ifndef MODALUQ_TESTS_INSTANTIATE_EIGEN
#define MODALUQ_TESTS_EIGEN_EXTERN extern
#else
#define MODALUQ_TESTS_EIGEN_EXTERN
#endif

MODALUQ_TESTS_EIGEN_EXTERN template class Eigen::BDCSVD<Eigen::MatrixXd>;
MODALUQ_TESTS_EIGEN_EXTERN template class Eigen::JacobiSVD<Eigen::MatrixXd>;
MODALUQ_TESTS_EIGEN_EXTERN template class Eigen::EigenSolver<Eigen::MatrixXd>;
MODALUQ_TESTS_EIGEN_EXTERN template class Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>;
MODALUQ_TESTS_EIGEN_EXTERN template class Eigen::HouseholderQR<Eigen::MatrixXd>;
MODALUQ_TESTS_EIGEN_EXTERN template class Eigen::ColPivHouseholderQR<Eigen::MatrixXd>;
MODALUQ_TESTS_EIGEN_EXTERN template class Eigen::PartialPivLU<Eigen::MatrixXd>;
MODALUQ_TESTS_EIGEN_EXTERN template class Eigen::PartialPivLU<Eigen::MatrixXcd>;
