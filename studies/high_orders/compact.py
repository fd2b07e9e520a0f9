"""Compact per-mode table: mean/median/tail per variant (rows) for one config & order.
usage: python3 compact.py FILE.npz [--xi] [--robust] [variants...]"""
import sys

import numpy as np

d = np.load(sys.argv[1])
XI = "--xi" in sys.argv
ROB = "--robust" in sys.argv
est = d["X"] if XI else d["F"]
sig = d["SX"] if XI else d["SF"]
variants = list(d["variants"])
vl = [a for a in sys.argv[2:] if not a.startswith("--")] or variants
def sd(x):
    x = x[np.isfinite(x)]
    return 1.4826 * np.median(np.abs(x - np.median(x))) if ROB else np.std(x, ddof=1)
for c, cfg in enumerate(d["configs"]):
    for o, n in enumerate(d["orders"]):
        s_mc = np.array([sd(est[c, :, o, m]) for m in range(6)])
        print(f"\n{cfg} n={n}  ({'xi' if XI else 'f'}; sigma_MC {'robust' if ROB else 'std'}; mean / median / share>3 per mode 1..6)")
        for vn in vl:
            v = variants.index(vn)
            s = sig[c, :, o, :, v]
            mean = np.nanmean(s, 0) / s_mc
            med = np.nanmedian(s, 0) / s_mc
            tail = np.nanmean(np.where(np.isfinite(s), s > 3 * s_mc, np.nan), 0)
            print(f"  {vn:5s} " + " ".join(f"{a:5.2f}" for a in mean) + " | " + " ".join(f"{a:4.2f}" for a in med)
                  + " | " + " ".join(f"{a:4.2f}" for a in tail))
