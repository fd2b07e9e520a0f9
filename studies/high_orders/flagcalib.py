"""Calibration with the fix plus a per-pole flag: flag = sigma(base)/sigma(fix) > T for f or xi.
Per config/order: share flagged; RMS(e) of unflagged poles with sigma_fix (f, xi, modes 1..6);
RMS(e) of flagged poles with sigma_fix and with sigma_base (modes pooled).
e = (estimate - mean over all matched records)/sigma.  usage: python3 flagcalib.py FILE.npz VARIANT T"""
import sys

import numpy as np

d = np.load(sys.argv[1])
v = list(d["variants"]).index(sys.argv[2])
T = float(sys.argv[3])
print(f"fix {sys.argv[2]}, flag sigma_base/sigma_fix > {T} (f or xi)")
for c, cfg in enumerate(d["configs"]):
    for o, n in enumerate(d["orders"]):
        rf = d["SF"][c, :, o, :, 0] / d["SF"][c, :, o, :, v]
        rx = d["SX"][c, :, o, :, 0] / d["SX"][c, :, o, :, v]
        flag = (rf > T) | (rx > T)
        ok = np.isfinite(d["F"][c, :, o])
        line = f"{cfg} n={n}: flagged {np.sum(flag & ok) / ok.sum():.1%}"
        for name, E, S in (("f", d["F"], d["SF"]), ("xi", d["X"], d["SX"])):
            e_fix = (E[c, :, o] - np.nanmean(E[c, :, o], 0)) / S[c, :, o, :, v]
            e_base = (E[c, :, o] - np.nanmean(E[c, :, o], 0)) / S[c, :, o, :, 0]
            un = ok & ~flag
            rms_un = [np.sqrt(np.mean(e_fix[un[:, m], m] ** 2)) for m in range(6)]
            fl = ok & flag
            line += (f"\n   {name:2s}: unflagged RMS(e) " + " ".join(f"{x:4.2f}" for x in rms_un)
                     + f" | flagged RMS(e) fix {np.sqrt(np.mean(e_fix[fl] ** 2)) if fl.any() else np.nan:6.2f}"
                     + f" base {np.sqrt(np.mean(e_base[fl] ** 2)) if fl.any() else np.nan:5.2f}")
        print(line)
