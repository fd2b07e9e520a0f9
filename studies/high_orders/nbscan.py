"""Part 4 at the mode level: sigma_f, sigma_xi at the true order (12) for n_blocks = 25, 50, 100
(identical records), IO with unknown_input_std = 0 (IO0) and the default 0.1 (IO), and the
Richardson-type extrapolation to infinitely long blocks, var_inf = 2 var(n_b/2) - var(n_b)
(block-variance bias linear in n_b), from the same record.

usage: OPENBLAS_NUM_THREADS=1 nice -n 10 python3 nbscan.py N_RECORDS OUT.npz
"""
import sys
import time
import warnings

import numpy as np
from prop import Record, covariances

import modaluq
from modaluq.validation.montecarlo import match_modes

warnings.simplefilter("ignore")
NBS = (25, 50, 100)


def main():
    n_rec, out = int(sys.argv[1]), sys.argv[2]
    t0 = time.process_time()
    F = np.full((2, n_rec, 6), np.nan)
    X = np.full((2, n_rec, 6), np.nan)
    VF = np.full((2, n_rec, len(NBS), 6), np.nan)
    VX = np.full((2, n_rec, len(NBS), 6), np.nan)
    for k in range(n_rec):
        seed = np.random.SeedSequence(0, spawn_key=(k,))
        for c, uis in enumerate((0.0, 0.1)):
            sim = modaluq.simulate(10_000, seed=seed, unknown_input_std=uis)
            for t, nb in enumerate(NBS):
                H, dH = covariances(sim.y, sim.u, 15, 15, nb)
                rec = Record(H, dH, 3, sim.fs)
                md = rec.order(12)
                idx = match_modes(md["f"], sim.frequency_hz)
                for m in range(6):
                    if idx[m] < 0:
                        continue
                    g = md["grads"][idx[m]]
                    F[c, k, m] = md["f"][idx[m]]
                    X[c, k, m] = md["xi"][idx[m]]
                    df = rec.perturb(12, g["Ff"], g["Fdf"])
                    dx = rec.perturb(12, g["Fx"], g["Fdx"])
                    VF[c, k, t, m] = df @ df
                    VX[c, k, t, m] = dx @ dx
        if (k + 1) % 25 == 0:
            print(f"{k + 1} records, cpu {time.process_time() - t0:.0f} s", file=sys.stderr, flush=True)
    np.savez(out, F=F, X=X, VF=VF, VX=VX, nbs=NBS)
    for name, E, V in (("f", F, VF), ("xi", X, VX)):
        for c, cfg in enumerate(("IO0 (unknown_input_std=0)", "IO (unknown_input_std=0.1)")):
            smc = np.nanstd(E[c], axis=0, ddof=1)
            print(f"\n{name}, {cfg}, order 12, {n_rec} records: mean sigma / sigma_MC, modes 1..6")
            for t, nb in enumerate(NBS):
                print(f"  n_blocks {nb:3d}: " + " ".join(f"{x:5.2f}" for x in np.nanmean(np.sqrt(V[c, :, t]), 0) / smc))
            for a, b in ((0, 1), (1, 2)):
                ve = 2 * V[c, :, a] - V[c, :, b]
                neg = np.mean(ve <= 0, axis=0)
                s = np.sqrt(np.clip(ve, 0, None))
                print(f"  extrapolated 2 var({NBS[a]}) - var({NBS[b]}): " + " ".join(f"{x:5.2f}" for x in np.nanmean(s, 0) / smc)
                      + "   (share <= 0: " + " ".join(f"{x:.2f}" for x in neg) + ")")


if __name__ == "__main__":
    main()
