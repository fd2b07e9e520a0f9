"""Simulated hard cases through the engineer's call: only ``fs``, the inputs (if any) and a band,
``modaluq.identify(y, u, fs=..., frequency_range=(lo, hi)).select_modes()``; no block_rows, no
orders (project issue 12).

1. 0.2 % damping from a 4-minute record of the paper's chain;
2. two modes 1 % apart in frequency (output-only, and input/output on a physical 2-DOF system);
3. a strong harmonic of a rotating machine inside the band, between two modes;
4. a band that holds only 2 of the chain's 6 modes.

Every expected value is derived from the simulated system, never read off an identification: the
chain's exact modal parameters from its matrices (``Simulation.frequency_hz`` / ``damping_ratio``,
``modaluq.simulate.modal_parameters``), the close pair's from its AR(2) poles or its matrices.
Seeds are fixed; the seeds of the suite were chosen before the runs (1, 2, 3 as elsewhere).
"""

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

import modaluq
from modaluq.harmonics import possible_harmonics
from modaluq.preprocess import preprocess
from modaluq.simulate import acceleration_response, chain_system, modal_parameters
from modaluq.stabilization import modal_assurance_criterion

pytestmark = pytest.mark.filterwarnings("ignore::modaluq.ModalUQWarning")

SEEDS = (1, 2, 3)
IO_IDS = ["input/output", "output-only"]


def engineers_call(y, u, fs, band):
    """What an engineer types: the record, the inputs (or None), fs and a band; nothing else."""
    result = modaluq.identify(y, u, fs=fs, frequency_range=band)
    return result, result.select_modes()


def in_band(frequency_hz, band):
    f = np.sort(np.asarray(frequency_hz))
    return f[(f > band[0]) & (f < band[1])]


# ------------------------------------------------------------------ 1. 0.2 % damping, 4 minutes


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("with_input", [True, False], ids=IO_IDS)
def test_two_tenths_of_a_percent_damping_from_four_minutes(seed, with_input):
    """The paper chain with 0.2 % modal damping, 240 s at 50 Hz, band 1-20 Hz (all six modes).

    Hard because the lowest mode decays over 1/(2π · 1.93 Hz · 0.002) = 41 s, so the record holds
    only 6 of its decay times, and the automatic block length assumes 1 % damping. Checks: exactly
    the six true modes and nothing else in the band; each frequency within 0.5 % and within 4 σ_f
    of the true one; each damping ratio of the right magnitude (0.05-0.8 %, i.e. within a factor 4
    of 0.2 %, nowhere near the 2 % of the default chain) and within 4 σ_ξ (+ 0.02 %) of the true one.
    """
    sim = modaluq.simulate(12_000, seed=seed, damping_ratio=0.002)
    band = (1.0, 20.0)
    assert sim.n_samples / sim.fs == 240.0
    order = np.argsort(sim.frequency_hz)
    f_true, xi_true = sim.frequency_hz[order], sim.damping_ratio[order]
    assert f_true.size == in_band(f_true, band).size == 6
    _, sel = engineers_call(sim.y, sim.u if with_input else None, sim.fs, band)

    assert sel.n_modes == 6, (sel.frequency_hz, f_true)
    err = np.abs(sel.frequency_hz - f_true)
    assert np.all(err < 0.005 * f_true), (sel.frequency_hz, f_true)
    assert np.all(err < 4 * sel.frequency_std + 1e-4 * f_true), (err, sel.frequency_std)
    assert np.all((sel.damping_ratio > 0.0005) & (sel.damping_ratio < 0.008)), sel.damping_ratio
    assert np.all(np.abs(sel.damping_ratio - xi_true) < 4 * sel.damping_std + 2e-4), (
        sel.damping_ratio, sel.damping_std)


# ------------------------------------------------------------------ 2. two modes 1 % apart


def close_pair_record(seed, n_samples=25_000, fs=25.0, f=(5.0, 5.05), xi=0.01, noise=0.05):
    """Two modes 1 % apart with distinct shapes on three sensors, each driven by its own white noise.

    Each modal coordinate is the AR(2) recursion whose poles are exactly exp(s dt) of the
    continuous mode (s = -ξω ± iω√(1-ξ²)), so |s| / 2π is exactly ``f`` and -Re(s)/|s| exactly
    ``xi``. Outputs y = Φ q plus sensor noise of ``noise`` times each channel's std."""
    rng = np.random.default_rng(seed)
    shapes = np.array([[1.0, 1.0, 0.5], [1.0, -1.0, 0.3]]).T  # MAC 0.01
    q = []
    for fk in f:
        w = 2 * np.pi * fk
        r = np.exp(-xi * w / fs)
        a1, a2 = 2 * r * np.cos(w * np.sqrt(1 - xi ** 2) / fs), -r * r
        q.append(scipy.signal.lfilter([1.0], [1.0, -a1, -a2], rng.standard_normal(n_samples + 5_000))[5_000:])
    y = np.column_stack(q) @ shapes.T
    y += noise * y.std(axis=0) * rng.standard_normal(y.shape)
    return y, fs, np.array(f), np.full(2, xi), shapes


def coupled_pair_system(f0=5.0, spacing=0.01, xi=0.01, mass=1.0):
    """Two equal grounded oscillators joined by a weak spring: M, K, C of two modes ``spacing`` apart.

    Each mass m sits on a spring k = m (2π f0)² to the ground; the coupling spring k_c puts the
    in-phase mode at f0 and the out-of-phase one at f0 sqrt(1 + 2 k_c / k) = f0 (1 + spacing).
    Modal damping ``xi`` on both (C = M Φ diag(2 ξ ω) Φᵀ M, Φ mass-normalised)."""
    k = mass * (2 * np.pi * f0) ** 2
    kc = 0.5 * k * ((1 + spacing) ** 2 - 1)
    M = mass * np.eye(2)
    K = np.array([[k + kc, -kc], [-kc, k + kc]])
    omega2, phi = scipy.linalg.eigh(K, M)
    mphi = M @ phi
    C = (mphi * (2 * xi * np.sqrt(omega2))) @ mphi.T
    return M, K, C


def assert_close_pair_resolved(sel, f_true, xi_true, shapes):
    """Exactly two modes, each within a quarter of the spacing and 4 σ_f of its true frequency,
    each with its own shape (MAC > 0.9 with its own, < 0.5 with the other's), ξ within 0.5-2x."""
    assert sel.n_modes == 2, sel.frequency_hz
    spacing = f_true[1] - f_true[0]
    assert np.all(np.abs(sel.frequency_hz - f_true) < 0.25 * spacing), sel.frequency_hz
    assert np.all(np.abs(sel.frequency_hz - f_true) < 4 * sel.frequency_std + 1e-3)
    mac = modal_assurance_criterion(sel.mode_shape, shapes)
    assert np.all(np.diag(mac) > 0.9) and np.all(mac[[0, 1], [1, 0]] < 0.5), mac
    assert np.all((sel.damping_ratio > 0.5 * xi_true) & (sel.damping_ratio < 2 * xi_true)), sel.damping_ratio


@pytest.mark.parametrize("seed", SEEDS)
def test_two_modes_one_percent_apart_output_only(seed):
    """Output-only: two 1 %-damped modes 0.05 Hz apart (their half-power bands, 2 ξ f = 0.1 Hz
    wide, overlap), 1000 s, band 4-6 Hz. Checks: exactly two modes selected (not merged into one,
    no twin), each within a quarter of the spacing and within 4 σ_f of its true frequency, each
    with its own shape (MAC > 0.9 with its true shape, < 0.5 with the other's) and a damping
    ratio of 0.5-2 % (a merged pair would show one pole with an inflated damping)."""
    y, fs, f_true, xi_true, shapes = close_pair_record(seed)
    _, sel = engineers_call(y, None, fs, (4.0, 6.0))
    assert_close_pair_resolved(sel, f_true, xi_true, shapes)


@pytest.mark.parametrize("seed", SEEDS)
def test_two_modes_one_percent_apart_input_output(seed):
    """Input/output on a physical system: two weakly coupled 5 Hz oscillators (modes 5.00 and
    5.05 Hz, 1 % damping), a measured white force on mass 1, unmeasured forces of 10 % on both
    masses, accelerations of both masses with 5 % sensor noise, 1000 s at 25 Hz, band 4-6 Hz.
    The true values come from the matrices (modal_parameters), checked against the analytic
    f0 and f0 (1 + 1 %). Checks: exactly two modes, each within a quarter of the spacing and
    4 σ_f, each with its own shape (in-phase / out-of-phase: MAC > 0.9 with its own, < 0.5 with
    the other) and a damping ratio of 0.5-2 %."""
    M, K, C = coupled_pair_system()
    f_true, xi_true, shapes = modal_parameters(M, K, C, output_dofs=(0, 1))
    np.testing.assert_allclose(f_true, [5.0, 5.05], rtol=1e-12)
    np.testing.assert_allclose(xi_true, 0.01, rtol=1e-12)
    fs, n, discard = 25.0, 25_000, 2_500  # discard 100 s: 30 decay times of the start from rest
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n + discard, 1))
    force = 0.1 * rng.standard_normal((n + discard, 2))
    force[:, 0] += u[:, 0]
    y = acceleration_response(force, M, K, C, fs=fs, output_dofs=(0, 1))[discard:]
    y += 0.05 * y.std(axis=0) * rng.standard_normal(y.shape)

    _, sel = engineers_call(y, u[discard:], fs, (4.0, 6.0))
    assert_close_pair_resolved(sel, f_true, xi_true, shapes)


# ------------------------------------------------------------------ 3. a machine harmonic in the band


def chain_with_machine(seed, harmonic_hz, n_samples=60_000, strength=2.0, machine_dof=2, discard=3_000):
    """The paper chain (20 min at 50 Hz) plus a rotating machine on mass ``machine_dof + 1``: a
    sinusoidal force at ``harmonic_hz``, unmeasured. Its steady-state acceleration response
    (exact, from the chain's matrices, started ``discard`` samples early so that the start from
    rest has decayed) is added to the broadband response; the force amplitude is set so that in
    the channel where the harmonic is strongest its RMS is ``strength`` times the broadband RMS
    (2: 80 % of that channel's variance)."""
    sim = modaluq.simulate(n_samples, seed=seed)
    M, K, C = chain_system()  # the chain simulate uses by default
    t = np.arange(n_samples + discard) / sim.fs
    force = np.zeros((n_samples + discard, M.shape[0]))
    force[:, machine_dof] = np.sin(2 * np.pi * harmonic_hz * t + 0.3)
    y_h = acceleration_response(force, M, K, C, fs=sim.fs, output_dofs=sim.output_dofs)[discard:]
    j = int(np.argmax(y_h.std(axis=0)))
    y_h *= strength * sim.y[:, j].std() / y_h[:, j].std()
    return sim, sim.y + y_h


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("harmonic_hz", [4.0, 11.0])
@pytest.mark.parametrize("with_input", [True, False], ids=IO_IDS)
def test_a_strong_machine_harmonic_between_modes_is_not_reported_as_a_mode(seed, harmonic_hz, with_input):
    """A strong unmeasured sinusoidal force (4 Hz: between modes 1 and 2; 11 Hz: between modes 3
    and 4) on the 20-minute chain record, band 1-20 Hz. SSI sees a sinusoid as an undamped pole, so
    the diagram has a pole with |ξ| < 0.1 % at the harmonic at most orders (checked, so that the test
    exercises something; its near-zero or negative damping is what keeps it out of the selection). The
    harmonic must not be reported as a physical mode without a flag: a selected mode within 1 % of
    it must be flagged by ``possible_harmonics`` as ``modaluq identify`` (Analysis.run) calls it (kurtosis of the
    band-passed response, on the preprocessed record), and the kurtosis test does flag the
    harmonic's frequency. The six structural modes must be selected within 1 % and not flagged,
    and no other unflagged mode may be selected."""
    # Output-only, 4 Hz, seed 2 was a known limit (issue 12 closing note): a twin of mode 6
    # (16.961 Hz, ξ 0.43 %) stayed selected, its MAC to the mode 0.772 under doublet_min_mac. It is
    # a twin born of the noise (above k*, inside the mode's band, less than half as damped) and
    # drop_noise_twins drops it whatever the MAC.
    sim, y = chain_with_machine(seed, harmonic_hz)
    band = (1.0, 20.0)
    u = sim.u if with_input else None
    result, sel = engineers_call(y, u, sim.fs, band)
    pre = preprocess(y, u, fs=sim.fs, frequency_range=band)
    assert pre.fs == result.fs
    flags = possible_harmonics(pre.y, pre.fs, sel.frequency_hz, sel.damping_ratio)

    diagram = result.stabilization_diagram()
    undamped_pole_at_harmonic = ((np.abs(diagram.frequency_hz - harmonic_hz) < 0.002 * harmonic_hz)
                                 & (np.abs(diagram.damping_ratio) < 0.001))
    assert np.unique(diagram.order[undamped_pole_at_harmonic]).size >= len(diagram.orders) // 2  # SSI sees it
    assert possible_harmonics(pre.y, pre.fs, [harmonic_hz]).tolist() == [True]

    near_harmonic = np.abs(sel.frequency_hz - harmonic_hz) < 0.01 * harmonic_hz
    assert np.all(flags[near_harmonic]), (sel.frequency_hz, flags)
    f_true = np.sort(sim.frequency_hz)
    structural = np.abs(sel.frequency_hz[:, None] - f_true[None, :]) < 0.01 * f_true[None, :]
    for i, f in enumerate(f_true):
        k = np.flatnonzero(structural[:, i])
        assert k.size == 1, f"true mode {f:.4g} Hz selected {k.size} times: {sel.frequency_hz[k]} Hz, xi {sel.damping_ratio[k]}"
        assert not flags[k[0]], f"structural mode {f:.4g} Hz flagged as a harmonic"
    unexplained = ~structural.any(axis=1) & ~flags
    assert not unexplained.any(), (sel.frequency_hz[unexplained], f_true)


# ------------------------------------------------------------------ 4. a band with 2 of the 6 modes


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("band", [(1.0, 7.0), (4.0, 10.0), (12.0, 16.4)], ids=["1-7Hz", "4-10Hz", "12-16.4Hz"])
@pytest.mark.parametrize("with_input", [True, False], ids=IO_IDS)
def test_a_band_with_two_of_the_six_modes_selects_exactly_those_two(seed, band, with_input):
    """The paper chain, 240 s at 50 Hz, with a band that holds only two of its six modes: 1-7 Hz
    (modes 1-2; the record is decimated to 25 Hz), 4-10 Hz (modes 2-3, the others outside on both
    sides), 12-16.4 Hz (modes 4-5, with mode 6 only 3.7 % above the upper edge). Checks: exactly
    those two modes are selected, nothing outside the band, each within 2 % (a quarter of the
    closest spacing of the chain) and within 4 σ_f (+ 0.1 %) of its true frequency."""
    sim = modaluq.simulate(12_000, seed=seed)
    f_true = in_band(sim.frequency_hz, band)
    assert f_true.size == 2
    _, sel = engineers_call(sim.y, sim.u if with_input else None, sim.fs, band)
    assert sel.n_modes == 2, (sel.frequency_hz, f_true)
    assert np.all((sel.frequency_hz > band[0]) & (sel.frequency_hz < band[1])), sel.frequency_hz
    err = np.abs(sel.frequency_hz - f_true)
    assert np.all(err < 0.02 * f_true), (sel.frequency_hz, f_true)
    assert np.all(err < 4 * sel.frequency_std + 1e-3 * f_true), (err, sel.frequency_std)
