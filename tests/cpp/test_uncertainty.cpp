#include <doctest/doctest.h>

#include "support/uncertainty_cases.hpp"

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_uncertainty {

using namespace support;


TEST_CASE("stage dGamma: SVD-basis solve equals B_j^+ C_j and finite differences") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case c = make_case(io);
        const Index n = 6;
        const auto sub = modaluq::subspace_matrix(c.cov);
        const modaluq::Realization re(sub.H, 2, n);
        const MatrixXd TH = modaluq::propagate_to_subspace(sub, c.cov, c.cov.covariance_factor());
        const MatrixXd JG = jacobian_Gamma_H(re, sub.H, n);
        for (Index k : {0, 11}) {
            const Eigen::Map<const MatrixXd> dH(TH.col(k).data(), sub.H.rows(), sub.H.cols());
            const MatrixXd dg = modaluq::detail::gamma_perturbation(re, dH, n);
            const VectorXd explicit_dg = JG * TH.col(k);
            CHECK(rel(Eigen::Map<const VectorXd>(dg.data(), dg.size()), explicit_dg) < 1e-9);
            const double h = 1e-6 * sub.H.norm() / dH.norm();
            const MatrixXd Gp = modaluq::Realization(sub.H + h * dH, 2, n).observability();
            const MatrixXd Gm = modaluq::Realization(sub.H - h * dH, 2, n).observability();
            CHECK(rel(dg, (Gp - Gm) / (2 * h)) < 1e-6);
        }
    }
}

TEST_CASE("stages dGamma + Q fused (QStage) equal q_matrices of gamma_perturbation") {
    for (bool io : {false, true})
        for (Index past : {5, 3}) {  // H wider than tall, and taller than wide
            CAPTURE(io);
            CAPTURE(past);
            Case c = make_case(io);
            c.o.past_block_rows = past;
            c.cov = modaluq::compute_covariances(c.s.y, io ? c.s.u : MatrixXd(), c.o.layout(2, io ? 1 : 0), 20);
            const Index n = 6, l = 2;
            const auto sub = modaluq::subspace_matrix(c.cov);
            const modaluq::Realization re(sub.H, l, n);
            const MatrixXd TH = modaluq::propagate_to_subspace(sub, c.cov, c.cov.covariance_factor());
            const Index n_sigma = std::min<Index>(n + 1, re.singular_values().size());
            const modaluq::detail::QStage stage(re, n_sigma);
            for (Index k : {0, 7, 19}) {
                const Eigen::Map<const MatrixXd> dH(TH.col(k).data(), sub.H.rows(), sub.H.cols());
                VectorXd ds_ref;
                const MatrixXd dg = modaluq::detail::gamma_perturbation(re, dH, n, &ds_ref, n_sigma);
                MatrixXd qa(n, n), qb(n, n), q4(l, n), qa_f(n, n), qb_f(n, n), q4_f(l, n);
                modaluq::detail::q_matrices(re.observability(), dg, l, qa, qb, q4);
                VectorXd ds(n_sigma);
                stage.compute(dH, qa_f, qb_f, q4_f, ds);
                CHECK(rel(qa_f, qa) < 1e-10);
                CHECK(rel(qb_f, qb) < 1e-10);
                CHECK(rel(q4_f, q4) < 1e-10);
                CHECK(rel(ds, ds_ref) < 1e-12);
            }
        }
}

TEST_CASE("stage d lambda, d shape: Q-matrix path equals finite differences of the eigenstructure") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case c = make_case(io);
        const Index n = 6, l = 2;
        const auto sub = modaluq::subspace_matrix(c.cov);
        const modaluq::Realization re(sub.H, l, n);
        const MatrixXd G = re.observability();
        std::mt19937_64 rng(9);
        std::normal_distribution<double> g01;
        MatrixXd dG(G.rows(), n);
        for (Index i = 0; i < dG.size(); ++i) dG(i) = g01(rng);
        MatrixXd qa(n, n), qb(n, n), q4(l, n);
        modaluq::detail::q_matrices(G, dG, l, qa, qb, q4);
        const modaluq::StateSpace ss = re.system(n);
        modaluq::Eigenstructure eig;
        const modaluq::Modes m = modaluq::modes_from_system(ss, c.o.fs, &eig);
        const modaluq::detail::OrderContext ctx(eig, ss, re.gamma_up_r());
        Eigen::VectorXcd dl(m.n_modes());
        MatrixXcd ds(l, m.n_modes());
        modaluq::detail::eigen_perturbation(ctx, qa, qb, q4, dl, ds);

        const double h = 1e-6 * G.norm() / dG.norm();
        auto modes_at = [&](const MatrixXd& g) {
            const Index a = g.rows();
            modaluq::StateSpace s2;
            s2.A = g.topRows(a - l).colPivHouseholderQr().solve(g.bottomRows(a - l));
            s2.C = g.topRows(l);
            return modaluq::modes_from_system(s2, c.o.fs);
        };
        const modaluq::Modes mp = modes_at(G + h * dG), mm = modes_at(G - h * dG);
        for (Index i = 0; i < m.n_modes(); ++i) {
            const Index ip = nearest(mp, m.frequency_hz(i)), im = nearest(mm, m.frequency_hz(i));
            const cd fd_l = (mp.eigenvalue(ip) - mm.eigenvalue(im)) / (2 * h);
            CHECK(std::abs(dl(i) - fd_l) < 1e-6 * std::abs(fd_l) + 1e-12);
            const Index k = m.reference_component(i);
            const Eigen::VectorXcd raw = ss.C * ctx.phi.col(i);
            const Eigen::VectorXcd an = (ds.col(i) - raw / raw(k) * ds(k, i)) / raw(k);
            const Eigen::VectorXcd fd_s =
                (mp.mode_shape.col(ip) / mp.mode_shape(k, ip) - mm.mode_shape.col(im) / mm.mode_shape(k, im)) / (2 * h);
            CHECK((an - fd_s).norm() < 1e-5 * fd_s.norm() + 1e-12);
        }
    }
}

TEST_CASE("stage d lambda, d shape: the batched all-blocks path equals the per-block path") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case c = make_case(io);
        const Index N = 6, l = 2, nb = 7;
        const auto sub = modaluq::subspace_matrix(c.cov);
        const modaluq::Realization re(sub.H, l, N);
        const MatrixXd G = re.observability();
        std::mt19937_64 rng(3);
        std::normal_distribution<double> g01;
        modaluq::detail::BlockQ q(nb, N, l);
        std::vector<MatrixXd> qa(nb, MatrixXd(N, N)), qb(nb, MatrixXd(N, N)), q4(nb, MatrixXd(l, N));
        for (Index k = 0; k < nb; ++k) {
            MatrixXd dG(G.rows(), N);
            for (Index i = 0; i < dG.size(); ++i) dG(i) = g01(rng);
            modaluq::detail::q_matrices(G, dG, l, qa[k], qb[k], q4[k]);
            q.set(k, qa[k], qb[k], q4[k]);
            // The interleaved storage returns each block's matrices unchanged.
            CHECK(MatrixXd(q.qa_block(k)) == qa[k]);
            CHECK(MatrixXd(q.qb_block(k)) == qb[k]);
            CHECK(MatrixXd(q.q4_block(k)) == q4[k]);
        }
        for (Index n : {4, 6}) {  // order n uses the leading blocks of the order-N matrices
            CAPTURE(n);
            const modaluq::StateSpace ss = re.system(n);
            modaluq::Eigenstructure eig;
            const modaluq::Modes m = modaluq::modes_from_system(ss, c.o.fs, &eig);
            const modaluq::detail::OrderContext ctx(eig, ss, re.gamma_up_r());
            MatrixXcd dlam;
            std::vector<MatrixXcd> dshape;
            modaluq::detail::eigen_perturbation_blocks(ctx, q, dlam, dshape);
            REQUIRE(dlam.rows() == m.n_modes());
            for (Index k = 0; k < nb; ++k) {
                Eigen::VectorXcd dl(m.n_modes());
                MatrixXcd ds(l, m.n_modes());
                modaluq::detail::eigen_perturbation(ctx, qa[k].topLeftCorner(n, n), qb[k].topLeftCorner(n, n),
                                                    q4[k].leftCols(n), dl, ds);
                CHECK((dlam.col(k) - dl).norm() < 1e-10 * dl.norm());
                for (Index i = 0; i < m.n_modes(); ++i)
                    CHECK((dshape[i].col(k) - ds.col(i)).norm() < 1e-10 * ds.col(i).norm());
            }
        }
    }
}

TEST_CASE("stage f, xi, normalised shape: modal_perturbation equals finite differences") {
    const double fs = 50.0;
    const cd lambda = std::exp(cd(-0.02 * 2 * modaluq::detail::pi * 5.0, 2 * modaluq::detail::pi * 5.0) / fs);
    Eigen::VectorXcd raw(3);
    raw << cd(0.3, 0.1), cd(-1.2, 0.05), cd(0.7, -0.2);
    Eigen::RowVectorXcd dl(2);
    dl << cd(0.3, -0.7), cd(-0.2, 0.4);
    MatrixXcd ds(3, 2);
    ds << cd(1, 2), cd(0, 1), cd(-1, 0.5), cd(2, -1), cd(0.3, 0.3), cd(-0.5, 1);
    const MatrixXd ut = modaluq::detail::modal_perturbation(lambda, fs, raw, 1, dl, ds);
    auto th = [&](cd lam, const Eigen::VectorXcd& r) {
        const cd mu = std::log(lam) * fs;
        VectorXd t(8);
        const Eigen::VectorXcd sh = r / r(1);
        t << std::abs(mu) / (2 * modaluq::detail::pi), -mu.real() / std::abs(mu), sh.real(), sh.imag();
        return t;
    };
    for (Index k = 0; k < 2; ++k) {
        const double h = 1e-7;
        const VectorXd fd = (th(lambda + h * dl(k), raw + h * ds.col(k)) - th(lambda - h * dl(k), raw - h * ds.col(k))) / (2 * h);
        CHECK(rel(ut.col(k), fd) < 1e-6);
    }
}

TEST_CASE("end to end: the efficient multi-order path equals the explicit full path and finite differences") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        Case c = make_case(io);
        c.o.orders = {2, 4, 6};
        const auto id = modaluq::identify(c.cov, c.o);
        for (Index n : {4, 6}) {
            CAPTURE(n);
            const auto& m = id.at_order(n);
            const auto covs = explicit_covariances(c.cov, c.o.fs, n);
            REQUIRE(static_cast<Index>(covs.size()) == m.n_modes());
            const Index np = 2 + 2 * 2;
            for (Index i = 0; i < m.n_modes(); ++i) {
                const MatrixXd prod = Eigen::Map<const MatrixXd>(m.covariance.col(i).data(), np, np);
                CHECK(rel(prod, covs[i]) < 1e-10);
            }
        }
        // Finite differences of the whole pipeline along each block direction.
        const MatrixXd TR = c.cov.covariance_factor();
        auto o = c.o;
        o.uncertainty = false;
        o.orders = {6};
        const auto& m = id.at_order(6);
        for (Index i = 0; i < m.n_modes(); ++i) {
            const Index k = m.reference_component(i);
            MatrixXd U(6, TR.cols());
            for (Index b = 0; b < TR.cols(); ++b) {
                const double h = step(stack_r(c.cov), TR.col(b));
                const auto mp = modaluq::identify(perturb(c.cov, TR.col(b), h), o).at_order(6);
                const auto mm = modaluq::identify(perturb(c.cov, TR.col(b), -h), o).at_order(6);
                U.col(b) = (theta(mp, nearest(mp, m.frequency_hz(i)), k) - theta(mm, nearest(mm, m.frequency_hz(i)), k)) / (2 * h);
            }
            const MatrixXd fd = U * U.transpose();
            const MatrixXd an = Eigen::Map<const MatrixXd>(m.covariance.col(i).data(), 6, 6);
            CAPTURE(i);
            CHECK(rel(an, fd) < 1e-5);
            CHECK(std::abs(std::sqrt(fd(0, 0)) / m.frequency_std(i) - 1) < 1e-6);
        }
    }
}

TEST_CASE("standard deviations do not depend on the units of u or y") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case c = make_case(io);
        auto ident = [&](const MatrixXd& y, const MatrixXd& u) {
            return modaluq::identify(y, io ? u : MatrixXd(), c.o).at_order(6);
        };
        const auto base = ident(c.s.y, c.s.u);
        const auto u10 = ident(c.s.y, 10.0 * c.s.u);
        const auto y10 = ident(10.0 * c.s.y, c.s.u);
        CHECK(rel(u10.frequency_std, base.frequency_std) < 1e-8);
        CHECK(rel(u10.damping_std, base.damping_std) < 1e-8);
        CHECK(rel(y10.frequency_std, base.frequency_std) < 1e-8);
        CHECK(rel(y10.damping_std, base.damping_std) < 1e-8);
        CHECK(rel(y10.mode_shape_std_real, base.mode_shape_std_real) < 1e-8);
    }
}

TEST_CASE("uncertainty flags") {
    const Case c = make_case(true);
    auto o = c.o;
    o.n_blocks = 4;  // fewer than 2 + 2l + 1
    o.orders = {6};
    const auto few = modaluq::identify(c.s.y, c.s.u, o);
    CHECK(few.too_few_blocks);
    CHECK_FALSE(modaluq::identify(c.s.y, c.s.u, c.o).too_few_blocks);

    // The singular-value gap statistic z_n = (s_n - s_{n+1}) / std(s_n - s_{n+1}), with the std
    // from central differences of the SVD along every column of T_R (independent of dsigma).
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case k = make_case(io);
        auto ko = k.o;
        ko.orders = {2, 3, 4, 5, 6};
        const auto id = modaluq::identify(k.cov, ko);
        const MatrixXd TR = k.cov.covariance_factor();
        const auto sv = [](const modaluq::Covariances& cv) {
            return Eigen::BDCSVD<MatrixXd>(modaluq::subspace_matrix(cv).H).singularValues().eval();
        };
        const VectorXd s0 = sv(k.cov);
        MatrixXd ds(s0.size(), TR.cols());
        for (Index j = 0; j < TR.cols(); ++j) {
            const VectorXd d = TR.col(j);
            const double h = 1e-6 * stack_r(k.cov).norm() / d.norm();
            ds.col(j) = (sv(perturb(k.cov, d, h)) - sv(perturb(k.cov, d, -h))) / (2 * h);
        }
        for (const auto& m : id.modes) {
            CAPTURE(m.order);
            const Index n = m.order;
            const double z = (s0(n - 1) - s0(n)) / (ds.row(n - 1) - ds.row(n)).norm();
            CHECK(std::abs(m.singular_value_gap - z) < 1e-5 * z);
            // Only a cut between significant singular values (order < k*) is flagged (§5.5).
            CHECK(m.close_singular_values == (n < id.significant_singular_values && z < 3.0));
        }
    }

    auto q = o;
    q.uncertainty = false;
    const auto quiet = modaluq::identify(c.s.y, c.s.u, q);
    CHECK(quiet.at_order(6).frequency_std.size() == 0);
    CHECK(quiet.n_blocks == 0);
}

// ----------------------------------------------------------------------------- §5.5
namespace {

// 3-DOF chain (true order 6) with horizons that reach order 10: the orders above 6 keep noise
// singular vectors, which the propagation freezes.
Case make_high_case(bool io) {
    Case c;
    c.s = simulate(3, {0, 2}, 6000, 29, io, 1.0, 0.05, 20.0, false, 10.0);
    c.o.fs = c.s.fs;
    c.o.block_rows = 6;
    c.o.past_block_rows = 6;
    c.o.orders = {4, 6, 8, 10};
    c.o.n_blocks = 20;
    c.cov = modaluq::compute_covariances(c.s.y, io ? c.s.u : MatrixXd(), c.o.layout(2, io ? 1 : 0), c.o.n_blocks);
    return c;
}

}  // namespace

TEST_CASE("noise floor: delta_k and k* follow their definition (eqs. 5.10-5.12)") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case c = make_high_case(io);
        const auto sub = modaluq::subspace_matrix(c.cov);
        const modaluq::Realization re(sub.H, 2, 10);
        const MatrixXd TH = modaluq::propagate_to_subspace(sub, c.cov, c.cov.covariance_factor());
        const Index a = sub.H.rows(), b = sub.H.cols(), r = re.singular_values().size();
        // Every delta_k from explicit draws and a full SVD of each trailing block.
        const MatrixXd eps = modaluq::detail::rademacher_signs(TH.cols(), modaluq::detail::kNoiseFloorDraws);
        CHECK(eps.cwiseAbs().minCoeff() == 1.0);
        CHECK(std::abs(eps.mean()) < 0.1);
        VectorXd delta = VectorXd::Zero(r);
        for (Index t = 0; t < eps.cols(); ++t) {
            const VectorXd d = TH * eps.col(t);
            const MatrixXd D = re.U().transpose() * Eigen::Map<const MatrixXd>(d.data(), a, b) * re.V();
            for (Index k = 0; k < r; ++k)
                delta(k) += std::pow(Eigen::JacobiSVD<MatrixXd>(D.bottomRightCorner(r - k, r - k)).singularValues()(0), 2);
        }
        delta = (delta / double(eps.cols())).cwiseSqrt();
        Index k_ref = 11;
        for (Index k = 0; k < 11; ++k)
            if (re.singular_values()(k) < 1.5 * delta(k)) { k_ref = k; break; }
        const auto nf = modaluq::detail::noise_floor(re, TH, b, 1.5, 11);
        CHECK(nf.k == k_ref);
        CHECK(nf.k == 6);  // the true order of the 3-DOF chain
        for (Index k = 0; k < nf.delta.size(); ++k)
            if (!std::isnan(nf.delta(k))) CHECK(std::abs(nf.delta(k) / delta(k) - 1) < 1e-12);
        CHECK(!std::isnan(nf.delta(nf.k)));
        // delta_k does not increase with k (what the skipping relies on).
        for (Index k = 1; k < r; ++k) CHECK(delta(k) <= delta(k - 1) * (1 + 1e-12));
        // The threads do not change it.
        CHECK(modaluq::detail::noise_floor(re, TH, b, 1.5, 11, 3).delta.cwiseEqual(nf.delta).count() ==
              (nf.delta.array() == nf.delta.array()).count());
    }
}

TEST_CASE("noise floor: the power iteration of large trailing blocks is a tight lower bound") {
    std::mt19937 gen(5);
    std::normal_distribution<double> nd;
    for (Index m : {80, 150}) {
        CAPTURE(m);
        MatrixXd H(m + 10, m), dh(m + 10, m);
        for (Index i = 0; i < H.size(); ++i) H.data()[i] = nd(gen), dh.data()[i] = nd(gen);
        const Eigen::BDCSVD<MatrixXd> svd(H, Eigen::ComputeThinU | Eigen::ComputeThinV);
        const MatrixXd U = svd.matrixU(), V = svd.matrixV();
        for (Index k : {0, 5}) {
            const double est = modaluq::detail::trailing_norm(U, V, dh, k);
            const MatrixXd D = U.rightCols(m - k).transpose() * dh * V.rightCols(m - k);
            const double exact = Eigen::JacobiSVD<MatrixXd>(D).singularValues()(0);
            CHECK(est <= exact * (1 + 1e-12));
            CHECK(est >= 0.98 * exact);
        }
    }
}

TEST_CASE("frozen dGamma equals finite differences of Gamma with the noise directions held (eq. 5.13)") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case c = make_high_case(io);
        const Index n = 10, kf = 6;
        const auto sub = modaluq::subspace_matrix(c.cov);
        const modaluq::Realization re(sub.H, 2, n);
        const MatrixXd TH = modaluq::propagate_to_subspace(sub, c.cov, c.cov.covariance_factor());
        // Gamma~(H): u_j(H) sqrt s_j(H) for j < k*, u0_j sqrt s_j(H) for j >= k* (u0 nominal).
        const auto gamma_tilde = [&](const MatrixXd& H) {
            const modaluq::Realization rp(H, 2, n);
            MatrixXd g = rp.observability();
            for (Index j = kf; j < n; ++j) g.col(j) = re.U().col(j) * std::sqrt(rp.singular_values()(j));
            return g;
        };
        const MatrixXd JG = jacobian_Gamma_H(re, sub.H, n, kf);
        for (Index k : {0, 9}) {
            const Eigen::Map<const MatrixXd> dH(TH.col(k).data(), sub.H.rows(), sub.H.cols());
            const MatrixXd dg = modaluq::detail::gamma_perturbation(re, dH, n, nullptr, 0, kf);
            const double h = 1e-6 * sub.H.norm() / dH.norm();
            const MatrixXd fd = (gamma_tilde(sub.H + h * dH) - gamma_tilde(sub.H - h * dH)) / (2 * h);
            CHECK(rel(dg, fd) < 1e-6);
            CHECK(rel(dg.leftCols(kf), modaluq::detail::gamma_perturbation(re, dH, n).leftCols(kf)) < 1e-14);
            const VectorXd explicit_dg = JG * TH.col(k);
            CHECK(rel(Eigen::Map<const VectorXd>(dg.data(), dg.size()), explicit_dg) < 1e-9);
        }
    }
}

TEST_CASE("QStage's frozen Q matrices equal q_matrices of the frozen dGamma") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        const Case c = make_high_case(io);
        const Index n = 10, l = 2, kf = 6;
        const auto sub = modaluq::subspace_matrix(c.cov);
        const modaluq::Realization re(sub.H, l, n);
        const MatrixXd TH = modaluq::propagate_to_subspace(sub, c.cov, c.cov.covariance_factor());
        const modaluq::detail::QStage stage(re, n + 1, kf);
        REQUIRE(stage.freezes());
        for (Index k : {0, 13}) {
            const Eigen::Map<const MatrixXd> dH(TH.col(k).data(), sub.H.rows(), sub.H.cols());
            modaluq::detail::QBlock base, frozen;
            VectorXd ds(n + 1);
            stage.compute(dH, base, &frozen, ds);
            MatrixXd qa(n, n), qb(n, n), q4(l, n);
            modaluq::detail::q_matrices(re.observability(), modaluq::detail::gamma_perturbation(re, dH, n, nullptr, 0, kf),
                                        l, qa, qb, q4);
            CHECK(rel(frozen.qa, qa) < 1e-10);
            CHECK(rel(frozen.qb, qb) < 1e-10);
            CHECK(rel(frozen.q4, q4) < 1e-10);
            modaluq::detail::q_matrices(re.observability(), modaluq::detail::gamma_perturbation(re, dH, n), l, qa, qb, q4);
            CHECK(rel(base.qa, qa) < 1e-10);
            CHECK(rel(base.q4, q4) < 1e-10);
            // They differ only in rows and columns >= k*.
            CHECK(rel(frozen.qa.topLeftCorner(kf, kf), base.qa.topLeftCorner(kf, kf)) == 0.0);
            CHECK(rel(frozen.qb.topLeftCorner(kf, kf), base.qb.topLeftCorner(kf, kf)) == 0.0);
        }
    }
}

TEST_CASE("end to end with frozen noise: each pole equals the explicit frozen or plain path, by its flag") {
    for (bool io : {false, true}) {
        CAPTURE(io);
        Case c = make_high_case(io);
        c.o.noise_coupling_limit = 5.0;  // low enough that this small case has poles on both sides
        const auto id = modaluq::identify(c.cov, c.o);
        auto plain_o = c.o;
        plain_o.freeze_noise = false;
        const auto plain = modaluq::identify(c.cov, plain_o);
        const Index ks = id.significant_singular_values, np = 6;
        CHECK(ks == 6);
        CHECK(plain.significant_singular_values == ks);
        Index flagged = 0, frozen = 0;
        for (Index n : c.o.orders) {
            CAPTURE(n);
            const auto& m = id.at_order(n);
            const auto& mp = plain.at_order(n);
            if (n <= ks) {  // nothing frozen: bit for bit the plain propagation
                CHECK((m.covariance.array() == mp.covariance.array()).all());
                CHECK((m.noise_coupling.array() == 1.0).all());
                continue;
            }
            const auto cov_frozen = explicit_covariances(c.cov, c.o.fs, n, ks);
            const auto cov_plain = explicit_covariances(c.cov, c.o.fs, n);
            REQUIRE(static_cast<Index>(cov_frozen.size()) == m.n_modes());
            for (Index i = 0; i < m.n_modes(); ++i) {
                CAPTURE(i);
                const MatrixXd got = Eigen::Map<const MatrixXd>(m.covariance.col(i).data(), np, np);
                const double rho = std::max({1.0, std::sqrt(cov_plain[i](0, 0) / cov_frozen[i](0, 0)),
                                             std::sqrt(cov_plain[i](1, 1) / cov_frozen[i](1, 1))});
                CHECK(std::abs(m.noise_coupling(i) / rho - 1) < 1e-8);
                CHECK(m.noise_coupled(i) == (rho > c.o.noise_coupling_limit));
                CHECK(rel(got, m.noise_coupled(i) ? cov_plain[i] : cov_frozen[i]) < 1e-10);
                CHECK(rel(Eigen::Map<const MatrixXd>(mp.covariance.col(i).data(), np, np), cov_plain[i]) < 1e-10);
                flagged += m.noise_coupled(i);
                frozen += !m.noise_coupled(i) && rho > 1.0 + 1e-6;
            }
        }
        CHECK(flagged > 0);  // both branches are exercised
        CHECK(frozen > 0);
    }
}

}  // namespace test_uncertainty
