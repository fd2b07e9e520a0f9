"""Issue 27, item 1 ("diagnosis first"): above the true model order, is the low σ of the physical
modes' f and ξ due to (i) the block estimate of the covariance of H, or (ii) the first-order map J
with the noise singular directions frozen from k* (docs/uq-math.md §3, §5.5)?

Records as ``modaluq validate`` simulates them (the paper's chain, N = 10,000, p = q = 15,
n_blocks = 50, record k = ``modaluq.simulate(N, seed=record_seed(seed, k))``), each identified
output-only (OO) and input/output (IO) at orders 12 (control) and 24, poles matched to the true
modes with ``match_modes`` (±5 %). Per record, per method, with the NumPy reference
(tests/python/oracle.py: the record's H, its block factor T_H = J_{H,R} T_R, its noise floor k*,
the explicit Jacobians) the rows j_f, j_ξ (1 × h) of the first-order map from vec H to f and ξ of
each matched pole, both frozen from the record's own k* (the core's map) and plain (unfrozen):

  (a) σ_core   the core's σ (``modaluq.identify``); checked equal to ‖j T_H‖ with the record's
               block factor and the core's choice frozen/plain (ρ ≤ 20), to ~1e-8 relative;
  (b) σ_trueH  ‖j T_true‖, T_true = [vec H_r − mean]/√(R−1) over all R records of the run (the
               Monte Carlo covariance of H, the same method's H);
  (c) σ_plain  the unfrozen map on the true covariance, ‖j_plain T_true‖;
  (a') σ_blkpl the unfrozen map on the record's block factor (for reference).

Poles the core flags noise-coupled (ρ > 20) are left out of every statistic, as in the
"Above the true order" tables. Per method × order × mode: median σ/σ_MC, coverage of ±1.96 σ around
the Monte Carlo mean, RMS z; at order 24, RMS z of (a) and (b) by terciles of the record's ρ
(noise_coupling), the distance (relative) of the pole to the nearest unmatched pole, and k*.

usage: OPENBLAS_NUM_THREADS=1 python studies/above_order_diagnosis.py --records 200 --out diag.npz
       python studies/above_order_diagnosis.py --report diag.npz
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time
import warnings

import numpy as np

from modaluq.identification import identify
from modaluq.results import ModalUQWarning
from modaluq.settings import Settings
from modaluq.simulate import simulate
from modaluq.validation.montecarlo import match_modes, record_seed

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "python"))
import oracle  # noqa: E402

N_SAMPLES = 10_000
P = 15
N_BLOCKS = 50
ORDERS = (12, 24)
METHODS = ("OO", "IO")
LIMIT = 20.0                     # noise_coupling_limit (the core's default)
ESTIMATORS = ("core", "blk", "trueH", "plain", "blkplain")
LABELS = {"core": "(a) σ_core", "blk": "oracle σ, block T_H", "trueH": "(b) σ_trueH",
          "plain": "(c) σ_plain (true Σ_H)", "blkplain": "σ plain, block T_H"}


def _perm(a, b):
    """Column permutation π with M @ P_{a,b} = M[:, π] (P_{a,b} vec X = vec Xᵀ, X a × b)."""
    # column i + j a of P_{a,b} is e_{j + i b} (X[i, j] is entry i + j a of vec X, j + i b of vec Xᵀ)
    return np.arange(a * b).reshape(a, b).reshape(-1, order="F")


def jacobian_gamma_h(H, n, frozen_from=None):
    """oracle.jacobian_Gamma_H with the commutation product done as a column permutation."""
    a, b = H.shape
    U, s, Vt = oracle.svd_sorted(H)
    Ia, Ib = np.eye(a), np.eye(b)
    perm = _perm(a, b)
    J = np.empty((a * n, a * b))
    for j in range(n):
        sj, uj, vj = s[j], U[:, j], Vt[j, :]
        J[j * a:(j + 1) * a] = np.outer(uj, np.kron(vj, uj)) / (2.0 * np.sqrt(sj))
        if frozen_from is None or j < frozen_from:
            Bj = np.block([[Ia, -H / sj], [-H.T / sj, Ib]])
            Cj = np.vstack([np.kron(vj[None, :], Ia - np.outer(uj, uj)),
                            np.kron(uj[None, :], Ib - np.outer(vj, vj))[:, perm]]) / sj
            J[j * a:(j + 1) * a] += np.sqrt(sj) * (oracle._pinv_drop_one(Bj) @ Cj)[:a]
    return J


def record_realizations(y, u, fs, orders):
    """The oracle's identification of one record: H, T_H, k*, the SVD of H and per order the
    frequencies, damping ratios and the (f, ξ) rows of J_{θ,Γ} (2 nm × a n, "rows")."""
    cov = oracle.covariances(y, u, P, P, N_BLOCKS)
    R = [cov[k] for k in ("R1", "R2", "R3", "R4")]
    H = oracle.subspace_matrix(*R)
    T_H = oracle.jacobian_H_R(*R) @ cov["T_R"]
    l = y.shape[1]
    k_star, _ = oracle.noise_floor(H, T_H, max(orders) + 1)
    svd = oracle.svd_sorted(H)
    U, s, _ = svd
    out = {"H": H, "T_H": T_H, "k_star": k_star, "svd": svd}
    for n in orders:
        G = U[:, :n] * np.sqrt(s[:n])
        A, C = oracle.system_matrices(G, l)
        md = oracle.modes(A, C, fs)
        J_AC = oracle.jacobian_AC_Gamma(G, l)
        J_th = oracle.jacobian_theta_AC(A, C, fs, ref_index=md["ref_index"])
        out[n] = {"f": md["frequency_hz"], "xi": md["damping_ratio"],
                  "rows": np.vstack([J[:2] for J in J_th]) @ J_AC, "nm": len(J_th), "a_n": G.size}
    return out


def record_maps(y, u, fs, orders=ORDERS):
    """H (vec), T_H, k* and per order: the oracle's frequencies and the (f, ξ) rows of the frozen
    and the plain map (n_modes × 2 × h) of one record and method."""
    rec = record_realizations(y, u, fs, orders)
    H, k_star = rec["H"], rec["k_star"]
    n_max = max(orders)
    J_plain = jacobian_gamma_h(H, n_max)
    J_frozen = jacobian_gamma_h(H, n_max, frozen_from=k_star) if k_star < n_max else J_plain
    out = {"H": oracle.vec(H), "T_H": rec["T_H"], "k_star": k_star}
    for n in orders:
        md = rec[n]
        rows, a_n, nm = md["rows"], md["a_n"], md["nm"]
        plain = (rows @ J_plain[:a_n]).reshape(nm, 2, -1)
        frozen = (rows @ J_frozen[:a_n]).reshape(nm, 2, -1) if n > k_star else plain
        out[n] = {"f": md["f"], "xi": md["xi"], "frozen": frozen, "plain": plain}
    return out


def run(n_records, seed=0, progress=True):
    """Simulate and identify; returns the arrays (method × order × record × mode [× 2 × h])."""
    settings = Settings(block_rows=P, orders=ORDERS, n_blocks=N_BLOCKS)
    R, M, O = n_records, len(METHODS), len(ORDERS)
    truth = simulate(N_SAMPLES, seed=record_seed(seed, 0))
    nt = truth.frequency_hz.size
    h = None
    nan = np.full((M, O, R, nt), np.nan)
    res = {k: nan.copy() for k in ("f", "xi", "f_core", "xi_core", "sf_core", "sx_core", "rho", "dist")}
    res["k_star"] = np.zeros((M, R), int)
    res["flag"] = np.zeros((M, O, R, nt), bool)
    maps = Hs = blk = None
    t0 = time.perf_counter()
    for k in range(R):
        sim = simulate(N_SAMPLES, seed=record_seed(seed, k))
        for m, u in enumerate((None, sim.u)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ModalUQWarning)
                core = identify(sim.y, u, fs=sim.fs, settings=settings)
            rec = record_maps(sim.y, u, sim.fs)
            if maps is None:
                h = rec["H"].size
                maps = np.full((M, O, R, nt, 2, 2, h), np.nan)      # [..., frozen|plain, f|ξ, h]
                Hs = np.zeros((M, R, h))
                blk = np.full((M, O, R, nt, 2, 2), np.nan)                 # [..., frozen|plain, f|ξ]
            Hs[m, k], res["k_star"][m, k] = rec["H"], rec["k_star"]
            for o, n in enumerate(ORDERS):
                md, cm = rec[n], core.at_order(n)
                idx = match_modes(md["f"], truth.frequency_hz)
                ic = match_modes(cm.frequency_hz, truth.frequency_hz)
                for i in np.flatnonzero(idx >= 0):
                    j = idx[i]
                    res["f"][m, o, k, i], res["xi"][m, o, k, i] = md["f"][j], md["xi"][j]
                    maps[m, o, k, i, 0], maps[m, o, k, i, 1] = md["frozen"][j], md["plain"][j]
                    others = np.delete(md["f"], idx[idx >= 0])
                    if others.size:
                        res["dist"][m, o, k, i] = np.min(np.abs(others - md["f"][j])) / md["f"][j]
                    if ic[i] >= 0:
                        c = ic[i]
                        res["f_core"][m, o, k, i], res["xi_core"][m, o, k, i] = cm.frequency_hz[c], cm.damping_ratio[c]
                        res["sf_core"][m, o, k, i], res["sx_core"][m, o, k, i] = cm.frequency_std[c], cm.damping_std[c]
                        res["flag"][m, o, k, i] = cm.noise_coupled[c]
                blk[m, o, k] = np.linalg.norm(maps[m, o, k] @ rec["T_H"], axis=-1)
        if progress and (k == 0 or (k + 1) % 10 == 0):
            el = time.perf_counter() - t0
            print(f"record {k + 1}/{R}: {el:.0f} s ({el / (k + 1):.2f} s/record)", file=sys.stderr, flush=True)
    # σ of every estimator
    sig = {e: np.full((M, O, R, nt, 2), np.nan) for e in ESTIMATORS}
    for m in range(M):
        T_true = (Hs[m] - Hs[m].mean(axis=0)).T / np.sqrt(R - 1)                  # h × R
        for o in range(O):
            fr, pl = maps[m, o, :, :, 0], maps[m, o, :, :, 1]                       # R × nt × 2 × h
            blk_fr, blk_pl = blk[m, o, :, :, 0], blk[m, o, :, :, 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                rho = np.maximum(1.0, np.nanmax(blk_pl / blk_fr, axis=-1))
            use = (rho <= LIMIT)[..., None]
            res["rho"][m, o] = rho
            sig["blk"][m, o] = np.where(use, blk_fr, blk_pl)
            sig["blkplain"][m, o] = blk_pl
            tr_fr = np.linalg.norm(fr @ T_true, axis=-1)
            tr_pl = np.linalg.norm(pl @ T_true, axis=-1)
            sig["trueH"][m, o] = np.where(use, tr_fr, tr_pl)
            sig["plain"][m, o] = tr_pl
            sig["core"][m, o] = np.stack([res["sf_core"][m, o], res["sx_core"][m, o]], axis=-1)
    for e in ESTIMATORS:
        res["sig_" + e] = sig[e]
    res["H_mean"] = Hs.mean(axis=1)
    res["true_f"], res["true_xi"] = truth.frequency_hz, truth.damping_ratio
    res["seconds"] = time.perf_counter() - t0
    return res


def _stats(x, s):
    """median σ/σ_MC, coverage of ±1.96 σ, RMS z over the finite entries of x (records) and s."""
    ok = np.isfinite(x) & np.isfinite(s) & (s > 0)
    x, s = x[ok], s[ok]
    if x.size < 3:
        return np.nan, np.nan, np.nan, x.size
    sd = x.std(ddof=1)
    z = (x - x.mean()) / s
    return np.median(s) / sd, np.mean(np.abs(z) <= 1.96), np.sqrt(np.mean(z * z)), x.size


def report(res):
    nt = res["true_f"].size
    R = res["f"].shape[2]
    lines = [f"{R} records; poles flagged noise-coupled by the core left out (counts in 'n').", ""]
    # check: core = oracle with the record's block factor
    ok = np.isfinite(res["sig_core"]) & np.isfinite(res["sig_blk"]) & ~res["flag"][..., None]
    rel = np.abs(res["sig_core"][ok] / res["sig_blk"][ok] - 1)
    dfc = np.abs(res["f_core"] - res["f"])[np.isfinite(res["f_core"]) & np.isfinite(res["f"])]
    lines.append(f"check: max |σ_core / σ_oracle,block − 1| = {rel.max():.1e} over {rel.size} σ "
                 f"(median {np.median(rel):.1e}); max |f_core − f_oracle| = {dfc.max():.1e} Hz")
    lines.append("")
    for var, name in ((0, "f"), (1, "ξ")):
        lines.append(f"**{name}**: median σ/σ_MC · coverage of ±1.96 σ · RMS z")
        lines.append("")
        lines.append("| method | order | mode | n | (a) σ_core | (b) σ_trueH | (c) σ_plain, true Σ_H | plain, block T_H |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for m, meth in enumerate(METHODS):
            for o, n in enumerate(ORDERS):
                for i in range(nt):
                    x = (res["f"] if var == 0 else res["xi"])[m, o, :, i].copy()
                    x[res["flag"][m, o, :, i]] = np.nan
                    cells = []
                    for e in ("core", "trueH", "plain", "blkplain"):
                        med, cov, rz, cnt = _stats(x, res["sig_" + e][m, o, :, i, var])
                        cells.append(f"{med:.2f} · {cov:.2f} · {rz:.2f}")
                    lines.append(f"| {meth} | {n} | {i + 1} | {cnt} | " + " | ".join(cells) + " |")
        lines.append("")
    # order 24: by terciles of per-record covariates (modes pooled; z of f and ξ pooled)
    lines.append("Order 24, modes 2–6 pooled, f and ξ pooled: RMS z of (a) and (b) by tercile of a per-record "
                 "covariate (low / mid / high)")
    lines.append("")
    lines.append("| method | covariate | terciles (edges) | (a) RMS z | (b) RMS z |")
    lines.append("|---|---|---|---|---|")
    o = ORDERS.index(24)
    for m, meth in enumerate(METHODS):
        zs = {e: [] for e in ("core", "trueH")}
        cov = {"ρ (noise_coupling)": [], "distance to nearest other pole": [], "k*": []}
        for i in range(1, nt):
            for var, key in ((0, "f"), (1, "xi")):
                x = res[key][m, o, :, i].copy()
                x[res["flag"][m, o, :, i]] = np.nan
                ok = np.isfinite(x)
                mu = np.nanmean(x)
                for e in zs:
                    z = (x - mu) / res["sig_" + e][m, o, :, i, var]
                    zs[e].append(np.where(ok, z, np.nan))
                cov["ρ (noise_coupling)"].append(res["rho"][m, o, :, i])
                cov["distance to nearest other pole"].append(res["dist"][m, o, :, i])
                cov["k*"].append(res["k_star"][m].astype(float))
        for name, c in cov.items():
            c = np.concatenate(c)
            za, zb = np.concatenate(zs["core"]), np.concatenate(zs["trueH"])
            ok = np.isfinite(c) & np.isfinite(za) & np.isfinite(zb)
            if ok.sum() < 9:
                continue
            edges = np.quantile(c[ok], [1 / 3, 2 / 3])
            if name == "k*":
                vals = np.unique(c[ok])
                groups = [c == v for v in vals]
                lab = ", ".join(f"k*={int(v)}: {int((ok & g).sum())}" for v, g in zip(vals, groups))
            else:
                groups = [c <= edges[0], (c > edges[0]) & (c <= edges[1]), c > edges[1]]
                lab = f"{edges[0]:.3g}, {edges[1]:.3g}"
            ra = " / ".join(f"{np.sqrt(np.mean(za[ok & g] ** 2)):.2f}" for g in groups)
            rb = " / ".join(f"{np.sqrt(np.mean(zb[ok & g] ** 2)):.2f}" for g in groups)
            lines.append(f"| {meth} | {name} | {lab} | {ra} | {rb} |")
    lines.append("")
    ks = {meth: np.bincount(res["k_star"][m]) for m, meth in enumerate(METHODS)}
    lines.append("k* over records: " + "; ".join(
        f"{meth}: " + ", ".join(f"{v}×{c}" for v, c in enumerate(b) if c) for meth, b in ks.items()))
    return "\n".join(lines)


def record_done(k, n_records, t0, progress=True, max_seconds=None):
    """After record k (0-based) of a run started at ``t0`` (perf_counter): prints the progress
    every 10 records when asked; True when the run should stop (``max_seconds`` crossed)."""
    done, el = k + 1, time.perf_counter() - t0
    if progress and (k == 0 or done % 10 == 0):
        print(f"record {done}/{n_records}: {el:.0f} s ({el / done:.2f} s/record)", file=sys.stderr, flush=True)
    return max_seconds is not None and el > max_seconds


def study_parser(doc):
    """The options every Monte Carlo study here has: --records, --seed, --out, --report."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--records", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=pathlib.Path)
    ap.add_argument("--report", type=pathlib.Path, help="reprint the tables of a saved run")
    return ap


def finish(res, out, report):
    """A study's run done: saved to ``out`` (npz) when given, its tables printed; returns it."""
    if out is not None:
        np.savez_compressed(out, **res)
    print(report(res))
    return res


def reprint(path, report):
    """The tables of a run saved by :func:`finish` again."""
    with np.load(path) as z:
        print(report({k: z[k] for k in z.files}))


def main(n_records=100, seed=0, out=None, progress=True):
    return finish(run(n_records, seed=seed, progress=progress), out, report)


if __name__ == "__main__":
    args = study_parser(__doc__).parse_args()
    if args.report:
        reprint(args.report, report)
    else:
        main(args.records, args.seed, args.out)
