"""Issue 26, items 1, 3 and 8: a part says "done" about bytes, not a path; one run at a time on a
store; records reached through symbolic links (docs/reliability.md, "Batches of records")."""

import os
import shutil
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from monitoring_support import SETTINGS

import modaluq
from modaluq.cli import main
from modaluq.monitoring import TrackingSettings, monitor, simulate_monitoring
from modaluq.monitoring import worker as worker_module

pytest.importorskip("xarray")

TRACKING = TrackingSettings(reference_records=3)
RUN = dict(settings=SETTINGS, tracking=TRACKING, threads=1, progress=False)


@pytest.fixture(scope="module")
def six_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("six") / "site"
    simulate_monitoring(6, n_samples=4000, seed=5).write(folder)
    return folder


@pytest.fixture
def site(six_files, tmp_path):
    """A fresh copy of the six records, last modified a minute ago (settled)."""
    folder = tmp_path / "site"
    shutil.copytree(six_files, folder)
    _age(*folder.iterdir())
    return folder


def _age(*paths, seconds=60):
    then = time.time() - seconds
    for p in paths:
        os.utime(p, (then, then))


def test_a_record_completed_after_its_first_run_is_run_again(site, tmp_path):
    last = sorted(site.glob("*.csv"))[-1]
    full = last.read_bytes()
    lines = full.splitlines(keepends=True)
    last.write_bytes(b"".join(lines[:len(lines) // 2]))  # cut at a line end: a valid, shorter record
    _age(last)
    out = tmp_path / "t.nc"
    first = monitor(site, out=out, **RUN)
    assert first.n_run == 6 and first.n_failed == 0
    last.write_bytes(full)  # the acquisition finishes the file
    _age(last, seconds=30)
    again = monitor(site, out=out, **RUN)
    assert again.n_run == 1  # the completed record only
    fresh = monitor(site, out=tmp_path / "fresh.nc", **RUN)
    assert again.dataset["n_blocks"].values[-1] == fresh.dataset["n_blocks"].values[-1] > \
        first.dataset["n_blocks"].values[-1]
    np.testing.assert_array_equal(again.dataset["frequency_hz"].values, fresh.dataset["frequency_hz"].values)
    # touched but the same bytes: its hash is the part's, nothing is run again
    _age(last, seconds=20)
    assert monitor(site, out=out, **RUN).n_run == 0


def test_a_file_modified_in_the_last_seconds_is_left_for_the_next_run(site, tmp_path, monkeypatch):
    monkeypatch.setenv("MODALUQ_SETTLE_SECONDS", str(worker_module.SETTLE_SECONDS))
    last = sorted(site.glob("*.csv"))[-1]
    last.write_bytes(last.read_bytes())  # written just now
    out = tmp_path / "t.nc"
    with pytest.warns(modaluq.ModalUQWarning, match=f"still being written.*{last.name}"):
        first = monitor(site, out=out, **RUN)
    assert first.n_records == 5 and first.n_failed == 0 and last.name not in first.dataset["record"].values
    _age(last)
    again = monitor(site, out=out, **RUN)
    assert again.n_run == 1 and again.n_records == 6 and again.n_failed == 0


def test_a_file_that_changes_while_it_is_read_is_not_done(site, tmp_path, monkeypatch):
    last = sorted(site.glob("*.csv"))[-1]
    original = worker_module._analysis

    def rewritten_while_read(task, config):
        analysis = original(task, config)
        if task.name == last.name:
            last.write_bytes(last.read_bytes())  # the same bytes, written again: its mtime moves
        return analysis

    monkeypatch.setattr(worker_module, "_analysis", rewritten_while_read)
    out = tmp_path / "t.nc"
    with pytest.warns(modaluq.ModalUQWarning, match=f"still being written.*{last.name}"):
        first = monitor(site, out=out, **RUN)
    assert first.n_records == 5 and first.n_failed == 0
    monkeypatch.setattr(worker_module, "_analysis", original)
    again = monitor(site, out=out, **RUN)
    assert again.n_run == 1 and again.n_records == 6


def test_parts_made_with_other_settings_are_not_used(site, tmp_path):
    # two runs with other settings writing into one folder of parts (what the store lock now
    # prevents) leave parts of both: those of the other settings are run again, not used
    first = monitor(site, out=tmp_path / "a.nc", **RUN)
    monitor(site, out=tmp_path / "b.nc", **dict(RUN, settings=SETTINGS.replace(orders=tuple(range(2, 21, 2)))))
    theirs = sorted((tmp_path / "b.parts").glob("[!s]*.json"))
    for p in theirs[:2]:
        shutil.copy(p, tmp_path / "a.parts" / p.name)
    again = monitor(site, out=tmp_path / "a.nc", **RUN)
    assert again.n_run == 2
    np.testing.assert_array_equal(again.dataset["frequency_hz"].values, first.dataset["frequency_hz"].values)
    assert again.poles.equals(first.poles)


_HOLDER = textwrap.dedent("""
    import sys, time
    from modaluq.monitoring.parts import store_lock
    with store_lock(sys.argv[1], command="the night's run"):
        print("locked", flush=True)
        time.sleep(120)
""")


def test_a_second_run_on_a_store_is_refused_naming_the_holder(site, tmp_path, capsys):
    out = tmp_path / "t.nc"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(out)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(RuntimeError, match=rf"in use by another run: pid {holder.pid} on .*the night's run"):
            monitor(site, out=out, **RUN)
        assert not (tmp_path / "t.parts").exists()  # refused before anything is touched
        assert main(["monitor", str(site), "--out", str(out), "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert f"pid {holder.pid}" in err and "the night's run" in err
        # killed (kill -9) while holding it: the lock left behind does not block
        holder.kill()
        holder.wait(30)
    finally:
        holder.kill()
        holder.wait(30)
        holder.stdout.close()
    assert (tmp_path / "t.lock").exists()
    assert monitor(site, out=out, **RUN).n_run == 6


def test_the_same_record_through_a_symbolic_link_is_taken_once(site, tmp_path):
    last = sorted(site.glob("*.csv"))[-1]
    (site / "latest.csv").symlink_to(last.name)
    with pytest.warns(modaluq.ModalUQWarning, match=f"latest.csv.*same file as {last.name}"):
        m = monitor(site, out=tmp_path / "t.nc", **RUN)
    assert m.n_records == 6 and m.n_failed == 0 and "latest.csv" not in m.dataset["record"].values
    # a link and its target given one by one: the same
    with pytest.warns(modaluq.ModalUQWarning, match="same file"):
        m = monitor(sorted(site.glob("*.csv")), **RUN)
    assert m.n_records == 6


def test_a_dangling_link_is_a_failure_at_load(site, tmp_path):
    (site / "gone.csv").symlink_to(tmp_path / "moved-away.csv")
    m = monitor(site, out=tmp_path / "t.nc", **RUN)
    assert m.n_records == 7 and m.n_failed == 1
    row = m.failures.iloc[0]
    assert row["record"] == "gone.csv" and row["stage"] == "load" and "dangling symbolic link" in row["error"]
    assert "gone.csv" in (tmp_path / "t.failures.csv").read_text()
