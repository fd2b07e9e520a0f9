"""Checks for the write-up (mc2_300.npz + mc5_300.npz, same records):
1. change of sigma at the true order (12) by each fix variant;
2. xi calibration on clean poles (not 'bad': |xi - median| <= 5 robust sd and MAC >= 0.9), base vs w1.5;
3. flags for bad poles: r = sigma_base/sigma_fix > 5 (f or xi) and noise participation PART > thresholds."""
import numpy as np

m2 = np.load("mc2_300.npz")
m5 = np.load("mc5_300.npz")
assert np.allclose(m2["F"], m5["F"], equal_nan=True)
v2 = list(m2["variants"])
v5 = list(m5["variants"])
print("1. relative change of sigma_f at order 12, max over records [share of records with > 1 % change], modes 1..6")
for c, cfg in enumerate(m2["configs"]):
    base = m2["SF"][c, :, 0, :, 0]
    for vn, S in [(v, m2["SF"][c, :, 0, :, v2.index(v)]) for v in ("d1", "d2", "d3", "d5")] + [("w1.5", m5["SF"][c, :, 0, :, v5.index("w1.5")])]:
        rel = np.abs(S / base - 1)
        print(f"   {cfg:3s} {vn:5s}: " + " ".join(f"{np.nanmax(rel[:, m]):.1e}[{np.nanmean(rel[:, m] > 0.01):.2f}]" for m in range(6)))
print("\n2. xi on clean poles: RMS(e) with e = (xi - mean over clean)/sigma; base | w1.5 ; share of poles that are bad")
for c, cfg in enumerate(m5["configs"]):
    for o, n in enumerate(m5["orders"]):
        rb, rf, nbad = [], [], 0
        for m in range(6):
            x = m5["X"][c, :, o, m]
            ok = np.isfinite(x)
            med = np.median(x[ok])
            rob = 1.4826 * np.median(np.abs(x[ok] - med))
            bad = ok & ((np.abs(x - med) > 5 * rob) | (m5["MAC"][c, :, o, m] < 0.9))
            clean = ok & ~bad
            nbad += bad.sum()
            mu = x[clean].mean()
            rb.append(np.sqrt(np.mean(((x[clean] - mu) / m5["SX"][c, clean, o, m, 0]) ** 2)))
            rf.append(np.sqrt(np.mean(((x[clean] - mu) / m5["SX"][c, clean, o, m, 1]) ** 2)))
        print(f"   {cfg:3s} n={n}: base " + " ".join(f"{a:.2f}" for a in rb) + " | w1.5 " + " ".join(f"{a:.2f}" for a in rf) + f" ; bad {nbad / np.isfinite(m5['X'][c, :, o]).sum():.1%}")
print("\n2b. f on clean poles: RMS(e); base | w1.5")
for c, cfg in enumerate(m5["configs"]):
    for o, n in enumerate(m5["orders"]):
        rb, rf = [], []
        for m in range(6):
            x = m5["X"][c, :, o, m]
            f = m5["F"][c, :, o, m]
            ok = np.isfinite(x)
            med = np.median(x[ok])
            rob = 1.4826 * np.median(np.abs(x[ok] - med))
            clean = ok & ~((np.abs(x - med) > 5 * rob) | (m5["MAC"][c, :, o, m] < 0.9))
            mu = f[clean].mean()
            rb.append(np.sqrt(np.mean(((f[clean] - mu) / m5["SF"][c, clean, o, m, 0]) ** 2)))
            rf.append(np.sqrt(np.mean(((f[clean] - mu) / m5["SF"][c, clean, o, m, 1]) ** 2)))
        print(f"   {cfg:3s} n={n}: base " + " ".join(f"{a:.2f}" for a in rb) + " | w1.5 " + " ".join(f"{a:.2f}" for a in rf))
print("\n3. flags at orders 24/36: recall on bad poles / share of clean poles flagged")
for c, cfg in enumerate(m5["configs"]):
    for o, n in enumerate(m5["orders"]):
        if n == 12:
            continue
        res = {}
        for m in range(6):
            x = m5["X"][c, :, o, m]
            ok = np.isfinite(x)
            med = np.median(x[ok])
            rob = 1.4826 * np.median(np.abs(x[ok] - med))
            bad = ok & ((np.abs(x - med) > 5 * rob) | (m5["MAC"][c, :, o, m] < 0.9))
            clean = ok & ~bad
            r = np.maximum(m5["SF"][c, :, o, m, 0] / m5["SF"][c, :, o, m, 1], m5["SX"][c, :, o, m, 0] / m5["SX"][c, :, o, m, 1])
            P = m5["PART"][c, :, o, m]
            for name, fl in (("ratio>5", r > 5), ("PART>0.05", P > 0.05), ("PART>0.1", P > 0.1), ("PART>0.2", P > 0.2)):
                a = res.setdefault(name, [0, 0, 0, 0])
                a[0] += (bad & fl).sum()
                a[1] += bad.sum()
                a[2] += (clean & fl).sum()
                a[3] += clean.sum()
        print(f"   {cfg:3s} n={n}: " + "; ".join(f"{k}: {a[0]}/{a[1]} bad, {a[2] / a[3]:.1%} clean" for k, a in res.items()))
