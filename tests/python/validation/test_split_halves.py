"""``modaluq.validation.split_halves`` and ``modaluq validate --split-halves FILE``: the two halves
of one record identified alike, z = (x₁ − x₂) / √(σ₁² + σ₂²) per mode found in both."""

import numpy as np
import pytest

import modaluq
from modaluq.analysis import Analysis
from modaluq.cli import main
from modaluq.indicators import mac_test, shape_covariance
from modaluq.simulate import simulate
from modaluq.validation import PooledSplitHalves, SplitHalves, split_halves, split_halves_windows

SETTINGS = modaluq.Settings(block_rows=15, orders=range(2, 31, 2), n_blocks=30)


@pytest.fixture(scope="module")
def record():
    return simulate(n_samples=40_000, seed=11)


def test_the_halves_are_identified_alike_and_z_is_the_difference_over_its_std(record):
    a = Analysis.from_arrays(record.y, fs=record.fs, settings=SETTINGS)
    check = split_halves(a)
    assert isinstance(check, SplitHalves)
    half = record.y.shape[0] / record.fs / 2
    assert check.halves_s == ((0.0, half), (half, 2 * half))
    # independently: each half through Analysis with the same window and settings
    runs = [a.with_settings(start=s0, stop=s1).run(check_harmonics=False, issue_warnings=False).selected
            for s0, s1 in check.halves_s]
    assert check.summary()["n_pairs"] == 6  # the chain's six modes, found in both halves
    for k in range(6):
        i = int(np.argmin(abs(runs[0].frequency_hz - check.frequency_hz[k, 0])))
        j = int(np.argmin(abs(runs[1].frequency_hz - check.frequency_hz[k, 1])))
        assert check.frequency_hz[k, 0] == runs[0].frequency_hz[i] and check.frequency_hz[k, 1] == runs[1].frequency_hz[j]
        assert abs(check.frequency_hz[k, 0] / check.frequency_hz[k, 1] - 1) <= 0.02
        zf = (runs[0].frequency_hz[i] - runs[1].frequency_hz[j]) / np.hypot(runs[0].frequency_std[i],
                                                                             runs[1].frequency_std[j])
        zx = (runs[0].damping_ratio[i] - runs[1].damping_ratio[j]) / np.hypot(runs[0].damping_std[i],
                                                                              runs[1].damping_std[j])
        assert check.z_frequency[k] == pytest.approx(zf, rel=1e-12)
        assert check.z_damping[k] == pytest.approx(zx, rel=1e-12)
        # the shapes: 1 - MAC standardised by its mean and σ under "same mode", from each half's covariance
        t = mac_test(runs[0].mode_shape[:, i], runs[1].mode_shape[:, j], shape_covariance(runs[0].mode_covariance[i]),
                     shape_covariance(runs[1].mode_covariance[j]))
        assert check.mac[k] == pytest.approx(t.mac, rel=1e-12)
        assert check.z_mac[k] == pytest.approx((1 - t.mac - t.loss_mean) / t.loss_std, rel=1e-9)
        assert check.mac_p_value[k] == pytest.approx(t.p_value, rel=1e-9)
    s = check.summary()
    assert s["rms_z_frequency"] == pytest.approx(np.sqrt(np.mean(check.z_frequency ** 2)))
    assert s["within_damping"] == pytest.approx(np.mean(abs(check.z_damping) <= 1.959963984540054))
    assert s["rms_z_mac"] == pytest.approx(np.sqrt(np.mean(check.z_mac ** 2)))
    assert s["same_mode_rejected"] == pytest.approx(np.mean(check.mac_p_value < 0.05))
    table = check.to_dataframe()
    assert list(table["z_frequency"]) == list(check.z_frequency) and table.shape == (6, 18)
    assert list(table["paired_by_std"]) == list(check.by_std)
    assert "6 modes in both halves" in check.report() and "RMS z_MAC" in check.report()
    assert f"With 6 pairs, an RMS z is known to about ±{1 / np.sqrt(12):.2f}" in check.report()


def test_each_half_read_with_its_own_sigma(record):
    """Issue 27 (p): z = Δ / (√2 σ_h) per half, its summary, table columns and report lines."""
    a = Analysis.from_arrays(record.y, fs=record.fs, settings=SETTINGS)
    check = split_halves(a)
    f, sf, x, sx = check.frequency_hz, check.frequency_std, check.damping_ratio, check.damping_std
    for h in (0, 1):
        assert check.z_frequency_own_sigma[:, h] == pytest.approx((f[:, 0] - f[:, 1]) / (np.sqrt(2) * sf[:, h]), rel=1e-12)
        assert check.z_damping_own_sigma[:, h] == pytest.approx((x[:, 0] - x[:, 1]) / (np.sqrt(2) * sx[:, h]), rel=1e-12)
    s = check.summary()
    both = np.concatenate([check.z_damping_own_sigma[:, 0], check.z_damping_own_sigma[:, 1]])
    assert s["rms_z_damping_own_sigma"] == pytest.approx(np.sqrt(np.mean(both ** 2)))
    assert s["within_damping_own_sigma"] == pytest.approx(np.mean(abs(both) <= 1.959963984540054))
    table = check.to_dataframe()
    assert list(table["z_frequency_own_sigma_2"]) == list(check.z_frequency_own_sigma[:, 1])
    assert "Each half's own σ" in check.report()
    pooled = split_halves_windows(a, (1,))
    assert "own σ: within ±1.96 f, ξ" in pooled.report()
    # (q): each half's 95 % interval ± t σ, t the Student-t quantile (SciPy's) of that half's blocks − 1,
    # the core's count of its identification
    from scipy.stats import t as student_t

    # independently: each half through Analysis with the same window and settings, its core's count
    runs = [a.with_settings(start=s0, stop=s1).run(check_harmonics=False, issue_warnings=False).result
            for s0, s1 in check.halves_s]
    factor = np.array([student_t.ppf(0.975, run.n_blocks - 1) for run in runs])
    assert check.interval_factor_95 == pytest.approx(np.tile(factor, (len(check.mac), 1)), rel=1e-12)
    both_halves = check.z_damping_own_sigma  # (n_pairs, 2): half h read against its own t
    assert s["within_damping_own_interval"] == pytest.approx(np.mean(abs(both_halves) <= factor), rel=1e-12)
    assert f"t = {factor[0]:.3f}" in check.report() and "own σ: within ± t σ f, ξ" in pooled.report()
    assert pooled.pooled().summary()["within_damping_own_interval"] == pytest.approx(
        np.mean(np.concatenate([abs(c.z_damping_own_sigma) <= c.interval_factor_95 for _, _, c in pooled.checks])))
    # with equal σ in both halves the two readings are one: √(σ² + σ²) = √2 σ
    same = SplitHalves(f, np.column_stack([sf[:, 0], sf[:, 0]]), x, np.column_stack([sx[:, 0], sx[:, 0]]), check.mac)
    assert same.z_frequency_own_sigma[:, 1] == pytest.approx(same.z_frequency, rel=1e-12)


def test_own_sigma_reads_the_coverage_of_one_records_interval():
    """Why the report gives the own-σ reading: with σ that scatters from record to record (here
    log-normal, independent of the estimates), a single record's interval x ± 1.96 σ covers less
    than 95 %; the combined z of the halves reads more, each half's own σ reads that coverage
    (Δ / √2 has the law of one record's error)."""
    rng = np.random.default_rng(1)
    n = 200_000
    x = rng.standard_normal((n, 2))
    sigma = np.exp(0.5 * rng.standard_normal((n, 2)) - 0.25)
    one_record = np.mean(abs(x[:, 0]) / sigma[:, 0] <= 1.959963984540054)
    halves = SplitHalves(x, sigma, x, sigma, np.ones(n))
    s = halves.summary()
    assert one_record < 0.85  # the interval's coverage, far below 95 %
    assert s["within_frequency"] > one_record + 0.03  # the combined reading over-reads it
    assert s["within_frequency_own_sigma"] == pytest.approx(one_record, abs=0.005)


def test_the_second_half_takes_the_first_halfs_automatic_settings(record):
    check = split_halves(Analysis.from_arrays(record.y, fs=record.fs))  # block_rows, orders, n_blocks chosen
    assert set(check.settings) == {"block_rows", "past_block_rows", "n_blocks", "orders"}
    assert check.summary()["n_pairs"] >= 5


def test_pairs_are_one_to_one_within_the_frequency_difference(record):
    a = Analysis.from_arrays(record.y, fs=record.fs, settings=SETTINGS)
    tight = split_halves(a, max_frequency_difference=1e-6, pair_within_std=0)
    assert tight.summary()["n_pairs"] == 0 and np.isnan(tight.summary()["rms_z_frequency"])
    assert len(tight.unmatched_hz[0]) >= 6 and len(tight.unmatched_hz[1]) >= 6
    assert "Half 1 only: " in tight.report() and "(Unpaired: no mode of the other half" in tight.report()
    assert tight.pairing == {"max_frequency_difference": 1e-6, "pair_within_std": 0.0, "min_mac": 0.8}
    wide = split_halves(a, max_frequency_difference=0.5, min_mac=0.0)
    assert len(set(map(tuple, wide.frequency_hz.round(12)))) == wide.summary()["n_pairs"]
    assert len(np.unique(wide.frequency_hz[:, 0])) == len(np.unique(wide.frequency_hz[:, 1])) == len(wide.mac)


def test_the_pairing_does_not_truncate_z_below_pair_within_std(record):
    """With a relative window too narrow to pair anything, the σ window alone pairs exactly the mode
    pairs (MAC ≥ 0.8) whose |z_f| is at most pair_within_std, and the report says the rule."""
    a = Analysis.from_arrays(record.y, fs=record.fs, settings=SETTINGS)
    halves = [a.with_settings(start=s0, stop=s1).run(check_harmonics=False, issue_warnings=False).selected
              for s0, s1 in split_halves(a, max_frequency_difference=1e-6, pair_within_std=0).halves_s]
    f = [np.asarray(h.frequency_hz) for h in halves]
    sf = [np.asarray(h.frequency_std) for h in halves]
    mac = modaluq.stabilization.modal_assurance_criterion(halves[0].mode_shape, halves[1].mode_shape)
    z = (f[0][:, None] - f[1][None, :]) / np.hypot(sf[0][:, None], sf[1][None, :])
    for k in (1.0, 4.0):
        check = split_halves(a, max_frequency_difference=1e-6, pair_within_std=k)
        assert check.summary()["n_pairs"] >= 3 and np.all(np.abs(check.z_frequency) <= k)
        # every pair the σ window allows and no other, when each mode has one candidate
        allowed = {(i, j) for i, j in zip(*np.nonzero((np.abs(z) <= k) & (mac >= 0.8)))}
        assert all(np.sum([p[0] == i for p in allowed]) == 1 for i, _ in allowed)
        got = {(int(np.flatnonzero(f[0] == p[0])[0]), int(np.flatnonzero(f[1] == p[1])[0]))
               for p in check.frequency_hz}
        assert got == allowed
        assert check.by_std.all() and check.summary()["n_pairs_by_std"] == check.summary()["n_pairs"]
        assert (f"Pairs: frequencies apart by at most 0.0001 %"
                f" or, where unambiguous, by at most {k:g} combined σ_f, MAC ≥ 0.8") in check.report()
        assert check.report().count(" (σ) |") == check.summary()["n_pairs"]
    default = split_halves(a)
    assert not default.by_std.any() and "(σ)" not in default.report()
    assert ("Pairs: frequencies apart by at most 2 % or, where unambiguous, by at most 4 combined σ_f, MAC ≥ 0.8, "
            "nearest first, one to one.") in default.report()


def test_windows_are_split_halves_of_each_window_pooled(record):
    """split_halves_windows equals split_halves run on each window by hand; the pooled summary is
    that of all their z; a window too short is recorded and the others go on."""
    a = Analysis.from_arrays(record.y, fs=record.fs, settings=SETTINGS)
    T = record.y.shape[0] / record.fs
    pooled = split_halves_windows(a, (2, 1))
    assert isinstance(pooled, PooledSplitHalves) and pooled.levels == [1, 2] and pooled.failed == ()
    assert [(n, k) for n, k, _ in pooled.checks] == [(1, 0), (2, 0), (2, 1)]
    zf, zx = [], []
    for n, k, check in pooled.checks:
        own = split_halves(a.with_settings(start=k * T / n, stop=(k + 1) * T / n))
        assert check.halves_s == own.halves_s
        np.testing.assert_array_equal(check.frequency_hz, own.frequency_hz)
        np.testing.assert_array_equal(check.damping_std, own.damping_std)
        zf += list(own.z_frequency)
        zx += list(own.z_damping)
    s = pooled.summary()
    assert s["n_pairs"] == len(zf) >= 15 and s["n_windows_run"] == 3 and s["n_windows_failed"] == 0
    assert s["rms_z_frequency"] == pytest.approx(np.sqrt(np.mean(np.square(zf))), rel=1e-12)
    assert s["within_damping"] == pytest.approx(np.mean(np.abs(zx) <= 1.959963984540054))
    assert pooled.pooled(2).summary()["n_pairs"] == len(pooled.checks[1][2].mac) + len(pooled.checks[2][2].mac)
    table = pooled.to_dataframe()
    assert list(table.columns[:4]) == ["n_windows", "window", "t0_s", "t1_s"] and len(table) == s["n_pairs"]
    assert list(table["z_frequency"]) == pytest.approx(zf, rel=1e-12)
    assert set(table.loc[table["n_windows"] == 2, "t0_s"]) == {0.0, T / 2}
    text = pooled.report()
    assert text.startswith("## Split halves over consecutive windows") and f"| **all** | {len(zf)} |" in text
    assert text.count("## Split halves: ") == 3
    # windows too short for the settings: recorded, the others still run
    short = split_halves_windows(a, (1, 40))
    assert len(short.checks) == 1 and len(short.failed) == 40 and short.summary()["n_windows_failed"] == 40
    n, k, (t0, t1), message = short.failed[0]
    assert (n, k, t0) == (40, 0, 0.0) and t1 == pytest.approx(T / 40) and "half 1" in message
    assert "Window 1 of 40 (0-20 s) failed: half 1" in short.report() and "39 more of the 40" in short.report()
    assert "fewer windows give longer halves" in short.failed[0][3]
    # halves with fewer samples than twice the channels: said so, not read as a transposed array
    tiny = split_halves_windows(a, (3000,))
    assert not tiny.checks and len(tiny.failed) == 3000
    assert tiny.failed[0][3].startswith("halves of about 6 samples, too short for 3 channels")
    assert "1 modes" not in short.report()
    assert "y.T" not in tiny.report() and "| **all** | 0 |" in tiny.report()
    assert tiny.report().count("failed:") == 1 and "... and 2999 more of the 3000 windows failed" in tiny.report()


def test_windows_bad_input_is_named(record):
    a = Analysis.from_arrays(record.y, fs=record.fs, settings=SETTINGS)
    with pytest.raises(ValueError, match="windows"):
        split_halves_windows(a, (0, 2))
    with pytest.raises(TypeError, match="windows"):
        split_halves_windows(a, "two")
    with pytest.raises(ValueError, match="pair_within_std"):
        split_halves_windows(a, (1,), pair_within_std=-1)
    with pytest.raises(TypeError, match="tolerance"):
        split_halves_windows(a, (1,), tolerance=0.1)
    with pytest.raises(ValueError, match="uncertainty"):
        split_halves_windows(a.with_settings(uncertainty=False))
    with pytest.raises(TypeError, match="analysis must be"):
        split_halves_windows(record.y)
    with pytest.raises(ValueError, match=r"stop must be after start; got start = 400 s, stop = 300 s"):
        split_halves_windows(a.with_settings(start=400.0, stop=300.0))
    with pytest.raises(ValueError, match=r"stop must be after start; got start = 400 s, stop = 300 s"):
        split_halves(a.with_settings(start=400.0, stop=300.0))


def test_bad_input_is_named(record):
    a = Analysis.from_arrays(record.y, fs=record.fs, settings=SETTINGS)
    with pytest.raises(TypeError, match="analysis must be"):
        split_halves(record.y)
    with pytest.raises(ValueError, match="uncertainty"):
        split_halves(a.with_settings(uncertainty=False))
    with pytest.raises(ValueError, match="max_frequency_difference"):
        split_halves(a, max_frequency_difference=0)
    with pytest.raises(ValueError, match="min_mac"):
        split_halves(a, min_mac=1.5)
    with pytest.raises(ValueError, match="pair_within_std"):
        split_halves(a, pair_within_std=-1)
    short = Analysis.from_arrays(record.y[:1000], fs=record.fs, settings=SETTINGS)
    with pytest.raises(ValueError, match="half 1"):
        split_halves(short)


def test_cli_split_halves_end_to_end(record, tmp_path, capsys):
    csv = tmp_path / "rec.csv"
    np.savetxt(csv, np.column_stack([np.arange(len(record.y)) / record.fs, record.y]), delimiter=",",
               header="time [s],a,b,c", comments="")
    out = tmp_path / "check"
    status = main(["validate", "--split-halves", str(csv), "--block-rows", "15", "--order", *map(str, range(2, 31, 2)),
                   "--n-blocks", "30", "--out", str(out), "--no-progress"])
    text, err = capsys.readouterr()
    assert status == 0, err
    assert "## Split halves: 0-400 s against 400-800 s" in text and "6 modes in both halves" in text
    assert (out / "report.md").read_text() == text
    assert (out / "pairs.csv").read_text().splitlines()[0].startswith("frequency_hz_1,frequency_hz_2")
    # --tolerance and --pair-within-std reach the pairing: the σ window alone pairs, the window alone not
    argv = ["validate", "--split-halves", str(csv), "--block-rows", "15", "--order", *map(str, range(2, 31, 2)),
            "--n-blocks", "30", "--no-progress", "--tolerance", "1e-6"]
    assert main([*argv, "--pair-within-std", "0"]) == 0
    assert "No mode was found in both halves" in capsys.readouterr().out
    assert main([*argv, "--pair-within-std", "6"]) == 0
    text = capsys.readouterr().out
    assert "or, where unambiguous, by at most 6 combined σ_f" in text and "modes in both halves" in text
    assert "No mode was found" not in text and " (σ) |" in text
    # --windows: the pooled check over consecutive windows, as split_halves_windows reports it
    argv = ["validate", "--split-halves", str(csv), "--block-rows", "15", "--order", *map(str, range(2, 31, 2)),
            "--n-blocks", "30", "--no-progress", "--windows", "1", "2", "--out", str(tmp_path / "w")]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert text == split_halves_windows(Analysis.from_file(csv, settings=SETTINGS), (1, 2)).report()
    assert (tmp_path / "w" / "pairs.csv").read_text().startswith("n_windows,window,t0_s,t1_s,frequency_hz_1")


def test_cli_split_halves_reads_the_modes_at_the_representative_asked_for(record, tmp_path, capsys, monkeypatch):
    """--representative lowest: the report of split_halves on an Analysis with that clustering."""
    csv = tmp_path / "rec.csv"
    np.savetxt(csv, np.column_stack([np.arange(len(record.y)) / record.fs, record.y]), delimiter=",",
               header="time [s],a,b,c", comments="")
    argv = ["validate", "--split-halves", str(csv), "--block-rows", "15", "--order", *map(str, range(2, 31, 2)),
            "--n-blocks", "30", "--no-progress"]
    assert main([*argv, "--representative", "lowest"]) == 0
    lowest = capsys.readouterr().out
    analysis = Analysis.from_file(csv, settings=SETTINGS,
                                  clustering=modaluq.ClusteringSettings(representative="lowest"))
    assert lowest == split_halves(analysis).report()
    assert main(argv) == 0
    assert capsys.readouterr().out != lowest  # the modes are read at other orders
    assert main([*argv, "--shape-representative", "lowest"]) == 0
    analysis = Analysis.from_file(csv, settings=SETTINGS,
                                  clustering=modaluq.ClusteringSettings(shape_representative="lowest"))
    assert capsys.readouterr().out == split_halves(analysis).report()
    # --no-order-discrepancy reaches the analysis the command builds
    given = []
    from_file = Analysis.from_file.__func__

    def recording(cls, *args, **kwargs):
        given.append(kwargs["clustering"])
        return from_file(cls, *args, **kwargs)

    monkeypatch.setattr(Analysis, "from_file", classmethod(recording))
    assert main([*argv, "--no-order-discrepancy"]) == 0
    assert main(argv) == 0
    assert [c.order_discrepancy for c in given] == [False, True]


@pytest.mark.parametrize("argv, message", [
    (["--split-halves", "x.csv", "--records", "3"], "--records: option(s) of the simulation"),
    (["--fs", "10"], "--fs: option(s) of --split-halves FILE"),
    (["--representative", "lowest"], "--representative: option(s) of --split-halves FILE"),
    (["--shape-representative", "lowest"], "--shape-representative: option(s) of --split-halves FILE"),
    (["--no-order-discrepancy"], "--no-order-discrepancy: option(s) of --split-halves FILE"),
    (["--pair-within-std", "2"], "--pair-within-std: option(s) of --split-halves FILE"),
    (["--windows", "2"], "--windows: option(s) of --split-halves FILE"),
    (["--split-halves", "x.csv", "--windows", "0"], "--windows"),
    (["--split-halves", "x.csv", "--pair-within-std", "-1"], "--pair-within-std"),
    (["--split-halves", "missing.csv"], "missing.csv"),
])
def test_cli_split_halves_options_are_checked(argv, message, capsys):
    assert main(["validate", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
