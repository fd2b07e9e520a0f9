#pragma once
/// @file noise_floor.hpp
/// The noise floor k* of H (docs/uq-math.md §5.5): the first singular value that is not larger than the
/// typical perturbation of the trailing block of H by its own estimation error. Singular vectors
/// from k* on span estimation noise; their first-order rotations mean nothing (Weyl).

#include <Eigen/Core>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "../realization.hpp"
#include "gemm.hpp"
#include "parallel.hpp"

namespace modaluq {
namespace detail {

/// SplitMix64 (Steele, Lea & Flood 2014): a fixed, portable stream, so that k* depends neither on
/// the standard library nor on the number of threads. tests/python/oracle.py implements the same.
struct SplitMix64 {
    std::uint64_t state;
    std::uint64_t next() {
        std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
};

inline constexpr Index kNoiseFloorDraws = 20;                  ///< T in (5.10)
inline constexpr std::uint64_t kNoiseFloorSeed = 0x6d6f64616c7571ull;  ///< "modaluq"
inline constexpr Index kDenseTrailingNorm = 64;                ///< exact SVD up to this size

/// Rademacher signs (n_b x T): entry (b, t) from draw t n_b + b of the stream, +1 when its top bit
/// is clear. E[vec dH vec dH^T] = T_H T_H^T exactly for dH = sum_b eps_b dH^b (eq. 5.10). The
/// bootstrap (bootstrap.hpp) draws its own signs from another seed.
inline Eigen::MatrixXd rademacher_signs(Index nb, Index draws, std::uint64_t seed = kNoiseFloorSeed) {
    SplitMix64 rng{seed};
    Eigen::MatrixXd eps(nb, draws);
    for (Index t = 0; t < draws; ++t)
        for (Index b = 0; b < nb; ++b) eps(b, t) = (rng.next() >> 63) ? -1.0 : 1.0;
    return eps;
}

/// ||U_k^T dH V_k||_2 with U_k, V_k the singular vectors from index k on (eq. 5.11). Exact
/// (SVD) for r - k <= kDenseTrailingNorm; above, a power iteration on M^T M from the all-ones
/// vector until the estimate grows by less than 1e-4 relative in a step (at most 200 steps). Its
/// estimate is a lower bound, within about 1 % on noise blocks (a threshold at 1.5 delta_k needs
/// no more), so a too-low value only freezes less.
inline double trailing_norm(const Eigen::MatrixXd& U, const Eigen::MatrixXd& V,
                            const Eigen::Ref<const Eigen::MatrixXd>& dh, Index k) {
    const Index m = U.cols() - k;
    if (m <= 0) return 0.0;
    const auto Uk = U.rightCols(m);
    const auto Vk = V.rightCols(m);
    if (m <= kDenseTrailingNorm) {
        Eigen::MatrixXd w(m, dh.cols()), d(m, m);
        gemm(w, Uk, Op::T, dh, Op::N);
        gemm(d, w, Op::N, Vk, Op::N);
        return Eigen::JacobiSVD<Eigen::MatrixXd>(d).singularValues()(0);
    }
    Eigen::VectorXd x = Eigen::VectorXd::Constant(m, 1.0 / std::sqrt(static_cast<double>(m)));
    Eigen::VectorXd y(dh.rows()), z(m), t(dh.cols());
    double est = 0.0;
    for (int it = 0; it < 200; ++it) {
        y.noalias() = dh * (Vk * x);
        z.noalias() = Uk.transpose() * y;
        const double now = z.norm();
        if (now == 0.0) return 0.0;
        const bool done = it > 0 && now - est <= 1e-4 * now;
        est = now;
        if (done) break;
        t.noalias() = dh.transpose() * (Uk * z);
        x.noalias() = Vk.transpose() * t;
        x /= x.norm();
    }
    return est;
}

/// k* and the delta_k evaluated on the way (NaN where skipped).
struct NoiseFloor {
    Index k = 0;            ///< first index k with s_k < factor delta_k; k_max if none below k_max
    Eigen::VectorXd delta;  ///< delta_k = RMS_t ||D_t[k:, k:]||_2 where evaluated (eq. 5.11)
};

/// Noise floor (eq. 5.12): the smallest k < k_max with s_k < factor delta_k. delta_k does not
/// increase with k (norm of a sub-block), so an evaluated delta_k' bounds every later one and
/// indices with s_k >= factor * bound are skipped; the first bound is the RMS Frobenius norm.
/// @param t_h  T_H, (a b) x n_b;  @param b  columns of H
inline NoiseFloor noise_floor(const Realization& re, const Eigen::MatrixXd& t_h, Index b, double factor,
                              Index k_max, Index threads = 1) {
    const Eigen::MatrixXd& U = re.U();
    const Eigen::MatrixXd& V = re.V();
    const Eigen::VectorXd& s = re.singular_values();
    const Index a = U.rows(), nb = t_h.cols(), T = kNoiseFloorDraws;
    k_max = std::min<Index>(k_max, s.size());
    NoiseFloor out;
    out.delta = Eigen::VectorXd::Constant(k_max, std::numeric_limits<double>::quiet_NaN());
    out.k = k_max;
    if (k_max <= 0) return out;
    Eigen::MatrixXd draws(a * b, T);  // column t is vec dH_t
    gemm(draws, t_h, Op::N, rademacher_signs(nb, T), Op::N);
    double bound = std::sqrt(draws.colwise().squaredNorm().mean());
    std::vector<double> sq(static_cast<size_t>(T));
    for (Index k = 0; k < k_max; ++k) {
        if (s(k) >= factor * bound) continue;
        parallel_for(T, threads, [&](Index t) {
            const Eigen::Map<const Eigen::MatrixXd> dh(draws.col(t).data(), a, b);
            const double v = trailing_norm(U, V, dh, k);
            sq[static_cast<size_t>(t)] = v * v;
        });
        double sum = 0.0;
        for (double v : sq) sum += v;  // in draw order: independent of threads
        out.delta(k) = std::sqrt(sum / static_cast<double>(T));
        if (s(k) < factor * out.delta(k)) {
            out.k = k;
            return out;
        }
        bound = out.delta(k);
    }
    return out;
}

}  // namespace detail
}  // namespace modaluq
