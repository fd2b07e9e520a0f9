"""Monte Carlo of the C++ core's multi-setup σ: the modular merge (multisetup.hpp) against PoSER
(poser.hpp), issue 23; docs/multisetup.md "PoSER against modular", docs/uq-math.md §13.9.

N simulated deck campaigns (modaluq.simulate.campaign defaults: 24 DOFs, 6 setups of 5-6
sensors with references L3 and R8, 480-720 s each at 25 Hz, ambient level varying between
setups, 5 % sensor noise), output-only, or input/output with a measured force at L5
(unmeasured forces 0.3x it). Each campaign is identified at the true order 12 with p = q = 15
and 40 blocks per setup by the core: the modular merge (identify_setups) and PoSER (each setup
identified alone at order 12, its six modes merged by poser_merge, default options). Reported
per mode and method: the std of f and ξ over the campaigns (MC) against the median reported σ,
the median σ/σ_MC of the shape components (Re, Im, normalised at the true shape's largest
component), the smallest MAC with the true shape, how many campaigns the reference test
rejected (it must stay silent), and per mode the modular/PoSER ratio of σ_f and of the MC std.

With ``diagram``: the public API instead, as an engineer would run it: identify_setups with
block_rows=20, orders 2..40, the default n_blocks, then select_modes(), for both methods (PoSER:
each setup's own diagram and selection, its σ frozen at its own noise floor; modular: the merged
diagram, each setup's noise floor frozen, docs/uq-math.md §13.4, or not with ``unfrozen``); f, ξ
and their σ of each selected mode: median σ over the MC std, and the coverage of ±1.96 σ around
the true value. The modular merge's selection reports the σ of each cluster's mean (docs/uq-math.md
§13.10); a second table sets it beside the median of the cluster's σ (``cluster_std="median"``, the
selection before issue 23's fix) for the same selected values.

With ``diagram auto``: the engineer's call of issue 23, ``frequency_range=(0.5, 11)`` only (the
automatic block_rows, orders and n_blocks), the modular merge only.

Usage: OPENBLAS_NUM_THREADS=1 python studies/poser_mc.py [N] [diagram [unfrozen] [auto]] [output-only|input/output ...]
"""
import sys
import time
import warnings

import numpy as np

import modaluq
from modaluq import _core
from modaluq.settings import Settings
from modaluq.simulate.campaign import simulate_campaign

P, ORDER, NB = 15, 12, 40
CONFIGS = {"output-only": {}, "input/output": {"input_dofs": ("L5",), "input_std": 1.0, "unknown_input_std": 0.3}}
METHODS = ("modular", "poser")


def _setups(c, io):
    s = Settings(block_rows=P, orders=[ORDER], n_blocks=NB)
    out = []
    for st in c.setups:
        y = st.y
        u = st.u if io else None
        lay = s.layout(y.shape[1], 0 if u is None else u.shape[1])
        lay.references = [0, 1]
        u_t = np.empty((0, y.shape[0])) if u is None else np.ascontiguousarray(u.T)
        cov = _core.compute_covariances(y.T, u_t, lay, NB, True, True, 1)
        out.append(_core.SetupData(cov, [0, 1], c.fs))
    return out, s.to_core(c.fs)


def _theta(f, sf, x, sx, shape, cov, k, l):
    """(f, σf, ξ, σξ, shape normalised at k, σRe, σIm) with the covariance renormalised (7.6)."""
    n = 2 + 2 * l
    C = cov.reshape(n, n, order="F")
    J = np.zeros((n, n))
    J[0, 0] = J[1, 1] = 1.0
    sk = shape[k]
    for a in range(2 * l):  # real directions of the shape
        d = np.zeros(l, complex)
        d[a % l] = 1.0 if a < l else 1j
        dt = (d - shape * d[k] / sk) / sk
        dt[k] = 0.0
        J[2:2 + l, 2 + a], J[2 + l:, 2 + a] = dt.real, dt.imag
    sd = np.sqrt(np.clip(np.diag(J @ C @ J.T), 0, None))
    return f, sd[0], x, sd[1], shape / sk, sd[2:2 + l], sd[2 + l:]


def run_one(seed, kw, io):
    c = simulate_campaign(seed, **kw)
    setups, o = _setups(c, io)
    names = list(c.setups[0].channels[:2]) + [ch for st in c.setups for ch in st.channels[2:]]
    Phi = c.mode_shape[[c.dofs.index(n) for n in names]]
    kref = np.argmax(np.abs(Phi), axis=0)
    truth = Phi / Phi[kref, np.arange(Phi.shape[1])]
    nm, l = len(c.frequency_hz), len(names)
    out = {m: {"f": np.full((nm, 4), np.nan), "shape": np.full((nm, l), np.nan + 0j), "sre": np.full((nm, l), np.nan),
               "sim": np.full((nm, l), np.nan), "mac": np.full(nm, np.nan)} for m in METHODS}
    out["rejected"] = 0
    mod = _core.identify_setups(setups, o).modes[0]
    per = []
    for st in setups:
        m = _core.identify_covariances(st.covariances, o).modes[0]
        per.append(_core.PoserSetupModes(m.frequency_hz, m.damping_ratio, m.mode_shape, m.covariance, [0, 1]))
    pr = _core.poser_merge(per)
    out["rejected"] = int(np.asarray(pr.reference_rejected).sum())
    out["max_chi2"] = float(np.nanmax(np.asarray(pr.reference_chi2)))
    for meth, r in (("modular", mod), ("poser", pr)):
        for t, f0 in enumerate(c.frequency_hz):
            i = np.flatnonzero(np.abs(np.asarray(r.frequency_hz) / f0 - 1) < 0.05)
            if i.size != 1:
                continue
            i = int(i[0])
            th = _theta(r.frequency_hz[i], r.frequency_std[i], r.damping_ratio[i], r.damping_std[i],
                        np.asarray(r.mode_shape)[:, i], np.asarray(r.covariance)[:, i], kref[t], l)
            o_ = out[meth]
            o_["f"][t] = th[:4]
            o_["shape"][t], o_["sre"][t], o_["sim"][t] = th[4], th[5], th[6]
            sh, tr = th[4], truth[:, t]
            o_["mac"][t] = abs(np.vdot(sh, tr)) ** 2 / (np.vdot(sh, sh).real * np.vdot(tr, tr).real)
    return out, kref


def report(name, runs, truth_f, kref):
    print(f"\n### {name}: {len(runs)} campaigns, order {ORDER}, p = q = {P}, {NB} blocks per setup\n")
    print("| mode | f (Hz) | method | found | std f (MC) | median σ_f | σ_f/MC | std ξ (MC) | median σ_ξ | σ_ξ/MC "
          "| shape σ/MC median [min, max] | MAC min |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    summary = {}
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
                if c == kref[t]:
                    continue
                ratios += [np.median(sre[:, c]) / np.std(S[:, c].real, ddof=1),
                           np.median(sim[:, c]) / np.std(S[:, c].imag, ddof=1)]
            ratios = np.array(ratios)
            mac = np.array([r[m]["mac"][t] for r in runs])[ok]
            summary[(t, m)] = (sf, msf)
            print(f"| {t + 1} | {f0:.2f} | {m} | {ok.sum()} | {sf:.2e} | {msf:.2e} | {msf / sf:.2f} | {sx:.2e} | "
                  f"{msx:.2e} | {msx / sx:.2f} | {np.median(ratios):.2f} [{ratios.min():.2f}, {ratios.max():.2f}] | "
                  f"{mac.min():.4f} |")
    print("\n| mode | median σ_f modular/PoSER | std f (MC) modular/PoSER [16 %, 84 % bootstrap] |")
    print("|---|---|---|")
    rng = np.random.default_rng(0)
    for t in range(len(truth_f)):
        a = np.array([r["modular"]["f"][t, 1] / r["poser"]["f"][t, 1] for r in runs])
        fm = np.array([r["modular"]["f"][t, 0] for r in runs])
        fp = np.array([r["poser"]["f"][t, 0] for r in runs])
        ok = np.isfinite(fm) & np.isfinite(fp)
        fm, fp = fm[ok], fp[ok]
        boot = []
        for _ in range(2000):  # resampled campaigns: the two stds are of the same campaigns
            i = rng.integers(0, len(fm), len(fm))
            if np.unique(i).size > 1:  # (a resample of one campaign has no std)
                boot.append(np.std(fm[i], ddof=1) / np.std(fp[i], ddof=1))
        lo, hi = np.percentile(boot, [16, 84])
        print(f"| {t + 1} | {np.nanmedian(a):.2f} | {np.std(fm, ddof=1) / np.std(fp, ddof=1):.2f} "
              f"[{lo:.2f}, {hi:.2f}] |")
    chi = np.array([r["max_chi2"] for r in runs])
    print(f"\nreference test: {sum(r['rejected'] for r in runs)} rejections in {len(runs)} correct campaigns; "
          f"largest chi2 per campaign: median {np.median(chi):.1f}, max {chi.max():.1f}")


AUTO = {"frequency_range": (0.5, 11.0)}
DIAGRAM = {"block_rows": 20, "orders": range(2, 41, 2)}


def run_diagram(seed, kw, io, freeze_noise=True, auto=False):
    """f, σ_f, ξ, σ_ξ of the selected modes nearest each true mode, both methods, public API;
    under "shape" the shape normalised at the true shape's largest component and the σ of its
    real and imaginary parts (the covariance renormalised there, as ``_theta``)."""
    c = simulate_campaign(seed, **kw)
    frames = c.frames(input_names=["F5"] if io else ())
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for m in METHODS[:1] if auto else METHODS:
            r = modaluq.identify_setups(frames, fs=c.fs, references=["L3", "R8"], inputs=["F5"] if io else None,
                                        method=m, freeze_noise=freeze_noise, **(AUTO if auto else DIAGRAM))
            sel = r.select_modes()
            # the modular merge's selection reports the σ of the cluster's mean (docs/uq-math.md
            # §13.10); the median of its poles' σ (before issue 23's fix) from the same diagram
            alt = r.stabilization_diagram().select_modes(cluster_std="median") if m == "modular" else None
            names = list(sel.output_names)
            Phi = c.mode_shape[[c.dofs.index(n) for n in names]]
            kref = np.argmax(np.abs(Phi), axis=0)
            nm, l = len(c.frequency_hz), len(names)
            f = np.full((nm, 4), np.nan)
            f_alt = np.full((nm, 4), np.nan)
            shape = np.full((nm, 3, l), np.nan + 0j)  # shape, σ Re, σ Im
            for t, f0 in enumerate(c.frequency_hz):
                i = np.flatnonzero(np.abs(sel.frequency_hz / f0 - 1) < 0.05)
                if i.size == 1:
                    k = i[0]
                    f[t] = sel.frequency_hz[k], sel.frequency_std[k], sel.damping_ratio[k], sel.damping_std[k]
                    if alt is not None:
                        f_alt[t] = alt.frequency_hz[k], alt.frequency_std[k], alt.damping_ratio[k], alt.damping_std[k]
                    th = _theta(f[t, 0], f[t, 1], f[t, 2], f[t, 3], sel.mode_shape[:, k],
                                sel.mode_covariance[k].ravel(order="F"), kref[t], l)
                    shape[t] = th[4], th[5], th[6]
            out[m] = f
            if alt is not None:
                out[m + " median"] = f_alt
            out[m + " shape"] = shape
            out["kref"] = kref
    return out


def main_diagram(n, configs=None, freeze_noise=True, auto=False):
    results = {}
    for name, kw in CONFIGS.items():
        if configs and name not in configs:
            continue
        t0 = time.process_time()
        runs = []
        for s in range(n):
            runs.append(run_diagram(30_000 + s, kw, bool(kw), freeze_noise, auto))
            if (s + 1) % 10 == 0:
                print(f"  {name}: {s + 1}/{n} campaigns, {time.process_time() - t0:.0f} CPU s", file=sys.stderr, flush=True)
        results[name] = runs
        truth = simulate_campaign(0, durations=(10.0,) * 6)
        how = "frequency_range (0.5, 11) Hz only" if auto else "orders 2..40, block_rows 20, default n_blocks"
        print(f"\n### {name}, diagram ({how}, {'frozen' if freeze_noise else 'unfrozen'} merge): {n} campaigns\n")
        print("| mode | f (Hz) | found modular / PoSER | σ_f/MC modular | σ_f/MC PoSER | σ_ξ/MC modular | σ_ξ/MC PoSER "
              "| coverage f modular / PoSER | coverage ξ modular / PoSER | shape σ/MC modular, median [min, max] "
              "| shape σ/MC PoSER | median σ_f modular/PoSER | MC std f modular/PoSER |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for t, (f0, x0) in enumerate(zip(truth.frequency_hz, truth.damping_ratio)):
            row = {}
            for m in METHODS:
                if m not in runs[0]:  # auto: the modular merge only
                    row[m] = (0,) + (np.nan,) * 8
                    continue
                F = np.array([r[m][t] for r in runs])
                F = F[np.isfinite(F[:, 0])]
                sf, sx = np.std(F[:, 0], ddof=1), np.std(F[:, 2], ddof=1)
                cov_f = np.mean(np.abs(F[:, 0] - f0) <= 1.96 * F[:, 1])
                cov_x = np.mean(np.abs(F[:, 2] - x0) <= 1.96 * F[:, 3])
                S = np.array([r[m + " shape"][t] for r in runs])
                S = S[np.isfinite(S[:, 0, 0])]
                ratios = [np.median(S[:, 1 + part, c].real) / np.std(getattr(S[:, 0, c], name), ddof=1)
                          for c in range(S.shape[2]) if c != runs[0]["kref"][t]
                          for part, name in ((0, "real"), (1, "imag"))]
                row[m] = (len(F), sf, np.median(F[:, 1]) / sf, np.median(F[:, 3]) / sx, cov_f, cov_x,
                          np.median(ratios), np.min(ratios), np.max(ratios))
            a = np.array([r["modular"][t, 1] / r["poser"][t, 1] if "poser" in r else np.nan for r in runs])
            M, Q = row["modular"], row["poser"]
            print(f"| {t + 1} | {f0:.2f} | {M[0]} / {Q[0]} | {M[2]:.2f} | {Q[2]:.2f} | {M[3]:.2f} | {Q[3]:.2f} | "
                  f"{100 * M[4]:.0f} / {100 * Q[4]:.0f} % | {100 * M[5]:.0f} / {100 * Q[5]:.0f} % | "
                  f"{M[6]:.2f} [{M[7]:.2f}, {M[8]:.2f}] | {Q[6]:.2f} [{Q[7]:.2f}, {Q[8]:.2f}] | "
                  f"{np.nanmedian(a) if np.isfinite(a).any() else np.nan:.2f} | {M[1] / Q[1]:.2f} |")
        print("\nModular σ of the selected modes (same values): the σ of the cluster's mean (default) and the "
              "median of its poles' σ (before); σ_ξ/MC robust: over 1.4826 × the MAD of ξ\n")
        print("| mode | σ_f/MC mean / median | σ_ξ/MC mean / median | σ_ξ/MC robust mean / median "
              "| coverage f mean / median | coverage ξ mean / median |")
        print("|---|---|---|---|---|---|")
        for t, (f0, x0) in enumerate(zip(truth.frequency_hz, truth.damping_ratio)):
            cells = []
            for key in ("modular", "modular median"):
                F = np.array([r[key][t] for r in runs])
                F = F[np.isfinite(F[:, 0])]
                sf, sx = np.std(F[:, 0], ddof=1), np.std(F[:, 2], ddof=1)
                mad = 1.4826 * np.median(np.abs(F[:, 2] - np.median(F[:, 2])))
                cells.append((np.median(F[:, 1]) / sf, np.median(F[:, 3]) / sx, np.median(F[:, 3]) / mad,
                              np.mean(np.abs(F[:, 0] - f0) <= 1.96 * F[:, 1]),
                              np.mean(np.abs(F[:, 2] - x0) <= 1.96 * F[:, 3])))
            a, b = cells
            print(f"| {t + 1} | {a[0]:.2f} / {b[0]:.2f} | {a[1]:.2f} / {b[1]:.2f} | {a[2]:.2f} / {b[2]:.2f} | "
                  f"{100 * a[3]:.0f} / {100 * b[3]:.0f} % | {100 * a[4]:.0f} / {100 * b[4]:.0f} % |")
        print(f"CPU time {time.process_time() - t0:.0f} s")
    return results


def main(n=100, configs=None):
    if configs and "diagram" in configs:
        return main_diagram(n, [c for c in configs if c not in ("diagram", "unfrozen", "auto")], "unfrozen" not in configs,
                            "auto" in configs)
    results = {}
    for name, kw in CONFIGS.items():
        if configs and name not in configs:
            continue
        t0 = time.process_time()
        runs, kref = [], None
        for s in range(n):
            out, kref = run_one(20_000 + s, kw, bool(kw))
            runs.append(out)
        report(name, runs, simulate_campaign(0, durations=(10.0,) * 6).frequency_hz, kref)
        print(f"CPU time {time.process_time() - t0:.0f} s")
        results[name] = runs
    return results


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100, sys.argv[2:] or None)
