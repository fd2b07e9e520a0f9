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


def _softened():
    damaged = STIFFNESS.copy()
    damaged[-1] *= 0.9
    return damaged


@pytest.fixture(scope="module")
def records():
    return _selected(1), _selected(2), _selected(3, _softened())


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
        assert c.z_mac[k] == pytest.approx((1 - t.mac - t.loss_mean) / t.loss_std, rel=1e-9)
    # unpaired modes are the others, on each side
    for side, sel in ((0, a), (1, b)):
        paired = set(c.frequency_hz[:, side])
        assert sorted(c.unmatched_hz[side]) == sorted(f for f in sel.frequency_hz if f not in paired)
    text = c.report()
    assert text.startswith("## Modes compared") and "modes in both sets" in text
    assert list(c.to_dataframe()["z_frequency"]) == list(c.z_frequency)


def test_a_changed_structure_stands_out_and_noise_does_not(records):
    """Two records of one structure: every |z_f| below 4 (6 modes). The last spring 10 % softer moves
    the model's 14.49 Hz mode to 14.08 Hz (2.8 %), beyond the 2 % window and 4 σ: unpaired in both
    sets; with a 5 % window it pairs, and the modes the spring moves by more than 1 % are many σ off."""
    a, b, damaged = records
    before = simulate(10, seed=0, stiffness=STIFFNESS).frequency_hz
    after = simulate(10, seed=0, stiffness=_softened()).frequency_hz
    moved = np.abs(after / before - 1)
    assert np.sum(moved > 0.01) == 2 and np.sum(moved > 0.02) == 1  # the model: 2.8 % and 1.2 %
    same = compare_modes(a, b)
    assert same.summary()["n_pairs"] == 6 and np.max(np.abs(same.z_frequency)) < 4
    assert "If nothing but the noise changed and σ is right" in same.report()
    narrow = compare_modes(a, damaged)
    assert narrow.summary()["n_pairs"] == 5
    gone = before[moved > 0.02][0], after[moved > 0.02][0]
    assert [len(u) for u in narrow.unmatched_hz] == [1, 1]
    assert abs(narrow.unmatched_hz[0][0] / gone[0] - 1) < 0.01 and abs(narrow.unmatched_hz[1][0] / gone[1] - 1) < 0.01
    changed = compare_modes(a, damaged, max_frequency_difference=0.05)
    assert changed.summary()["n_pairs"] == 6
    for f0 in before[moved > 0.01]:
        k = int(np.argmin(np.abs(changed.frequency_hz[:, 0] - f0)))
        assert abs(changed.z_frequency[k]) > 4
    for f0 in before[moved < 0.002]:  # the modes the spring hardly moves: within noise
        k = int(np.argmin(np.abs(changed.frequency_hz[:, 0] - f0)))
        assert abs(changed.z_frequency[k]) < 4


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
    with pytest.raises(ValueError, match="max_frequency_difference"):
        compare_modes(a, b, max_frequency_difference=0)
    sim = simulate(20_000, seed=5, output_dofs=(0, 1, 2, 3, 4))
    five = modaluq.identify(sim.y, fs=sim.fs, frequency_range=(1, 20)).select_modes()
    with pytest.raises(ValueError, match="3 and 5 channels"):
        compare_modes(a, five)
    sim = simulate(20_000, seed=6)
    named = [modaluq.identify(sim.y, fs=sim.fs, frequency_range=(1, 20), output_names=names).select_modes()
             for names in (["a1", "a2", "a5"], ["a1", "a5", "a2"])]
    with pytest.raises(ValueError, match=r"\['a1', 'a2', 'a5'\] and \['a1', 'a5', 'a2'\]"):
        compare_modes(*named)
    result = modaluq.identify(sim.y, fs=sim.fs, frequency_range=(1, 20), uncertainty=False)
    with pytest.raises(ValueError, match="second has no σ"):
        compare_modes(named[0], result)
    with pytest.raises(TypeError, match="first must be selected modes"):  # one order's poles are not a selection
        compare_modes(result.modes[-1], named[0])


def test_an_analysis_that_ran_and_no_pair():
    sim = simulate(20_000, seed=7)
    analysis = modaluq.Analysis.from_arrays(sim.y, fs=sim.fs, settings=modaluq.Settings(frequency_range=(1, 20)))
    ran = analysis.run(check_harmonics=False, issue_warnings=False)
    assert compare_modes(ran, ran.selected).summary()["rms_z_frequency"] == 0
    # a second record identified as the first was: its horizons, orders and blocks
    alike = modaluq.Analysis.from_arrays(simulate(20_000, seed=9).y, fs=sim.fs).identified_like(ran)
    for key in ("block_rows", "past_block_rows", "orders", "n_blocks"):
        assert list(np.atleast_1d(getattr(alike.settings, key))) == list(np.atleast_1d(ran.result.settings[key]))
    with pytest.raises(ValueError, match="has not been run"):
        ran.identified_like(alike)  # alike has not been run
    other = compare_modes(ran, _selected(8), max_frequency_difference=1e-9, pair_within_std=0)
    assert other.summary()["n_pairs"] == 0 and "No mode was found in both sets" in other.report()


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
