"""Issue 26, item 11: what a new user met. Modes with no reliable pole flagged everywhere they
appear; a plot refusing a record other than the one identified; the low signal-to-noise warning
changing the table; dead channels named; records too short for any identification refused."""

import json
import pathlib
import warnings

import numpy as np
import pytest

import modaluq
from modaluq import Analysis, ModalUQWarning, Settings, export
from modaluq.cli import main
from modaluq.preprocess import preprocess

DATA = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data"
if not DATA.is_dir():
    DATA = pathlib.Path("/work/shared/data")
SLAB = DATA / "cessipy_smartphone_slab.npz"
PAINTER = DATA / "cesmd_painter_st_overpass_2016.npz"


def _needs(path):
    if not path.exists():
        pytest.skip(f"{path.name} (shared/data) is not here")


@pytest.fixture(scope="module")
def slab():
    """The slab's vertical channel, recommended slice, band 10-30 Hz (docs/settings.md): the 14.9
    and 21.9 Hz columns have every pole noise-coupled, the 17.8 Hz mode does not."""
    _needs(SLAB)
    raw = np.load(SLAB)["y"][2000:18384, 2]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModalUQWarning)
        result = modaluq.identify(raw, fs=425.08, frequency_range=(10.0, 30.0))
    diagram = result.stabilization_diagram()
    return raw, result, diagram, diagram.select_modes()


# --------------------------------------------------------------------------- 1. noise-coupled modes


def test_a_mode_whose_poles_are_all_noise_coupled_is_flagged_from_the_diagrams_flags(slab):
    _, _, diagram, sel = slab
    np.testing.assert_allclose(sel.frequency_hz, [14.91, 17.80, 21.90], atol=0.01)  # the selection is unchanged
    expected = [bool(diagram.noise_coupled[m].all()) for m in sel.members]
    assert sel.noise_coupled.tolist() == expected == [True, False, True]


def test_the_flag_shows_in_the_table_the_dataframe_and_every_export(slab, tmp_path):
    _, _, diagram, sel = slab
    rows = str(sel).splitlines()[2:5]
    assert [r.endswith("noise?") for r in rows] == [True, False, True]
    assert sel.NOISE_COUPLED_LEGEND in str(sel)
    assert sel.to_dataframe()["noise_coupled"].tolist() == [True, False, True]
    report = export.report(diagram, sel)
    assert [m["noise_coupled"] for m in report["modes"]] == [True, False, True]
    export.write_csv(tmp_path / "modes.csv", sel)
    assert "noise_coupled" in (tmp_path / "modes.csv").read_text().splitlines()[0]
    pytest.importorskip("xarray")
    ds = diagram.to_xarray(sel)
    assert ds["selected_noise_coupled"].values.tolist() == [1, 0, 1]


def test_no_marker_and_no_legend_when_no_mode_is_flagged(chain):
    sel = modaluq.identify(chain.y, fs=chain.fs, block_rows=21, orders=range(2, 41, 2)).select_modes()
    if sel.noise_coupled.any():
        pytest.skip("a mode of this chain is noise-coupled")
    assert "noise?" not in str(sel) and sel.NOISE_COUPLED_LEGEND not in str(sel)


# --------------------------------------------------------------------------- 2. the plot's record


def test_plot_refuses_the_raw_record_of_a_decimated_identification(slab):
    raw, result, _, _ = slab
    assert result.settings["preprocessing"]["decimation"] > 1
    with pytest.raises(ValueError, match=r"y has 16384 samples .* 4096 samples .*preprocessed"):
        result.plot(y=raw)
    pre = preprocess(raw, fs=425.08, frequency_range=(10.0, 30.0))
    fig = result.plot(y=pre.y)  # the record identified: drawn
    assert len(fig.axes) == 2


# --------------------------------------------------------------------------- 3. low signal-to-noise


def test_a_low_signal_to_noise_warning_changes_the_mode_table():
    _needs(PAINTER)
    d = np.load(PAINTER)
    a = Analysis.from_arrays(d["y"], fs=float(d["fs"])).run(check_harmonics=False, issue_warnings=False)
    assert a.result.low_signal_to_noise and any("cannot be told from noise" in w for w in a.warnings)
    assert a.selected.low_signal_to_noise
    heading = str(a.selected).splitlines()[0]
    assert "cannot be told from noise" in heading
    assert "cannot be told from noise" in a.describe_modes().splitlines()[0]
    report = export.report(a.diagram, a.selected)
    assert report["low_signal_to_noise"] is True
    assert a.selected.to_dataframe()["low_signal_to_noise"].all()


def test_no_such_heading_when_the_signal_is_above_the_noise(slab):
    _, result, _, sel = slab
    assert not result.low_signal_to_noise and not sel.low_signal_to_noise
    assert "cannot be told from noise" not in str(sel)


# --------------------------------------------------------------------------- 4. dead channels


def test_a_dead_channel_is_named(chain_10k):
    y = chain_10k.y.copy()
    y[:, 1] = 0.0
    with pytest.warns(ModalUQWarning, match=r"output channel 'acc2' .* is constant"):
        modaluq.identify(y, fs=chain_10k.fs, block_rows=10, orders=range(2, 21, 2),
                         output_names=["acc1", "acc2", "acc3"])
    a = Analysis.from_arrays(y, fs=chain_10k.fs, output_names=["acc1", "acc2", "acc3"],
                             settings=Settings(block_rows=10, orders=range(2, 21, 2)))
    a.run(check_harmonics=False, issue_warnings=False)
    assert any("'acc2'" in w and "constant" in w for w in a.warnings)


@pytest.mark.parametrize("n_samples", [1, 2, 63, 64, 65, 1000, 4097])
def test_constant_channels_equal_the_sample_by_sample_comparison(n_samples):
    # the fast path looks at 64 spread rows first: a channel that differs only between them
    # (or only in its last sample) must not be called constant
    from modaluq.checks import constant_channels

    rng = np.random.default_rng(n_samples)
    x = rng.standard_normal((n_samples, 6))
    x[:, 1] = 3.0
    x[:, 2] = 0.0
    x[:, 3] = -1.5
    x[n_samples // 2 + (1 if n_samples > 2 else 0) - 1, 3] = -1.5 + 1e-12  # one sample off, between the spread rows
    x[:, 4] = 7.0
    x[-1, 4] = np.nan
    reference = np.flatnonzero(np.all(x == x[:1], axis=0)).tolist()
    assert constant_channels(x) == reference
    assert set(reference) >= {1, 2} and 4 not in reference


def test_a_record_of_dead_channels_is_refused(chain_10k):
    y = np.full((chain_10k.y.shape[0], 3), 2.5)
    with pytest.raises(ValueError, match="every output is constant"):
        modaluq.identify(y, fs=chain_10k.fs, block_rows=10, orders=range(2, 21, 2))


def test_the_command_line_names_a_dead_channel(chain_10k, tmp_path, capsys):
    y = chain_10k.y.copy()
    y[:, 2] = 0.0
    path = tmp_path / "dead.csv"
    np.savetxt(path, y, delimiter=",", header="a,b,dead", comments="", fmt="%.10g")
    assert main(["identify", str(path), "--fs", str(chain_10k.fs), "--block-rows", "10", "--orders", "2:20:2",
                 "--no-progress"]) == 0
    assert "'dead'" in capsys.readouterr().err


# --------------------------------------------------------------------------- 5. short records


@pytest.mark.parametrize("n_outputs,minimum", [(1, 209), (3, 79)])
def test_a_record_too_short_for_any_identification_is_refused(chain_10k, n_outputs, minimum):
    y = chain_10k.y[:20, :n_outputs]
    with pytest.raises(ValueError, match=rf"20 samples, too short .* at least {minimum} are needed"):
        modaluq.identify(y, fs=chain_10k.fs)
    with pytest.raises(ValueError, match=f"at least {minimum}"):
        Analysis.from_arrays(y, fs=chain_10k.fs).run(check_harmonics=False, issue_warnings=False)
    modaluq.identify(chain_10k.y[:minimum, :n_outputs], fs=chain_10k.fs)  # the minimum itself is identified


def test_the_command_line_refuses_a_20_sample_record_in_one_line(chain_10k, tmp_path, capsys):
    path = tmp_path / "short.csv"
    np.savetxt(path, chain_10k.y[:20], delimiter=",", header="a,b,c", comments="", fmt="%.10g")
    assert main(["identify", str(path), "--fs", str(chain_10k.fs), "--no-progress"]) == 2
    assert "too short for any identification" in capsys.readouterr().err


def test_export_json_carries_both_flags(slab, tmp_path):
    _, _, diagram, sel = slab
    out = json.loads(export.write_json(tmp_path / "m.json", diagram, sel).read_text())
    assert [m["noise_coupled"] for m in out["modes"]] == [True, False, True]
    assert out["low_signal_to_noise"] is False
