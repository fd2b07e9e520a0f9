"""Checks of the multi-setup NumPy reference (tests/python/oracle_multisetup.py; uq-math §13).

Every new sensitivity is compared with central finite differences (FD) of the map it
differentiates, along the columns of each setup's block factor (the directions the
covariance is made of): the merge (13.5)-(13.6), the global (A, C) and modes, PoSER's
rescaling (13.10), and end to end from each setup's R1..R4 (input/output, so that J_{H,R}
is in the chain).  The building blocks reused from the single-setup theory are checked against
the explicit oracle (tests/python/oracle.py), and a one-setup "campaign" against
``oracle.identify``.

Data: the deck campaign of ``modaluq.simulate.campaign`` shortened to three setups of 60-80 s
(fs = 25 Hz), p = q = 8, order 12 (the true order), n_b = 10 blocks per setup.
"""

import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import oracle  # noqa: E402
import oracle_multisetup as om  # noqa: E402
from modaluq.simulate.campaign import DEFAULT_ROVING, simulate_campaign  # noqa: E402

P = 8
ORDER = 12
NB = 10
STEP = 1e-6
TOL = 1e-5


def _campaign(io, seed=5):
    kw = {"input_dofs": ("L5",), "input_std": 3.0, "unknown_input_std": 0.5} if io else {}
    return simulate_campaign(seed, durations=(60.0, 80.0, 70.0), roving=DEFAULT_ROVING[:3], **kw)


def _prepare(camp, io):
    return om.prepare_setups([(s.y, s.u if io else None) for s in camp.setups], P, P, NB,
                             [s.references for s in camp.setups])


@pytest.fixture(scope="module", params=["oo", "io"])
def case(request):
    io = request.param == "io"
    c = _campaign(io)
    return c, _prepare(c, io), io


def _rel(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(np.asarray(b))


def _fd(fun, x, d):
    eps = STEP * np.linalg.norm(x) / np.linalg.norm(d)
    return (fun(x + eps * d) - fun(x - eps * d)) / (2 * eps)


def _with_H(setups, j, H):
    out = [dict(s) for s in setups]
    out[j]["H"] = H
    return out


# ----------------------------------------------------------------------- reused pieces
def test_setup_covariances_equal_the_explicit_oracle():
    c = _campaign(True)
    s = c.setups[1]
    a = om.setup_covariances(s.y, s.u, 5, 4, 7, s.references)
    b = oracle.covariances(s.y, s.u, 5, 4, 7, references=list(s.references))
    for k in ("R1", "R2", "R3", "R4", "T_R"):
        assert _rel(a[k], b[k]) < 1e-12, k


def test_T_H_equals_the_kronecker_J_HR(case):
    c, setups, io = case
    s = c.setups[2]
    cov = om.setup_covariances(s.y, s.u if io else None, P, P, NB, s.references)
    H, T_H = om.setup_subspace(cov)
    J = oracle.jacobian_H_R(cov["R1"], cov["R2"], cov["R3"], cov["R4"])
    assert _rel(H, oracle.subspace_matrix(cov["R1"], cov["R2"], cov["R3"], cov["R4"])) < 1e-14
    assert _rel(T_H, J @ cov["T_R"]) < 1e-12


def test_dGamma_equals_the_explicit_J_Gamma_H_and_fd(case):
    _, setups, _ = case
    st = setups[1]
    H, T_H = st["H"], st["T_H"]
    a = H.shape[0]
    _, dG = om.gamma_factor(H, T_H, ORDER)
    J = oracle.jacobian_Gamma_H(H, ORDER)
    ref = (J @ T_H).reshape(ORDER, a, -1).transpose(1, 0, 2)
    assert _rel(dG, ref) < 1e-9
    fd = np.stack([_fd(lambda h: oracle.gamma(h.reshape(H.shape, order="F"), ORDER),
                       oracle.vec(H), T_H[:, k]) for k in range(3)], axis=2)
    assert _rel(dG[:, :, :3], fd) < TOL


# ------------------------------------------------------------------------ the merge
@pytest.mark.parametrize("pool", [False, True])
def test_merge_perturbation_equals_fd_for_every_setup(case, pool):
    _, setups, _ = case
    camp = om.Campaign(setups, P, ORDER, pool_references=pool)
    D = om.merge_gamma_perturbation(camp, ORDER)

    for j, st in enumerate(setups):
        def merged(hvec, j=j):
            H = hvec.reshape(st["H"].shape, order="F")
            return om.merge_gamma(om.Campaign(_with_H(setups, j, H), P, ORDER, uncertainty=False,
                                              pool_references=pool), ORDER)
        fd = np.stack([_fd(merged, oracle.vec(st["H"]), st["T_H"][:, k]) for k in range(NB)], axis=2)
        assert _rel(D[j], fd) < TOL, j


def test_merge_without_the_residual_term_misses_fd(case):
    """The least-squares residual E_j of the normalisation (13.5) matters on noisy data."""
    _, setups, _ = case
    camp = om.Campaign(setups, P, ORDER)
    j = 2
    st = camp.setups[j]
    B = camp.setups[0]["Gamma"][camp.setups[0]["rows_ref"], :ORDER]
    X = st["Gamma"][st["rows_ref"], :ORDER]
    T = np.linalg.lstsq(X, B, rcond=None)[0]
    assert np.linalg.norm(B - X @ T) > 1e-3 * np.linalg.norm(B)
    D = om.merge_gamma_perturbation(camp, ORDER)[j]
    dX = st["dGamma"][st["rows_ref"], :ORDER]
    Xp = np.linalg.pinv(X)
    short = np.einsum("am,mnk->ank", st["Gamma"][st["rows_mov"], :ORDER],
                      -np.einsum("nr,rmk,ml->nlk", Xp, dX, T))
    short += np.einsum("amk,mn->ank", st["dGamma"][st["rows_mov"], :ORDER], T)
    assert _rel(short, D[camp.setups[j]["grows_mov"]]) > 1e-3


def test_system_and_modal_stage_equal_fd_and_the_explicit_jacobians(case):
    _, setups, _ = case
    camp = om.Campaign(setups, P, ORDER)
    G = om.merge_gamma(camp, ORDER)
    dG = np.concatenate(om.merge_gamma_perturbation(camp, ORDER), axis=2)[:, :, :4]
    l = camp.l_g
    A, C, dA, dC = om.system_perturbation(G, dG, l)
    fdA = np.stack([_fd(lambda g: oracle.system_matrices(g.reshape(G.shape, order="F"), l)[0].ravel(order="F"),
                        oracle.vec(G), oracle.vec(dG[:, :, k])) for k in range(4)], axis=1)
    assert _rel(dA.reshape(-1, 4, order="F"), fdA) < TOL
    md, fac = om.modal_perturbation(A, C, dA, dC, 25.0)
    J_AC = oracle.jacobian_AC_Gamma(G, l)
    J_th = oracle.jacobian_theta_AC(A, C, 25.0, ref_index=md["ref_index"])
    dvec = np.stack([oracle.vec(dG[:, :, k]) for k in range(4)], axis=1)
    for i, J in enumerate(J_th):
        assert _rel(fac[i], J @ J_AC @ dvec) < 1e-8, i


@pytest.mark.parametrize("pool", [False, True])
def test_end_to_end_from_each_setups_covariances_equals_fd(case, pool):
    """θ = [f, ξ, Re ϕ̃, Im ϕ̃] of every mode from the R's of each setup, along T_R."""
    c, setups, io = case
    res, camp = om.identify_modular(setups, fs=c.fs, p=P, orders=[ORDER], pool_references=pool)
    r0 = res[ORDER]
    k = r0["ref_index"]
    covs = [om.setup_covariances(s.y, s.u if io else None, P, P, NB, s.references) for s in c.setups]
    col = 0
    for j, cov in enumerate(covs):
        a, b = cov["R1"].shape
        pm = 0 if cov["R3"] is None else cov["R3"].shape[0]

        def theta(rvec, j=j, a=a, b=b, pm=pm):
            R = oracle._unstack_r(rvec, a, b, pm)
            st = _with_H(setups, j, oracle.subspace_matrix(*R))
            out, _ = om.identify_modular(st, fs=c.fs, p=P, orders=[ORDER], ref_index=k, uncertainty=False,
                                         pool_references=pool)
            o = out[ORDER]
            assert len(o["frequency_hz"]) == len(k)
            return np.vstack([o["frequency_hz"], o["damping_ratio"], o["mode_shape"].real,
                              o["mode_shape"].imag]).T
        rvec = np.concatenate([oracle.vec(X) for X in (cov["R1"], cov["R2"], cov["R3"], cov["R4"])
                               if X is not None])
        for kk in range(3):
            fd = _fd(theta, rvec, cov["T_R"][:, kk])
            an = r0["factor"][:, :, col + kk]
            assert _rel(an, fd) < TOL, (j, kk)
        col += cov["T_R"].shape[1]
    assert col == r0["factor"].shape[2]


def test_one_setup_equals_the_single_setup_oracle(case):
    c, _, io = case
    s = c.setups[0]
    st = om.prepare_setups([(s.y, s.u if io else None)], P, P, NB, [s.references])
    res, camp = om.identify_modular(st, fs=c.fs, p=P, orders=[8, ORDER])
    ref = oracle.identify(s.y, s.u if io else None, fs=c.fs, block_rows=P, orders=[8, ORDER],
                          n_blocks=NB, references=list(s.references), freeze_noise=False)
    perm = [ch for _, ch in camp.dofs]                 # global row g is channel perm[g]
    for n in (8, ORDER):
        a, b = res[n], ref[n]
        assert np.allclose(a["frequency_hz"], b["frequency_hz"], rtol=1e-10)
        assert np.allclose(a["damping_ratio"], b["damping_ratio"], rtol=1e-8)
        assert np.allclose(a["mode_shape"], b["mode_shape"][perm], rtol=1e-8, atol=1e-10)
        assert np.allclose(a["frequency_std"], b["frequency_std"], rtol=1e-7)
        assert np.allclose(a["damping_std"], b["damping_std"], rtol=1e-7)
        assert np.allclose(a["mode_shape_std_real"], b["mode_shape_std_real"][perm], rtol=1e-6, atol=1e-12)


def test_merge_is_invariant_to_each_setups_units(case):
    """Scaling all channels of one setup (H → c²H) changes nothing in the merged result."""
    c, setups, io = case
    res, _ = om.identify_modular(setups, fs=c.fs, p=P, orders=[ORDER])
    scaled = [dict(s) for s in setups]
    scaled[1] = dict(setups[1], H=9.0 * setups[1]["H"], T_H=9.0 * setups[1]["T_H"])
    res2, _ = om.identify_modular(scaled, fs=c.fs, p=P, orders=[ORDER])
    for key in ("frequency_hz", "mode_shape", "frequency_std", "damping_std", "mode_shape_std_real"):
        assert np.allclose(res[ORDER][key], res2[ORDER][key], rtol=1e-8, atol=1e-12), key


@pytest.mark.parametrize("pool", [False, True])
def test_merge_recovers_the_true_modes(case, pool):
    c, setups, _ = case
    res, camp = om.identify_modular(setups, fs=c.fs, p=P, orders=[ORDER], pool_references=pool)
    r = res[ORDER]
    assert np.allclose(r["frequency_hz"], c.frequency_hz, rtol=0.02)
    names = [c.setups[j].channels[ch] for j, ch in camp.dofs]
    Phi = c.mode_shape[[c.dofs.index(n) for n in names]]
    mac = np.abs(np.sum(r["mode_shape"].conj() * Phi, axis=0)) ** 2 / (
        np.sum(np.abs(r["mode_shape"]) ** 2, axis=0) * np.sum(Phi ** 2, axis=0))
    assert mac.min() > 0.98


# ------------------------------------------------------------------------------ PoSER
def test_poser_rescaling_equals_fd():
    rng = np.random.default_rng(2)
    sizes = [6, 5, 6]
    r = 2
    shapes = [rng.standard_normal(s) + 1j * rng.standard_normal(s) for s in sizes]
    refs_of = [np.arange(r)] * 3
    mov_of = [r + np.arange(s - r) for s in sizes]
    psi, _, k = om.rescale_shapes(shapes, None, refs_of, mov_of)
    for j, s in enumerate(sizes):
        for part in (1.0, 1j):                           # real and imaginary directions
            d = part * rng.standard_normal(s)
            ds = [np.zeros((n, 1), dtype=complex) for n in sizes]
            ds[j][:, 0] = d
            _, D, _ = om.rescale_shapes(shapes, ds, refs_of, mov_of, k)

            def fun(x, j=j):
                sh = list(shapes)
                sh[j] = shapes[j] + x[0] * d
                return om.rescale_shapes(sh, None, refs_of, mov_of, k)[0]
            h = 1e-6
            fd = (fun([h]) - fun([-h])) / (2 * h)
            assert _rel(D[j][:, 0], fd) < 1e-7, (j, part)
    # the result does not depend on each setup's own scaling of its shape
    sh = [shapes[0], (2 - 3j) * shapes[1], shapes[2]]
    assert np.allclose(om.rescale_shapes(sh, None, refs_of, mov_of, k)[0], psi)


def test_poser_inverse_variance_sigma(case):
    c, setups, _ = case
    res = om.identify_poser(setups, fs=c.fs, p=P, order=ORDER, targets=c.frequency_hz)
    singles = [om.identify_modular([s], fs=c.fs, p=P, orders=[ORDER])[0][ORDER] for s in setups]
    for t, f0 in enumerate(c.frequency_hz):
        sig = []
        for r in singles:
            i = np.argmin(np.abs(r["frequency_hz"] - f0))
            sig.append(r["frequency_std"][i])
        assert res["frequency_std"][t] == pytest.approx(np.sum(np.array(sig) ** -2.0) ** -0.5, rel=1e-10)
    assert np.all(np.isfinite(res["frequency_hz"]))
