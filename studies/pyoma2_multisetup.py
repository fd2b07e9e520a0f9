"""Cross-check of the multi-setup merge with pyOMA2 (issue 23; docs/multisetup.md "Cross-check
with pyOMA2").

The same simulated deck campaigns (modaluq.simulate.campaign defaults: 24 DOFs, 6 setups of 5-6
sensors with references L3 and R8, 480-720 s each at 25 Hz, ambient level varying between setups,
5 % sensor noise, output-only; seeds 40000, 40001, ...) identified by four merges, all SSI-cov with
block_rows 20 (pyOMA2 ``br=20``: the same H, lags 1..39, references L3 and R8 as the past
channels) and read at the true order 12 and at order 36, the pole nearest each true frequency
(within 5 %, among those with 0 < ξ < 20 %: pyOMA2 drops the others) taken as the mode:

- modaluq modular: ``identify_setups(..., block_rows=20, orders=range(2, 41, 2))``, then
  ``Result.at_order(n)``; the merge is redone at each order (docs/uq-math.md §13.2);
- pyOMA2 PreGER: ``MultiSetup_PreGER`` + ``SSI_MS(method="cov", br=20, ordmax=...)``, then
  ``mpe(sel_freq=true f, order_in=n)``, twice: with ``ordmax = n`` (the merge at order n: the
  same algorithm as modaluq's) and with ``ordmax = 40`` read at n (one stabilization diagram to
  40, as an engineer runs it: pyOMA2 aligns the setups once at ordmax and reads the lower orders
  from the leading columns of that merge, ``functions/ssi.py: SSI_multi_setup``);
- modaluq PoSER: each setup of ``identify_setups(..., method="poser")`` at order n, the poles
  nearest the true frequencies merged by the core (``_core.poser_merge``: inverse-variance f and
  ξ, complex least-squares scale on the references, σ propagated);
- pyOMA2 PoSER: ``SingleSetup`` + ``SSI(method="cov", br=20, ref_ind=[0, 1])`` per setup,
  ``mpe`` at order n, ``MultiSetup_PoSER.merge_results()`` (plain means of f and ξ over the
  setups, real modal scale factor on the references); its ``Fn_std`` is the spread between
  the setups. The same shapes are merged once more with the scale factor of the earlier pyOMA2
  sources that its issue #55 reports (``MSF(anchor refs, setup refs)``; 1.4.3 has
  ``MSF(setup refs, anchor refs)``) to show that bug's effect on these records.

Printed: per order and mode, each merge's f and ξ (mean and std over the campaigns), MAC of its
global shape (24 DOFs, matched by DOF name: pyOMA2's global order is rebuilt from its own
rules, references of setup 0 then each setup's other channels) with the true shape, modaluq's
median σ; the differences between the tools for the same method; pyOMA2's PreGER at order 12
against its ``ordmax``; the per-setup identifications of both tools against each other.

pyOMA2 (PyPI ``pyOMA-2``) is not a dependency of modaluq and lives in its own venv. The script
runs either in one process, if both import (modaluq through PYTHONPATH in pyOMA2's venv), or
in two: modaluq in its venv, pyOMA2 in a child process of the ``--peer`` interpreter
(``$PYOMA2_PYTHON``), the records and the results exchanged as .npz files in a temporary folder
(``--keep DIR`` keeps them). The child imports numpy and pyOMA2 only. Without pyOMA2 anywhere it
prints modaluq's columns only.

Usage (about 2 CPU s per campaign, half of it pyOMA2's; 10 campaigns ~20 s of one core):
    OPENBLAS_NUM_THREADS=1 TQDM_DISABLE=1 python studies/pyoma2_multisetup.py [N_SEEDS] [--peer PYTHON] [--keep DIR]
e.g. ``.venv/bin/python studies/pyoma2_multisetup.py 10 --peer /work/wt/peers/bin/python``.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import tempfile
import time

import numpy as np

SEED0 = 40_000
BR = 20                  #: block rows (modaluq block_rows = past_block_rows; pyOMA2 br)
ORDERS = (12, 36)        #: the orders read: the true order and one where an engineer reads a diagram
DIAGRAM_MAX = 40         #: the diagram's largest order (p r = 20 x 2: the largest the merge allows)
ORDMAX_SCAN = (12, 24, 30, 36, 40)  #: pyOMA2 PreGER runs; each is read at order 12
N_REFS = 2               #: the references are the first two columns of every setup (L3, R8)
TOL = 0.05               #: a mode is the pole nearest the true frequency, within 5 %
HC = {"xi_max": 0.2, "mpc_lim": None, "mpd_lim": None, "CoV_max": None}  #: pyOMA2: no hard criteria but ξ < 20 %
TOOLS = ("modaluq modular", "pyOMA2 PreGER, ordmax = n", f"pyOMA2 PreGER, diagram to {DIAGRAM_MAX}",
         "modaluq PoSER", "pyOMA2 PoSER")


def _nearest(freqs, targets, xi=None):
    """For each target frequency, the index of the nearest entry of freqs within TOL, else -1; with
    damping ratios xi, only poles with 0 < ξ < HC["xi_max"] (pyOMA2 drops the others: HC_damp)."""
    f = np.asarray(freqs, float)
    out = np.full(len(targets), -1)
    if f.size == 0:
        return out
    for t, f0 in enumerate(targets):
        d = np.abs(f / f0 - 1)
        d[~np.isfinite(d)] = np.inf
        if xi is not None:
            d[~((np.asarray(xi) > 0) & (np.asarray(xi) < HC["xi_max"]))] = np.inf
        i = int(np.argmin(d))
        if d[i] < TOL:
            out[t] = i
    return out


def _aligned(f, xi, phi, targets, n_dofs):
    """f, ξ (n_targets,) and shapes (n_dofs, n_targets) of the entries nearest each target (NaN where none)."""
    idx = _nearest(f, targets)
    F, X = np.full(len(targets), np.nan), np.full(len(targets), np.nan)
    P = np.full((n_dofs, len(targets)), np.nan + 0j)
    for t, i in enumerate(idx):
        if i >= 0:
            F[t], X[t], P[:, t] = f[i], xi[i], phi[:, i]
    return F, X, P


# ----------------------------------------------------------------------------------------------
# pyOMA2 (numpy and pyoma2 only: this part runs in pyOMA2's venv)


def pyoma2_global_names(channels, ref_ind):
    """pyOMA2's global DOF order (pre_multisetup / SSI_multi_setup / merge_mode_shapes): the
    references of setup 0 in ref_ind order, then each setup's other channels in column order."""
    names = [channels[0][i] for i in ref_ind[0]]
    for ch, ref in zip(channels, ref_ind):
        names += [c for k, c in enumerate(ch) if k not in ref]
    return names


def pyoma2_campaign(ys, channels, fs, targets):
    """pyOMA2's PreGER and PoSER on one campaign (records ys, demeaned). Returns a dict of arrays."""
    import logging

    from pyoma2.algorithms import SSI, SSI_MS
    from pyoma2.functions.gen import MSF
    from pyoma2.setup import MultiSetup_PoSER, MultiSetup_PreGER, SingleSetup

    logging.getLogger("pyoma2").setLevel(logging.WARNING)
    for h in logging.getLogger().handlers:  # pyOMA2 installs an INFO handler on the root logger
        h.setLevel(logging.WARNING)
    ref_ind = [list(range(N_REFS)) for _ in ys]
    names = pyoma2_global_names(channels, ref_ind)
    l_g = len(names)
    out = {"names": np.array(names)}
    sel = [float(f) for f in targets]

    # PreGER: one run per ordmax, read at order 12 (and at 36 from the runs that reach it)
    for om in sorted(set(ORDMAX_SCAN) | set(ORDERS) | {DIAGRAM_MAX}):
        ms = MultiSetup_PreGER(fs=fs, ref_ind=ref_ind, datasets=[np.array(y) for y in ys])
        alg = SSI_MS(name="ssi", method="cov", br=BR, ordmin=0, ordmax=om, step=1, hc=HC)
        ms.add_algorithms(alg)
        ms.run_by_name("ssi")
        for n in ORDERS:
            if n > om:
                continue
            alg.mpe(sel_freq=sel, order_in=int(n))  # drops a mode it cannot find (and shortens Fn)
            r = alg.result
            phi = np.asarray(r.Phi).reshape(l_g, -1)
            F, X, P = _aligned(np.asarray(r.Fn), np.asarray(r.Xi), phi, targets, l_g)
            # the same pick straight from the poles of order n (the check of mpe's pick)
            fp = np.asarray(r.Fn_poles)[:, n]
            F2, _, _ = _aligned(fp, np.asarray(r.Xi_poles)[:, n], np.asarray(r.Phi_poles)[:, n, :].T, targets, l_g)
            key = f"preger_om{om}_n{n}"
            out[key + "_f"], out[key + "_xi"], out[key + "_phi"], out[key + "_fpoles"] = F, X, P, F2

    # PoSER: every setup alone (single-setup orders are exact truncations: ordmax 40 once), mpe at n
    singles = []
    for y in ys:
        s = SingleSetup(np.array(y), fs=fs)
        a = SSI(name="ssi", method="cov", br=BR, ref_ind=list(range(N_REFS)), ordmin=0, ordmax=DIAGRAM_MAX,
                step=1, hc=HC)
        s.add_algorithms(a)
        s.run_by_name("ssi")
        singles.append(s)
    for n in ORDERS:
        per_f, per_x, per_phi = [], [], []
        for s, ch in zip(singles, channels):
            a = s.algorithms["ssi"]
            a.mpe(sel_freq=sel, order_in=int(n))
            F, X, P = _aligned(np.asarray(a.result.Fn), np.asarray(a.result.Xi),
                               np.asarray(a.result.Phi).reshape(len(ch), -1), targets, len(ch))
            per_f.append(F)
            per_x.append(X)
            per_phi.append(P)
        po = MultiSetup_PoSER(ref_ind=ref_ind, single_setups=singles, names=["ssi"])
        r = po.merge_results()["ssi"]
        key = f"poser_n{n}"
        F, X, P = _aligned(np.asarray(r.Fn), np.asarray(r.Xi), np.asarray(r.Phi), targets, l_g)
        idx = _nearest(np.asarray(r.Fn), targets)
        out[key + "_f"], out[key + "_xi"], out[key + "_phi"] = F, X, P
        out[key + "_fstd"] = np.array([r.Fn_std[i] if i >= 0 else np.nan for i in idx])
        out[key + "_xistd"] = np.array([r.Xi_std[i] if i >= 0 else np.nan for i in idx])
        out[key + "_nsetups"] = np.array([len(r.setups_used[i]) if i >= 0 else 0 for i in idx])
        out[key + "_setup_f"] = np.array(per_f)          # (n_setups, n_targets)
        out[key + "_setup_xi"] = np.array(per_x)
        # the merge of the sources before the fix of issue #55: MSF(anchor refs, setup refs)
        old = np.full((l_g, len(targets)), np.nan + 0j)
        alpha_old, alpha_new = np.full((len(ys), len(targets)), np.nan), np.full((len(ys), len(targets)), np.nan)
        alpha_old[0], alpha_new[0] = 1.0, 1.0
        for t in range(len(targets)):
            if not all(np.isfinite(p[:, t]).all() for p in per_phi):
                continue
            ref1 = per_phi[0][ref_ind[0], t]
            parts = [ref1, np.delete(per_phi[0][:, t], ref_ind[0])]
            for j in range(1, len(per_phi)):
                alpha = MSF(ref1, per_phi[j][ref_ind[j], t])[0]                  # before the fix
                alpha_old[j, t], alpha_new[j, t] = alpha, MSF(per_phi[j][ref_ind[j], t], ref1)[0]  # 1.4.3
                parts.append(alpha * np.delete(per_phi[j][:, t], ref_ind[j]))
            old[:, t] = np.concatenate(parts)
        out[key + "_phi_prefix"] = old
        out[key + "_alpha_ratio"] = alpha_old / alpha_new  # (n_setups, n_targets), 1 for setup 0
    return out


def _pyoma2_worker(folder):
    """Child mode: every campaign_*.npz of folder through pyOMA2, results to pyoma2_*.npz."""
    for name in sorted(os.listdir(folder)):
        if not (name.startswith("campaign_") and name.endswith(".npz")):
            continue
        d = np.load(os.path.join(folder, name))
        n_setups = int(d["n_setups"])
        ys = [d[f"y{j}"] for j in range(n_setups)]
        channels = [list(d[f"channels{j}"]) for j in range(n_setups)]
        out = pyoma2_campaign(ys, channels, float(d["fs"]), d["targets"])
        np.savez(os.path.join(folder, "pyoma2_" + name[len("campaign_"):]), **out)


def _has_pyoma2():
    try:
        import pyoma2  # noqa: F401
    except ImportError:
        return False
    return True


# ----------------------------------------------------------------------------------------------
# modaluq


def modaluq_campaign(camp):
    """modaluq's modular merge and PoSER on one campaign, read at ORDERS. Returns a dict of arrays."""
    import warnings

    import modaluq
    from modaluq import _core

    targets = camp.frequency_hz
    frames = camp.frames()
    refs = list(camp.setups[0].channels[:N_REFS])
    kw = dict(fs=camp.fs, references=refs, block_rows=BR, orders=range(2, DIAGRAM_MAX + 1, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the per-setup "blocks shorter than the decay" notes of PoSER's setups
        mod = modaluq.identify_setups(frames, **kw)
        pos = modaluq.identify_setups(frames, method="poser", **kw)
    out = {"names": np.array(mod.output_names), "poser_names": np.array(pos.output_names)}
    l_g = len(mod.output_names)
    for n in ORDERS:
        m = mod.at_order(n)
        idx = _nearest(m.frequency_hz, targets, m.damping_ratio)
        key = f"modular_n{n}"
        for name, arr in (("f", m.frequency_hz), ("xi", m.damping_ratio), ("sf", m.frequency_std),
                          ("sxi", m.damping_std)):
            out[f"{key}_{name}"] = np.array([arr[i] if i >= 0 else np.nan for i in idx])
        out[key + "_phi"] = np.column_stack([m.mode_shape[:, i] if i >= 0 else np.full(l_g, np.nan + 0j) for i in idx])
        # PoSER at order n: each setup's poles nearest the true frequencies, merged by the core
        per, setup_f, setup_info = [], [], []
        for res in pos.setups:
            if tuple(res.output_names[:N_REFS]) != tuple(refs):
                raise RuntimeError(f"references are not the first channels of a setup: {res.output_names}")
            s = res.at_order(n)
            i = _nearest(s.frequency_hz, targets, s.damping_ratio)
            setup_f.append([s.frequency_hz[k] if k >= 0 else np.nan for k in i])
            truth = camp.mode_shape[[camp.dofs.index(c) for c in res.output_names]]
            # per pick: MAC of the setup's own shape with the truth on its channels, ξ, σ_f
            setup_info.append([(_mac(s.mode_shape[:, k], truth[:, t]), s.damping_ratio[k], s.frequency_std[k])
                               if k >= 0 else (np.nan,) * 3 for t, k in enumerate(i)])
            i = i[i >= 0]
            cov = np.stack([s.covariance[k].reshape(-1, order="F") for k in i], axis=1)
            per.append(_core.PoserSetupModes(s.frequency_hz[i], s.damping_ratio[i], s.mode_shape[:, i], cov,
                                             list(range(N_REFS))))
        r = _core.poser_merge(per, _core.PoserOptions())
        idx = _nearest(np.asarray(r.frequency_hz), targets)
        key = f"poser_n{n}"
        shape = np.asarray(r.mode_shape)
        for name, arr in (("f", r.frequency_hz), ("xi", r.damping_ratio), ("sf", r.frequency_std),
                          ("sxi", r.damping_std)):
            arr = np.asarray(arr)
            out[f"{key}_{name}"] = np.array([arr[i] if i >= 0 else np.nan for i in idx])
        out[key + "_phi"] = np.column_stack([shape[:, i] if i >= 0 else np.full(l_g, np.nan + 0j) for i in idx])
        out[key + "_setup_f"] = np.array(setup_f)
        out[key + "_setup_info"] = np.array(setup_info)  # (n_setups, n_targets, 3)
    return out


# ----------------------------------------------------------------------------------------------
# comparison


def _mac(a, b):
    """MAC of complex a with b (NaN if a has NaN)."""
    if not np.all(np.isfinite(a)):
        return np.nan
    return float(abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real))


def _by_name(phi, names, order):
    """Rows of phi (over names) rearranged to the DOF order ``order``."""
    pos = {n: k for k, n in enumerate(names)}
    return phi[[pos[n] for n in order]]


def _collect(mq_runs, po_runs, camp0):
    """Per (tool, order): f, ξ, σf, σξ (n_seeds, n_modes) and MAC with the truth; over DECK_DOFS."""
    dofs = list(camp0.dofs)
    truth = camp0.mode_shape
    rows = {}
    for n in ORDERS:
        sources = {"modaluq modular": (mq_runs, f"modular_n{n}", "names"),
                   "modaluq PoSER": (mq_runs, f"poser_n{n}", "poser_names")}
        if po_runs is not None:
            sources.update({"pyOMA2 PreGER, ordmax = n": (po_runs, f"preger_om{n}_n{n}", "names"),
                            f"pyOMA2 PreGER, diagram to {DIAGRAM_MAX}": (po_runs, f"preger_om{DIAGRAM_MAX}_n{n}", "names"),
                            "pyOMA2 PoSER": (po_runs, f"poser_n{n}", "names")})
        for tool, (runs, key, names_key) in sources.items():
            f = np.array([r[key + "_f"] for r in runs])
            x = np.array([r[key + "_xi"] for r in runs])
            phi = np.array([_by_name(r[key + "_phi"], list(r[names_key]), dofs) for r in runs])  # (seeds, 24, modes)
            mac = np.array([[_mac(p[:, t], truth[:, t]) for t in range(truth.shape[1])] for p in phi])
            d = {"f": f, "xi": x, "phi": phi, "mac": mac}
            if key + "_sf" in runs[0]:
                d["sf"] = np.array([r[key + "_sf"] for r in runs])
                d["sxi"] = np.array([r[key + "_sxi"] for r in runs])
            if tool == "pyOMA2 PoSER":
                d["fstd"] = np.array([r[key + "_fstd"] for r in runs])
                d["mac_prefix"] = np.array([[_mac(p[:, t], truth[:, t]) for t in range(truth.shape[1])] for p in
                                            [_by_name(r[key + "_phi_prefix"], list(r["names"]), dofs) for r in runs]])
            rows[(tool, n)] = d
    return rows


def _fmt(v, digits):
    return "—" if not np.isfinite(v) else f"{v:.{digits}f}"


def report(rows, camp0, n_seeds, po_runs, mq_runs, seed0=SEED0):
    f0s, x0s = camp0.frequency_hz, camp0.damping_ratio
    tools = [t for t in TOOLS if (t, ORDERS[0]) in rows]
    for n in ORDERS:
        print(f"\n### order {n}: {n_seeds} campaigns, block_rows {BR}, the pole nearest each true frequency\n")
        print("| mode | true f (Hz) | true ξ (%) | merge | found | f (Hz), mean ± std | ξ (%), mean ± std "
              "| MAC with truth, mean [min] | modaluq median σ_f (Hz) | modaluq median σ_ξ (%) |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for t, (f0, x0) in enumerate(zip(f0s, x0s)):
            for tool in tools:
                d = rows[(tool, n)]
                f, x, mac = d["f"][:, t], d["xi"][:, t], d["mac"][:, t]
                ok = np.isfinite(f)
                k = int(ok.sum())
                sf = _fmt(np.median(d["sf"][ok, t]), 4) if "sf" in d and k else ""
                sx = _fmt(100 * np.median(d["sxi"][ok, t]), 2) if "sxi" in d and k else ""
                if k:
                    fs = f"{np.mean(f[ok]):.4f} ± {np.std(f[ok], ddof=1) if k > 1 else np.nan:.4f}"
                    xs = f"{100 * np.mean(x[ok]):.2f} ± {100 * np.std(x[ok], ddof=1) if k > 1 else np.nan:.2f}"
                    ms = f"{np.nanmean(mac):.4f} [{np.nanmin(mac):.4f}]"
                    if np.isnan(mac[ok]).any():  # a merged mode without some setups' DOFs (pyOMA2's match_modes)
                        ms += f" ({int(np.isnan(mac[ok]).sum())} without every DOF)"
                else:
                    fs = xs = ms = "—"
                print(f"| {t + 1} | {f0:.2f} | {100 * x0:.1f} | {tool} | {k}/{len(f)} | {fs} | {xs} | {ms} | {sf} | {sx} |")
    if po_runs is None:
        print("\n(pyOMA2 not available: give --peer PYTHON or run in a venv with pyOMA2)")
        return

    print("\n### pyOMA2 against modaluq, the same method (Δf/f = f_pyOMA2 / f_modaluq − 1, Δξ/ξ alike, "
          "1 − MAC between the two shapes)\n")
    print("| order | mode | PreGER (ordmax = n) vs modular: largest abs Δf/f, Δξ/ξ, 1 − MAC "
          f"| PreGER (diagram to {DIAGRAM_MAX}) vs modular: mean Δf/f, mean Δξ/ξ, largest 1 − MAC "
          "| PoSER vs PoSER: largest abs Δf/f, Δξ/ξ, 1 − MAC |")
    print("|---|---|---|---|---|")
    for n in ORDERS:
        M = rows[("modaluq modular", n)]
        pairs = [(M, rows[("pyOMA2 PreGER, ordmax = n", n)]), (M, rows[(f"pyOMA2 PreGER, diagram to {DIAGRAM_MAX}", n)]),
                 (rows[("modaluq PoSER", n)], rows[("pyOMA2 PoSER", n)])]
        for t in range(len(f0s)):
            cells = []
            for c, (a, b) in enumerate(pairs):
                df = b["f"][:, t] / a["f"][:, t] - 1  # pyOMA2 relative to modaluq
                dx = b["xi"][:, t] / a["xi"][:, t] - 1
                dm = np.array([max(0.0, 1 - _mac(p[:, t], q[:, t])) if np.all(np.isfinite(q[:, t])) else np.nan
                               for p, q in zip(a["phi"], b["phi"])])
                if not np.isfinite(df).any():
                    cells.append("—")
                elif c == 1:
                    cells.append(f"{np.nanmean(df):+.1e}, {np.nanmean(dx):+.1e}, {np.nanmax(dm):.1e}")
                else:
                    cells.append(f"{np.nanmax(abs(df)):.1e}, {np.nanmax(abs(dx)):.1e}, {np.nanmax(dm):.1e}")
            print(f"| {n} | {t + 1} | " + " | ".join(cells) + " |")

    print("\n### the single setups before the PoSER merge: modaluq's and pyOMA2's f per setup and mode\n")
    for n in ORDERS:
        a = np.array([r[f"poser_n{n}_setup_f"] for r in mq_runs])
        b = np.array([r[f"poser_n{n}_setup_f"] for r in po_runs])
        both = np.isfinite(a) & np.isfinite(b)
        print(f"order {n}: {int(both.sum())} (campaign, setup, mode) found by both, {int((np.isfinite(a) != np.isfinite(b)).sum())} "
              f"by one only; largest abs Δf/f {np.max(abs(a[both] / b[both] - 1)):.1e}")
        info = np.array([r[f"poser_n{n}_setup_info"] for r in mq_runs])  # (seeds, setups, modes, 3)
        for c, j, t in np.argwhere(info[..., 0] < 0.95):
            print(f"  seed {seed0 + c}, setup {j}, mode {t + 1}: the pick at {a[c, j, t]:.4f} Hz is spurious (ξ "
                  f"{100 * info[c, j, t, 1]:.2f} %, modaluq σ_f {info[c, j, t, 2]:.3f} Hz, MAC with the true shape on "
                  f"the setup's channels {info[c, j, t, 0]:.2f})")

    for n in ORDERS:
        for c, r in enumerate(po_runs):
            for t in np.flatnonzero(r[f"poser_n{n}_nsetups"] < len(r[f"poser_n{n}_setup_f"])):
                print(f"  order {n}, seed {seed0 + c}, mode {t + 1}: pyOMA2's merged mode nearest the true f "
                      f"({r[f'poser_n{n}_f'][t]:.4f} Hz, ξ {100 * r[f'poser_n{n}_xi'][t]:.2f} %) merges "
                      f"{r[f'poser_n{n}_nsetups'][t]} setup(s) only (match_modes: reference MAC < 0.5)")

    print("\n### pyOMA2 PoSER: its Fn_std (the std between the setups) against the scatter of its merged f over the campaigns\n")
    print("| order | mode | median Fn_std (Hz) | std of merged f over campaigns (Hz) | ratio "
          "| modaluq PoSER: median σ_f / its std over campaigns |")
    print("|---|---|---|---|---|---|")
    for n in ORDERS:
        P, Q = rows[("pyOMA2 PoSER", n)], rows[("modaluq PoSER", n)]
        for t in range(len(f0s)):
            s = np.nanstd(P["f"][:, t], ddof=1)
            print(f"| {n} | {t + 1} | {np.nanmedian(P['fstd'][:, t]):.4f} | {s:.4f} | {np.nanmedian(P['fstd'][:, t]) / s:.1f} "
                  f"| {np.nanmedian(Q['sf'][:, t]) / np.nanstd(Q['f'][:, t], ddof=1):.2f} |")

    print(f"\n### pyOMA2 PreGER read at order 12 against the diagram's ordmax ({n_seeds} campaigns)\n")
    print("| ordmax | " + " | ".join(f"mode {t + 1}: found, mean ξ (%), min MAC" for t in range(len(f0s))) + " |")
    print("|---|" + "---|" * len(f0s))
    dofs = list(camp0.dofs)
    for om in ORDMAX_SCAN:
        key = f"preger_om{om}_n12"
        cells = []
        for t in range(len(f0s)):
            f = np.array([r[key + "_f"][t] for r in po_runs])
            x = np.array([r[key + "_xi"][t] for r in po_runs])
            mac = np.array([_mac(_by_name(r[key + "_phi"], list(r["names"]), dofs)[:, t], camp0.mode_shape[:, t])
                            for r in po_runs])
            ok = np.isfinite(f)
            cells.append(f"{int(ok.sum())}, {100 * np.mean(x[ok]):.2f}, {np.nanmin(mac):.3f}" if ok.any() else "0")
        print(f"| {om} | " + " | ".join(cells) + " |")
    miss = sum(int(np.sum(np.isfinite(r[f"preger_om{om}_n12_fpoles"]) != np.isfinite(r[f"preger_om{om}_n12_f"])))
               for r in po_runs for om in ORDMAX_SCAN)
    print(f"\n(mpe's pick against the nearest pole of the order: {miss} disagreement(s))")

    print("\n### pyOMA2 PoSER shapes merged with the scale factor before the fix of its issue #55 "
          "(MSF(anchor refs, setup refs)): MAC with truth, mean [min]; its scale over 1.4.3's, median [range] "
          "over the setups 1-5 of every campaign\n")
    for n in ORDERS:
        P = rows[("pyOMA2 PoSER", n)]
        ratio = np.array([r[f"poser_n{n}_alpha_ratio"][1:] for r in po_runs])  # (seeds, setups 1.., modes)
        print(f"order {n}: " + "; ".join(
            f"mode {t + 1} {np.nanmean(P['mac_prefix'][:, t]):.4f} [{np.nanmin(P['mac_prefix'][:, t]):.4f}], "
            f"scale {np.nanmedian(ratio[:, :, t]):.2f} [{np.nanmin(ratio[:, :, t]):.2f}, {np.nanmax(ratio[:, :, t]):.2f}]"
            for t in range(len(f0s))))


def main(n_seeds=10, seed0=SEED0, peer_python=None, keep=None):
    from modaluq.simulate.campaign import simulate_campaign

    t0 = time.process_time()
    in_process = _has_pyoma2()
    peer = None if in_process else (peer_python or os.environ.get("PYOMA2_PYTHON"))
    folder_ctx = tempfile.TemporaryDirectory(prefix="pyoma2_multisetup_") if keep is None else None
    folder = keep if keep is not None else folder_ctx.name
    os.makedirs(folder, exist_ok=True)
    mq_runs, po_runs = [], [] if (in_process or peer) else None
    camp0 = None
    try:
        for s in range(n_seeds):
            camp = simulate_campaign(seed0 + s)
            camp0 = camp0 or camp
            mq_runs.append(modaluq_campaign(camp))
            ys = [st.y - st.y.mean(axis=0) for st in camp.setups]  # modaluq removes each record's mean (demean=True)
            if in_process:
                po_runs.append(pyoma2_campaign(ys, [list(st.channels) for st in camp.setups], camp.fs, camp.frequency_hz))
            elif peer:
                np.savez(os.path.join(folder, f"campaign_{s:04d}.npz"), fs=camp.fs, targets=camp.frequency_hz,
                         n_setups=len(ys), **{f"y{j}": y for j, y in enumerate(ys)},
                         **{f"channels{j}": np.array(st.channels) for j, st in enumerate(camp.setups)})
        t_main = time.process_time() - t0
        if peer:
            env = dict(os.environ, OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS", "1"),
                       OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "1"), TQDM_DISABLE="1")
            env.pop("PYTHONPATH", None)  # the child needs numpy and pyOMA2 only
            subprocess.run([peer, os.path.abspath(__file__), "--worker", folder], check=True, env=env)
            po_runs = [dict(np.load(os.path.join(folder, f"pyoma2_{s:04d}.npz"))) for s in range(n_seeds)]
        rows = _collect(mq_runs, po_runs, camp0)
        report(rows, camp0, n_seeds, po_runs, mq_runs, seed0)
    finally:
        if folder_ctx is not None:
            folder_ctx.cleanup()
    child = resource.getrusage(resource.RUSAGE_CHILDREN)
    how = "one process" if in_process else (f"pyOMA2 in {peer}" if peer else "modaluq only")
    what = "simulation, modaluq and pyOMA2" if in_process else "simulation and modaluq"
    print(f"\nCPU time: {time.process_time() - t0:.1f} s in this process ({how}; {what} {t_main:.1f} s), "
          f"{child.ru_utime + child.ru_stime:.1f} s in the pyOMA2 child")
    return {"rows": rows, "modaluq": mq_runs, "pyoma2": po_runs}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("n_seeds", nargs="?", type=int, default=10)
    ap.add_argument("--seed0", type=int, default=SEED0)
    ap.add_argument("--peer", help="Python of a venv with pyOMA2 (default $PYOMA2_PYTHON)")
    ap.add_argument("--keep", help="keep the exchanged .npz files in this folder")
    ap.add_argument("--worker", help=argparse.SUPPRESS)  # child mode: the pyOMA2 side on a folder of records
    args = ap.parse_args()
    if args.worker:
        _pyoma2_worker(args.worker)
    else:
        main(args.n_seeds, args.seed0, args.peer, args.keep)
