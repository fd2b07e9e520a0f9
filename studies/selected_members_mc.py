"""Monte Carlo of the engineer's call with each selected mode's cluster kept: the members' orders,
f, ξ and σ, the noise floor k*, and the selected value and σ of three selections of the same
identification (the default, ``cluster_std="mean"``, ``representative="lowest"``), so that
candidate σ for the selected modes can be compared after the run on the same records (issue 27:
the output-only engineer's call is 10–40 % low).

Usage:
  python studies/selected_members_mc.py RECORDS [chain|frame] OUT.pkl    # run (about 1.5 s a record)
  python studies/selected_members_mc.py --report OUT.pkl [OUT2.pkl ...]  # the candidates' tables
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
STRUCTURES = {"chain": ({}, 7000), "frame": (dict(n_dof=4, input_dofs=(0, 3)), 8000)}
VARIANTS = {"default": None, "mean": ClusteringSettings(cluster_std="mean"),
            "lowest": ClusteringSettings(representative="lowest")}


def _mode_rows(res, truth):
    """Per true mode: a dict of each variant's (f, σ_f, ξ, σ_ξ) and the default's cluster members."""
    d = res.stabilization_diagram()
    sels = {v: res.select_modes(settings=c) for v, c in VARIANTS.items()}
    rows = []
    for f0 in truth:
        row = {}
        for v, sel in sels.items():
            j = np.flatnonzero(np.abs(sel.frequency_hz / f0 - 1) < 0.02)
            if not j.size:
                continue
            j = j[np.argmin(np.abs(sel.frequency_hz[j] - f0))]
            row[v] = (sel.frequency_hz[j], sel.frequency_std[j], sel.damping_ratio[j], sel.damping_std[j])
            if v == "default":
                m = np.asarray(sel.members[j])
                row["members"] = dict(order=d.order[m], f=d.frequency_hz[m], xi=d.damping_ratio[m],
                                      sf=d.frequency_std[m], sxi=d.damping_std[m],
                                      coupled=d.noise_coupled[m], rep=int(sel.representative_pole[j]),
                                      rep_index=int(np.flatnonzero(m == sel.representative_pole[j])[0]))
        row["k_star"] = int(d.noise_floor_order)
        rows.append(row)
    return rows


def run(n_records, structure, out):
    keywords, offset = STRUCTURES[structure]
    data = {"structure": structure, "records": {}}
    for with_input in (False, True):
        name = "IO" if with_input else "OO"
        recs = []
        for k in range(n_records):
            sim = modaluq.simulate(int(DURATION * FS), seed=offset + k, **keywords)
            truth = np.sort(sim.frequency_hz)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = modaluq.identify(sim.y, sim.u if with_input else None, fs=sim.fs, frequency_range=(1, 20))
            recs.append(_mode_rows(res, truth))
            if (k + 1) % 20 == 0:
                print(f"{structure} {name}: {k + 1}/{n_records}", flush=True)
        data["records"][name] = recs
        data["truth"] = truth
    with open(out, "wb") as fh:
        pickle.dump(data, fh)


def candidates(row):
    """Candidate σ (f, ξ) for the default's selected value, from its cluster."""
    mem = row["members"]
    ok = ~mem["coupled"] & np.isfinite(mem["sf"])
    if not ok.any():  # every member noise-coupled: the selection's own fallback
        ok = np.isfinite(mem["sf"])
    f, xi, sf, sxi = (mem[k][ok] for k in ("f", "xi", "sf", "sxi"))
    med_f, med_x = np.median(sf), np.median(sxi)
    spread_f, spread_x = np.std(f, ddof=1), np.std(xi, ddof=1)
    mad_f = 1.4826 * np.median(np.abs(f - np.median(f)))
    mad_x = 1.4826 * np.median(np.abs(xi - np.median(xi)))
    return {
        "median σ (now)": (med_f, med_x),
        "√(σ² + spread²)": (np.hypot(med_f, spread_f), np.hypot(med_x, spread_x)),
        "√(σ² + MAD²)": (np.hypot(med_f, mad_f), np.hypot(med_x, mad_x)),
        "max(σ, spread)": (max(med_f, spread_f), max(med_x, spread_x)),
        "RMS member σ": (np.sqrt(np.mean(sf ** 2)), np.sqrt(np.mean(sxi ** 2))),
    }


def _cells(values, sigmas):
    """median σ / std over records, coverage of ±1.96 σ around the mean, RMS z."""
    ok = np.isfinite(values) & np.isfinite(sigmas) & (sigmas > 0)
    v, s = values[ok], sigmas[ok]
    std = np.std(v, ddof=1)
    z = (v - v.mean()) / s
    return np.median(s) / std, np.mean(np.abs(z) <= 1.96), np.sqrt(np.mean(z ** 2))


def report(paths):
    for path in paths:
        with open(path, "rb") as fh:
            data = pickle.load(fh)
        truth = data["truth"]
        for name, recs in data["records"].items():
            print(f"\n{data['structure']} {name}, {len(recs)} records: median σ/σ_MC · coverage · RMS z, f | ξ")
            labels = None
            table = {}
            for m in range(len(truth)):
                rows = [r[m] for r in recs if "default" in r[m]]
                vf = np.array([r["default"][0] for r in rows])
                vx = np.array([r["default"][2] for r in rows])
                cand = [candidates(r) for r in rows]
                labels = list(cand[0])
                for lab in labels:
                    sfs = np.array([c[lab][0] for c in cand])
                    sxs = np.array([c[lab][1] for c in cand])
                    table.setdefault(lab, []).append((_cells(vf, sfs), _cells(vx, sxs)))
                for v in ("mean", "lowest"):
                    rv = [r[v] for r in recs if v in r[m] for r in [r[m]]]
                    a = np.array(rv)
                    table.setdefault(f"selection {v!r}", []).append((_cells(a[:, 0], a[:, 1]),
                                                                   _cells(a[:, 2], a[:, 3])))
            for lab, cells in table.items():
                fs = ", ".join(f"{c[0][0]:.2f}·{c[0][1]:.2f}" for c in cells)
                xs = ", ".join(f"{c[1][0]:.2f}·{c[1][1]:.2f}" for c in cells)
                inband = sum((0.85 <= c[i][0] <= 1.18) and (0.93 <= c[i][1] <= 0.97) for c in cells for i in (0, 1))
                cov = min(c[i][1] for c in cells for i in (0, 1))
                print(f"| {lab} | {fs} | {xs} | {inband}/{2 * len(cells)}, cov ≥ {cov:.2f} |")


if __name__ == "__main__":
    if sys.argv[1] == "--report":
        report(sys.argv[2:])
    else:
        run(int(sys.argv[1]), sys.argv[2], sys.argv[3])
