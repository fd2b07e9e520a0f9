import numpy as np
from prop import Record, covariances

import modaluq

np.set_printoptions(linewidth=200, precision=3, suppress=True)
seed = np.random.SeedSequence(0, spawn_key=(0,))
sim = modaluq.simulate(10_000, seed=seed)
H, dH = covariances(sim.y, None, 15, 15, 50)
rec = Record(H, dH, 3, sim.fs)
print(rec.s[:40])
print(rec.s_std[:40])
print("z adjacent", (rec.s[:-1]-rec.s[1:])[:40]/np.array([rec.gap_std[i,i+1] for i in range(40)]))
print(rec.gap_z[11:26, 11:40].round(1))
