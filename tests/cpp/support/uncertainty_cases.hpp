#pragma once
/// @file uncertainty_cases.hpp
/// The small simulated cases of the propagation's stage tests.



#include "support.hpp"

namespace support {

struct Case {
    Sim s;
    modaluq::IdentifyOptions o;
    modaluq::Covariances cov;
};

// 3-DOF chain, 2 outputs, p != q; the known input has std 10 so that the R3+ dR3 R3+ term of
// dH matters (docs/uq-math.md §4.1).
inline Case make_case(bool io, Index n = 6) {
    Case c;
    c.s = simulate(3, {0, 2}, 6000, 17, io, io ? 1.0 : 1.0, 0.05, 20.0, false, 10.0);
    c.o.fs = c.s.fs;
    c.o.block_rows = 4;
    c.o.past_block_rows = 5;
    c.o.orders = {n};
    c.o.n_blocks = 20;
    c.cov = modaluq::compute_covariances(c.s.y, io ? c.s.u : MatrixXd(), c.o.layout(2, io ? 1 : 0), c.o.n_blocks);
    return c;
}

inline modaluq::Covariances perturb(const modaluq::Covariances& c, const VectorXd& d, double h) {
    modaluq::Covariances p = c;
    Index pos = 0;
    for (MatrixXd* m : {&p.R1, &p.R2, &p.R3, &p.R4}) {
        if (m->size() == 0) continue;
        *m += h * Eigen::Map<const MatrixXd>(d.data() + pos, m->rows(), m->cols());
        pos += m->size();
    }
    return p;
}

// Step for central differences: 1e-6 relative to the unperturbed quantity.
inline double step(const VectorXd& x, const VectorXd& d) { return 1e-6 * x.norm() / d.norm(); }

inline VectorXd stack_r(const modaluq::Covariances& c) {
    VectorXd r(c.layout.n_covariance_entries());
    Index pos = 0;
    for (const MatrixXd* m : {&c.R1, &c.R2, &c.R3, &c.R4}) {
        r.segment(pos, m->size()) = Eigen::Map<const VectorXd>(m->data(), m->size());
        pos += m->size();
    }
    return r;
}

// theta = [f, xi, Re shape, Im shape] of mode i, normalised at component k.
inline VectorXd theta(const modaluq::Modes& m, Index i, Index k) {
    const Index l = m.mode_shape.rows();
    VectorXd t(2 + 2 * l);
    const Eigen::VectorXcd sh = m.mode_shape.col(i) / m.mode_shape(k, i);
    t << m.frequency_hz(i), m.damping_ratio(i), sh.real(), sh.imag();
    return t;
}

inline Index nearest(const modaluq::Modes& m, double f) {
    Index i;
    (m.frequency_hz.array() - f).abs().minCoeff(&i);
    return i;
}

}  // namespace support
