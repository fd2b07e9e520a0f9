#pragma once
/// @file bootstrap.hpp
/// The standard deviations of f and xi above the noise floor k* from a parametric (wild) bootstrap
/// of H (docs/uq-math.md §5.6). Above k* the noise singular directions in the model are chosen by
/// the noise itself: no first-order map describes that (frozen, it gives sigma too small; free,
/// too large). Draw b perturbs H by its own estimation error, H_b = H + unvec(T_H eps_b) with
/// Rademacher eps_b (so E[vec dH vec dH^T] = T_H T_H^T), identifies H_b at every order asked and
/// follows each pole to the nearest pole of its order; its sigma is the robust spread (1.4826 MAD)
/// of the followed values, which a pole swapping with a spurious one in a few draws does not inflate.

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdint>
#include <limits>
#include <vector>

#include "../errors.hpp"
#include "../modal.hpp"
#include "../realization.hpp"
#include "noise_floor.hpp"
#include "parallel.hpp"

namespace modaluq {
namespace detail {

inline constexpr std::uint64_t kBootstrapSeed = 0x626f6f7473747270ull;  ///< "bootstrp"
/// A draw's pole follows a pole of the record when it is the nearest in |df|/f + |dxi| and within
/// this relative distance in frequency.
inline constexpr double kBootstrapFollowTolerance = 0.05;
/// Below this fraction of draws followed, a pole keeps its first-order sigma.
inline constexpr double kBootstrapMinFollowed = 0.8;
inline constexpr double kMadToStd = 1.482602218505602;  ///< 1 / Phi^{-1}(3/4)

/// Rademacher signs (n_b x draws) of the bootstrap: the stream of rademacher_signs with its own seed.
inline Eigen::MatrixXd bootstrap_signs(Index nb, Index draws) { return rademacher_signs(nb, draws, kBootstrapSeed); }

/// The poles (f in Hz, xi) of one draw at one order, Im lambda > 0, in no particular order.
struct DrawPoles {
    std::vector<double> f, xi;
};

/// f and xi of the poles of (A, C) = re.system(n): the eigenvalues only.
inline DrawPoles draw_poles(const Realization& re, Index n, double fs) {
    DrawPoles out;
    const StateSpace ss = re.system(n);
    if (!ss.A.allFinite()) return out;
    Eigen::EigenSolver<Eigen::MatrixXd> es(ss.A, /*computeEigenvectors=*/false);
    if (es.info() != Eigen::Success) return out;
    for (Index i = 0; i < n; ++i) {
        const std::complex<double> lambda = es.eigenvalues()(i);
        if (!(lambda.imag() > 0.0)) continue;
        const std::complex<double> mu = std::log(lambda) * fs;
        out.f.push_back(std::abs(mu) / (2.0 * pi));
        out.xi.push_back(-mu.real() / std::abs(mu));
    }
    return out;
}

/// 1.4826 times the median absolute deviation from the median of x (x is reordered).
inline double mad_std(std::vector<double>& x) {
    auto median = [](std::vector<double>& v) {
        const std::size_t m = v.size() / 2;
        std::nth_element(v.begin(), v.begin() + m, v.end());
        const double hi = v[m];
        if (v.size() % 2) return hi;
        return 0.5 * (hi + *std::max_element(v.begin(), v.begin() + m));
    };
    const double med = median(x);
    for (double& v : x) v = std::abs(v - med);
    return kMadToStd * median(x);
}

/// Per target order, per pole: the bootstrap sigma of f and xi (NaN where fewer than
/// kBootstrapMinFollowed of the draws followed the pole).
struct BootstrapStd {
    std::vector<Eigen::VectorXd> f, xi;
};

/// @param H        the record's subspace matrix (a x b)
/// @param t_h      T_H, (a b) x n_b
/// @param l        outputs
/// @param fs       sampling frequency, Hz
/// @param targets  the record's modes at each order to bootstrap (target t: its order, f and xi)
/// @param draws    B
/// @param threads  threads over the draws (the result does not depend on it)
inline BootstrapStd bootstrap_std(const Eigen::MatrixXd& H, const Eigen::MatrixXd& t_h, Index l, double fs,
                                  const std::vector<const Modes*>& targets, Index draws, Index threads) {
    const Index nt = static_cast<Index>(targets.size()), nb = t_h.cols();
    BootstrapStd out;
    out.f.resize(targets.size());
    out.xi.resize(targets.size());
    if (nt == 0 || draws < 1) return out;
    Index n_max = 0;
    for (const Modes* m : targets) n_max = std::max(n_max, m->order);
    const Eigen::MatrixXd eps = bootstrap_signs(nb, draws);
    // sf[t][i * draws + d]: pole i of target t in draw d (NaN: not followed, or the draw failed)
    std::vector<std::vector<double>> sf(targets.size()), sx(targets.size());
    for (Index t = 0; t < nt; ++t) {
        sf[t].assign(static_cast<std::size_t>(targets[t]->n_modes() * draws), std::numeric_limits<double>::quiet_NaN());
        sx[t] = sf[t];
    }
    parallel_for(draws, threads, [&](Index d) {  // draws write disjoint samples
        Eigen::MatrixXd Hb = H;
        Eigen::Map<Eigen::VectorXd>(Hb.data(), Hb.size()).noalias() += t_h * eps.col(d);
        try {
            const Realization re(Hb, l, std::min(n_max, std::min(Hb.rows() - l, Hb.cols())));
            for (Index t = 0; t < nt; ++t) {
                const Modes& m = *targets[t];
                if (m.order > re.max_order()) continue;
                const DrawPoles p = draw_poles(re, m.order, fs);
                const Index np = static_cast<Index>(p.f.size());
                for (Index i = 0; i < m.n_modes(); ++i) {
                    const double f0 = m.frequency_hz(i), x0 = m.damping_ratio(i);
                    Index best = -1;
                    double dbest = std::numeric_limits<double>::infinity();
                    for (Index j = 0; j < np; ++j) {
                        const double dist = std::abs(p.f[j] / f0 - 1.0) + std::abs(p.xi[j] - x0);
                        if (dist < dbest) dbest = dist, best = j;
                    }
                    if (best >= 0 && std::abs(p.f[best] / f0 - 1.0) <= kBootstrapFollowTolerance) {
                        sf[t][i * draws + d] = p.f[best];
                        sx[t][i * draws + d] = p.xi[best];
                    }
                }
            }
        } catch (const numerical_error&) {
            // a draw without a realization follows no pole
        }
    });
    const Index min_followed = static_cast<Index>(std::ceil(kBootstrapMinFollowed * static_cast<double>(draws)));
    for (Index t = 0; t < nt; ++t) {
        const Index nm = targets[t]->n_modes();
        out.f[t] = Eigen::VectorXd::Constant(nm, std::numeric_limits<double>::quiet_NaN());
        out.xi[t] = out.f[t];
        for (Index i = 0; i < nm; ++i) {
            std::vector<double> a, b;
            for (Index d = 0; d < draws; ++d)
                if (!std::isnan(sf[t][i * draws + d])) {
                    a.push_back(sf[t][i * draws + d]);
                    b.push_back(sx[t][i * draws + d]);
                }
            if (static_cast<Index>(a.size()) < std::max<Index>(min_followed, 2)) continue;
            out.f[t](i) = mad_std(a);
            out.xi[t](i) = mad_std(b);
        }
    }
    return out;
}

/// Replace sigma_f and sigma_xi by the bootstrap's at every order above k_star, for the poles
/// not noise_coupled that the bootstrap followed (docs/uq-math.md §5.6). The covariance's f and xi
/// rows and columns and the factor rows are scaled by sigma_boot / sigma_first_order, so the
/// covariance stays positive semi-definite and the correlations are kept.
inline void apply_bootstrap(std::vector<Modes>& modes, const Eigen::MatrixXd& H, const Eigen::MatrixXd& t_h, Index l,
                            double fs, Index k_star, Index draws, Index threads) {
    std::vector<Modes*> target;
    for (Modes& m : modes)
        if (!m.degenerate && m.order > k_star && m.n_modes() > 0 && m.frequency_std.size() == m.n_modes())
            target.push_back(&m);
    if (target.empty()) return;
    const BootstrapStd bs =
        bootstrap_std(H, t_h, l, fs, std::vector<const Modes*>(target.begin(), target.end()), draws, threads);
    const Index np = 2 + 2 * l, nb = t_h.cols();
    for (std::size_t t = 0; t < target.size(); ++t) {
        Modes& m = *target[t];
        for (Index i = 0; i < m.n_modes(); ++i) {
            const double sf = bs.f[t](i), sx = bs.xi[t](i);
            // a zero first-order sigma has no factor to rescale: keep it (never seen but exact poles)
            if (m.noise_coupled(i) || !(sf > 0.0) || !(sx > 0.0) || !(m.frequency_std(i) > 0.0) ||
                !(m.damping_std(i) > 0.0))
                continue;
            const double cf = sf / m.frequency_std(i), cx = sx / m.damping_std(i);
            Eigen::Map<Eigen::MatrixXd> cov(m.covariance.col(i).data(), np, np);
            cov.row(0) *= cf;
            cov.col(0) *= cf;
            cov.row(1) *= cx;
            cov.col(1) *= cx;
            m.frequency_damping_factor.col(i).head(nb) *= cf;
            m.frequency_damping_factor.col(i).segment(nb, nb) *= cx;
            m.frequency_std(i) = sf;
            m.damping_std(i) = sx;
            m.bootstrapped(i) = true;
        }
    }
}

}  // namespace detail
}  // namespace modaluq
