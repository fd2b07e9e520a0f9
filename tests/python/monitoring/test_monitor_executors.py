"""Where the records run (modaluq.monitoring.executors): threads, a Dask cluster, a scheduler,
worker processes; a killed run restarted."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from monitoring_support import SETTINGS, assert_same_tracks

from modaluq.monitoring import TrackingSettings, load_tracks, monitor, record_files, simulate_monitoring

pytest.importorskip("xarray")


def test_results_do_not_depend_on_the_number_of_threads(serial, campaign):
    assert_same_tracks(serial, monitor(campaign.records, settings=SETTINGS, threads=2, progress=False))


# ------------------------------------------------------------------------------ Dask


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    # the scheduler's HTTP server on a random port: Dask's default 8787 may be another cluster's (a warning)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) \
            as cluster, distributed.Client(cluster) as client:
        yield client


@pytest.mark.slow
def test_dask_local_cluster_gives_the_serial_results(dask_client, csv_folder, tmp_path):
    folder, _ = csv_folder
    files = record_files(folder)
    cov = folder.with_name("site.covariates.csv")
    eight = TrackingSettings(reference_records=8)
    serial = monitor(files, settings=SETTINGS, threads=1, progress=False, covariates=cov, tracking=eight)
    on_dask = monitor(files, settings=SETTINGS, executor=dask_client, progress=False, covariates=cov, tracking=eight)
    assert_same_tracks(serial, on_dask, other_process=True)
    # a corrupt file among them: reported, the others finish
    (tmp_path / "corrupt.npz").write_bytes(b"PK\x03\x04 not a zip")
    m = monitor(files + [tmp_path / "corrupt.npz"], settings=SETTINGS, executor=dask_client, progress=False,
                covariates=cov, tracking=eight)
    assert m.n_failed == 1 and m.failures.iloc[0]["stage"] == "load"
    np.testing.assert_array_equal(m.dataset["frequency_hz"].values[:20], serial.dataset["frequency_hz"].values)
    # a running scheduler by its address: the same results
    by_address = monitor(files, settings=SETTINGS, scheduler=dask_client.scheduler.address, progress=False,
                         covariates=cov, tracking=eight)
    assert_same_tracks(serial, by_address, other_process=True)


@pytest.mark.slow
def test_a_killed_run_restarted_finishes_every_record_exactly_once(tmp_path):
    pytest.importorskip("distributed")
    folder = tmp_path / "site"
    simulate_monitoring(20, n_samples=20000, seed=2).write(folder, format="npz")
    out = tmp_path / "tracks.nc"
    cmd = [sys.executable, "-m", "modaluq.cli", "monitor", str(folder), "--out", str(out), "--orders", "2:40:2",
           "--workers", "2", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    parts = tmp_path / "tracks.parts"
    deadline = time.time() + 120
    while time.time() < deadline and len(list(parts.glob("*.json"))) < 6:  # settings.json + 5 records
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)  # the driver and its workers, mid-run
    proc.wait()
    done_before = {p.name: p.read_bytes() for p in parts.glob("*.json") if p.name != "settings.json"}
    assert 5 <= len(done_before) < 20 and not out.exists()
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert f"({20 - len(done_before)} run now" in again.stdout
    ds = load_tracks(out)
    names = list(ds["record"].values)
    assert sorted(names) == sorted(f"record-{k:04d}.npz" for k in range(20)) and len(set(names)) == 20
    assert (ds["status"].values == "done").all()
    # the parts finished before the kill were not run again
    assert all((parts / n).read_bytes() == b for n, b in done_before.items())
    assert len([p for p in parts.glob("*.json") if p.name != "settings.json"]) == 20
    assert not list(parts.glob(".*.tmp"))
    json.loads((parts / "settings.json").read_text())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
def test_a_worker_process_reuses_large_buffers_under_dasks_malloc_setting():
    # Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which also fixes glibc's mmap
    # threshold at 128 KiB: every large temporary is then a fresh mmap whose pages fault in again
    # (a record took 1.14 s instead of 0.83 s). After the worker's configuration they are reused.
    code = """
import resource, numpy as np
from modaluq.monitoring.executors import configure_worker_process
def faults():
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(20):
        np.ones(1 << 19).sum()  # 4 MiB, allocated and freed
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
as_dask_starts_it = faults()
configure_worker_process()
faults()  # the first buffer on the heap faults in once
print(as_dask_starts_it, faults())
"""
    env = dict(os.environ, MALLOC_TRIM_THRESHOLD_="65536")
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    as_dask_starts_it, configured = map(int, run.stdout.split())
    assert as_dask_starts_it > 20 * 256  # each 4 MiB buffer faults in again (here 514 faults of its 1024 pages)
    assert configured < as_dask_starts_it / 10, (as_dask_starts_it, configured)
