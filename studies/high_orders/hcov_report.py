"""Report of hcov.py: block estimate of var<g_m, H> (mean over records) / Monte Carlo variance,
as std ratios, per n_blocks, plus the autocovariance structure of the column influence z_c.
usage: python3 hcov_report.py OUT.npz [OUT2.npz ...]"""
import sys

import numpy as np

for fn in sys.argv[1:]:
    d = np.load(fn)
    proj, bv, ac, nbs = d["proj"], d["blockvar"], d["acov"], d["nbs"]
    N = int(d["N"])
    R = proj.shape[0]
    mc = np.var(proj, axis=0, ddof=1)
    print(f"\n{fn}: unknown_input_std={float(d['unknown_input_std'])}, {R} records, N={N}; reference f = {np.round(d['f_ref'], 3)}")
    print("sqrt(mean block var) / MC std of <g_m,H>, modes 1..6 (MC std rel. s.e. ~ %.0f %%)" % (100 / np.sqrt(2 * (R - 1))))
    for t, nb in enumerate(nbs):
        print(f"  n_blocks {nb:4d} (N_b {N // nb:4d}): " + " ".join(f"{x:5.2f}" for x in np.sqrt(bv[:, t].mean(0) / mc)))
    # long-run variance from the mean autocovariance, truncated at lag L: (1/N) sum_{|tau|<L} (1-|tau|/N) gamma(tau)
    lags = np.arange(ac.shape[1])
    print("  var from the mean autocovariance of z (sum over |lag| < L) / MC var:")
    for L in (30, 100, 200, 400, 800, ac.shape[1]):
        w = np.where(lags < L, 1.0, 0.0)
        lr = (ac[:, 0] + 2 * np.sum(ac[:, 1:] * w[1:], axis=1)) / N
        print(f"    L={L:5d}: " + " ".join(f"{x:5.2f}" for x in np.sqrt(lr / mc)))
    # Bartlett-weighted (what blocks of length Nb estimate, to first order)
    print("  Bartlett window 1-|lag|/N_b (what a block of N_b columns sees) / MC, as std ratio:")
    for nb in nbs:
        Nb = N // nb
        w = np.clip(1 - lags / Nb, 0, None)
        lr = (ac[:, 0] + 2 * np.sum(ac[:, 1:] * w[1:], axis=1)) / N
        print(f"    N_b={Nb:4d}: " + " ".join(f"{x:5.2f}" for x in np.sqrt(lr / mc)))
    if "pgram" in d:
        pg = d["pgram"]
        S0 = N * mc
        print("  mean periodogram of z / (N var_MC) = S(f)/S(0), averaged over bins [k1, k2) (bin k = k/N per column; a block of N_b columns averages ~ bins < N/N_b):")
        for k1, k2 in ((1, 3), (3, 10), (10, 25), (25, 50), (50, 100), (100, 200), (200, 400)):
            print(f"    bins {k1:3d}-{k2:3d} (period {N // k2}-{N // k1} columns): " + " ".join(f"{x:5.2f}" for x in pg[:, k1:k2].mean(1) / S0))
    c = ac / ac[:, :1]
    print("  autocorrelation of z at lags 0,15,30,50,100,150,200,300,400,600,800: ")
    for m in range(6):
        print(f"    mode {m + 1}: " + " ".join(f"{c[m, L]:+.2f}" for L in (0, 15, 30, 50, 100, 150, 200, 300, 400, 600, 800)))
