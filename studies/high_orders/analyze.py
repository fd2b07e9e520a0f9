"""Tables from mc.py's npz: ratios of reported sigma to Monte Carlo std, with and without the fix,
variance decomposition by groups of Omega terms, and the dependence on the cut gap.

usage: python3 analyze.py FILE.npz [variant ...] [--xi] [--robust]   (last variant: conditioning check)
"""
import sys

import numpy as np

d = np.load(sys.argv[1])
XI = "--xi" in sys.argv
ROBUST = "--robust" in sys.argv
EST = d["X"] if XI else d["F"]
SIG = d["SX"] if XI else d["SF"]
configs, orders, variants, groups = list(d["configs"]), list(d["orders"]), list(d["variants"]), list(d["groups"])
n_rec = EST.shape[1]
par = "xi" if XI else "f"
print(f"# {sys.argv[1]}: {n_rec} records, n_blocks {int(d['n_blocks'])}, parameter {par}"
      f"{', robust sigma_MC (1.4826 MAD)' if ROBUST else ''}")
print("package vs numpy baseline sigma_f, max rel diff:",
      np.nanmax(np.abs(d["SF"][..., 0] / d["SFpkg"] - 1)))


def mc_std(x):
    x = x[np.isfinite(x)]
    if ROBUST:
        return 1.4826 * np.median(np.abs(x - np.median(x)))
    return np.std(x, ddof=1)


def table(variant_list):
    for c, cfg in enumerate(configs):
        for o, n in enumerate(orders):
            print(f"\n## {cfg}, order {n}")
            hdr = "| | " + " | ".join(f"mode {m + 1}" for m in range(6)) + " |"
            print(hdr)
            print("|---" * 7 + "|")
            sd = np.array([mc_std(EST[c, :, o, m]) for m in range(6)])
            nm = np.sum(np.isfinite(EST[c, :, o]), axis=0)
            print("| matched | " + " | ".join(f"{v}" for v in nm) + " |")
            scale = 1e2 if not XI else 1e3
            unit = "1e-2 Hz" if not XI else "‰"
            print(f"| σ_MC ({unit}) | " + " | ".join(f"{scale * v:.3g}" for v in sd) + " |")
            for vn in variant_list:
                v = variants.index(vn)
                s = SIG[c, :, o, :, v]
                mean = np.nanmean(s, axis=0) / sd
                med = np.nanmedian(s, axis=0) / sd
                tail = np.nanmean(np.where(np.isfinite(s), s > 3 * sd, np.nan), axis=0)
                print(f"| {vn}: mean/σ_MC | " + " | ".join(f"{x:.2f}" for x in mean) + " |")
                print(f"| {vn}: median/σ_MC | " + " | ".join(f"{x:.2f}" for x in med) + " |")
                print(f"| {vn}: share > 3σ_MC | " + " | ".join(f"{x:.2f}" for x in tail) + " |")


def decomposition():
    print("\n# variance decomposition of the baseline sigma_f^2 (share = cov(term, total)/var(total));"
          " median over records [mean over records with sigma > 3 sigma_MC]")
    G = d["GSHARE"]
    for c, cfg in enumerate(configs):
        for o, n in enumerate(orders):
            sd = np.array([mc_std(d["F"][c, :, o, m]) for m in range(6)])
            s = d["SF"][c, :, o, :, 0]
            tail = s > 3 * sd
            row = []
            for gi, g in enumerate(groups):
                med = np.nanmedian(G[c, :, o, :, gi], axis=0)
                tl = [np.nanmean(G[c, tail[:, m], o, m, gi]) if tail[:, m].any() else np.nan for m in range(6)]
                row.append(f"{g}: " + " ".join(f"{a:+.2f}[{b:+.2f}]" for a, b in zip(med, tl)))
            print(f"{cfg} n={n}:\n   " + "\n   ".join(row))


def gap_dependence():
    print("\n# baseline sigma_f / sigma_MC against the cut gap z = (s_n - s_n+1)/std; median [mean] (records)")
    bins = [0, 0.5, 1, 2, 3, np.inf]
    for c, cfg in enumerate(configs):
        for o, n in enumerate(orders):
            sd = np.array([mc_std(d["F"][c, :, o, m]) for m in range(6)])
            z = d["CUTZ"][c, :, o]
            r = d["SF"][c, :, o, :, 0] / sd
            line = []
            for lo, hi in zip(bins[:-1], bins[1:]):
                sel = (z >= lo) & (z < hi)
                if sel.sum() == 0:
                    continue
                rr = r[sel]
                line.append(f"z∈[{lo},{hi}) n={sel.sum()}: med " + ",".join(f"{x:.2f}" for x in np.nanmedian(rr, 0))
                            + " mean " + ",".join(f"{x:.2f}" for x in np.nanmean(rr, 0)))
            rho = [np.corrcoef(np.log(z[np.isfinite(r[:, m])]), np.log(r[np.isfinite(r[:, m]), m]))[0, 1]
                   for m in range(6)]
            print(f"{cfg} n={n}: corr(log z, log ratio) per mode " + ",".join(f"{x:+.2f}" for x in rho))
            for ln in line:
                print("   " + ln)


def conditioning(vn):
    """Residual tail after a fix variant against eigenvalue conditioning of the matched pole."""
    if "ECOND" not in d:
        return
    v = variants.index(vn)
    print(f"\n# eigenvalue condition number / nearest-eigenvalue distance (Hz): records with {vn} sigma_f > 3 sigma_MC vs the rest (medians)")
    for c, cfg in enumerate(configs):
        for o, n in enumerate(orders):
            sd = np.array([mc_std(d["F"][c, :, o, m]) for m in range(6)])
            s = SIG[c, :, o, :, v]
            tail = s > 3 * sd
            ok = np.isfinite(s) & ~tail
            ec, ed = d["ECOND"][c, :, o], d["EDIST"][c, :, o]
            print(f"{cfg} n={n}: tail n={tail.sum()}: cond {np.median(ec[tail]) if tail.any() else np.nan:.2f} "
                  f"dist {np.median(ed[tail]) if tail.any() else np.nan:.3f} | rest cond {np.median(ec[ok]):.2f} "
                  f"dist {np.median(ed[ok]):.3f}")


if __name__ == "__main__":
    vl = [a for a in sys.argv[2:] if not a.startswith("--")] or ["base", "k1", "k2", "k3", "k5"]
    table(vl)
    if not XI:
        decomposition()
        gap_dependence()
        conditioning(vl[-1])
