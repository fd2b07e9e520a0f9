"""Per-record linearity test: perturb H by its own block-estimated covariance and redo the
identification exactly (no linearisation): H* = H + sum_k xi_k dH^k, xi ~ N(0, I), so that
cov(vec H*) = T_H T_H^T, the covariance the first-order sigma propagates. The std of the
matched pole's f over the draws ("sigma_boot") is the non-linear counterpart of the reported
first-order sigma; the same draws scaled by t = 0.1 (and the std divided by t) test whether the
record is in its linear regime.

usage: OPENBLAS_NUM_THREADS=1 nice -n 10 python3 boot.py N_RECORDS DRAWS OUT.npz
"""
import sys
import time
import warnings

import numpy as np
from prop import Record, covariances

import modaluq
from modaluq.validation.montecarlo import match_modes

warnings.simplefilter("ignore")
P = 15
ORDERS = (12, 24, 36)
TS = (1.0, 0.1)


def poles(H, n, l, fs):
    U, s, Vt = np.linalg.svd(H)
    G = U[:, :n] * np.sqrt(s[:n])
    A = np.linalg.lstsq(G[:-l], G[l:], rcond=None)[0]
    w = np.linalg.eigvals(A)
    w = w[w.imag > 0]
    return np.log(w) * fs


def main():
    n_rec, draws, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    t0 = time.process_time()
    shp = (3, n_rec, len(ORDERS), 6)
    F = np.full(shp, np.nan)
    SL = np.full(shp, np.nan)
    SB = np.full(shp + (len(TS),), np.nan)       # plain std / t
    SBR = np.full(shp + (len(TS),), np.nan)      # robust std (1.4826 MAD) / t
    rng = np.random.default_rng(123)
    ft = None
    for k in range(n_rec):
        seed = np.random.SeedSequence(0, spawn_key=(k,))
        sim = modaluq.simulate(10_000, seed=seed)
        sim0 = modaluq.simulate(10_000, seed=seed, unknown_input_std=0.0)
        ft = sim.frequency_hz
        for c, (y, u) in enumerate(((sim.y, None), (sim.y, sim.u), (sim0.y, sim0.u))):
            H, dH = covariances(y, u, P, P, 50)
            rec = Record(H, dH, 3, sim.fs)
            xis = rng.standard_normal((draws, dH.shape[0]))
            for o, n in enumerate(ORDERS):
                md = rec.order(n)
                idx = match_modes(md["f"], ft)
                mu0 = np.log(md["lam"]) * sim.fs
                star = {t: [poles(H + t * np.tensordot(x, dH, 1), n, 3, sim.fs) for x in xis] for t in TS}
                for m in range(6):
                    if idx[m] < 0:
                        continue
                    i = idx[m]
                    g = md["grads"][i]
                    F[c, k, o, m] = md["f"][i]
                    SL[c, k, o, m] = np.linalg.norm(rec.perturb(n, g["Ff"], g["Fdf"]))
                    for ti, t in enumerate(TS):
                        fb = np.array([np.abs(p[np.argmin(np.abs(p - mu0[i]))]) / (2 * np.pi) if p.size else np.nan
                                       for p in star[t]])
                        fb = fb[np.isfinite(fb)]
                        SB[c, k, o, m, ti] = np.std(fb, ddof=1) / t
                        SBR[c, k, o, m, ti] = 1.4826 * np.median(np.abs(fb - np.median(fb))) / t
        if (k + 1) % 10 == 0:
            print(f"{k + 1} records, cpu {time.process_time() - t0:.0f} s", file=sys.stderr, flush=True)
            np.savez(out, F=F[:, :k + 1], SL=SL[:, :k + 1], SB=SB[:, :k + 1], SBR=SBR[:, :k + 1], ts=TS,
                     orders=ORDERS)
    np.savez(out, F=F, SL=SL, SB=SB, SBR=SBR, ts=TS, orders=ORDERS)


if __name__ == "__main__":
    main()
