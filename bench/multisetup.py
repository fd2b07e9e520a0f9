#!/usr/bin/env python
"""Multi-setup campaigns (issue 23, the time bullet): ``identify_setups`` against the setups alone.

    python bench/multisetup.py                   # 10 setups x 6 channels x 10^5 samples, 3 repeats
    python bench/multisetup.py --setups 4 --samples 20000 --repeats 1     # a quick look

The campaign: the deck of :mod:`modaluq.simulate.campaign` (six modes, 1.2-9.4 Hz, fs 25 Hz),
references L3 and R8 in every setup and four roving channels per setup (10 setups: 2 + 40 = 42
global DOFs; the deck has 22 roving DOFs, so a DOF roved twice gets a second name, ``L1@7``:
the timing does not care, the merge treats it as one more DOF). Each setup 10^5 samples.

Both sides get the same records and the same settings: block rows p = q = 50 (the merge bounds
the order by q r = 100 with r = 2 references; one setup with the same two references by the
same q r), orders 2, 4, ..., 100, 20 blocks, uncertainty on, no preprocessing:

* ``merged``: one ``modaluq.identify_setups`` call over the 10 setups (the stages inside it are
  timed too: the covariance pass of every setup and the core's merge, identification and
  propagation);
* ``single``: 10 ``modaluq.identify`` calls, one per setup, references the same two channels.

Every measurement runs in a fresh subprocess with one BLAS/OpenMP thread (set before numpy is
imported), CPU seconds by ``time.process_time`` around the call (the data are loaded before), the
median of ``--repeats`` processes. The ratio merged / single is the issue's target (within 2x).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS"):
    os.environ[_v] = "1"
os.environ.setdefault("TQDM_DISABLE", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

REFERENCES = ("L3", "R8")
SETTINGS = dict(block_rows=50, past_block_rows=50, orders=list(range(2, 101, 2)), n_blocks=20)


def roving(n_setups: int, per_setup: int = 4) -> tuple:
    """``per_setup`` roving DOFs per setup, cycling over the deck's 22; a DOF roved again is
    renamed ``NAME@k`` (k = the setup) so every non-reference name is measured once."""
    from modaluq.simulate.campaign import DECK_DOFS

    free = [d for d in DECK_DOFS if d not in REFERENCES]
    out = []
    for j in range(n_setups):
        out.append(tuple(free[(j * per_setup + i) % len(free)] for i in range(per_setup)))
    return tuple(out)


def campaign(n_setups: int, n_samples: int, per_setup: int = 4, seed: int = 23):
    """The benchmark's campaign: the simulated campaign and, per setup, its channel names (a DOF
    roved again is renamed ``NAME@j``, j its setup)."""
    from modaluq.simulate.campaign import simulate_campaign

    camp = simulate_campaign(seed, durations=(n_samples / 25.0,) * n_setups, roving=roving(n_setups, per_setup),
                             references=REFERENCES)
    seen, names = set(), []
    for j, s in enumerate(camp.setups):
        chans = []
        for c in s.channels:
            if c not in REFERENCES and c in seen:
                c = f"{c}@{j}"
            seen.add(c)
            chans.append(c)
        names.append(chans)
    return camp, names


def simulate(n_setups: int, n_samples: int, path: str, per_setup: int = 4) -> None:
    import numpy as np

    camp, names = campaign(n_setups, n_samples, per_setup)
    np.savez(os.path.join(path, "campaign.npz"), **{f"y{j}": s.y for j, s in enumerate(camp.setups)})
    with open(os.path.join(path, "meta.json"), "w") as fh:
        json.dump({"fs": camp.fs, "names": names, "frequency_hz": camp.frequency_hz.tolist()}, fh)


def worker(path: str, kind: str, settings: dict) -> dict:
    """One measurement in this (fresh) process: ``kind`` is "merged" or "single"."""
    import numpy as np
    import pandas as pd

    import modaluq
    from modaluq import _core

    with open(os.path.join(path, "meta.json")) as fh:
        meta = json.load(fh)
    data = np.load(os.path.join(path, "campaign.npz"))
    frames = [pd.DataFrame(data[f"y{j}"], columns=names) for j, names in enumerate(meta["names"])]
    fs = meta["fs"]
    stages = {"covariances": 0.0, "merge": 0.0}
    if kind == "merged":
        # the stages: wrap the two core calls identify_setups makes (the extension's functions)
        cov, ident = _core.compute_covariances, _core.identify_setups

        def timed(fn, stage):
            def call(*a, **k):
                t0 = time.process_time()
                try:
                    return fn(*a, **k)
                finally:
                    stages[stage] += time.process_time() - t0
            return call

        _core.compute_covariances = timed(cov, "covariances")
        _core.identify_setups = timed(ident, "merge")
        c0 = time.process_time()
        res = modaluq.identify_setups(frames, fs=fs, references=list(REFERENCES), **settings)
        cpu = time.process_time() - c0
        sel = res.select_modes()
        found = sorted(float(f) for f in sel.frequency_hz)
    else:
        c0 = time.process_time()
        found = []
        for df in frames:
            refs = [list(df.columns).index(r) for r in REFERENCES]
            res = modaluq.identify(df, fs=fs, references=refs, **settings)  # coupling_sketch: ignored
        cpu = time.process_time() - c0
        found = sorted(float(f) for f in res.select_modes().frequency_hz)  # the last setup's, as a check
    return {"kind": kind, "cpu": cpu, "stages": stages if kind == "merged" else None, "found_hz": found,
            "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS")}


def measure(path: str, kind: str, settings: dict) -> dict:
    env = dict(os.environ)
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", kind, "--data", path,
           "--settings", json.dumps(settings)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode:
        raise RuntimeError(f"{kind} worker failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--setups", type=int, default=10)
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", default=None, help="also write the measurements to this file")
    ap.add_argument("--max-order", type=int, default=100, help="orders 2, 4, ... up to this (default 100)")
    ap.add_argument("--roving", type=int, default=4, help="roving channels per setup (default 4; 2 references)")
    ap.add_argument("--n-blocks", type=int, default=SETTINGS["n_blocks"], help="blocks per setup (default 20)")
    ap.add_argument("--no-uncertainty", action="store_true", help="both sides without the uncertainty (a diagnosis)")
    ap.add_argument("--coupling-sketch", type=int, default=None,
                    help="the merge's coupling_sketch (default: the core's; 0 = the exact noise-coupling test)")
    ap.add_argument("--settings", help=argparse.SUPPRESS)
    ap.add_argument("--worker", choices=["merged", "single"], help=argparse.SUPPRESS)
    ap.add_argument("--data", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.data, args.worker, json.loads(args.settings))))
        return 0
    settings = dict(SETTINGS, orders=list(range(2, args.max_order + 1, 2)), n_blocks=args.n_blocks)
    if args.no_uncertainty:
        settings["uncertainty"] = False
    if args.coupling_sketch is not None:
        settings["coupling_sketch"] = args.coupling_sketch

    import modaluq
    from modaluq import _core

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        simulate(args.setups, args.samples, tmp, args.roving)
        print(f"simulated {args.setups} setups x {2 + args.roving} channels x {args.samples} samples "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
        runs = {"merged": [], "single": []}
        for r in range(args.repeats):
            for kind in ("merged", "single"):
                m = measure(tmp, kind, settings)
                runs[kind].append(m)
                extra = (f" (covariances {m['stages']['covariances']:.1f} s, merge {m['stages']['merge']:.1f} s)"
                         if m["stages"] else "")
                print(f"  repeat {r + 1}: {kind:6s} {m['cpu']:7.1f} CPU s{extra}", flush=True)
    med = {k: statistics.median(m["cpu"] for m in v) for k, v in runs.items()}
    stage_med = {s: statistics.median(m["stages"][s] for m in runs["merged"]) for s in ("covariances", "merge")}
    build = getattr(_core, "__name__", "?")
    print(f"\nsettings: {json.dumps(settings)}")
    print(f"modaluq {modaluq.__version__}, core {getattr(_core, '__file__', build)}")
    print(f"merged (identify_setups): {med['merged']:.1f} CPU s (covariances {stage_med['covariances']:.1f}, "
          f"merge/identification/propagation {stage_med['merge']:.1f})")
    print(f"single ({args.setups} x identify):   {med['single']:.1f} CPU s")
    print(f"ratio merged / single:    {med['merged'] / med['single']:.2f} (target <= 2)")
    print(f"modes found (merged, last repeat): {', '.join(f'{f:.3f}' for f in runs['merged'][-1]['found_hz'])}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"settings": settings, "setups": args.setups, "samples": args.samples, "runs": runs,
                       "median_cpu": med, "median_stages": stage_med, "core": getattr(_core, "__file__", build)},
                      fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
