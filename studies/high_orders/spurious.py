"""sigma of the spurious (unmatched) poles with and without the fix (and the fix with the flag rule: sigma_base when
sigma_base/sigma_fix > 5 for f or xi), order 24/36, 30 records. usage: OPENBLAS_NUM_THREADS=1 python3 spurious.py [N_RECORDS]"""
import sys
import warnings

import numpy as np
from prop import Record, covariances, factor_noise_columns, noise_floor, trailing_norms

import modaluq
from modaluq.validation.montecarlo import match_modes

warnings.simplefilter("ignore")
rows = []
for k in range(int(sys.argv[1]) if len(sys.argv) > 1 else 30):
    sim = modaluq.simulate(10_000, seed=np.random.SeedSequence(0, spawn_key=(k,)))
    for c, u in enumerate((None, sim.u)):
        H, dH = covariances(sim.y, u, 15, 15, 50)
        rec = Record(H, dH, 3, sim.fs)
        ks = noise_floor(rec, 1.5, trailing_norms(rec, kmax=30))
        M = factor_noise_columns(rec, ks)
        for n in (24, 36):
            md = rec.order(n)
            idx = set(match_modes(md["f"], sim.frequency_hz)) - {-1}
            for i, g in enumerate(md["grads"]):
                sb = np.linalg.norm(rec.perturb(n, g["Ff"], g["Fdf"]))
                sf = np.linalg.norm(rec.perturb(n, g["Ff"], g["Fdf"], M))
                xb = np.linalg.norm(rec.perturb(n, g["Fx"], g["Fdx"]))
                xf = np.linalg.norm(rec.perturb(n, g["Fx"], g["Fdx"], M))
                rows.append((c, n, i in idx, md["f"][i], md["xi"][i], sb / md["f"][i], sf / md["f"][i], xb, xf))
R = np.array(rows, dtype=float)
def rr(s):
    return np.maximum(s[:, 5] / s[:, 6], s[:, 7] / s[:, 8])
def hyb(s):
    return np.where(rr(s) > 5, s[:, 5], s[:, 6])   # sigma_f/f with the flag rule: base sigma when flagged
for c in (0, 1):
    for n in (24, 36):
        for phys in (1, 0):
            s = R[(R[:, 0] == c) & (R[:, 1] == n) & (R[:, 2] == phys)]
            print(f"{'OO' if c == 0 else 'IO'} n={n} {'matched ' if phys else 'spurious'} ({len(s)}): median sigma_f/f base {np.median(s[:,5]):.2e} fix {np.median(s[:,6]):.2e}; "
                  f"share sigma_f/f > 0.02: base {np.mean(s[:,5] > 0.02):.2f} fix {np.mean(s[:,6] > 0.02):.2f} fix+flag {np.mean(hyb(s) > 0.02):.2f}; flagged (r>5) {np.mean(rr(s) > 5):.2f}; median sigma_xi base {np.median(s[:,7]):.3f} fix {np.median(s[:,8]):.3f}")
