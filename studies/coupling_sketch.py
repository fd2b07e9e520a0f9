"""The merge's sketched noise-coupling test against the exact one (issue 23's time; docs/uq-math.md
§13.4, IdentifyOptions::coupling_sketch).

N campaigns of the benchmark's kind (bench/multisetup.py: the deck of modaluq.simulate.campaign at
25 Hz, references L3 and R8, 4 roving channels in each of S setups, p = q = 50, orders 2..100, 20
blocks per setup), each merged by identify_setups with the exact test (coupling_sketch = 0) and with
sketches of s combinations per setup. Reported per s, over every pole above its campaign's noise
floor:

* the flags: poles flagged by both, by the exact test only, by the sketch only, and the spread of
  log(rho_sketch / rho_exact);
* the sigma of the poles both flag (sketch: frozen rows times rho; exact: the unfrozen rows) as a
  ratio sketch / exact, for f, xi and the shape components;
* the selected modes (select_modes() with the defaults): whether the same modes are selected, and
  the largest relative change of f, sigma_f and sigma_xi;
* the CPU time of the merge.

Usage: OPENBLAS_NUM_THREADS=1 python studies/coupling_sketch.py [N] [--setups S] [--samples M] [--sketch 2 4 8]
(defaults N = 4, S = 10, M = 100000: about 3 min of one core).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

import numpy as np
import pandas as pd

import modaluq

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "bench"))
import multisetup as bench_multisetup  # noqa: E402  (the benchmark's campaign and settings)

REFERENCES = bench_multisetup.REFERENCES
SETTINGS = bench_multisetup.SETTINGS


def campaign(seed: int, n_setups: int, n_samples: int) -> tuple:
    """One campaign of the benchmark's kind (bench/multisetup.py's) as DataFrames, and its rate."""
    camp, names = bench_multisetup.campaign(n_setups, n_samples, seed=seed)
    return [pd.DataFrame(s.y, columns=n) for s, n in zip(camp.setups, names)], camp.fs


def merge(frames, fs, sketch):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # slowly decaying noise poles: the same for every sketch
        t0 = time.process_time()
        res = modaluq.identify_setups(frames, fs=fs, references=list(REFERENCES), coupling_sketch=sketch, **SETTINGS)
        return res, time.process_time() - t0


def above_floor(res):
    """Per order above the smallest setup floor: (rho, flag, sigma_f, sigma_xi, shape sigma) of every pole."""
    k = res.significant_singular_values
    out = []
    for m in res.modes:
        if m.order <= k or not len(m.frequency_hz):
            continue
        shape = np.sqrt(m.mode_shape_std_real ** 2 + m.mode_shape_std_imag ** 2)
        out.append((np.asarray(m.noise_coupling), np.asarray(m.noise_coupled), np.asarray(m.frequency_std),
                    np.asarray(m.damping_std), np.median(shape, axis=0)))
    return [np.concatenate(x) for x in zip(*out)]


def _span(v) -> str:
    return f"{min(v):.1f}-{max(v):.1f}" if len(v) else "-"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("n", nargs="?", type=int, default=4)
    ap.add_argument("--setups", type=int, default=10)
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--sketch", type=int, nargs="+", default=[2, 4, 8])
    args = ap.parse_args(argv)
    rows = {s: {"both": 0, "exact_only": 0, "sketch_only": 0, "neither": 0, "log_rho": [], "ratio_f": [],
                "ratio_xi": [], "ratio_shape": [], "rho_differ": [], "same_selection": 0, "sel_f": 0.0, "sel_sf": 0.0,
                "sel_sx": 0.0, "cpu": []} for s in args.sketch}
    cpu_exact = []
    for seed in range(args.n):
        frames, fs = campaign(700 + seed, args.setups, args.samples)
        exact, t = merge(frames, fs, 0)
        cpu_exact.append(t)
        rho_e, flag_e, sf_e, sx_e, sh_e = above_floor(exact)
        sel_e = exact.select_modes()
        for s in args.sketch:
            res, t = merge(frames, fs, s)
            r = rows[s]
            r["cpu"].append(t)
            rho_s, flag_s, sf_s, sx_s, sh_s = above_floor(res)
            r["both"] += int(np.sum(flag_e & flag_s))
            r["exact_only"] += int(np.sum(flag_e & ~flag_s))
            r["sketch_only"] += int(np.sum(~flag_e & flag_s))
            r["neither"] += int(np.sum(~flag_e & ~flag_s))
            r["log_rho"].extend(np.log(rho_s / rho_e))
            r["rho_differ"].extend(rho_e[flag_e != flag_s])
            both = flag_e & flag_s
            r["ratio_f"].extend(sf_s[both] / sf_e[both])
            r["ratio_xi"].extend(sx_s[both] / sx_e[both])
            r["ratio_shape"].extend(sh_s[both] / sh_e[both])
            sel = res.select_modes()
            if sel.n_modes == sel_e.n_modes:
                r["same_selection"] += int(np.allclose(sel.frequency_hz, sel_e.frequency_hz, rtol=1e-3))
                rel = lambda a, b: float(np.max(np.abs(np.asarray(a) / np.asarray(b) - 1)))  # noqa: E731
                r["sel_f"] = max(r["sel_f"], rel(sel.frequency_hz, sel_e.frequency_hz))
                r["sel_sf"] = max(r["sel_sf"], rel(sel.frequency_std, sel_e.frequency_std))
                r["sel_sx"] = max(r["sel_sx"], rel(sel.damping_std, sel_e.damping_std))
        print(f"campaign {seed + 1}/{args.n} done", flush=True)
    print(f"\n{args.n} campaigns of {args.setups} setups x 6 channels x {args.samples} samples; merge CPU s, exact: "
          f"{np.median(cpu_exact):.2f}")
    print("| s | merge CPU s | flagged both / exact only / sketch only / neither | log(rho_s/rho_e) median, 5-95 % "
          "| exact rho where the flags differ | sigma sketch/exact of poles both flag: f, xi, shape (median [5, 95 %]) | same selection | "
          "selected: max rel. change f, sigma_f, sigma_xi |")
    print("|---|---|---|---|---|---|---|---|")
    for s, r in rows.items():
        q = lambda v: f"{np.median(v):.2f} [{np.percentile(v, 5):.2f}, {np.percentile(v, 95):.2f}]" if len(v) else "-"  # noqa: E731
        lr = np.asarray(r["log_rho"])
        print(f"| {s} | {np.median(r['cpu']):.2f} | {r['both']} / {r['exact_only']} / {r['sketch_only']} / {r['neither']} "
              f"| {np.median(lr):+.2f}, [{np.percentile(lr, 5):+.2f}, {np.percentile(lr, 95):+.2f}] "
              f"| {_span(r['rho_differ'])} | {q(r['ratio_f'])}, {q(r['ratio_xi'])}, {q(r['ratio_shape'])} | {r['same_selection']}/{args.n} "
              f"| {r['sel_f']:.1e}, {r['sel_sf']:.1e}, {r['sel_sx']:.1e} |")
    return rows


if __name__ == "__main__":
    main()
