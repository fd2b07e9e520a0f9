"""modaluq.monitor: the batch, its part files, stores, notes and arguments."""

import concurrent.futures
import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from monitoring_support import SETTINGS

import modaluq
from modaluq.monitoring import TrackingSettings, load_tracks, monitor, record_files, time_from_name
from modaluq.monitoring.plot import plot_tracked_frequencies
from modaluq.monitoring.store import COMPLEX_SHAPES

pytest.importorskip("xarray")


def test_monitor_tracks_every_mode_of_the_simulator(serial, campaign):
    ds = serial.dataset
    assert serial.n_failed == 0 and ds.sizes["record"] == 24 and ds.sizes["mode"] == 6
    # tracked mode j is the true mode j at every record: within 5 σ of the truth
    z = (ds["frequency_hz"].values - campaign.frequency_hz) / ds["frequency_std"].values
    assert np.nanmax(np.abs(z)) < 5 and np.isfinite(z).mean() > 0.95
    assert ds["in_reference"].values.sum() == 20
    assert ds["time"].values[1] - ds["time"].values[0] == np.timedelta64(3600, "s")
    assert "temperature" in ds and ds.attrs["false_alarm_rate"] == 0.01
    assert set(serial.poles["tracked_mode"].dropna().unique()) <= set(range(1, 7))
    assert "24 records: 24 identified, 0 failed" in str(serial)


def test_store_round_trip_netcdf_zarr_parquet(serial, campaign, tmp_path):
    out = tmp_path / "tracks.nc"
    m = monitor(campaign.records, settings=SETTINGS, out=out, progress=False, poles=tmp_path / "poles.parquet")
    assert m.n_run == 24 and set(m.written) == {str(out), str(tmp_path / "poles.parquet"),
                                               str(tmp_path / "tracks.failures.csv")}
    back = load_tracks(out)
    # the store read again is the dataset (complex shapes rebuilt, times in ns, booleans back)
    import xarray as xr

    xr.testing.assert_identical(back, m.dataset)
    np.testing.assert_array_equal(back["mode_shape"].values, serial.dataset["mode_shape_real"].values
                                  + 1j * serial.dataset["mode_shape_imag"].values)
    assert back["mode_shape"].dtype == complex and back["alarm"].dtype == bool
    np.testing.assert_array_equal(back["frequency_hz"].values, serial.dataset["frequency_hz"].values)
    np.testing.assert_array_equal(back["time"].values, serial.dataset["time"].values)
    import pandas as pd

    assert pd.read_parquet(tmp_path / "poles.parquet").shape == serial.poles.shape
    pytest.importorskip("zarr")
    z = monitor(campaign.records, settings=SETTINGS, out=tmp_path / "tracks.zarr", progress=False)
    xr.testing.assert_identical(load_tracks(tmp_path / "tracks.zarr"), m.dataset)
    assert z.n_run == 0  # the same stem: the part files of tracks.nc serve, nothing is identified again


def test_resume_runs_nothing_done_and_refuses_other_settings(campaign, tmp_path):
    out = tmp_path / "t.nc"
    first = monitor(campaign.records[:8], settings=SETTINGS, out=out, progress=False,
                    tracking=TrackingSettings(reference_records=4))
    parts = sorted((tmp_path / "t.parts").glob("*.json"))
    stamps = {p: p.stat().st_mtime_ns for p in parts}
    again = monitor(campaign.records[:12], settings=SETTINGS, out=out, progress=False,
                    tracking=TrackingSettings(reference_records=4))
    assert first.n_run == 8 and again.n_run == 4  # only the 4 new records ran
    assert all(p.stat().st_mtime_ns == t for p, t in stamps.items())
    np.testing.assert_array_equal(again.dataset["frequency_hz"].values[:8], first.dataset["frequency_hz"].values)
    # other settings: refused, naming what differs and how to start again
    with pytest.raises(ValueError, match=r"other settings \(settings\.orders differ\).*--no-resume"):
        monitor(campaign.records[:8], settings=SETTINGS.replace(orders=(2, 4, 6, 8)), out=out, progress=False)
    # a clustering option counts, by its dotted name
    with pytest.raises(ValueError, match=r"other settings \(clustering\.order_discrepancy differ\)"):
        monitor(campaign.records[:8], settings=SETTINGS, out=out, progress=False,
                clustering=modaluq.ClusteringSettings(order_discrepancy=False))
    assert monitor(campaign.records[:8], settings=SETTINGS, out=out, progress=False, resume=False,
                   tracking=TrackingSettings(reference_records=4)).n_run == 8


def test_a_store_made_before_a_setting_was_added_resumes_with_its_old_value(campaign, tmp_path):
    """A store made before order_discrepancy, drop_noise_twins, reassign_borrowed_poles and
    unanchored_noise_coupling existed: its parts' fingerprint has no such keys. The defaults are
    refused by name; all off (--no-order-discrepancy --no-drop-noise-twins
    --no-reassign-borrowed-poles --no-unanchored-sigma) is the fingerprint it was made with, and its
    parts serve."""
    from modaluq.monitoring.worker import ADDED_SETTINGS, TaskConfig

    old = modaluq.ClusteringSettings(order_discrepancy=False, drop_noise_twins=False, reassign_borrowed_poles=False,
                                     unanchored_noise_coupling=None)
    fingerprint = TaskConfig(settings=SETTINGS, clustering=old).fingerprint()
    assert set(ADDED_SETTINGS["clustering"]).isdisjoint(fingerprint["clustering"])  # as before the key
    out = tmp_path / "t.nc"
    tracking = TrackingSettings(reference_records=4)
    first = monitor(campaign.records[:6], settings=SETTINGS, clustering=old, out=out, progress=False,
                    tracking=tracking)
    stamp = json.loads((tmp_path / "t.parts" / "settings.json").read_text())
    assert set(ADDED_SETTINGS["clustering"]).isdisjoint(stamp["clustering"])
    with pytest.raises(ValueError, match=r"clustering\.order_discrepancy.*differ"):
        monitor(campaign.records[:6], settings=SETTINGS, out=out, progress=False, tracking=tracking)
    with pytest.raises(ValueError, match=r"clustering\.drop_noise_twins\b.*differ"):
        monitor(campaign.records[:6], settings=SETTINGS, out=out, progress=False, tracking=tracking,
                clustering=modaluq.ClusteringSettings(order_discrepancy=False))
    with pytest.raises(ValueError, match=r"clustering\.reassign_borrowed_poles\b.*differ"):
        monitor(campaign.records[:6], settings=SETTINGS, out=out, progress=False, tracking=tracking,
                clustering=modaluq.ClusteringSettings(order_discrepancy=False, drop_noise_twins=False))
    with pytest.raises(ValueError, match=r"clustering\.unanchored_noise_coupling differ"):
        monitor(campaign.records[:6], settings=SETTINGS, out=out, progress=False, tracking=tracking,
                clustering=modaluq.ClusteringSettings(order_discrepancy=False, drop_noise_twins=False,
                                                      reassign_borrowed_poles=False))
    again = monitor(campaign.records[:6], settings=SETTINGS, clustering=old, out=out, progress=False,
                    tracking=tracking)
    assert first.n_run == 6 and again.n_run == 0


def test_a_store_without_parts_takes_other_settings(campaign, tmp_path):
    """A run that stopped before its first record (settings.json written, no part) does not lock
    the store to its settings: there is nothing to mix."""
    from modaluq.monitoring.parts import Parts
    from modaluq.monitoring.worker import TaskConfig

    folder = tmp_path / "t.parts"
    Parts(folder, TaskConfig(settings=SETTINGS.replace(orders=(2, 4, 6, 8))))  # the stamp only
    out = monitor(campaign.records[:6], settings=SETTINGS, out=tmp_path / "t.nc", progress=False,
                  tracking=TrackingSettings(reference_records=4))
    assert out.n_run == 6
    assert json.loads((folder / "settings.json").read_text())["settings"]["orders"] == list(SETTINGS.orders)


def test_a_restart_removes_the_half_written_parts_of_a_killed_writer(campaign, tmp_path):
    out = tmp_path / "t.nc"
    monitor(campaign.records[:6], settings=SETTINGS, out=out, progress=False,
            tracking=TrackingSettings(reference_records=4))
    parts = tmp_path / "t.parts"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    torn = parts / f".0123456789abcdef0123.json.{int(dead.stdout)}.tmp"  # killed in the middle of a write
    torn.write_bytes(b'{"key": "record-00')
    alive = parts / f".fedcba9876543210fedc.json.{os.getppid()}.tmp"  # a live writer's: not touched
    alive.write_bytes(b"{")
    again = monitor(campaign.records[:6], settings=SETTINGS, out=out, progress=False,
                    tracking=TrackingSettings(reference_records=4))
    assert again.n_run == 0 and not torn.exists() and alive.exists()


def test_a_corrupt_file_is_a_failure_with_its_stage_and_the_batch_goes_on(csv_folder, tmp_path):
    folder, camp = csv_folder
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "corrupt.csv").write_text("time,a,b\n0,1,2\n0.1,x,\x00\n")
    short = bad / "short.csv"
    np.savetxt(short, np.column_stack([np.arange(30) / 50, np.ones((30, 3))]), delimiter=",", header="t,a,b,c",
               comments="")
    files = record_files([folder]) + [bad / "corrupt.csv", short, bad / "missing.csv"]
    m = monitor(files, settings=SETTINGS, out=tmp_path / "t.nc", progress=False,
                covariates=folder.with_name("site.covariates.csv"), tracking=TrackingSettings(reference_records=8))
    assert m.n_records == 23 and m.n_failed == 3
    # the failed files have no time, but only identified records' order matters: no note of it
    assert m.notes == ()
    f = m.failures.set_index("record")
    assert f.loc["corrupt.csv", "stage"] == "load" and f.loc["missing.csv", "stage"] == "load"
    assert "missing.csv" in f.loc["missing.csv", "error"]
    assert f.loc["short.csv", "stage"] in ("preprocess", "identify")
    assert (m.dataset["status"].values == "done").sum() == 20
    # the failures table beside the store holds the same rows
    import pandas as pd

    assert pd.read_csv(tmp_path / "t.failures.csv").shape[0] == 3
    # covariates and times came from the table beside the folder
    np.testing.assert_allclose(m.dataset["temperature"].values[:20], camp.temperature, rtol=1e-5)


def test_reference_span_and_a_missing_covariate(campaign, serial):
    span = (str(campaign.time[4]), str(campaign.time[15]))
    m = monitor(campaign.records, settings=SETTINGS, progress=False, tracking=TrackingSettings(reference_span=span))
    assert m.dataset["in_reference"].values.tolist() == [4 <= k <= 15 for k in range(24)]
    # records before the reference period get χ² but no control chart
    assert np.isnan(m.dataset["control"].values[:4]).all() and np.isfinite(m.dataset["chi2"].values[:4]).any()
    # without the temperature, the reference's reduced χ² flags it in the summary
    records = [type(r)(**{**r.__dict__, "covariates": {}}) for r in campaign.records]
    with pytest.warns(modaluq.ModalUQWarning, match=r"mode\(s\) 1, 2, .*reduced chi2 .* a covariate .* is missing"):
        text = str(monitor(records, settings=SETTINGS, progress=False))
    assert "!: reduced chi2 above" in text and "note: mode(s) 1, 2" in text


def test_a_covariate_constant_over_the_reference_leaves_the_store_and_says_why(campaign, tmp_path):
    records = [type(r)(**{**r.__dict__, "covariates": {"temperature": 12.0 if k < 20 else float(k)}})
               for k, r in enumerate(campaign.records)]
    m = monitor(records, settings=SETTINGS, out=tmp_path / "t.nc", progress=False)
    assert m.n_failed == 0 and (tmp_path / "t.nc").exists()
    assert "covariates: constant or collinear" in m.dataset.attrs["tracking_error"]
    assert np.isfinite(m.dataset["frequency_hz"].values).any() and "control" not in m.dataset
    assert "no change test" in str(m)


def test_what_limits_the_tests_is_said_not_silent(campaign, serial):
    # two records without a temperature (one in the reference period), two without a time
    records = [type(r)(**{**r.__dict__, "covariates": {} if k in (2, 18) else r.covariates,
                          "time": None if k in (5, 6) else r.time}) for k, r in enumerate(campaign.records)]
    with pytest.warns(modaluq.ModalUQWarning) as caught:
        m = monitor(records, settings=SETTINGS, progress=False, tracking=TrackingSettings(reference_records=8))
    said = [str(w.message) for w in caught]
    assert any("2 records have no value of a covariate (temperature)" in w and "not tested" in w
               and "1 of the 8 reference records is left out" in w for w in said), said
    assert any("2 of 24 identified records have no time (record-0005, record-0006)" in w for w in said), said
    ds = m.dataset
    # the records without a time come last, in the order given; the others by time
    assert list(ds["record"].values[-2:]) == ["record-0005", "record-0006"]
    assert np.isnat(ds["time"].values[-2:]).all() and not np.isnat(ds["time"].values[:-2]).any()
    # the record without a temperature after the reference is tracked but not tested, and the
    # summary counts only the records tested
    k = list(ds["record"].values).index("record-0018")
    assert np.isfinite(ds["frequency_hz"].values[k]).any() and np.isnan(ds["control"].values[k]).all()
    tested = int(np.isfinite(ds["control"].values[~ds["in_reference"].values, 0]).sum())
    assert tested == 24 - 8 - 1
    text = str(m)
    assert f" of {tested}" in text and "note: 2 records have no value of a covariate" in text
    assert "note:" not in m.summary(notes=False)
    assert json.loads(ds.attrs["notes"]) == list(m.notes)
    # a reference period that takes every record
    with pytest.warns(modaluq.ModalUQWarning, match="takes all 5 identified records.*no record after it is tested"):
        monitor(campaign.records[:5], settings=SETTINGS, progress=False)


def test_a_covariate_table_must_name_the_records(csv_folder, tmp_path):
    import pandas as pd

    folder, _ = csv_folder
    table = pd.read_csv(folder.with_name("site.covariates.csv"))
    table.drop(columns="record").to_csv(tmp_path / "no_record.csv", index=False)  # a weather station's export
    with pytest.raises(ValueError, match="covariates: the table needs a 'record' column"):
        monitor(folder, covariates=tmp_path / "no_record.csv", out=tmp_path / "t.nc", progress=False)
    table.assign(record="x" + table["record"]).to_csv(tmp_path / "other_names.csv", index=False)
    with pytest.raises(ValueError, match="covariates: no row of the table is a record"):
        monitor(folder, covariates=tmp_path / "other_names.csv", out=tmp_path / "t.nc", progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["no_record.csv", "other_names.csv"]  # nothing written


def test_the_callers_warning_filters_are_the_same_after_a_thread_pool_run(campaign):
    import warnings

    before = list(warnings.filters)
    monitor(campaign.records[:8], settings=SETTINGS, threads=2, progress=False,
            tracking=TrackingSettings(reference_records=4))
    assert warnings.filters == before


def test_on_a_thread_pool_each_record_keeps_its_own_warnings_and_none_is_issued(campaign, monkeypatch):
    import warnings

    from modaluq import analysis

    # a warning that words each record's own estimate (the analysis's real warnings are the same
    # sentence in every record of a campaign): which record's words end up where
    def own_words(result, selected, lag=None, pole_frequency_hz=None):
        return [f"mode 1 of this record at {selected.frequency_hz[0]:.9f} Hz"] if selected.n_modes else []

    monkeypatch.setattr(analysis, "_warnings_of_selection", own_words)
    settings, tracking = SETTINGS.replace(n_blocks=60), TrackingSettings(reference_records=4)
    expected = monitor(campaign.records[:8], settings=settings, threads=1, progress=False,
                       tracking=tracking).dataset["warnings"].values
    assert len(set(expected)) >= 4 and all(w.startswith("mode 1 of this record at 1.9") for w in expected if w)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        threaded = monitor(campaign.records[:8], settings=settings, threads=2, progress=False, tracking=tracking)
    assert [str(w.message) for w in caught if issubclass(w.category, modaluq.ModalUQWarning)] == []
    np.testing.assert_array_equal(threaded.dataset["warnings"].values, expected)


def test_a_failed_part_write_stops_the_queued_records(campaign, tmp_path, monkeypatch):
    from modaluq.monitoring import parts, run

    started = []

    def counted(task, config):
        started.append(task.key)
        return process_record(task, config)

    process_record = run.process_record
    monkeypatch.setattr(run, "process_record", counted)

    def full_disk(self, key, text):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(parts.Parts, "write", full_disk)
    with pytest.raises(OSError, match="No space left"):
        monitor(campaign.records[:12], settings=SETTINGS, out=tmp_path / "t.nc", threads=1, progress=False)
    assert len(started) <= 2  # the one that failed to be written, and at most the one already running


def test_no_resume_starts_again_with_other_settings(campaign, tmp_path):
    out = tmp_path / "t.nc"
    tracking = TrackingSettings(reference_records=4)
    monitor(campaign.records[:6], settings=SETTINGS, out=out, progress=False, tracking=tracking)
    other = SETTINGS.replace(orders=tuple(range(2, 21, 2)))
    again = monitor(campaign.records[:5], settings=other, out=out, progress=False, tracking=tracking, resume=False)
    assert again.n_run == 5
    assert len([p for p in (tmp_path / "t.parts").glob("*.json") if p.name != "settings.json"]) == 5
    assert monitor(campaign.records[:5], settings=other, out=out, progress=False, tracking=tracking).n_run == 0


def test_time_from_file_names_and_record_order():
    assert time_from_name("bridge_2026-03-01_12-30-00.csv") == np.datetime64("2026-03-01T12:30:00")
    assert time_from_name("acc20260301T1230.h5") == np.datetime64("2026-03-01T12:30:00")
    assert time_from_name("run1.csv") is None


def test_bad_arguments_are_errors_naming_the_parameter(campaign, tmp_path):
    with pytest.raises(ValueError, match="records"):
        monitor([], progress=False)
    with pytest.raises(TypeError, match="records"):
        monitor([42], progress=False)
    with pytest.raises(ValueError, match="more than once"):
        monitor([campaign.records[0], campaign.records[0]], progress=False)
    with pytest.raises(ValueError, match="out"):
        monitor(campaign.records[:3], out=tmp_path / "t.txt", progress=False)
    with pytest.raises(TypeError, match="tracking"):
        monitor(campaign.records[:3], tracking={"smoothing": 1}, progress=False)
    with pytest.raises(ValueError, match="at most one of"):
        monitor(campaign.records[:3], workers=2, scheduler="tcp://localhost:1", progress=False)
    with pytest.raises(ValueError, match="at most one of executor=, threads="):  # not silently one of them
        monitor(campaign.records[:3], threads=1, executor=concurrent.futures.ThreadPoolExecutor(1), progress=False)
    with pytest.raises(TypeError, match="records must be"):
        monitor(np.zeros((3, 1000)), progress=False)
    with pytest.raises(ValueError, match="pattern"):
        monitor(str(tmp_path / "*.csv"), progress=False)
    # a mistyped folder: said so, and nothing written
    with pytest.raises(ValueError, match="no such file or folder: .*nosuch"):
        monitor(str(tmp_path / "nosuch") + "/", out=tmp_path / "t.nc", progress=False)
    with pytest.raises(ValueError, match="no such file or folder"):
        monitor(tmp_path / "nosuch", out=tmp_path / "t.nc", progress=False)
    assert not list(tmp_path.iterdir())


def test_plots_of_the_tracks(serial, tmp_path):
    fig = serial.plot_frequencies()
    assert len(fig.axes) == 6
    fig.savefig(tmp_path / "f.png")
    fig = serial.plot_control_chart()
    assert len(fig.axes) == 6 and fig.axes[0].get_yscale() == "log"
    for ax, mode in zip(fig.axes, serial.dataset["mode"].values):  # every record's χ² is on its axis
        assert np.nanmax(serial.dataset["chi2"].sel(mode=mode).values) <= ax.get_ylim()[1]


def test_the_summary_is_what_a_notebook_shows_and_alarms_carry_the_modes_calibration(serial):
    assert repr(serial).startswith("<modaluq Monitoring: 24 records>\n24 records: 24 identified")
    alarms = serial.alarms()
    assert list(alarms.columns) == ["record", "time", "mode", "frequency_hz", "frequency_change", "damping_change",
                                    "control", "sigma_confirmed", "shape_p_value", "frequency_damping_alarm",
                                    "shape_alarm"]
    confirmed = serial.dataset["sigma_confirmed"].values
    assert alarms["sigma_confirmed"].tolist() == [bool(confirmed[m - 1]) for m in alarms["mode"]]
    ds = serial.dataset
    # one row per record and mode with an alarm of either test, each flag as the store has it
    either = ds["alarm"].values | ds["shape_alarm"].values
    assert len(alarms) == int(either.sum())
    for _, row in alarms.iterrows():
        at = dict(record=row["record"], mode=row["mode"])
        assert row["frequency_damping_alarm"] == bool(ds["alarm"].sel(at)) and \
            row["shape_alarm"] == bool(ds["shape_alarm"].sel(at))
        assert row["shape_p_value"] == pytest.approx(float(ds["shape_p_value"].sel(at)), nan_ok=True)


def test_a_store_written_before_the_shape_test_still_gives_its_summary_alarms_and_plot(serial, tmp_path):
    path = tmp_path / "old.nc"  # a store as modaluq wrote it before the shape test
    serial.dataset.drop_vars(["shape_p_value", "shape_alarm", "mac_to_reference_std",
                              *COMPLEX_SHAPES]).to_netcdf(path)  # complex shapes as their parts, as store.write
    old = dataclasses.replace(serial, dataset=load_tracks(path))
    alarms = old.alarms()
    assert len(alarms) == int(serial.dataset["alarm"].values.sum())  # the change test's alarms only
    assert not alarms["shape_alarm"].any() and alarms["shape_p_value"].isna().all()
    assert alarms["frequency_damping_alarm"].all()
    rows = old.summary(notes=False).splitlines()[3:3 + serial.dataset.sizes["mode"]]
    assert rows and all(r.rstrip().endswith(" -") for r in rows), rows  # "-": no shape test in this store
    plot_tracked_frequencies(old.dataset).savefig(tmp_path / "old.png")


def test_without_the_change_test_the_shape_alarms_are_still_listed(serial):
    # the regression of f and ξ could not be made (e.g. a covariate constant over the reference):
    # the store has no control statistic, but the shapes were tested
    ds = serial.dataset.drop_vars(["control", "control_limit", "frequency_change", "damping_change", "chi2",
                                   "sigma_confirmed", "alarm"], errors="ignore").copy(deep=True)
    flags = ds["shape_alarm"].transpose("record", "mode").values
    flags[:] = False
    flags[-3:, 0] = True  # three shape alarms of mode 1
    ds["shape_alarm"] = (("record", "mode"), flags)
    m = dataclasses.replace(serial, dataset=ds)
    alarms = m.alarms()
    assert alarms["record"].tolist() == list(ds["record"].values[-3:]) and alarms["mode"].tolist() == [1, 1, 1]
    assert alarms["shape_alarm"].all() and not alarms["frequency_damping_alarm"].any()
    assert alarms[["frequency_change", "damping_change", "control"]].isna().all().all()
    assert alarms["sigma_confirmed"].isna().all()
    assert "3 of " in m.summary(notes=False).splitlines()[3]  # mode 1's row counts them


def test_a_single_record_and_simulated_files_and_objects_name_their_channels_alike(campaign, tmp_path):
    with pytest.warns(modaluq.ModalUQWarning, match="takes all 1 identified records"):
        assert monitor(campaign.records[0], settings=SETTINGS, progress=False, threads=1).n_records == 1
    files = campaign.write(tmp_path / "site", format="npz")
    m = monitor([files[0], *campaign.records[1:4]], settings=SETTINGS, progress=False, threads=1,
                covariates=tmp_path / "site.covariates.csv", tracking=TrackingSettings(reference_records=3))
    assert m.n_failed == 0 and list(m.dataset["channel"].values) == list(campaign.records[0].output_names)
    assert campaign.records[0].output_names == ("acc1", "acc2", "acc5")
