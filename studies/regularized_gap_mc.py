"""Issue 27, a candidate above the true order: a regularised gap (a soft freeze) in the SVD-basis solve.

Above the noise floor k* the frozen first-order map (the core's, docs/uq-math.md eq. 5.13) gives σ
too small and the unfrozen one (eq. 5.5) too large; a constant blend of their variances fits
neither both 2× and 3× the true order (docs/validation.md, Issue 27 (e), (f)). The candidate
freezes nothing; every pair i ≠ j of the SVD-basis solve (uq-math §5.3) gets a saturating
denominator:

    Ω_ij = num_ij · sign(g_ij) / sqrt(g_ij² + c τ_ij²),   num_ij = s_j Ua_ij + s_i Ua_ji,
    g_ij = s_j² − s_i²,   τ_ij² = Σ_b (num^b_ij)²                    ("saturating", the candidate)

with Ua = Uᵀ dH V and τ_ij² the variance of num_ij under the record's own block factor T_H (block
b: dH^b = unvec(T_H[:, b]), Ua^b = Uᵀ dH^b V; Σ_H = T_H T_Hᵀ). Resolved gaps (|g| ≫ τ) keep the
exact first-order rotation; unresolved ones (two noise singular values) saturate at variance 1/c
(the exact 2 × 2 rotation ½ atan(2ε/g) tends to ±π/4: variance π²/16, c ≈ 1.6). The scale term
ds_j and, when a > b, the out-of-span part (I − UUᵀ) dH v_j / s_j stay as in eq. 5.6. The variant
``--form tikhonov`` uses the vanishing form Ω_ij = num_ij g_ij / (g_ij² + c τ_ij²) instead.

The map is built as an explicit J_{Γ,H} (a n × a b, column-major vec as the oracle's), and
σ of f and ξ per pole is ‖rows J[:a n] T_H‖ as in studies/above_order_diagnosis.record_maps. The
reference columns are the frozen map (κ = 0 of study (f), the core) and the plain one. Poles with
ρ = max(σ_plain/σ_frozen over f, ξ) > 20 (the ones the core flags) are left out, as there.

Records as ``modaluq validate`` simulates them (N = 10,000, p = q = 15, n_blocks = 50, record k =
``modaluq.simulate(N, seed=record_seed(seed, k), **structure)``), output-only (OO) and
input/output (IO); poles matched to the true modes with ``match_modes`` (±5 %). Statistics, pooled
lines and the bands as in studies/partial_unfreeze_mc.py.

Structures: ``chain`` (the paper's 6-DOF chain, true order 12; orders 12, 24, 36) and ``frame``
(``n_dof=4, input_dofs=(0, 3)``, true order 8; orders 8, 16, 24).

usage: OPENBLAS_NUM_THREADS=1 python studies/regularized_gap_mc.py --check [--structure frame]   # the checks
       OPENBLAS_NUM_THREADS=1 python studies/regularized_gap_mc.py --records 600 --max-seconds 1500 --out rg.npz
       OPENBLAS_NUM_THREADS=1 python studies/regularized_gap_mc.py --structure frame --records 600 --max-seconds 1500
       (--cs c ... sets the saturating c, --tik-cs c ... adds the Tikhonov variant)
       python studies/regularized_gap_mc.py --report rg.npz
"""
from __future__ import annotations

import pathlib
import sys
import warnings

import numpy as np

from modaluq.identification import identify
from modaluq.results import ModalUQWarning
from modaluq.settings import Settings
from modaluq.simulate import simulate
from modaluq.validation.montecarlo import match_modes, record_seed

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
# the oracle's maps, statistics and CLI (studies/above_order_diagnosis.py), the bands of study (f)
from above_order_diagnosis import (  # noqa: E402
    N_BLOCKS,
    P,
    _perm,
    finish,
    jacobian_gamma_h,
    oracle,
    record_realizations,
    reprint,
    study_parser,
)
from partial_unfreeze_mc import (  # noqa: E402
    LIMIT,
    METHODS,
    N_SAMPLES,
    per_mode_tables,
    pooled_table,
    run_records,
    variant_stats,
)

CS = (0.5, 1.0, 1.6, 3.0, 10.0)
FORMS = ("saturating", "tikhonov")
STRUCTURES = {"chain": (dict(), (12, 24, 36)),
              "frame": (dict(n_dof=4, input_dofs=(0, 3)), (8, 16, 24))}


def gap_weights(s, Ua_blocks, c, form="saturating"):
    """W (d × d), Ω_ij = W_ij num_ij, W_jj = 0: 1/g (c = 0), sign(g)/sqrt(g² + c τ²) (saturating)
    or g/(g² + c τ²) (tikhonov); τ² = Σ_b (num^b)², num^b = Ua^b s_j + Ua^bᵀ s_i (Ua_blocks n_b × d × d)."""
    g = s[None, :] ** 2 - s[:, None] ** 2                                   # g_ij = s_j² − s_i²
    num = Ua_blocks * s[None, None, :] + np.swapaxes(Ua_blocks, 1, 2) * s[None, :, None]
    tau2 = np.sum(num * num, axis=0)
    off = ~np.eye(s.size, dtype=bool)
    W = np.zeros_like(g)
    with np.errstate(divide="ignore", invalid="ignore"):
        if form == "saturating":
            W[off] = np.sign(g[off]) / np.sqrt(g[off] ** 2 + c * tau2[off])
        elif form == "tikhonov":
            W[off] = g[off] / (g[off] ** 2 + c * tau2[off])
        else:
            raise ValueError(f"unknown form {form!r}")
    W[~np.isfinite(W)] = 0.0
    return W


def block_projections(U, Vt, T_H):
    """Ua^b = Uᵀ dH^b V for every block b (n_b × d × d), dH^b = unvec(T_H[:, b]) (column-major)."""
    a, b = U.shape[0], Vt.shape[1]
    dH = T_H.T.reshape(-1, b, a).transpose(0, 2, 1)                       # n_b × a × b
    return np.einsum("ai,kab,jb->kij", U, dH, Vt, optimize=True)


def jacobian_gamma_h_reg(H, n, W, frozen_from=None, svd=None):
    """Explicit J_{Γ,H} (a n × a b) of eqs. 5.3, 5.6 with Ω_ij = W_ij (s_j Ua_ij + s_i Ua_ji):

        du_j = M_j dH v_j + N_j dHᵀ u_j + (I − UUᵀ) dH v_j / s_j,
        M_j = U diag(W_:j s_j) Uᵀ,  N_j = U diag(W_:j s) Vᵀ,

    i.e. rows (v_jᵀ ⊗ (M_j + (I − UUᵀ)/s_j)) + (u_jᵀ ⊗ N_j) P_{a,b}. W = 1/g gives the plain
    map (eq. 5.5); ``frozen_from`` = k* drops du_j for j ≥ k* (eq. 5.13)."""
    a, b = H.shape
    U, s, Vt = oracle.svd_sorted(H) if svd is None else svd
    perm = _perm(a, b)
    perp = np.eye(a) - U @ U.T
    J = np.empty((a * n, a * b))
    for j in range(n):
        sj, uj, vj = s[j], U[:, j], Vt[j, :]
        J[j * a:(j + 1) * a] = np.outer(uj, np.kron(vj, uj)) / (2.0 * np.sqrt(sj))
        if frozen_from is None or j < frozen_from:
            M = (U * (W[:, j] * sj)) @ U.T + perp / sj
            N = (U * (W[:, j] * s)) @ Vt
            J[j * a:(j + 1) * a] += np.sqrt(sj) * (np.kron(vj[None, :], M) + np.kron(uj[None, :], N)[:, perm])
    return J


def record_parts(y, u, fs, orders):
    """H, T_H, k*, the SVD, Ua^b and per order the oracle's f, ξ and the (f, ξ) rows (2 nm × a n)."""
    out = record_realizations(y, u, fs, orders)
    out["Ua"] = block_projections(out["svd"][0], out["svd"][2], out["T_H"])
    return out


def specs_of(cs=CS, tik_cs=()):
    """The regularised variants: (form, c) for each saturating c, then each Tikhonov c."""
    return [("saturating", float(c)) for c in cs] + [("tikhonov", float(c)) for c in tik_cs]


def variants(specs):
    """Column names: the frozen map (the core), each (form, c), the plain map."""
    return ["frozen"] + [("c" if form == "saturating" else "tik c") + f"={c:g}" for form, c in specs] + ["plain"]


def record_sigmas(y, u, fs, orders, specs):
    """k* and per order f, ξ and σ (n_modes × n_variants × 2) of every variant (frozen, each
    (form, c) of ``specs``, plain), all with the record's own block factor T_H."""
    rec = record_parts(y, u, fs, orders)
    H, T_H, k_star, svd = rec["H"], rec["T_H"], rec["k_star"], rec["svd"]
    n_max = max(orders)
    J_plain = jacobian_gamma_h(H, n_max)
    J_frozen = jacobian_gamma_h(H, n_max, frozen_from=k_star) if k_star < n_max else J_plain
    JT = [J_frozen @ T_H]
    for form, c in specs:
        W = gap_weights(svd[1], rec["Ua"], c, form)
        JT.append(jacobian_gamma_h_reg(H, n_max, W, svd=svd) @ T_H)
    JT.append(J_plain @ T_H)
    out = {"k_star": k_star}
    for n in orders:
        md = rec[n]
        an = H.shape[0] * n
        sig = np.stack([np.linalg.norm((md["rows"] @ jt[:an]).reshape(md["nm"], 2, -1), axis=-1) for jt in JT],
                       axis=1)                                                    # nm × variants × 2
        out[n] = {"f": md["f"], "xi": md["xi"], "sigma": sig}
    return out


def run(n_records, structure="chain", seed=0, progress=True, max_seconds=None, specs=None):
    """Simulate and identify; arrays method × order × record × mode [× variant × 2]. With
    ``max_seconds``, stops after the record that crosses it (the arrays are cut to the records done)."""
    specs = specs_of() if specs is None else specs
    kw, orders = STRUCTURES[structure]
    res = run_records(n_records, kw, orders, seed, progress, max_seconds,
                      lambda y, u, fs, orders: record_sigmas(y, u, fs, orders, specs), {"sigma": (len(specs) + 2, 2)})
    with np.errstate(divide="ignore", invalid="ignore"):
        res["rho"] = np.maximum(1.0, np.max(res["sigma"][..., -1, :] / res["sigma"][..., 0, :], axis=-1))
    res["cs"] = np.array([c for _, c in specs])
    res["forms"] = np.array([form for form, _ in specs])
    res["structure"] = np.array(structure)
    return res


def table(res):
    """stats[variant, method, order, mode, var] = (median, coverage, RMS z, n)."""
    return variant_stats(res, [res["sigma"][..., c, :] for c in range(res["sigma"].shape[-2])])


def true_order_change(res, names):
    """Lines: per variant, the change of σ at the first (true) order over the poles of the records
    with k* ≥ that order (where the frozen and the plain map coincide)."""
    n0 = int(res["orders"][0])
    sig = res["sigma"][:, 0]                                                      # M × R × nt × V × 2
    ok = (res["k_star"] >= n0)[:, :, None] & np.isfinite(sig[..., 0, 0])
    lines = [f"order {n0}, {int(ok.sum())} poles of records with k* ≥ {n0}: |σ/σ_frozen − 1| max, 99 %, median"]
    for c, name in enumerate(names[1:-1], start=1):
        r = np.abs(sig[..., c, :] / sig[..., 0, :] - 1)[ok]
        lines.append(f"  {name}: {r.max():.1e}, {np.quantile(r, 0.99):.1e}, {np.median(r):.1e}")
    return lines


def report(res, columns=None):
    """The tables of a run; ``columns`` (variant names) restricts the per-mode tables."""
    orders = [int(n) for n in res["orders"]]
    names = variants(list(zip([str(f) for f in res["forms"]], res["cs"])))
    M, O, R, nt = res["f"].shape
    st = table(res)
    sel = list(range(len(names))) if not columns else [names.index(c) for c in columns]
    lines = [f"structure {res['structure']}, {R} records ({float(res['seconds']):.0f} s, "
             f"{float(res['seconds']) / max(R, 1):.2f} s/record); poles with ρ > {LIMIT:g} left out (counts in 'n').", ""]
    ks = {meth: np.bincount(res["k_star"][m]) for m, meth in enumerate(METHODS)}
    lines.append("k* over records: " + "; ".join(
        f"{meth}: " + ", ".join(f"{v}×{c}" for v, c in enumerate(b) if c) for meth, b in ks.items()))
    lines += true_order_change(res, names)
    lines.append("")
    lines += per_mode_tables(st[sel], [names[c] for c in sel], orders, nt)
    lines += pooled_table(st, names, orders, nt, "variant", with_median=True)
    return "\n".join(lines)


def gap_resolution(s, Ua_blocks, k_star, n_max):
    """Prints quantiles of |g_ij|/τ_ij over the pairs i ≠ j, j < n_max, by class (both < k*,
    one on each side, both ≥ k*): the saturating weight bites where |g|/τ ≲ sqrt(c)."""
    g = s[None, :] ** 2 - s[:, None] ** 2
    num = Ua_blocks * s[None, None, :] + np.swapaxes(Ua_blocks, 1, 2) * s[None, :, None]
    r = np.abs(g) / np.sqrt(np.sum(num * num, axis=0))
    i, j = np.meshgrid(np.arange(s.size), np.arange(s.size), indexing="ij")
    use = (i != j) & (j < n_max)
    for lab, sel in (("signal-signal", (i < k_star) & (j < k_star)),
                     ("signal-noise", (i < k_star) != (j < k_star)),
                     ("noise-noise", (i >= k_star) & (j >= k_star))):
        x = r[use & sel]
        if x.size:
            q = np.quantile(x, [0.0, 0.05, 0.5, 0.95])
            print(f"  |g|/τ, {lab} pairs ({x.size}): min {q[0]:.3g}, 5 % {q[1]:.3g}, median {q[2]:.3g}, 95 % {q[3]:.3g}")


def checks(n_records=3, structure="chain", seed=0, form="saturating", c_check=1.6, c_big=1e6):
    """The checks before any Monte Carlo, printed: (1) c = 0 is the oracle's plain J, (2) the own
    frozen variant is the oracle's frozen J, (3) c = c_big against the frozen σ above k*, (4) the
    candidate (c = c_check) against the core's σ at the true order."""
    kw, orders = STRUCTURES[structure]
    truth = simulate(N_SAMPLES, seed=record_seed(seed, 0), **kw)
    n0 = orders[0]
    settings = Settings(block_rows=P, orders=(n0,), n_blocks=N_BLOCKS)
    worst = {1: 0.0, 2: 0.0, 4: 0.0, "4core": 0.0, "core": 0.0}
    for k in range(n_records):
        sim = simulate(N_SAMPLES, seed=record_seed(seed, k), **kw)
        for m, u in enumerate((None, sim.u)):
            rec = record_parts(sim.y, u, sim.fs, orders)
            H, k_star, svd = rec["H"], rec["k_star"], rec["svd"]
            n_max = max(orders)
            if k == 0:
                gap_resolution(svd[1], rec["Ua"], k_star, n_max)
            J_plain = jacobian_gamma_h(H, n_max)
            J0 = jacobian_gamma_h_reg(H, n_max, gap_weights(svd[1], rec["Ua"], 0.0, form), svd=svd)
            kf = min(k_star, n_max - 1) if k_star < n_max else n_max // 2          # a freeze that bites
            J_fr = jacobian_gamma_h(H, n_max, frozen_from=kf)
            J0_fr = jacobian_gamma_h_reg(H, n_max, gap_weights(svd[1], rec["Ua"], 0.0, form), frozen_from=kf, svd=svd)
            e1 = np.linalg.norm(J0 - J_plain) / np.linalg.norm(J_plain)
            e2 = np.linalg.norm(J0_fr - J_fr) / np.linalg.norm(J_fr)
            worst[1], worst[2] = max(worst[1], e1), max(worst[2], e2)
            print(f"record {k} {METHODS[m]}: k* = {k_star}; (1) ‖J(c=0) − J_plain‖/‖J_plain‖ = {e1:.1e}; "
                  f"(2) frozen from {kf}: ‖J_own − J_oracle‖/‖J_oracle‖ = {e2:.1e}")
            sig = record_sigmas(sim.y, u, sim.fs, orders, [(form, c) for c in (c_check, 1e2, 1e4, c_big)])
            # (3) record 0: large c against the frozen σ above k*
            if k == 0:
                for n in orders:
                    if n <= k_star:
                        continue
                    s = sig[n]["sigma"]
                    idx = match_modes(sig[n]["f"], truth.frequency_hz)
                    phys = idx[idx >= 0]
                    for lab, col in (("c=1e2", 2), ("c=1e4", 3), (f"c={c_big:g}", 4), (f"c={c_check:g}", 1),
                                     ("plain", 5)):
                        r = s[phys, col] / s[phys, 0]
                        print(f"  (3) order {n}, {phys.size} physical poles, σ({lab})/σ_frozen: f "
                              + " ".join(f"{x:.2f}" for x in r[:, 0]) + "; ξ " + " ".join(f"{x:.2f}" for x in r[:, 1]))
                    r = s[:, 4] / s[:, 0]
                    print(f"      all {s.shape[0]} poles, σ(c={c_big:g})/σ_frozen: median {np.median(r):.3f}, "
                          f"range {r.min():.3f}–{r.max():.3f}")
            # (4) the true order: the candidate against the core
            s = sig[n0]["sigma"]
            idx = match_modes(sig[n0]["f"], truth.frequency_hz)
            phys = idx[idx >= 0]
            d4 = np.abs(s[phys, 1] / s[phys, 0] - 1).max()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ModalUQWarning)
                core = identify(sim.y, u, fs=sim.fs, settings=settings).at_order(n0)
            ic = match_modes(core.frequency_hz, truth.frequency_hz)
            both = (idx >= 0) & (ic >= 0)
            sc = np.stack([core.frequency_std[ic[both]], core.damping_std[ic[both]]], axis=-1)
            dcore = np.abs(s[idx[both], 0] / sc - 1).max()
            d4c = np.abs(s[idx[both], 1] / sc - 1).max()
            worst[4], worst["4core"], worst["core"] = max(worst[4], d4), max(worst["4core"], d4c), max(worst["core"], dcore)
            print(f"  (4) order {n0}: max |σ(c={c_check:g})/σ_frozen − 1| = {d4:.2e} over {phys.size} physical poles "
                  f"(f, ξ); against modaluq.identify's σ: {d4c:.2e} (oracle frozen vs core: {dcore:.1e})")
    print(f"worst: (1) {worst[1]:.1e}; (2) {worst[2]:.1e}; (4) {worst[4]:.2e} "
          f"(vs core {worst['4core']:.2e}; oracle vs core {worst['core']:.1e})")
    return worst


def main(n_records=100, structure="chain", seed=0, out=None, progress=True, max_seconds=None, specs=None):
    return finish(run(n_records, structure=structure, seed=seed, progress=progress, max_seconds=max_seconds,
                      specs=specs), out, report)


if __name__ == "__main__":
    ap = study_parser(__doc__)
    ap.add_argument("--structure", choices=sorted(STRUCTURES), default="chain")
    ap.add_argument("--form", choices=FORMS, default="saturating", help="the form --check checks")
    ap.add_argument("--cs", type=float, nargs="*", default=list(CS), help="c of the saturating form")
    ap.add_argument("--tik-cs", type=float, nargs="*", default=[], help="c of the Tikhonov form (variant)")
    ap.add_argument("--max-seconds", type=float, help="stop after the record that crosses this wall time")
    ap.add_argument("--check", action="store_true", help="run the checks (on --records records; 3 unless given)")
    ap.add_argument("--columns", nargs="*", help="with --report: the variants of the per-mode tables (e.g. frozen c=10 plain)")
    args = ap.parse_args()
    if args.report:
        reprint(args.report, lambda res: report(res, args.columns))
    elif args.check:
        checks(args.records if "--records" in sys.argv else 3, args.structure, args.seed, args.form)
    else:
        main(args.records, args.structure, args.seed, args.out, max_seconds=args.max_seconds,
             specs=specs_of(args.cs, args.tik_cs))
