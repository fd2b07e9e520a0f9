"""Markdown tables of docs/validation-high-orders.md from the saved runs.

usage: python3 tables.py [section ...]   (in the folder of the runs' npz files)   sections: base decomp fix xi flag boot hcov (default all)
needs mc2_300.npz, mc5_300.npz (or mc4_300.npz), boot150.npz, hcov_io0.npz, hcov_io.npz, nbscan.npz
"""
import os
import sys

import numpy as np

HERE = os.getcwd()  # the runs write their npz files into the folder they run in


def load(name):
    return np.load(os.path.join(HERE, name))


M2 = load("mc2_300.npz")
M5 = load("mc5_300.npz") if os.path.exists(os.path.join(HERE, "mc5_300.npz")) else load("mc4_300.npz")
CONFIGS = [str(c) for c in M2["configs"]]
ORDERS = [int(o) for o in M2["orders"]]
LABEL = {"OO": "OO", "IO": "IO", "IO0": "IO, unknown_input_std=0"}


def fmt(xs, p=2):
    return " ".join(f"{x:.{p}f}" for x in xs)


def stats(est, sig, c, o):
    """mean/median ratio, tail share, RMS(e) per mode for one variant's sigma (n_rec, 6)."""
    e_all = est[c, :, o]
    smc = np.array([np.nanstd(e_all[:, m], ddof=1) for m in range(6)])
    mean = np.nanmean(sig, 0) / smc
    med = np.nanmedian(sig, 0) / smc
    tail = np.nanmean(np.where(np.isfinite(sig), sig > 3 * smc, np.nan), 0)
    e = (e_all - np.nanmean(e_all, 0)) / sig
    rms = np.sqrt(np.nanmean(e ** 2, 0))
    return smc, mean, med, tail, rms


def variant(name, xi=False):
    key = "SX" if xi else "SF"
    if name.startswith("w1.5+flag"):       # recommended rule: sigma_fix unless sigma_base/sigma_fix > T (f or xi)
        T = float(name[len("w1.5+flag"):])
        r = np.maximum(variant("base") / variant("w1.5"), variant("base", True) / variant("w1.5", True))
        return np.where(r > T, variant("base", xi), variant("w1.5", xi))
    for d in (M2, M5):
        vs = [str(v) for v in d["variants"]]
        if name in vs:
            return d[key][..., vs.index(name)]
    raise KeyError(name)


def section_base():
    print("\n### Baseline (current core), frequency\n")
    print("| method | order | σ_MC of f (10⁻² Hz), modes 1–6 | mean σ/σ_MC | median σ/σ_MC | share σ > 3σ_MC | RMS(e) |")
    print("|---|---|---|---|---|---|---|")
    for c, cfg in enumerate(CONFIGS):
        for o, n in enumerate(ORDERS):
            smc, mean, med, tail, rms = stats(M2["F"], variant("base")[c, :, o], c, o)
            print(f"| {LABEL[cfg]} | {n} | {fmt(100 * smc, 3)} | {fmt(mean)} | {fmt(med)} | {fmt(tail)} | {fmt(rms)} |")
    print("\n### Baseline (current core), damping ratio\n")
    print("| method | order | σ_MC of ξ (‰), robust σ_MC (‰) in brackets | mean σ/σ_MC | median σ/σ_MC | share σ > 3σ_MC | RMS(e) |")
    print("|---|---|---|---|---|---|---|")
    for c, cfg in enumerate(CONFIGS):
        for o, n in enumerate(ORDERS):
            smc, mean, med, tail, rms = stats(M2["X"], variant("base", True)[c, :, o], c, o)
            x = M2["X"][c, :, o]
            rob = [1.4826 * np.nanmedian(np.abs(x[:, m] - np.nanmedian(x[:, m]))) for m in range(6)]
            cell = " ".join(f"{1e3 * a:.2f}[{1e3 * b:.2f}]" for a, b in zip(smc, rob))
            print(f"| {LABEL[cfg]} | {n} | {cell} | {fmt(mean)} | {fmt(med)} | {fmt(tail)} | {fmt(rms)} |")


def section_decomp():
    G = M2["GSHARE"]
    groups = [str(g) for g in M2["groups"]]
    sel = {"within kept set": ["within"], "physical j, across the cut": ["phys-x-close", "phys-x-far"],
           "noise j, across the cut, z < 3": ["noise-x-close"], "noise j, across the cut, z ≥ 3": ["noise-x-far"],
           "d s_j": ["ds"]}
    print("\n| method | order | records | " + " | ".join(sel) + " |")
    print("|---|---|---|" + "---|" * len(sel))
    for c, cfg in enumerate(CONFIGS):
        for o, n in enumerate(ORDERS):
            s = M2["SF"][c, :, o, :, 0]
            smc = np.array([np.nanstd(M2["F"][c, :, o, m], ddof=1) for m in range(6)])
            tail = s > 3 * smc
            for lab, mask in (("all (median)", np.isfinite(s)), ("σ > 3σ_MC (mean)", tail)):
                if not mask.any():
                    continue
                cells = []
                for names in sel.values():
                    v = sum(G[c, :, o, :, groups.index(g)] for g in names)
                    cells.append(f"{(np.nanmedian(v[mask]) if 'median' in lab else np.nanmean(v[mask])):+.2f}")
                print(f"| {LABEL[cfg]} | {n} | {lab}, {mask.sum()} poles | " + " | ".join(cells) + " |")


def section_fix(xi=False):
    names = (["base", "d3", "d5", "w1.5", "w1.5+flag5"] if xi else
             ["base", "d1", "d2", "d3", "d5", "w1.5", "w1.5+flag5"])
    est = M2["X"] if xi else M2["F"]
    print("\n| method | order | variant | mean σ/σ_MC | median σ/σ_MC | share σ > 3σ_MC | RMS(e) |")
    print("|---|---|---|---|---|---|---|")
    for c, cfg in enumerate(CONFIGS):
        for o, n in enumerate(ORDERS):
            for vn in names:
                _, mean, med, tail, rms = stats(est, variant(vn, xi)[c, :, o], c, o)
                print(f"| {LABEL[cfg]} | {n} | {vn} | {fmt(mean)} | {fmt(med)} | {fmt(tail)} | {fmt(rms)} |")


def section_flag(T=5.0):
    print("\n| method | order | flagged poles | f: RMS(e) unflagged, σ_fix | ξ: RMS(e) unflagged, σ_fix | flagged, RMS(e) of ξ with σ_fix / σ_base |")
    print("|---|---|---|---|---|---|")
    base_f, fix_f = variant("base"), variant("w1.5")
    base_x, fix_x = variant("base", True), variant("w1.5", True)
    for c, cfg in enumerate(CONFIGS):
        for o, n in enumerate(ORDERS):
            flag = (base_f[c, :, o] / fix_f[c, :, o] > T) | (base_x[c, :, o] / fix_x[c, :, o] > T)
            ok = np.isfinite(M2["F"][c, :, o])
            cells = []
            for E, S in ((M2["F"], fix_f), (M2["X"], fix_x)):
                e = (E[c, :, o] - np.nanmean(E[c, :, o], 0)) / S[c, :, o]
                cells.append(fmt([np.sqrt(np.mean(e[ok[:, m] & ~flag[:, m], m] ** 2)) for m in range(6)]))
            fl = ok & flag
            ex = M2["X"][c, :, o] - np.nanmean(M2["X"][c, :, o], 0)
            if fl.any():
                last = f"{np.sqrt(np.mean((ex / fix_x[c, :, o])[fl] ** 2)):.1f} / {np.sqrt(np.mean((ex / base_x[c, :, o])[fl] ** 2)):.2f}"
            else:
                last = "–"
            print(f"| {LABEL[cfg]} | {n} | {fl.sum() / ok.sum():.1%} | {cells[0]} | {cells[1]} | {last} |")


def section_boot():
    d = load("boot150.npz")
    F, SL, SB, SBR = d["F"], d["SL"], d["SB"], d["SBR"]
    print(f"\n{F.shape[1]} records, 80 draws each.\n")
    print("| method | order | σ | mean σ/σ_MC | share σ > 3σ_MC | RMS(e) |")
    print("|---|---|---|---|---|---|")
    for c, cfg in enumerate(("OO", "IO", "IO0")):
        for o, n in enumerate(d["orders"]):
            smc = np.array([np.nanstd(F[c, :, o, m], ddof=1) for m in range(6)])
            for name, S in (("first order (core)", SL[c, :, o]), ("H-bootstrap, t = 0.1", SB[c, :, o, :, 1]),
                            ("H-bootstrap, t = 1", SB[c, :, o, :, 0]), ("H-bootstrap, t = 1, robust", SBR[c, :, o, :, 0])):
                e = (F[c, :, o] - np.nanmean(F[c, :, o], 0)) / S
                print(f"| {LABEL[cfg]} | {n} | {name} | {fmt(np.nanmean(S, 0) / smc)} | "
                      f"{fmt(np.nanmean(np.where(np.isfinite(S), S > 3 * smc, np.nan), 0))} | {fmt(np.sqrt(np.nanmean(e ** 2, 0)))} |")


def section_hcov():
    for fn in ("hcov_io0.npz", "hcov_io.npz"):
        d = load(fn)
        proj, bv, nbs, N = d["proj"], d["blockvar"], d["nbs"], int(d["N"])
        mc = np.var(proj, axis=0, ddof=1)
        print(f"\n{fn} (unknown_input_std = {float(d['unknown_input_std'])}, {proj.shape[0]} records): "
              "√(mean block variance) / MC std of ⟨g_m, H⟩\n")
        print("| n_blocks | N_b | mode 1 | mode 2 | mode 3 | mode 4 | mode 5 | mode 6 |")
        print("|---|---|---|---|---|---|---|---|")
        for t, nb in enumerate(nbs):
            print(f"| {nb} | {N // nb} | " + " | ".join(f"{x:.2f}" for x in np.sqrt(bv[:, t].mean(0) / mc)) + " |")
        pg = d["pgram"]
        print("\nmean periodogram of the influence series z_c, S(f)/S(0), S(0) = N var_MC:\n")
        print("| period (columns) | mode 1 | mode 2 | mode 3 | mode 4 | mode 5 | mode 6 |")
        print("|---|---|---|---|---|---|---|")
        for k1, k2 in ((1, 3), (3, 10), (10, 25), (25, 50), (50, 100), (100, 200), (200, 400)):
            print(f"| {N // k2}–{N // k1} | " + " | ".join(f"{x:.2f}" for x in pg[:, k1:k2].mean(1) / (N * mc)) + " |")
    d = load("nbscan.npz")
    print("\nMode level, order 12, 200 records: mean σ / σ_MC\n")
    print("| method | parameter | n_blocks 25 | n_blocks 50 | n_blocks 100 | extrapolated 2·var(25) − var(50) | extrapolated 2·var(50) − var(100) |")
    print("|---|---|---|---|---|---|---|")
    for c, cfg in enumerate(("IO, unknown_input_std=0", "IO, unknown_input_std=0.1")):
        for name, E, V in (("f", d["F"], d["VF"]), ("ξ", d["X"], d["VX"])):
            smc = np.nanstd(E[c], axis=0, ddof=1)
            cells = [fmt(np.nanmean(np.sqrt(V[c, :, t]), 0) / smc) for t in range(3)]
            for a, b in ((0, 1), (1, 2)):
                ve = np.clip(2 * V[c, :, a] - V[c, :, b], 0, None)
                cells.append(fmt(np.nanmean(np.sqrt(ve), 0) / smc) + f" ({np.mean(2 * V[c, :, a] - V[c, :, b] <= 0):.0%} ≤ 0)")
            print(f"| {cfg} | {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    secs = sys.argv[1:] or ["base", "decomp", "fix", "xi", "flag", "boot", "hcov"]
    for s in secs:
        print(f"\n<!-- section {s} -->")
        {"base": section_base, "decomp": section_decomp, "fix": section_fix, "xi": lambda: section_fix(True),
         "flag": section_flag, "boot": section_boot, "hcov": section_hcov}[s]()
