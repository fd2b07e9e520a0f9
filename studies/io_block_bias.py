"""Issue 27, one cell: input/output with the measured input carrying (nearly) all the response,
true order, σ growing with n_blocks. Which part is wrong, why, and a fix that stays PSD.

The paper's chain (block_rows p = q = 15, order 12, 10,000 samples per record), records with
``unknown_input_std`` = 0 (the issue's "known input only") or small. NumPy only: the first-order
chain is ``studies/high_orders/prop.py`` (equal to the core's σ, ``high_orders/check.py``).

Influence series. With G = R2 R3⁺, M = R3⁺ R4ᵀ and e⁺_c = y⁺_c − G u⁺_c, e⁻_c = y⁻_c − Mᵀ u⁺_c
(Hankel column c), J_{H,R} applied to column c's products is e⁺_c e⁻_cᵀ, so along a direction g
(a × b) ⟨g, H⟩ is linearised as mean_c z_c, z_c = e⁺_cᵀ g e⁻_c, and the core's block estimate
of var⟨g, H⟩ is var(block means of z)/n_b (docs/uq-math.md §3). Split by the block row i of e⁺:
z_c = Σ_i z_{c,i}, z_{c,i} = (e⁺_c)_iᵀ g_i e⁻_c, where (e⁺_c)_i is the output at time q + i + c.

Estimators of var⟨g, H⟩ compared (each from one record):
* ``columns``: the core's, blocks of consecutive Hankel columns;
* ``aligned``: the same sum cut by the time of the *future* sample: z_{c,i} goes to the block
  containing t = c + i (block k: t in [k N_b, (k+1) N_b)); a partition of the same terms, so the
  estimate is a block sample covariance (PSD) with the same sum;
* ``obm2``: overlapping pairs of adjacent column blocks (a Bartlett window twice as long, PSD);
* ``lag1``: C0 + 2 C1 of the column-block means (adjacent-block covariance added, NOT PSD);
* ``scaled``: per parameter, the core's variance × max(1/4, 1 + 2 (ρ1 + 1/n_b)), ρ1 the lag-1
  autocorrelation of the block deviations (D Σ D with D diagonal, so PSD; a factor D U_θ);
* ``scaled/mode``: the same with one ρ1 per mode (the mean of its f's and ξ's): Σ_θ × a scalar;
* ``jack``: delete-one-block jackknife of ⟨g, H(R)⟩, with H = R1 − R2 R3⁺ R4ᵀ recomputed.

Directions: (1) fixed g = ∂f_m/∂H, ∂ξ_m/∂H from a long reference record, to compare the block
estimate with the Monte Carlo variance of ⟨g, H⟩ and to split z into the parts of the sensor noise
v and of the noise-free response d (e⁺ = e⁺_d + v⁺, e⁻ = e⁻_d + v⁻, the noise-free outputs from
the same seed with noise_std = 0); (2) each record's own gradients (what the core uses), for
σ/σ_MC and coverage of ±1.96 σ of the identified f and ξ themselves.

usage: OPENBLAS_NUM_THREADS=1 nice -n 19 python studies/io_block_bias.py [N_RECORDS] [UNKNOWN_INPUT_STD] [OUT.npz]
(default 150 records, 0.0; about 0.9 s CPU per record), or ``--report OUT.npz`` to print a saved run
"""
import pathlib
import sys
import time
import warnings

import numpy as np

import modaluq
from modaluq.validation.montecarlo import match_modes

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent / "high_orders"))
from prop import Record, covariances, grad_H, hankel  # noqa: E402

P = 15
ORDER = 12
NBS = (25, 50, 100, 200)
METHODS = ("columns", "aligned", "aligned⊥", "obm2", "lag1", "scaled", "scaled/mode", "jack")
C_MIN = 0.25        # floor of the variance factor of ``scaled`` (σ at least halved)
TERMS = ("d·d", "v·d", "d·v", "v·v")       # (part of e⁺)·(part of e⁻)


def _directions(rec, md, idx):
    """(12, a, b): ∂f_m/∂H for modes 1..6 then ∂ξ_m/∂H (NaN where a mode is missed)."""
    a = rec.U.shape[0]
    g = np.full((12, a, a), np.nan)
    for m, j in enumerate(idx):
        if j >= 0:
            gr = md["grads"][j]
            g[m] = grad_H(rec, ORDER, gr["Ff"], gr["Fdf"])
            g[6 + m] = grad_H(rec, ORDER, gr["Fx"], gr["Fdx"])
    return g


def _rowblock_z(ep, em, g, l):
    """z_{c,i} (dirs, p, N) for e⁺ (a, N), e⁻ (b, N), directions g (dirs, a, b)."""
    Q = np.einsum("mab,bc->mac", g, em, optimize=True)     # g e⁻
    Z = ep[None] * Q                                       # (dirs, a, N)
    return Z.reshape(g.shape[0], P, l, -1).sum(axis=2)


def _aligned(Z, nb):
    """Block estimate with z_{c,i} given to the block of t = c + i (future-sample time)."""
    dirs, p, N = Z.shape
    Nb = N // nb
    zt = np.zeros((dirs, N + p - 1))
    for i in range(p):
        zt[:, i:i + N] += Z[:, i]
    bm = zt[:, :nb * Nb].reshape(dirs, nb, Nb).mean(axis=2)
    d = bm - bm.mean(axis=1, keepdims=True)
    return np.sum(d * d, axis=1) / (nb * (nb - 1))


def _block_vars(Z, nb, Zp=None):
    """var estimates of mean_c z_c (dirs,) from the row-block series Z (dirs, p, N); Zp: the same
    with e⁺ projected off span Γ (same column sums), for ``aligned⊥``."""
    dirs, p, N = Z.shape
    Nb = N // nb
    z = Z.sum(axis=1)
    bm = z[:, :nb * Nb].reshape(dirs, nb, Nb).mean(axis=2)
    d = bm - bm.mean(axis=1, keepdims=True)
    den = nb * (nb - 1)
    out = {"columns": np.sum(d * d, axis=1) / den}
    s2 = d[:, :-1] + d[:, 1:]
    out["obm2"] = np.sum(s2 * s2, axis=1) / 2 / den
    out["lag1"] = out["columns"] + 2 * np.sum(d[:, :-1] * d[:, 1:], axis=1) / den
    # per parameter: var × (1 + 2 ρ1), ρ1 the lag-1 autocorrelation of the block deviations with
    # its centring bias (−1/n_b) removed, floored: D Σ D with D diagonal > 0 stays PSD
    rho1 = np.sum(d[:, :-1] * d[:, 1:], axis=1) / np.maximum(np.sum(d * d, axis=1), 1e-300) + 1.0 / nb
    out["scaled"] = out["columns"] * np.maximum(C_MIN, 1 + 2 * rho1)
    # one factor per mode: ρ1 averaged over its f and ξ (directions m and m + 6), Σ_θ × scalar
    rm = np.tile((rho1[:6] + rho1[6:]) / 2, 2) if dirs == 12 else rho1
    out["scaled/mode"] = out["columns"] * np.maximum(C_MIN, 1 + 2 * rm)
    out["aligned"] = _aligned(Z, nb)
    if Zp is not None:
        out["aligned⊥"] = _aligned(Zp, nb)
    return out


def _jackknife(Yp, Ym, Up, g, nb):
    """Delete-one-block jackknife variance of ⟨g, H(R)⟩ (dirs,)."""
    N = Yp.shape[1]
    Nb = N // nb
    sl = slice(0, nb * Nb)

    def blocks(X, Y):
        return np.einsum("akt,bkt->kab", X[:, sl].reshape(X.shape[0], nb, Nb), Y[:, sl].reshape(Y.shape[0], nb, Nb))

    full = [X @ Y.T for X, Y in ((Yp, Ym), (Yp, Up), (Up, Up), (Ym, Up))]
    blk = [blocks(X, Y) for X, Y in ((Yp, Ym), (Yp, Up), (Up, Up), (Ym, Up))]
    th = np.empty((nb, g.shape[0]))
    for k in range(nb):
        R1, R2, R3, R4 = ((F - B[k]) / (N - Nb) for F, B in zip(full, blk))
        H = R1 - R2 @ np.linalg.pinv(R3, rtol=1e-10) @ R4.T
        th[k] = np.einsum("mab,ab->m", g, H)
    d = th - th.mean(axis=0)
    return (nb - 1) / nb * np.sum(d * d, axis=0)


def edge_constant(g, uis, n_samples=50_000):
    """K (dirs,) of the edge bias of the sensor-noise part: E[block estimate] ≈ (1 + K/N_b) × var.

    The noise sample v_t enters p Hankel columns (row block i of column t − q − i), with total
    weight w_t = Σ_i g_i e⁻_{d, t−q−i} (e⁻_d: the noise-free past, input part removed), so its
    share of var⟨g, H⟩ is E[v_tᵀ w_t]². A block edge that cuts the p columns after the s-th leaves
    each block a partial sum; the excess is |w^{≤s}|² + |w^{>s}|² − |w|² (weights: the sensor-noise
    variance of each channel). K = Σ_s E(excess_s) / E|w|². Also returns E|w|² / Σ_i E|w_i|²."""
    seed = np.random.SeedSequence(2727)
    sim = modaluq.simulate(n_samples, seed=seed, unknown_input_std=uis)
    clean = modaluq.simulate(n_samples, seed=seed, unknown_input_std=uis, noise_std=0.0)
    sv2 = np.var(sim.y - clean.y, axis=0)
    l = sim.y.shape[1]
    Yp, Ym, Up = hankel(sim.y, sim.u, P, P)
    N = Yp.shape[1]
    _, Ymd, _ = hankel(clean.y, None, P, P)
    R3p = np.linalg.pinv(Up @ Up.T / N, rtol=1e-10)
    emd = Ymd - (Ym @ Up.T / N) @ R3p @ Up
    Q = np.einsum("mab,bc->mac", g, emd, optimize=True).reshape(len(g), P, l, N)
    part = np.zeros((len(g), P, l, N + P - 1))
    for i in range(P):
        part[:, i, :, i:i + N] = Q[:, i]
    part = part[..., P:N - 1]                     # times whose p terms are all in the record
    cum = np.cumsum(part, axis=1)
    w = cum[:, -1]

    def power(x):
        return np.einsum("mct,c->mt", x * x, sv2).mean(axis=-1)

    full = power(w)
    K = sum(power(cum[:, s]) + power(w - cum[:, s]) - full for s in range(P - 1)) / full
    return K, full / sum(power(part[:, i]) for i in range(P))


def main(n_records=150, unknown_input_std=0.0, out=None, n_samples=10_000, n_reference=200_000):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _run(n_records, unknown_input_std, out, n_samples, n_reference)


def _run(n_rec, uis, out, n_samples, n_ref):
    t0 = time.process_time()
    ref = modaluq.simulate(n_ref, seed=987654, unknown_input_std=uis)
    Href, dHref = covariances(ref.y, ref.u, P, P, 50)
    rref = Record(Href, dHref, 3, ref.fs)
    mref = rref.order(ORDER)
    gref = _directions(rref, mref, match_modes(mref["f"], ref.frequency_hz))
    Gam = rref.U[:, :ORDER] * np.sqrt(rref.s[:ORDER])
    ann = [np.linalg.norm(Gam.T @ g) / (np.linalg.norm(Gam) * np.linalg.norm(g)) for g in gref]
    nd, nn = 12, len(NBS)
    est = {m: np.full((n_rec, nn, nd), np.nan) for m in METHODS}      # own gradients
    estf = {m: np.full((n_rec, nn, nd), np.nan) for m in ("columns", "aligned", "aligned⊥")}  # fixed gradients
    Uref = rref.U[:, :ORDER]
    ann_own = np.full((n_rec, nd), np.nan)
    K, cancel = edge_constant(gref, uis)
    term_blk = np.full((n_rec, nn, len(TERMS), nd), np.nan)          # columns estimate per term, fixed g
    term_blk_al = np.full((n_rec, nn, len(TERMS), nd), np.nan)
    theta = np.full((n_rec, nd), np.nan)                              # mean z, fixed g
    theta_terms = np.full((n_rec, len(TERMS), nd), np.nan)
    theta_nl = np.full((n_rec, nd), np.nan)                           # <g, H> exactly
    par = np.full((n_rec, nd), np.nan)                                # identified f_m, xi_m
    share = np.full(n_rec, np.nan)
    for k in range(n_rec):
        seed = np.random.SeedSequence(27, spawn_key=(k,))
        sim = modaluq.simulate(n_samples, seed=seed, unknown_input_std=uis)
        clean = modaluq.simulate(n_samples, seed=seed, unknown_input_std=uis, noise_std=0.0)
        only_u = modaluq.simulate(n_samples, seed=seed, unknown_input_std=0.0, noise_std=0.0)
        yc = clean.y - clean.y.mean(axis=0)
        yu = only_u.y - only_u.y.mean(axis=0)   # same known input (drawn first from the same seed)
        share[k] = np.sum(yu * yu) / np.sum(yc * yc)
        Yp, Ym, Up = hankel(sim.y, sim.u, P, P)
        Ypd, Ymd, _ = hankel(clean.y, None, P, P)
        N = Yp.shape[1]
        R2, R3, R4 = Yp @ Up.T / N, Up @ Up.T / N, Ym @ Up.T / N
        R3p = np.linalg.pinv(R3, rtol=1e-10)
        G, M = R2 @ R3p, R3p @ R4.T
        H = Yp @ Ym.T / N - G @ R4.T
        ep_d, em_d = Ypd - G @ Up, Ymd - M.T @ Up
        ep_v, em_v = Yp - Ypd, Ym - Ymd
        ep, em = Yp - G @ Up, Ym - M.T @ Up
        # fixed directions: the covariance of H along them, and its parts
        Zt = {}
        for name, (x, y) in zip(TERMS, ((ep_d, em_d), (ep_v, em_d), (ep_d, em_v), (ep_v, em_v))):
            Zt[name] = _rowblock_z(x, y, gref, 3)
            theta_terms[k, TERMS.index(name)] = Zt[name].sum(axis=1).mean(axis=1)
        Zf = sum(Zt.values())
        Zfp = _rowblock_z(ep - Uref @ (Uref.T @ ep), em, gref, 3)
        theta[k] = Zf.sum(axis=1).mean(axis=1)
        theta_nl[k] = np.einsum("mab,ab->m", gref, H)
        for t, nb in enumerate(NBS):
            v = _block_vars(Zf, nb, Zfp)
            for m in estf:
                estf[m][k, t] = v[m]
            for j, name in enumerate(TERMS):
                vt = _block_vars(Zt[name], nb)
                term_blk[k, t, j] = vt["columns"]
                term_blk_al[k, t, j] = vt["aligned"]
        # the record's own gradients: sigma of the identified f, xi
        _, dH = covariances(sim.y, sim.u, P, P, 25)
        rec = Record(H, dH, 3, sim.fs)
        md = rec.order(ORDER)
        idx = match_modes(md["f"], sim.frequency_hz)
        for m, j in enumerate(idx):
            if j >= 0:
                par[k, m], par[k, 6 + m] = md["f"][j], md["xi"][j]
        g = _directions(rec, md, idx)
        ok = np.isfinite(g[:, 0, 0])
        g = np.where(ok[:, None, None], g, 0.0)
        U1 = rec.U[:, :ORDER]
        ann_own[k] = np.linalg.norm(np.einsum("ai,mab->mib", U1, g), axis=(1, 2)) / np.maximum(
            np.linalg.norm(g, axis=(1, 2)), 1e-300)
        Z = _rowblock_z(ep, em, g, 3)
        Zp = _rowblock_z(ep - U1 @ (U1.T @ ep), em, g, 3)
        for t, nb in enumerate(NBS):
            v = _block_vars(Z, nb, Zp)
            v["jack"] = _jackknife(Yp, Ym, Up, g, nb)
            for m in METHODS:
                est[m][k, t] = np.where(ok, v[m], np.nan)
        if (k + 1) % 25 == 0:
            print(f"{k + 1} records, cpu {time.process_time() - t0:.0f} s", file=sys.stderr, flush=True)
    res = dict(est=est, estf=estf, term_blk=term_blk, term_blk_al=term_blk_al, theta=theta,
               theta_terms=theta_terms, theta_nl=theta_nl, par=par, share=share, ann=np.array(ann), ann_own=ann_own,
               truth=np.concatenate([ref.frequency_hz, ref.damping_ratio]), K=K, cancel=cancel, N=n_samples - 2 * P + 1)
    if out:
        np.savez(out, **{k: v for k, v in res.items() if not isinstance(v, dict)}, unknown_input_std=uis,
                 **{f"est_{m}": v for m, v in est.items()}, **{f"estf_{m}": v for m, v in estf.items()})
    _add_gated(res["est"])
    report(res, n_rec, uis)
    return res


def _add_gated(est):
    """``scaled/mode, gated``: the per-mode factor only where ρ1 + 1/n_b differs from 0 by more than
    2/√n_b (its sampling std under independent blocks is ≈ 1/√n_b); derived from ``scaled/mode``."""
    col, sm = est["columns"], est["scaled/mode"]
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = (sm / col - 1) / 2
    sq = np.sqrt(np.asarray(NBS, float))[None, :, None]
    est["scaled/mode, gated"] = np.where(np.abs(rho) * sq > 2, sm, col)


def report_file(path):
    """Print the tables of a run saved by ``main(..., out=path)``."""
    d = np.load(path)
    res = {k: d[k] for k in d.files if not k.startswith("est")}
    res["est"] = {k[4:]: d[k] for k in d.files if k.startswith("est_")}
    res["estf"] = {k[5:]: d[k] for k in d.files if k.startswith("estf_")}
    res.setdefault("N", np.array(10_000 - 2 * P + 1))   # runs saved before N was stored: 10,000 samples
    _add_gated(res["est"])
    report(res, len(res["par"]), float(d["unknown_input_std"]) if "unknown_input_std" in d.files else float("nan"))


def _row(x):
    return " ".join(f"{v:.2f}" for v in x)


def report(res, n_rec, uis):
    par, theta = res["par"], res["theta"]
    print(f"\nchain, order {ORDER}, p = q = {P}, unknown_input_std = {uis:g}, {n_rec} records; "
          f"known input's share of the noise-free output power: median {np.median(res['share']) * 100:.1f} %")
    print(f"|Γᵀg|/(|Γ||g|) at the reference (f then ξ): {_row(res['ann'] * 1e3)} ×1e-3; "
          f"|U1ᵀg|/|g| with each record's own g: max {np.nanmax(res['ann_own']):.1e}")
    smc_par = np.nanstd(par, axis=0, ddof=1)
    smc_lin = np.nanstd(theta, axis=0, ddof=1)
    smc_nl = np.nanstd(res["theta_nl"], axis=0, ddof=1)
    print("\n(1) first-order map: std over records of <g_ref, H> (linearised, exact) / std of f, ξ identified")
    print("| | f, modes 1–6 | ξ, modes 1–6 |\n|---|---|---|")
    print(f"| linearised / identified | {_row(smc_lin[:6] / smc_par[:6])} | {_row(smc_lin[6:] / smc_par[6:])} |")
    print(f"| exact <g,H> / identified | {_row(smc_nl[:6] / smc_par[:6])} | {_row(smc_nl[6:] / smc_par[6:])} |")
    print("\n(2) block estimate of var<g_ref, H> against its Monte Carlo variance: √(mean estimate)/std_MC")
    print("| n_blocks | estimator | f, modes 1–6 | ξ, modes 1–6 |\n|---|---|---|---|")
    for t, nb in enumerate(NBS):
        for m, e in res["estf"].items():
            r = np.sqrt(np.nanmean(e[:, t], axis=0)) / smc_lin
            print(f"| {nb} | {m} | {_row(r[:6])} | {_row(r[6:])} |")
    print("\n(2b) the edge constant K of the sensor-noise part (edge_constant) and its prediction √(1 + K/N_b)")
    print(f"| | f, modes 1–6 | ξ, modes 1–6 |\n|---|---|---|\n| E|w|²/Σ_i E|w_i|² | {_row(res['cancel'][:6])} | "
          f"{_row(res['cancel'][6:])} |\n| K (columns) | {' '.join(f'{x:.0f}' for x in res['K'][:6])} | "
          f"{' '.join(f'{x:.0f}' for x in res['K'][6:])} |")
    for nb in NBS:
        Nb = int(res["N"]) // nb
        r = np.sqrt(1 + res["K"] / Nb)
        print(f"| n_blocks {nb} (N_b = {Nb}) | {_row(r[:6])} | {_row(r[6:])} |")
    print("\n(3) parts of z (e⁺ part · e⁻ part; d noise-free, v sensor noise), columns estimator:"
          " mean estimate / var_MC of the part, and the part's share of var_MC of the total")
    vt = np.nanvar(res["theta_terms"], axis=0, ddof=1)          # (terms, dirs)
    vtot = np.nanvar(theta, axis=0, ddof=1)
    print("| part | n_blocks | estimator | f, modes 1–6 | ξ, modes 1–6 |\n|---|---|---|---|---|")
    for j, name in enumerate(TERMS):
        print(f"| {name} | – | var_MC(part)/var_MC(total) | {_row(vt[j, :6] / vtot[:6])} | {_row(vt[j, 6:] / vtot[6:])} |")
        for t, nb in enumerate(NBS):
            for lab, arr in (("columns", res["term_blk"]), ("aligned", res["term_blk_al"])):
                r = np.nanmean(arr[:, t, j], axis=0) / vtot
                print(f"| {name} | {nb} | {lab} (/ var_MC total) | {_row(r[:6])} | {_row(r[6:])} |")
    print("\n(4) identified f and ξ, the record's own gradients: mean σ / σ_MC, median σ/σ_MC, coverage of ±1.96 σ"
          " around the Monte Carlo mean")
    print("| n_blocks | estimator | f: mean σ/σ_MC | ξ: mean σ/σ_MC | f: coverage % | ξ: coverage % | PSD |")
    print("|---|---|---|---|---|---|---|")
    dev = np.abs(par - np.nanmean(par, axis=0))
    for t, nb in enumerate(NBS):
        for m, e in res["est"].items():
            v = e[:, t]
            neg = np.mean(v <= 0) * 100
            s = np.sqrt(np.clip(v, 0, None))
            r = np.nanmean(s, axis=0) / smc_par
            with np.errstate(invalid="ignore"):
                cov = np.nanmean(np.where(np.isfinite(par), dev <= 1.96 * s, np.nan), axis=0) * 100
            psd = "yes" if m != "lag1" else f"no ({neg:.1f} % ≤ 0)"
            if m in ("scaled", "scaled/mode"):
                psd = f"yes ({np.mean(v <= res['est']['columns'][:, t] * C_MIN * 1.000001) * 100:.1f} % floored)"
            print(f"| {nb} | {m} | {_row(r[:6])} | {_row(r[6:])} | "
                  f"{' '.join(f'{c:.0f}' for c in cov[:6])} | {' '.join(f'{c:.0f}' for c in cov[6:])} | {psd} |")


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--report":
        report_file(sys.argv[2])
        sys.exit()
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 150, float(sys.argv[2]) if len(sys.argv) > 2 else 0.0,
         sys.argv[3] if len(sys.argv) > 3 else None)
