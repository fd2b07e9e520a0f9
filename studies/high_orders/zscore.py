"""Standardised errors e = (f - mean f)/sigma in records with sigma > 3 sigma_MC vs the rest:
RMS(e) should be ~1 if the record's sigma were right. usage: python3 zscore.py FILE.npz [variant]"""
import sys

import numpy as np

d = np.load(sys.argv[1])
vn = sys.argv[2] if len(sys.argv) > 2 else "base"
v = list(d["variants"]).index(vn)
for c, cfg in enumerate(d["configs"]):
    for o, n in enumerate(d["orders"]):
        out = []
        for m in range(6):
            f = d["F"][c, :, o, m]
            s = d["SF"][c, :, o, m, v]
            ok = np.isfinite(f)
            smc = np.std(f[ok], ddof=1)
            e = (f - np.nanmean(f)) / s
            tail = ok & (s > 3 * smc)
            rest = ok & ~tail
            rt = np.sqrt(np.mean(e[tail] ** 2)) if tail.any() else np.nan
            er = np.abs(f - np.nanmean(f)) / smc
            out.append(f"m{m+1}: tail RMS e {rt:.2f} (|f-mean|/σ_MC rms {np.sqrt(np.mean(er[tail]**2)) if tail.any() else np.nan:.2f}), rest RMS e {np.sqrt(np.mean(e[rest]**2)):.2f}")
        print(f"{cfg} n={n} [{vn}]: " + "; ".join(out))
