#pragma once
/// @file stabilization_cases.hpp
/// Poles built by hand for the stabilization and selection tests.

#include <algorithm>
#include <map>
#include <set>

#include "support.hpp"

namespace support {

struct P {
    double f, xi = 0.02;
    int shape = 0;           // index into kShapes
    double sf = -1, sxi = -1;  // default: 0.1 % of f, 5 % of xi
    bool coupled = false;
};

// 0 and 3 have MAC 0.88: one mode whose shape varies with the order, or two close modes
inline const std::vector<std::vector<double>> kShapes = {{1.0, 0.5, -0.3}, {0.2, -0.7, 1.0}, {0.6, 1.0, 0.4}, {1.0, 0.5, 0.1}};

// Poles of the given orders (each order's poles sorted by frequency, as identify gives them).
inline modaluq::Poles make_poles(const std::map<Index, std::vector<P>>& by_order, bool with_std = true) {
    Index n = 0;
    for (const auto& kv : by_order) n += Index(kv.second.size());
    modaluq::Poles p;
    p.order.resize(n);
    p.frequency_hz.resize(n);
    p.damping_ratio.resize(n);
    p.frequency_std.resize(n);
    p.damping_std.resize(n);
    p.mode_shape.resize(3, n);
    p.mode_shape_std_real.setConstant(3, n, 1e-3);
    p.mode_shape_std_imag.setConstant(3, n, 1e-3);
    p.close_singular_values.setConstant(n, false);
    p.noise_coupled.setConstant(n, false);
    p.has_uncertainty = with_std;
    Index i = 0;
    for (const auto& [order, list] : by_order) {
        p.orders.push_back(order);
        std::vector<P> sorted = list;
        std::sort(sorted.begin(), sorted.end(), [](const P& a, const P& b) { return a.f < b.f; });
        for (const P& q : sorted) {
            p.order(i) = order;
            p.frequency_hz(i) = q.f;
            p.damping_ratio(i) = q.xi;
            const double nan = std::numeric_limits<double>::quiet_NaN();
            p.frequency_std(i) = with_std ? (q.sf < 0 ? 1e-3 * q.f : q.sf) : nan;
            p.damping_std(i) = with_std ? (q.sxi < 0 ? 0.05 * std::abs(q.xi) : q.sxi) : nan;
            for (Index r = 0; r < 3; ++r) p.mode_shape(r, i) = kShapes[q.shape][r];
            p.noise_coupled(i) = q.coupled;
            ++i;
        }
    }
    return p;
}

inline Index find(const modaluq::Diagram& d, Index order, double f) {
    for (Index i = 0; i < d.size(); ++i)
        if (d.poles.order(i) == order && std::abs(d.poles.frequency_hz(i) - f) < 1e-12) return i;
    FAIL("no pole at order ", order, " and ", f, " Hz");
    return -1;
}

// A diagram whose poles are all stable: selection tests independent of the stability rules.
inline modaluq::Diagram all_stable(const std::map<Index, std::vector<P>>& by_order) {
    modaluq::Diagram d;
    d.poles = make_poles(by_order);
    d.status.assign(std::size_t(d.poles.size()), modaluq::PoleStatus::stable);
    return d;
}

}  // namespace support
