"""Records that dominate RMS(e) of xi after the fix: their xi, sigma (base / fix), nearest-eigenvalue
distance and MAC with the true shape. usage: python3 xi_outliers.py FILE.npz VARIANT"""
import sys

import numpy as np

d = np.load(sys.argv[1])
vn = sys.argv[2]
v = list(d["variants"]).index(vn)
for c, o, m in ((1, 1, 2), (1, 1, 3), (0, 1, 3), (2, 1, 1), (0, 2, 1)):
    x = d["X"][c, :, o, m]
    sb = d["SX"][c, :, o, m, 0]
    sf = d["SX"][c, :, o, m, v]
    ok = np.isfinite(x)
    med = np.median(x[ok])
    rob = 1.4826 * np.median(np.abs(x[ok] - med))
    e = (x - np.nanmean(x)) / sf
    top = np.argsort(-np.nan_to_num(e ** 2))[:5]
    print(f"{d['configs'][c]} n={d['orders'][o]} mode {m+1}: xi true {d['true_xi'][m]:.4f}, median {med:.4f}, robust sd {rob:.5f}, sd {np.nanstd(x):.5f}; "
          f"share |x-med|>5 robust sd: {np.mean(np.abs(x[ok]-med) > 5*rob):.3f}")
    for t in top:
        print(f"   rec {t:3d}: xi {x[t]:.4f} f {d['F'][c,t,o,m]:.3f} sigma base {sb[t]:.5f} fix {sf[t]:.5f} e {e[t]:7.1f}  dist {d['EDIST'][c,t,o,m]:.3f} Hz cond {d['ECOND'][c,t,o,m]:.2f} MAC {d['MAC'][c,t,o,m]:.3f}")
