#!/usr/bin/env python
"""Wide arrays (issue 25, part 3): many channels, few references, long records, orders to 200, σ.

    python bench/wide.py                      # W1 once, then the scaling sweep and the plot
    python bench/wide.py --only W1            # the 100-channel case only
    python bench/wide.py --sweep channels,samples,orders --peers

W1: 100 channels (accelerations of every mass of a 100-DOF chain whose modes lie in 0.15-19 Hz,
98 of them in the 0.5-20 Hz band), 8 of them references, 1 hour at 100 Hz (360,000 samples),
block rows p = q = 40, orders 2, 4, ..., 200, 50 blocks, uncertainty on. Why p = 40 and not the
automatic choice: see docs/performance.md, "Wide arrays".

Every point runs in a fresh subprocess with one BLAS thread (bench/run.py's worker: CPU seconds by
time.process_time around the call, peak memory by VmHWM reset just before it, so the data and the
imports are not counted; the process's whole peak is reported as well). pyOMA2 runs where it can,
from the venv given by --peer-python (it must hold pyOMA-2 and modaluq's dependencies).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS"):
    os.environ[_v] = "1"
os.environ.setdefault("TQDM_DISABLE", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import run as bench_run  # noqa: E402  (bench/run.py: worker, adapters, peak-memory reset)

FS = 100.0
F_TOP = 19.0      # highest mode of the chains, Hz
N_REFS = 8
SEED = 25

# W1 and the sweeps' base point
BASE = dict(channels=100, n=360_000, p=40, n_max=200, n_blocks=50)
SWEEPS = {
    "channels": [dict(BASE, channels=c) for c in (10, 25, 50, 100, 200)],
    "samples": [dict(BASE, n=n) for n in (100_000, 1_000_000)] + [dict(BASE, channels=25, n=10_000_000)],
    "orders": [dict(BASE, n_max=k) for k in (50, 100, 200, 300)],
}


def references(channels):
    import numpy as np

    return sorted({int(round(x)) for x in np.linspace(0, channels - 1, min(N_REFS, channels))})


def simulate(channels, n, path):
    """Accelerations of every mass of a uniform chain of ``channels`` masses (highest mode F_TOP)."""
    import numpy as np

    import modaluq

    # uniform chain, unit masses: omega_max = 2 sqrt(k) sin(...) ~ 2 sqrt(k)
    k = (2 * np.pi * F_TOP / 2) ** 2
    sim = modaluq.simulate(n, seed=SEED, n_dof=channels, output_dofs=range(channels), input_dofs=(),
                           fs=FS, mass=1.0, stiffness=k, discard=20_000, unknown_input_std=1.0)
    y = np.ascontiguousarray(sim.y)
    os.makedirs(path, exist_ok=True)
    np.save(os.path.join(path, "y.npy"), y)
    np.save(os.path.join(path, "u.npy"), np.zeros((n, 0)))
    with open(os.path.join(path, "meta.json"), "w") as fh:
        json.dump({"fs": FS, "frequency_hz": sim.frequency_hz.tolist(),
                   "damping_ratio": sim.damping_ratio.tolist(), "n_outputs": channels}, fh)


def cfg_of(pt):
    return dict(n_dof=pt["channels"], n=pt["n"], p=pt["p"], n_max=pt["n_max"], n_blocks=pt["n_blocks"],
                unc=True, io=False, references=references(pt["channels"]))


def spawn(spec, timeout, python=None):
    cmd = [python or sys.executable, os.path.abspath(__file__), "--_worker", json.dumps(spec)]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=HERE,
                              env=dict(os.environ, PYTHONPATH=os.path.join(ROOT, "python")))
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "reason": f"> {timeout:.0f} s wall"}
    for line in reversed(proc.stdout.splitlines()):
        if line.startswith("BENCHJSON "):
            return json.loads(line[len("BENCHJSON "):])
    tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
    return {"status": "error", "reason": f"exit {proc.returncode}: " + " | ".join(tail)}


def worker(spec):
    import numpy as np

    bench_run._import_numpy()
    cfg = spec["cfg"]
    y = np.load(os.path.join(spec["data"], "y.npy"), mmap_mode="r")[: cfg["n"]]
    y = np.ascontiguousarray(y)
    out = {"tool": spec["tool"]}
    orders = list(range(2, cfg["n_max"] + 1, 2))
    if spec["tool"] == "modaluq":
        import modaluq

        def run():
            return modaluq.identify(y, fs=FS, block_rows=cfg["p"], orders=orders, n_blocks=cfg["n_blocks"],
                                    references=cfg["references"], uncertainty=True, threads=1)
    else:
        # pyOMA2's reference-based SSI: ref_ind; step 2 as in bench/run.py
        run = bench_run.pyoma2_runner(y, FS, dict(
            name="ssi", method="cov", br=cfg["p"], ordmin=0, ordmax=cfg["n_max"], step=2, calc_unc=True,
            nb=cfg["n_blocks"], ref_ind=cfg["references"],
            hc={"xi_max": 0.2, "mpc_lim": None, "mpd_lim": None, "CoV_max": None}))
    import gc

    gc.collect()
    base, peak = bench_run._reset_peak()
    c0, w0 = time.process_time(), time.perf_counter()
    res = run()
    out.update(status="ok", cpu=time.process_time() - c0, wall=time.perf_counter() - w0,
               mem_mb=max(0.0, peak() - base), rss_before_mb=base,
               process_peak_mb=bench_run._status_mb("VmHWM"))
    if spec["tool"] == "modaluq":
        m = res.at_order(cfg["n_max"])
        out["poles_at_nmax"] = int(len(m.frequency_hz))
        out["k_star"] = getattr(res, "noise_floor_order", None)
    return out


def run_point(pt, root, tool, timeout, python=None):
    key = f"l{pt['channels']}_n{pt['n']}"
    path = os.path.join(root, key)
    if not os.path.exists(os.path.join(path, "meta.json")):
        t0 = time.perf_counter()
        simulate(pt["channels"], pt["n"], path)
        print(f"  simulated {key} in {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return spawn({"tool": tool, "cfg": cfg_of(pt), "data": path}, timeout, python)


def describe(pt):
    return f"{pt['channels']} ch ({len(references(pt['channels']))} ref), N={pt['n']:.0e}, p=q={pt['p']}, " \
           f"orders 2..{pt['n_max']}, n_b={pt['n_blocks']}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default=None, help="W1 only (no sweep)")
    ap.add_argument("--sweep", default="channels,samples,orders")
    ap.add_argument("--peers", action="store_true", help="also pyOMA2 (from --peer-python)")
    ap.add_argument("--peer-python", default="/work/wt/peers/bin/python")
    ap.add_argument("--peer-max-channels", type=int, default=25,
                    help="pyOMA2 only up to this many channels (it forms the full H per block)")
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--plot", default=os.path.join(ROOT, "docs", "img", "wide_scaling.png"))
    ap.add_argument("--data", default=None, help="directory for the simulated records (kept)")
    ap.add_argument("--_worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args._worker is not None:
        spec = json.loads(args._worker)
        try:
            out = worker(spec)
        except Exception as exc:
            out = {"status": "error", "reason": f"{type(exc).__name__}: {exc}"}
        sys.stdout.write("\nBENCHJSON " + json.dumps(out) + "\n")
        return 0
    root = args.data or tempfile.mkdtemp(prefix="modaluq-wide-")
    print(f"# bench/wide.py  ({bench_run.modaluq_build()})\nmachine: {bench_run.machine_info()}\n")
    results = {"W1": None, "sweeps": {}}
    r = run_point(BASE, root, "modaluq", args.timeout)
    results["W1"] = dict(point=BASE, modaluq=r)
    print(f"W1 {describe(BASE)}: {fmt(r)}", flush=True)
    if args.only is None:
        for name in [s for s in args.sweep.split(",") if s]:
            for pt in SWEEPS[name]:
                if pt == BASE:
                    r = results["W1"]["modaluq"]
                else:
                    r = run_point(pt, root, "modaluq", args.timeout)
                row = dict(point=pt, modaluq=r)
                if args.peers and pt["channels"] <= args.peer_max_channels and pt["n"] <= 1_000_000:
                    row["pyOMA2"] = run_point(pt, root, "pyOMA2", args.timeout, args.peer_python)
                elif args.peers:
                    row["pyOMA2"] = {"status": "skipped",
                                     "reason": f"more than {args.peer_max_channels} channels or 1e6 samples"}
                results["sweeps"].setdefault(name, []).append(row)
                print(f"{name:8s} {describe(pt)}: modaluq {fmt(r)}"
                      + (f" | pyOMA2 {fmt(row['pyOMA2'])}" if "pyOMA2" in row else ""), flush=True)
        if args.plot and results["sweeps"]:
            plot(results["sweeps"], args.plot)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    return 0


def fmt(r):
    if r.get("status") != "ok":
        return f"{r.get('status')}: {r.get('reason')}"
    return f"{r['cpu']:.2f} CPU s, {r['wall']:.2f} wall s, +{r['mem_mb']:.0f} MB (process peak {r['process_peak_mb']:.0f} MB)"


def plot(sweeps, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k in ("channels", "samples", "orders") if k in sweeps]
    fig, axes = plt.subplots(2, len(keys), figsize=(4 * len(keys), 6), dpi=100, squeeze=False)
    xkey = {"channels": ("channels", "channels l (8 references)"), "samples": ("n", "samples N"),
            "orders": ("n_max", "largest order n_max")}
    for j, k in enumerate(keys):
        field, label = xkey[k]
        for tool, style in (("modaluq", "o-"), ("pyOMA2", "s--")):
            ok = [row for row in sweeps[k] if row.get(tool, {}).get("status") == "ok"]
            # points at the base's channel count form the line; others (10^7 samples at fewer
            # channels) are separate, labelled markers
            main = [(row["point"][field], row[tool]) for row in ok
                    if k == "channels" or row["point"]["channels"] == BASE["channels"]]
            other = [row for row in ok if k != "channels" and row["point"]["channels"] != BASE["channels"]]
            if main:
                xs = [x for x, _ in main]
                axes[0, j].loglog(xs, [r["cpu"] for _, r in main], style, label=tool)
                axes[1, j].loglog(xs, [r["mem_mb"] for _, r in main], style, label=tool)
            for row in other:
                x, r = row["point"][field], row[tool]
                for i, v in ((0, r["cpu"]), (1, r["mem_mb"])):
                    axes[i, j].loglog([x], [v], "D", color="C2",
                                      label=f"{tool}, {row['point']['channels']} channels")
                    axes[i, j].annotate(f"{row['point']['channels']} ch", (x, v), textcoords="offset points",
                                        xytext=(-30, 4), fontsize=8)
        for i, what in enumerate(("CPU s (1 thread)", "peak MB added")):
            ax = axes[i, j]
            ax.set_ylabel(what)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
            if i == 1:
                ax.set_xlabel(label)
        axes[0, j].set_title(f"vs {k}", fontsize=9)
    fig.suptitle(f"modaluq wide arrays: base {describe(BASE)}; portable build", fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
