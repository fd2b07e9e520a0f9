"""Preprocessing (window, band, anti-aliased decimation, detrend, high-pass) and the settings
chosen from the data (docs/settings.md), in the library and the command line."""

import json
import math
import pathlib

import numpy as np
import pytest

import modaluq
from modaluq import PoleStatus
from modaluq.auto_settings import (
    BLOCK_SPAN,
    CENTRE_PERIODS,
    LAG_PERIODS,
    MAX_BLOCKS,
    MAX_ROWS,
    choose_settings,
    lag_warning,
)
from modaluq.cli import main
from modaluq.preprocess import decimation_factor, preprocess

DATA = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data"


def tone(f, fs, n, amplitude=1.0):
    return amplitude * np.sin(2 * np.pi * f * np.arange(n) / fs)


# --------------------------------------------------------------------------- preprocessing


def test_window_in_seconds_and_what_was_done_is_recorded():
    y = np.random.default_rng(0).standard_normal((10_000, 2))
    p = preprocess(y, fs=100.0, start=10.0, stop=60.0)
    assert p.n_samples == 5_000 and p.first_sample == 1_000 and p.fs == 100.0 and p.decimation == 1
    np.testing.assert_array_equal(p.y, y[1_000:6_000])
    assert (p.start_s, p.stop_s) == (10.0, 60.0)
    assert p.settings()["steps"] == ["window 10-60 s of 100 s"]


@pytest.mark.parametrize("kw,exc,name", [
    (dict(start=200.0), ValueError, "start"),
    (dict(start=50.0, stop=20.0), ValueError, "stop"),
    (dict(frequency_range=(5.0, 60.0)), ValueError, "Nyquist"),
    (dict(frequency_range=(20.0, 5.0)), ValueError, "f_low < f_high"),
    (dict(frequency_range=3.0), TypeError, "frequency_range"),
    (dict(frequency_range=(1.0, 20.0), decimate=3), ValueError, "decimate"),
    (dict(detrend="quadratic"), ValueError, "detrend"),
    (dict(highpass=60.0), ValueError, "highpass"),
    (dict(decimate=0), ValueError, "decimate"),
])
def test_bad_preprocessing_names_the_parameter(kw, exc, name):
    with pytest.raises(exc, match=name):
        preprocess(np.zeros((10_000, 1)) + tone(3.0, 100.0, 10_000)[:, None], fs=100.0, **kw)


def test_decimation_is_anti_aliased_and_keeps_the_band():
    fs, n = 1000.0, 200_000
    band = (1.0, 20.0)
    q = decimation_factor(fs, band[1])
    assert q == math.floor(fs / (3 * band[1])) == 16
    inside, alias = tone(15.0, fs, n), tone(480.0, fs, n)   # 480 Hz would fold to 20 Hz at 62.5 Hz
    p = preprocess(np.column_stack([inside, alias]), fs=fs, frequency_range=band)
    assert p.decimation == q and p.fs == fs / q
    body = slice(200, -200)  # away from the filter's start-up at the ends
    rms = np.sqrt(np.mean(p.y[body] ** 2, axis=0))
    assert abs(rms[0] / np.sqrt(0.5) - 1) < 0.01           # the band passes unchanged
    assert rms[1] / np.sqrt(0.5) < 1e-2                     # what would alias is suppressed by > 40 dB


def test_inputs_are_processed_like_the_outputs():
    """The same linear filter on y and u: y = 2 u stays exactly so (an input/output relation)."""
    u = np.random.default_rng(1).standard_normal((20_000, 1))
    p = preprocess(2.0 * u, u, fs=200.0, frequency_range=(1.0, 20.0), highpass=0.5, detrend="linear")
    assert p.decimation == 3 and p.u.shape == p.y.shape
    np.testing.assert_allclose(p.y, 2.0 * p.u, rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------- settings from the data


def test_lags_span_two_periods_of_the_band_and_blocks_half_a_decay_time():
    # a wide band (f_high / f_low >= 25): two periods of f_low are the longer of the two spans
    s = choose_settings(100_000, 100.0, 1, frequency_range=(1.0, 30.0))
    assert s.block_rows == math.ceil(LAG_PERIODS * 100.0 / 1.0) == 200
    assert s.orders == tuple(range(2, 101, 2))
    decay = 1 / (2 * np.pi * 1.0 * 0.01)
    assert s.n_blocks == min(int((100_000 / 100.0) // (0.5 * decay)), MAX_BLOCKS)
    assert len(s.reasons) == 3 and "2 periods of f_low = 1 Hz" in s.reasons[0]


def test_lags_of_a_narrow_band_span_ten_periods_of_its_centre():
    """The smartphone slab's band 10-30 Hz at 106 Hz: 2 periods of 10 Hz are 22 rows, 10 periods of
    the centre sqrt(10 * 30) = 17.3 Hz are 62; the longer wins (docs/settings.md: the 17.2 and
    17.8 Hz modes are resolved from about 60 rows on)."""
    s = choose_settings(16_384, 106.25, 3, frequency_range=(10.0, 30.0))
    assert s.block_rows == math.ceil(CENTRE_PERIODS * 106.25 / math.sqrt(10.0 * 30.0)) == 62
    assert "10 periods of the band's centre 17.3 Hz" in s.reasons[0]
    # without a band only the first rule counts: f_low = fs / 20, two periods = 40 rows
    assert choose_settings(16_384, 106.25, 3).block_rows == 40


def test_settings_are_capped_by_the_size_of_h_and_the_record():
    many = choose_settings(100_000, 50.0, 20, frequency_range=(0.2, 20.0))
    assert many.block_rows == MAX_ROWS // 20 and "capped" in many.reasons[0]
    short = choose_settings(4_000, 50.0, 3, frequency_range=(0.2, 20.0))
    assert short.block_rows * 2 * BLOCK_SPAN * short.n_blocks <= 4_000
    assert "holds" in short.reasons[0]
    given = choose_settings(100_000, 50.0, 3, frequency_range=(1.0, 20.0), block_rows=30, n_blocks=7)
    assert (given.block_rows, given.n_blocks) == (30, 7) and len(given.reasons) == 1  # only the orders chosen


def test_a_horizon_shorter_than_one_period_of_the_band_is_a_warning_with_the_number():
    assert lag_warning(40, 50.0, (2.0, 20.0)) is None
    msg = lag_warning(20, 425.0, (10.0, 30.0))
    assert "block_rows >= 43" in msg and "less than one period" in msg
    sim = modaluq.simulate(20_000, seed=3)
    with pytest.warns(modaluq.ModalUQWarning, match="block_rows >= 50"):
        modaluq.identify(sim.y, fs=sim.fs, frequency_range=(1.0, 20.0), block_rows=10, orders=[6])


def test_identify_with_only_fs_and_a_band():
    sim = modaluq.simulate(40_000, seed=7, fs=200.0)
    r = modaluq.identify(sim.y, sim.u, fs=sim.fs, frequency_range=(1.0, 20.0))
    assert r.fs == 200.0 / 3 and r.settings["preprocessing"]["decimation"] == 3
    assert r.settings["frequency_range"] == [1.0, 20.0] and len(r.settings["chosen"]) == 3
    sel = r.stabilization_diagram().select_modes()
    _all_found(sel.frequency_hz, sim.frequency_hz)


def _all_found(found, true, rtol=0.01):
    """Every true mode has a selected mode within rtol. (A spurious column can still be selected
    beside them: σ-aware selection is issue 12's next step.)"""
    found = np.asarray(found)
    for f in true:
        assert np.min(np.abs(found - f)) <= rtol * f, (f, found)


def test_poles_outside_the_band_are_rejected_with_the_reason_and_the_plot_follows_the_band():
    sim = modaluq.simulate(20_000, seed=3)
    r = modaluq.identify(sim.y, sim.u, fs=sim.fs, frequency_range=(4.0, 10.0), block_rows=20, orders=range(2, 31, 2))
    d = r.stabilization_diagram()
    outside = (d.frequency_hz < 4.0) | (d.frequency_hz > 10.0)
    assert outside.any() and all(d.status[i] is PoleStatus.REJECTED for i in np.flatnonzero(outside))
    assert all(d.reason[i].startswith("outside the band 4-10 Hz") for i in np.flatnonzero(outside))
    sel = d.select_modes()
    np.testing.assert_allclose(sel.frequency_hz, sim.frequency_hz[(sim.frequency_hz > 4) & (sim.frequency_hz < 10)],
                               rtol=0.01)
    pytest.importorskip("matplotlib")
    assert d.plot().axes[0].get_xlim() == (4.0, 10.0)


@pytest.mark.skipif(not (DATA / "ssicov_lysefjord_bridge_sim.npz").exists(), reason="shared records not present")
def test_bridge_record_with_only_fs_and_a_band_finds_its_six_modes():
    d = np.load(DATA / "ssicov_lysefjord_bridge_sim.npz")
    r = modaluq.identify(d["y"], fs=float(d["fs"]), frequency_range=(0.15, 1.5))
    sel = r.stabilization_diagram().select_modes()
    np.testing.assert_allclose(sel.frequency_hz, d["fn_ref_discrete_hz"], rtol=0.01)  # six, none spurious


def test_cli_band_window_and_automatic_settings(tmp_path, capsys):
    sim = modaluq.simulate(30_000, seed=2, fs=200.0)
    path = tmp_path / "rec.npz"
    np.savez(path, y=sim.y, u=sim.u, fs=sim.fs)
    out = tmp_path / "modes.json"
    rc = main(["identify", str(path), "--frequency-range", "1", "20", "--start", "10", "--no-progress",
               "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "decimated by 3" in captured.out and "chosen: block_rows" in captured.out
    report = json.loads(out.read_text())
    settings = report["stamp"]["settings"]
    pre = settings.get("preprocessing") or settings["identification"]["preprocessing"]
    assert pre["decimation"] == 3 and pre["start_s"] == 10.0
    _all_found([m["frequency_hz"] for m in report["modes"]], sim.frequency_hz)


def test_cli_bad_band_exits_2_naming_it(tmp_path, capsys):
    path = tmp_path / "rec.npz"
    np.savez(path, y=np.random.default_rng(0).standard_normal((5_000, 2)), fs=50.0)
    rc = main(["identify", str(path), "--frequency-range", "5", "40", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and "--frequency-range upper edge 40 Hz must be below the Nyquist frequency" in err


@pytest.mark.skipif(not (DATA / "koma_shearframe_sim.npz").exists(), reason="shared records not present")
def test_koma_frame_with_only_fs_and_a_band_finds_its_five_modes():
    d = np.load(DATA / "koma_shearframe_sim.npz")
    r = modaluq.identify(d["y"], fs=float(d["fs"]), frequency_range=(0.1, 1.5))
    sel = r.stabilization_diagram().select_modes()
    np.testing.assert_allclose(sel.frequency_hz, d["fn_ref_discrete_hz"], rtol=0.01)  # five, none spurious


def test_cli_does_not_warn_about_lags_it_chose_itself(tmp_path, capsys):
    """8 outputs cap the automatic horizon below one period of f_low: the reason says so, and no
    warning calls the tool's own choice wrong; a user's too-short block_rows is warned about."""
    rng = np.random.default_rng(5)
    path = tmp_path / "rec.npz"
    np.savez(path, y=rng.standard_normal((18_000, 8)), fs=30.0)
    assert main(["identify", str(path), "--frequency-range", "0.2", "5", "--no-progress", "--orders", "2:20:2"]) == 0
    captured = capsys.readouterr()
    assert "H is capped at 300 rows" in captured.out and "gives lags of" not in captured.err
    assert main(["identify", str(path), "--frequency-range", "0.2", "5", "--no-progress", "--block-rows", "10",
                 "--orders", "2:20:2"]) == 0
    assert "block_rows = 10 gives lags of" in capsys.readouterr().err


def test_an_automatic_horizon_capped_below_one_period_is_a_warning_with_what_to_change():
    """19 outputs at 100 Hz with a band from 1 Hz (Meloland's layout): H's 300-row cap leaves 15
    block rows (0.15 s of lags); the warning says so and gives the numbers: at most 3 outputs for
    the 100 rows a period of 1 Hz needs, or block_rows >= 100."""
    rng = np.random.default_rng(3)
    y = rng.standard_normal((8_000, 19))
    with pytest.warns(modaluq.ModalUQWarning, match=r"automatic block_rows = 15 .* at most 3 outputs .* block_rows >= 100"):
        modaluq.identify(y, fs=100.0, frequency_range=(1.0, 20.0), orders=range(2, 21, 2), uncertainty=False)
