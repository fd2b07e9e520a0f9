"""Weyl ratios s_k / delta_k of the first 16 singular values (40 records).
usage: python3 wtest.py [N_RECORDS]"""
import sys
import warnings

import numpy as np
from prop import Record, covariances, trailing_norms

import modaluq

warnings.simplefilter("ignore")
np.set_printoptions(precision=2, suppress=True, linewidth=200)
rows = {0: [], 1: [], 2: []}
for k in range(int(sys.argv[1]) if len(sys.argv) > 1 else 40):
    seed = np.random.SeedSequence(0, spawn_key=(k,))
    sim = modaluq.simulate(10_000, seed=seed)
    sim0 = modaluq.simulate(10_000, seed=seed, unknown_input_std=0.0)
    for c, (y, u) in enumerate(((sim.y, None), (sim.y, sim.u), (sim0.y, sim0.u))):
        H, dH = covariances(y, u, 15, 15, 50)
        rec = Record(H, dH, 3, 50.)
        dl = trailing_norms(rec, kmax=16)
        rows[c].append(rec.s[:16] / dl[:16])
for c in range(3):
    R = np.array(rows[c])
    print(["OO","IO","IO0"][c])
    print(" min ", R.min(0))
    print(" med ", np.median(R,0))
    print(" max ", R.max(0))
