"""modaluq.validation: the Monte Carlo check of the analytic std (paper §5.1) and its tool.

The statistical test runs the paper's setting (N = 10,000, order 12, p = q = 15, 50 blocks) on
200 records: with 200 records the sample std σ_MC is itself uncertain by about
1/√(2·199) ≈ 5 %, so ±20 % is a 4-sigma band for a correct analytic std.  Output-only mode 1
is left out: it is weakly observed (its singular values sit near the noise floor) and its
estimates have heavy tails, as in the paper (Table 2: σ̄_est = 2.02 ± 1.80 ·10⁻² Hz).
"""

import struct
import time
import warnings

import numpy as np
import pytest

import modaluq
from modaluq.cli import main
from modaluq.validation import (
    METHODS,
    PAPER_TABLE_1,
    PAPER_TABLE_2,
    MonteCarloResult,
    match_modes,
    monte_carlo,
    record_seed,
)

PAPER_SETTINGS = dict(n_samples=10_000, order=12, block_rows=15, past_block_rows=15, n_blocks=50)
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def mc200():
    t0 = time.perf_counter()
    mc = monte_carlo(200, **PAPER_SETTINGS, seed=0, processes=2, progress=False)
    print(f"\n200-record Monte Carlo: {time.perf_counter() - t0:.1f} s wall time on 2 processes")
    return mc


def _assert_same_run(a, b):
    for name in ("frequency_hz", "damping_ratio", "frequency_std", "damping_std", "n_identified", "failed",
                 "close_singular_values", "n_warnings"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


# --------------------------------------------------------------------------- statistics


@pytest.mark.slow
def test_analytic_std_matches_monte_carlo_within_20_percent(mc200):
    io, oo = METHODS.index("input/output"), METHODS.index("output-only")
    assert mc200.n_missed[io].sum() == 0, mc200.n_missed          # IO finds all six modes in every record
    for name in ("frequency", "damping"):
        ratio = getattr(mc200, f"{name}_std_ratio")
        for m, modes in ((io, range(6)), (oo, range(1, 6))):
            for i in modes:
                assert mc200.n_matched[m, i] >= 190, (METHODS[m], i + 1, mc200.n_matched[m, i])
                assert abs(ratio[m, i] - 1) <= 0.20, (f"{METHODS[m]} mode {i + 1} {name}: "
                                                      f"σ̄_est / σ_MC = {ratio[m, i]:.3f}")


def test_summary_is_the_statistics_of_the_arrays(mc200):
    """The summary fields are the plain statistics of the per-record arrays (recomputed here)."""
    m, i = METHODS.index("input/output"), 3
    f, sf = mc200.frequency_hz[m, :, i], mc200.frequency_std[m, :, i]
    ok = np.isfinite(f)
    assert mc200.frequency_mean[m, i] == pytest.approx(np.mean(f[ok]), rel=1e-12)
    assert mc200.frequency_std_mc[m, i] == pytest.approx(np.std(f[ok], ddof=1), rel=1e-12)
    assert mc200.frequency_std_est[m, i] == pytest.approx(np.mean(sf[ok]), rel=1e-12)
    assert mc200.frequency_std_ratio[m, i] == pytest.approx(np.mean(sf[ok]) / np.std(f[ok], ddof=1), rel=1e-12)
    # The bootstrap SE of a ratio of two averages over 200 records: a few percent, not 0, not 1.
    assert 0.01 < mc200.frequency_std_ratio_se[m, i] < 0.2
    # per-record z and the coverage of ±1.96 σ over the unflagged records
    keep = ok & ~mc200.noise_coupled[m, :, i]
    z = (f[keep] - f[keep].mean()) / sf[keep]
    assert mc200.frequency_rms_z_unflagged[m, i] == pytest.approx(np.sqrt(np.mean(z ** 2)), rel=1e-12)
    assert mc200.frequency_coverage_unflagged[m, i] == pytest.approx(np.mean(np.abs(z) <= 1.96), rel=1e-12)
    assert "coverage of ±1.96 σ (f), unflagged" in mc200.report()
    # the 95 % interval: Student's t with 50 - 1 degrees of freedom (SciPy's, not the package's)
    from scipy.stats import t as student_t

    from modaluq.validation.statistics import blocks_used

    assert blocks_used(mc200.settings) == 50  # the paper's 9,971 columns make exactly 50 blocks of 199
    factor = student_t.ppf(0.975, 49)
    assert mc200.interval_factor_95 == pytest.approx(factor, rel=1e-12)
    assert mc200.frequency_coverage_interval_unflagged[m, i] == pytest.approx(np.mean(np.abs(z) <= factor), rel=1e-12)
    assert "coverage of the 95 % interval ± t σ (f), unflagged" in mc200.report()


# --------------------------------------------------------------------------- the tool


def test_same_seed_gives_identical_arrays_whatever_the_processes():
    kw = dict(PAPER_SETTINGS, n_bootstrap=20, progress=False)
    serial = monte_carlo(5, seed=3, processes=1, **kw)
    again = monte_carlo(5, seed=3, processes=1, **kw)
    pooled = monte_carlo(5, seed=3, processes=2, chunk_size=2, **kw)
    _assert_same_run(serial, again)
    _assert_same_run(serial, pooled)
    np.testing.assert_array_equal(serial.frequency_std_ratio_se, pooled.frequency_std_ratio_se)
    other = monte_carlo(2, seed=4, processes=1, **kw)
    assert not np.array_equal(other.frequency_hz[:, :2], serial.frequency_hz[:, :2], equal_nan=True)


def test_record_is_the_public_simulate_and_identify():
    """Record k is simulate(seed=SeedSequence(seed).spawn(k+1)[k]) identified by identify()."""
    mc = monte_carlo(3, **PAPER_SETTINGS, seed=5, processes=1, progress=False, n_bootstrap=0)
    k = 2
    child = np.random.SeedSequence(5).spawn(k + 1)[k]
    np.testing.assert_array_equal(record_seed(5, k).generate_state(4), child.generate_state(4))
    sim = modaluq.simulate(10_000, seed=child)
    for m, u in enumerate((None, sim.u)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", modaluq.ModalUQWarning)
            modes = modaluq.identify(sim.y, u, fs=sim.fs, block_rows=15, orders=12, n_blocks=50).at_order(12)
        for i, f_true in enumerate(sim.frequency_hz):
            j = int(np.argmin(np.abs(modes.frequency_hz - f_true)))
            if abs(modes.frequency_hz[j] - f_true) < 0.03 * f_true:   # clearly inside every window
                assert mc.frequency_hz[m, k, i] == modes.frequency_hz[j]
                assert mc.damping_std[m, k, i] == modes.damping_std[j]


def test_match_modes_windows():
    true = [2.0, 14.49, 15.85]
    # 15.1 is 0.61 Hz above 14.49: inside 14.49's window (half the gap to 15.85 is 0.68 Hz).
    np.testing.assert_array_equal(match_modes([15.1, 2.05], true), [1, 0, -1])
    # 15.2 is 0.71 Hz above 14.49 (outside its narrowed window) and 0.65 Hz below 15.85 (inside).
    np.testing.assert_array_equal(match_modes([15.2], true), [-1, -1, 0])
    # 2.11 is 5.5 % above 2.0: a miss at the default ±5 %, a match at ±6 %.
    np.testing.assert_array_equal(match_modes([2.11], true), [-1, -1, -1])
    np.testing.assert_array_equal(match_modes([2.11], true, tolerance=0.06), [0, -1, -1])
    # Nearest wins; an empty identification misses everything.
    np.testing.assert_array_equal(match_modes([2.04, 1.99], true), [1, -1, -1])
    np.testing.assert_array_equal(match_modes([], true), [-1, -1, -1])
    with pytest.raises(ValueError, match="tolerance"):
        match_modes([2.0], true, tolerance=1.5)
    with pytest.raises(ValueError, match="distinct"):
        match_modes([2.0], [2.0, 2.0])


@pytest.mark.parametrize("kwargs,exc,name", [
    (dict(n_records=0), ValueError, "n_records"),
    (dict(n_records=2.5), TypeError, "n_records"),
    (dict(processes=0), ValueError, "processes"),
    (dict(seed=-1), ValueError, "seed"),
    (dict(n_blocks=1), ValueError, "n_blocks"),
    (dict(match_tolerance=0.0), ValueError, "match_tolerance"),
    (dict(progress="yes"), TypeError, "progress"),
    (dict(mp_context="threads"), ValueError, "mp_context"),
    (dict(order=60), ValueError, "order"),               # refused by the identification itself
    (dict(n_samples=500), ValueError, "too short"),
])
def test_bad_parameters_name_themselves(kwargs, exc, name):
    kw = dict(n_records=2, processes=1, progress=False)
    kw.update(kwargs)
    with pytest.raises(exc, match=name):
        monte_carlo(**kw)


def test_report_has_both_tables_with_the_paper_beside_ours(mc200):
    text = mc200.report()
    for heading in ("Table 1", "Table 2", "Frequency (Hz)", "Damping ratio (‰", "(10⁻² Hz)", "(‰)",
                    "σ̄_est / σ_MC ± SE, ours", "within ±10 %", "misses"):
        assert heading in text, heading
    # The paper's numbers, as printed in its tables.
    assert f"{PAPER_TABLE_1['output-only']['frequency_hz'][0]:.4g}" in text          # 1.937
    assert f"{PAPER_TABLE_1['output-only']['damping_permille'][0]:.1f}" in text      # 29.4
    oo2 = PAPER_TABLE_2["output-only"]
    assert f"{oo2['frequency_std_est_centihz'][0]:.2f} ± {oo2['frequency_std_est_spread_centihz'][0]:.2f}" in text
    # Ours, in the paper's units (10^-2 Hz, per mille), with the ratio and its standard error.
    io = METHODS.index("input/output")
    assert f"{1e2 * mc200.frequency_std_mc[io, 0]:.3f}" in text
    assert f"{1e3 * mc200.damping_mean[io, 0]:.2f}" in text
    assert f"{mc200.damping_std_ratio[io, 2]:.2f} ± {mc200.damping_std_ratio_se[io, 2]:.2f}" in text


def test_dataframe_and_save_load_roundtrip(mc200, tmp_path):
    pd = pytest.importorskip("pandas")
    df = mc200.to_dataframe()
    assert len(df) == 2 * 200 * 6
    assert {"record", "method", "mode", "frequency_hz", "frequency_std", "damping_ratio", "damping_std",
            "matched"} <= set(df.columns)
    io4 = df[(df.method == "input/output") & (df["mode"] == 4)]
    assert io4.frequency_hz.std(ddof=1) == pytest.approx(mc200.frequency_std_mc[1, 3], rel=1e-12)
    assert isinstance(mc200.summary_dataframe(), pd.DataFrame)
    path = tmp_path / "run.npz"
    mc200.save(path)
    back = MonteCarloResult.load(path)
    _assert_same_run(back, mc200)
    np.testing.assert_array_equal(back.frequency_std_ratio_se, mc200.frequency_std_ratio_se)
    assert back.settings == mc200.settings


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24]), len(data)


def test_cli_end_to_end(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = tmp_path / "mc"
    rc = main(["validate", "--records", "4", "--processes", "1", "--seed", "2", "--no-progress",
               "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "Table 2" in captured.out
    assert (out / "report.md").read_text(encoding="utf-8") == captured.out
    for png in ("histograms_std.png", "histograms_estimates.png"):
        (width, height), n_bytes = _png_size(out / png)
        assert width >= 400 and height >= 300 and 10_000 < n_bytes < 1_000_000
    lines = (out / "results.csv").read_text().splitlines()
    assert len(lines) == 1 + 2 * 4 * 6 and lines[0].startswith("record,method,mode")
    assert len((out / "summary.csv").read_text().splitlines()) == 1 + 2 * 6
    back = MonteCarloResult.load(out / "results.npz")
    assert back.n_records == 4 and back.settings["seed"] == 2


@pytest.mark.parametrize("argv,option", [
    (["--records", "0"], "--records"),
    (["--processes", "0"], "--processes"),
    (["--tolerance", "2"], "--tolerance"),
    (["--records", "2", "--order", "60"], "order"),
])
def test_cli_bad_argument_exits_2_with_one_line(argv, option, capsys):
    rc = main(["validate", "--no-progress", "--processes", "1", *argv])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and option in err and err.startswith("modaluq validate: error:")


def test_several_orders_from_the_same_records_and_the_other_cases():
    """--order N1 N2 ...: one result per order, computed from the same simulated records."""
    kw = dict(processes=1, progress=False, n_bootstrap=0, seed=4)
    both = monte_carlo(3, order=[12, 24], **kw)
    assert isinstance(both, tuple) and [r.settings["order"] for r in both] == [12, 24]
    single = monte_carlo(3, order=24, **kw)
    np.testing.assert_array_equal(single.frequency_std, both[1].frequency_std)
    assert both[1].mode_shape.shape == (2, 3, 6, 3) and both[1].noise_coupled.dtype == bool
    assert both[0].noise_coupled_share.shape == (2, 6)
    frame = monte_carlo(3, order=8, n_dof=4, input_dofs=(0, 3), unknown_input_std=0.0, damping_ratio=0.01, **kw)
    assert frame.n_modes == 4 and not frame.settings["paper_case"]
    np.testing.assert_allclose(frame.true_damping_ratio, 0.01)
    plain = monte_carlo(3, order=24, freeze_noise=False, **kw)
    assert not plain.noise_coupled.any() and plain.settings["freeze_noise"] is False


def test_cli_several_orders_writes_one_file_set_per_order(tmp_path, capsys):
    out = tmp_path / "mc"
    rc = main(["validate", "--records", "3", "--processes", "1", "--no-progress", "--order", "12", "24",
               "--unknown-input-std", "0", "--damping-ratio", "0.01", "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert captured.out.count("# modaluq Monte Carlo validation") == 2
    assert "Flagged poles, medians and mode shapes" in captured.out
    for n in (12, 24):
        back = MonteCarloResult.load(out / f"results_n{n}.npz")
        assert back.settings["order"] == n and back.settings["simulate_keywords"]["unknown_input_std"] == 0.0
        assert (out / f"histograms_std_n{n}.png").exists()


@pytest.mark.parametrize("argv,option", [
    (["--unknown-input-std", "-1"], "--unknown-input-std"),
    (["--damping-ratio", "0"], "--damping-ratio"),
    (["--noise-coupling-limit", "0.5"], "--noise-coupling-limit"),
])
def test_cli_new_options_are_checked(argv, option, capsys):
    rc = main(["validate", "--no-progress", "--processes", "1", *argv])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and option in err
