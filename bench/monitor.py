#!/usr/bin/env python
"""Benchmark of ``modaluq.monitor`` (issue 15): the pipeline's overhead over a bare identify, the
scaling from 1 to 2 workers, and the peak memory of a worker.

    python bench/monitor.py                          # 200 records of 20 channels x 10^5 samples
    python bench/monitor.py --records 40 --samples 50000

The records are written once to ``--data`` (``.npz``, 16 MB each at the default size: 3.2 GB) by
the simulator (20-DOF chain, output-only, 100 Hz), so making them is not timed. Then, in one run:

- ``bare``: a user's own loop, serially, one BLAS thread: ``np.load`` of each file and
  ``modaluq.identify`` on its samples, the floor of the pipeline (the identify calls alone are
  timed too);
- ``monitor`` on the thread pool (1 and 2 threads) and on a Dask ``LocalCluster`` (1 and 2
  one-thread worker processes): load, preprocess, identify, select, write the part file, then
  track and write the store, all timed (the cluster's start is not);
- the peak resident memory of each Dask worker process (``ru_maxrss``) after its run.

The overhead is ``t(monitor, 1 worker) / t(bare load + identify) - 1``; the scaling ``t(1 worker) / t(2 workers)``.
Results go to stdout as a table and to ``--json``; docs/performance.md records them.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np


def make_records(folder: Path, n_records: int, n_channels: int, n_samples: int) -> list:
    from modaluq.simulate import simulate

    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for k in range(n_records):
        # one record every 10 minutes from 2026-01-01 00:00, the time in the name (days roll over:
        # an hour 24 is no time, and monitor would say so)
        start = str(np.datetime64("2026-01-01T00:00:00") + np.timedelta64(10 * k, "m"))
        path = folder / f"rec_{start.replace('T', '_').replace(':', '-')}_{k:04d}.npz"
        if not path.exists():
            sim = simulate(n_samples, seed=k, n_dof=n_channels, output_dofs=tuple(range(n_channels)), input_dofs=(),
                           input_std=1.0, unknown_input_std=1.0, fs=100.0)
            np.savez(path, y=sim.y.astype(np.float64), fs=sim.fs)
        paths.append(path)
        print(f"\rrecords: {k + 1}/{n_records}", end="", file=sys.stderr)
    print(file=sys.stderr)
    return paths


def bare(paths) -> tuple:
    """``(load + identify, identify alone)`` in seconds: a user's own loop over the files."""
    from threadpoolctl import threadpool_limits

    import modaluq

    total, identify = 0.0, 0.0
    with threadpool_limits(1, user_api="blas"):
        for p in paths:
            t0 = time.perf_counter()
            with np.load(p) as z:
                y, fs = z["y"], float(z["fs"])
            t1 = time.perf_counter()
            modaluq.identify(y, fs=fs)
            t2 = time.perf_counter()
            total += t2 - t0
            identify += t2 - t1
    return total, identify


def run_monitor(paths, out: Path, **executor) -> float:
    from modaluq.monitoring import monitor

    shutil.rmtree(out.with_name(out.stem + ".parts"), ignore_errors=True)
    t0 = time.perf_counter()
    m = monitor(paths, out=out, progress=False, settle_seconds=0, **executor)  # files written by this script
    seconds = time.perf_counter() - t0
    assert m.n_failed == 0, m.failures
    return seconds


def run_dask(paths, out: Path, n_workers: int) -> tuple:
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        seconds = run_monitor(paths, out, executor=client)

        def peak_mib():
            import resource

            return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

        peaks = list(client.run(peak_mib).values())
    return seconds, peaks


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--records", type=int, default=200)
    ap.add_argument("--channels", type=int, default=20)
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--data", type=Path, default=Path("build/bench-monitor"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    folder = args.data / f"{args.records}x{args.channels}x{args.samples}"
    paths = make_records(folder, args.records, args.channels, args.samples)
    out = args.data / "tracks.nc"
    results = {"records": args.records, "channels": args.channels, "samples": args.samples}
    print("bare identify ...", file=sys.stderr)
    results["bare_s"], results["bare_identify_only_s"] = bare(paths)
    for threads in (1, 2):
        print(f"monitor, {threads} thread(s) ...", file=sys.stderr)
        results[f"threads{threads}_s"] = run_monitor(paths, out, threads=threads)
    for workers in (1, 2):
        print(f"monitor, Dask LocalCluster of {workers} worker(s) ...", file=sys.stderr)
        seconds, peaks = run_dask(paths, out, workers)
        results[f"dask{workers}_s"] = seconds
        results[f"dask{workers}_peak_mib"] = peaks
    n = args.records
    rows = [("bare identify only", results["bare_identify_only_s"]),
            ("bare load + identify, serial", results["bare_s"]), ("monitor, 1 thread", results["threads1_s"]),
            ("monitor, 2 threads", results["threads2_s"]), ("monitor, Dask 1 worker", results["dask1_s"]),
            ("monitor, Dask 2 workers", results["dask2_s"])]
    print(f"\n{n} records of {args.channels} channels x {args.samples} samples")
    print(f"{'':30s} {'total [s]':>10s} {'per record [s]':>15s}")
    for name, s in rows:
        print(f"{name:30s} {s:10.1f} {s / n:15.3f}")
    results["overhead_threads"] = results["threads1_s"] / results["bare_s"] - 1
    results["overhead_dask"] = results["dask1_s"] / results["bare_s"] - 1
    results["scaling_threads"] = results["threads1_s"] / results["threads2_s"]
    results["scaling_dask"] = results["dask1_s"] / results["dask2_s"]
    results["overhead_threads_over_identify_only"] = results["threads1_s"] / results["bare_identify_only_s"] - 1
    print(f"overhead over bare load + identify: thread pool {100 * results['overhead_threads']:.1f} %, "
          f"Dask {100 * results['overhead_dask']:.1f} % (thread pool over identify alone: "
          f"{100 * results['overhead_threads_over_identify_only']:.1f} %)")
    print(f"scaling 1 -> 2 workers: thread pool {results['scaling_threads']:.2f}x, Dask {results['scaling_dask']:.2f}x")
    print(f"peak memory per Dask worker: 1 worker {max(results['dask1_peak_mib']):.0f} MiB, "
          f"2 workers {', '.join(f'{p:.0f}' for p in results['dask2_peak_mib'])} MiB")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
