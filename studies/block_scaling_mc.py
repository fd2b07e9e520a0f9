"""Issue 27: the per-mode lag-1 scaling of σ ("scaled/mode", docs/validation.md "Issue 27: σ that
covers", (b) and (c)) measured by Monte Carlo everywhere the issue asks, post hoc from the
factor rows the core returns, against the core's σ from the same records.

For every pole the core returns its first-order factor rows u_f and u_ξ (``Modes.frequency_damping_factor``,
one column per block of data in time order; σ_f = ‖u_f‖, σ_ξ = ‖u_ξ‖). Per mode:

    ρ_r = Σ_k u_r(k) u_r(k+1) / Σ_k u_r(k)²   (r = f, ξ),   ρ = (ρ_f + ρ_ξ)/2 + 1/n_b,
    c = max(1/4, 1 + 2ρ),   σ_f, σ_ξ ← √c · σ_f, √c · σ_ξ            ("scaled/mode")

and, as a separate, pre-defined variant (docs/validation.md (b)), the same applied only where
|ρ| > 2/√n_b ("gated"). No core change: both are computed from the same identification as the
core's σ.

Records are those of ``modaluq validate`` (python/modaluq/validation/montecarlo.py): record k is
``modaluq.simulate(10_000, seed=record_seed(seed, k), **case)``, identified output-only (OO) and
input/output (IO) with p = q = 15 and the case's n_blocks, poles matched to the true modes at each
order with ``match_modes`` (±5 %). Poles flagged ``noise_coupled`` are left out of every statistic
(as in the "Above the true order" tables) and counted. Per case × n_blocks × method × order × mode,
over the unflagged matched records: median σ/σ_MC, coverage of ±1.96 σ around the Monte Carlo
mean, RMS over the records of z = (x − mean)/σ, for f and ξ and each estimator.

usage: OPENBLAS_NUM_THREADS=1 python studies/block_scaling_mc.py [--records N] [--cases paper known known-mid light frame]
       [--out FILE.npz]       (about 0.4 s per record of all five cases on one core)
       python studies/block_scaling_mc.py --report FILE.npz [FILE.npz ...]   (the tables of saved runs)
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings

import numpy as np

from modaluq._core import NumericalError
from modaluq.identification import identify
from modaluq.results import ModalUQWarning
from modaluq.settings import Settings
from modaluq.simulate import simulate
from modaluq.validation.montecarlo import match_modes, record_seed

N_SAMPLES = 10_000
BLOCK_ROWS = 15
TOLERANCE = 0.05
C_MIN = 0.25
#: name: (label, keywords of modaluq.simulate, methods, orders, n_blocks)
CASES = {
    "paper": ("chain, paper case (unknown forces 10 %)", {}, ("OO", "IO"), (12, 24, 36), (50,)),
    "known": ("chain, known input only (unknown_input_std 0)", {"unknown_input_std": 0.0}, ("IO", "OO"),
              (12, 24), (25, 200)),
    "known-mid": ("chain, known input only, input/output, n_b between", {"unknown_input_std": 0.0}, ("IO",),
                  (12, 24), (50, 100)),
    "light": ("chain, ξ = 0.2 % (unknown forces 10 %)", {"damping_ratio": 0.002}, ("OO",), (12, 24), (50, 200)),
    "frame": ("4-storey frame, two inputs (--n-dof 4 --input-dofs 0 3)", {"n_dof": 4, "input_dofs": (0, 3)},
              ("OO", "IO"), (8, 16, 24), (50,)),
}
TRUE_ORDER = {"paper": 12, "known": 12, "known-mid": 12, "light": 12, "frame": 8}
ESTIMATORS = ("core", "scaled/mode", "gated")
FIELDS = ("f", "xi", "sf", "sx", "rho_f", "rho_x")


def scale_factor(rho_f, rho_x, n_blocks, gated=False):
    """c per pole (the variance factor) from the lag-1 autocorrelations of its factor rows."""
    rho = (np.asarray(rho_f) + np.asarray(rho_x)) / 2 + 1.0 / n_blocks
    c = np.maximum(C_MIN, 1 + 2 * rho)
    if gated:
        c = np.where(np.abs(rho) > 2 / np.sqrt(n_blocks), c, 1.0)
    return c


def lag1(u):
    """ρ (..., ) of factor rows u (..., n_b): Σ u(k) u(k+1) / Σ u(k)²."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sum(u[..., :-1] * u[..., 1:], axis=-1) / np.sum(u * u, axis=-1)


def run_case(name, n_records, seed=0, progress=True):
    """Simulate and identify ``n_records`` records of case ``name``; return its arrays."""
    label, sim_kw, methods, orders, nbs = CASES[name]
    shape = None
    out = None
    t0 = time.perf_counter()
    for k in range(n_records):
        sim = simulate(N_SAMPLES, seed=record_seed(seed, k), **sim_kw)
        if out is None:
            nm = sim.frequency_hz.size
            shape = (len(nbs), len(methods), len(orders), n_records, nm)
            out = {f: np.full(shape, np.nan) for f in FIELDS}
            out.update(flagged=np.zeros(shape, bool), short=np.zeros(shape, bool),
                       failed=np.zeros(shape[:2] + (n_records,), bool),
                       true_f=sim.frequency_hz, true_xi=sim.damping_ratio)
        for b, nb in enumerate(nbs):
            settings = Settings(block_rows=BLOCK_ROWS, orders=orders, n_blocks=nb)
            for m, meth in enumerate(methods):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", ModalUQWarning)
                    try:
                        res = identify(sim.y, sim.u if meth == "IO" else None, fs=sim.fs, settings=settings)
                    except NumericalError:
                        out["failed"][b, m, k] = True
                        continue
                for o, n in enumerate(orders):
                    modes = res.at_order(n)
                    idx = match_modes(modes.frequency_hz, out["true_f"], TOLERANCE)
                    hit = idx >= 0
                    if not hit.any():
                        continue
                    j = idx[hit]
                    u = modes.frequency_damping_factor[j]          # (hits, 2, n_b)
                    cell = (b, m, o, k)
                    out["f"][cell][hit] = modes.frequency_hz[j]
                    out["xi"][cell][hit] = modes.damping_ratio[j]
                    out["sf"][cell][hit] = modes.frequency_std[j]
                    out["sx"][cell][hit] = modes.damping_std[j]
                    out["rho_f"][cell][hit] = lag1(u[:, 0])
                    out["rho_x"][cell][hit] = lag1(u[:, 1])
                    out["flagged"][cell][hit] = modes.noise_coupled[j]
                    out["short"][cell][hit] = modes.block_too_short[j]
        if progress and (k + 1) % 50 == 0:
            print(f"  {name}: {k + 1}/{n_records} records, {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    out["elapsed_s"] = time.perf_counter() - t0
    return out


def cell_stats(x, s):
    """(median σ/σ_MC, coverage %, RMS z) of estimates x and their σ s over the records."""
    ok = np.isfinite(x) & np.isfinite(s)
    x, s = x[ok], s[ok]
    if x.size < 3:
        return np.nan, np.nan, np.nan
    d = x - x.mean()
    sd = x.std(ddof=1)
    return np.median(s) / sd, 100 * np.mean(np.abs(d) <= 1.96 * s), np.sqrt(np.mean((d / s) ** 2))


def summarize(name, a):
    """stats[b, m, o, estimator, param(f, ξ), statistic(ratio, coverage, rms z), mode], flagged %,
    median c per mode."""
    _, _, methods, orders, nbs = CASES[name]
    nb_, nm_, no_, _, nmode = a["f"].shape
    stats = np.full((nb_, nm_, no_, len(ESTIMATORS), 2, 3, nmode), np.nan)
    flagged = np.full((nb_, nm_, no_, nmode), np.nan)
    c_med = np.full((nb_, nm_, no_, nmode), np.nan)
    short = np.full((nb_, nm_, no_, nmode), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        for b, nb in enumerate(nbs):
            c = {"core": np.ones_like(a["f"][b]), "scaled/mode": scale_factor(a["rho_f"][b], a["rho_x"][b], nb),
                 "gated": scale_factor(a["rho_f"][b], a["rho_x"][b], nb, gated=True)}
            matched = np.isfinite(a["f"][b])
            flagged[b] = 100 * (a["flagged"][b] & matched).sum(axis=2) / matched.sum(axis=2)
            use = matched & ~a["flagged"][b]
            short[b] = 100 * (a["short"][b] & use).sum(axis=2) / use.sum(axis=2)
            for m in range(nm_):
                for o in range(no_):
                    for i in range(nmode):
                        u = use[m, o, :, i]
                        c_med[b, m, o, i] = np.median(c["scaled/mode"][m, o, u, i]) if u.any() else np.nan
                        for e, est in enumerate(ESTIMATORS):
                            g = np.sqrt(c[est][m, o, u, i])
                            for p, (x, s) in enumerate((("f", "sf"), ("xi", "sx"))):
                                stats[b, m, o, e, p, :, i] = cell_stats(a[x][b, m, o, u, i], g * a[s][b, m, o, u, i])
    return stats, flagged, c_med, short


def _fmt(v, spec):
    return " ".join("–" if not np.isfinite(x) else format(x, spec) for x in v)


def case_table(name, a):
    label, _, methods, orders, nbs = CASES[name]
    stats, flagged, c_med, short = summarize(name, a)
    n = a["f"].shape[3]
    lines = [f"**{label}**, {n} records, true order {TRUE_ORDER[name]}; per cell modes 1–{a['f'].shape[4]}",
             "",
             "| n_b | method | order | σ | f: median σ/σ_MC | f: coverage % | f: RMS z | ξ: median σ/σ_MC "
             "| ξ: coverage % | ξ: RMS z |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for b, nb in enumerate(nbs):
        for m, meth in enumerate(methods):
            for o, order in enumerate(orders):
                for e, est in enumerate(ESTIMATORS):
                    s = stats[b, m, o, e]
                    lines.append(f"| {nb} | {meth} | {order} | {est} | {_fmt(s[0, 0], '.2f')} | {_fmt(s[0, 1], '.0f')} "
                                 f"| {_fmt(s[0, 2], '.2f')} | {_fmt(s[1, 0], '.2f')} | {_fmt(s[1, 1], '.0f')} "
                                 f"| {_fmt(s[1, 2], '.2f')} |")
                lines.append(f"| {nb} | {meth} | {order} | median c; flagged %; block_too_short % "
                             f"| {_fmt(c_med[b, m, o], '.2f')} | {_fmt(flagged[b, m, o], '.1f')} "
                             f"| {_fmt(short[b, m, o], '.0f')} | | | |")
    fails = a["failed"].sum()
    if fails:
        lines.append(f"\n{fails} identifications failed (NumericalError).")
    return "\n".join(lines)


def _band(stats, e):
    """Shares of cells (f and ξ × modes) with coverage in 93–97 %, median ratio in 0.85–1.18,
    RMS z in 0.9–1.1; and the cells themselves."""
    cov, rat, rz = stats[..., e, :, 1, :], stats[..., e, :, 0, :], stats[..., e, :, 2, :]
    return (cov >= 93) & (cov <= 97), (rat >= 0.85) & (rat <= 1.18), (rz >= 0.9) & (rz <= 1.1), \
        np.isfinite(cov)


def summary_table(results):
    """One row per group of cells and estimator: how many are in the issue's bands, and, among the
    cells the core already has in both bands, how many the estimator keeps there."""
    groups = {}
    for name, a in results.items():
        _, _, methods, orders, nbs = CASES[name]
        stats = summarize(name, a)[0]
        for b, nb in enumerate(nbs):
            for m, meth in enumerate(methods):
                for o, order in enumerate(orders):
                    key = f"{name} {meth}, order {order} ({order // TRUE_ORDER[name]}×)" + \
                        (f", n_b {nb}" if len(nbs) > 1 else "")
                    groups.setdefault(key, []).append(stats[b, m, o])
    lines = ["| cells | estimator | n | coverage 93–97 % | median σ/σ_MC 0.85–1.18 | RMS z 0.9–1.1 "
             "| coverage min–median–max | RMS z min–median–max | core in both bands: kept |",
             "|---|---|---|---|---|---|---|---|---|"]
    for key, cells in groups.items():
        st = np.stack(cells)
        core_cov, core_rat, _, ok = _band(st, 0)
        core_good = core_cov & core_rat & ok
        for e, est in enumerate(ESTIMATORS):
            cov, rat, rz, ok = _band(st, e)
            nok = ok.sum()
            cv, z = st[..., e, :, 1, :][ok], st[..., e, :, 2, :][ok]
            kept = (cov & rat & core_good).sum()
            lines.append(f"| {key} | {est} | {nok} | {cov[ok].sum()} | {rat[ok].sum()} | {rz[ok].sum()} "
                         f"| {cv.min():.0f}–{np.median(cv):.0f}–{cv.max():.0f} "
                         f"| {z.min():.2f}–{np.median(z):.2f}–{z.max():.2f} | {kept}/{core_good.sum()} |")
    return "\n".join(lines)


def report(results):
    parts = [case_table(name, a) for name, a in results.items()]
    parts.append("**Summary** (a cell: one mode's f or ξ; n: cells with ≥ 3 unflagged records)\n\n"
                 + summary_table(results))
    return "\n\n".join(parts)


def save(path, results, meta):
    flat = {"meta": json.dumps(meta)}
    for name, a in results.items():
        for key, v in a.items():
            flat[f"{name}/{key}"] = np.asarray(v)
    np.savez_compressed(path, **flat)


def load(path):
    z = np.load(path, allow_pickle=False)
    results = {}
    for key in z.files:
        if key == "meta":
            continue
        name, field = key.split("/", 1)
        results.setdefault(name, {})[field] = z[key]
    return {n: results[n] for n in CASES if n in results}, json.loads(str(z["meta"]))


def main(n_records=400, cases=tuple(CASES), out=None, seed=0, progress=True):
    """Run ``cases`` on ``n_records`` records each, print the tables, save ``out`` (.npz) if
    given; return {case: arrays}."""
    results = {}
    for name in cases:
        results[name] = run_case(name, n_records, seed=seed, progress=progress)
        print(f"{name}: {n_records} records in {results[name]['elapsed_s']:.0f} s", file=sys.stderr)
        if out is not None:   # after each case, so that a long run keeps what it has
            save(out, results, {"n_records": n_records, "seed": seed, "cases": list(results)})
    print(report(results))
    return results


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--records", type=int, default=400, help="records per case (default 400)")
    p.add_argument("--cases", nargs="+", choices=tuple(CASES), default=tuple(CASES))
    p.add_argument("--seed", type=int, default=0, help="run seed (record k: SeedSequence(seed, spawn_key=(k,)))")
    p.add_argument("--out", help="save the per-record arrays to this .npz")
    p.add_argument("--report", nargs="+", metavar="NPZ", help="print the tables of saved runs and exit")
    args = p.parse_args()
    if args.report:
        merged = {}
        for f in args.report:
            merged.update(load(f)[0])
        print(report(merged))
    else:
        main(args.records, args.cases, args.out, args.seed)
