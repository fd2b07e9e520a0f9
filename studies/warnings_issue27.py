"""Issue 27, item 4: how often each warning of a run fires, and whether what it says changes a
selected mode or its σ (docs/settings.md, "Warnings that mean something").

Runs as a user would (``Analysis.from_file`` / ``from_arrays`` with automatic settings and a band):
the shared records (docs/make_record_figures.sh's calls) and simulations with known modes (the
paper's chain, and a 10-mass "beam-like" chain with a 0.3 %-damped first mode, 8 outputs and a
band from 0.5 Hz). For the simulations each selected mode is matched to the truth (within 3 %)
and z = (estimate − truth) / σ is kept: a warning that matters shows as z beyond ±1.96.

Usage: nice -n 19 python studies/warnings_issue27.py [DATA_DIR] [N_SEEDS]   (default ../shared/data, 24)
About 3 CPU minutes at 24 seeds.
"""
import json
import sys
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

import modaluq
from modaluq import Analysis, Settings

RECORDS = {  # name: (file, Analysis.from_file keywords, settings keywords) as docs/make_record_figures.sh
    "koma frame": ("koma_shearframe_sim.npz", {}, dict(frequency_range=(0.1, 1.5))),
    "bridge": ("ssicov_lysefjord_bridge_sim.npz", {}, dict(frequency_range=(0.15, 1.5))),
    "slab": ("cessipy_smartphone_slab.npz", dict(outputs=["phone_Z_vertical"]),
             dict(start=4.705, stop=43.248, frequency_range=(10, 30))),
    "Meloland (ground input)": ("cesmd_meloland_overpass_2016.npz", {}, dict(frequency_range=(1, 20))),
    "Painter Street (ground input)": ("cesmd_painter_st_overpass_2016.npz", {}, dict(frequency_range=(1, 15))),
    "wind turbine": ("owi_offshore_wind_turbine_tower_2020.tdms", {}, dict(frequency_range=(0.2, 5))),
    "sensor array": ("owi_sensor_array_with_ambient_2022.tdms", dict(read_options=dict(group="acceleration")),
                     dict(frequency_range=(1, 60))),
}


def kinds(a):
    """The kind of each warning of an analysis: the core's code, or what Python added (by the
    function that words it; a study may read its own words)."""
    res = a.result
    out = []
    for w in a.warnings:
        if w in res.warnings and res.warning_codes[res.warnings.index(w)] is not None:
            out.append(str(res.warning_codes[res.warnings.index(w)]))
        elif "decay" in w and "slow" in w:
            out.append("slow_decay")
        elif "block_rows" in w and "period" in w:
            out.append("short_lags")
        elif "constant" in w:
            out.append("constant_channel")
        else:
            out.append("other: " + w[:60])
    return out


SIMULATIONS = {  # name: (simulate keywords, with the input?, band)
    "chain OO, band 1-20 Hz": (dict(n_samples=20_000), False, (1, 20)),
    "chain IO, band 1-20 Hz": (dict(n_samples=20_000), True, (1, 20)),
    "chain OO, band 0.5-20 Hz": (dict(n_samples=20_000), False, (0.5, 20)),
    "beam-like OO, band 0.5-20 Hz": (dict(n_samples=20_000, n_dof=10, output_dofs=(0, 1, 2, 4, 5, 7, 8, 9),
                                          damping_ratio=[0.003] + [0.01] * 9), False, (0.5, 20)),
}


def simulated_run(name, seed):
    kw, io, band = SIMULATIONS[name]
    sim = modaluq.simulate(seed=seed, **kw)
    a = Analysis.from_arrays(sim.y, sim.u if io else None, fs=sim.fs,
                             settings=Settings(frequency_range=band)).run(check_harmonics=False, issue_warnings=False)
    sel = a.selected
    truth_f, truth_xi = np.asarray(sim.frequency_hz), np.asarray(sim.damping_ratio)
    modes = []
    for k in range(sel.n_modes):
        j = int(np.argmin(abs(truth_f - sel.frequency_hz[k]) / truth_f))
        if abs(truth_f[j] - sel.frequency_hz[k]) / truth_f[j] > 0.03:
            continue
        modes.append(dict(true_mode=j, f=float(sel.frequency_hz[k]),
                          zf=float((sel.frequency_hz[k] - truth_f[j]) / sel.frequency_std[k]),
                          zxi=float((sel.damping_ratio[k] - truth_xi[j]) / sel.damping_std[k]),
                          slow=bool(sel.block_too_short[k])))
    found = sorted({m["true_mode"] for m in modes})
    return dict(kinds=kinds(a), modes=modes, found=found, n_true=len(truth_f), **raw_slow_decay(a),
                block_rows=a.result.settings["block_rows"], n_blocks=a.result.n_blocks)


def raw_slow_decay(a):
    """identify()'s own slow-decay warning (every pole of every order): said, and whether the core's
    "use n_blocks <= K" would go below the rules' fewest blocks (2 <= K < max(10, 2 l + 3))."""
    slow = a.result.slow_decay
    fewest = max(10, 2 * a.result.n_outputs + 3)
    return dict(raw_slow=slow is not None,
                raw_below_fewest=slow is not None and 2 <= slow.fitting_n_blocks < fewest)


def main(data=Path("../shared/data"), n_seeds=24, out=None):
    report = {"records": {}, "simulations": {}}
    print("| record | analysis's warnings (kind) | identify()'s slow-decay warning |\n|---|---|---|")
    for name, (file, fkw, skw) in RECORDS.items():
        path = data / file
        if not path.exists():
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a = Analysis.from_file(path, settings=Settings(**skw), **fkw).run(check_harmonics=False,
                                                                              issue_warnings=False)
        k = kinds(a)
        report["records"][name] = dict(kinds=k, warnings=list(a.warnings), **raw_slow_decay(a),
                                       selected_hz=[round(float(f), 4) for f in a.selected.frequency_hz])
        raw = raw_slow_decay(a)
        print(f"| {name} | {', '.join(k) or '–'} | {'yes' if raw['raw_slow'] else 'no'}"
              f"{' (K below the fewest blocks)' if raw['raw_below_fewest'] else ''} |")
    print("\n| simulation | runs | fired (runs) | identify()'s slow decay: runs, K below the fewest | modes found | "
          "coverage f / ξ, all modes | slow-flagged modes: n, coverage f / ξ |")
    print("|---|---|---|---|---|---|---|")
    for name in SIMULATIONS:
        runs = []
        for seed in range(n_seeds):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                runs.append(simulated_run(name, seed))
        report["simulations"][name] = runs
        fired = Counter(k for r in runs for k in set(r["kinds"]))
        ms = [m for r in runs for m in r["modes"]]
        slow = [m for m in ms if m["slow"]]

        def cov(lst, key):
            return f"{100 * np.mean([abs(m[key]) < 1.96 for m in lst]):.0f} %" if lst else "–"
        found = np.mean([len(r["found"]) / r["n_true"] for r in runs])
        print(f"| {name} | {len(runs)} | {', '.join(f'{k} {v}' for k, v in sorted(fired.items())) or '–'} | "
              f"{sum(r['raw_slow'] for r in runs)}, {sum(r['raw_below_fewest'] for r in runs)} | {100 * found:.0f} % | {cov(ms, 'zf')} / {cov(ms, 'zxi')} | {len(slow)}: {cov(slow, 'zf')} / "
              f"{cov(slow, 'zxi')} |")
    if out:
        Path(out).write_text(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    args = sys.argv[1:]
    main(Path(args[0]) if args else Path("../shared/data"), int(args[1]) if len(args) > 1 else 24,
         out=args[2] if len(args) > 2 else None)
