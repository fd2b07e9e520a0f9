"""Issue 27, (g): a candidate above the true order, the parametric bootstrap of the covariances.

(e) found that above the true order the first-order map is the problem, not the covariance of H:
frozen noise directions (the core) give σ too small, unfrozen ones too large, and (f) found no
constant blend. Both are linearisations at the estimate, and the noise singular directions are
not small perturbations: which noise directions enter the model is decided by the noise itself.
The candidate does not linearise. Per record, with the record's own block factor T_R of the
covariances r = [vec R1; (vec R2; vec R3; vec R4)] (what the core has), draw

    r_b = r + s · T_R ε_b,   ε_b ~ N(0, I_{n_blocks}),   b = 1..B,

build H_b = H(r_b) exactly (input/output: R1 − R2 R3⁺ R4ᵀ, no linearisation either), take its
SVD, and identify every order asked from it. Each of the record's poles is followed to the
nearest pole of the same order in each draw (|Δf|/f + |Δξ|, accepted within 5 % in f); its σ is
the spread over the draws divided by s: the std (σ_boot) and 1.4826·MAD (σ_mad). s = 1 perturbs
at the scale of the estimation error itself (the draws' noise directions are as random as the
records'); s → 0 tends to the plain (unfrozen) first-order map.

Records as ``modaluq validate`` simulates them (N = 10,000, p = q = 15, n_blocks = 50), output-only
(OO) and input/output (IO); the record's poles are the NumPy reference's (equal to the core's),
matched to the true modes with ``match_modes`` (±5 %); σ_core is the core's (``modaluq.identify``),
and poles it flags noise-coupled are left out of every statistic. Per estimator × method × order
× mode: median σ/σ_MC, coverage of ±1.96 σ around the Monte Carlo mean, RMS z; and per estimator
× order a pooled line (cells in the bands: coverage 0.93–0.97 and median 0.85–1.18).

usage: OPENBLAS_NUM_THREADS=1 python studies/bootstrap_sigma_mc.py --records 200 --out bs.npz
       OPENBLAS_NUM_THREADS=1 python studies/bootstrap_sigma_mc.py --structure frame --records 200
       python studies/bootstrap_sigma_mc.py --report bs.npz
"""
from __future__ import annotations

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

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "python"))
# record_maps: the smoke test's reference (the plain first-order map of a record)
from above_order_diagnosis import _stats, finish, record_done, record_maps, reprint, study_parser  # noqa: E402,F401

import oracle  # noqa: E402

N_SAMPLES = 10_000
P = 15
N_BLOCKS = 50
METHODS = ("OO", "IO")
LIMIT = 20.0                       # noise_coupling_limit (the core's default)
DRAWS = 100
SCALES = (1.0, 0.5)
STRUCTURES = {"chain": (dict(), (12, 24, 36)),
              "frame": (dict(n_dof=4, input_dofs=(0, 3)), (8, 16, 24)),
              "light": (dict(damping_ratio=0.003), (12, 24, 36)),           # every mode 0.3 % damped
              "known": (dict(unknown_input_std=0.0), (12, 24, 36))}         # the measured input only
COVERAGE_BAND = (0.93, 0.97)
MEDIAN_BAND = (0.85, 1.18)


def bootstrap(y, u, fs, orders, draws=DRAWS, scales=SCALES, seed=0, n_blocks=N_BLOCKS):
    """The record's poles per order and their bootstrap σ: {order: dict(f, xi, boot, mad)} with
    boot/mad (n_scales × n_modes × 2)."""
    cov = oracle.covariances(y, u, P, P, n_blocks)
    R = [cov[k] for k in ("R1", "R2", "R3", "R4")]
    H = oracle.subspace_matrix(*R)
    a, b = H.shape
    pm = 0 if u is None else R[2].shape[0]
    r = oracle._stack_r(cov)
    l = y.shape[1]
    ref = oracle.poles_at_orders(H, l, fs, orders)
    rng = np.random.default_rng(seed)
    eps = rng.standard_normal((cov["T_R"].shape[1], draws))
    out = {}
    samples = {n: np.full((len(scales), draws, ref[n][0].size, 2), np.nan) for n in orders}
    for c, sc in enumerate(scales):
        dr = sc * (cov["T_R"] @ eps)
        for t in range(draws):
            Hb = oracle.subspace_matrix(*oracle._unstack_r(r + dr[:, t], a, b, pm))
            pb = oracle.poles_at_orders(Hb, l, fs, orders)
            for n in orders:
                samples[n][c, t, :, 0], samples[n][c, t, :, 1] = oracle.follow_poles(*ref[n], *pb[n])
    for n in orders:
        smp = samples[n]
        found = np.mean(np.isfinite(smp[..., 0]), axis=1)                      # scales × modes
        sc = np.asarray(scales)[:, None, None]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            boot = np.nanstd(smp, axis=1, ddof=1) / sc
            med = np.nanmedian(smp, axis=1)
            mad = 1.4826 * np.nanmedian(np.abs(smp - med[:, None]), axis=1) / sc
        bad = (found < 0.8)[..., None]
        out[n] = {"f": ref[n][0], "xi": ref[n][1], "boot": np.where(bad, np.nan, boot),
                  "mad": np.where(bad, np.nan, mad), "found": found}
    return out


def run(n_records, structure="chain", seed=0, draws=DRAWS, progress=True, max_seconds=None, n_blocks=N_BLOCKS):
    """Arrays method × order × record × mode [× scale] [× 2]; with ``max_seconds`` cut to the
    records done when it is crossed."""
    kw, orders = STRUCTURES[structure]
    truth = simulate(N_SAMPLES, seed=record_seed(seed, 0), **kw)
    nt, S = truth.frequency_hz.size, len(SCALES)
    M, O, R = len(METHODS), len(orders), n_records
    settings = Settings(block_rows=P, orders=orders, n_blocks=n_blocks)
    res = {"f": np.full((M, O, R, nt), np.nan), "xi": np.full((M, O, R, nt), np.nan),
           "flag": np.zeros((M, O, R, nt), bool), "found": np.full((M, O, R, nt, S), np.nan),
           "s_core": np.full((M, O, R, nt, 2), np.nan), "s_boot": np.full((M, O, R, nt, S, 2), np.nan),
           "s_mad": np.full((M, O, R, nt, S, 2), np.nan), "k_star": np.zeros((M, R), int)}
    t0 = time.perf_counter()
    done = 0
    for k in range(R):
        sim = simulate(N_SAMPLES, seed=record_seed(seed, k), **kw)
        for m, u in enumerate((None, sim.u)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ModalUQWarning)
                core = identify(sim.y, u, fs=sim.fs, settings=settings)
            bs = bootstrap(sim.y, u, sim.fs, orders, draws=draws, seed=k, n_blocks=n_blocks)
            res["k_star"][m, k] = core.significant_singular_values
            for o, n in enumerate(orders):
                md, cm = bs[n], core.at_order(n)
                idx = match_modes(md["f"], truth.frequency_hz)
                ic = match_modes(cm.frequency_hz, truth.frequency_hz)
                for i in np.flatnonzero((idx >= 0) & (ic >= 0)):
                    j, c = idx[i], ic[i]
                    res["f"][m, o, k, i], res["xi"][m, o, k, i] = md["f"][j], md["xi"][j]
                    res["s_core"][m, o, k, i] = cm.frequency_std[c], cm.damping_std[c]
                    res["flag"][m, o, k, i] = cm.noise_coupled[c]
                    res["s_boot"][m, o, k, i] = md["boot"][:, j]
                    res["s_mad"][m, o, k, i] = md["mad"][:, j]
                    res["found"][m, o, k, i] = md["found"][:, j]
        done = k + 1
        if record_done(k, R, t0, progress, max_seconds):
            break
    for key in ("f", "xi", "flag", "found", "s_core", "s_boot", "s_mad"):
        res[key] = res[key][:, :, :done]
    res["k_star"] = res["k_star"][:, :done]
    res["n_blocks"] = np.array(n_blocks)
    res["orders"], res["scales"] = np.array(orders), np.array(SCALES)
    res["structure"] = np.array(structure)
    res["true_f"], res["true_xi"] = truth.frequency_hz, truth.damping_ratio
    res["seconds"] = time.perf_counter() - t0
    return res


def estimators(res):
    """{name: σ array method × order × record × mode × 2}."""
    est = {"core": res["s_core"]}
    for c, sc in enumerate(res["scales"]):
        est[f"boot s={sc:g}"] = res["s_boot"][..., c, :]
        est[f"mad s={sc:g}"] = res["s_mad"][..., c, :]
    # the candidate: the core's σ up to the record's noise floor k*, the bootstrap's (MAD, s = 1) above
    above = res["orders"][None, :, None] > res["k_star"][:, None, :]               # method × order × record
    est["hybrid"] = np.where(above[..., None, None], res["s_mad"][..., 0, :], res["s_core"])
    return est


def report(res):
    est = estimators(res)
    orders = [int(n) for n in res["orders"]]
    M, O, R, nt = res["f"].shape
    lines = [f"{R} records ({res['structure']}, {int(res['n_blocks'])} blocks); poles flagged noise-coupled "
             "by the core left out.", ""]
    pooled = {e: {n: [0, 0, 1.0, np.inf, -np.inf] for n in orders} for e in est}
    for v, name in ((0, "f"), (1, "ξ")):
        lines.append(f"**{name}**: median σ/σ_MC · coverage of ±1.96 σ · RMS z")
        lines.append("")
        lines.append("| method | order | mode | n | " + " | ".join(est) + " |")
        lines.append("|---|---|---|---|" + "---|" * len(est))
        for m, meth in enumerate(METHODS):
            for o, n in enumerate(orders):
                for i in range(nt):
                    x = (res["f"] if v == 0 else res["xi"])[m, o, :, i].copy()
                    x[res["flag"][m, o, :, i]] = np.nan
                    cells, cnt = [], 0
                    for e, s in est.items():
                        med, cov, rz, cnt = _stats(x, s[m, o, :, i, v])
                        cells.append(f"{med:.2f} · {cov:.2f} · {rz:.2f}")
                        if i > 0 and np.isfinite(cov):
                            p = pooled[e][n]
                            p[0] += int(COVERAGE_BAND[0] <= cov <= COVERAGE_BAND[1]
                                        and MEDIAN_BAND[0] <= med <= MEDIAN_BAND[1])
                            p[1] += 1
                            p[2] = min(p[2], cov)
                            p[3], p[4] = min(p[3], rz), max(p[4], rz)
                    lines.append(f"| {meth} | {n} | {i + 1} | {cnt} | " + " | ".join(cells) + " |")
        lines.append("")
    lines.append("Pooled, modes 2.., OO and IO, f and ξ: cells in the bands / cells; worst coverage; RMS z range")
    lines.append("")
    lines.append("| estimator | " + " | ".join(f"order {n}" for n in orders) + " |")
    lines.append("|---|" + "---|" * len(orders))
    for e in est:
        lines.append(f"| {e} | " + " | ".join(
            f"{p[0]}/{p[1]}; cov ≥ {p[2]:.2f}; RMS z {p[3]:.2f}–{p[4]:.2f}" for p in (pooled[e][n] for n in orders)) + " |")
    return "\n".join(lines)


def main(n_records=100, structure="chain", seed=0, draws=DRAWS, out=None, max_seconds=None, progress=True,
         n_blocks=N_BLOCKS):
    return finish(run(n_records, structure, seed=seed, draws=draws, progress=progress, max_seconds=max_seconds,
                      n_blocks=n_blocks), out, report)


if __name__ == "__main__":
    ap = study_parser(__doc__)
    ap.add_argument("--structure", choices=sorted(STRUCTURES), default="chain")
    ap.add_argument("--draws", type=int, default=DRAWS)
    ap.add_argument("--n-blocks", type=int, default=N_BLOCKS)
    ap.add_argument("--max-seconds", type=float, help="stop after the record that crosses this wall time")
    args = ap.parse_args()
    if args.report:
        reprint(args.report, report)
    else:
        main(args.records, args.structure, args.seed, args.draws, args.out, args.max_seconds, n_blocks=args.n_blocks)
