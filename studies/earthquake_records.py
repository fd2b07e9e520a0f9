"""Meloland and Painter Street (earthquake records, ground channels as inputs): which of the data
README's "sanity check" frequencies are physical modes, with the evidence.

Every run is the engineer's call, ``modaluq.identify(y, u, fs=fs, frequency_range=band)``,
output-only (OO) and with the ground channels as inputs (IO), plus the same call on

- the two halves of the event window (start/stop; the first holds the strong motion, the
  second the weaker coda), at the window's automatic block_rows, so that only the data differ;
- shorter and longer horizons (0.75 and 1.5 times the automatic block_rows);
- the transverse-only and the vertical-only deck channels (a supplementary view).

Each selected mode is labelled with the deck pattern it matches best: the MAC of its shape with
a template per pattern built from the channel names (all deck transverse channels in phase,
the two spans out of phase, west edge against east edge ...); below MAC 0.5 it is "mixed".
Each README value (and each mode the default call selects that is not near one) is a target:
its pattern is that of the clearest-shaped mode within 2 % of it in the default calls (else in
any run), and in every run the nearest mode of that pattern within 8 % is taken as the same
mode (a mode's frequency moves by up to 6 % between the strong-motion half and the coda, and by
up to 5 % between output-only and input/output). Independent of SSI, the template is used as a
spatial filter on the deck channels: the peaks of its spectrum, and of its H1 from the matching
ground channel(s) with the coherence, are checked near the mode; so are the peaks of the ground
motion's own spectrum (an output-only pole at a ground-motion peak may be the input's).

A target is called **physical** when it is found output-only and with the ground input, in both
halves of the record, at a second horizon, with a clear pattern (template MAC >= 0.5), a median
damping ratio below 10 %, and a peak of its spatially filtered spectrum or H1 within 4 % of its
frequency; **probable** when it misses one of these; otherwise **not shown**.

Usage: OPENBLAS_NUM_THREADS=1 python studies/earthquake_records.py [DATA_DIR]
(default ../shared/data; about 20 s on one core). docs/settings.md ("Earthquake records") uses
its tables.
"""
import collections
import re
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy import signal

import modaluq
from modaluq.stabilization import modal_assurance_criterion as mac

# pattern: (deck template = spatial filter {station: weight}, ground input of its H1 {station: weight})
RECORDS = {
    "Meloland": dict(
        file="cesmd_meloland_overpass_2016.npz", band=(1.0, 20.0), window=(None, None), halves=((10, 44), (44, 78)),
        sanity=[("1.47", 1.47, 1.47), ("2.98", 2.98, 2.98), ("3.2", 3.2, 3.2), ("3.97", 3.97, 3.97),
                ("4.1-4.5", 4.1, 4.5), ("17.16", 17.16, 17.16)],
        # the README's ANPSD peaks that are not in its SSI list
        spectral=[("6.0 (ANPSD)", 6.0, 6.0), ("15.8 (ANPSD)", 15.8, 15.8), ("17.3 (ANPSD)", 17.3, 17.3)],
        patterns={
            # all deck transverse channels in phase, largest over the column (first transverse)
            "T-sym": ({"sta03": .4, "sta05": .8, "sta07": 1, "sta09": .8, "sta13": .4}, {"sta02": 1}),
            # south half against north half in plan (rotation about the column)
            "T-anti": ({"sta03": 1, "sta05": .6, "sta09": -.6, "sta13": -1}, {"sta11": 1, "sta26": -1}),
            # both spans up together (node over the column)
            "V-sym": ({"sta16": 1, "sta18": 1, "sta20": 1, "sta22": 1}, {"sta01": 1, "sta30": 1}),
            # south span against north span
            "V-anti": ({"sta16": 1, "sta18": 1, "sta20": -1, "sta22": -1}, {"sta10": 1, "sta23": -1}),
            # west edge against east edge along the deck
            "torsion": ({"sta16": 1, "sta17": 1, "sta20": 1, "sta18": -1, "sta21": -1, "sta22": -1},
                        {"sta01": 1, "sta30": -1}),
            "long": ({"sta08": 1, "sta27": 1, "sta31": 1, "sta32": 1}, {"sta04": 1}),
        }),
    "Painter Street": dict(
        file="cesmd_painter_st_overpass_2016.npz", band=(1.0, 15.0), window=(25, 60),
        halves=((25, 42.5), (42.5, 60)),
        sanity=[("3.30", 3.30, 3.30), ("3.9", 3.9, 3.9), ("4.3", 4.3, 4.3), ("4.7", 4.7, 4.7), ("5.8", 5.8, 5.8),
                ("7.1", 7.1, 7.1), ("10.8", 10.8, 10.8)],
        spectral=[("10.5 (ANPSD)", 10.5, 10.5), ("14.9 (ANPSD)", 14.9, 14.9)],
        patterns={
            "T-sym": ({"sta04": .6, "sta07": 1, "sta09": .6}, {"sta03": 1}),
            "T-anti": ({"sta04": 1, "sta09": -1}, {"sta20": 1, "sta17": -1}),
            "V-sym": ({"sta06": 1, "sta08": 1}, {"sta02": 1}),
            "V-anti": ({"sta06": 1, "sta08": -1}, {"sta19": 1, "sta16": -1}),
            "V-west": ({"sta06": 1}, {"sta02": 1}),   # the west span's midspan alone
            "V-east": ({"sta08": 1}, {"sta02": 1}),
            "long": ({"sta11": 1}, {"sta01": 1}),
        }),
}
CLEAR = 0.5        # template MAC for a clear pattern
MATCH_TOL = 0.08   # the nearest mode of the target's pattern within 8 % is the same mode
README_TOL = 0.02  # "at" a README value: within 2 %


def station(name):
    return str(name).split("|")[0]


def runs_of(rec, d, kinds=None):
    """(label, excitation, kind, channels, identify kwargs) of every run (of ``kinds``, default all)."""
    names = [str(n) for n in d["channel_names"]]
    fs, band = float(d["fs"]), rec["band"]
    y, u = d["y"], d["u"]
    allc = list(range(len(names)))
    out = []
    base = modaluq.identify(y, fs=fs, frequency_range=band)
    p0 = int(base.settings["block_rows"])
    a, b = rec["window"]
    pw = p0
    if a is not None or b is not None:
        pw = int(modaluq.identify(y, fs=fs, frequency_range=band, start=a, stop=b).settings["block_rows"])
    for io in (False, True):
        ex = "IO" if io else "OO"
        uu = u if io else None
        out.append((f"default {ex}", ex, "default", allc, dict(y=y, u=uu)))
        if a is not None or b is not None:
            out.append((f"window {a}-{b} s {ex}", ex, "window", allc, dict(y=y, u=uu, start=a, stop=b)))
        for k, (s0, s1) in enumerate(rec["halves"]):
            out.append((f"half {k + 1} ({s0}-{s1} s, p={pw}) {ex}", ex, f"half{k + 1}", allc,
                        dict(y=y, u=uu, start=s0, stop=s1, block_rows=pw)))
        for fac in (0.75, 1.5):
            p = int(round(p0 * fac))
            out.append((f"p={p} ({fac:g}x) {ex}", ex, f"p{fac:g}", allc, dict(y=y, u=uu, block_rows=p)))
        for direction in ("Tran", "Up"):
            cols = [i for i, n in enumerate(names) if f"|{direction}|" in n]
            out.append((f"{direction} only {ex}", ex, f"view-{direction}", cols, dict(y=y[:, cols], u=uu)))
    if kinds is not None:
        out = [run for run in out if run[2] in kinds]
    return out, p0, pw


def label(shape_full, cols, templates):
    """(best pattern, its MAC) with each template restricted to the channels of the run."""
    best, best_mac = "mixed", 0.0
    for name, t in templates.items():
        tt = np.zeros_like(t)
        tt[cols] = t[cols]
        if not np.any(tt):
            continue
        m = float(mac(shape_full, tt)[0, 0])
        if m > best_mac:
            best, best_mac = name, m
    return best, best_mac


def diagnose(result, f0, tol=0.03):
    """Why the default call selects nothing near f0: pole statuses, reasons, clusters."""
    dg = result.stabilization_diagram()
    sel = dg.select_modes()
    near = np.abs(dg.frequency_hz / f0 - 1) < tol
    st = collections.Counter(str(s) for s in dg.status[near])
    reasons = collections.Counter(re.sub(r"[-+]?\d[\d.e+-]*", "#", r).split(" (vs")[0] for r in dg.reason[near] if r)
    clusters = [f"{f:.2f} Hz ({n} poles: {why})" for f, n, why in
                zip(sel.dropped_frequency_hz, sel.dropped_n_poles, sel.dropped_reason)
                if abs(f / f0 - 1) < tol and n >= 3]
    top = "; ".join(f"{n}x '{r}'" for r, n in reasons.most_common(2))
    return (f"{int(near.sum())} poles within ±{100 * tol:.0f} % of {f0:.2f} Hz: "
            + ", ".join(f"{n} {s}" for s, n in st.most_common()) + (f" (most common: {top})" if top else "")
            + f"; min_cluster_size {sel.min_cluster_size}; dropped clusters: "
            + (", ".join(clusters) if clusters else "none with >= 3 poles"))


def spectra(rec, d, templates, inputs):
    """Per pattern: frequencies, filtered deck PSD, |H1| from the ground combination, coherence."""
    fs = float(d["fs"])
    a, b = rec["window"]
    i0 = 0 if a is None else int(a * fs)
    i1 = None if b is None else int(b * fs)
    y, u = d["y"][i0:i1], d["u"][i0:i1]
    nper = int(10.24 * fs)
    out = {}
    for name, t in templates.items():
        yo = y @ t
        ui = u @ inputs[name]
        f, pyy = signal.welch(yo, fs=fs, nperseg=nper, nfft=4 * nper)
        _, puu = signal.welch(ui, fs=fs, nperseg=nper, nfft=4 * nper)
        _, puy = signal.csd(ui, yo, fs=fs, nperseg=nper, nfft=4 * nper)
        out[name] = (f, pyy, np.abs(puy) / puu, np.abs(puy) ** 2 / (puu * pyy))
    return out


def peak_near(f, a, f0, band, tol=0.04):
    m = (f >= band[0]) & (f <= band[1])
    k, _ = signal.find_peaks(a[m], prominence=0.1 * a[m].max())
    if not k.size:
        return None
    fp = f[m][k]
    j = int(np.argmin(np.abs(fp - f0)))
    return float(fp[j]) if abs(fp[j] / f0 - 1) <= tol else None


def ground_peaks(rec, d):
    """Peaks of the ground motion's own spectrum (mean normalised PSD of every ground channel)."""
    fs = float(d["fs"])
    a, b = rec["window"]
    u = d["u"][0 if a is None else int(a * fs):None if b is None else int(b * fs)]
    nper = int(10.24 * fs)
    f, p = signal.welch(u, fs=fs, nperseg=nper, nfft=4 * nper, axis=0)
    anpsd = (p / p.sum(axis=0)).mean(axis=1)
    m = (f >= rec["band"][0]) & (f <= rec["band"][1])
    k, _ = signal.find_peaks(anpsd[m], prominence=0.05 * anpsd[m].max())
    return f[m][k]


def identify_all(rec, d, templates, kinds=None):
    names = [str(n) for n in d["channel_names"]]
    fs = float(d["fs"])
    runs, p0, pw = runs_of(rec, d, kinds)
    modes, results = [], {}
    for run_label, ex, kind, cols, kw in runs:
        kw = dict(kw)
        r = modaluq.identify(kw.pop("y"), kw.pop("u"), fs=fs, frequency_range=rec["band"], **kw)
        s = r.select_modes()
        results[run_label] = (r, s, kind, ex)
        for k in range(s.n_modes):
            full = np.zeros(len(names), complex)
            full[cols] = s.mode_shape[:, k]
            lab, lm = label(full, cols, templates)
            others = np.delete(s.frequency_hz, k)
            gap = float(np.min(np.abs(others - s.frequency_hz[k]))) if others.size else np.inf
            modes.append(dict(run=run_label, ex=ex, kind=kind, f=float(s.frequency_hz[k]),
                              xi=float(s.damping_ratio[k]), sf=float(s.frequency_std[k]),
                              sxi=float(s.damping_std[k]), label=lab if lm >= CLEAR else "mixed",
                              best=lab, lmac=lm, n=int(s.n_poles[k]), gap=gap))
    return runs, modes, results, p0, pw


def rel(f, lo, hi):
    """Relative distance of f from the interval [lo, hi] (0 inside)."""
    return max(lo / f - 1, f / hi - 1, 0.0)


def make_targets(rec, modes):
    targets = [dict(text=t, lo=lo, hi=hi, source="README") for t, lo, hi in rec["sanity"]]
    targets += [dict(text=t, lo=lo, hi=hi, source="README ANPSD") for t, lo, hi in rec.get("spectral", [])]
    for t in targets:
        assign_pattern(t, modes)
    # the default calls' modes that are near no README value become targets too
    for m in sorted((m for m in modes if m["kind"] == "default"), key=lambda m: (m["ex"], m["f"])):
        if any(rel(m["f"], t["lo"], t["hi"]) <= README_TOL for t in targets):
            continue
        if m["label"] != "mixed" and any(t["pattern"] == m["label"] and rel(m["f"], t["lo"], t["hi"]) <= MATCH_TOL
                                         for t in targets):
            continue
        t = dict(text=f"{m['f']:.2f} (default {m['ex']})", lo=m["f"], hi=m["f"], source="default")
        assign_pattern(t, modes)
        targets.append(t)
    return targets


def assign_pattern(t, modes):
    """The pattern of the clearest-shaped mode within 2 %: default calls, else any run, else the views."""
    for pool in (lambda m: m["kind"] == "default", lambda m: not m["kind"].startswith("view"), lambda m: True):
        c = [m for m in modes if pool(m) and rel(m["f"], t["lo"], t["hi"]) <= README_TOL]
        if c:
            best = max(c, key=lambda m: m["lmac"])
            t["pattern"] = best["label"] if best["label"] != "mixed" else None
            t["pattern_mac"] = best["lmac"]
            t["pattern_from"] = f"{best['f']:.3f} Hz, {best['run']}"
            return
    t["pattern"], t["pattern_mac"], t["pattern_from"] = None, np.nan, "no mode within 2 % in any run"


def match(t, modes, run_label):
    """The mode of the target's pattern in one run (nearest within 8 %), else None."""
    c = [m for m in modes if m["run"] == run_label]
    if t["pattern"] is not None:
        c = [m for m in c if m["label"] == t["pattern"] and rel(m["f"], t["lo"], t["hi"]) <= MATCH_TOL]
    else:
        c = [m for m in c if rel(m["f"], t["lo"], t["hi"]) <= README_TOL]
    return min(c, key=lambda m: rel(m["f"], t["lo"], t["hi"])) if c else None


def match_mixed(t, modes, run_label, ex):
    """Second tier: a mixed-shape mode (template MAC < 0.5) within 2 % of the frequency at which the
    pattern was found (same excitation model if it was found with it, else all runs)."""
    same = [m["f"] for m in t["m"].values() if m is not None and not m.get("mixed") and m["ex"] == ex]
    every = [m["f"] for m in t["m"].values() if m is not None and not m.get("mixed")]
    if t["pattern"] is None or not every:
        return None
    f0 = float(np.median(same or every))
    c = [m for m in modes if m["run"] == run_label and m["label"] == "mixed" and abs(m["f"] / f0 - 1) <= README_TOL]
    if not c:
        return None
    m = dict(min(c, key=lambda m: abs(m["f"] / f0 - 1)))
    m["mixed"] = True
    return m


def study(title, rec, data_dir, kinds=None):
    d = np.load(Path(data_dir) / rec["file"])
    fs = float(d["fs"])
    names = [str(n) for n in d["channel_names"]]
    sta = [station(n) for n in names]
    in_sta = [station(n) for n in d["input_names"]]
    templates = {k: np.array([v[0].get(s, 0.0) for s in sta], float) for k, v in rec["patterns"].items()}
    inputs = {k: np.array([v[1].get(s, 0.0) for s in in_sta], float) for k, v in rec["patterns"].items()}
    runs, modes, results, p0, pw = identify_all(rec, d, templates, kinds)
    spec = spectra(rec, d, templates, inputs)
    gpk = ground_peaks(rec, d)
    band = rec["band"]
    main_runs = [lab for lab, _, kind, *_ in runs if not kind.startswith("view")]
    targets = make_targets(rec, modes)

    for t in targets:
        t["m"] = {lab: match(t, modes, lab) for lab, *_ in runs}
        for lab, ex, *_ in runs:
            if t["m"][lab] is None:
                t["m"][lab] = match_mixed(t, modes, lab, ex)
        # heavily damped members (xi >= 10 %) are shown but not counted
        mem = [m for lab, m in t["m"].items() if m is not None and lab in main_runs and m["xi"] < 0.10]
        t["f_oo"] = [m["f"] for m in mem if m["ex"] == "OO"]
        t["f_io"] = [m["f"] for m in mem if m["ex"] == "IO"]
        kinds = {m["kind"] for m in mem}
        t["xi"] = float(np.median([m["xi"] for m in mem])) if mem else np.nan
        t["spec"], t["ground"] = [], []
        if t["pattern"] is not None and mem:
            fr, pyy, h1, coh = spec[t["pattern"]]
            for f0 in {float(np.median(x)) for x in (t["f_oo"], t["f_io"]) if x}:
                for what, a in (("PSD", pyy), ("H1", h1)):
                    fp = peak_near(fr, a, f0, band)
                    if fp is not None:
                        t["spec"].append((what, round(fp, 2), round(float(np.interp(fp, fr, coh)), 2)))
            t["spec"] = sorted(set(t["spec"]))
        if t["f_oo"]:
            foo = float(np.median(t["f_oo"]))
            t["ground"] = [round(float(g), 2) for g in gpk if abs(g / foo - 1) <= README_TOL]
        checks = dict(OO_and_IO=bool(t["f_oo"]) and bool(t["f_io"]),
                      both_halves="half1" in kinds and "half2" in kinds,
                      second_horizon=bool(kinds & {"p0.75", "p1.5"}),
                      clear_pattern=t["pattern"] is not None,
                      damping_below_10=bool(mem) and t["xi"] < 0.10,
                      spectral_peak=bool(t["spec"]))
        t["failed"] = [k for k, v in checks.items() if not v]
        t["verdict"] = ("not found" if not mem else "physical" if not t["failed"]
                        else "probable" if len(t["failed"]) == 1 else "not shown")
        t["at_readme"] = {ex: any(rel(f, t["lo"], t["hi"]) <= README_TOL for f in fl)
                          for ex, fl in (("OO", t["f_oo"]), ("IO", t["f_io"]))}

    # ------------------------------------------------------------------ print
    r0 = results["default OO"][0]
    print(f"\n## {title} (band {band[0]:g}-{band[1]:g} Hz, fs {fs:g} Hz, {len(names)} deck outputs, "
          f"{d['u'].shape[1]} ground inputs)\n")
    print(f"Default call: block_rows {p0} ({p0 / r0.fs:.2f} s of lags at {r0.fs:g} Hz), n_blocks {r0.n_blocks}; "
          f"halves {rec['halves'][0]} and {rec['halves'][1]} s at block_rows {pw}; horizons "
          f"{round(0.75 * p0)} and {round(1.5 * p0)}.")
    print("Ground-motion spectral peaks (mean normalised PSD of the ground channels): "
          + ", ".join(f"{g:.2f}" for g in gpk) + " Hz.")
    for lab in ("default OO", "default IO"):
        r, s = results[lab][:2]
        short = [re.split(r"[:;]", w)[0][:100] for w in r.warnings]
        print(f"- {lab}: selects " + ", ".join(f"{f:.2f}" for f in s.frequency_hz) + f" Hz; k* = "
              f"{r.significant_singular_values}; warnings: " + (" | ".join(short) if short else "none"))

    def cell(m, sigma=False):
        if m is None:
            return "–"
        mark = (" mixed" if m.get("mixed") or m["label"] == "mixed" else "") + ("*" if m["xi"] >= 0.10 else "")
        if sigma:
            return f"{m['f']:.3f} ± {m['sf']:.3f}, ξ {100 * m['xi']:.1f} ± {100 * m['sxi']:.1f}{mark}"
        return f"{m['f']:.2f} ({100 * m['xi']:.1f}){mark}"

    print("\n### Evidence per README value (and per other mode the default call selects)\n")
    print("Cells f Hz (ξ %) of the mode of the target's pattern in that run (within 8 %); 'mixed': no mode of the "
          "pattern, but a mixed-shape mode within 2 % of where the pattern was found; '*': ξ >= 10 %, not counted. "
          "Default cells f ± σ_f Hz, ξ ± σ_ξ %. H1/PSD: peaks of the pattern's spatially filtered deck spectrum "
          "and of its H1 from the ground (coherence) within 4 %; ground: ground-motion peak within 2 % of the "
          "output-only frequency; README: output-only / input-output frequency within 2 % of the README value.\n")
    head = ["value (Hz)", "pattern (MAC)", "default OO", "default IO", "half 1 OO / IO", "half 2 OO / IO",
            "0.75·p OO / IO", "1.5·p OO / IO"]
    if any(kind == "window" for _, _, kind, *_ in runs):
        head.insert(4, "window OO / IO")
    head += ["Tran only OO / IO", "Up only OO / IO", "σ_f/(fξ)", "gap/σ_f", "H1/PSD", "ground", "README",
             "verdict"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))

    def pair(kind):
        return " / ".join(cell(next((t["m"][lab] for lab, ex_, k, *_ in runs if k == kind and ex_ == ex), None))
                          for ex in ("OO", "IO"))

    for t in targets:
        dm = [t["m"]["default OO"], t["m"]["default IO"]]
        row = [t["text"], f"{t['pattern'] or 'mixed'} ({t['pattern_mac']:.2f})" if np.isfinite(t["pattern_mac"])
               else "–", cell(dm[0], True), cell(dm[1], True)]
        kinds = ["window"] if "window OO / IO" in head else []
        for kind in kinds + ["half1", "half2", "p0.75", "p1.5", "view-Tran", "view-Up"]:
            row.append(pair(kind))
        dd = [m for m in dm if m is not None]
        row.append(" / ".join(f"{m['sf'] / (m['f'] * m['xi']):.2f}" for m in dd) or "–")
        row.append(" / ".join(f"{m['gap'] / m['sf']:.0f}" for m in dd) or "–")
        row.append(", ".join(f"{w} {fp:.2f} ({c:.2f})" for w, fp, c in t["spec"]) or "–")
        row.append(", ".join(f"{g:.2f}" for g in t["ground"]) or "–")
        row.append("–" if t["source"] == "default" else
                   " / ".join("yes" if t["at_readme"][ex] else "no" for ex in ("OO", "IO")))
        row.append(t["verdict"] + (f" (fails: {', '.join(t['failed'])})" if t["failed"] and t["verdict"] != "not found"
                                   else ""))
        print("| " + " | ".join(row) + " |")

    print("\n### Default call: the README values and the modes shown physical or probable it does not select\n")
    for t in targets:
        for ex in ("OO", "IO"):
            m = t["m"][f"default {ex}"]
            selected_at = [f for f in results[f"default {ex}"][1].frequency_hz
                           if rel(f, t["lo"], t["hi"]) <= README_TOL]
            if t["source"] == "default" and m is not None:
                continue
            if m is not None and selected_at:
                continue
            if t["source"] != "README" and t["verdict"] not in ("physical", "probable"):
                continue
            others = t["f_oo"] if ex == "OO" else t["f_io"]
            shown = others and t["verdict"] in ("physical", "probable")
            f0 = float(np.median(others)) if shown else (t["lo"] + t["hi"]) / 2
            what = (f"selects {cell(m)} of this pattern, but nothing within 2 % of {t['text']}" if m is not None
                    else "selects " + (", ".join(f"{f:.3f}" for f in selected_at) + " (another pattern)"
                                       if selected_at else "nothing of this pattern"))
            print(f"- {t['text']} Hz, default {ex}: {what}. Diagram: "
                  + diagnose(results[f"default {ex}"][0], f0, tol=0.02 if t["lo"] == t["hi"] else
                             (t["hi"] - t["lo"]) / (t["hi"] + t["lo"]) + 0.02))
    return targets, results


def main(data_dir="../shared/data", records=tuple(RECORDS), kinds=None):
    """Print the study of each of ``records`` (names of :data:`RECORDS`); return {name: (targets, results)}.

    ``kinds`` limits the runs (default all: "default", "window", "half1", "half2", "p0.75", "p1.5",
    "view-Tran", "view-Up"); the verdicts need them all."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {title: study(title, RECORDS[title], data_dir, kinds) for title in records}


if __name__ == "__main__":
    main(*sys.argv[1:2])
