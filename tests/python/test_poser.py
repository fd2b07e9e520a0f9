"""identify_setups(method="poser") and the reference-consistency warning of both methods
(docs/uq-math.md §13.5, §13.9; the core's poser_merge is checked in tests/cpp/test_poser.cpp)."""

import os
import sys
import warnings

import numpy as np
import pytest

import modaluq
from modaluq import _core
from modaluq.simulate.campaign import DEFAULT_ROVING, simulate_campaign

sys.path.insert(0, os.path.dirname(__file__))
import oracle_multisetup as om  # noqa: E402

ORDERS = list(range(2, 25, 2))
KW = dict(block_rows=15, orders=ORDERS, n_blocks=20)  # each setup alone: >= 2 l_j + 3 blocks


def _frames(camp, swap_in=None):
    out = camp.frames()
    if swap_in is not None:  # the two references' labels swapped in this setup
        out[swap_in] = out[swap_in].rename(columns={"L3": "R8", "R8": "L3"})
    return out


def _campaign(seed):
    return simulate_campaign(seed, durations=(120.0, 140.0, 110.0, 130.0, 150.0, 120.0))


@pytest.fixture(scope="module")
def campaign():
    return _campaign(4)


@pytest.fixture(scope="module")
def poser(campaign):
    with warnings.catch_warnings():
        warnings.simplefilter("error", modaluq.ReferenceMismatchWarning)
        return modaluq.identify_setups(_frames(campaign), fs=campaign.fs, references=["L3", "R8"], method="poser",
                                       **KW)


def test_poser_global_modes_with_their_sigma(campaign, poser):
    assert isinstance(poser, modaluq.PoserResult)
    expected = ["L3", "R8"] + [c for s in campaign.setups for c in s.channels[2:]]
    assert list(poser.output_names) == expected
    sel = poser.select_modes()
    assert isinstance(sel, modaluq.SelectedModes)
    assert sel.output_names == tuple(expected)
    assert sel.mode_shape.shape == (24, 6)
    assert np.all(np.abs(sel.frequency_hz / campaign.frequency_hz - 1) < 0.01)
    truth = campaign.mode_shape[[campaign.dofs.index(n) for n in sel.output_names]]
    for k in range(6):
        phi = sel.mode_shape[:, k]
        mac = abs(np.vdot(truth[:, k], phi)) ** 2 / (np.vdot(phi, phi).real * truth[:, k] @ truth[:, k])
        assert mac > 0.99, (k, mac)
        assert np.abs(phi).max() == pytest.approx(1.0)
    # σ from the propagated covariance, (2 + 2 l_g)^2 per mode
    assert sel.mode_covariance.shape == (6, 50, 50)
    d = np.sqrt(np.clip(np.diagonal(sel.mode_covariance, axis1=1, axis2=2), 0, None))
    np.testing.assert_allclose(d[:, 0], sel.frequency_std, rtol=1e-12)
    np.testing.assert_allclose(d[:, 2:26].T, sel.mode_shape_std_real, rtol=1e-12)
    assert np.all((sel.frequency_std > 0) & (sel.frequency_std < 0.02 * sel.frequency_hz))
    assert np.all(np.isfinite(sel.mode_shape_std_real))
    # every setup found every mode; the table and the DataFrame work as for one record
    assert np.all(poser.mode_index >= 0)
    assert "6 modes" in str(sel)
    assert list(sel.to_dataframe().index) == [1, 2, 3, 4, 5, 6]
    # each global shape is the basis setup's (the first that has the mode), read at its shape order
    for t in range(sel.n_modes):
        b = int(np.flatnonzero(poser.mode_index[:, t] >= 0)[0])
        assert sel.shape_order[t] == poser.setup_modes[b].shape_order[poser.mode_index[b, t]]
    assert sel.settings == poser.setup_modes[0].settings
    assert "(orders " + ", ".join(str(int(o)) for o in sel.shape_order) + ")" in str(sel)
    # the intervals take the fewest blocks of a setup (each setup's the core's count of its record)
    fewest = min(res.n_blocks for res in poser.setups)
    assert sel.n_blocks == fewest >= 2 and f"(Student t of {fewest} blocks)" in str(sel)
    assert not poser.reference_check.rejected.any()


def test_poser_f_is_the_inverse_variance_mean_of_the_setups(poser):
    sel = poser.select_modes()
    for t in range(sel.n_modes):
        f, w = [], []
        for j, s in enumerate(poser.setup_modes):
            i = poser.mode_index[j, t]
            f.append(s.frequency_hz[i])
            w.append(1.0 / s.mode_covariance[i, 0, 0])
        assert sel.frequency_hz[t] == pytest.approx(np.dot(w, f) / np.sum(w), rel=1e-13)
        assert sel.frequency_std[t] == pytest.approx(np.sum(w) ** -0.5, rel=1e-10)
        # the merged σ_f is below every setup's
        assert sel.frequency_std[t] < min(np.asarray(w) ** -0.5)


def test_poser_and_modular_agree(campaign, poser):
    res = modaluq.identify_setups(_frames(campaign), fs=campaign.fs, references=["L3", "R8"], **KW)
    mod = res.select_modes()
    assert mod.output_names == poser.select_modes().output_names
    sel = poser.select_modes()
    np.testing.assert_allclose(mod.frequency_hz, sel.frequency_hz, rtol=0.01)
    mac = modaluq.modal_assurance_criterion(mod.mode_shape, sel.mode_shape)
    assert np.all(np.diag(mac) > 0.99)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["modular", "poser"])
def test_a_mislabelled_reference_is_named(method, campaign):
    with pytest.warns(modaluq.ReferenceMismatchWarning) as record:
        modaluq.identify_setups(_frames(campaign, swap_in=3), fs=campaign.fs, references=["L3", "R8"],
                                method=method, **KW)
    msgs = [str(w.message) for w in record if issubclass(w.category, modaluq.ReferenceMismatchWarning)]
    assert len(msgs) == 1 and msgs[0].startswith("setup 3:"), msgs  # one warning, naming the setup
    assert "'L3' or 'R8'" in msgs[0] and "chi2 = " in msgs[0] and "6 mode(s)" in msgs[0]
    assert any(n.startswith("T") for n in campaign.mode_names)  # torsion modes: L and R of opposite sign


@pytest.mark.slow
def test_a_mislabelled_basis_setup_is_named(campaign):
    # setup 0 is every mode's basis: every other setup disagrees with it, so it is the suspect
    with pytest.warns(modaluq.ReferenceMismatchWarning) as record:
        out = modaluq.identify_setups(_frames(campaign, swap_in=0), fs=campaign.fs, references=["L3", "R8"],
                                      method="poser", **KW)
    msgs = [str(w.message) for w in record if issubclass(w.category, modaluq.ReferenceMismatchWarning)]
    assert len(msgs) == 1 and msgs[0].startswith("setup 0:") and "every other setup" in msgs[0], msgs
    assert list(out.reference_check.suspects()) == [0]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 12, 13])
def test_a_correct_campaign_is_silent(seed):
    camp = _campaign(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("error", modaluq.ReferenceMismatchWarning)
        out = modaluq.identify_setups(_frames(camp), fs=camp.fs, references=["L3", "R8"], method="poser", **KW)
    assert out.reference_check.n_tests >= 5 * 5
    assert np.nanmin(out.reference_check.p_value) > modaluq.poser.REFERENCE_TEST_LEVEL / out.reference_check.n_tests


def test_method_is_checked(campaign):
    with pytest.raises(ValueError, match="method must be 'modular' or 'poser'"):
        modaluq.identify_setups(_frames(campaign), fs=campaign.fs, references=["L3", "R8"], method="PoSER", **KW)


def test_poser_selects_each_setup_with_the_clustering_and_criteria_given(campaign, poser):
    # The shapes of the representatives (the choice before the lowest sufficient order), and a
    # looser frequency criterion: each setup is selected with them, and the merge carries them.
    clustering = modaluq.ClusteringSettings(shape_representative="median")
    criteria = modaluq.StabilityCriteria(max_frequency_change=0.02)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ReferenceMismatchWarning)
        out = modaluq.identify_setups(_frames(campaign), fs=campaign.fs, references=["L3", "R8"], method="poser",
                                      criteria=criteria, clustering=clustering, **KW)
    for res, sel in zip(out.setups, out.setup_modes):
        expected = res.select_modes(criteria, clustering)
        np.testing.assert_array_equal(sel.frequency_hz, expected.frequency_hz)
        np.testing.assert_array_equal(sel.shape_pole, expected.representative_pole)
    assert out.select_modes().settings == out.setup_modes[0].settings
    assert out.select_modes().settings != poser.select_modes().settings
    # the criteria reached the diagrams: a looser frequency change lets more poles be stable
    assert sum(int(np.sum(sel.n_poles)) for sel in out.setup_modes) != sum(
        int(np.sum(sel.n_poles)) for sel in poser.setup_modes)


def test_a_merged_mode_is_flagged_where_any_setups_mode_was_widened(poser):
    sel = poser.select_modes()
    for t in range(sel.n_modes):
        expected = any(bool(s.order_discrepancy[poser.mode_index[j, t]]) for j, s in enumerate(poser.setup_modes)
                       if poser.mode_index[j, t] >= 0)
        assert sel.order_discrepancy[t] == expected


def test_selection_settings_are_refused_by_name_where_they_do_not_apply(campaign):
    args = dict(fs=campaign.fs, references=["L3", "R8"], **KW)
    with pytest.raises(ValueError, match="clustering: only with method='poser'"):
        modaluq.identify_setups(_frames(campaign), clustering=modaluq.ClusteringSettings(), **args)
    with pytest.raises(ValueError, match="criteria: only with method='poser'"):
        modaluq.identify_setups(_frames(campaign), criteria=modaluq.StabilityCriteria(), **args)
    with pytest.raises(TypeError, match="clustering must be a modaluq.ClusteringSettings"):
        modaluq.identify_setups(_frames(campaign), method="poser", clustering={"linkage": "single"}, **args)
    with pytest.raises(TypeError, match="criteria must be a modaluq.StabilityCriteria"):
        modaluq.identify_setups(_frames(campaign), method="poser", criteria=0.01, **args)


@pytest.mark.parametrize("io", [False, True])
def test_core_merge_equals_the_numpy_reference(io):
    # The NumPy reference's PoSER (factor form (12.10), oracle_multisetup.identify_poser) against
    # the core's poser_merge (covariance form (12.12)) fed with the same per-setup modes.
    kw = {"input_dofs": ("L5",), "input_std": 3.0, "unknown_input_std": 0.5} if io else {}
    c = simulate_campaign(5, durations=(60.0, 80.0, 70.0), roving=DEFAULT_ROVING[:3], **kw)
    setups = om.prepare_setups([(s.y, s.u if io else None) for s in c.setups], 8, 8, 10,
                               [s.references for s in c.setups])
    per = [om.identify_modular([st], fs=c.fs, p=8, orders=[12])[0][12] for st in setups]
    ref = om.identify_poser(setups, fs=c.fs, p=8, order=12, targets=per[0]["frequency_hz"])
    core = _core.poser_merge([_core.PoserSetupModes(r["frequency_hz"], r["damping_ratio"], r["mode_shape"],
                                                    np.stack([cv.reshape(-1, order="F") for cv in r["covariance"]],
                                                             axis=1), [0, 1]) for r in per])
    order = np.argsort(ref["frequency_hz"])
    assert len(core.frequency_hz) == len(order) == 6
    np.testing.assert_allclose(core.frequency_hz, ref["frequency_hz"][order], rtol=1e-12)
    np.testing.assert_allclose(core.damping_ratio, ref["damping_ratio"][order], rtol=1e-12)
    np.testing.assert_allclose(core.mode_shape, ref["mode_shape"][:, order], rtol=0, atol=1e-12)
    np.testing.assert_allclose(core.frequency_std, ref["frequency_std"][order], rtol=1e-10)
    np.testing.assert_allclose(core.damping_std, ref["damping_std"][order], rtol=1e-10)
    cov_ref = ref["covariance"][order]
    cov = np.stack([np.asarray(core.covariance)[:, t].reshape(cov_ref.shape[1:], order="F") for t in range(6)])
    assert np.max(np.abs(cov - cov_ref)) < 1e-10 * np.max(np.abs(cov_ref))
