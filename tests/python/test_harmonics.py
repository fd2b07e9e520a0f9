"""Harmonics of the excitation (rotating machinery) told from structural modes by the kurtosis of
the band-pass filtered response (harmonics.py; Jacobsen, Andersen & Brincker 2007)."""

import numpy as np
import pytest

import modaluq
from modaluq.harmonics import HARMONIC_KURTOSIS, harmonic_kurtosis, possible_harmonics


def test_kurtosis_of_a_sinusoid_and_of_a_random_mode():
    rng = np.random.default_rng(3)
    t = np.arange(100_000) / 100.0
    sine = np.sin(2 * np.pi * 10.0 * t)[:, None]
    noise = rng.standard_normal((t.size, 1))
    k = harmonic_kurtosis(np.hstack([sine, 1e-3 * noise]), 100.0, [10.0])
    assert abs(k[0] - 1.5) < 0.05                      # the strongest channel: the sinusoid
    k = harmonic_kurtosis(noise, 100.0, [10.0, 30.0])
    assert np.all(np.abs(k - 3.0) < 0.3)               # filtered Gaussian noise
    assert np.isnan(harmonic_kurtosis(noise, 100.0, [49.5])[0])  # the band does not fit below fs/2


# block_rows 40 (lags of 0.8 s) keeps the test fast; identify warns that 1 Hz wants longer lags
@pytest.mark.filterwarnings("ignore:block_rows = 40 gives lags:modaluq.ModalUQWarning")
def test_a_machine_harmonic_in_the_band_is_flagged_and_the_modes_are_not():
    sim = modaluq.simulate(60_000, seed=4)
    t = np.arange(sim.n_samples) / sim.fs
    y = sim.y + 0.5 * np.std(sim.y, axis=0) * np.sin(2 * np.pi * 11.0 * t)[:, None]   # a rotating machine
    r = modaluq.identify(y, fs=sim.fs, frequency_range=(1.0, 20.0), block_rows=40, orders=range(2, 61, 2))
    sel = r.stabilization_diagram().select_modes()
    flags = possible_harmonics(y, r.fs, sel.frequency_hz, sel.damping_ratio)
    near = np.abs(sel.frequency_hz - 11.0) < 0.05
    assert flags[near].all()                            # not reported as a mode, or reported flagged
    assert possible_harmonics(y, r.fs, [11.0]).tolist() == [True]
    for f in sim.frequency_hz[1:]:                      # OO mode 1 is weak; the others found, unflagged
        k = int(np.argmin(np.abs(sel.frequency_hz - f)))
        assert abs(sel.frequency_hz[k] - f) < 0.01 * f and not flags[k], (f, sel.frequency_hz, flags)


def test_light_damping_lowers_the_bar_and_bad_arguments_are_named():
    rng = np.random.default_rng(0)
    y = rng.standard_normal((20_000, 2))
    assert possible_harmonics(y, 50.0, [5.0], [0.001]).tolist() == [False]  # Gaussian: kurtosis ~3
    with pytest.raises(ValueError, match="threshold"):
        possible_harmonics(y, 50.0, [5.0], threshold=5.0)
    with pytest.raises(ValueError, match="relative_bandwidth"):
        harmonic_kurtosis(y, 50.0, [5.0], relative_bandwidth=0.0)
    assert 1.5 < HARMONIC_KURTOSIS < 3.0


def test_a_lightly_damped_mode_is_flagged_only_beside_a_family_of_a_clear_harmonic():
    """Kurtosis 2.2-2.6 with ξ < 0.5 % is within the estimate's noise of a Gaussian mode: it is
    flagged only at an integer multiple of a frequency whose kurtosis alone says "sinusoid"."""
    from unittest import mock

    from modaluq import harmonics

    kurt = np.array([1.6, 2.5, 2.5, 2.5])          # a clear line, then three borderline values
    f = np.array([0.8, 1.6, 2.0, 3.2])              # 2x and 4x the line; 2.0 Hz is 2.5x
    xi = np.array([0.0003, 0.003, 0.003, 0.02])     # the 3.2 Hz pole is not lightly damped
    with mock.patch.object(harmonics, "harmonic_kurtosis", return_value=kurt):
        flags = harmonics.possible_harmonics(np.zeros((100, 1)), 50.0, f, xi)
    assert flags.tolist() == [True, True, False, False]
    with mock.patch.object(harmonics, "harmonic_kurtosis", return_value=np.array([2.54])):
        assert not harmonics.possible_harmonics(np.zeros((100, 1)), 50.0, [1.17], [0.004])[0]
