"""Self-checks of the NumPy reference oracle (tests/python/oracle.py).

Independent of the C++ core: every explicit Jacobian of the oracle is compared with
central finite differences (FD) of the stage it differentiates (docs/uq-math.md §11.2), the data
matrices with a hand-written per-sample loop, and the propagated standard deviations with
unit-invariance properties (docs/uq-math.md §4.1, §10.1).

Test systems: a 3-DOF mass-spring chain (1.42, 3.97, 5.74 Hz, 2 % modal damping), exactly
discretised (zero-order hold, augmented matrix exponential), fs = 20 Hz, white forces at
every DOF, 5 % white sensor noise.  Output-only: displacements at DOFs 1 and 3.
Input/output: accelerations at DOFs 1 and 3 (with feedthrough) and one known white force at
DOF 1 with std 10 (unknown forces std 1), so that R3 ~ 100 I and the R3^+ dR3 R3^+ term of
J_{H,R} matters.  Horizons p = 6 future, q = 8 past block rows (non-square H).
"""

import os
import sys

import numpy as np
import pytest
import scipy.linalg

sys.path.insert(0, os.path.dirname(__file__))
import oracle  # noqa: E402

FS = 20.0
P, Q = 6, 8
ORDER = 6
NB = 20
FD_REL_STEP = 1e-6
FD_TOL = 1e-5


# --------------------------------------------------------------------------------------
# simulation
# --------------------------------------------------------------------------------------
def simulate(n_samples, outputs="disp", dofs=(0, 2), input_std=None, seed=0, noise=0.05,
             discard=1000):
    """3-DOF chain ground-k-m-k-m-k-m (m = 1, k = 400), 2 % modal damping, exact ZOH
    discretisation of all nodal forces.  Returns (y, u or None, natural frequencies)."""
    rng = np.random.default_rng(seed)
    nd = 3
    M = np.eye(nd)
    k = 400.0
    K = np.array([[2 * k, -k, 0.0], [-k, 2 * k, -k], [0.0, -k, k]])
    w2, Phi = scipy.linalg.eigh(K, M)
    Phi = Phi / np.sqrt(np.diag(Phi.T @ M @ Phi))
    Cdamp = M @ Phi @ np.diag(2 * 0.02 * np.sqrt(w2)) @ Phi.T @ M
    Mi = np.linalg.inv(M)
    n = 2 * nd
    Ac = np.block([[np.zeros((nd, nd)), np.eye(nd)], [-Mi @ K, -Mi @ Cdamp]])
    Bc = np.vstack([np.zeros((nd, nd)), Mi])
    aug = np.zeros((n + nd, n + nd))
    aug[:n, :n], aug[:n, n:] = Ac, Bc
    E = scipy.linalg.expm(aug / FS)
    Ad, Bd = E[:n, :n], E[:n, n:]
    sel = np.eye(nd)[list(dofs)]
    if outputs == "disp":
        Cy, Dy = np.hstack([sel, np.zeros_like(sel)]), np.zeros((len(dofs), nd))
    else:
        Cy, Dy = sel @ np.hstack([-Mi @ K, -Mi @ Cdamp]), sel @ Mi
    total = n_samples + discard
    if input_std is None:
        F, u = rng.standard_normal((total, nd)), None
    else:
        F = 0.1 * input_std * rng.standard_normal((total, nd))
        u = input_std * rng.standard_normal((total, 1))
        F[:, 0] += u[:, 0]
    x = np.zeros(n)
    y = np.empty((total, len(dofs)))
    for t in range(total):
        y[t] = Cy @ x + Dy @ F[t]
        x = Ad @ x + Bd @ F[t]
    y = y[discard:]
    y = y + noise * y.std(axis=0) * rng.standard_normal(y.shape)
    return y, (None if u is None else u[discard:]), np.sqrt(w2) / (2 * np.pi)


class Case:
    """Nominal quantities of the pipeline for one data set."""

    def __init__(self, y, u, p=P, q=Q, n=ORDER, n_blocks=NB):
        self.y, self.u, self.p, self.q, self.n = y, u, p, q, n
        self.l = y.shape[1]
        self.cov = oracle.covariances(y, u, p, q, n_blocks)
        c = self.cov
        self.R = (c["R1"], c["R2"], c["R3"], c["R4"])
        self.a, self.b = c["R1"].shape
        self.pm = 0 if c["R3"] is None else c["R3"].shape[0]
        self.r = oracle._stack_r(c)
        self.H = oracle.subspace_matrix(*self.R)
        self.G = oracle.gamma(self.H, n)
        self.A, self.C = oracle.system_matrices(self.G, self.l)
        self.md = oracle.modes(self.A, self.C, FS)


@pytest.fixture(scope="module")
def oo():
    y, u, _ = simulate(6000, outputs="disp", seed=1)
    return Case(y, u)


@pytest.fixture(scope="module")
def io():
    y, u, _ = simulate(6000, outputs="acc", input_std=10.0, seed=2)
    return Case(y, u)


@pytest.fixture(params=["oo", "io"])
def case(request):
    return request.getfixturevalue(request.param)


# --------------------------------------------------------------------------------------
# FD helpers
# --------------------------------------------------------------------------------------
def fd_jacobian(f, x, steps):
    """Central differences of a vector function f at x, per-coordinate steps."""
    x = np.asarray(x, dtype=np.float64)
    cols = []
    for i in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[i] += steps[i]
        xm[i] -= steps[i]
        cols.append((f(xp) - f(xm)) / (2 * steps[i]))
    return np.column_stack(cols)


def rel_err(J, Jfd):
    return np.linalg.norm(J - Jfd) / np.linalg.norm(J)


def r_steps(case):
    """Relative step per coordinate of r = [vec R1; vec R2; vec R3; vec R4]: 1e-6 times
    the largest modulus of the R matrix the coordinate belongs to."""
    sizes = [case.a * case.b]
    mats = [case.R[0]]
    if case.pm:
        sizes += [case.a * case.pm, case.pm ** 2, case.b * case.pm]
        mats += list(case.R[1:])
    return np.concatenate([np.full(s, FD_REL_STEP * np.abs(M).max())
                           for s, M in zip(sizes, mats)])


def theta_matched(A, C, nominal):
    """theta = [f, xi, Re phi~, Im phi~] for every nominal mode, taken from the perturbed
    (A, C): modes matched by frequency, reference component k kept at the nominal one."""
    md = oracle.modes(A, C, FS)
    out = []
    for f0, k in zip(nominal["frequency_hz"], nominal["ref_index"]):
        j = np.argmin(np.abs(md["frequency_hz"] - f0))
        shape = md["mode_shape_raw"][:, j] / md["mode_shape_raw"][k, j]
        out.append(np.concatenate([[md["frequency_hz"][j], md["damping_ratio"][j]],
                                   shape.real, shape.imag]))
    return np.concatenate(out)


def theta_group_errors(J, Jfd, l):
    """Relative Frobenius errors per group of theta rows: f, xi, Re phi~, Im phi~."""
    d = 2 + 2 * l
    nm = J.shape[0] // d
    groups = {"f": [0], "xi": [1], "re": list(range(2, 2 + l)), "im": list(range(2 + l, d))}
    return {g: rel_err(J[np.add.outer(np.arange(nm) * d, rows).ravel()],
                       Jfd[np.add.outer(np.arange(nm) * d, rows).ravel()])
            for g, rows in groups.items()}


def pipeline_theta(case, r):
    """End-to-end theta(R): R -> H -> SVD -> Gamma -> (A, C) -> modal parameters."""
    R = oracle._unstack_r(r, case.a, case.b, case.pm)
    H = oracle.subspace_matrix(*R)
    G = oracle.gamma(H, case.n)
    A, C = oracle.system_matrices(G, case.l)
    return theta_matched(A, C, case.md)


# --------------------------------------------------------------------------------------
# data matrices and covariances
# --------------------------------------------------------------------------------------
def test_data_matrices_match_per_sample_loop():
    rng = np.random.default_rng(0)
    n_samples, l, m, p, q = 17, 3, 2, 3, 4
    refs = [2, 0]
    y = rng.standard_normal((n_samples, l)) + 5.0
    u = rng.standard_normal((n_samples, m)) - 3.0
    Yp, Ym, Up = oracle.data_matrices(y, u, p, q, references=refs)
    N = n_samples - p - q + 1
    assert Yp.shape == (p * l, N) and Ym.shape == (q * len(refs), N) and Up.shape == (p * m, N)
    ym, um = y.mean(axis=0), u.mean(axis=0)
    for c in range(N):
        for i in range(p):
            for ch in range(l):
                assert Yp[i * l + ch, c] == pytest.approx(y[q + i + c, ch] - ym[ch], abs=1e-14)
            for ch in range(m):
                assert Up[i * m + ch, c] == pytest.approx(u[q + i + c, ch] - um[ch], abs=1e-14)
        for j in range(q):
            for t, ch in enumerate(refs):
                assert Ym[j * len(refs) + t, c] == pytest.approx(y[j + c, ch] - ym[ch], abs=1e-14)
    # demean=False keeps the raw samples; 1-D input is one channel; u=None gives no U+
    Yp0, Ym0, Up0 = oracle.data_matrices(y[:, 1], None, p, q, demean=False)
    assert Up0 is None
    assert np.array_equal(Yp0[0], y[q:q + N, 1]) and np.array_equal(Ym0[-1], y[q - 1:q - 1 + N, 1])


def test_R1_block_toeplitz_lags_and_no_lag_zero():
    rng = np.random.default_rng(1)
    n_samples, l, p, q = 40, 2, 3, 4
    y = rng.standard_normal((n_samples, l))
    c = oracle.covariances(y, None, p, q, n_blocks=2)
    yc = y - y.mean(axis=0)
    N = c["N"]
    assert N == n_samples - p - q + 1
    for i in range(p):
        for j in range(q):
            block = sum(np.outer(yc[q + i + k], yc[j + k]) for k in range(N)) / N
            np.testing.assert_allclose(c["R1"][i * l:(i + 1) * l, j * l:(j + 1) * l], block,
                                       rtol=1e-13, atol=1e-15)
            assert q + i - j >= 1   # lag of block (i, j); lag 0 never enters


def test_R_equals_block_mean_and_T_R_layout():
    rng = np.random.default_rng(2)
    p, q, nb, Nb = 3, 2, 5, 11
    n_samples = nb * Nb + p + q - 1              # N = nb * Nb exactly
    y = rng.standard_normal((n_samples, 2))
    u = 3.0 * rng.standard_normal((n_samples, 1))
    c = oracle.covariances(y, u, p, q, nb)
    assert c["N"] == nb * Nb and c["Nb"] == Nb and c["n_blocks"] == nb
    for key in ("R1", "R2", "R3", "R4"):
        mean = np.mean([B[key] for B in c["blocks"]], axis=0)
        np.testing.assert_allclose(c[key], mean, rtol=1e-12, atol=1e-14)
    # block k is the product restricted to columns [k Nb, (k+1) Nb), divided by Nb
    Yp, Ym, Up = oracle.data_matrices(y, u, p, q)
    k = 3
    cols = slice(k * Nb, (k + 1) * Nb)
    np.testing.assert_allclose(c["blocks"][k]["R4"], Ym[:, cols] @ Up[:, cols].T / Nb, rtol=1e-13)
    # T_R columns: column-major vec, stacked R1..R4, centred on the block mean
    rk = np.column_stack([np.concatenate([B[key].flatten(order="F") for key in ("R1", "R2", "R3", "R4")])
                          for B in c["blocks"]])
    T = (rk - rk.mean(axis=1, keepdims=True)) / np.sqrt(nb * (nb - 1))
    np.testing.assert_allclose(c["T_R"], T, rtol=1e-12, atol=1e-15)
    a, b, pm = 3 * 2, 2 * 2, 3
    assert c["T_R"].shape == (a * b + a * pm + pm * pm + b * pm, nb)
    # trailing columns (N not a multiple of nb) enter the point estimate only
    c2 = oracle.covariances(np.vstack([y, y[:3]]), None, p, q, nb)
    assert c2["Nb"] == Nb and c2["N"] == nb * Nb + 3 and c2["R2"] is None
    assert c2["T_R"].shape == (a * b, nb)


def test_commutation_matrix():
    X = np.arange(12.0).reshape(3, 4)
    P = oracle.commutation_matrix(3, 4)
    np.testing.assert_array_equal(P @ oracle.vec(X), oracle.vec(X.T))


# --------------------------------------------------------------------------------------
# Jacobians vs central finite differences
# --------------------------------------------------------------------------------------
def test_jacobian_H_R_output_only_is_identity(oo):
    np.testing.assert_array_equal(oracle.jacobian_H_R(oo.R[0]), np.eye(oo.a * oo.b))


def test_jacobian_H_R_fd_io(io):
    J = oracle.jacobian_H_R(*io.R)
    f = lambda r: oracle.vec(oracle.subspace_matrix(*oracle._unstack_r(r, io.a, io.b, io.pm)))
    Jfd = fd_jacobian(f, io.r, r_steps(io))
    assert rel_err(J, Jfd) < FD_TOL
    # the R3 block alone (where the seed text's R2 R3^+ dR3 R4^T term would be wrong)
    h = io.a * io.b
    s3 = slice(h + io.a * io.pm, h + io.a * io.pm + io.pm ** 2)
    assert rel_err(J[:, s3], Jfd[:, s3]) < FD_TOL
    # this test can detect that bug: with input std 10 the wrong term is far off
    R1, R2, R3, R4 = io.R
    R3p = np.linalg.inv(R3)
    wrong = np.kron(R4, R2 @ R3p)        # vec(G dR3 R4^T) = (R4 kron G) vec dR3
    assert rel_err(wrong, Jfd[:, s3]) > 0.5


def test_jacobian_Gamma_H_fd(case):
    J = oracle.jacobian_Gamma_H(case.H, case.n)
    f = lambda x: oracle.vec(oracle.gamma(oracle.unvec(x, case.a, case.b), case.n))
    x = oracle.vec(case.H)
    Jfd = fd_jacobian(f, x, np.full(x.size, FD_REL_STEP * np.abs(x).max()))
    assert rel_err(J, Jfd) < FD_TOL
    # multi-order reuse: J_{Gamma_n,H} is the leading a*n rows of J_{Gamma_nmax,H}
    np.testing.assert_array_equal(oracle.jacobian_Gamma_H(case.H, 4), J[:4 * case.a])


def test_jacobian_AC_Gamma_fd(case):
    J = oracle.jacobian_AC_Gamma(case.G, case.l)
    n = case.n

    def f(x):
        A, C = oracle.system_matrices(oracle.unvec(x, case.a, n), case.l)
        return np.concatenate([oracle.vec(A), oracle.vec(C)])

    x = oracle.vec(case.G)
    Jfd = fd_jacobian(f, x, np.full(x.size, FD_REL_STEP * np.abs(x).max()))
    assert rel_err(J[:n * n], Jfd[:n * n]) < FD_TOL          # J_{A,Gamma}
    assert rel_err(J, Jfd) < FD_TOL
    # the least-squares residual term is needed on noisy data (docs/uq-math.md §6): without it
    # J_{A,Gamma} misses FD by far more than the FD truncation error
    l, a = case.l, case.a
    up = case.G[:-l]
    W = np.linalg.inv(up.T @ up)
    S1 = np.eye(a)[:a - l]
    S2 = np.eye(a)[l:]
    no_residual = np.kron(np.eye(n), W @ up.T) @ (np.kron(np.eye(n), S2) - np.kron(case.A.T, S1))
    assert rel_err(no_residual, Jfd[:n * n]) > 10 * FD_TOL


def test_jacobian_theta_AC_fd(case):
    n, l = case.n, case.l
    Js = oracle.jacobian_theta_AC(case.A, case.C, FS)
    assert len(Js) == len(case.md["frequency_hz"]) == 3
    J = np.vstack(Js)
    f = lambda x: theta_matched(oracle.unvec(x[:n * n], n, n), oracle.unvec(x[n * n:], l, n), case.md)
    x = np.concatenate([oracle.vec(case.A), oracle.vec(case.C)])
    steps = np.concatenate([np.full(n * n, FD_REL_STEP * np.abs(case.A).max()),
                            np.full(l * n, FD_REL_STEP * np.abs(case.C).max())])
    Jfd = fd_jacobian(f, x, steps)
    assert rel_err(J, Jfd) < FD_TOL
    for g, e in theta_group_errors(J, Jfd, l).items():
        assert e < FD_TOL, g
    # the reference component has zero sensitivity
    d = 2 + 2 * l
    for i, k in enumerate(case.md["ref_index"]):
        assert not np.any(J[i * d + 2 + k]) and not np.any(J[i * d + 2 + l + k])


def _theta_R(case):
    J_HR = oracle.jacobian_H_R(*case.R)
    J_GH = oracle.jacobian_Gamma_H(case.H, case.n)
    J_AC = oracle.jacobian_AC_Gamma(case.G, case.l)
    J_th = np.vstack(oracle.jacobian_theta_AC(case.A, case.C, FS))
    return J_th @ J_AC @ J_GH @ J_HR


def test_end_to_end_jacobian_theta_R_fd(case):
    J = _theta_R(case)
    Jfd = fd_jacobian(lambda r: pipeline_theta(case, r), case.r, r_steps(case))
    assert rel_err(J, Jfd) < FD_TOL
    for g, e in theta_group_errors(J, Jfd, case.l).items():
        assert e < FD_TOL, g
    # identify() wires the same chain: its std equal the FD-Jacobian propagation of T_R
    res = oracle.identify(case.y, case.u, fs=FS, block_rows=case.p, past_block_rows=case.q,
                          orders=case.n, n_blocks=NB)[case.n]
    std_fd = np.sqrt(np.sum((Jfd @ case.cov["T_R"]) ** 2, axis=1)).reshape(-1, 2 + 2 * case.l)
    np.testing.assert_allclose(res["frequency_std"], std_fd[:, 0], rtol=1e-4)
    np.testing.assert_allclose(res["damping_std"], std_fd[:, 1], rtol=1e-4)
    l = case.l
    tiny = 1e-6 * std_fd[:, 2:].max()      # FD leaves ~1e-11 on the (zero) reference component
    np.testing.assert_allclose(res["mode_shape_std_real"], std_fd[:, 2:2 + l].T, rtol=1e-4, atol=tiny)
    np.testing.assert_allclose(res["mode_shape_std_imag"], std_fd[:, 2 + l:].T, rtol=1e-4, atol=tiny)


# --------------------------------------------------------------------------------------
# identify(): structure, explicit vs factor path, invariances, order limits
# --------------------------------------------------------------------------------------
def _run(y, u, orders=(4, ORDER), **kw):
    return oracle.identify(y, u, fs=FS, block_rows=P, past_block_rows=Q, orders=list(orders),
                           n_blocks=NB, **kw)


@pytest.fixture(scope="module")
def results(oo, io):
    return {"oo": _run(oo.y, oo.u), "io": _run(io.y, io.u)}


@pytest.mark.parametrize("name", ["oo", "io"])
def test_identify_structure_and_nominal(name, results, request):
    c = request.getfixturevalue(name)
    res = results[name][ORDER]
    l = c.l
    fn = simulate(10, seed=0)[2]
    nm = len(res["frequency_hz"])
    assert nm == 3
    np.testing.assert_allclose(res["frequency_hz"], fn, rtol=0.02)
    assert np.all(np.diff(res["frequency_hz"]) > 0)
    assert res["mode_shape"].shape == (l, nm) and res["mode_shape"].dtype == complex
    assert res["covariance"].shape == (nm, 2 + 2 * l, 2 + 2 * l)
    for key in ("frequency_std", "damping_std"):
        assert res[key].shape == (nm,) and np.all(res[key] > 0)
    for i, k in enumerate(res["ref_index"]):
        assert res["mode_shape"][k, i] == 1.0
        assert np.all(np.abs(res["mode_shape"][:, i]) <= 1.0)
        assert res["mode_shape_std_real"][k, i] == 0.0 and res["mode_shape_std_imag"][k, i] == 0.0
    np.testing.assert_allclose(res["frequency_std"], np.sqrt(res["covariance"][:, 0, 0]))
    np.testing.assert_array_equal(res["eigenvalues"], c.md["eigenvalues"])
    # uncertainty=False gives the same point estimates and no std
    plain = oracle.identify(c.y, c.u, fs=FS, block_rows=P, past_block_rows=Q, orders=ORDER,
                            n_blocks=NB, uncertainty=False)[ORDER]
    assert "frequency_std" not in plain
    np.testing.assert_array_equal(plain["frequency_hz"], res["frequency_hz"])


@pytest.mark.parametrize("name", ["oo", "io"])
def test_explicit_and_factor_paths_agree(name, results, request):
    c = request.getfixturevalue(name)
    fac = oracle.identify_factor(c.y, c.u, fs=FS, block_rows=P, past_block_rows=Q,
                                 orders=[4, ORDER], n_blocks=NB)
    for n in (4, ORDER):
        ex = results[name][n]
        scale = np.abs(ex["covariance"]).max()
        np.testing.assert_allclose(fac[n]["covariance"], ex["covariance"], rtol=0, atol=1e-8 * scale)
        np.testing.assert_allclose(fac[n]["frequency_std"], ex["frequency_std"], rtol=1e-7)
        np.testing.assert_allclose(fac[n]["damping_std"], ex["damping_std"], rtol=1e-7)


def test_sigma_invariant_to_input_units(io, results):
    ref = results["io"]
    scaled = _run(io.y, 10.0 * io.u)
    for n in ref:
        np.testing.assert_allclose(scaled[n]["frequency_hz"], ref[n]["frequency_hz"], rtol=1e-10)
        np.testing.assert_allclose(scaled[n]["frequency_std"], ref[n]["frequency_std"], rtol=1e-6)
        np.testing.assert_allclose(scaled[n]["damping_std"], ref[n]["damping_std"], rtol=1e-6)


@pytest.mark.parametrize("name", ["oo", "io"])
def test_sigma_invariant_to_output_units(name, results, request):
    c = request.getfixturevalue(name)
    ref = results[name]
    scaled = _run(10.0 * c.y, c.u)
    for n in ref:
        np.testing.assert_allclose(scaled[n]["frequency_std"], ref[n]["frequency_std"], rtol=1e-6)
        np.testing.assert_allclose(scaled[n]["damping_std"], ref[n]["damping_std"], rtol=1e-6)
        np.testing.assert_allclose(scaled[n]["mode_shape_std_real"], ref[n]["mode_shape_std_real"],
                                   rtol=1e-6, atol=1e-12)


def test_orders_share_one_svd(oo, results):
    # the order-4 model uses the leading 4 columns of the same Gamma
    G4 = oracle.gamma(oo.H, 4)
    np.testing.assert_array_equal(G4, oo.G[:, :4])
    A4, C4 = oracle.system_matrices(G4, oo.l)
    md = oracle.modes(A4, C4, FS)
    np.testing.assert_allclose(results["oo"][4]["frequency_hz"], md["frequency_hz"], rtol=1e-12)


def test_order_limits(oo):
    l = oo.l
    limit = min((P - 1) * l, Q * l)              # 10
    res = oracle.identify(oo.y, None, fs=FS, block_rows=P, past_block_rows=Q, orders=limit,
                          n_blocks=NB, uncertainty=False)
    assert limit in res
    with pytest.raises(ValueError):
        oracle.identify(oo.y, None, fs=FS, block_rows=P, past_block_rows=Q, orders=[4, limit + 1],
                        n_blocks=NB)
    # with one reference the past limit q*r binds: q*r = 8 < (p-1)*l = 10
    with pytest.raises(ValueError):
        oracle.identify(oo.y, None, fs=FS, block_rows=P, past_block_rows=Q, orders=9,
                        n_blocks=NB, references=[0])
    res = oracle.identify(oo.y, None, fs=FS, block_rows=P, past_block_rows=Q, orders=ORDER,
                          n_blocks=NB, references=[0])
    assert len(res[ORDER]["frequency_hz"]) == 3


def test_svd_sign_convention(case):
    U, s, Vt = oracle.svd_sorted(case.H)
    assert np.all(np.diff(s) <= 0)
    np.testing.assert_allclose(U * s @ Vt, case.H, atol=1e-12 * s[0])
    for j in range(len(s)):
        assert U[np.argmax(np.abs(U[:, j])), j] > 0
