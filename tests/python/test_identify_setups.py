"""modaluq.identify_setups: a campaign of DataFrames merged in the core (docs/uq-math.md §13)."""

import numpy as np
import pandas as pd
import pytest

import modaluq
from modaluq.simulate.campaign import simulate_campaign

ORDERS = list(range(2, 25, 2))


def _frames(camp, io=False):
    return camp.frames(input_names=["F5"] if io else ())


@pytest.fixture(scope="module")
def campaign():
    return simulate_campaign(4, durations=(120.0, 140.0, 110.0, 130.0, 150.0, 120.0))


def test_global_dofs_and_modes(campaign):
    res = modaluq.identify_setups(_frames(campaign), fs=campaign.fs, references=["L3", "R8"],
                                  block_rows=15, orders=ORDERS, n_blocks=12)
    expected = ["L3", "R8"] + [c for s in campaign.setups for c in s.channels[2:]]
    assert list(res.output_names) == expected
    assert sorted(res.output_names) == sorted(campaign.dofs)
    m = res.at_order(12)
    assert m.mode_shape.shape[0] == 24
    # the true order: six modes near the truth, global shapes with MAC >= 0.99 over all 24 DOFs
    truth = campaign.mode_shape[[campaign.dofs.index(n) for n in res.output_names]]
    for k, f0 in enumerate(campaign.frequency_hz):
        i = int(np.argmin(np.abs(m.frequency_hz - f0)))
        assert abs(m.frequency_hz[i] / f0 - 1) < 0.02
        phi = m.mode_shape[:, i]
        mac = abs(np.vdot(truth[:, k], phi)) ** 2 / (np.vdot(phi, phi).real * truth[:, k] @ truth[:, k])
        assert mac > 0.99, (k, mac)
        assert 0 < m.frequency_std[i] < 0.05 * f0
    # the diagram and the selection run on the merged result as on one record
    sel = res.select_modes()
    assert len(sel.frequency_hz) == 6
    assert np.all(np.abs(sel.frequency_hz / campaign.frequency_hz - 1) < 0.01)


def test_input_output_campaign():
    camp = simulate_campaign(6, durations=(90.0, 100.0, 80.0), roving=(("L1", "L2", "L4", "L5"),
                             ("L6", "L7", "L8", "L9"), ("R2", "R3", "R4", "R5")),
                             input_dofs=("L5",), input_std=3.0, unknown_input_std=0.5)
    res = modaluq.identify_setups(_frames(camp, io=True), fs=camp.fs, references=["L3", "R8"], inputs=["F5"],
                                  block_rows=10, orders=[12], n_blocks=12)
    assert res.n_inputs == 1
    assert "F5" not in res.output_names
    m = res.at_order(12)
    assert np.all(np.abs(m.frequency_hz[:, None] - camp.frequency_hz[None]).min(axis=0) / camp.frequency_hz < 0.02)


def test_refusals(campaign):
    frames = _frames(campaign)[:3]
    with pytest.raises(ValueError, match=r"setup 1 lacks the reference channel\(s\) \['R8'\]"):
        modaluq.identify_setups([frames[0], frames[1].drop(columns="R8"), frames[2]], fs=campaign.fs,
                                references=["L3", "R8"], block_rows=10, orders=[12], n_blocks=12)
    with pytest.raises(ValueError, match="setup 2 has fs = 50.0 Hz"):
        modaluq.identify_setups(frames, fs=[25.0, 25.0, 50.0], references=["L3", "R8"], block_rows=10,
                                orders=[12], n_blocks=12)
    with pytest.raises(ValueError, match="above what the merge supports"):
        modaluq.identify_setups(frames, fs=campaign.fs, references=["L3", "R8"], block_rows=4, orders=[12],
                                n_blocks=12)
    with pytest.raises(ValueError, match="channel 'L1' is measured in setups 0 and 1"):
        modaluq.identify_setups([frames[0], frames[0]], fs=campaign.fs, references=["L3", "R8"], block_rows=10,
                                orders=[12], n_blocks=12)
    with pytest.raises(ValueError, match="block_correlation_correction applies to one record"):
        modaluq.identify_setups(frames, fs=campaign.fs, references=["L3", "R8"], block_rows=10, orders=[12],
                                n_blocks=12, block_correlation_correction=True)


# --------------------------------------------------------------------------- recordings, files, campaigns

SMALL = dict(block_rows=10, orders=[12], n_blocks=12)
SMALL_DIAGRAM = dict(block_rows=10, orders=list(range(2, 21, 2)), n_blocks=12)


def _recordings(camp, io=False):
    from modaluq.io import Recording

    return [Recording(y=s.y, u=s.u if io else None, fs=camp.fs, output_names=s.channels,
                      input_names=("F5",) if io else (), source=f"rec{j}") for j, s in enumerate(camp.setups)]


def _write_csvs(camp, folder, n=3):
    paths = []
    for j, s in enumerate(camp.setups[:n]):
        t = np.arange(s.y.shape[0]) / camp.fs
        p = folder / f"s{j}.csv"
        np.savetxt(p, np.column_stack([t, s.y]), delimiter=",", header=",".join(["time", *s.channels]),
                   comments="", fmt="%.10g")
        paths.append(p)
    return paths


def test_recordings_and_files_give_the_dataframes_result(campaign, tmp_path):
    frames = _frames(campaign)[:3]
    ref = modaluq.identify_setups(frames, fs=campaign.fs, references=["L3", "R8"], **SMALL)
    # Recordings carry their rate: fs may be left out
    recs = _recordings(campaign)[:3]
    by_rec = modaluq.identify_setups(recs, references=["L3", "R8"], **SMALL)
    assert by_rec.output_names == ref.output_names
    np.testing.assert_allclose(by_rec.at_order(12).frequency_hz, ref.at_order(12).frequency_hz, rtol=1e-12)
    np.testing.assert_allclose(by_rec.at_order(12).frequency_std, ref.at_order(12).frequency_std, rtol=1e-12)
    # files (CSV with a time column: their own rate), mixed with a DataFrame given fs
    paths = _write_csvs(campaign, tmp_path)
    mixed = modaluq.identify_setups([paths[0], str(paths[1]), frames[2]], fs=campaign.fs, references=["L3", "R8"],
                                    **SMALL)
    assert mixed.output_names == ref.output_names
    np.testing.assert_allclose(mixed.at_order(12).frequency_hz, ref.at_order(12).frequency_hz, rtol=1e-6)


def test_recording_inputs_are_inputs():
    camp = simulate_campaign(6, durations=(90.0, 100.0, 80.0), roving=(("L1", "L2", "L4", "L5"),
                             ("L6", "L7", "L8", "L9"), ("R2", "R3", "R4", "R5")),
                             input_dofs=("L5",), input_std=3.0, unknown_input_std=0.5)
    by_frames = modaluq.identify_setups(_frames(camp, io=True), fs=camp.fs, references=["L3", "R8"],
                                        inputs=["F5"], **SMALL)
    by_recs = modaluq.identify_setups(_recordings(camp, io=True), references=["L3", "R8"], **SMALL)
    assert by_recs.n_inputs == 1 and by_recs.output_names == by_frames.output_names
    np.testing.assert_allclose(by_recs.at_order(12).frequency_hz, by_frames.at_order(12).frequency_hz, rtol=1e-12)


def test_rates_and_types_are_checked_per_setup(campaign):
    from modaluq.io import Recording

    recs = _recordings(campaign)[:3]
    odd = Recording(y=recs[1].y, u=None, fs=50.0, output_names=recs[1].output_names, source="odd.csv")
    with pytest.raises(ValueError, match=r"setup 1 \(odd.csv\) is sampled at 50 Hz but fs = 25 Hz"):
        modaluq.identify_setups([recs[0], odd, recs[2]], fs=25.0, references=["L3", "R8"], **SMALL)
    with pytest.raises(ValueError, match=r"setup 1 \(odd.csv\) has fs = 50.0 Hz but setup 0 \(rec0\) has 25.0"):
        modaluq.identify_setups([recs[0], odd, recs[2]], references=["L3", "R8"], **SMALL)
    with pytest.raises(ValueError, match="setup 2 is a DataFrame, which carries no rate: give fs"):
        modaluq.identify_setups([recs[0], recs[1], _frames(campaign)[2]], references=["L3", "R8"], **SMALL)
    with pytest.raises(TypeError, match="setup 1 must be a pandas.DataFrame .* got ndarray"):
        modaluq.identify_setups([recs[0], recs[1].y], references=["L3", "R8"], **SMALL)
    with pytest.raises(TypeError, match="single DataFrame"):
        modaluq.identify_setups(_frames(campaign)[0], fs=25.0, references=["L3", "R8"], **SMALL)
    with pytest.raises(TypeError, match="campaign file"):
        modaluq.identify_setups("setup1.csv", fs=25.0, references=["L3", "R8"], **SMALL)
    with pytest.raises(TypeError, match="references"):
        modaluq.identify_setups(recs, **SMALL)
    twice = pd.concat([_frames(campaign)[0], _frames(campaign)[0][["L1"]]], axis=1)
    with pytest.raises(ValueError, match="setup 0 has more than one channel named 'L1'"):
        modaluq.identify_setups([twice], fs=25.0, references=["L3", "R8"], **SMALL)


def test_a_campaign_file_is_a_setups_argument(campaign, tmp_path):
    from modaluq.io import load_campaign

    _write_csvs(campaign, tmp_path)
    (tmp_path / "c.toml").write_text(
        'references = ["L3", "R8"]\nfs = 25.0\n[settings]\nblock_rows = 10\norders = [12]\nn_blocks = 12\n'
        + "".join(f'[[setup]]\nfile = "s{j}.csv"\n' for j in range(3)))
    ref = modaluq.identify_setups(_frames(campaign)[:3], fs=campaign.fs, references=["L3", "R8"], **SMALL)
    by_path = modaluq.identify_setups(tmp_path / "c.toml")
    by_obj = modaluq.identify_setups(load_campaign(tmp_path / "c.toml"), orders=[10, 12])  # keywords win
    assert by_path.output_names == ref.output_names == by_obj.output_names
    np.testing.assert_allclose(by_path.at_order(12).frequency_hz, ref.at_order(12).frequency_hz, rtol=1e-6)
    assert list(by_obj.orders) == [10, 12]
    (tmp_path / "bad.toml").write_text('references = ["L3", "R8"]\n[settings]\nblok_rows = 10\n'
                                       '[[setup]]\nfile = "s0.csv"\n')
    with pytest.raises(ValueError, match=r"bad.toml: \[settings\]: .*'blok_rows'"):
        modaluq.identify_setups(tmp_path / "bad.toml")


def _reliable(diagram, members):
    """The members whose σ the selection uses: not at a close cut, not noise-coupled, finite σ."""
    m = np.asarray(members)
    keep = ~(diagram.close_singular_values[m] | diagram.noise_coupled[m])
    keep &= np.isfinite(diagram.frequency_std[m]) & np.isfinite(diagram.damping_std[m])
    return m[keep]


def test_the_merged_selection_reports_the_sigma_of_the_cluster_mean(campaign):
    """identify_setups' selection: σ of the mean of the reliable members (docs/uq-math.md §13.10),
    the value, the clusters and the shapes' σ unchanged; the same by every path (Result,
    Diagram, modaluq.select_modes)."""
    res = modaluq.identify_setups(_frames(campaign), fs=campaign.fs, references=["L3", "R8"],
                                  block_rows=15, orders=ORDERS, n_blocks=12)
    diagram = res.stabilization_diagram()
    sel = res.select_modes()
    median = diagram.select_modes(cluster_std="median")
    median_at_rep = diagram.select_modes(cluster_std="median", shape_representative="median")
    assert sel.settings.cluster_std == "mean" and median.settings.cluster_std == "median"
    assert "of the mean over the cluster" in str(sel)
    for other in (diagram.select_modes(), modaluq.select_modes(diagram), diagram.select_modes(cluster_std="mean")):
        np.testing.assert_array_equal(other.frequency_std, sel.frequency_std)
    assert sel.n_modes == median.n_modes >= 6
    np.testing.assert_array_equal(sel.representative_pole, median.representative_pole)
    np.testing.assert_array_equal(sel.frequency_hz, median.frequency_hz)
    np.testing.assert_array_equal(sel.mode_shape_std_real, median.mode_shape_std_real)
    rows = diagram.frequency_damping_factor
    assert rows.shape == (diagram.n_poles, 2, res.n_blocks)
    for k in range(sel.n_modes):
        reliable = _reliable(diagram, sel.members[k])
        u = rows[reliable].mean(axis=0)  # the mean's factor rows
        sf, sx = np.linalg.norm(u[0]), np.linalg.norm(u[1])
        assert sel.frequency_std[k] == pytest.approx(sf, rel=1e-12)
        assert sel.damping_std[k] == pytest.approx(sx, rel=1e-12)
        assert sel.frequency_damping_correlation[k] == pytest.approx(u[0] @ u[1] / (sf * sx), rel=1e-9, abs=1e-12)
        # the median run reports the median of the same poles' σ
        assert median.frequency_std[k] == np.median(diagram.frequency_std[reliable])
        # never above the members' mean σ (Cauchy-Schwarz)
        assert sf <= np.mean(diagram.frequency_std[reliable]) * (1 + 1e-12)
        # the mode's covariance: its [f, ξ] block is the mean's, the shape block the shape pole's
        # (by default the lowest sufficient member)
        cov, own = sel.mode_covariance[k], diagram.pole_covariance(sel.shape_pole[k])
        rho = sel.frequency_damping_correlation[k]
        np.testing.assert_allclose(cov[:2, :2], [[sf * sf, rho * sf * sx], [rho * sf * sx, sx * sx]], rtol=1e-9)
        np.testing.assert_array_equal(cov[2:, 2:], own[2:, 2:])
        np.testing.assert_allclose(cov[0, 2:], own[0, 2:] * sf / np.sqrt(own[0, 0]), rtol=1e-12)
        np.testing.assert_array_equal(median.mode_covariance[k][2:, 2:], own[2:, 2:])
        # with the shape read at the representative and the median σ, the representative's covariance
        np.testing.assert_array_equal(median_at_rep.mode_covariance[k],
                                      diagram.pole_covariance(sel.representative_pole[k]))
    # the merged poles decorrelate across orders: the mean's σ is mostly below one order's
    assert np.median(sel.frequency_std / median.frequency_std) < 1.0


def test_one_record_keeps_the_median(campaign):
    """identify's selection is unchanged: the median of the reliable members' σ, bit for bit, and
    the representative's f-ξ correlation; the covariance is the shape pole's with that [f, ξ]
    block, and the representative's own with shape_representative="median"."""
    s = campaign.setups[0]
    res = modaluq.identify(s.y, fs=campaign.fs, block_rows=15, orders=ORDERS, n_blocks=20)
    diagram = res.stabilization_diagram()
    sel = res.select_modes()
    at_rep = diagram.select_modes(shape_representative="median")
    assert sel.settings.cluster_std == "median"
    assert "median over the cluster" in str(sel)
    assert diagram.frequency_damping_factor.shape == (diagram.n_poles, 2, res.n_blocks)  # kept all the same
    assert sel.n_modes >= 3
    for k in range(sel.n_modes):
        reliable = _reliable(diagram, sel.members[k])
        assert sel.frequency_std[k] == np.median(diagram.frequency_std[reliable])
        assert sel.damping_std[k] == np.median(diagram.damping_std[reliable])
        rep = sel.representative_pole[k]
        assert sel.frequency_damping_correlation[k] == diagram.frequency_damping_correlation[rep]
        np.testing.assert_array_equal(at_rep.mode_covariance[k], diagram.pole_covariance(rep))
        shape_cov = diagram.pole_covariance(sel.shape_pole[k])
        np.testing.assert_array_equal(sel.mode_covariance[k][2:, 2:], shape_cov[2:, 2:])
        if sel.shape_pole[k] != rep:  # [f, ξ]: the mode's σ with the representative's correlation
            sf, sx, rho = sel.frequency_std[k], sel.damping_std[k], sel.frequency_damping_correlation[k]
            np.testing.assert_allclose(sel.mode_covariance[k][:2, :2], [[sf * sf, rho * sf * sx], [rho * sf * sx, sx * sx]],
                                       rtol=1e-12)
    assert np.any(sel.shape_pole != sel.representative_pole)
    # asked for, the mean is available for one record too
    mean = diagram.select_modes(cluster_std="mean")
    np.testing.assert_array_equal(mean.frequency_hz, sel.frequency_hz)
    assert not np.array_equal(mean.frequency_std, sel.frequency_std)


def test_factor_rows_survive_a_copy_of_the_result(campaign):
    """A Result without the core's identification (copied, unpickled) flattens its modes with
    their factor rows: the same selection."""
    import pickle

    res = modaluq.identify_setups(_frames(campaign)[:3], fs=campaign.fs, references=["L3", "R8"], **SMALL_DIAGRAM)
    copy = pickle.loads(pickle.dumps(res))
    assert copy.core_identification is None
    a, b = res.select_modes(), copy.select_modes()
    np.testing.assert_array_equal(a.frequency_std, b.frequency_std)
    assert b.settings.cluster_std == "mean"
    m = res.at_order(12)
    assert m.frequency_damping_factor.shape == (m.n_modes, 2, res.n_blocks)
    np.testing.assert_allclose(np.einsum("mik,mjk->mij", m.frequency_damping_factor, m.frequency_damping_factor),
                               m.covariance[:, :2, :2], rtol=1e-12, atol=1e-12 * np.max(m.covariance[:, :2, :2]))
