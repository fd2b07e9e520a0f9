"""Monte Carlo of the engineer's call with each selected mode's cluster kept: the members' orders,
f, ξ, σ and noise-coupling flags, the noise floor k*, and the selected value and σ of six
selections of the same identification (the default; ``order_discrepancy=False``, the σ before
2026-11-27 but for the noise-coupled clusters' rule; ``drop_noise_twins=False``, the selection
before the twins born of the noise were dropped; ``reassign_borrowed_poles=False``, the selection
before 2026-11-28; ``cluster_std="mean"``; ``representative="lowest"``), so that candidate σ for
the selected modes can be compared after the run on the same records (issue 27, docs/validation.md
(h), (i), (j)). The report also counts, per selection, the true modes found (a selected mode
within 2 %) and the modes selected.

Each table cell is median σ / σ_MC · coverage of ±1.96 σ around the Monte Carlo mean · RMS z, for
f and for ξ of each true mode; the last column counts the cells inside both bands (median
0.85–1.18, coverage 0.93–0.97) and gives the worst coverage.

With ``--max-order N`` every record is identified at orders 2..N only, and with ``--k-star-factor
C`` at orders 2..C k* (the record identified once at the automatic orders for its noise floor k*,
then again with the orders capped; no change where C k* reaches the automatic maximum): what the
engineer's call gives when it reads no member far above the true order (issue 27 (n)).

The report also reads every member pole as a fixed-order estimator (z against the records' mean
at that order, the pole's own σ), binned by its ρ (``Diagram.noise_coupling``), the Monte Carlo
side of docs/validation.md (o). ``--n-blocks N``, ``--duration S`` and ``--sensor-noise-ar
PHI,LEVEL`` (AR(1) sensor noise of std LEVEL times each channel's instead of the white 5 %) vary
the records for it, ``--excitation-ar PHI`` drives the chain with AR(1) forces instead of white
ones, and the structure ``chain10`` (a 10-DOF chain read in 1–10 Hz) has five modes outside the
band.

Usage:
  python studies/selected_members_mc.py RECORDS [chain|frame|chain10] OUT.pkl [--max-order N | --k-star-factor C]
        [--n-blocks N] [--duration S] [--sensor-noise-ar PHI,LEVEL | --excitation-ar PHI]
                                                                          # run (about 1 s a record)
  python studies/selected_members_mc.py --report OUT.pkl [OUT2.pkl ...]  # the tables again
"""
import pickle
import sys
import warnings

import numpy as np

import modaluq
from modaluq.settings import ClusteringSettings

FS = 50.0
DURATION = 400.0
#: structure: (modaluq.simulate keywords, seed offset)
STRUCTURES = {"chain": ({}, 7000), "frame": (dict(n_dof=4, input_dofs=(0, 3)), 8000),
              # issue 27 (o): a record with modes outside the band (1.2-9.4 Hz in it, 14-17 Hz above)
              "chain10": (dict(n_dof=10), 9000),
              # issue 27 (p): the system of the shared record koma_shearframe_sim.npz (koma_frame), output-only
              "koma": ({}, 10000)}
#: the engineer's band per structure (Hz); the true modes are those inside it
BANDS = {"chain": (1.0, 20.0), "frame": (1.0, 20.0), "chain10": (1.0, 10.0), "koma": (0.1, 1.5)}
#: sampling frequency per structure where it is not FS (Hz)
SAMPLING = {"koma": 12.0}
VARIANTS = {"default": None, "no order check": ClusteringSettings(order_discrepancy=False),
            "no noise twins": ClusteringSettings(drop_noise_twins=False),
            "no pole reassign": ClusteringSettings(reassign_borrowed_poles=False),
            "mean": ClusteringSettings(cluster_std="mean"), "lowest": ClusteringSettings(representative="lowest")}


def nearest_mode(sel, f0):
    """The selected mode nearest the true frequency ``f0`` within 2 %, or None."""
    j = np.flatnonzero(np.abs(sel.frequency_hz / f0 - 1) < 0.02)
    return None if not j.size else int(j[np.argmin(np.abs(sel.frequency_hz[j] - f0))])


def _mode_rows(res, truth):
    """Per true mode: a dict of each variant's (f, σ_f, ξ, σ_ξ) and the default's cluster members."""
    d = res.stabilization_diagram()
    sels = {v: res.select_modes(settings=c) for v, c in VARIANTS.items()}
    rows = []
    for f0 in truth:
        row = {}
        for v, sel in sels.items():
            j = nearest_mode(sel, f0)
            if j is None:
                continue
            row[v] = (sel.frequency_hz[j], sel.frequency_std[j], sel.damping_ratio[j], sel.damping_std[j])
            if v == "default":
                row["widened"] = bool(sel.order_discrepancy[j])
                m = np.asarray(sel.members[j])
                row["members"] = dict(order=d.order[m], f=d.frequency_hz[m], xi=d.damping_ratio[m],
                                      sf=d.frequency_std[m], sxi=d.damping_std[m],
                                      coupled=d.noise_coupled[m], rho=d.noise_coupling[m], rep=int(sel.representative_pole[j]),
                                      rep_index=int(np.flatnonzero(m == sel.representative_pole[j])[0]))
        row["k_star"] = int(d.noise_floor_order)
        row["n_blocks"] = int(res.n_blocks)  # the core's blocks (more than asked where whole blocks are left over)
        row["n_selected"] = {v: sel.n_modes for v, sel in sels.items()}
        rows.append(row)
    return rows


def identify_capped(y, u, fs, max_order=None, k_star_factor=None, n_blocks=None, band=(1.0, 20.0)):
    """The engineer's identification (automatic settings, ``frequency_range=band``; ``n_blocks``
    when given), at orders 2..max_order, or 2..k_star_factor k* (k* of the automatic
    identification), when given."""
    res = modaluq.identify(y, u, fs=fs, frequency_range=band, n_blocks=n_blocks)
    cap = max_order if k_star_factor is None else int(k_star_factor * res.significant_singular_values) // 2 * 2
    if cap is None or cap >= max(res.settings["orders"]):
        return res
    return modaluq.identify(y, u, fs=fs, frequency_range=band, n_blocks=n_blocks, orders=list(range(2, cap + 1, 2)))


def with_ar_sensor_noise(sim, seed, phi, level):
    """``sim``'s noise-free outputs plus AR(1) sensor noise (coefficient ``phi``, std ``level`` times
    each channel's std), independent per channel: colored noise, whose covariance at lags ≥ 1 is not
    zero, where the default white sensor noise enters lag 0 only (issue 27 (o))."""
    from scipy.signal import lfilter

    noise = lfilter([1.0], [1.0, -phi], np.random.default_rng(seed).standard_normal(sim.y.shape), axis=0)
    return sim.y + level * sim.y.std(0) * noise / noise.std(0)


def colored_chain(n_samples, seed, phi, discard=3000, noise_std=0.05):
    """The paper's chain (``modaluq.simulate``'s defaults: a known force at DOF 0, unknown forces of
    10 % at every DOF, 5 % white sensor noise) with every force passed through AR(1) (coefficient
    ``phi``): a colored excitation where ``simulate``'s is white (issue 27 (o)). Returns (y, u, the
    true frequencies in Hz); u is the known force as applied (colored)."""
    from scipy.signal import lfilter

    from modaluq.simulate import _chain, default_output_dofs

    m, k, c = _chain.chain_system(6)
    dofs = default_output_dofs(6)
    rng = np.random.default_rng(seed)  # drawn in simulate's order: phi = 0 gives simulate's record
    known = rng.standard_normal(n_samples + discard)
    force = rng.standard_normal((n_samples + discard, 6)) * 0.1
    force[:, 0] += known
    force, known = lfilter([1.0], [1.0, -phi], force, axis=0), lfilter([1.0], [1.0, -phi], known)
    y = np.empty((n_samples + discard, len(dofs)))
    _chain.ModalPlan(m, k, c, FS, dofs).run(iter([np.ascontiguousarray(force.T)]), y)
    y = y[discard:]
    y = y + noise_std * y.std(0) * rng.standard_normal(y.shape)  # simulate's order of operations
    return y, known[discard:, None], np.sort(_chain.modal_parameters(m, k, c, output_dofs=dofs)[0])


def koma_frame(n_samples, seed, discard=2000, noise=0.6):
    """The system of the shared record ``koma_shearframe_sim.npz`` (its data README: koma's notebook
    "Cov-SSI - Shear frame"): a 5-level shear frame, k = 8000, m = 500, dampers of 50 to ground,
    white forces of std 1000 at every level, **displacement** outputs (top level first), Gaussian
    noise of ``noise`` times each channel's std, fs = 12 Hz. Discretized exactly (zero-order hold of
    the forces) where the notebook integrates with Newmark, so the true modes are the continuous
    ones. Returns (y, the true frequencies in Hz)."""
    from scipy.signal import dlsim

    from modaluq.simulate import _chain

    n, fs = 5, SAMPLING["koma"]
    K = 8000.0 * (2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1))
    K[-1, -1] = 8000.0  # the top level has one spring
    M, C = 500.0 * np.eye(n), 50.0 * np.eye(n)
    A, B, _, _ = _chain.state_space(M, K, C, fs=fs, output_dofs=range(n))
    out = np.zeros((n, 2 * n))
    out[:, n:] = np.eye(n)[::-1]  # state [q'; q]: displacements, the top level first
    rng = np.random.default_rng(seed)
    force = 1000.0 * rng.standard_normal((n_samples + discard, n))
    y = dlsim((A, B, out, np.zeros((n, n)), 1 / fs), force)[1][discard:]
    y = y + noise * y.std(0) * rng.standard_normal(y.shape)
    return y, np.sort(_chain.modal_parameters(M, K, C, output_dofs=range(n))[0])


def run(n_records, structure, out=None, duration=DURATION, max_order=None, k_star_factor=None, n_blocks=None,
        sensor_noise_ar=None, excitation_ar=None):
    """Identify ``n_records`` records of ``structure`` (output-only, then input/output), at capped
    orders when asked (:func:`identify_capped`), with ``n_blocks`` blocks (None: automatic) and,
    with ``sensor_noise_ar`` = (phi, level), AR(1) sensor noise instead of the white 5 %
    (:func:`with_ar_sensor_noise`, seeded 99000 + the record's number), and with ``excitation_ar``
    = phi the chain driven by AR(1) forces (:func:`colored_chain`); write the data to ``out`` (a
    pickle) when given; return it."""
    if excitation_ar is not None and (structure != "chain" or sensor_noise_ar is not None):
        raise ValueError("excitation_ar: the chain only, with its white sensor noise")
    if structure == "koma" and (excitation_ar is not None or sensor_noise_ar is not None):
        raise ValueError("koma: its own white forces and sensor noise only")
    keywords, offset = STRUCTURES[structure]
    fs = SAMPLING.get(structure, FS)
    data = {"structure": structure, "records": {}}
    for with_input in (False,) if structure == "koma" else (False, True):
        name = "IO" if with_input else "OO"
        recs = []
        for k in range(n_records):
            if structure == "koma":
                (y, truth), u = koma_frame(int(duration * fs), offset + k), None
            elif excitation_ar is None:
                sim = modaluq.simulate(int(duration * FS), seed=offset + k, **keywords,
                                       **({} if sensor_noise_ar is None else {"noise_std": 0.0}))
                y = sim.y if sensor_noise_ar is None else with_ar_sensor_noise(sim, 99000 + k, *sensor_noise_ar)
                u, truth = sim.u, np.sort(sim.frequency_hz)
                truth = truth[(truth > BANDS[structure][0]) & (truth < BANDS[structure][1])]
            else:
                y, u, truth = colored_chain(int(duration * FS), offset + k, excitation_ar)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = identify_capped(y, u if with_input else None, fs, max_order, k_star_factor, n_blocks,
                                      BANDS[structure])
            recs.append(_mode_rows(res, truth))
            if (k + 1) % 20 == 0:
                print(f"{structure} {name}: {k + 1}/{n_records}", flush=True)
        data["records"][name] = recs
        data["truth"] = truth
    if out is not None:
        with open(out, "wb") as fh:
            pickle.dump(data, fh)
    return data


def spread_candidate(row):
    """A candidate measured and not taken (docs/validation.md (h)): the default's σ with the
    cluster's spread across orders added, √(σ² + spread²), for f and ξ."""
    mem = row["members"]
    sf, sxi = row["default"][1], row["default"][3]
    return np.hypot(sf, np.std(mem["f"], ddof=1)), np.hypot(sxi, np.std(mem["xi"], ddof=1))


#: ρ above which every reliable member of a cluster has lost its own directions to the freeze (the
#: core's default ClusteringOptions::unanchored_noise_coupling)
UNANCHORED_RHO = 2.0


def unanchored_candidate(row, limit=UNANCHORED_RHO):
    """The rule the selection took on 2026-12-07 (docs/validation.md (n)), computed after the run so
    that a run made without it shows it: a cluster none of whose reliable members (not flagged, the
    cluster not mostly flagged) has ρ ≤ ``limit`` has no order at which the mode's own singular
    directions are free (k* below them): its σ becomes the median over those members of ρ σ, the
    unfrozen σ's bound, when larger. None for pickles without ρ. (On a run with the rule in the core
    it changes nothing but the order-discrepancy widening's base, which comes first there.)"""
    mem = row["members"]
    if "rho" not in mem:
        return None
    sf, sxi = row["default"][1], row["default"][3]
    reliable = ~mem["coupled"]
    if 2 * reliable.sum() < reliable.size or not np.nanmin(mem["rho"][reliable], initial=np.inf) > limit:
        return sf, sxi
    rho = mem["rho"][reliable]
    return max(sf, np.median(rho * mem["sf"][reliable])), max(sxi, np.median(rho * mem["sxi"][reliable]))


def t_candidate(row):
    """Issue 27 (p), (q): the product's 95 % interval ± t σ (``SelectedModes.intervals``, t the
    Student-t quantile of the record's n_blocks − 1): the default's σ, read with the factor t
    instead of 1.96 (a third entry: the factor); None in pickles made before the blocks were kept."""
    from modaluq.intervals import interval_factor

    if "n_blocks" not in row:
        return None
    return row["default"][1], row["default"][3], interval_factor(int(row["n_blocks"]))


#: the candidates computed after the run from the default's cluster: label -> function of a row
CANDIDATES = {"√(σ² + spread²)": spread_candidate, f"unanchored (ρ > {UNANCHORED_RHO:g}): ρ σ": unanchored_candidate,
              "interval ± t σ (t of n_blocks − 1)": t_candidate}


def _cells(values, sigmas, factors=None):
    """median σ / std over records, coverage of ± factor σ (1.96, or each record's interval factor)
    around the mean, RMS z."""
    factors = np.full(np.shape(values), 1.96) if factors is None else np.asarray(factors, float)
    ok = np.isfinite(values) & np.isfinite(sigmas) & (sigmas > 0)
    v, s = values[ok], sigmas[ok]
    std = np.std(v, ddof=1)
    z = (v - v.mean()) / s
    return np.median(s) / std, np.mean(np.abs(z) <= factors[ok]), np.sqrt(np.mean(z ** 2))


def tables(data, variants=None, spread=True) -> dict:
    """{configuration: {variant: [(cells of f, cells of ξ) per true mode]}} from a run's data
    (``variants``: the selections kept, default this study's; ``spread``: with the candidates of
    :data:`CANDIDATES`, where the pickle holds what they need)."""
    variants = list(VARIANTS if variants is None else variants) + (list(CANDIDATES) if spread else [])
    out = {}
    for name, recs in data["records"].items():
        table = {}
        for m in range(len(data["truth"])):
            for v in variants:
                rows = [r[m] for r in recs if ("default" if v in CANDIDATES else v) in r[m]]
                if v in CANDIDATES:
                    sig = [CANDIDATES[v](r) for r in rows]
                    if any(x is None for x in sig):
                        continue
                    a = np.array([(r["default"][0], x[0], r["default"][2], x[1]) for r, x in zip(rows, sig)])
                    factors = np.array([x[2] if len(x) > 2 else 1.96 for x in sig])
                else:
                    a = np.array([r[v] for r in rows])
                    factors = None
                if len(rows) < 3:
                    continue
                table.setdefault(v, []).append((_cells(a[:, 0], a[:, 1], factors), _cells(a[:, 2], a[:, 3], factors)))
        out[name] = table
    return out


def print_table(structure, name, n_records, table):
    """A configuration's table: per selection, each true mode's cells of f and of ξ, and the cells in
    both bands with the worst coverage."""
    print(f"\n{structure} {name}, {n_records} records: median σ/σ_MC · coverage · RMS z per mode, f | ξ")
    for lab, cells in table.items():
        fs = ", ".join("{:.2f}·{:.2f}·{:.2f}".format(*c[0]) for c in cells)
        xs = ", ".join("{:.2f}·{:.2f}·{:.2f}".format(*c[1]) for c in cells)
        inband = sum((0.85 <= c[i][0] <= 1.18) and (0.93 <= c[i][1] <= 0.97) for c in cells for i in (0, 1))
        cov = min(c[i][1] for c in cells for i in (0, 1))
        print(f"| {lab} | {fs} | {xs} | {inband}/{2 * len(cells)}, cov ≥ {cov:.2f} |")


#: bins of ρ (``Diagram.noise_coupling``) of the fixed-order table, as in studies/split_halves_pool.py --fixed-orders
RHO_BINS = ((0.0, 1.2), (1.2, 2.0), (2.0, 5.0), (5.0, np.inf))


def _paired_orders(recs):
    """(ρ, z_f, z_ξ) as the split halves read them: records paired (0, 1), (2, 3), ..., at every order
    both records' clusters of a true mode hold, z = (x_a − x_b) / √(σ_a² + σ_b²), ρ the larger."""
    z = []
    for a, b in zip(recs[0::2], recs[1::2]):
        for ra, rb in zip(a, b):
            if "members" not in ra or "members" not in rb or "rho" not in ra["members"]:
                continue
            ma, mb = ra["members"], rb["members"]
            at = {int(o): i for i, o in enumerate(mb["order"])}
            for i, o in enumerate(ma["order"]):
                if int(o) in at:
                    j = at[int(o)]
                    z.append((max(ma["rho"][i], mb["rho"][j]), (ma["f"][i] - mb["f"][j]) / np.hypot(ma["sf"][i], mb["sf"][j]),
                              (ma["xi"][i] - mb["xi"][j]) / np.hypot(ma["sxi"][i], mb["sxi"][j])))
    return z


def fixed_order_by_rho(recs, min_records=100, paired=False):
    """Issue 27 (o): every member pole of the selected true modes read as a fixed-order estimator. At
    each order a mode's cluster holds in at least ``min_records`` records, z = (x − mean over those
    records) / the pole's own σ; or, with ``paired``, as the split halves read them
    (:func:`_paired_orders`). Returned per bin of ρ (:data:`RHO_BINS`) as (poles, RMS z f, RMS z ξ,
    coverage f, coverage ξ)."""
    z = _paired_orders(recs) if paired else []
    for m in range(0 if paired else max(map(len, recs))):
        per_order = {}
        for r in recs:
            if m < len(r) and "members" in r[m] and "rho" in r[m]["members"]:
                mem = r[m]["members"]
                for i, o in enumerate(mem["order"]):
                    per_order.setdefault(int(o), []).append((mem["f"][i], mem["sf"][i], mem["xi"][i], mem["sxi"][i],
                                                             mem["rho"][i]))
        for v in per_order.values():
            if len(v) >= min_records:
                v = np.array(v)
                z += zip(v[:, 4], (v[:, 0] - v[:, 0].mean()) / v[:, 1], (v[:, 2] - v[:, 2].mean()) / v[:, 3])
    z = np.array(z, float).reshape(-1, 3)
    out = {}
    for lo, hi in RHO_BINS:
        b = z[(z[:, 0] >= lo) & (z[:, 0] < hi)]
        if len(b):
            out[(lo, hi)] = (len(b), *np.sqrt(np.mean(b[:, 1:] ** 2, 0)), *np.mean(np.abs(b[:, 1:]) <= 1.96, 0))
    return out


def report(paths):
    for path in paths:
        with open(path, "rb") as fh:
            data = pickle.load(fh)
        for name, table in tables(data).items():
            print_table(data["structure"], name, len(data["records"][name]), table)
        for name, recs in data["records"].items():
            if all("n_selected" in r[0] for r in recs):  # pickles made before 2026-11-28 lack it
                found = {v: [sum(v in r[m] for r in recs) for m in range(len(data["truth"]))] for v in VARIANTS}
                print(f"{data['structure']} {name}: true modes found / modes selected per record, by selection: "
                      + "; ".join(f"{v} {found[v]} / {np.mean([r[0]['n_selected'][v] for r in recs]):.2f}"
                                  for v in VARIANTS))
            fired = np.mean([r[m]["widened"] for r in recs for m in range(len(r)) if "widened" in r[m]])
            print(f"{data['structure']} {name}: σ widened by the order (order_discrepancy) for {100 * fired:.1f} % "
                  "of the selected true modes")
            for paired, label in ((False, "member poles as fixed-order estimators by ρ"),
                                  (True, "the same read as the split halves read them (records paired, orders both hold)")):
                bins = fixed_order_by_rho(recs, min_records=min(100, max(2, len(recs) // 2)), paired=paired)
                print(f"{data['structure']} {name}: {label} (issue 27 (o)): "
                      + "; ".join(f"ρ {lo:g}–{hi:g}: {b[0]} poles, RMS z {b[1]:.2f}, {b[2]:.2f}, coverage {b[3]:.3f}, "
                                  f"{b[4]:.3f}" for (lo, hi), b in bins.items()))


if __name__ == "__main__":
    if sys.argv[1] == "--report":
        report(sys.argv[2:])
    else:
        cap = dict(zip(sys.argv[4::2], sys.argv[5::2]))
        unknown = set(cap) - {"--max-order", "--k-star-factor", "--n-blocks", "--duration", "--sensor-noise-ar",
                              "--excitation-ar"}
        if unknown:
            sys.exit(f"unknown options {sorted(unknown)}; see the usage in the docstring")
        run(int(sys.argv[1]), sys.argv[2], sys.argv[3],
            max_order=int(cap["--max-order"]) if "--max-order" in cap else None,
            k_star_factor=float(cap["--k-star-factor"]) if "--k-star-factor" in cap else None,
            n_blocks=int(cap["--n-blocks"]) if "--n-blocks" in cap else None,
            duration=float(cap.get("--duration", DURATION)),
            sensor_noise_ar=tuple(map(float, cap["--sensor-noise-ar"].split(","))) if "--sensor-noise-ar" in cap else None,
            excitation_ar=float(cap["--excitation-ar"]) if "--excitation-ar" in cap else None)
