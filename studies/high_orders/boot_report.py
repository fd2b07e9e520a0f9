"""Report of boot.py: per config/order, mean and median over records of sigma/sigma_MC for the
first-order sigma (lin), the H-bootstrap std (t=1: boot, robust: bootR) and the small-step one (t=0.1),
the tail share > 3 sigma_MC, and the calibration RMS of e = (f - mean f)/sigma (1 = right).
sigma_MC from the same records. usage: python3 boot_report.py boot150.npz"""
import sys

import numpy as np

d = np.load(sys.argv[1])
F, SL, SB, SBR = d["F"], d["SL"], d["SB"], d["SBR"]
for c, cfg in enumerate(("OO", "IO", "IO0")):
    for o, n in enumerate(d["orders"]):
        print(f"\n{cfg} n={n} ({F.shape[1]} records): mean | median | share>3 | RMS(e), modes 1..6")
        smc = np.array([np.nanstd(F[c, :, o, m], ddof=1) for m in range(6)])
        for name, S in (("lin", SL[c, :, o]), ("boot", SB[c, :, o, :, 0]), ("bootR", SBR[c, :, o, :, 0]),
                        ("t0.1", SB[c, :, o, :, 1])):
            e = (F[c, :, o] - np.nanmean(F[c, :, o], 0)) / S
            print(f"  {name:5s} " + " ".join(f"{x:5.2f}" for x in np.nanmean(S, 0) / smc) + " | "
                  + " ".join(f"{x:4.2f}" for x in np.nanmedian(S, 0) / smc) + " | "
                  + " ".join(f"{x:4.2f}" for x in np.nanmean(np.where(np.isfinite(S), S > 3 * smc, np.nan), 0)) + " | "
                  + " ".join(f"{x:4.2f}" for x in np.sqrt(np.nanmean(e ** 2, 0))))
