// poser.hpp: the PoSER merge (docs/uq-math.md §13.5, §13.9). A synthetic campaign whose
// per-setup shapes are exact scaled restrictions of one global shape gives the closed form
// (weighted means, sigma_f = (sum 1/sigma_j^2)^-1/2, the global shape exactly, zero reference
// residual); the Jacobians (alpha_j, the rescaled and normalised shape, f and xi, the
// reference residual) are checked against central finite differences of the merge itself.
#include "eigen_instances.hpp"

#include <doctest/doctest.h>

#include <modaluq/poser.hpp>

#include <cmath>
#include <random>
#include <vector>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_poser {

namespace {

using Eigen::Index;
using Eigen::MatrixXcd;
using Eigen::MatrixXd;
using Eigen::VectorXcd;
using Eigen::VectorXd;
using cd = std::complex<double>;
using modaluq::PoserResult;
using modaluq::PoserSetupModes;

// Global layout: references R0, R1, then 2 moving DOFs per setup; 3 setups, 2 modes.
constexpr Index kR = 2, kSetups = 3, kMove = 2, kModes = 2;
constexpr Index kLg = kR + kSetups * kMove;

struct Case {
    std::vector<PoserSetupModes> setups;
    MatrixXcd psi;  // kLg x kModes, the true global shapes
    std::vector<std::vector<Index>> rows;  // per setup, its rows' global DOFs (row order)
};

MatrixXd random_spd(Index n, std::mt19937& g, double scale) {
    std::normal_distribution<double> N(0.0, 1.0);
    MatrixXd a(n, n);
    for (Index i = 0; i < a.size(); ++i) a(i) = N(g);
    return scale * (a * a.transpose() / double(n) + 0.1 * MatrixXd::Identity(n, n));
}

// Each setup measures the references in a permuted row order (setup 1: R1 first) and its two
// moving DOFs; its shape is c_j times the true one on its rows (c_j complex: a per-setup
// normalisation the merge must undo), f and xi as given.
Case make_case(unsigned seed = 7, double noise = 0.0) {
    std::mt19937 g(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    Case c;
    c.psi.resize(kLg, kModes);
    for (Index i = 0; i < c.psi.size(); ++i) c.psi(i) = cd(N(g), 0.2 * N(g));
    const double f0[kModes] = {2.0, 5.0}, x0[kModes] = {0.01, 0.02};
    for (Index j = 0; j < kSetups; ++j) {
        PoserSetupModes s;
        std::vector<Index> rows;
        if (j == 1) {
            rows = {kR + j * kMove, 1, kR + j * kMove + 1, 0};  // R1 at row 1, R0 at row 3
            s.references = {3, 1};
        } else {
            rows = {0, 1, kR + j * kMove, kR + j * kMove + 1};
            s.references = {0, 1};
        }
        const Index l = Index(rows.size()), np = 2 + 2 * l;
        s.frequency_hz.resize(kModes);
        s.damping_ratio.resize(kModes);
        s.mode_shape.resize(l, kModes);
        s.covariance.resize(np * np, kModes);
        for (Index m = 0; m < kModes; ++m) {
            const cd scale(0.5 + 0.3 * j, 0.4 * j - 0.3 * m);
            for (Index r = 0; r < l; ++r) s.mode_shape(r, m) = scale * c.psi(rows[r], m) * (1.0 + noise * cd(N(g), N(g)));
            s.frequency_hz(m) = f0[m] * (1.0 + 0.001 * (j - 1));
            s.damping_ratio(m) = x0[m] * (1.0 + 0.05 * (j - 1));
            const MatrixXd cv = random_spd(np, g, 1e-4 * (1.0 + j));
            s.covariance.col(m) = Eigen::Map<const VectorXd>(cv.data(), np * np);
        }
        c.setups.push_back(s);
        c.rows.push_back(rows);
    }
    return c;
}

MatrixXd cov_of(const PoserSetupModes& s, Index m) {
    const Index np = 2 + 2 * s.mode_shape.rows();
    return Eigen::Map<const MatrixXd>(s.covariance.col(m).data(), np, np);
}

// theta = [f, xi, Re shape, Im shape] of mode m of a merge.
VectorXd theta(const PoserResult& r, Index m) {
    const Index l = r.mode_shape.rows();
    VectorXd t(2 + 2 * l);
    t << r.frequency_hz(m), r.damping_ratio(m), r.mode_shape.col(m).real(), r.mode_shape.col(m).imag();
    return t;
}

// Setup j's mode m moved by h along the real direction u of [f, xi, Re shape, Im shape].
std::vector<PoserSetupModes> moved(std::vector<PoserSetupModes> s, Index j, Index m, const VectorXd& u, double h) {
    PoserSetupModes& x = s[j];
    const Index l = x.mode_shape.rows();
    x.frequency_hz(m) += h * u(0);
    x.damping_ratio(m) += h * u(1);
    for (Index r = 0; r < l; ++r) x.mode_shape(r, m) += h * cd(u(2 + r), u(2 + l + r));
    return s;
}

}  // namespace

TEST_CASE("poser: a consistent campaign gives the closed form") {
    const Case c = make_case();
    const PoserResult r = modaluq::poser_merge(c.setups);
    REQUIRE(r.n_modes() == kModes);
    CHECK(r.mode_shape.rows() == kLg);
    for (Index m = 0; m < kModes; ++m) {
        double wf = 0, wx = 0, f = 0, x = 0;
        for (const auto& s : c.setups) {
            const MatrixXd cv = cov_of(s, m);
            wf += 1 / cv(0, 0);
            wx += 1 / cv(1, 1);
            f += s.frequency_hz(m) / cv(0, 0);
            x += s.damping_ratio(m) / cv(1, 1);
        }
        CHECK(r.frequency_hz(m) == doctest::Approx(f / wf).epsilon(1e-14));
        CHECK(r.damping_ratio(m) == doctest::Approx(x / wx).epsilon(1e-14));
        CHECK(r.frequency_std(m) == doctest::Approx(1 / std::sqrt(wf)).epsilon(1e-12));
        CHECK(r.damping_std(m) == doctest::Approx(1 / std::sqrt(wx)).epsilon(1e-12));
        // the global shape is the true one, normalised at its largest component
        Index k;
        c.psi.col(m).cwiseAbs().maxCoeff(&k);
        CHECK(r.reference_component(m) == k);
        CHECK((r.mode_shape.col(m) - c.psi.col(m) / c.psi(k, m)).norm() < 1e-13);
        // alpha_j undoes each setup's scale relative to the basis setup's
        for (Index j = 0; j < kSetups; ++j) {
            const cd sj(0.5 + 0.3 * j, 0.4 * j - 0.3 * m), s0(0.5, -0.3 * m);
            CHECK(std::abs(r.scale(j, m) - s0 / sj) < 1e-13);
            CHECK(r.mode_index(j, m) == m);
        }
        CHECK(r.basis_setup(m) == 0);
        // zero residual of the references: chi2 = 0, p = 1, nothing rejected
        for (Index j = 1; j < kSetups; ++j) {
            CHECK(r.reference_chi2(j, m) < 1e-20);
            CHECK(r.reference_p_value(j, m) == doctest::Approx(1.0));
            CHECK(!r.reference_rejected(j, m));
        }
        CHECK(std::isnan(r.reference_chi2(0, m)));
    }
    CHECK(r.reference_dof == 2);
    CHECK(r.n_reference_tests == (kSetups - 1) * kModes);
    // the layout: references once, then each setup's moving rows in row order
    CHECK(r.dof_setup[0] == -1);
    CHECK(r.dof_setup[kR] == 0);
    CHECK(r.dof_setup[kR + kMove] == 1);
    CHECK(r.dof_channel[kR + kMove] == 0);  // setup 1's first moving row is its row 0
    CHECK(r.dof_channel[kR + kMove + 1] == 2);
}

TEST_CASE("poser: the merge does not depend on each setup's normalisation or on the sorting") {
    Case c = make_case(3, 0.01);
    const PoserResult a = modaluq::poser_merge(c.setups);
    // rescale setup 2's shapes by a complex constant (its covariance accordingly)
    const cd s(0.3, -1.7);
    PoserSetupModes& x = c.setups[2];
    const Index l = x.mode_shape.rows(), np = 2 + 2 * l;
    MatrixXd T = MatrixXd::Identity(np, np);  // real map of phi -> s phi
    T.block(2, 2, l, l) = s.real() * MatrixXd::Identity(l, l);
    T.block(2, 2 + l, l, l) = -s.imag() * MatrixXd::Identity(l, l);
    T.block(2 + l, 2, l, l) = s.imag() * MatrixXd::Identity(l, l);
    T.block(2 + l, 2 + l, l, l) = s.real() * MatrixXd::Identity(l, l);
    for (Index m = 0; m < kModes; ++m) {
        x.mode_shape.col(m) *= s;
        const MatrixXd cv = T * cov_of(x, m) * T.transpose();
        x.covariance.col(m) = Eigen::Map<const VectorXd>(cv.data(), np * np);
    }
    // and swap setup 1's modes
    PoserSetupModes& y = c.setups[1];
    y.frequency_hz.reverseInPlace();
    y.damping_ratio.reverseInPlace();
    y.mode_shape = y.mode_shape.rowwise().reverse().eval();
    y.covariance = y.covariance.rowwise().reverse().eval();
    const PoserResult b = modaluq::poser_merge(c.setups);
    CHECK((a.mode_shape - b.mode_shape).norm() < 1e-12);
    CHECK((a.covariance - b.covariance).norm() < 1e-12 * a.covariance.norm());
    CHECK((a.reference_chi2 - b.reference_chi2).bottomRows(kSetups - 1).norm() <
          1e-9 * a.reference_chi2.bottomRows(kSetups - 1).norm());
    CHECK(b.mode_index(1, 0) == 1);
}

TEST_CASE("poser: alpha_j (12.10) equals finite differences along real and imaginary directions") {
    std::mt19937 g(5);
    std::normal_distribution<double> N(0.0, 1.0);
    VectorXcd phi(3), b(3);
    for (Index i = 0; i < 3; ++i) {
        phi(i) = cd(N(g), N(g));
        b(i) = cd(N(g), N(g));
    }
    const cd a = modaluq::poser_scale(phi, b);
    const double n = phi.squaredNorm(), h = 1e-6;
    for (Index c = 0; c < 3; ++c)
        for (cd v : {cd(1, 0), cd(0, 1)}) {
            VectorXcd p = phi, q = phi;
            p(c) += h * v;
            q(c) -= h * v;
            const cd fd_phi = (modaluq::poser_scale(p, b) - modaluq::poser_scale(q, b)) / (2 * h);
            const cd an_phi = (std::conj(v) * b(c) - a * (std::conj(v) * phi(c) + std::conj(phi(c)) * v)) / n;
            CHECK(std::abs(fd_phi - an_phi) < 1e-8);
            p = b;
            q = b;
            p(c) += h * v;
            q(c) -= h * v;
            const cd fd_b = (modaluq::poser_scale(phi, p) - modaluq::poser_scale(phi, q)) / (2 * h);
            CHECK(std::abs(fd_b - std::conj(phi(c)) * v / n) < 1e-8);
        }
}

TEST_CASE("poser: the propagated covariance equals J Sigma J^T with J from finite differences") {
    // The covariance is linear in each setup's: adding u u^T (u without f, xi parts, so the
    // weights stay) to setup j's mode m adds v v^T, v = d theta / d(setup j) u, which central
    // differences of the merge give. Every setup (basis and not), references and moving rows,
    // real and imaginary parts, the normalisation.
    const Case c = make_case(11, 0.02);
    const PoserResult base = modaluq::poser_merge(c.setups);
    std::mt19937 g(2);
    std::normal_distribution<double> N(0.0, 1.0);
    const double h = 1e-6;
    for (Index j = 0; j < kSetups; ++j)
        for (Index m = 0; m < kModes; ++m) {
            const Index l = c.setups[j].mode_shape.rows(), np = 2 + 2 * l;
            VectorXd u(np);
            for (Index i = 0; i < np; ++i) u(i) = N(g);
            u(0) = u(1) = 0.0;
            const VectorXd fd = (theta(modaluq::poser_merge(moved(c.setups, j, m, u, h)), m) -
                                 theta(modaluq::poser_merge(moved(c.setups, j, m, u, -h)), m)) / (2 * h);
            std::vector<PoserSetupModes> s = c.setups;
            const MatrixXd cv = cov_of(s[j], m) + u * u.transpose();
            s[j].covariance.col(m) = Eigen::Map<const VectorXd>(cv.data(), np * np);
            const PoserResult r = modaluq::poser_merge(s);
            const Index ng = 2 + 2 * kLg;
            const MatrixXd added = Eigen::Map<const MatrixXd>(r.covariance.col(m).data(), ng, ng) -
                                   Eigen::Map<const MatrixXd>(base.covariance.col(m).data(), ng, ng);
            const MatrixXd expect = fd * fd.transpose();
            CHECK((added - expect).norm() < 1e-7 * expect.norm());
            CHECK(fd.segment(2, kLg).norm() > 1e-3);  // the direction moved the shape
        }
}

TEST_CASE("poser: f and xi are linear in each setup's with the inverse-variance weights") {
    const Case c = make_case(13, 0.01);
    const PoserResult base = modaluq::poser_merge(c.setups);
    const double h = 1e-6;
    for (Index j = 0; j < kSetups; ++j)
        for (Index m = 0; m < kModes; ++m) {
            const Index np = 2 + 2 * c.setups[j].mode_shape.rows();
            double wf = 0, wx = 0;
            for (const auto& s : c.setups) {
                wf += 1 / cov_of(s, m)(0, 0);
                wx += 1 / cov_of(s, m)(1, 1);
            }
            for (Index a : {0, 1}) {
                const VectorXd u = VectorXd::Unit(np, a);
                const VectorXd fd = (theta(modaluq::poser_merge(moved(c.setups, j, m, u, h)), m) -
                                     theta(modaluq::poser_merge(moved(c.setups, j, m, u, -h)), m)) / (2 * h);
                const double w = 1 / cov_of(c.setups[j], m)(a, a) / (a == 0 ? wf : wx);
                CHECK(fd(a) == doctest::Approx(w).epsilon(1e-7));
                CHECK(fd.segment(2, 2 * kLg).norm() < 1e-9);  // the shape does not move
            }
            // and the covariance of f: sum_j w_j^2 sigma_j^2 (with the f-xi-shape correlations)
            CHECK(base.frequency_std(m) == doctest::Approx(1 / std::sqrt(wf)).epsilon(1e-12));
        }
}

TEST_CASE("poser: the reference residual's covariance equals finite differences; chi2 follows its law") {
    // 3 references (4 degrees of freedom), 2 setups; the residual e = b - alpha phi of setup 1.
    std::mt19937 g(17);
    std::normal_distribution<double> N(0.0, 1.0);
    std::vector<PoserSetupModes> s(2);
    VectorXcd psi(3 + 4);
    for (Index i = 0; i < psi.size(); ++i) psi(i) = cd(N(g), 0.3 * N(g));
    for (Index j = 0; j < 2; ++j) {
        s[j].references = {0, 1, 2};
        s[j].frequency_hz = VectorXd::Constant(1, 3.0);
        s[j].damping_ratio = VectorXd::Constant(1, 0.02);
        s[j].mode_shape.resize(5, 1);
        s[j].mode_shape.col(0) << psi.head(3), psi.segment(3 + 2 * j, 2);
        s[j].mode_shape *= cd(1.0 + j, 0.5 * j);
        const MatrixXd cv = random_spd(12, g, 1e-4);
        s[j].covariance = Eigen::Map<const VectorXd>(cv.data(), 144);
    }
    // a little inconsistency, so the residual is not zero
    s[1].mode_shape(1, 0) += cd(0.003, -0.002);
    const PoserResult r = modaluq::poser_merge(s);
    CHECK(r.reference_dof == 4);
    // var Re e_c + var Im e_c from z, against J_e Sigma J_e^T with J_e from differences
    auto residual = [](const std::vector<PoserSetupModes>& x) {
        VectorXcd b = x[0].mode_shape.col(0).head(3), phi = x[1].mode_shape.col(0).head(3);
        return VectorXcd(b - modaluq::poser_scale(phi, b) * phi);
    };
    const VectorXcd e = residual(s);
    VectorXd var = VectorXd::Zero(3);
    const double h = 1e-7;
    for (Index j = 0; j < 2; ++j) {
        MatrixXd Je(6, 12);
        for (Index a = 0; a < 12; ++a) {
            const VectorXcd d = (residual(moved(s, j, 0, VectorXd::Unit(12, a), h)) -
                                 residual(moved(s, j, 0, VectorXd::Unit(12, a), -h))) / (2 * h);
            Je.col(a) << d.real(), d.imag();
        }
        const MatrixXd se = Je * cov_of(s[j], 0) * Je.transpose();
        for (Index c = 0; c < 3; ++c) var(c) += se(c, c) + se(3 + c, 3 + c);
    }
    for (Index c = 0; c < 3; ++c)
        CHECK(r.reference_z[1](c, 0) == doctest::Approx(std::abs(e(c)) / std::sqrt(var(c))).epsilon(1e-6));
    // chi2 under the model: shapes drawn from their covariance, mean 2r - 2 = 4
    std::vector<Eigen::LLT<MatrixXd>> L;
    for (Index j = 0; j < 2; ++j) L.emplace_back(cov_of(s[j], 0) * 1e-4);  // small: first order holds
    std::vector<PoserSetupModes> t = s;
    t[1].mode_shape(1, 0) -= cd(0.003, -0.002);
    double mean = 0.0;
    Index rejected = 0;
    const int draws = 4000;
    for (int k = 0; k < draws; ++k) {
        std::vector<PoserSetupModes> x = t;
        for (Index j = 0; j < 2; ++j) {
            VectorXd z(12);
            for (Index i = 0; i < 12; ++i) z(i) = N(g);
            x = moved(x, j, 0, L[j].matrixL() * z, 1.0);
            const MatrixXd cv = cov_of(s[j], 0) * 1e-4;
            x[j].covariance = Eigen::Map<const VectorXd>(cv.data(), 144);
        }
        const PoserResult q = modaluq::poser_merge(x);
        mean += q.reference_chi2(1, 0) / draws;
        rejected += q.reference_rejected(1, 0);
    }
    CHECK(mean == doctest::Approx(4.0).epsilon(0.06));  // std of the mean: sqrt(8 / 4000) = 0.045
    CHECK(rejected <= 2);                               // level 1e-3
}

TEST_CASE("poser: a mislabelled reference is rejected in its setup only") {
    Case c = make_case(19, 0.003);
    // the consistent case passes
    const PoserResult ok = modaluq::poser_merge(c.setups);
    CHECK(!ok.reference_rejected.any());
    // setup 2's reference labels swapped
    std::swap(c.setups[2].references[0], c.setups[2].references[1]);
    const PoserResult bad = modaluq::poser_merge(c.setups);
    for (Index m = 0; m < kModes; ++m) {
        CHECK(bad.reference_rejected(2, m));
        CHECK(!bad.reference_rejected(1, m));
        CHECK(bad.reference_p_value(2, m) < 1e-10);
    }
}

TEST_CASE("poser: matching by frequency and reference MAC; a mode missing in a setup") {
    Case c = make_case(23);
    // setup 2 loses mode 1 and gains a spurious mode at 8 Hz
    PoserSetupModes& s = c.setups[2];
    s.frequency_hz(1) = 8.0;
    PoserResult r = modaluq::poser_merge(c.setups);
    CHECK(r.n_modes() == 1);  // min_setups 0: in every setup
    modaluq::PoserOptions o;
    o.min_setups = 2;
    r = modaluq::poser_merge(c.setups, o);
    REQUIRE(r.n_modes() == 2);
    CHECK(r.mode_index(2, 1) == -1);
    CHECK(std::isnan(r.mode_shape(kR + 2 * kMove, 1).real()));
    CHECK(std::isnan(r.mode_shape_std_real(kR + 2 * kMove, 1)));
    CHECK(std::isfinite(r.mode_shape_std_real(kR + kMove, 1)));
    o.min_setups = 1;
    r = modaluq::poser_merge(c.setups, o);
    CHECK(r.n_modes() == 3);
    CHECK(r.frequency_hz(2) == doctest::Approx(8.0));
    CHECK(r.basis_setup(2) == 2);
    // a frequency 4 % off still matches, 6 % off does not
    c = make_case(23);
    c.setups[1].frequency_hz(0) *= 1.04;
    CHECK(modaluq::poser_merge(c.setups).n_modes() == 2);
    c.setups[1].frequency_hz(0) *= 1.06 / 1.04;
    CHECK(modaluq::poser_merge(c.setups).n_modes() == 1);
}

TEST_CASE("poser: bad input is refused naming the setup") {
    Case c = make_case();
    auto refused = [](const std::vector<PoserSetupModes>& s, const char* part) {
        try {
            modaluq::poser_merge(s);
        } catch (const modaluq::invalid_argument& e) {
            return std::string(e.what()).find(part) != std::string::npos;
        }
        return false;
    };
    auto s = c.setups;
    s[1].references = {0};
    CHECK(refused(s, "setup 1 has 1 references"));
    s = c.setups;
    s[2].references[1] = 9;
    CHECK(refused(s, "setup 2: reference 1 is row 9"));
    s = c.setups;
    s[2].references[1] = s[2].references[0];
    CHECK(refused(s, "setup 2: row"));
    s = c.setups;
    s[1].frequency_hz(0) = std::nan("");
    CHECK(refused(s, "setup 1: mode 0"));
    s = c.setups;
    s[2].covariance.resize(0, 0);
    CHECK(refused(s, "for every setup's modes or for none"));
    s = c.setups;
    s[0].covariance.conservativeResize(10, 2);
    CHECK(refused(s, "setup 0: covariance must be"));
    s = c.setups;
    s[1].mode_shape(1, 0) = 0.0;
    s[1].mode_shape(3, 0) = 0.0;
    CHECK(refused(s, "setup 1: mode 0 has zero reference components"));
    CHECK_THROWS_AS(modaluq::poser_merge({}), modaluq::invalid_argument);
    modaluq::PoserOptions o;
    o.frequency_tolerance = 0.0;
    CHECK_THROWS_AS(modaluq::poser_merge(c.setups, o), modaluq::invalid_argument);
}

TEST_CASE("poser: without uncertainty, point estimates with equal weights") {
    Case c = make_case();
    for (auto& s : c.setups) s.covariance.resize(0, 0);
    const PoserResult r = modaluq::poser_merge(c.setups);
    REQUIRE(r.n_modes() == kModes);
    CHECK(!r.has_uncertainty);
    CHECK(r.frequency_std.size() == 0);
    CHECK(r.frequency_hz(0) == doctest::Approx((c.setups[0].frequency_hz(0) + c.setups[1].frequency_hz(0) +
                                                c.setups[2].frequency_hz(0)) / 3));
    CHECK(std::isnan(r.reference_chi2(1, 0)));
    CHECK(r.n_reference_tests == 0);
}

}  // namespace test_poser
