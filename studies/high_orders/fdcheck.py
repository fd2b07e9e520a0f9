import numpy as np
from prop import Record, covariances, grad_H

import modaluq

sim = modaluq.simulate(10000, seed=5, unknown_input_std=0.0)
H, dH = covariances(sim.y, sim.u, 15, 15, 50)
rec = Record(H, dH, 3, sim.fs)
md = rec.order(12)
rng = np.random.default_rng(0)
E = rng.standard_normal(H.shape) * np.linalg.norm(H) * 1e-7
for m in range(6):
    g = grad_H(rec, 12, md["grads"][m]["Ff"], md["grads"][m]["Fdf"])
    fp = Record(H + E, dH, 3, sim.fs).order(12)["f"][m]
    fm = Record(H - E, dH, 3, sim.fs).order(12)["f"][m]
    sig_direct = np.linalg.norm(rec.perturb(12, md["grads"][m]["Ff"], md["grads"][m]["Fdf"]))
    sig_g = np.linalg.norm(np.einsum("kab,ab->k", dH, g))
    print(m, (fp - fm) / 2, np.sum(g * E), sig_direct, sig_g)
