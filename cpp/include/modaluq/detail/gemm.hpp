#pragma once
/// @file detail/gemm.hpp
/// The large matrix products of the core (dGamma, the Q matrices, stage 4, the IO T_H) go
/// through gemm(), which is Eigen's product, or an optimised BLAS's dgemm/zgemm when
/// MODALUQ_USE_BLAS is defined and a BLAS is linked (the CMake option of the same name does
/// both for the tests and the Python module). Why: those products are most of the run time,
/// and OpenBLAS runs them 1.2-1.9x faster than Eigen 3.4 on the benchmark's shapes (AVX2,
/// one thread; docs/performance.md). Only these calls change: defining EIGEN_USE_BLAS instead would
/// also hand Eigen's own decompositions to the BLAS.
///
/// Any BLAS with the reference Fortran interface and 32-bit integers works (OpenBLAS, BLIS,
/// MKL's LP64 interface). How many threads it uses is its own setting (OPENBLAS_NUM_THREADS).

#include <Eigen/Core>

#include <climits>
#include <complex>

#ifdef MODALUQ_USE_BLAS
extern "C" {
void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* b, const int* ldb, const double* beta, double* c,
            const int* ldc);
void zgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const std::complex<double>* alpha, const std::complex<double>* a, const int* lda,
            const std::complex<double>* b, const int* ldb, const std::complex<double>* beta,
            std::complex<double>* c, const int* ldc);
}
#endif

namespace modaluq::detail {

/// How an operand enters the product: as it is, or transposed (never conjugated).
enum class Op { N, T };

/// Whether gemm() calls a BLAS in this build.
constexpr bool gemm_uses_blas() {
#ifdef MODALUQ_USE_BLAS
    return true;
#else
    return false;
#endif
}

namespace gemm_impl {

template <class S>
using Mat = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;

template <class S, class A, class B>
void eigen_product(Eigen::Ref<Mat<S>> c, const A& a, const B& b, S alpha, S beta) {
    if (beta == S(0)) c.noalias() = alpha * (a * b);
    else {
        if (beta != S(1)) c *= beta;
        c.noalias() += alpha * (a * b);
    }
}

template <class S>
void eigen_gemm(Eigen::Ref<Mat<S>> c, const Eigen::Ref<const Mat<S>>& a, Op ta, const Eigen::Ref<const Mat<S>>& b,
                Op tb, S alpha, S beta) {
    if (ta == Op::N && tb == Op::N) eigen_product<S>(c, a, b, alpha, beta);
    else if (ta == Op::T && tb == Op::N) eigen_product<S>(c, a.transpose(), b, alpha, beta);
    else if (ta == Op::N) eigen_product<S>(c, a, b.transpose(), alpha, beta);
    else eigen_product<S>(c, a.transpose(), b.transpose(), alpha, beta);
}

#ifdef MODALUQ_USE_BLAS
inline void blas(const char* ta, const char* tb, const int* m, const int* n, const int* k, const double* alpha,
                 const double* a, const int* lda, const double* b, const int* ldb, const double* beta, double* c,
                 const int* ldc) {
    dgemm_(ta, tb, m, n, k, alpha, a, lda, b, ldb, beta, c, ldc);
}
inline void blas(const char* ta, const char* tb, const int* m, const int* n, const int* k,
                 const std::complex<double>* alpha, const std::complex<double>* a, const int* lda,
                 const std::complex<double>* b, const int* ldb, const std::complex<double>* beta,
                 std::complex<double>* c, const int* ldc) {
    zgemm_(ta, tb, m, n, k, alpha, a, lda, b, ldb, beta, c, ldc);
}
#endif

template <class S>
void run(Eigen::Ref<Mat<S>> c, const Eigen::Ref<const Mat<S>>& a, Op ta, const Eigen::Ref<const Mat<S>>& b, Op tb,
         S alpha, S beta) {
    const Eigen::Index m = c.rows(), n = c.cols(), k = ta == Op::N ? a.cols() : a.rows();
    eigen_assert((ta == Op::N ? a.rows() : a.cols()) == m && (tb == Op::N ? b.cols() : b.rows()) == n &&
                 (tb == Op::N ? b.rows() : b.cols()) == k && "gemm: shapes do not agree");
    (void)m, (void)n, (void)k;
#ifdef MODALUQ_USE_BLAS
    // Eigen's path for what a BLAS rejects: empty products (a leading dimension of 0),
    // dimensions beyond 32-bit integers, and views whose columns overlap (outer stride below
    // the row count).
    const auto fits = [](Eigen::Index v) { return v > 0 && v <= INT_MAX; };
    if (fits(m) && fits(n) && fits(k) && fits(a.outerStride()) && fits(b.outerStride()) && fits(c.outerStride()) &&
        a.outerStride() >= a.rows() && b.outerStride() >= b.rows() && c.outerStride() >= c.rows()) {
        const int im = static_cast<int>(m), in = static_cast<int>(n), ik = static_cast<int>(k);
        const int lda = static_cast<int>(a.outerStride()), ldb = static_cast<int>(b.outerStride()),
                  ldc = static_cast<int>(c.outerStride());
        const char* opa = ta == Op::N ? "N" : "T";
        const char* opb = tb == Op::N ? "N" : "T";
        blas(opa, opb, &im, &in, &ik, &alpha, a.data(), &lda, b.data(), &ldb, &beta, c.data(), &ldc);
        return;
    }
#endif
    eigen_gemm<S>(c, a, ta, b, tb, alpha, beta);
}

}  // namespace gemm_impl

/// c = alpha op(a) op(b) + beta c, for column-major operands with unit inner stride
/// (matrices, blocks of them, Maps with an outer stride; anything else is copied into a
/// temporary by Eigen::Ref). c must already have the product's shape. beta = 0 ignores what
/// c held (NaN included).
inline void gemm(Eigen::Ref<Eigen::MatrixXd> c, const Eigen::Ref<const Eigen::MatrixXd>& a, Op ta,
                 const Eigen::Ref<const Eigen::MatrixXd>& b, Op tb, double alpha = 1.0, double beta = 0.0) {
    gemm_impl::run<double>(c, a, ta, b, tb, alpha, beta);
}
inline void gemm(Eigen::Ref<Eigen::MatrixXcd> c, const Eigen::Ref<const Eigen::MatrixXcd>& a, Op ta,
                 const Eigen::Ref<const Eigen::MatrixXcd>& b, Op tb, std::complex<double> alpha = 1.0,
                 std::complex<double> beta = 0.0) {  // the same for complex operands (zgemm)
    gemm_impl::run<std::complex<double>>(c, a, ta, b, tb, alpha, beta);
}

}  // namespace modaluq::detail
