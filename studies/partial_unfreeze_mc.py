"""Issue 27, (f): a candidate fix above the true order, partial unfreezing of the variance.

Above the true order the frozen first-order map (noise directions from k* held fixed, the core's)
gives σ too small and the unfrozen (plain) map too large (docs/validation.md, Issue 27 (e)). The
candidate, per pole and per parameter (f and ξ), with each record's OWN block factor T_H (what
the core has):

    σ_κ² = σ_frozen² + κ (σ_plain² − σ_frozen²),   κ ∈ {0, 0.05, 0.1, 0.2, 0.3, 0.5, 1}

(κ = 0 is the core, κ = 1 the plain map). At orders ≤ k* the two maps coincide, so σ_κ = σ_frozen.

Records as ``modaluq validate`` simulates them (N = 10,000, p = q = 15, n_blocks = 50, record k =
``modaluq.simulate(N, seed=record_seed(seed, k), **structure)``), each identified output-only (OO)
and input/output (IO) with the NumPy reference (tests/python/oracle.py, the maps of
studies/above_order_diagnosis.py), poles matched to the true modes with ``match_modes`` (±5 %);
poles with ρ = max(σ_plain/σ_frozen over f, ξ) > 20 (those the core flags noise-coupled) are left
out. Per κ × method × order × mode: median σ_κ/σ_MC, coverage of ±1.96 σ_κ around the Monte Carlo
mean, RMS z; and per κ × order a pooled line over the modes 2.. (cells in the bands: coverage
0.93–0.97 and median 0.85–1.18).

Structures: ``chain`` (the paper's 6-DOF chain, true order 12; orders 12, 24, 36) and ``frame``
(``n_dof=4, input_dofs=(0, 3)``, true order 8; orders 8, 16).

usage: OPENBLAS_NUM_THREADS=1 python studies/partial_unfreeze_mc.py --records 300 --out pu.npz
       OPENBLAS_NUM_THREADS=1 python studies/partial_unfreeze_mc.py --structure frame --records 300
       python studies/partial_unfreeze_mc.py --report pu.npz
"""
from __future__ import annotations

import pathlib
import sys
import time

import numpy as np

from modaluq.simulate import simulate
from modaluq.validation.montecarlo import match_modes, record_seed

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
# the oracle's maps of each record, with its p = q = 15 and 50 blocks (studies/above_order_diagnosis.py)
from above_order_diagnosis import _stats, finish, record_done, record_maps, reprint, study_parser  # noqa: E402

N_SAMPLES = 10_000
METHODS = ("OO", "IO")
LIMIT = 20.0                     # noise_coupling_limit (the core's default)
KAPPAS = (0.0, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0)
STRUCTURES = {"chain": (dict(), (12, 24, 36)),
              "frame": (dict(n_dof=4, input_dofs=(0, 3)), (8, 16))}
COVERAGE_BAND = (0.93, 0.97)
MEDIAN_BAND = (0.85, 1.18)


def record_sigmas(y, u, fs, orders):
    """k* and per order the oracle's f, ξ and σ of the frozen and the plain map, both with the
    record's own block factor T_H: σ arrays n_modes × 2 (f, ξ)."""
    rec = record_maps(y, u, fs, orders)
    out = {"k_star": rec["k_star"]}
    for n in orders:
        md = rec[n]
        out[n] = {"f": md["f"], "xi": md["xi"], "s_frozen": np.linalg.norm(md["frozen"] @ rec["T_H"], axis=-1),
                  "s_plain": np.linalg.norm(md["plain"] @ rec["T_H"], axis=-1)}
    return out


def run_records(n_records, kw, orders, seed, progress, max_seconds, record_fn, fields):
    """The Monte Carlo loop of these studies: record k = ``simulate(N_SAMPLES, seed=record_seed(seed,
    k), **kw)``, identified output-only and input/output by ``record_fn(y, u, fs, orders)`` (a dict
    with "k_star" and per order "f", "xi" and each field); the poles matched to the true modes.
    Returns arrays method × order × record × mode [× the field's shape], cut to the records done
    (``max_seconds``: stop after the record that crosses it), and "k_star", "true_f", "true_xi",
    "orders", "seconds"."""
    truth = simulate(N_SAMPLES, seed=record_seed(seed, 0), **kw)
    nt = truth.frequency_hz.size
    M, O, R = len(METHODS), len(orders), n_records
    res = {key: np.full((M, O, R, nt) + tuple(shape), np.nan) for key, shape in {"f": (), "xi": (), **fields}.items()}
    res["k_star"] = np.zeros((M, R), int)
    t0 = time.perf_counter()
    done = 0
    for k in range(R):
        sim = simulate(N_SAMPLES, seed=record_seed(seed, k), **kw)
        for m, u in enumerate((None, sim.u)):
            rec = record_fn(sim.y, u, sim.fs, orders)
            res["k_star"][m, k] = rec["k_star"]
            for o, n in enumerate(orders):
                md = rec[n]
                idx = match_modes(md["f"], truth.frequency_hz)
                for i in np.flatnonzero(idx >= 0):
                    for key in ("f", "xi", *fields):
                        res[key][m, o, k, i] = md[key][idx[i]]
        done = k + 1
        if record_done(k, R, t0, progress, max_seconds):
            break
    for key in ("f", "xi", *fields):
        res[key] = res[key][:, :, :done]
    res["k_star"] = res["k_star"][:, :done]
    res["orders"] = np.array(orders)
    res["true_f"], res["true_xi"] = truth.frequency_hz, truth.damping_ratio
    res["seconds"] = time.perf_counter() - t0
    return res


def run(n_records, structure="chain", seed=0, progress=True, max_seconds=None):
    """Simulate and identify; arrays method × order × record × mode [× 2]. With ``max_seconds``,
    stops after the record that crosses it (the arrays are cut to the records done)."""
    kw, orders = STRUCTURES[structure]
    res = run_records(n_records, kw, orders, seed, progress, max_seconds, record_sigmas,
                      {"s_frozen": (2,), "s_plain": (2,)})
    with np.errstate(divide="ignore", invalid="ignore"):
        res["rho"] = np.maximum(1.0, np.max(res["s_plain"] / res["s_frozen"], axis=-1))
    res["kappas"] = np.array(KAPPAS)
    res["structure"] = np.array(structure)
    return res


def sigma_kappa(s_frozen, s_plain, kappa):
    """σ_κ = sqrt(σ_frozen² + κ (σ_plain² − σ_frozen²))."""
    return np.sqrt(s_frozen ** 2 + kappa * (s_plain ** 2 - s_frozen ** 2))


def table(res):
    """stats[κ, method, order, mode, var] = (median, coverage, RMS z, n)."""
    return variant_stats(res, [sigma_kappa(res["s_frozen"], res["s_plain"], kap) for kap in res["kappas"]])


def variant_stats(res, sigmas):
    """stats[variant, method, order, mode, var] = (median σ/σ_MC, coverage, RMS z, n) of f and ξ,
    ``sigmas`` one (method × order × record × mode × 2) array of σ per variant; poles with
    ρ > LIMIT left out."""
    M, O, _, nt = res["f"].shape
    st = np.full((len(sigmas), M, O, nt, 2, 4), np.nan)
    for c, sig in enumerate(sigmas):
        for m in range(M):
            for o in range(O):
                for i in range(nt):
                    keep = res["rho"][m, o, :, i] <= LIMIT
                    for v, key in enumerate(("f", "xi")):
                        x = np.where(keep, res[key][m, o, :, i], np.nan)
                        st[c, m, o, i, v] = _stats(x, sig[m, o, :, i, v])
    return st


def _in_band(med, cov):
    return ((COVERAGE_BAND[0] <= cov) & (cov <= COVERAGE_BAND[1])
            & (MEDIAN_BAND[0] <= med) & (med <= MEDIAN_BAND[1]))


def report(res):
    orders, kappas = [int(n) for n in res["orders"]], res["kappas"]
    M, O, R, nt = res["f"].shape
    st = table(res)
    lines = [f"structure {res['structure']}, {R} records; poles with ρ > {LIMIT:g} left out (counts in 'n').", ""]
    # check: at orders ≤ k* the maps coincide
    for o, n in enumerate(orders):
        below = res["k_star"][:, None, :, None] >= n                              # M × 1 × R × 1
        a, b = res["s_frozen"][:, o], res["s_plain"][:, o]
        ok = np.isfinite(a[..., 0]) & below[:, 0]
        if ok.any():
            d = np.abs(b[ok] / a[ok] - 1).max()
            lines.append(f"order {n}: {int(ok.sum())} poles of records with k* ≥ {n}: max |σ_plain/σ_frozen − 1| = {d:.1e}")
    ks = {meth: np.bincount(res["k_star"][m]) for m, meth in enumerate(METHODS)}
    lines.append("k* over records: " + "; ".join(
        f"{meth}: " + ", ".join(f"{v}×{c}" for v, c in enumerate(b) if c) for meth, b in ks.items()))
    lines.append("")
    lines += per_mode_tables(st, [f"κ={k:g}" for k in kappas], orders, nt, symbol="σ_κ")
    lines += pooled_table(st, [f"{k:g}" for k in kappas], orders, nt, "κ")
    return "\n".join(lines)


def per_mode_tables(st, heads, orders, nt, symbol="σ") -> list:
    """The tables of f and ξ, a row per method × order × mode and a column per variant of ``st``
    (stats[variant, method, order, mode, var] = (median, coverage, RMS z, n))."""
    lines = []
    for v, name in ((0, "f"), (1, "ξ")):
        lines.append(f"**{name}**: median {symbol}/σ_MC · coverage of ±1.96 {symbol} · RMS z")
        lines.append("")
        lines.append(f"| method | order | mode | n | {' | '.join(heads)} |")
        lines.append("|---|---|---|---|" + "---|" * len(heads))
        for m, meth in enumerate(METHODS):
            for o, n in enumerate(orders):
                for i in range(nt):
                    cells = [f"{st[c, m, o, i, v, 0]:.2f} · {st[c, m, o, i, v, 1]:.2f} · {st[c, m, o, i, v, 2]:.2f}"
                             for c in range(len(heads))]
                    lines.append(f"| {meth} | {n} | {i + 1} | {int(st[0, m, o, i, v, 3])} | " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def pooled_table(st, labels, orders, nt, label_head, with_median=False) -> list:
    """A row per variant of ``st``, pooled over modes 2.., OO and IO, f and ξ: cells in both bands /
    cells, the worst coverage, the range of RMS z (and of the median σ/σ_MC)."""
    lines = [f"Pooled, modes 2–{nt}, OO and IO, f and ξ: cells in the bands (coverage "
             f"{COVERAGE_BAND[0]:.2f}–{COVERAGE_BAND[1]:.2f} and median {MEDIAN_BAND[0]:.2f}–{MEDIAN_BAND[1]:.2f}) "
             "/ cells; worst coverage; range of RMS z" + ("; range of the median σ/σ_MC" if with_median else ""), ""]
    lines.append(f"| {label_head} | " + " | ".join(f"order {n}" for n in orders) + " |")
    lines.append("|---|" + "---|" * len(orders))
    for c, label in enumerate(labels):
        cells = []
        for o in range(len(orders)):
            s = st[c, :, o, 1:, :, :]                                                # M × modes × 2 × 4
            med, cov, rz = s[..., 0].ravel(), s[..., 1].ravel(), s[..., 2].ravel()
            ok = np.isfinite(med)
            inb = int(_in_band(med[ok], cov[ok]).sum())
            cell = f"{inb}/{int(ok.sum())}; cov ≥ {np.nanmin(cov):.2f}; RMS z {np.nanmin(rz):.2f}–{np.nanmax(rz):.2f}"
            cells.append(cell + (f"; median {np.nanmin(med):.2f}–{np.nanmax(med):.2f}" if with_median else ""))
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    return lines


def main(n_records=100, structure="chain", seed=0, out=None, progress=True, max_seconds=None):
    return finish(run(n_records, structure=structure, seed=seed, progress=progress, max_seconds=max_seconds),
                  out, report)


if __name__ == "__main__":
    ap = study_parser(__doc__)
    ap.add_argument("--structure", choices=sorted(STRUCTURES), default="chain")
    ap.add_argument("--max-seconds", type=float, help="stop after the record that crosses this wall time")
    args = ap.parse_args()
    if args.report:
        reprint(args.report, report)
    else:
        main(args.records, args.structure, args.seed, args.out, max_seconds=args.max_seconds)
