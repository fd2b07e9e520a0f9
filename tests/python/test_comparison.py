"""``modaluq.compare_modes``: two sets of selected modes paired and compared against their σ."""

from types import SimpleNamespace

import numpy as np
import pytest

import modaluq
from modaluq.comparison import ModeComparison, _pair, compare_modes
from modaluq.indicators import mac_test, shape_covariance
from modaluq.simulate import simulate

#: the paper's chain; stiffness 100/200 alternating N/m, the last spring 10 % softer for "damaged"
STIFFNESS = np.array([100.0, 200.0, 100.0, 200.0, 100.0, 200.0])


def _selected(seed, stiffness=STIFFNESS):
    sim = simulate(20_000, seed=seed, stiffness=stiffness)
    return modaluq.identify(sim.y, fs=sim.fs, frequency_range=(1, 20)).select_modes()


@pytest.fixture(scope="module")
def records():
    damaged = STIFFNESS.copy()
    damaged[-1] *= 0.9
    return _selected(1), _selected(2), _selected(3, damaged)


def test_pairs_and_z_equal_a_computation_by_hand(records):
    a, b, _ = records
    c = compare_modes(a, b)
    assert isinstance(c, ModeComparison) and c.summary()["n_pairs"] >= 5
    for k in range(c.summary()["n_pairs"]):
        i = int(np.flatnonzero(a.frequency_hz == c.frequency_hz[k, 0])[0])
        j = int(np.flatnonzero(b.frequency_hz == c.frequency_hz[k, 1])[0])
        assert abs(a.frequency_hz[i] / b.frequency_hz[j] - 1) <= 0.02 or c.by_std[k]
        zf = (a.frequency_hz[i] - b.frequency_hz[j]) / np.hypot(a.frequency_std[i], b.frequency_std[j])
        zx = (a.damping_ratio[i] - b.damping_ratio[j]) / np.hypot(a.damping_std[i], b.damping_std[j])
        assert c.z_frequency[k] == pytest.approx(zf, rel=1e-12) and c.z_damping[k] == pytest.approx(zx, rel=1e-12)
        t = mac_test(a.mode_shape[:, i], b.mode_shape[:, j], shape_covariance(a.mode_covariance[i]),
                     shape_covariance(b.mode_covariance[j]))
        assert c.mac[k] == pytest.approx(t.mac, rel=1e-12) and c.mac_p_value[k] == pytest.approx(t.p_value, rel=1e-9)
    # unpaired modes are the others
    assert len(c.unmatched_hz[0]) == a.n_modes - c.summary()["n_pairs"]
    text = c.report()
    assert text.startswith("## Modes compared") and "modes in both sets" in text
    assert list(c.to_dataframe()["z_frequency"]) == list(c.z_frequency)


def test_a_changed_structure_stands_out_and_noise_does_not(records):
    """Two records of one structure: every |z_f| below 4 (6 modes). The last spring 10 % softer moves
    the 14.5 Hz mode by 3 %, beyond the 2 % window and 4 σ: unpaired in both sets; with a 5 % window
    it pairs, and it and the 15.9 Hz mode (1.4 %) are many σ off."""
    a, b, damaged = records
    same = compare_modes(a, b)
    assert same.summary()["n_pairs"] == 6 and np.max(np.abs(same.z_frequency)) < 4
    assert "If nothing but the noise changed and σ is right" in same.report()
    narrow = compare_modes(a, damaged)
    assert narrow.summary()["n_pairs"] == 5 and len(narrow.unmatched_hz[0]) == 1
    assert abs(narrow.unmatched_hz[0][0] - 14.5) < 0.1 and abs(narrow.unmatched_hz[1][0] - 14.0) < 0.1
    changed = compare_modes(a, damaged, max_frequency_difference=0.05)
    assert changed.summary()["n_pairs"] == 6
    moved = np.abs(changed.frequency_hz[:, 1] / changed.frequency_hz[:, 0] - 1)
    assert np.sum(moved > 0.01) >= 2 and np.all(np.abs(changed.z_frequency)[moved > 0.01] > 4)


def test_a_result_is_compared_by_its_default_selection():
    sim = simulate(20_000, seed=4)
    result = modaluq.identify(sim.y, fs=sim.fs, frequency_range=(1, 20))
    np.testing.assert_array_equal(compare_modes(result, result.select_modes()).z_frequency,
                                  np.zeros(result.select_modes().n_modes))


def test_bad_input_is_named(records):
    a, b, _ = records
    with pytest.raises(TypeError, match="first must be selected modes"):
        compare_modes(np.zeros(3), b)
    with pytest.raises(TypeError, match="second must be selected modes"):
        compare_modes(a, "b")
    with pytest.raises(ValueError, match="pair_within_std"):
        compare_modes(a, b, pair_within_std=-1)
    with pytest.raises(ValueError, match="min_mac"):
        compare_modes(a, b, min_mac=2)
    other = SimpleNamespace(frequency_hz=np.array([5.0]), frequency_std=np.array([0.1]),
                            damping_ratio=np.array([0.02]), damping_std=np.array([0.002]),
                            mode_shape=np.ones((5, 1), complex))
    with pytest.raises(ValueError, match="3 and 5 channels"):
        compare_modes(a, other)


def _modes(frequency_hz, frequency_std, shapes):
    """What _pair reads of a half's selected modes."""
    return SimpleNamespace(frequency_hz=np.array(frequency_hz, float), frequency_std=np.array(frequency_std, float),
                           mode_shape=np.array(shapes, complex).T)


def test_pairs_by_sigma_only_where_unambiguous():
    """The rules of _pair on hand-made halves (shapes as unit vectors: MAC 1 when equal, 0 when
    orthogonal): the window first, nearest first; then a σ-only pair when neither mode has another
    candidate; never by σ with a NaN or infinite σ."""
    e = np.eye(4)
    # window pair (10.0, 10.1: 1 %) beside a σ-only pair (20.0, 21.0: 4.8 %, 0.7 combined σ, z 1.4)
    h1 = _modes([10.0, 20.0], [0.01, 0.5], [e[0], e[1]])
    h2 = _modes([10.1, 21.0], [0.01, 0.5], [e[0], e[1]])
    assert _pair(h1, h2, 0.02, 0.8, 4.0) == [(0, 0, False), (1, 1, True)]
    assert _pair(h1, h2, 0.02, 0.8, 1.0) == [(0, 0, False)]            # 1.4 combined σ apart
    assert _pair(h1, h2, 0.02, 0.8, 0.0) == [(0, 0, False)]
    # a broad mode whose σ window holds two modes of the other half alike in shape: no pair
    h1 = _modes([1.56], [0.04], [e[0]])
    h2 = _modes([1.51, 1.61], [0.01, 0.003], [e[0], e[0]])
    assert _pair(h1, h2, 0.02, 0.8, 4.0) == []
    # ... unless the shapes tell them apart (MAC < min_mac for one of them)
    h2 = _modes([1.51, 1.61], [0.01, 0.003], [e[0], e[2]])
    assert _pair(h1, h2, 0.02, 0.8, 4.0) == [(0, 0, True)]
    # the other half's mode has a second candidate: no σ-only pair either
    h1 = _modes([1.46, 1.56], [0.012, 0.04], [e[0], e[0]])
    h2 = _modes([1.51], [0.013], [e[0]])
    assert _pair(h1, h2, 0.02, 0.8, 4.0) == []
    # a window pair still forms when a σ-only candidate competes, and takes its modes first
    h1 = _modes([5.0, 5.3], [0.001, 0.2], [e[0], e[0]])
    h2 = _modes([5.05], [0.001], [e[0]])
    assert _pair(h1, h2, 0.02, 0.8, 4.0) == [(0, 0, False)]
    # NaN or infinite σ: the window only
    for bad in (np.nan, np.inf):
        h1 = _modes([20.0], [bad], [e[1]])
        h2 = _modes([21.0], [0.5], [e[1]])
        assert _pair(h1, h2, 0.02, 0.8, 4.0) == []
        assert _pair(h1, h2, 0.06, 0.8, 4.0) == [(0, 0, False)]
