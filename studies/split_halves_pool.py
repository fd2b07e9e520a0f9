"""Issue 27, "split halves of the shared measured records": z = (x₁ − x₂) / √(σ₁² + σ₂²) of f
and ξ pooled over many mode pairs, with ``modaluq.validation.split_halves`` on windows of the
shared records (docs/validation.md, "The split-halves check on your own record").

The windows (fixed before any z was looked at): each record, of length T, is cut into n = 1, 2,
4 and 8 consecutive non-overlapping windows of T/n, and each window is split into its two halves
(``split_halves`` with ``start``/``stop`` = the window), at the first half's automatic settings
(block_rows, orders, n_blocks) and the band of the record below; pairs within 2 % in frequency
and MAC >= 0.8 (the defaults). A window too short for the automatic settings is counted as
failed and gives no pair. Pairs of one level n are independent (disjoint data); pairs of
different levels share data and are not, so the table also gives each level alone.

Records and bands: the bands of the table already in docs/validation.md; the smartphone slab
is its ``recommended_slice`` (the data README: the operator touches the phone outside it), all
three channels; the TDMS files are read by ``modaluq.io.load`` (all 8 acceleration channels).
The earthquake records (Meloland, Painter Street, output-only) are run too but **not pooled**:
strong motion is transient, the first half holds the shaking and the second the coda, and the
structure's frequencies move with amplitude (up to 6 % between them, studies/earthquake_records.py),
so a z beyond ±1.96 there says nothing about σ. The simulated records are a separate group.

Each pair is also flagged ``harmonic`` when ``modaluq.harmonics.possible_harmonics`` (the
package's kurtosis test, run on the window's outputs with every frequency of both halves, so that
the family rule sees the fundamentals) flags its mean frequency: a rotor harmonic moves with the
rotor's speed, not with σ. The measured pool is given with and without them. ``rms_ratio`` is the
RMS of the second half's outputs over the first's (the largest over channels, ≥ 1): a diagnostic
of stationarity, not a rule.

A relative window alone truncates z_f: two frequencies more than the tolerance apart (2 %) are not
paired, so a pair's |z_f| could be at most tolerance·f / √(σ_f₁² + σ_f₂²), which is below 1.96 for
short halves and broad modes, biasing RMS z_f down and the share within ±1.96 up. Since
2026-11-28 ``split_halves`` also pairs frequencies within ``pair_within_std`` (default 4) combined
σ_f where neither mode has another candidate (``by_std``: such a pair), so that cap is lifted to
4 for those modes; ``--pair-within-std 0`` gives the rule before. ``z_f_cap`` is the window's
cap, tolerance·f / √(σ_f₁² + σ_f₂²); the tables also give the pairs with ``z_f_cap`` >= 3 (a
condition on σ, not on z) and the pool without the ``by_std`` pairs, and ``--tolerance`` reruns
the pairing wider.

The shapes are checked alike (``z_mac``, ``mac_p_value``: the "same mode" test of the two halves'
shapes with both shapes' covariances, ``modaluq.indicators.mac_test``): RMS z_MAC ≈ 1 and about
5 % of the pairs rejected at 5 % if the shapes' σ are right. The pairing's MAC >= 0.8 truncates
z_MAC as the tolerance truncates z_f.

``--fixed-orders`` (issue 27 (o)) asks instead *which* σ the pairs test: for every mode pair, every
model order both halves' clusters hold is compared pole against pole with each pole's own σ (the
per-order σ, a fixed-order estimator), beside the selected modes' z with the default σ (the median of
the members' σ), with the σ of the members' mean (``cluster_std="mean"``, (12.14) of uq-math.md) and
the mean correlation between the members' ξ factor rows, its median over the modes (1: the orders
move together).

Beside the usual z, every table gives each half read with its own σ (issue 27 (p)): z = (x₁ − x₂) /
(√2 σ_h) for h = 1, 2, both counted. The combined z divides by both halves' σ together and so
averages out how much one record's σ scatters; the own-σ reading reads the coverage of a single
record's interval, 1–2 points low in the Monte Carlo (the coverage lies between the two). ``--simulated-koma N`` runs the same windows on N simulated records of the koma
frame's system (the group "Monte Carlo"), whose per-record coverage
``studies/selected_members_mc.py N koma OUT.pkl --duration 600`` measures: the check of the check.

Usage: OPENBLAS_NUM_THREADS=1 python studies/split_halves_pool.py [DATA_DIR] [--out pairs.csv] [--simulated-koma N]
(default ../shared/data; about 1 min on one core). docs/validation.md quotes its table.
"""
import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import modaluq
from modaluq.analysis import Analysis
from modaluq.comparison import compare_modes, rms_and_within
from modaluq.harmonics import possible_harmonics
from modaluq.io import load
from modaluq.validation import split_halves_windows
from modaluq.validation.split_halves import _run_halves  # the halves as split_halves runs them

Z_95 = 1.959963984540054
LEVELS = (1, 2, 4, 8)


def _npz(file, *, sliced=False):
    def read(data):
        d = np.load(data / file)
        y = d["y"]
        if sliced:
            a, b = d["recommended_slice"][:2]
            y = y[a:b]
        return np.asarray(y, float), float(d["fs"])
    return read


def _tdms(file):
    def read(data):
        rec = load(data / file)
        return np.asarray(rec.y, float), float(rec.fs)
    return read


#: name: (group, reader, band in Hz). Groups: "measured" (pooled), "earthquake" (not pooled), "simulated".
RECORDS = {
    "wind turbine tower": ("measured", _tdms("owi_offshore_wind_turbine_tower_2020.tdms"), (0.2, 5.0)),
    "sensor array": ("measured", _tdms("owi_sensor_array_with_ambient_2022.tdms"), (1.0, 40.0)),
    "smartphone slab": ("measured", _npz("cessipy_smartphone_slab.npz", sliced=True), (5.0, 40.0)),
    "Meloland (earthquake)": ("earthquake", _npz("cesmd_meloland_overpass_2016.npz"), (1.0, 20.0)),
    "Painter Street (earthquake)": ("earthquake", _npz("cesmd_painter_st_overpass_2016.npz"), (1.0, 15.0)),
    "koma shear frame": ("simulated", _npz("koma_shearframe_sim.npz"), (0.1, 1.5)),
    "Lysefjord bridge": ("simulated", _npz("ssicov_lysefjord_bridge_sim.npz"), (0.1, 1.5)),
}

COLUMNS = ("group", "record", "n_windows", "window", "t0_s", "t1_s", "half_s", "block_rows", "n_blocks", "orders",
           "f1_hz", "f2_hz", "sigma_f1_hz", "sigma_f2_hz", "xi1", "xi2", "sigma_xi1", "sigma_xi2",
           "z_f", "z_xi", "z_f_own1", "z_f_own2", "z_xi_own1", "z_xi_own2", "z_f_cap", "by_std", "mac", "z_mac",
           "mac_p_value", "harmonic", "rms_ratio")


def simulated_koma(n_records, seed=20000):
    """Issue 27 (p): register ``n_records`` records of the koma frame's system (1200 s at 12 Hz, as the
    shared file; ``selected_members_mc.koma_frame``, seeds ``seed`` + k) as the group "Monte Carlo",
    so that the split halves are read on records whose per-record coverage the Monte Carlo knows;
    returns their names."""
    if str(Path(__file__).resolve().parent) not in sys.path:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
    from selected_members_mc import koma_frame  # the studies' own generator of the koma system

    names = []
    for k in range(n_records):
        name = f"koma system, simulated record {k}"
        RECORDS[name] = ("Monte Carlo", lambda data, k=k: (koma_frame(14400, seed + k)[0], 12.0), (0.1, 1.5))
        names.append(name)
    return names


def _clustering(representative):
    if representative == "no-noise-twins":  # the default but drop_noise_twins (before 2026-11-27)
        return modaluq.ClusteringSettings(drop_noise_twins=False)
    if representative == "no-pole-reassign":  # the default but reassign_borrowed_poles (before 2026-11-28)
        return modaluq.ClusteringSettings(reassign_borrowed_poles=False)
    if representative == "no-order-check":  # the default but order_discrepancy (before 2026-11-27)
        return modaluq.ClusteringSettings(order_discrepancy=False)
    if representative == "no-unanchored":  # the default but unanchored_noise_coupling (before 2026-12-07)
        return modaluq.ClusteringSettings(unanchored_noise_coupling=None)
    if representative == "cluster-mean":  # the default but the cluster's mean sigma (12.14), not the median
        return modaluq.ClusteringSettings(cluster_std="mean")
    if representative in ("shape-lowest", "shape-median"):
        return modaluq.ClusteringSettings(shape_representative=representative.split("-")[1])
    return modaluq.ClusteringSettings(representative=representative)


def pairs_of_record(name, data, levels=LEVELS, tolerance=0.02, representative="median", pair_within_std=4.0):
    """Every mode pair of every window of one record (dicts with :data:`COLUMNS`), and the failed
    windows; ``representative`` is ``ClusteringSettings.representative``, or "shape-lowest" /
    "shape-median" for the median representative with that ``shape_representative`` ("median" and
    "shape-lowest" are the default since 2026-11-27, "shape-median" the default before), or
    "no-order-check" for the default with ``order_discrepancy=False``, "cluster-mean" with ``cluster_std="mean"``, "no-noise-twins" with
    ``drop_noise_twins=False``, "no-pole-reassign" with ``reassign_borrowed_poles=False``; ``pair_within_std`` is ``split_halves``' (0: the 2 % window alone)."""
    group, read, band = RECORDS[name]
    y, fs = read(data)
    a = Analysis.from_arrays(y, fs=fs, settings=modaluq.Settings(frequency_range=band),
                             clustering=_clustering(representative))
    pooled = split_halves_windows(a, levels, max_frequency_difference=tolerance, pair_within_std=pair_within_std)
    rows = []
    failed = [(name, n, k, message) for n, k, _, message in pooled.failed]
    for n, k, check in pooled.checks:
        (t0, _), (_, t1) = check.halves_s
        i0, i1, i2 = (int(round(t * fs)) for t in (t0, 0.5 * (t0 + t1), t1))
        rms = np.sqrt(np.mean((y[i0:i1] - y[i0:i1].mean(0)) ** 2, 0)), \
            np.sqrt(np.mean((y[i1:i2] - y[i1:i2].mean(0)) ** 2, 0))
        ratio = float(np.max(np.maximum(rms[1] / rms[0], rms[0] / rms[1])))
        f, sf, x, sx = check.frequency_hz, check.frequency_std, check.damping_ratio, check.damping_std
        every = np.concatenate([f.mean(1), *check.unmatched_hz])
        xi_every = np.concatenate([x.mean(1), np.full(sum(map(len, check.unmatched_hz)), np.nan)])
        harmonic = possible_harmonics(y[i0:i2], fs, every, xi_every)[:len(f)] if len(f) else []
        for m in range(len(f)):
            rows.append(dict(
                group=group, record=name, n_windows=n, window=k, t0_s=t0, t1_s=t1, half_s=(t1 - t0) / 2,
                block_rows=check.settings["block_rows"], n_blocks=check.settings["n_blocks"],
                # t of each half's core blocks − 1
                interval_factor1=float(check.interval_factor_95[m, 0]), interval_factor2=float(check.interval_factor_95[m, 1]),
                orders=check.settings["orders"], f1_hz=f[m, 0], f2_hz=f[m, 1],
                sigma_f1_hz=sf[m, 0], sigma_f2_hz=sf[m, 1], xi1=x[m, 0], xi2=x[m, 1],
                sigma_xi1=sx[m, 0], sigma_xi2=sx[m, 1], z_f=check.z_frequency[m], z_xi=check.z_damping[m],
                z_f_own1=check.z_frequency_own_sigma[m, 0], z_f_own2=check.z_frequency_own_sigma[m, 1],
                z_xi_own1=check.z_damping_own_sigma[m, 0], z_xi_own2=check.z_damping_own_sigma[m, 1],
                z_f_cap=tolerance * f[m].max() / np.hypot(*sf[m]), by_std=bool(check.by_std[m]), mac=check.mac[m],
                z_mac=check.z_mac[m],
                mac_p_value=check.mac_p_value[m],
                harmonic=bool(harmonic[m]), rms_ratio=ratio))
    return rows, failed


def _row_correlation(factor):
    """Mean correlation between distinct rows of ``factor`` (members × blocks): 1 when the members'
    first-order moves are one."""
    k = len(factor)
    if k < 2:
        return np.nan
    x = factor / np.linalg.norm(factor, axis=1, keepdims=True)
    g = x @ x.T
    return float((g.sum() - k) / (k * (k - 1)))


def _lag1(u):
    """ρ₁ of (3.4) of uq-math.md §3.1 for one factor row (blocks in time order), with its +1/n_b."""
    u = u - u.mean()
    return float(u[:-1] @ u[1:] / (u @ u) + 1 / len(u))


def fixed_order_pairs(name, data, levels=LEVELS):
    """Issue 27 (o): for each mode pair of each window of one record (paired as ``split_halves`` pairs
    them, default settings), the z of f and ξ of the two halves' poles at every order both clusters
    hold (each pole's own σ), and the selected modes' z with the default σ and with
    ``cluster_std="mean"``, and the lag-1 block correlation ρ₁ of both representatives' rows;
    returns (pair dicts, order dicts)."""
    group, read, band = RECORDS[name]
    y, fs = read(data)
    a = Analysis.from_arrays(y, fs=fs, settings=modaluq.Settings(frequency_range=band))
    mean_std = modaluq.ClusteringSettings(cluster_std="mean")
    pairs, orders = [], []
    length = len(y) / fs
    for n in levels:
        for k in range(n):
            try:
                runs, _ = _run_halves(a.with_settings(start=k * length / n, stop=(k + 1) * length / n))
            except ValueError:  # a window too short for the automatic settings: no pair, as in the pool
                continue
            c = compare_modes(runs[0].selected, runs[1].selected)
            means = [modaluq.select_modes(r.diagram, mean_std) for r in runs]
            k_star = max(r.diagram.noise_floor_order for r in runs)
            for m in range(len(c.mac)):
                clusters, pair = [], dict(group=group, record=name, n_windows=n, window=k)
                for h, (run, mean) in enumerate(zip(runs, means)):
                    sel, d = run.selected, run.diagram
                    j = int(np.argmin(np.abs(sel.frequency_hz - c.frequency_hz[m, h])))
                    jm = int(np.argmin(np.abs(mean.frequency_hz - sel.frequency_hz[j])))
                    members = np.asarray(sel.members[j])
                    rep = sel.representative_pole[j]
                    pair[f"lag1_f{h}"], pair[f"lag1_xi{h}"] = (_lag1(u) for u in d.frequency_damping_factor[rep])
                    clusters.append({int(d.order[i]): i for i in members})
                    pair |= {f"f{h}": sel.frequency_hz[j], f"xi{h}": sel.damping_ratio[j],
                             f"sigma_f{h}": sel.frequency_std[j], f"sigma_xi{h}": sel.damping_std[j],
                             f"mean_sigma_f{h}": mean.frequency_std[jm], f"mean_sigma_xi{h}": mean.damping_std[jm],
                             f"row_correlation{h}": _row_correlation(d.frequency_damping_factor[members, 1])}
                pair["z_f"], pair["z_xi"] = c.z_frequency[m], c.z_damping[m]
                pair["z_f_mean"] = (pair["f0"] - pair["f1"]) / np.hypot(pair["mean_sigma_f0"], pair["mean_sigma_f1"])
                pair["z_xi_mean"] = (pair["xi0"] - pair["xi1"]) / np.hypot(pair["mean_sigma_xi0"], pair["mean_sigma_xi1"])
                z = []
                for o in sorted(set(clusters[0]) & set(clusters[1])):
                    (d0, i0), (d1, i1) = (runs[0].diagram, clusters[0][o]), (runs[1].diagram, clusters[1][o])
                    df, dx = d0.frequency_hz[i0] - d1.frequency_hz[i1], d0.damping_ratio[i0] - d1.damping_ratio[i1]
                    z.append((o, df / np.hypot(d0.frequency_std[i0], d1.frequency_std[i1]),
                              dx / np.hypot(d0.damping_std[i0], d1.damping_std[i1]),
                              max(d0.noise_coupling[i0], d1.noise_coupling[i1])))
                    orders.append(dict(record=name, n_windows=n, order=o, above_noise_floor=o > k_star,
                                       z_f=z[-1][1], z_xi=z[-1][2], noise_coupling=z[-1][3],
                                       # issue 27 (p): each half's pole with its own σ and ρ
                                       own=[(df / np.sqrt(2) / d.frequency_std[i], dx / np.sqrt(2) / d.damping_std[i],
                                             d.noise_coupling[i]) for d, i in ((d0, i0), (d1, i1))]))
                z = np.array([t[1:3] for t in z], float).reshape(-1, 2)
                pair["fixed_z_f"], pair["fixed_z_xi"] = (np.sqrt(np.mean(z ** 2, 0)) if len(z) else (np.nan, np.nan))
                pair["common_orders"] = len(z)
                pairs.append(pair)
    return pairs, orders


def _rms(values):
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return np.sqrt(np.mean(v ** 2)) if v.size else np.nan


#: bins of the larger ρ (``Diagram.noise_coupling``) of the two poles compared, the bins of
#: studies/selected_members_mc.py's fixed-order table (the Monte Carlo side of (o))
RHO_BINS = ((0.0, 1.2), (1.2, 2.0), (2.0, 5.0), (5.0, np.inf))


def print_fixed_orders(pairs, orders):
    """The tables of issue 27 (o): RMS z of the same pairs read three ways, the fixed-order z by ρ and by
    number of windows."""
    print("| record | pairs | orders compared | fixed order: RMS z f, ξ (per pair over its common orders) | "
          "fixed order, above k*: RMS z f, ξ | selected, default σ: RMS z f, ξ | selected, σ of the mean: "
          "RMS z f, ξ | members' ξ-row correlation (median) |")
    print("|---|---|---|---|---|---|---|---|")
    for name in dict.fromkeys(p["record"] for p in pairs):
        mine = [p for p in pairs if p["record"] == name]
        o = [r for r in orders if r["record"] == name and r["above_noise_floor"]]
        corr = np.nanmedian([p[f"row_correlation{h}"] for p in mine for h in (0, 1)])
        print(f"| {name} | {len(mine)} | {sum(p['common_orders'] for p in mine)} | "
              f"{_rms([p['fixed_z_f'] for p in mine]):.2f}, {_rms([p['fixed_z_xi'] for p in mine]):.2f} | "
              f"{_rms([r['z_f'] for r in o]):.2f}, {_rms([r['z_xi'] for r in o]):.2f} | "
              f"{_rms([p['z_f'] for p in mine]):.2f}, {_rms([p['z_xi'] for p in mine]):.2f} | "
              f"{_rms([p['z_f_mean'] for p in mine]):.2f}, {_rms([p['z_xi_mean'] for p in mine]):.2f} | {corr:.2f} |")
    print("\nFixed order by ρ, the larger of the two poles' (orders compared, RMS z f, ξ, within ±1.96 f, ξ):\n")
    print("| record | " + " | ".join(f"ρ {lo:g}–{hi:g}" for lo, hi in RHO_BINS) + " |")
    print("|---|" + "---|" * len(RHO_BINS))
    for name in dict.fromkeys(p["record"] for p in pairs):
        cells = []
        for lo, hi in RHO_BINS:
            o = [r for r in orders if r["record"] == name and lo <= r["noise_coupling"] < hi]
            zf, zx = (np.array([r[k] for r in o], float) for k in ("z_f", "z_xi"))
            cells.append(f"{len(o)}, {_rms(zf):.2f}, {_rms(zx):.2f}, {100 * np.mean(np.abs(zf) <= Z_95):.0f} %, "
                         f"{100 * np.mean(np.abs(zx) <= Z_95):.0f} %" if o else "—")
        print(f"| {name} | " + " | ".join(cells) + " |")
    print("\nThe same, each half's pole read with its own σ (z = Δ / (√2 σ of that pole), binned by that pole's ρ; "
          "both halves' poles counted; issue 27 (p)):\n")
    print("| record | " + " | ".join(f"ρ {lo:g}–{hi:g}" for lo, hi in RHO_BINS) + " |")
    print("|---|" + "---|" * len(RHO_BINS))
    for name in dict.fromkeys(p["record"] for p in pairs):
        own = np.array([t for r in orders if r["record"] == name for t in r["own"]], float).reshape(-1, 3)
        cells = []
        for lo, hi in RHO_BINS:
            b = own[(own[:, 2] >= lo) & (own[:, 2] < hi)]
            cells.append(f"{len(b)}, {_rms(b[:, 0]):.2f}, {_rms(b[:, 1]):.2f}, {100 * np.mean(np.abs(b[:, 0]) <= Z_95):.0f} %, "
                         f"{100 * np.mean(np.abs(b[:, 1]) <= Z_95):.0f} %" if len(b) else "—")
        print(f"| {name} | " + " | ".join(cells) + " |")
    print("\nBy number of windows (fixed order, every common order; selected, default σ; the lag-1 block "
          "correlation ρ₁ of the representatives' f and ξ rows, mean ± its standard error):\n")
    print("| record | windows | orders compared | fixed order: RMS z f, ξ | pairs | selected: RMS z f, ξ | ρ₁ f | ρ₁ ξ |")
    print("|---|---|---|---|---|---|---|---|")
    for name in dict.fromkeys(p["record"] for p in pairs):
        for n in sorted({p["n_windows"] for p in pairs if p["record"] == name}):
            o = [r for r in orders if r["record"] == name and r["n_windows"] == n]
            mine = [p for p in pairs if p["record"] == name and p["n_windows"] == n]
            lag = {key: np.array([p[f"lag1_{key}{h}"] for p in mine for h in (0, 1)]) for key in ("f", "xi")}
            lag = {key: f"{v.mean():+.2f} ± {v.std(ddof=1) / np.sqrt(len(v)):.2f}" if len(v) > 1 else "—"
                   for key, v in lag.items()}
            print(f"| {name} | {n} | {len(o)} | {_rms([r['z_f'] for r in o]):.2f}, {_rms([r['z_xi'] for r in o]):.2f} | "
                  f"{len(mine)} | {_rms([p['z_f'] for p in mine]):.2f}, {_rms([p['z_xi'] for p in mine]):.2f} | "
                  f"{lag['f']} | {lag['xi']} |")


def stats(rows):
    """Pairs, RMS z, share within ±1.96 (a fraction) and the largest |z|, of f and of ξ, and the same
    RMS and share of each half read with its own σ; RMS z_MAC and the share of pairs whose "same mode"
    test of the shapes rejects at 5 % (in %)."""
    out = {"pairs": len(rows)}
    out["rms z_mac"] = rms_and_within(np.array([r["z_mac"] for r in rows], float))[0]
    p = np.array([r["mac_p_value"] for r in rows], float)
    p = p[np.isfinite(p)]
    out["rejected"] = 100 * np.mean(p < 0.05) if p.size else np.nan
    for key in ("z_f", "z_xi"):
        z = np.array([r[key] for r in rows], float)
        out[f"rms {key}"], out[f"within {key}"] = rms_and_within(z)
        z = z[np.isfinite(z)]
        out[f"max {key}"] = np.max(np.abs(z)) if z.size else np.nan
        # issue 27 (p): each half read with its own σ, both halves' z counted
        own = np.array([r[f"{key}_own{h}"] for r in rows for h in (1, 2)], float)
        out[f"rms own {key}"], out[f"within own {key}"] = rms_and_within(own)
        # (q): the product's 95 % interval ± t σ, t of the half's n_blocks − 1 (SelectedModes.intervals)
        factor = np.array([r[f"interval_factor{h}"] for r in rows for h in (1, 2)], float)
        out[f"within own interval {key}"] = rms_and_within(own * Z_95 / factor)[1] if rows else np.nan
    return out


def table_line(label, rows):
    s = stats(rows)
    if not s["pairs"]:
        return f"| {label} | 0 | — | — | — | — | — | — |"
    return (f"| {label} | {s['pairs']} | {s['rms z_f']:.2f}, {s['rms z_xi']:.2f} | "
            f"{100 * s['within z_f']:.0f} %, {100 * s['within z_xi']:.0f} % | {s['max z_f']:.1f}, {s['max z_xi']:.1f} | "
            f"{s['rms z_mac']:.2f}, {s['rejected']:.0f} % | {s['rms own z_f']:.2f}, {s['rms own z_xi']:.2f}; "
            f"{100 * s['within own z_f']:.0f} %, {100 * s['within own z_xi']:.0f} % | "
            f"{100 * s['within own interval z_f']:.0f} %, {100 * s['within own interval z_xi']:.0f} % |")


def print_tables(rows, failed, levels=LEVELS):
    print("| rows | pairs | RMS z f, ξ | within ±1.96 f, ξ | largest abs(z) f, ξ | shapes: RMS z_MAC, same mode "
          "rejected at 5 % | each half's own σ: RMS z f, ξ; within ±1.96 f, ξ | own σ: within the 95 % interval "
          "± t σ f, ξ |")
    print("|---|---|---|---|---|---|---|---|")
    for group in ("measured", "simulated", "earthquake", "Monte Carlo"):
        if not any(r["group"] == group for r in rows):
            continue
        names = [n for n in RECORDS if RECORDS[n][0] == group and any(r["record"] == n for r in rows)
                 and group != "Monte Carlo"]  # the Monte Carlo's records pooled only
        for name in names:
            mine = [r for r in rows if r["record"] == name]
            print(table_line(f"{name}, all windows", mine))
            for n in levels:
                print(table_line(f"{name}, {n} window(s)", [r for r in mine if r["n_windows"] == n]))
        mine = [r for r in rows if r["group"] == group]
        if group == "measured":
            print(table_line("**measured, pooled**", mine))
            print(table_line("measured, pooled, without harmonic-flagged pairs", [r for r in mine if not r["harmonic"]]))
            print(table_line("measured, pooled, without the pairs by σ alone", [r for r in mine if not r["by_std"]]))
            print(table_line("measured, pooled, without the pairs by σ alone and harmonic-flagged pairs",
                             [r for r in mine if not r["by_std"] and not r["harmonic"]]))
            print(table_line("measured, pooled, z_f_cap >= 3", [r for r in mine if r["z_f_cap"] >= 3]))
            print(table_line("measured, pooled, z_f_cap >= 3, without harmonic-flagged pairs",
                             [r for r in mine if r["z_f_cap"] >= 3 and not r["harmonic"]]))
            for n in levels:
                print(table_line(f"measured, {n} window(s) only", [r for r in mine if r["n_windows"] == n]))
            print(table_line("measured, long halves (1-2 windows)", [r for r in mine if r["n_windows"] <= 2]))
            print(table_line("measured, short halves (4-8 windows)", [r for r in mine if r["n_windows"] > 2]))
        elif mine:
            print(table_line(f"**{group}, pooled**" + (" (not in the measured pool)" if group == "earthquake" else ""),
                             mine))
            print(table_line(f"{group}, pooled, without the pairs by σ alone", [r for r in mine if not r["by_std"]]))
            print(table_line(f"{group}, pooled, z_f_cap >= 3", [r for r in mine if r["z_f_cap"] >= 3]))
            if group == "Monte Carlo":
                for n in levels:
                    print(table_line(f"Monte Carlo, {n} window(s) only", [r for r in mine if r["n_windows"] == n]))
    print()
    for name, n, k, msg in failed:
        print(f"failed: {name}, {n} window(s), window {k}: {msg}")
    worst = sorted((r for r in rows if r["group"] == "measured"),
                   key=lambda r: -max(abs(r["z_f"]), abs(r["z_xi"])))[:12]
    print("\nThe largest |z| of the measured records:\n")
    print("| record | windows | window (s) | f₁, f₂ (Hz) | σ_f₁, σ_f₂ (Hz) | z_f | z_f_cap | ξ₁, ξ₂ | σ_ξ₁, σ_ξ₂ | z_ξ | "
          "MAC | harmonic | rms ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in worst:
        print(f"| {r['record']} | {r['n_windows']} | {r['t0_s']:.0f}-{r['t1_s']:.0f} | {r['f1_hz']:.4f}, {r['f2_hz']:.4f} | "
              f"{r['sigma_f1_hz']:.2g}, {r['sigma_f2_hz']:.2g} | {r['z_f']:+.2f} | {r['z_f_cap']:.1f} | {r['xi1']:.4f}, {r['xi2']:.4f} | "
              f"{r['sigma_xi1']:.2g}, {r['sigma_xi2']:.2g} | {r['z_xi']:+.2f} | {r['mac']:.3f} | "
              f"{'yes' if r['harmonic'] else 'no'} | {r['rms_ratio']:.2f} |")


def main(data_dir="../shared/data", out=None, records=tuple(RECORDS), levels=LEVELS, tolerance=0.02,
         representative="median", pair_within_std=4.0, fixed_orders=False):
    """Run every record of ``records`` at every level of ``levels``, print the tables, write the
    pairs to ``out`` (CSV) if given; returns (rows, failed). With ``fixed_orders`` print the table of
    :func:`fixed_order_pairs` instead and return its (pairs, orders)."""
    data = Path(data_dir)
    for name in records:
        if name not in RECORDS:
            raise ValueError(f"record {name!r}: one of {tuple(RECORDS)}")
    if fixed_orders:
        pairs, orders = [], []
        for name in records:
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                p, o = fixed_order_pairs(name, data, levels)
            pairs += p
            orders += o
            print(f"{name}: {len(p)} pairs, {len(o)} orders compared, {time.perf_counter() - t:.1f} s", file=sys.stderr)
        print_fixed_orders(pairs, orders)
        return pairs, orders
    rows, failed = [], []
    for name in records:
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r, f = pairs_of_record(name, data, levels, tolerance, representative, pair_within_std)
        rows += r
        failed += f
        print(f"{name}: {len(r)} pairs, {len(f)} failed windows, {time.perf_counter() - t:.1f} s", file=sys.stderr)
    print_tables(rows, failed, levels)
    if out is not None:
        import pandas as pd

        pd.DataFrame(rows, columns=COLUMNS).to_csv(out, index=False)
        print(f"\nwrote {len(rows)} pairs to {out}", file=sys.stderr)
    return rows, failed


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data_dir", nargs="?", default="../shared/data")
    p.add_argument("--out", default=None, help="CSV of every pair")
    p.add_argument("--levels", type=int, nargs="+", default=list(LEVELS), help="numbers of windows (default 1 2 4 8)")
    p.add_argument("--tolerance", type=float, default=0.02, help="pairing: largest relative frequency difference")
    p.add_argument("--representative", choices=("median", "lowest", "shape-lowest", "shape-median", "no-order-check",
                                                "no-noise-twins", "no-pole-reassign", "no-unanchored", "cluster-mean"),
                   default="median",
                   help="ClusteringSettings.representative of every analysis (default median, with the "
                        "default shape_representative='lowest'); shape-lowest / shape-median: the median "
                        "representative with that shape_representative (shape-median: the default before "
                        "2026-11-27); no-order-check, no-noise-twins, no-pole-reassign: the default with "
                        "order_discrepancy, drop_noise_twins or reassign_borrowed_poles False; no-unanchored: "
                        "the default with unanchored_noise_coupling None; cluster-mean: the default with cluster_std='mean' "
                        "(issue 27 (o))")
    p.add_argument("--pair-within-std", type=float, default=4.0,
                   help="pairing: also pair frequencies within this many combined σ_f (default 4, the package's "
                        "default since 2026-11-28; 0: the relative window alone, the rule before)")
    p.add_argument("--fixed-orders", action="store_true",
                   help="issue 27 (o): compare the halves pole against pole at every common order (each pole's own "
                        "sigma) beside the selected modes' z with the default sigma and the sigma of the mean")
    p.add_argument("--records", nargs="+", default=list(RECORDS), help="records to run (default: all)")
    p.add_argument("--simulated-koma", type=int, default=0, metavar="N",
                   help="issue 27 (p): run N simulated records of the koma frame's system instead of --records "
                        "(the group 'Monte Carlo'; studies/selected_members_mc.py koma gives their per-record coverage)")
    args = p.parse_args()
    records = simulated_koma(args.simulated_koma) if args.simulated_koma else args.records
    main(args.data_dir, args.out, records=tuple(records), levels=tuple(args.levels), tolerance=args.tolerance,
         representative=args.representative, pair_within_std=args.pair_within_std, fixed_orders=args.fixed_orders)
