"""Monte Carlo of the multi-setup σ (issue 23; docs/uq-math.md §13) with the NumPy reference
tests/python/oracle_multisetup.py: N simulated deck campaigns (modaluq.simulate.campaign: 24
DOFs, 6 setups of 5-6 sensors with 2 references, 480-720 s each at 25 Hz, ambient level
varying between setups, 5 % sensor noise), output-only and input/output (a measured force at
L5), identified at the true order 12 with p = q = 15, 40 blocks per setup.

For each mode: the std over campaigns of f, ξ and of every shape component (Re, Im; shapes
normalised at the true shape's largest component) against the median reported σ, for the
modular merge and for PoSER; the MAC of the merged shape with the true shape; the median
ratio σ_f(modular)/σ_f(PoSER).

Three estimates per campaign: the modular merge with the references once (13.4), the pooled
variant whose A also uses every setup's normalised reference rows (13.11), and PoSER.

Usage: OPENBLAS_NUM_THREADS=1 python studies/multisetup_mc.py [N] [OUT.npz] [output-only|input/output]
(default 100 campaigns, both configurations: about 8 min of one core).
"""
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "python"))
import oracle_multisetup as om  # noqa: E402
from modaluq.simulate.campaign import simulate_campaign  # noqa: E402

P = 15
ORDER = 12
NB = 40
#: modular: references once (13.4); pooled: every setup's references in A (13.11); PoSER (13.8)-(13.10)
METHODS = ("modular", "pooled", "poser")
CONFIGS = {"output-only": {}, "input/output": {"input_dofs": ("L5",), "input_std": 1.0,
                                               "unknown_input_std": 0.3}}


def run_one(seed, kw, io):
    c = simulate_campaign(seed, **kw)
    recs = [(s.y, s.u if io else None) for s in c.setups]
    setups = om.prepare_setups(recs, P, P, NB, [s.references for s in c.setups])
    camp = om.Campaign(setups, P, ORDER, uncertainty=False)
    names = [c.setups[j].channels[ch] for j, ch in camp.dofs]
    Phi = c.mode_shape[[c.dofs.index(n) for n in names]]
    kref = np.argmax(np.abs(Phi), axis=0)
    truth = Phi / Phi[kref, np.arange(Phi.shape[1])]
    nm, l = len(c.frequency_hz), len(names)
    # per mode: f, σf, ξ, σξ, shape (l complex), σRe (l), σIm (l), MAC
    out = {m: {"f": np.full((nm, 4), np.nan), "shape": np.full((nm, l), np.nan + 0j),
               "sre": np.full((nm, l), np.nan), "sim": np.full((nm, l), np.nan), "mac": np.full(nm, np.nan)}
           for m in METHODS}
    for m, pool in (("modular", False), ("pooled", True)):
        res, _ = om.identify_modular(setups, fs=c.fs, p=P, orders=[ORDER], pool_references=pool)
        r = res[ORDER]
        for t, f0 in enumerate(c.frequency_hz):
            i = np.flatnonzero(np.abs(r["frequency_hz"] / f0 - 1) < 0.05)
            if i.size == 1:
                _fill(out[m], t, r, int(i[0]), truth[:, t], kref[t], l)
    pr = om.identify_poser(setups, fs=c.fs, p=P, order=ORDER, targets=c.frequency_hz, ref_index=kref)
    for t in range(nm):
        if np.isfinite(pr["frequency_hz"][t]):
            _fill(out["poser"], t, pr, t, truth[:, t], kref[t], l)
    return out


def _fill(o, t, r, i, true_shape, k, l):
    sh = r["mode_shape"][:, i]
    fac = r["factor"][i]
    if r["ref_index"][i] != k:       # renormalise at the true largest component, with its factor
        dsh = fac[2:2 + l] + 1j * fac[2 + l:]
        dsh = (dsh - np.outer(sh, dsh[k]) / sh[k]) / sh[k]      # (7.6) applied to ϕ̃
        dsh[k] = 0.0
        sh = sh / sh[k]
        fac = np.vstack([fac[:2], dsh.real, dsh.imag])
    std = np.sqrt(np.sum(fac ** 2, axis=1))
    o["f"][t] = r["frequency_hz"][i], std[0], r["damping_ratio"][i], std[1]
    o["shape"][t], o["sre"][t], o["sim"][t] = sh, std[2:2 + l], std[2 + l:]
    o["mac"][t] = np.abs(np.vdot(sh, true_shape)) ** 2 / (np.vdot(sh, sh).real * np.vdot(true_shape, true_shape).real)


def report(name, runs, truth_f, ref_idx):
    print(f"\n### {name}: {len(runs)} campaigns, order {ORDER}, p = q = {P}, {NB} blocks per setup\n")
    print("| mode | f (Hz) | method | found | std f (MC) | median σ_f | ratio | std ξ (MC) | median σ_ξ | ratio "
          "| shape ratio median [min, max] | MAC min / median |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for t, f0 in enumerate(truth_f):
        for m in METHODS:
            F = np.array([r[m]["f"][t] for r in runs])
            ok = np.isfinite(F[:, 0])
            sf, msf = np.std(F[ok, 0], ddof=1), np.median(F[ok, 1])
            sx, msx = np.std(F[ok, 2], ddof=1), np.median(F[ok, 3])
            S = np.array([r[m]["shape"][t] for r in runs])[ok]
            sre = np.array([r[m]["sre"][t] for r in runs])[ok]
            sim = np.array([r[m]["sim"][t] for r in runs])[ok]
            ratios = []
            for c in range(S.shape[1]):
                if c == ref_idx[t]:
                    continue
                ratios.append(np.median(sre[:, c]) / np.std(S[:, c].real, ddof=1))
                ratios.append(np.median(sim[:, c]) / np.std(S[:, c].imag, ddof=1))
            ratios = np.array(ratios)
            mac = np.array([r[m]["mac"][t] for r in runs])[ok]
            print(f"| {t + 1} | {f0:.2f} | {m} | {ok.sum()} | {sf:.2e} | {msf:.2e} | {msf / sf:.2f} | {sx:.2e} | "
                  f"{msx:.2e} | {msx / sx:.2f} | {np.median(ratios):.2f} [{ratios.min():.2f}, {ratios.max():.2f}] | "
                  f"{mac.min():.4f} / {np.median(mac):.4f} |")
    for t in range(len(truth_f)):
        line = []
        for m in ("modular", "pooled"):
            a = np.array([r[m]["f"][t, 1] / r["poser"]["f"][t, 1] for r in runs])
            b = np.array([r[m]["f"][t, 3] / r["poser"]["f"][t, 3] for r in runs])
            line.append(f"{m}/PoSER median σ_f {np.nanmedian(a):.2f}, σ_ξ {np.nanmedian(b):.2f}")
        print(f"mode {t + 1}: " + "; ".join(line))


def main(n=100, out_path=None, configs=None):
    results = {}
    for name, kw in CONFIGS.items():
        if configs and name not in configs:
            continue
        io = bool(kw)
        t0 = time.process_time()
        runs = [run_one(10_000 + s, kw, io) for s in range(n)]
        c = simulate_campaign(0, durations=(10.0,) * 6, **kw)
        Phi = c.mode_shape
        # true reference components in the global layout (the same in every campaign)
        setups = om.prepare_setups([(s.y, None) for s in c.setups], P, P, 2, [s.references for s in c.setups])
        camp = om.Campaign(setups, P, ORDER, uncertainty=False)
        names = [c.setups[j].channels[ch] for j, ch in camp.dofs]
        kref = np.argmax(np.abs(Phi[[c.dofs.index(nm) for nm in names]]), axis=0)
        report(name, runs, c.frequency_hz, kref)
        print(f"CPU time {time.process_time() - t0:.0f} s")
        results[name] = runs
    if out_path:
        np.savez(out_path, **{f"{k}_{m}_{key}": np.array([r[m][key] for r in v])
                              for k, v in results.items() for m in METHODS
                              for key in ("f", "shape", "sre", "sim", "mac")})
    return results


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100, sys.argv[2] if len(sys.argv) > 2 else None,
         sys.argv[3:] or None)
