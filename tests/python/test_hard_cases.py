"""Simulated hard cases through the engineer's call (only fs, the inputs, a band): every expected
value is the simulator's exact modal frequency.

Also hard, and tested elsewhere: a strong harmonic of the excitation inside the band
(test_harmonics.py), a band holding 2 of the chain's 6 modes (test_preprocess.py), the chain
sampled at 1000 Hz (test_records.py).
"""

import numpy as np
import pytest
import scipy.signal

import modaluq

pytestmark = pytest.mark.filterwarnings("ignore::modaluq.ModalUQWarning")


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("with_input", [True, False], ids=["input/output", "output-only"])
def test_two_tenths_of_a_percent_damping_from_four_minutes(seed, with_input):
    """The paper chain with 0.2 % damping, 240 s at 50 Hz (the lowest mode decays over 40 s, so the
    record holds only 6 decay times of it): the six modes, nothing else, frequencies within 0.1 %
    and damping ratios within 0.1-0.4 %, each within 4 σ of 0.2 %."""
    sim = modaluq.simulate(12_000, seed=seed, damping_ratio=0.002)
    sel = modaluq.identify(sim.y, sim.u if with_input else None, fs=sim.fs, frequency_range=(1, 20)).select_modes()
    np.testing.assert_allclose(sel.frequency_hz, np.sort(sim.frequency_hz), rtol=1e-3)
    assert np.all((sel.damping_ratio > 0.001) & (sel.damping_ratio < 0.004))
    assert np.all(np.abs(sel.damping_ratio - 0.002) < 4 * sel.damping_std + 2e-4)


def close_pair_record(seed, n_samples=25_000, fs=25.0, f=(5.0, 5.05), xi=0.01, noise=0.05):
    """Two modes 1 % apart with distinct shapes on three sensors, each driven by white noise.

    Each modal coordinate is the AR(2) recursion whose poles are exactly exp(s dt) of the
    continuous mode (s = -ξω ± iω√(1-ξ²)), so |s| / 2π is exactly ``f``. Outputs y = Φ q plus
    sensor noise of ``noise`` times each channel's std."""
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
    return y, fs, np.array(f)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_two_modes_one_percent_apart_are_both_found(seed):
    """Two 1 %-damped modes 0.05 Hz apart (their half-power bands overlap: 2 ξ f = 0.1 Hz), 1000 s:
    both selected, each within a quarter of the spacing, and nothing else in the band."""
    y, fs, truth = close_pair_record(seed)
    sel = modaluq.identify(y, fs=fs, frequency_range=(4.0, 6.0)).select_modes()
    assert sel.n_modes == 2, sel.frequency_hz
    spacing = truth[1] - truth[0]
    assert np.all(np.abs(sel.frequency_hz - truth) < 0.25 * spacing)
    assert np.all(np.abs(sel.frequency_hz - truth) < 4 * sel.frequency_std + 1e-3)
