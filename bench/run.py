#!/usr/bin/env python
"""Benchmark modaluq against the SSI-cov tools on PyPI (issue #5).

    python bench/run.py                      # everything: peers, floor, scaling sweep, plot
    python bench/run.py --quick              # a few minutes: fewer repeats, slow peers skipped
    python bench/run.py --only S1,U1 --no-peers --no-sweep

Every measurement runs in a fresh subprocess with ONE BLAS/OpenMP thread, on data simulated
once per configuration by the parent and stored as .npy files (so data generation neither
costs time nor inflates the memory peak of the tool being measured).  A worker loads the
data, imports its tool and runs it ``repeats`` times (time.process_time and time.perf_counter
around each call), then reports the median CPU and wall seconds and the memory a run adds:
the peak RSS during the run (VmHWM, reset before each run through /proc/self/clear_refs)
minus the RSS just before it, largest over the runs.  After the timed runs, the
result of the last run is checked against the true modes of the simulated structure (see
``check_modes``), so no tool is timed doing the wrong thing.

The machine floor of a configuration is the time the necessary work would take on this
machine, single-threaded, at the measured dgemm rate and memory bandwidth (see ``floor``
and docs/performance.md):

    t_floor = max(2 N (L+1) d^2 / F,  8 N d / B)        covariance lag products
            + t_svd(a x b)                                  numpy SVD of H, measured
            + sum_n t_eig(n x n)                            numpy eig at every order, measured
            + [2 n_b (3 a pm b + a (pm)^2)] / F             IO projection of every block (IO only)
            + [8 a b n_max n_b + 8 a n_max^2 n_b
               + 8 n_b sum_n n^2 (n/2)] / F                 propagation (uncertainty only)

with L = p + q - 1 lags, d channels (outputs + inputs), a = p l, b = q r, F the dgemm rate
(flop/s) and B the copy bandwidth (bytes/s, read + write).

Not part of the test suite: pytest collects tests/python only (pyproject ``testpaths``).
"""

from __future__ import annotations

import os

# One thread for every BLAS / OpenMP runtime, before numpy is imported (workers get the same
# variables through their environment).
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
for _v in _THREAD_VARS:
    os.environ[_v] = "1"
os.environ.setdefault("TQDM_DISABLE", "1")  # pyOMA2 and modaluq progress bars

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from importlib import metadata  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

SEED = 2024

# name: n_dof of the simulated chain, samples, block rows p (= q), largest order (orders
# 2, 4, ..., n_max), blocks, uncertainty, known input used
CONFIGS = {
    "S1": dict(n_dof=6, n=1_000_000, p=40, n_max=100, n_blocks=50, unc=False, io=False),
    "U1": dict(n_dof=6, n=100_000, p=40, n_max=100, n_blocks=50, unc=True, io=False),
    "U2": dict(n_dof=30, n=100_000, p=20, n_max=100, n_blocks=50, unc=True, io=False),
    "U3": dict(n_dof=30, n=1_000_000, p=40, n_max=200, n_blocks=100, unc=True, io=False),
    "IO": dict(n_dof=6, n=100_000, p=40, n_max=100, n_blocks=50, unc=True, io=True),
}
# Issue #5: modaluq's targets (CPU s) and pyOMA2's time when the issue was written.
TARGET = {"S1": 0.15, "U1": 0.3, "U2": 1.0, "U3": 5.0, "IO": 0.4}
PYOMA_ISSUE = {"S1": "1.9", "U1": "72", "U2": "118", "U3": "does not finish", "IO": "—"}

TOOLS = ("modaluq", "pyOMA2", "koma", "strid")
DIST = {"modaluq": "modaluq", "pyOMA2": "pyOMA-2", "koma": "koma-python", "strid": "strid"}

# Mode check: a true mode is found when a pole lies within min(FREQ_TOL * f, half the distance
# to the nearest other true mode) of its frequency, with a damping ratio within a factor
# DAMP_FACTOR of the true one (2 % for every mode of the chains: 0.8 % .. 5 %).
FREQ_TOL = 0.02
DAMP_FACTOR = 2.5


def checked_modes(cfg, freqs):
    """Indices of the true modes that every tool must find, and which ones.

    6-DOF chain: all six.  30-DOF chain: the 29 modes from 1.26 Hz up (modes 1.26-9.97 Hz
    on one branch, 15 modes crowded into 14.25-17.41 Hz, where the tolerance shrinks to half
    the spacing, 0.17-1.1 %).  Left out: the 0.42 Hz mode, whose 2.4 s period is 6-12 times
    the lag window of 20-40 block rows at 50 Hz, so below the largest order it comes out
    several % off (with modaluq as with pyOMA2).
    """
    if cfg["n_dof"] == 6:
        return list(range(len(freqs))), "all 6 modes"
    idx = [i for i, f in enumerate(freqs) if f > 1.0]
    return idx, f"{len(idx)} of {len(freqs)} modes, {freqs[idx[0]]:.2f}-{freqs[idx[-1]]:.2f} Hz (not 0.42 Hz)"


def check_orders(cfg):
    n_max = cfg["n_max"]
    return sorted({2 * round(0.3 * n_max), n_max})  # 60 % and 100 % of n_max


def freq_tolerance(freqs):
    f = np.asarray(freqs, float)
    gap = np.array([np.min(np.abs(f[i] - np.delete(f, i))) if len(f) > 1 else np.inf
                    for i in range(len(f))])
    return np.minimum(FREQ_TOL * f, 0.5 * gap)


# ------------------------------------------------------------------------ tool adapters
#
# Each adapter gets the data and the configuration and returns a callable that runs the tool
# once and returns {order: (freq_hz, damping_ratio, freq_std or None)} for the check orders
# (extraction happens after the timer stops).


class Unsupported(Exception):
    pass


def _orders(cfg):
    return list(range(2, cfg["n_max"] + 1, 2))


def adapter_modaluq(y, u, fs, cfg, threads=1):
    import modaluq

    orders = _orders(cfg)

    def run():
        return modaluq.identify(y, u if cfg["io"] else None, fs=fs, block_rows=cfg["p"],
                                orders=orders, n_blocks=cfg["n_blocks"],
                                uncertainty=cfg["unc"], threads=threads)

    def extract(res, n):
        m = res.at_order(n)
        std = m.frequency_std if cfg["unc"] else None
        return m.frequency_hz, m.damping_ratio, std

    settings = (f"identify(block_rows={cfg['p']}, orders=range(2, {cfg['n_max'] + 1}, 2), "
                f"n_blocks={cfg['n_blocks']}, uncertainty={cfg['unc']}"
                + (f", threads={threads})" if threads != 1 else ")"))
    return run, extract, settings


def pyoma2_runner(y, fs, kw):
    """A call running pyOMA2's SSI (keywords ``kw``, with its ``name``) on y; returns its result."""
    import logging

    logging.getLogger("pyoma2").setLevel(logging.WARNING)
    from pyoma2.algorithms import SSI
    from pyoma2.setup import SingleSetup

    def run():
        setup = SingleSetup(y, fs=fs)
        alg = SSI(**kw)
        setup.add_algorithms(alg)
        setup.run_by_name(kw["name"])
        return alg.result

    return run


def adapter_pyoma2(y, u, fs, cfg, step=2):
    method = "IOcov" if cfg["io"] else "cov"
    # Hard criteria off except the damping bound (cheap post-filters; the MPC / MPD / CoV
    # limits drop true modes of the 30-DOF chain whose poles pyOMA2 did compute, equal to
    # modaluq's to 1e-8).  ordmin only affects the soft criteria; orders 0, 2, ..., n_max.
    kw = dict(name="ssi", method=method, br=cfg["p"], ordmin=0, ordmax=cfg["n_max"],
              step=step, calc_unc=cfg["unc"], nb=cfg["n_blocks"],
              hc={"xi_max": 0.2, "mpc_lim": None, "mpd_lim": None, "CoV_max": None})
    if cfg["io"]:
        kw["U"] = u
    run = pyoma2_runner(y, fs, kw)

    def extract(res, n):
        col = n // step
        f, x = res.Fn_poles[:, col], res.Xi_poles[:, col]
        keep = ~(np.isnan(f) | np.isnan(x))
        std = res.Fn_poles_std[:, col][keep] if cfg["unc"] else None
        return f[keep], x[keep], std

    settings = ("SingleSetup + SSI(" + ", ".join(f"{k}={v!r}" for k, v in kw.items()
                                                   if k not in ("name", "U")) + ")")
    return run, extract, settings


def adapter_koma(y, u, fs, cfg):
    if cfg["io"]:
        raise Unsupported("output-only (covssi takes no inputs) and no uncertainty")
    if cfg["unc"]:
        raise Unsupported("no uncertainty (koma.oma.covssi returns poles and shapes only)")
    from koma.oma import covssi

    orders = _orders(cfg)

    def run():
        lam, _phi = covssi(y, fs, cfg["p"], orders, showinfo=False, return_flat=False)
        return lam

    def extract(lam, n):
        lam_n = np.asarray(lam[orders.index(n)])
        return np.abs(lam_n) / (2 * np.pi), -lam_n.real / np.abs(lam_n), None

    return run, extract, f"covssi(data, fs, i={cfg['p']}, orders=range(2, {cfg['n_max'] + 1}, 2))"


def adapter_strid(y, u, fs, cfg):
    if cfg["io"]:
        raise Unsupported("CovarianceDrivenStochasticSID is output-only (the IO method, "
                          "CombinedDeterministicStochasticSID, is data-driven) and no uncertainty")
    if cfg["unc"]:
        raise Unsupported("no uncertainty (CovarianceDrivenStochasticSID gives A, C, G, R0)")
    import strid

    orders = _orders(cfg)

    def run():
        ssid = strid.CovarianceDrivenStochasticSID(y.T, fs)
        out = {}
        for n in orders:
            A, C, _G, _R0 = ssid.perform(n, cfg["p"])
            out[n] = strid.Mode.find_modes_from_ss(A, C, fs)
        return out

    def extract(modes, n):
        ms = modes[n]
        return (np.array([m.f for m in ms]), np.array([m.xi for m in ms]), None)

    return run, extract, (f"CovarianceDrivenStochasticSID(y.T, fs).perform(order, "
                          f"block_rows={cfg['p']}) + Mode.find_modes_from_ss, "
                          f"orders 2..{cfg['n_max']} step 2")


ADAPTERS = {"modaluq": adapter_modaluq,
            "modaluq (threads=2)": lambda *a: adapter_modaluq(*a, threads=2),
            "pyOMA2": adapter_pyoma2,
            "pyOMA2 (step=1)": lambda *a: adapter_pyoma2(*a, step=1),
            "koma": adapter_koma, "strid": adapter_strid}


def check_modes(extract, res, cfg, meta):
    """Match the checked true modes at the check orders; returns (ok, text, per-mode std)."""
    f_true = np.asarray(meta["frequency_hz"])
    xi_true = np.asarray(meta["damping_ratio"])
    idx, _ = checked_modes(cfg, f_true)
    tol = freq_tolerance(f_true)
    missing, stds = [], {}
    for n in check_orders(cfg):
        f, x, s = extract(res, n)
        f, x = np.asarray(f, float), np.asarray(x, float)
        s = None if s is None else np.asarray(s, float)
        for i in idx:
            rel = np.abs(f - f_true[i]) / f_true[i]
            good = (np.abs(f - f_true[i]) <= tol[i]) & (x > xi_true[i] / DAMP_FACTOR) & (x < xi_true[i] * DAMP_FACTOR)
            if not good.any():
                missing.append(f"{f_true[i]:.2f}Hz@n{n}")
                continue
            j = np.flatnonzero(good)[np.argmin(rel[good])]
            if s is not None:
                stds[f"{n}:{i}"] = float(s[j])
    n_checks = len(idx) * len(check_orders(cfg))
    if missing:
        more = f" +{len(missing) - 3}" if len(missing) > 3 else ""
        return False, f"MISSED {len(missing)}/{n_checks}: " + ", ".join(missing[:3]) + more, stds
    return True, f"ok {n_checks}/{n_checks}", stds


# ------------------------------------------------------------------------------ worker

np = None  # numpy, imported lazily so the thread variables above are set first


def _import_numpy():
    global np
    import numpy

    np = numpy


def _status_mb(field):
    """A memory field of /proc/self/status (VmRSS, VmHWM) in MB, or None."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def _reset_peak():
    """Reset this process's peak RSS; returns (baseline MB, peak reader).

    Linux >= 4.0: writing 5 to /proc/self/clear_refs resets VmHWM to the current RSS, so the
    peak of a run minus the RSS just before it is what that run added.  ru_maxrss is no use
    here: after fork + exec it starts at the parent's RSS (getrusage reports the larger of
    the two), and it cannot be reset.  Without the reset, the fallback baseline is the peak
    so far (an earlier peak then hides a smaller one of the tool).
    """
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        base, peak = _status_mb("VmRSS"), _status_mb("VmHWM")
        if base is not None and peak is not None and peak - base < 1.0:
            return base, lambda: _status_mb("VmHWM")
    except OSError:
        pass
    maxrss = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # noqa: E731
    return maxrss(), maxrss


def worker_measure(spec):
    """Run one tool on one configuration ``repeats`` times; print one JSON line."""
    _import_numpy()
    warnings.simplefilter("ignore")
    cfg = spec["cfg"]
    with open(os.path.join(spec["data"], "meta.json")) as fh:
        meta = json.load(fh)
    y = np.load(os.path.join(spec["data"], "y.npy"))
    u = np.load(os.path.join(spec["data"], "u.npy"))
    if spec.get("n_samples"):
        y, u = y[: spec["n_samples"]].copy(), u[: spec["n_samples"]].copy()
    out = {"tool": spec["tool"]}
    try:
        run, extract, settings = ADAPTERS[spec["tool"]](y, u, meta["fs"], cfg)
    except Unsupported as exc:
        out.update(status="unsupported", reason=str(exc))
        return out
    out["settings"] = settings
    try:
        from threadpoolctl import threadpool_info

        out["blas_threads"] = sorted({d["num_threads"] for d in threadpool_info()})
    except Exception:  # pragma: no cover - threadpoolctl missing
        pass
    import gc

    cpu, wall, mem, rss = [], [], [], []
    res = None
    for _ in range(spec["repeats"]):
        res = None
        gc.collect()
        base, peak = _reset_peak()  # per run: memory a previous run kept is not counted
        rss.append(base)
        c0, w0 = time.process_time(), time.perf_counter()
        res = run()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
        mem.append(max(0.0, peak() - base))
    out.update(status="ok", cpu=cpu, wall=wall, mem_mb=max(mem), mem_runs=mem, rss_before=rss)
    if spec.get("check", True):
        ok, text, stds = check_modes(extract, res, cfg, meta)
        out.update(check_ok=ok, check=text, stds=stds)
    return out


def _best(fn, repeats=3):
    """Least CPU seconds of ``repeats`` calls (CPU time: the machine may be shared)."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def worker_floor(spec):
    """Measure the machine (dgemm rate, copy bandwidth) and the floor of each configuration."""
    _import_numpy()
    rng = np.random.default_rng(0)
    k = 1536
    A, B = rng.standard_normal((k, k)), rng.standard_normal((k, k))
    A @ B
    t = _best(lambda: A @ B, 5)
    rate = 2.0 * k ** 3 / t
    big = np.ones(50_000_000)  # 400 MB
    dst = np.empty_like(big)
    np.copyto(dst, big)
    t = _best(lambda: np.copyto(dst, big), 5)
    bandwidth = 2 * big.nbytes / t
    big = dst = None  # 800 MB freed before the measurements below
    floors = {}
    for name, cfg in spec["configs"].items():
        l = cfg["n_outputs"]
        m = 1 if cfg["io"] else 0
        p = q = cfg["p"]
        n, n_max, nb = cfg["n"], cfg["n_max"], cfg["n_blocks"]
        a, b = p * l, q * l
        d = l + m
        L = p + q - 1
        orders = _orders(cfg)
        t_cov = max(2.0 * n * (L + 1) * d * d / rate, 8.0 * n * d / bandwidth)
        H = rng.standard_normal((a, b))
        t_svd = _best(lambda: np.linalg.svd(H, full_matrices=False), 3)
        mats = [rng.standard_normal((k_, k_)) for k_ in orders]
        t_eig = _best(lambda: [np.linalg.eig(M_) for M_ in mats], 3)
        t_io = 2.0 * nb * (3 * a * p * m * b + a * (p * m) ** 2) / rate if (cfg["io"] and cfg["unc"]) else 0.0
        if cfg["unc"]:
            # dH V, U^T (dH V), U_n^T dH, (U_n^T dH) V; then the fused Q1..Q3 (uncertainty.hpp QStage)
            t_dg = 8.0 * a * b * n_max * nb / rate
            t_q = 8.0 * a * n_max ** 2 * nb / rate
            t_ord = 8.0 * nb * sum(k_ ** 2 * (k_ / 2) for k_ in orders) / rate
        else:
            t_dg = t_q = t_ord = 0.0
        parts = dict(cov=t_cov, svd=t_svd, eig=t_eig, io=t_io, dgamma=t_dg, q=t_q, orders=t_ord)
        floors[name] = dict(total=sum(parts.values()), parts=parts, a=a, b=b, d=d, L=L)
    return {"dgemm_gflops": rate / 1e9, "copy_gbs": bandwidth / 1e9, "floors": floors}


def worker_main(arg):
    spec = json.loads(arg)
    kind = spec.pop("kind")
    try:
        out = worker_floor(spec) if kind == "floor" else worker_measure(spec)
    except Exception as exc:  # report, never crash the parent's table
        import traceback

        out = {"status": "error", "reason": f"{type(exc).__name__}: {exc}",
               "traceback": traceback.format_exc(limit=4)}
    sys.stdout.write("\nBENCHJSON " + json.dumps(out) + "\n")
    sys.stdout.flush()


# ------------------------------------------------------------------------------ parent


def spawn(spec, timeout):
    """Run a worker; returns its JSON dict, or a timeout / error dict."""
    env = dict(os.environ)
    for v in _THREAD_VARS:
        env[v] = "1"
    cmd = [sys.executable, os.path.abspath(__file__), "--_worker", json.dumps(spec)]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env,
                              cwd=HERE)
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "reason": f"timeout (> {timeout:.0f} s wall)",
                "elapsed": time.perf_counter() - t0}
    for line in reversed(proc.stdout.splitlines()):
        if line.startswith("BENCHJSON "):
            return json.loads(line[len("BENCHJSON "):])
    tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
    return {"status": "error", "reason": f"worker exited with {proc.returncode}: " + " | ".join(tail)}


def make_data(cfg_name, cfg, root):
    """Simulate a configuration's record once; store y, u and the true modes."""
    import modaluq

    key = f"dof{cfg['n_dof']}_n{cfg['n']}"
    path = os.path.join(root, key)
    if os.path.exists(os.path.join(path, "meta.json")):
        return path
    os.makedirs(path, exist_ok=True)
    sim = modaluq.simulate(cfg["n"], seed=SEED, n_dof=cfg["n_dof"])
    np.save(os.path.join(path, "y.npy"), np.ascontiguousarray(sim.y))
    np.save(os.path.join(path, "u.npy"), np.ascontiguousarray(sim.u))
    with open(os.path.join(path, "meta.json"), "w") as fh:
        json.dump({"fs": sim.fs, "frequency_hz": sim.frequency_hz.tolist(),
                   "damping_ratio": sim.damping_ratio.tolist(), "n_outputs": sim.y.shape[1]}, fh)
    return path


def machine_info():
    model, cores = platform.processor() or "?", os.cpu_count()
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        fields = dict(line.split(":", 1) for line in out.splitlines() if ":" in line)
        model = fields.get("Model name", model).strip()
        cores = f"{fields.get('CPU(s)', cores).strip()} CPUs ({fields.get('Thread(s) per core', '?').strip()} thread/core)"
        caches = ", ".join(f"{k.strip()} {fields[k].strip()}" for k in ("L2 cache", "L3 cache") if k in fields)
    except Exception:
        caches = ""
    mem = ""
    try:
        with open("/proc/meminfo") as fh:
            mem = f"{int(fh.readline().split()[1]) / 1024 ** 2:.0f} GiB RAM"
    except OSError:
        pass
    return f"{model}, {cores}" + (f", {caches}" if caches else "") + (f", {mem}" if mem else "")


def versions():
    out = {}
    for tool, dist in DIST.items():
        try:
            out[tool] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[tool] = None
    out["numpy"] = metadata.version("numpy")
    out["scipy"] = metadata.version("scipy")
    return out


def modaluq_build():
    """Where the measured modaluq comes from: its CPU path (the workers inherit MODALUQ_CPU, so they
    run the same one), install time of its extension, checkout commit."""
    parts = []
    try:
        from modaluq import _core

        try:
            from modaluq.buildinfo import core_summary

            flags = getattr(_core, "builds", {}).get(_core.cpu_path, "")
            parts.append(f"core {core_summary()}" + (f" [{flags}]" if flags else ""))
        except ImportError:  # a modaluq from before the CPU paths (issue 25): one build
            parts.append("core: one build")
        stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(os.path.getmtime(_core.__file__)))
        parts.append(f"extension built {stamp}")
        parts.append("large products through " + ("OpenBLAS" if getattr(_core, "uses_blas", False) else "Eigen"))
    except Exception:
        pass
    try:
        head = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True).stdout.strip()
        if head:
            parts.append(f"checkout {head}" + (" + local changes" if dirty else ""))
    except OSError:
        pass
    return ", ".join(parts)


def import_error(tool):
    """Why a peer cannot be imported (None if it can), checked in a subprocess."""
    mod = {"modaluq": "modaluq", "pyOMA2": "pyoma2.algorithms", "koma": "koma.oma",
           "strid": "strid"}[tool]
    proc = subprocess.run([sys.executable, "-c", f"import {mod}"], capture_output=True, text=True)
    if proc.returncode == 0:
        return None
    last = (proc.stderr.strip().splitlines() or ["?"])[-1]
    return f"import {mod} failed: {last} (pip install {DIST[tool]})"


def fmt_s(x):
    if x is None:
        return "—"
    if x >= 100:
        return f"{x:.0f}"
    if x >= 10:
        return f"{x:.1f}"
    if x >= 1:
        return f"{x:.2f}"
    return f"{x:.3f}"


def table(header, rows):
    widths = [max(len(str(r[i])) for r in [header] + rows) for i in range(len(header))]
    line = lambda r: "| " + " | ".join(str(c).ljust(w) for c, w in zip(r, widths)) + " |"  # noqa: E731
    sep = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    return "\n".join([line(header), sep] + [line(r) for r in rows])


def median(xs):
    return statistics.median(xs) if xs else None


def run_sweeps(args, data_root, log):
    """modaluq time vs model order and vs record length; returns the points."""
    import modaluq  # noqa: F401  (data generation)

    rep = args.sweep_repeats
    sweeps = {"order": [], "length": []}
    # vs order: 30-DOF chain, 20 outputs, N = 1e5, block rows 20 (a = 400), 50 blocks
    base = dict(n_dof=30, n=100_000, p=20, n_blocks=50, io=False)
    path = make_data("sweep-order", base, data_root)
    n_maxes = [20, 40, 60, 100, 140, 200] if args.quick else [20, 40, 60, 80, 100, 140, 200]
    for unc in (True, False):
        for n_max in n_maxes:
            cfg = dict(base, n_max=n_max, unc=unc)
            r = spawn({"kind": "measure", "tool": "modaluq", "cfg": cfg, "data": path,
                       "repeats": rep, "check": False}, args.timeout)
            t = median(r.get("cpu", [])) if r.get("status") == "ok" else None
            sweeps["order"].append({"n_max": n_max, "unc": unc, "cpu": t, "status": r.get("status")})
            log(f"  sweep order  n_max={n_max:4d} unc={unc!s:5}  cpu {fmt_s(t)} s")
    # vs length: 6-DOF chain, 3 outputs, block rows 40, orders to 100, 50 blocks
    base = dict(n_dof=6, n=1_000_000, p=40, n_max=100, n_blocks=50, io=False)
    path = make_data("sweep-length", base, data_root)
    lengths = [10_000, 30_000, 100_000, 300_000, 1_000_000] if args.quick else \
        [10_000, 20_000, 50_000, 100_000, 200_000, 500_000, 1_000_000]
    for unc in (True, False):
        for n in lengths:
            cfg = dict(base, n=n, unc=unc)
            r = spawn({"kind": "measure", "tool": "modaluq", "cfg": cfg, "data": path,
                       "n_samples": n, "repeats": rep, "check": False}, args.timeout)
            t = median(r.get("cpu", [])) if r.get("status") == "ok" else None
            sweeps["length"].append({"n": n, "unc": unc, "cpu": t, "status": r.get("status")})
            log(f"  sweep length N={n:8d} unc={unc!s:5}  cpu {fmt_s(t)} s")
    return sweeps


def plot_sweeps(sweeps, path, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), dpi=100)
    ax = axes[0]
    for unc, style in ((True, "o-"), (False, "s--")):
        pts = [(s["n_max"], s["cpu"]) for s in sweeps["order"] if s["unc"] == unc and s["cpu"]]
        if pts:
            ax.loglog(*zip(*pts), style, label="with uncertainty" if unc else "no uncertainty")
    ax.set_xlabel("largest model order n_max (orders 2, 4, ..., n_max)")
    xs = sorted({s["n_max"] for s in sweeps["order"]})
    ax.set_xticks(xs)
    ax.set_xticks([], minor=True)
    ax.set_xticklabels([str(x) for x in xs])
    ax.set_ylabel("CPU s (1 thread)")
    ax.set_title("vs order: 20 ch, N = 1e5, p = q = 20, n_b = 50", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax = axes[1]
    for unc, style in ((True, "o-"), (False, "s--")):
        pts = [(s["n"], s["cpu"]) for s in sweeps["length"] if s["unc"] == unc and s["cpu"]]
        if pts:
            ax.loglog(*zip(*pts), style, label="with uncertainty" if unc else "no uncertainty")
    ax.set_xlabel("samples N")
    ax.set_title("vs length: 3 ch, p = q = 40, orders 2..100, n_b = 50", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="examples:\n  python bench/run.py\n  python bench/run.py --quick\n"
               "  python bench/run.py --only S1,U1 --no-peers --no-sweep --repeats 9\n"
               "configs: " + ", ".join(CONFIGS) + "; tools: " + ", ".join(TOOLS)
               + "\nsee docs/performance.md",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true",
                    help="modaluq 3 runs, peers 1 run, skip peer runs known to take > 1 min, "
                         "coarser sweep")
    ap.add_argument("--repeats", type=int, default=None, help="runs of modaluq per config (default 7)")
    ap.add_argument("--peer-repeats", type=int, default=None,
                    help="runs of a peer per config (default 3; slow ones always once)")
    ap.add_argument("--only", default=None, help="comma-separated configs, e.g. S1,U1")
    ap.add_argument("--tools", default=None, help="comma-separated tools (default all)")
    ap.add_argument("--no-peers", action="store_true", help="modaluq only")
    ap.add_argument("--no-floor", action="store_true", help="skip the machine floor")
    ap.add_argument("--no-sweep", action="store_true", help="skip the scaling sweep and plot")
    ap.add_argument("--sweep-repeats", type=int, default=None, help="runs per sweep point (default 3)")
    ap.add_argument("--timeout", type=float, default=600.0,
                    help="wall seconds per worker (default 600: the machine may be shared)")
    ap.add_argument("--plot", default=os.path.join(ROOT, "docs", "img", "performance_scaling.png"))
    ap.add_argument("--json", default=None, help="also write all results to this JSON file")
    ap.add_argument("--_worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args._worker is not None:
        worker_main(args._worker)
        return 0

    _import_numpy()
    warnings.simplefilter("ignore")
    rep_mq = args.repeats or (3 if args.quick else 7)
    rep_peer = args.peer_repeats or (1 if args.quick else 3)
    args.sweep_repeats = args.sweep_repeats or (1 if args.quick else 3)
    names = [c.strip() for c in args.only.split(",")] if args.only else list(CONFIGS)
    bad = [c for c in names if c not in CONFIGS]
    if bad:
        ap.error(f"unknown config(s) {bad}; choose from {list(CONFIGS)}")
    tools = [t.strip() for t in args.tools.split(",")] if args.tools else list(TOOLS)
    if args.no_peers:
        tools = ["modaluq"]
    if "modaluq" not in tools:
        tools = ["modaluq"] + tools  # ratios need it

    def log(msg):
        print(msg, file=sys.stderr, flush=True)

    t_start = time.perf_counter()
    vers = versions()
    info = machine_info()
    print("# modaluq benchmark (bench/run.py)\n")
    print(f"machine : {info}")
    print(f"python  : {platform.python_version()}, numpy {vers['numpy']}, scipy {vers['scipy']}; "
          f"1 BLAS/OpenMP thread ({', '.join(v + '=1' for v in _THREAD_VARS[:3])})")
    print("versions: " + ", ".join(f"{t} {vers[t] or '(not installed)'}" for t in TOOLS))
    build = modaluq_build()
    print(f"modaluq : {build}")
    print(f"command : python bench/run.py {' '.join(argv if argv is not None else sys.argv[1:])}".rstrip())
    print(f"runs    : modaluq median of {rep_mq}, peers median of {rep_peer} "
          f"(once when a run takes > 60 s); timeout {args.timeout:.0f} s wall\n")

    unavailable = {}
    for tool in tools:
        err = import_error(tool)
        if err and tool == "modaluq":
            for _ in range(10):  # the package may be in the middle of a re-install
                log("modaluq does not import; retrying in 30 s ...")
                time.sleep(30)
                err = import_error(tool)
                if not err:
                    break
        if err:
            unavailable[tool] = err
            print(f"{tool}: not measured: {err}")
    if "modaluq" in unavailable:
        return 1

    data_root = tempfile.mkdtemp(prefix="modaluq-bench-")
    results = {"machine": info, "versions": vers, "modaluq_build": build, "configs": {}, "floor": None,
               "sweeps": None}
    try:
        paths = {}
        for name in names:
            log(f"simulating {name} ...")
            paths[name] = make_data(name, CONFIGS[name], data_root)
            with open(os.path.join(paths[name], "meta.json")) as fh:
                meta = json.load(fh)
            CONFIGS[name]["n_outputs"] = meta["n_outputs"]
            CONFIGS[name]["freqs"] = meta["frequency_hz"]

        if not args.no_floor:
            log("measuring the machine floor ...")
            fl = spawn({"kind": "floor", "configs": {n: CONFIGS[n] for n in names}}, args.timeout)
            results["floor"] = fl if "floors" in fl else None
            if results["floor"] is None:
                print(f"floor: not measured: {fl.get('reason')}")

        for name in names:
            cfg = CONFIGS[name]
            row_tools = list(tools)
            if cfg["unc"] and (os.cpu_count() or 1) >= 2:  # BLAS stays at 1 thread; ours at 2
                row_tools.insert(1, "modaluq (threads=2)")
            if "pyOMA2" in tools and name == "U1" and not args.quick:
                row_tools.insert(row_tools.index("pyOMA2") + 1, "pyOMA2 (step=1)")
            res_cfg = {}
            for tool in row_tools:
                base_tool = tool.split(" ")[0]
                if base_tool in unavailable:
                    res_cfg[tool] = {"status": "unavailable", "reason": unavailable[base_tool]}
                    continue
                if base_tool == "pyOMA2" and name == "U3":
                    res_cfg[tool] = {"status": "skipped", "reason": "(skipped: does not finish)"}
                    continue
                slow = base_tool == "pyOMA2" and cfg["unc"]  # ~1-2 min a run
                if slow and args.quick:
                    res_cfg[tool] = {"status": "skipped",
                                     "reason": "(skipped with --quick: > 1 min a run)"}
                    continue
                reps = rep_mq if base_tool == "modaluq" else (1 if slow else rep_peer)
                log(f"{name}: {tool} x{reps} ...")
                spec = {"kind": "measure", "tool": tool, "cfg": cfg, "data": paths[name],
                        "repeats": reps}
                r = spawn(spec, args.timeout)
                res_cfg[tool] = r
                if r.get("status") == "ok":
                    log(f"   cpu {fmt_s(median(r['cpu']))} s  wall {fmt_s(median(r['wall']))} s  "
                        f"mem {r['mem_mb']:.0f} MB  {r.get('check', '')}")
                else:
                    log(f"   {r.get('status')}: {r.get('reason')}")
            results["configs"][name] = res_cfg

        if not args.no_sweep:
            log("scaling sweep (modaluq) ...")
            results["sweeps"] = run_sweeps(args, data_root, log)
    finally:
        shutil.rmtree(data_root, ignore_errors=True)

    report(results, names, args, rep_mq)
    if results["sweeps"] and args.plot:
        plot_sweeps(results["sweeps"], args.plot,
                    f"modaluq {vers['modaluq']}, 1 thread, {info.split(',')[0]}")
        print(f"\nplot: {os.path.relpath(args.plot, os.getcwd())} "
              f"({os.path.getsize(args.plot) / 1024:.0f} kB)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1, default=str)
    print(f"\ntotal benchmark time {time.perf_counter() - t_start:.0f} s")
    return 0


def report(results, names, args, rep_mq):
    floor = results["floor"]
    print("## Configurations\n")
    rows = []
    for name in names:
        c = CONFIGS[name]
        chk, why = checked_modes(c, c["freqs"])
        rows.append([name, f"{c['n_dof']}-DOF chain, {c['n_outputs']} outputs" + (" + 1 input" if c["io"] else ""),
                     f"{c['n']:.0e}".replace("e+0", "e"), f"{c['p']}", f"2..{c['n_max']} step 2",
                     c["n_blocks"] if c["unc"] else "—", "yes" if c["unc"] else "no",
                     f"{why}; orders {check_orders(c)}"])
    print(table(["cfg", "data", "N", "block rows p=q", "orders", "n_b", "uncertainty", "mode check"], rows))

    print("\n## Results (CPU and wall seconds: medians; peak MB: the most any run added to the "
          "resident memory, peak RSS during the run minus RSS just before it, data and imports "
          "already loaded)\n")
    rows = []
    for name in names:
        res = results["configs"].get(name, {})
        mq = res.get("modaluq", {})
        mq_cpu = median(mq.get("cpu", [])) if mq.get("status") == "ok" else None
        for tool, r in res.items():
            if r.get("status") == "ok":
                cpu, wall = median(r["cpu"]), median(r["wall"])
                ratio = "1" if tool == "modaluq" else (f"{cpu / mq_cpu:.0f}×" if mq_cpu and cpu / mq_cpu >= 10
                                                        else f"{cpu / mq_cpu:.1f}×" if mq_cpu else "—")
                rows.append([name, tool, fmt_s(cpu), fmt_s(wall), f"{r['mem_mb']:.0f}",
                             len(r["cpu"]), ratio, r.get("check", "")])
            else:
                reason = r.get("reason", r.get("status"))
                rows.append([name, tool, "—", "—", "—", 0, "—", reason])
    print(table(["cfg", "tool", "CPU s", "wall s", "peak MB", "runs", "CPU ÷ modaluq", "modes found / note"], rows))
    threads = sorted({n for res in results["configs"].values() for r in res.values()
                      for n in (r.get("blas_threads") or [])})
    if threads:
        print(f"\nBLAS threads in the workers (threadpoolctl): {', '.join(map(str, threads))}")

    print("\n## modaluq against the issue's targets and this machine's floor\n")
    if floor:
        print(f"measured: dgemm {floor['dgemm_gflops']:.1f} GFLOP/s (1 thread, numpy matmul "
              f"1536²), copy bandwidth {floor['copy_gbs']:.1f} GB/s (400 MB np.copyto, read+write)\n")
    rows = []
    for name in names:
        mq = results["configs"].get(name, {}).get("modaluq", {})
        cpu = median(mq.get("cpu", [])) if mq.get("status") == "ok" else None
        fl = floor["floors"].get(name) if floor else None
        parts = ""
        if fl:
            parts = ", ".join(f"{k} {v * 1e3:.0f}" for k, v in fl["parts"].items() if v >= 5e-4)
        rows.append([name, fmt_s(cpu), f"≤ {TARGET[name]}",
                     "—" if cpu is None else ("met" if cpu <= TARGET[name] else f"MISSED ({cpu / TARGET[name]:.1f}× target)"),
                     fmt_s(fl["total"]) if fl else "—",
                     f"{cpu / fl['total']:.1f}×" if (fl and cpu) else "—", parts or "—",
                     PYOMA_ISSUE[name]])
    print(table(["cfg", "modaluq CPU s", "target", "", "floor s", "÷ floor", "floor parts (ms)",
                 "pyOMA2 in the issue (s)"], rows))
    print("\nfloor = max(2·N·(L+1)·d² / F, 8·N·d / B) [covariance lag products, L = p+q-1, d = channels]"
          "\n      + t(numpy SVD of the a×b matrix H) + Σ_n t(numpy eig of n×n) [measured]"
          "\n      + 2·n_b·(3·a·pm·b + a·(pm)²) / F [IO: projecting the future inputs out of every block]"
          "\n      + (8·a·b·n_max·n_b + 8·a·n_max²·n_b + 8·n_b·Σ_n n²·(n/2)) / F"
          "\n        [uncertainty: ΔΓ for n_max singular vectors, Q1..Q3, per mode of every order]"
          "\n  with F the dgemm rate and B the copy bandwidth measured above.")

    # Uncertainty cross-check between tools that propagate it.
    notes = []
    for name in names:
        res = results["configs"].get(name, {})
        mq = res.get("modaluq", {}).get("stds") or {}
        for tool, r in res.items():
            if tool == "modaluq" or not r.get("stds"):
                continue
            common = [k for k in r["stds"] if k in mq and mq[k] > 0]
            if common:
                ratios = [r["stds"][k] / mq[k] for k in common]
                notes.append(f"{name} {tool}: frequency std ÷ modaluq's over {len(common)} checked "
                             f"modes: {min(ratios):.2f} … {max(ratios):.2f}")
    if notes:
        print("\n## Frequency standard deviations against modaluq's (same data, same orders)\n")
        for n in notes:
            print("- " + n)
    settings = {}
    for name in names:
        for tool, r in results["configs"].get(name, {}).items():
            if r.get("settings"):
                settings.setdefault(tool, {})[name] = r["settings"]
    if settings:
        print("\n## Calls\n")
        for tool, by in settings.items():
            for name, s in by.items():
                print(f"- {name} {tool}: {s}")
    if results["sweeps"]:
        print("\n## Scaling (modaluq CPU s, median of "
              f"{args.sweep_repeats})\n")
        sw = results["sweeps"]
        for key, label in (("order", "n_max"), ("length", "n")):
            xs = sorted({s[label] for s in sw[key]})
            row_u = [fmt_s(next((s["cpu"] for s in sw[key] if s[label] == x and s["unc"]), None)) for x in xs]
            row_n = [fmt_s(next((s["cpu"] for s in sw[key] if s[label] == x and not s["unc"]), None)) for x in xs]
            head = [label] + [f"{x:.0e}".replace("e+0", "e") if key == "length" else str(x) for x in xs]
            print(table(head, [["with uncertainty"] + row_u, ["no uncertainty"] + row_n]))
            print()


if __name__ == "__main__":
    sys.exit(main())
