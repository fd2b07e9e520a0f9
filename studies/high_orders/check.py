import time
import warnings

import numpy as np
from prop import Record, covariances

import modaluq

warnings.simplefilter("ignore")
sim = modaluq.simulate(10000, seed=3)
for u in (None, sim.u):
    t=time.process_time()
    H, dH = covariances(sim.y, u, 15, 15, 50)
    rec = Record(H, dH, 3, sim.fs)
    t1=time.process_time()
    res = modaluq.identify(sim.y, u, fs=sim.fs, block_rows=15, orders=[12,24,36], n_blocks=50)
    print("svals rel diff", np.max(np.abs(rec.s-res.singular_values[:45])/rec.s[0]))
    for n in (12,24,36):
        o = rec.order(n)
        m = res.at_order(n)
        sf = np.array([np.linalg.norm(rec.perturb(n, g["Ff"], g["Fdf"])) for g in o["grads"]])
        sx = np.array([np.linalg.norm(rec.perturb(n, g["Fx"], g["Fdx"])) for g in o["grads"]])
        print(n, "f diff", np.max(np.abs(o["f"]-m.frequency_hz)), "sf rel", np.max(np.abs(sf/m.frequency_std-1)), "sx rel", np.max(np.abs(sx/m.damping_std-1)))
        # within-kept couplings should give zero
        M = np.zeros((45,45))
        M[n:, :] = 1
        sfo = np.array([np.linalg.norm(rec.perturb(n, g["Ff"], g["Fdf"], M)) for g in o["grads"]])
        print("   only across-cut+ds / total:", np.round(sfo/sf,6))
    print("time numpy", t1-t)
