"""Does the sigma that the fix removes flag the bad poles? r = sigma_xi(base) / sigma_xi(fix) per record;
'bad' = |xi - median| > 5 robust sd or MAC with the true shape < 0.9. usage: python3 flagcheck.py FILE.npz VARIANT"""
import sys

import numpy as np

d = np.load(sys.argv[1])
v = list(d["variants"]).index(sys.argv[2])
for thr in (3.0, 5.0, 10.0):
    print(f"\nflag: r_xi = sigma_xi(base)/sigma_xi(fix) > {thr}")
    for c, cfg in enumerate(d["configs"]):
        for o, n in enumerate(d["orders"]):
            if n == 12:
                continue
            nb = nbf = ng = ngf = 0
            for m in range(6):
                x = d["X"][c, :, o, m]
                ok = np.isfinite(x)
                med = np.median(x[ok])
                rob = 1.4826 * np.median(np.abs(x[ok] - med))
                bad = ok & ((np.abs(x - med) > 5 * rob) | (d["MAC"][c, :, o, m] < 0.9))
                r = d["SX"][c, :, o, m, 0] / d["SX"][c, :, o, m, v]
                flag = r > thr
                nb += bad.sum()
                nbf += (bad & flag).sum()
                ng += (ok & ~bad).sum()
                ngf += (ok & ~bad & flag).sum()
            print(f"  {cfg} n={n}: bad poles {nb}, flagged {nbf} ({nbf / max(nb, 1):.0%}); good poles {ng}, flagged {ngf} ({ngf / ng:.1%})")
