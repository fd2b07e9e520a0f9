"""The C++ multi-setup merge (cpp/include/modaluq/multisetup.hpp, ``_core.identify_setups``)
equals the NumPy reference ``oracle_multisetup.identify_modular`` (docs/uq-math.md §13) on the
simulated deck campaign: f, ξ, the global shapes, their σ and covariance, output-only and
input/output, at every order of a small diagram, with each setup's noise columns frozen (the
default, §13.4, with the noise-coupling test on its default sketch of the blocks and on every
block) and without."""

import os
import sys

import numpy as np
import pytest

from modaluq import _core
from modaluq.simulate.campaign import simulate_campaign

sys.path.insert(0, os.path.dirname(__file__))
import oracle_multisetup as om  # noqa: E402

P = 8
NB = 10
ORDERS = [4, 6, 8, 10, 12, 14, 16]
TOL = 1e-10
# Above the true order (12) the σ run through the noise singular vectors of each setup, whose
# close singular values (1/(s_i² − s_j²) in (5.5)) amplify the rounding differences between
# LAPACK's and Eigen's SVD: measured 3e-12 (OO) and 1.4e-9 (IO) at order 16, 3e-13 up to 12.
TOL_ABOVE_TRUE_ORDER = 1e-8
TRUE_ORDER = 12


def _campaign(io):
    kw = {"input_dofs": ("L5",), "input_std": 3.0, "unknown_input_std": 0.5} if io else {}
    # all six setups of the deck, shortened to 60-86 s so that the reference runs in seconds
    return simulate_campaign(3, durations=(60.0, 72.0, 54.0, 66.0, 86.0, 60.0), **kw)


def _core_setups(camp, io):
    out = []
    for s in camp.setups:
        lay = _core.HankelLayout()
        lay.block_rows = P
        lay.past_block_rows = P
        lay.references = list(s.references)
        u_t = s.u.T if io else np.empty((0, s.y.shape[0]))
        cov = _core.compute_covariances(np.ascontiguousarray(s.y).T, np.ascontiguousarray(u_t), lay, NB)
        out.append(_core.SetupData(cov, list(s.references), camp.fs))
    return out


def _options(fs, uncertainty=True, freeze_noise=True, coupling_sketch=None, noise_coupling_limit=None):
    o = _core.IdentifyOptions()
    if noise_coupling_limit is not None:
        o.noise_coupling_limit = noise_coupling_limit
    if coupling_sketch is not None:
        o.coupling_sketch = coupling_sketch
    o.fs = fs
    o.block_rows = P
    o.past_block_rows = P
    o.orders = ORDERS
    o.n_blocks = NB
    o.uncertainty = uncertainty
    o.freeze_noise = freeze_noise
    return o


def _rel_cols(a, b):
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    assert a.shape == b.shape
    num = np.linalg.norm(a - b, axis=0)
    den = np.maximum(np.linalg.norm(b, axis=0), 1e-300)
    return float(np.max(num / den)) if a.size else 0.0


@pytest.fixture(scope="module", params=["oo", "io", "oo-unfrozen", "io-unfrozen", "oo-every-block", "io-every-block"])
def case(request):
    io = request.param.startswith("io")
    freeze = not request.param.endswith("unfrozen")
    # the noise-coupling test: the core's default sketch (4 of the NB = 10 blocks) or every block
    sketch = 0 if request.param.endswith("every-block") else _core.IdentifyOptions().coupling_sketch
    assert 0 < _core.IdentifyOptions().coupling_sketch < NB  # the default sketch is exercised
    # a limit low enough that some poles above the true order are flagged (their rho is 1-18 here)
    limit = 3.0
    camp = _campaign(io)
    ident = _core.identify_setups(_core_setups(camp, io), _options(camp.fs, freeze_noise=freeze,
                                                                   coupling_sketch=sketch, noise_coupling_limit=limit))
    ref, rcamp = om.identify_modular(
        om.prepare_setups([(s.y, s.u if io else None) for s in camp.setups], P, P, NB,
                          [s.references for s in camp.setups]),
        fs=camp.fs, p=P, orders=ORDERS, freeze_noise=freeze, coupling_sketch=sketch, noise_coupling_limit=limit)
    if freeze:  # flagged and unflagged poles above the floor: both rows of the test are exercised
        flags = np.concatenate([np.asarray(m.noise_coupled) for m in ident.modes if m.order > TRUE_ORDER])
        assert flags.any() and not flags.all(), flags
    k_star = [st["k_star"] for st in rcamp.setups]
    assert list(ident.setup_significant_singular_values) == k_star
    if freeze:  # the frozen path is exercised: some setup's floor lies below the highest order
        assert min(k_star) < max(ORDERS), k_star
    return camp, ident, ref, rcamp


def test_core_merge_equals_the_numpy_reference(case):
    camp, ident, ref, rcamp = case
    assert [(int(j), int(c)) for j, c in zip(ident.dof_setup, ident.dof_channel)] == rcamp.dofs
    worst = {}
    for n in ORDERS:
        r = ref[n]
        m = next(x for x in ident.modes if x.order == n)
        assert len(m.frequency_hz) == len(r["frequency_hz"]), n
        nm = len(r["frequency_hz"])
        if nm == 0:
            continue
        point = max(_rel_cols(m.frequency_hz[None], r["frequency_hz"][None]),
                    _rel_cols(m.damping_ratio[None], r["damping_ratio"][None]),
                    _rel_cols(m.mode_shape, r["mode_shape"]))
        cov_ref = r["covariance"].reshape(nm, -1).T
        sigma = max(_rel_cols(m.frequency_std[None], r["frequency_std"][None]),
                    _rel_cols(m.damping_std[None], r["damping_std"][None]),
                    _rel_cols(m.mode_shape_std_real, r["mode_shape_std_real"]),
                    _rel_cols(m.mode_shape_std_imag, r["mode_shape_std_imag"]),
                    _rel_cols(m.covariance, cov_ref),
                    _rel_cols(m.noise_coupling[None], r["noise_coupling"][None]),
                    # each pole's factor rows of f and xi, column i [u_f; u_xi] (Modes.frequency_damping_factor)
                    _rel_cols(m.frequency_damping_factor, r["factor"][:, :2, :].reshape(nm, -1).T))
        assert point < TOL, (n, point)
        assert sigma < (TOL if n <= TRUE_ORDER else TOL_ABOVE_TRUE_ORDER), (n, sigma)
        key = "up to the true order" if n <= TRUE_ORDER else "above"
        worst[key] = max(worst.get(key, 0.0), point, sigma)
    print(f"max relative difference core vs reference: {worst}")


def test_core_merge_feeds_the_diagram(case):
    camp, ident, ref, rcamp = case
    poles = _core.poles_of(ident)
    assert len(poles.frequency_hz) == sum(len(m.frequency_hz) for m in ident.modes)
    assert ident.n_blocks == NB * len(camp.setups)
    # the poles carry every pole's factor rows, one column per block of every setup
    assert poles.frequency_damping_factor.shape == (2 * ident.n_blocks, len(poles.frequency_hz))
    assert np.array_equal(poles.frequency_damping_factor,
                          np.hstack([m.frequency_damping_factor for m in ident.modes if len(m.frequency_hz)]))


def test_factor_rows_reproduce_the_covariance(case):
    """Each pole's stored rows [u_f; u_xi] are its factor's: U Uᵀ is the covariance's [f, ξ] block."""
    camp, ident, ref, rcamp = case
    l_g = ident.modes[0].mode_shape.shape[0]
    nb = ident.n_blocks
    for m in ident.modes:
        nm = len(m.frequency_hz)
        assert m.frequency_damping_factor.shape == ((2 * nb, nm) if nm else (0, 0))
        for i in range(nm):
            u = m.frequency_damping_factor[:, i].reshape(2, nb)
            cov = m.covariance[:, i].reshape(2 + 2 * l_g, 2 + 2 * l_g)[:2, :2]
            np.testing.assert_allclose(u @ u.T, cov, rtol=1e-12, atol=1e-12 * np.sqrt(cov[0, 0] * cov[1, 1]))
            assert np.linalg.norm(u[0]) == pytest.approx(m.frequency_std[i], rel=1e-12)


def test_a_sketch_over_setups_with_few_and_many_blocks_equals_the_reference():
    """coupling_sketch = 4 with setups of 3, 10 and 6 blocks: the 3-block setup keeps its blocks
    (identity), the others are combined; core and reference agree, flags and σ included."""
    camp = _campaign(False)
    blocks = [3, 10, 6, 10, 10, 6]
    setups = []
    for s, nb in zip(camp.setups, blocks):
        lay = _core.HankelLayout()
        lay.block_rows = P
        lay.past_block_rows = P
        lay.references = list(s.references)
        cov = _core.compute_covariances(np.ascontiguousarray(s.y).T, np.empty((0, s.y.shape[0])), lay, nb)
        setups.append(_core.SetupData(cov, list(s.references), camp.fs))
    ident = _core.identify_setups(setups, _options(camp.fs, coupling_sketch=4, noise_coupling_limit=3.0))
    assert list(ident.setup_n_blocks) == blocks
    ref, _ = om.identify_modular(
        om.prepare_setups([(s.y, None) for s in camp.setups], P, P, blocks, [s.references for s in camp.setups]),
        fs=camp.fs, p=P, orders=ORDERS, freeze_noise=True, coupling_sketch=4, noise_coupling_limit=3.0)
    flagged = 0
    for n in ORDERS:
        r, m = ref[n], next(x for x in ident.modes if x.order == n)
        nm = len(r["frequency_hz"])
        if nm == 0:
            continue
        assert np.array_equal(np.asarray(m.noise_coupled), r["noise_coupled"]), n
        flagged += int(np.sum(r["noise_coupled"]))
        tol = TOL if n <= TRUE_ORDER else TOL_ABOVE_TRUE_ORDER
        assert _rel_cols(m.noise_coupling[None], r["noise_coupling"][None]) < tol, n
        assert _rel_cols(m.covariance, r["covariance"].reshape(nm, -1).T) < tol, n
    assert flagged > 0


def test_core_refuses_a_setup_without_the_references():
    camp = _campaign(False)
    setups = _core_setups(camp, False)
    bad = _core.SetupData(setups[1].covariances, [0], camp.fs)
    with pytest.raises(ValueError, match="setup 1 has 1 references, setup 0 has 2"):
        _core.identify_setups([setups[0], bad] + setups[2:], _options(camp.fs))
    other = _core.SetupData(setups[2].covariances, list(camp.setups[2].references), 2 * camp.fs)
    with pytest.raises(ValueError, match="setup 1: fs = 50 Hz differs"):
        _core.identify_setups([setups[0], other], _options(camp.fs))
