"""Calibration of the reported sigma: standardised error e = (f - mean f)/sigma per record.
A right sigma gives RMS(e) = 1 overall AND within groups of records sorted by sigma/sigma_MC.
usage: python3 calib.py FILE.npz [--xi] variants...
prints per config/order: RMS(e) per mode, coverage P(|e|<1.96) pooled, and RMS(e) pooled over
modes within quartiles of sigma/sigma_MC (Q1 smallest sigma ... Q4 largest)."""
import sys

import numpy as np

d = np.load(sys.argv[1])
XI = "--xi" in sys.argv
est = d["X"] if XI else d["F"]
sig = d["SX"] if XI else d["SF"]
variants = list(d["variants"])
vl = [a for a in sys.argv[2:] if not a.startswith("--")] or variants
for c, cfg in enumerate(d["configs"]):
    for o, n in enumerate(d["orders"]):
        print(f"\n{cfg} n={n} ({'xi' if XI else 'f'}): RMS(e) modes 1..6 | coverage 95% (modes 1-6 pooled) | RMS(e) by quartile of sigma/sigma_MC (modes 2-6 pooled)")
        for vn in vl:
            v = variants.index(vn)
            rms, cov, E, R = [], [], [], []
            for m in range(6):
                f = est[c, :, o, m]
                s = sig[c, :, o, m, v]
                ok = np.isfinite(f) & np.isfinite(s)
                smc = np.std(f[ok], ddof=1)
                e = (f[ok] - f[ok].mean()) / s[ok]
                rms.append(np.sqrt(np.mean(e ** 2)))
                cov.append(np.abs(e) < 1.96)
                if m >= 1:
                    E.append(e)
                    R.append(s[ok] / smc)
            E = np.concatenate(E)
            R = np.concatenate(R)
            q = np.quantile(R, [0.25, 0.5, 0.75])
            bins = np.digitize(R, q)
            qr = [np.sqrt(np.mean(E[bins == b] ** 2)) for b in range(4)]
            print(f"  {vn:5s} " + " ".join(f"{x:4.2f}" for x in rms) + f" | {np.mean(np.concatenate(cov)):.3f} | "
                  + " ".join(f"{x:4.2f}" for x in qr))
