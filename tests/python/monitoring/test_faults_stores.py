"""Issue 26, items 6 and 10: the outputs of a monitoring run are written atomically (the previous
store and tables survive a full disk, a failed write, a kill -9 during the write, a concurrent
writer; the temporaries of dead writers are removed), and no CSV cell the package writes is run
by a spreadsheet as a formula."""

import csv
import dataclasses
import errno
import os
import pickle
import random
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from monitoring_support import SETTINGS

from modaluq import atomic
from modaluq.monitoring import load_tracks, monitor, simulate_monitoring, store
from modaluq.monitoring.tracking import TrackingSettings

xr = pytest.importorskip("xarray")
pytest.importorskip("zarr")
pytest.importorskip("netCDF4")

PYTHON_PATH = os.pathsep.join([str(Path(atomic.__file__).parents[1]), str(Path(__file__).parent)])


def leftovers(folder: Path) -> list:
    """The temporaries beside the outputs (this writer's and any other's)."""
    return sorted(p.name for p in folder.iterdir() if ".tmp-" in p.name or ".old-" in p.name
                  or p.name.endswith(".tmp"))


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """Two runs over one folder with different tracking (a: 6 reference records, b: 8, one failure more),
    so that an old and a new store can be told apart; pickled for the writer subprocesses."""
    base = tmp_path_factory.mktemp("stores")
    simulate_monitoring(8, n_samples=3000, seed=3).write(base / "site")
    out = base / "run.nc"
    a = monitor(base / "site", settings=SETTINGS, out=out, tracking=TrackingSettings(reference_records=6),
                threads=1, progress=False)
    b = monitor(base / "site", settings=SETTINGS, out=out, tracking=TrackingSettings(reference_records=5),
                threads=1, progress=False)
    b = dataclasses.replace(b, failures=pd.DataFrame([{"record": "bad.csv", "source": "bad.csv", "stage": "load",
                                                       "error": "ValueError: corrupt"}]))
    assert not a.dataset.identical(b.dataset)
    (base / "results.pkl").write_bytes(pickle.dumps((a, b)))
    return base, a, b


def outputs(folder: Path, kind: str) -> dict:
    return store.output_paths(folder / f"t.{kind}", None)


def snapshot(paths: dict):
    return (load_tracks(paths["store"]), paths["poles"].read_bytes(), paths["failures"].read_bytes())


# ---- item 6: a failed write leaves the previous outputs ------------------------------------------------------


@pytest.mark.parametrize("kind", ["nc", "zarr"])
def test_a_full_disk_during_the_store_write_leaves_the_previous_outputs(results, tmp_path, monkeypatch, kind):
    _, a, b = results
    paths = outputs(tmp_path, kind)
    store.write(a, paths)
    before = snapshot(paths)
    method = "to_netcdf" if kind == "nc" else "to_zarr"
    original = getattr(xr.Dataset, method)

    def half_then_full(self, target, *args, **kwargs):  # some bytes written, then the disk is full
        original(self, target, *args, **kwargs)
        if kind == "nc":
            os.truncate(target, os.path.getsize(target) // 2)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(xr.Dataset, method, half_then_full)
    with pytest.raises(OSError, match="No space left") as info:
        store.write(b, paths)
    assert str(paths["store"]) in str(info.value) and info.value.errno == errno.ENOSPC
    monkeypatch.undo()
    xr.testing.assert_identical(load_tracks(paths["store"]), before[0])
    assert paths["poles"].read_bytes() == before[1]  # intact, not emptied
    assert "bad.csv" in paths["failures"].read_text()  # still written: the new run's failures
    assert leftovers(tmp_path) == []


def test_a_failed_pole_table_write_replaces_nothing_but_the_failures(results, tmp_path, monkeypatch):
    _, a, b = results
    paths = outputs(tmp_path, "zarr")
    store.write(a, paths)
    before = snapshot(paths)
    original = pd.DataFrame.to_csv

    def full_for_poles(self, target=None, *args, **kwargs):
        if target is not None and "poles" in str(target):
            Path(target).write_text("record,ti")
            raise OSError(errno.ENOSPC, "No space left on device")
        return original(self, target, *args, **kwargs)

    monkeypatch.setattr(pd.DataFrame, "to_csv", full_for_poles)
    with pytest.raises(OSError, match=str(paths["poles"]).replace(".", r"\.")):
        store.write(b, paths)
    monkeypatch.undo()
    xr.testing.assert_identical(load_tracks(paths["store"]), before[0])  # the store waits for the tables
    assert paths["poles"].read_bytes() == before[1]
    assert "bad.csv" in paths["failures"].read_text()
    assert leftovers(tmp_path) == []


@pytest.fixture
def small_disk(tmp_path):
    """A 2 MB tmpfs (root only; skipped where mounting is not permitted)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk)],
                      capture_output=True).returncode != 0:
        pytest.skip("mounting a tmpfs is not permitted here")
    try:
        yield disk
    finally:
        # lazy if busy: a library may still hold a removed file open there (netCDF after a
        # failed close); a mount left behind would block the cleaning of pytest's old folders
        if subprocess.run(["umount", str(disk)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(disk)], check=False)


@pytest.mark.parametrize("kind", ["nc", "zarr"])
def test_a_real_full_disk_leaves_the_previous_outputs_and_writes_the_failures(results, small_disk, kind):
    _, a, b = results
    paths = outputs(small_disk, kind)
    store.write(a, paths)
    before = snapshot(paths)
    filler = small_disk / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT)  # fill the disk, then leave room for the failures table only
    try:
        while os.write(fd, b"\1" * 4096):
            pass
    except OSError as exc:
        assert exc.errno == errno.ENOSPC
    finally:
        os.close(fd)
    os.truncate(filler, max(0, filler.stat().st_size - 16 * 4096))
    with pytest.raises(OSError, match="No space left") as info:
        store.write(b, paths)
    assert any(str(paths[k]) in str(info.value) for k in ("store", "poles"))  # the one that did not fit
    xr.testing.assert_identical(load_tracks(paths["store"]), before[0])
    assert paths["poles"].read_bytes() == before[1]
    assert "bad.csv" in paths["failures"].read_text()
    assert leftovers(small_disk) == []
    filler.unlink()
    store.write(b, paths)  # room again: the retry succeeds (no temporary in its way)
    xr.testing.assert_identical(load_tracks(paths["store"]), b.dataset)


def test_a_writer_that_keeps_its_failed_file_open_does_not_keep_its_space(small_disk):
    # netCDF's C library keeps its file open when closing fails on a full disk (found by
    # scripts/fault_campaign.py: the failures table written after a failed store found no room).
    # A writer that fills the disk and fails holding its descriptor, as netCDF does: once the
    # write has failed, the space is back and the next output fits.
    held = []

    def fill_and_fail(tmp):
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT)
        held.append(fd)  # the library's handle, out of reach of Python
        while True:
            os.write(fd, b"\1" * 65536)  # ENOSPC ends it

    free = shutil.disk_usage(small_disk).free
    try:
        with pytest.raises(OSError, match="No space left"):
            atomic.write_temporary(small_disk / "tracks.nc", fill_and_fail)
        assert shutil.disk_usage(small_disk).free >= free - 4096
        atomic.write_atomically(small_disk / "tracks.failures.csv", lambda tmp: Path(tmp).write_text("record\n"))
        assert leftovers(small_disk) == []
    finally:
        for fd in held:
            os.close(fd)


# ---- item 6: temporaries of dead writers, a store left half swapped ------------------------------------------


def test_the_temporaries_of_dead_writers_are_removed_and_a_half_swapped_store_is_put_back(results, tmp_path):
    _, a, _ = results
    paths = outputs(tmp_path, "zarr")
    store.write(a, paths)
    expected = load_tracks(paths["store"])
    pid = dead_pid()
    os.rename(paths["store"], tmp_path / f"t.zarr.old-{pid}")  # killed between the two renames of the swap
    (tmp_path / f"t.zarr.tmp-{pid}").mkdir()  # and a half-written store of another dead writer
    (tmp_path / f"t.poles.csv.tmp-{pid}").write_text("record,ti")
    (tmp_path / f"t.failures.csv.tmp-{os.getpid()}").write_text("x")  # ours, left by a process that had our pid
    (tmp_path / ".t.zarr.123456789.tmp").mkdir()  # an earlier version's temporary
    live = tmp_path / f"t.zarr.tmp-{os.getppid()}"  # a live writer's: left alone
    live.mkdir()
    done = store.recover(paths)
    assert len(done) == 5 and "put back" in done[0]
    xr.testing.assert_identical(load_tracks(paths["store"]), expected)
    assert leftovers(tmp_path) == [live.name]


def test_a_run_starts_by_cleaning_up_and_a_leftover_never_blocks_it(results, tmp_path):
    base, a, _ = results
    out = base / "run.zarr"  # the fixture's parts: nothing is identified again
    pid = dead_pid()
    (base / f"run.zarr.tmp-{pid}").mkdir()
    (base / f"run.zarr.tmp-{os.getpid()}").write_text("not a directory")  # in the way of our own temporary
    (base / f"run.poles.csv.tmp-{pid}").write_text("x")
    m = monitor(base / "site", settings=SETTINGS, out=out, tracking=TrackingSettings(reference_records=6),
                threads=1, progress=False)
    assert m.n_run == 0
    xr.testing.assert_identical(load_tracks(out), m.dataset)
    assert [n for n in leftovers(base) if n.startswith("run.")] == []


# ---- item 6: kill -9 during the write, two writers at once ----------------------------------------------------

WRITER = """
import pickle, sys
from pathlib import Path
from modaluq.monitoring import store
a, b = pickle.loads(Path(sys.argv[1]).read_bytes())
paths = store.output_paths(sys.argv[2], None)
print("ready", flush=True)
for i in range(int(sys.argv[3])):
    store.write((a, b)[(i + int(sys.argv[4])) % 2], paths)
"""


def writer(base: Path, out: Path, rounds: int, first: int) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", WRITER, str(base / "results.pkl"), str(out), str(rounds),
                             str(first)], stdout=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONPATH=PYTHON_PATH))


def finish(proc: subprocess.Popen) -> int:
    """Wait for a writer, close its pipe; its exit code."""
    code = proc.wait(timeout=300)
    proc.stdout.close()
    return code


def stored(result) -> tuple:
    """What store.write writes of ``result``: the store as read back, the pole table's bytes."""
    return result.dataset, atomic.csv_safe(result.poles).to_csv(index=False).encode()


@pytest.mark.parametrize("kind, kills", [("zarr", 3), ("nc", 2)])
def test_kill_9_during_the_write_leaves_a_readable_store_and_the_resume_completes_it(results, tmp_path, kind, kills):
    base, a, b = results
    paths = outputs(tmp_path, kind)
    store.write(a, paths)
    candidates = [stored(a), stored(b)]
    rng = random.Random(26)
    for _ in range(kills):
        proc = writer(base, paths["store"], 1000, rng.randrange(2))
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(rng.uniform(0.0, 1.5))  # one write takes 0.3-3 s here: any moment of it
        proc.kill()
        finish(proc)
        if not paths["store"].exists():  # killed between the two renames of a Zarr swap: the old one is beside it
            olds = list(tmp_path.glob(f"t.{kind}.old-*"))
            assert kind == "zarr" and len(olds) == 1
            xr.open_zarr(olds[0]).load()  # readable where it is
            assert store.recover(paths)
        ds, poles = load_tracks(paths["store"]), paths["poles"].read_bytes()
        assert any(ds.identical(c[0]) for c in candidates)  # the old store or the new one, whole
        assert poles in [c[1] for c in candidates]
    # the resume (from the fixture's parts): the same store as an uninterrupted run, nothing left over
    shutil.copytree(base / "run.parts", tmp_path / "t.parts")
    m = monitor(base / "site", settings=SETTINGS, out=paths["store"], tracking=TrackingSettings(reference_records=6),
                threads=1, progress=False)
    xr.testing.assert_identical(load_tracks(paths["store"]), a.dataset)
    assert m.n_run == 0
    xr.testing.assert_identical(m.dataset, a.dataset)
    assert paths["poles"].read_bytes() == candidates[0][1]
    assert leftovers(tmp_path) == []


def test_two_writers_at_once_do_not_corrupt_each_other(results, tmp_path):
    base, a, b = results
    paths = outputs(tmp_path, "zarr")
    procs = [writer(base, paths["store"], 3, first) for first in (0, 1)]
    assert [finish(p) for p in procs] == [0, 0]
    ds = load_tracks(paths["store"])
    assert any(ds.identical(r.dataset) for r in (a, b))
    assert leftovers(tmp_path) == []


# ---- item 10: formulas in CSV cells ---------------------------------------------------------------------------


def test_csv_cells_that_start_a_formula_are_escaped_and_numbers_are_not():
    assert [atomic.csv_cell(v) for v in ("=cmd|' /C calc'!A0", "+1+2", "-x", "@SUM(A1)", "\tx", "\rx")] == [
        "'=cmd|' /C calc'!A0", "'+1+2", "'-x", "'@SUM(A1)", "'\tx", "'\rx"]
    assert [atomic.csv_cell(v) for v in (-0.5, "-0.5", "+1e3", "record-1.csv", np.float64(-2), 3, None)] == [
        -0.5, "-0.5", "+1e3", "record-1.csv", -2.0, 3, None]
    frame = pd.DataFrame({"name": ["=1+1", "ok"], "value": [-0.5, 2.0]})
    text = atomic.csv_safe(frame).to_csv(index=False)
    assert text.splitlines() == ["name,value", "'=1+1,-0.5", "ok,2.0"]
    assert frame["name"][0] == "=1+1"  # the caller's table is not changed


def test_file_names_starting_a_formula_are_escaped_in_the_pole_and_failure_tables(tmp_path):
    folder = tmp_path / "site"
    paths = simulate_monitoring(4, n_samples=3000, seed=4).write(folder)
    for p, name in zip(paths, ("=HYPERLINK(x).csv", "+plus.csv", "-minus.csv", "@at.csv")):
        p.rename(folder / name)
    (folder / "=bad.csv").write_text("not,a\nrecord\n")
    m = monitor(folder, settings=SETTINGS, out=tmp_path / "t.nc", threads=1, progress=False,
                tracking=TrackingSettings(reference_records=3))
    with open(tmp_path / "t.poles.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["record"] for r in rows} == {"'=HYPERLINK(x).csv", "'+plus.csv", "'-minus.csv", "'@at.csv"}
    assert all(float(r["frequency_hz"]) > 0 for r in rows)  # numbers stay numbers
    with open(tmp_path / "t.failures.csv", newline="") as fh:
        failures = list(csv.DictReader(fh))
    assert [f["record"] for f in failures] == ["'=bad.csv"] and failures[0]["source"].endswith("/=bad.csv")
    assert m.failures["record"].tolist() == ["=bad.csv"]  # the table in memory keeps the names
