"""(mc4: Weyl noise-floor variants wC: noise columns j >= k*, k* = first k with s_k < C delta_k, have Omega[:, j] = 0) Monte Carlo of the reported sigma_f, sigma_xi at orders 12, 24, 36 with and without the
prototype fix (drop Omega_ij of unresolved singular-value pairs), plus the per-record
decomposition of var(f) into groups of Omega terms.

usage: OPENBLAS_NUM_THREADS=1 nice -n 10 python3 mc.py N_RECORDS OUT.npz [n_blocks]
Record k: modaluq.simulate(10_000, seed=SeedSequence(0, spawn_key=(k,))) (the validation tool's
seeds); configs OO (default sim, u=None), IO (default sim), IO0 (unknown_input_std=0, same seed).
"""
import sys
import time
import warnings

import numpy as np
from mc import CONFIGS, GROUPS, ORDERS, P, group_masks, match_modes
from prop import Record, covariances, factor_noise_columns, factors2, noise_floor, trailing_norms

import modaluq

warnings.simplefilter("ignore")

# variants: 0 = baseline, 1.. = full mask kappa, then across-only kappa=2 (must equal full)
VARIANTS = ["base", "d3", "d5", "w1", "w1.5", "w2"]


def main():
    n_rec = int(sys.argv[1])
    out = sys.argv[2]
    nb = int(sys.argv[3]) if len(sys.argv) > 3 else 50
    nc, no, nm, nv = len(CONFIGS), len(ORDERS), 6, len(VARIANTS)
    shp = (nc, n_rec, no, nm)
    F = np.full(shp, np.nan)
    X = np.full(shp, np.nan)
    SF = np.full(shp + (nv,), np.nan)
    SX = np.full(shp + (nv,), np.nan)
    SFpkg = np.full(shp, np.nan)
    MAC = np.full(shp, np.nan)
    GVAR = np.full(shp + (len(GROUPS),), np.nan)   # variance of the group's term alone
    GSHARE = np.full(shp + (len(GROUPS),), np.nan)  # cov(group term, total) / var(total)
    CUTZ = np.full((nc, n_rec, no), np.nan)
    KSTAR = np.full((nc, n_rec, len(VARIANTS)), -1)
    ECOND = np.full(shp, np.nan)   # eigenvalue condition number |chi||phi|/|chi^H phi|
    EDIST = np.full(shp, np.nan)   # distance (Hz) from mu_i to the nearest other eigenvalue of A, |mu_i - mu_j|/2pi        # (s_n - s_{n+1}) / std
    SVAL = np.full((nc, n_rec, 45), np.nan)
    SSTD = np.full((nc, n_rec, 45), np.nan)
    t0 = time.process_time()
    truth = None
    for k in range(n_rec):
        seed = np.random.SeedSequence(0, spawn_key=(k,))
        sim = modaluq.simulate(10_000, seed=seed)
        sim0 = modaluq.simulate(10_000, seed=seed, unknown_input_std=0.0)
        if truth is None:
            truth = dict(f=sim.frequency_hz, xi=sim.damping_ratio, shape=sim.mode_shape)
        ft = truth["f"]
        for c, (y, u) in enumerate(((sim.y, None), (sim.y, sim.u), (sim0.y, sim0.u))):
            H, dH = covariances(y, u, P, P, nb)
            rec = Record(H, dH, y.shape[1], sim.fs)
            SVAL[c, k] = rec.s
            SSTD[c, k] = rec.s_std
            try:
                pkg = modaluq.identify(y, u, fs=sim.fs, block_rows=P, orders=list(ORDERS), n_blocks=nb)
            except Exception as e:  # noqa: BLE001
                print("package failed", k, c, e, file=sys.stderr)
                pkg = None
            delta = trailing_norms(rec, kmax=30)
            masks = []
            for v in VARIANTS:
                if v.startswith("w"):
                    ks = noise_floor(rec, float(v[1:]), delta)
                    KSTAR[c, k, VARIANTS.index(v)] = ks
                    masks.append(factor_noise_columns(rec, ks))
                else:
                    masks.append(factors2(rec, v))
            for o, n in enumerate(ORDERS):
                CUTZ[c, k, o] = rec.cut_gap(n)
                md = rec.order(n)
                idx = match_modes(md["f"], ft)
                masks_n = masks
                gm = group_masks(rec, n)
                if pkg is not None:
                    pm = pkg.at_order(n)
                for mode in range(6):
                    if idx[mode] < 0:
                        continue
                    i = idx[mode]
                    g = md["grads"][i]
                    F[c, k, o, mode] = md["f"][i]
                    ECOND[c, k, o, mode] = md["cond"][i]
                    EDIST[c, k, o, mode] = md["dist"][i]
                    X[c, k, o, mode] = md["xi"][i]
                    sh = g["shape"]
                    tr = truth["shape"][:, mode]
                    MAC[c, k, o, mode] = abs(np.vdot(tr, sh)) ** 2 / (np.vdot(tr, tr).real * np.vdot(sh, sh).real)
                    for v, M in enumerate(masks_n):
                        SF[c, k, o, mode, v] = np.linalg.norm(rec.perturb(n, g["Ff"], g["Fdf"], M))
                        SX[c, k, o, mode, v] = np.linalg.norm(rec.perturb(n, g["Fx"], g["Fdx"], M))
                    if pkg is not None and abs(pm.frequency_hz[i] - md["f"][i]) < 1e-8:
                        SFpkg[c, k, o, mode] = pm.frequency_std[i]
                    tot = rec.perturb(n, g["Ff"], g["Fdf"])
                    vt = tot @ tot
                    for gi, name in enumerate(GROUPS):
                        if name == "ds":
                            term = rec.ds[:, :n] @ g["Fdf"]
                        else:
                            Om = rec.Om[:, :, :n] * gm[name][None, :, :n]
                            term = np.einsum("kij,ij->k", Om, g["Ff"])
                        GVAR[c, k, o, mode, gi] = term @ term
                        GSHARE[c, k, o, mode, gi] = (term @ tot) / vt
        if (k + 1) % 10 == 0:
            print(f"{k + 1} records, cpu {time.process_time() - t0:.0f} s", file=sys.stderr, flush=True)
            np.savez(out, F=F[:, :k + 1], X=X[:, :k + 1], SF=SF[:, :k + 1], SX=SX[:, :k + 1],
                     SFpkg=SFpkg[:, :k + 1], MAC=MAC[:, :k + 1], GVAR=GVAR[:, :k + 1],
                     GSHARE=GSHARE[:, :k + 1], CUTZ=CUTZ[:, :k + 1], KSTAR=KSTAR[:, :k + 1], ECOND=ECOND[:, :k + 1], EDIST=EDIST[:, :k + 1], SVAL=SVAL[:, :k + 1],
                     SSTD=SSTD[:, :k + 1], true_f=truth["f"], true_xi=truth["xi"],
                     variants=VARIANTS, groups=GROUPS, configs=CONFIGS, orders=ORDERS, n_blocks=nb)
    np.savez(out, F=F, X=X, SF=SF, SX=SX, SFpkg=SFpkg, MAC=MAC, GVAR=GVAR, GSHARE=GSHARE, CUTZ=CUTZ, KSTAR=KSTAR, ECOND=ECOND, EDIST=EDIST,
             SVAL=SVAL, SSTD=SSTD, true_f=truth["f"], true_xi=truth["xi"], variants=VARIANTS,
             groups=GROUPS, configs=CONFIGS, orders=ORDERS, n_blocks=nb)
    print(f"done, cpu {time.process_time() - t0:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
