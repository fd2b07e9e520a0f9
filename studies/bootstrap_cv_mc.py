"""Issue 27, (m): the bootstrap of σ with the first-order map as a control variate.

The bootstrap of (g) (``bootstrap_draws``) covers above the true order, but its σ is the robust
spread of B followed poles: with B = 100 it is known to about ±12 %, which is why it is used only
above k* (below, it is noisier than the first-order σ) and why it costs 5–10 identifications.
Most of a draw's move of a pole is the first-order move the core already knows exactly: with the
pole's factor row u (σ_lin = ‖u‖, the core's frozen first-order σ) and the draw's signs ε_d, that
move is ℓ_d = u·ε_d. The control variate keeps the exact first-order variance and estimates from
the draws only what they add to it:

    σ_cv² = σ_lin² + s(δ)² − s(ℓ)²,     s = 1.4826 MAD over the followed draws,

δ_d the followed pole of draw d. Where the draws are linear, δ = ℓ and σ_cv = σ_lin exactly, with
no sampling noise at all; above k* the difference s(δ)² − s(ℓ)² is what the noise directions add,
and it is estimated from draws whose linear part cancels in it, so fewer draws should do.

Per record (as ``modaluq validate`` simulates, N = 10,000, p = q = 15, 50 blocks, OO and IO): the
oracle's H, T_H, k* and frozen (f, ξ) rows (``above_order_diagnosis.record_maps``), B = 100
Rademacher draws H + unvec(T_H ε_d) identified at each order (``oracle.poles_at_orders``), each
pole followed (``oracle.follow_poles``). For B in DRAW_COUNTS (the first B draws): the MAD σ of
(g) and σ_cv, each at every order ("all") and only above the record's k* (the core's first-order
σ up to it, "hybrid" as in (g)). Poles the core flags noise-coupled are left out.

usage: OPENBLAS_NUM_THREADS=1 python studies/bootstrap_cv_mc.py --records 400 --out cv.npz
       OPENBLAS_NUM_THREADS=1 python studies/bootstrap_cv_mc.py --structure frame --records 400
       python studies/bootstrap_cv_mc.py --report cv.npz
"""
from __future__ import annotations

import pathlib
import sys
import warnings

import numpy as np

from modaluq.identification import identify
from modaluq.results import ModalUQWarning
from modaluq.settings import Settings

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "python"))
from above_order_diagnosis import _stats, finish, record_maps, reprint, study_parser  # noqa: E402
from bootstrap_sigma_mc import COVERAGE_BAND, MEDIAN_BAND, METHODS, N_BLOCKS, STRUCTURES, P  # noqa: E402
from partial_unfreeze_mc import run_records  # noqa: E402

import oracle  # noqa: E402

DRAWS = 100
DRAW_COUNTS = (10, 20, 30, 50, 100)
MAD = 1.482602218505602


def _mad(x, axis):
    med = np.nanmedian(x, axis=axis, keepdims=True)
    return MAD * np.nanmedian(np.abs(x - med), axis=axis)


def draw_spreads(maps, l, fs, orders, draws=DRAWS, counts=DRAW_COUNTS):
    """{order: dict(lin (nm × 2), mad, cv (len(counts) × nm × 2), corr (nm × 2))} of one record:
    the frozen first-order σ, the MAD σ and the control-variate σ from the first B draws, and the
    correlation of the followed moves δ with their first-order part ℓ over all the draws."""
    H = oracle.unvec(maps["H"], *_shape(maps))
    T_H = maps["T_H"]
    eps = oracle.rademacher_signs(T_H.shape[1], draws, oracle.BOOTSTRAP_SEED)
    dH = T_H @ eps                                                     # h × draws
    targets = {n: (maps[n]["f"], maps[n]["xi"]) for n in orders}
    smp = {n: np.full((len(maps[n]["f"]), draws, 2), np.nan) for n in orders}
    for d in range(draws):
        drawn = oracle.poles_at_orders(H + oracle.unvec(dH[:, d], *H.shape), l, fs, targets)
        for n in orders:
            if len(targets[n][0]):
                smp[n][:, d, 0], smp[n][:, d, 1] = oracle.follow_poles(*targets[n], *drawn[n])
    out = {}
    for n in orders:
        rows = maps[n]["frozen"]                                       # nm × 2 × h
        nm = rows.shape[0]
        u = rows @ T_H                                                 # nm × 2 × n_b
        lin = np.linalg.norm(u, axis=2)
        ell = np.einsum("mvb,bd->mdv", u, eps)                         # nm × draws × 2
        corr = np.full((nm, 2), np.nan)
        for i in range(nm):
            ok = np.isfinite(smp[n][i, :, 0])
            if ok.sum() >= 3:
                for v in (0, 1):
                    corr[i, v] = np.corrcoef(smp[n][i, ok, v], ell[i, ok, v])[0, 1]
        mad = np.full((len(counts), nm, 2), np.nan)
        cv = np.full((len(counts), nm, 2), np.nan)
        for c, B in enumerate(counts):
            x, e = smp[n][:, :B].copy(), ell[:, :B].copy()
            ok = np.isfinite(x[..., 0])
            e[~ok] = np.nan
            enough = ok.sum(axis=1) >= max(int(np.ceil(0.8 * B)), 2)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                sd, se = _mad(x, 1), _mad(e, 1)
            var = lin ** 2 + sd ** 2 - se ** 2
            mad[c] = np.where(enough[:, None], sd, np.nan)
            cv[c] = np.where(enough[:, None], np.sqrt(np.maximum(var, 0.25 * lin ** 2)), np.nan)
        out[n] = {"lin": lin, "mad": mad, "cv": cv, "corr": corr}
    return out


def _shape(maps):
    a = maps["T_H"].shape[0]
    b = int(round(np.sqrt(a)))
    assert b * b == a, "p = q gives a square H"
    return b, b


def record_spreads(y, u, fs, orders, draws=DRAWS):
    """One record for :func:`partial_unfreeze_mc.run_records`: the oracle's poles per order with
    the core's σ and noise-coupling flag of the same pole (the core's poles equal the oracle's),
    and the spreads of :func:`draw_spreads`."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModalUQWarning)
        core = identify(y, u, fs=fs, settings=Settings(block_rows=P, orders=orders, n_blocks=N_BLOCKS))
    maps = record_maps(y, u, fs, orders)
    sp = draw_spreads(maps, y.shape[1], fs, orders, draws)
    out = {"k_star": maps["k_star"]}
    for n in orders:
        cm, f = core.at_order(n), maps[n]["f"]
        c = (np.argmin(np.abs(cm.frequency_hz[None, :] - f[:, None]), axis=1) if cm.n_modes
             else np.zeros(f.size, int))
        same = cm.n_modes > 0 and np.abs(cm.frequency_hz[c] - f) <= 1e-6 * f
        out[n] = {"f": f, "xi": maps[n]["xi"], "s_lin": sp[n]["lin"], "s_mad": np.moveaxis(sp[n]["mad"], 0, 1),
                  "s_cv": np.moveaxis(sp[n]["cv"], 0, 1), "corr": sp[n]["corr"],
                  "s_core": np.where(same[:, None], np.stack([cm.frequency_std[c], cm.damping_std[c]], axis=1)
                                     if cm.n_modes else np.nan, np.nan),
                  "flag": np.where(same, cm.noise_coupled[c] if cm.n_modes else False, False).astype(float)}
    return out


def run(n_records, structure="chain", seed=0, draws=DRAWS, progress=True, max_seconds=None):
    kw, orders = STRUCTURES[structure]
    C = len(DRAW_COUNTS)
    res = run_records(n_records, kw, orders, seed, progress, max_seconds,
                      lambda y, u, fs, orders: record_spreads(y, u, fs, orders, draws),
                      {"flag": (), "s_core": (2,), "s_lin": (2,), "s_mad": (C, 2), "s_cv": (C, 2), "corr": (2,)})
    res["flag"] = res["flag"] == 1
    res["counts"] = np.array(DRAW_COUNTS)
    res["structure"] = np.array(structure)
    return res


def estimators(res):
    """{name: σ array method × order × record × mode × 2}."""
    est = {"core": res["s_core"]}
    above = (res["orders"][None, :, None] > res["k_star"][:, None, :])[..., None, None]
    for c, B in enumerate(res["counts"]):
        est[f"mad{B} hybrid"] = np.where(above, res["s_mad"][..., c, :], res["s_core"])
        est[f"cv{B} hybrid"] = np.where(above, res["s_cv"][..., c, :], res["s_core"])
        est[f"cv{B} all"] = res["s_cv"][..., c, :]
    return est


def pooled(res, est):
    """{estimator: {order: [cells in both bands, cells, worst coverage, min RMS z, max RMS z]}},
    modes 2.., OO and IO, f and ξ."""
    orders = [int(n) for n in res["orders"]]
    M, O, R, nt = res["f"].shape
    out = {e: {n: [0, 0, 1.0, np.inf, -np.inf] for n in orders} for e in est}
    for v in (0, 1):
        for m in range(M):
            for o, n in enumerate(orders):
                for i in range(1, nt):
                    x = (res["f"] if v == 0 else res["xi"])[m, o, :, i].copy()
                    x[res["flag"][m, o, :, i]] = np.nan
                    for e, s in est.items():
                        med, cov, rz, _ = _stats(x, s[m, o, :, i, v])
                        if not np.isfinite(cov):
                            continue
                        p = out[e][n]
                        p[0] += int(COVERAGE_BAND[0] <= cov <= COVERAGE_BAND[1] and MEDIAN_BAND[0] <= med <= MEDIAN_BAND[1])
                        p[1] += 1
                        p[2] = min(p[2], cov)
                        p[3], p[4] = min(p[3], rz), max(p[4], rz)
    return out


def report(res):
    est = estimators(res)
    orders = [int(n) for n in res["orders"]]
    R = res["f"].shape[2]
    pool = pooled(res, est)
    lines = [f"{R} records ({res['structure']}); poles flagged noise-coupled by the core left out.", "",
             "Pooled, modes 2.., OO and IO, f and ξ: cells in the bands (coverage 0.93–0.97, median 0.85–1.18) "
             "/ cells; worst coverage; RMS z range", "",
             "| estimator | " + " | ".join(f"order {n}" for n in orders) + " |", "|---|" + "---|" * len(orders)]
    for e in est:
        lines.append(f"| {e} | " + " | ".join(
            f"{p[0]}/{p[1]}; cov ≥ {p[2]:.2f}; RMS z {p[3]:.2f}–{p[4]:.2f}" for p in (pool[e][n] for n in orders)) + " |")
    # the estimate's own noise: per-record σ of B draws against B = 100 (relative RMS), above k*
    lines += ["", "Per-record scatter of σ_B against σ_100 (RMS of σ_B/σ_100 − 1), above the record's k*, "
              "modes 2.., f and ξ pooled", "", "| B | " + " | ".join(f"MAD, order {n} | CV, order {n}" for n in orders)
              + " |", "|---|" + "---|---|" * len(orders)]
    above = res["orders"][None, :, None] > res["k_star"][:, None, :]
    for c, B in enumerate(res["counts"]):
        cells = []
        for o in range(len(orders)):
            for key in ("s_mad", "s_cv"):
                r = res[key][:, o, :, 1:, c, :] / res[key][:, o, :, 1:, -1, :] - 1
                r = r[np.broadcast_to(above[:, o, :, None, None], r.shape) & np.isfinite(r)]
                cells.append(f"{np.sqrt(np.mean(r ** 2)):.3f}" if r.size else "-")
        lines.append(f"| {B} | " + " | ".join(cells) + " |")
    # why: the followed moves against their first-order part, per mode (median over records)
    lines += ["", "Correlation of a draw's move δ with its first-order part ℓ = u·ε (median over records; "
              "f | ξ), poles not flagged", "", "| method | order | " + " | ".join(
                  f"mode {i + 1}" for i in range(res["corr"].shape[3])) + " |",
              "|---|---|" + "---|" * res["corr"].shape[3]]
    for m, meth in enumerate(METHODS):
        for o, n in enumerate(orders):
            cells = []
            for i in range(res["corr"].shape[3]):
                c = res["corr"][m, o, :, i].copy()
                c[res["flag"][m, o, :, i]] = np.nan
                cells.append(" | ".join(f"{np.nanmedian(c[:, v]):.2f}" if np.isfinite(c[:, v]).any() else "-"
                                        for v in (0, 1)).replace(" | ", "/"))
            lines.append(f"| {meth} | {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(n_records=100, structure="chain", seed=0, draws=DRAWS, out=None, max_seconds=None, progress=True):
    return finish(run(n_records, structure, seed=seed, draws=draws, progress=progress, max_seconds=max_seconds),
                  out, report)


if __name__ == "__main__":
    ap = study_parser(__doc__)
    ap.add_argument("--structure", choices=sorted(STRUCTURES), default="chain")
    ap.add_argument("--draws", type=int, default=DRAWS)
    ap.add_argument("--max-seconds", type=float, help="stop after the record that crosses this wall time")
    args = ap.parse_args()
    if args.report:
        reprint(args.report, report)
    else:
        main(args.records, args.structure, args.seed, args.draws, args.out, args.max_seconds)
