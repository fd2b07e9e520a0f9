"""The engineer's call (``identify(y, u, fs, frequency_range=(1, 20)).select_modes()``, automatic
settings) Monte Carlo of studies/selected_members_mc.py, with every record identified twice on the
same samples: the default, and with ``block_correlation_correction=True`` (docs/uq-math.md §3.1), the
default selection of each. It asks whether the gated block-correlation correction fixes the
input/output miscalibration of the selected modes' σ (docs/validation.md, issue 27 (h): the frame's
modes 3–4 over-covered, modes 1–2 low) without harming any other cell.

Records and seeds as studies/selected_members_mc.py (400 s; chain 7000 + k, frame 8000 + k),
output-only then input/output. Per selected true mode and identification it keeps f, σ_f, ξ, σ_ξ,
the order-discrepancy flag, the lag-1 statistic ρ of (3.4) at the representative (from the
default identification's factor rows, before the gate), and, for the corrected identification, the variance factor c
(``Modes.block_correlation_scale``, 1 where the gate stays shut) of the representative pole and of
every cluster member (read from ``Result.modes`` in the diagram's pole order), with n_blocks.

Each table cell is median σ / σ_MC · coverage of ±1.96 σ around the Monte Carlo mean · RMS z, for
f and for ξ of each true mode; the last column counts the cells inside both bands (median
0.85–1.18, coverage 0.93–0.97) and gives the worst coverage. The "default" rows are those of
studies/selected_members_mc.py on the same records.

Usage:
  python studies/selected_members_block_mc.py RECORDS [chain|frame] OUT.pkl [MAX_SECONDS]  # run
  python studies/selected_members_block_mc.py --report OUT.pkl [OUT2.pkl ...]            # the tables again

MAX_SECONDS (optional) stops a run after the record that passes half of it in each of output-only
and input/output, so both get the same records; the pickle holds the records done.
"""
import pathlib
import pickle
import sys
import time
import warnings

import numpy as np

import modaluq

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
# the records, the statistics and the table of the engineer's call (studies/selected_members_mc.py)
from selected_members_mc import DURATION, FS, STRUCTURES, nearest_mode, print_table, tables  # noqa: E402

#: identification: identify keywords (beside frequency_range)
VARIANTS = {"default": {}, "block corr": {"block_correlation_correction": True}}


def _pole_scale(res, d):
    """(n_poles,) block_correlation_scale of every diagram pole (the diagram's poles are the modes
    of every order, in order; Diagram.pole_covariance reads them alike), checked against f."""
    scale = np.concatenate([np.asarray(m.block_correlation_scale, float) for m in res.modes])
    f = np.concatenate([np.asarray(m.frequency_hz, float) for m in res.modes])
    if scale.size != d.frequency_hz.size or not np.array_equal(f, d.frequency_hz):
        raise RuntimeError("the diagram's poles are not the modes of every order in order")
    return scale


def _pole_rho(res):
    """(n_poles,) the lag-1 statistic ρ of uq-math (3.4) of every pole, from its factor rows u_f, u_ξ
    (blocks in time order): the mean of the defined ρ_r plus 1/n_b, before the gate; the correction
    would give c = max(1/4, 1 + 2ρ) where |ρ| > 2/√n_b."""
    u = np.concatenate([np.asarray(m.frequency_damping_factor, float) for m in res.modes])
    den = np.sum(u ** 2, axis=2)
    num = np.sum(u[:, :, 1:] * u[:, :, :-1], axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(den > 0, num / den, np.nan)
    return np.nanmean(r, axis=1) + 1.0 / u.shape[2]


def _mode_rows(results, truth):
    """Per true mode: a dict of each identification's (f, σ_f, ξ, σ_ξ), order-discrepancy flag, and
    (corrected run) c of the representative and of the cluster's members."""
    sels, scales = {}, {}
    for v, res in results.items():
        d = res.stabilization_diagram()
        sels[v] = res.select_modes()
        scales[v] = _pole_scale(res, d)
    rho = _pole_rho(results["default"])
    rows = []
    for f0 in truth:
        row = {}
        for v, sel in sels.items():
            j = nearest_mode(sel, f0)
            if j is None:
                continue
            row[v] = (sel.frequency_hz[j], sel.frequency_std[j], sel.damping_ratio[j], sel.damping_std[j])
            row[v + " widened"] = bool(sel.order_discrepancy[j])
            row[v + " c_rep"] = float(scales[v][int(sel.representative_pole[j])])
            row[v + " c_members"] = scales[v][np.asarray(sel.members[j])]
            row[v + " rho_rep"] = float(rho[int(sel.representative_pole[j])])  # the default run's ρ
        row["n_selected"] = {v: sel.n_modes for v, sel in sels.items()}
        row["n_blocks"] = int(results["default"].settings["n_blocks"])
        rows.append(row)
    return rows


def run(n_records, structure, out=None, duration=DURATION, max_seconds=None):
    """Identify ``n_records`` records of ``structure`` (output-only, then input/output) with each
    identification of ``VARIANTS``; write the data to ``out`` (a pickle) when given; return it."""
    keywords, offset = STRUCTURES[structure]
    data = {"structure": structure, "records": {}, "seconds": {}}
    for with_input in (False, True):
        name = "IO" if with_input else "OO"
        recs = []
        t0 = time.perf_counter()
        for k in range(n_records):
            sim = modaluq.simulate(int(duration * FS), seed=offset + k, **keywords)
            truth = np.sort(sim.frequency_hz)
            results = {}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                for v, kw in VARIANTS.items():
                    results[v] = modaluq.identify(sim.y, sim.u if with_input else None, fs=sim.fs,
                                                  frequency_range=(1, 20), **kw)
            recs.append(_mode_rows(results, truth))
            if (k + 1) % 20 == 0:
                print(f"{structure} {name}: {k + 1}/{n_records}, {time.perf_counter() - t0:.0f} s", flush=True)
            if max_seconds is not None and time.perf_counter() - t0 > max_seconds / 2:
                print(f"{structure} {name}: stopped after {k + 1} records (time)", flush=True)
                n_records = k + 1  # input/output gets as many records
                break
        data["records"][name] = recs
        data["seconds"][name] = time.perf_counter() - t0
        data["truth"] = truth
    if out is not None:
        with open(out, "wb") as fh:
            pickle.dump(data, fh)
    return data


def report(paths):
    for path in paths:
        with open(path, "rb") as fh:
            data = pickle.load(fh)
        for name, table in tables(data, VARIANTS, spread=False).items():
            recs = data["records"][name]
            print_table(data["structure"], name, len(recs), table)
            n_modes = len(data["truth"])
            found = {v: [sum(v in r[m] for r in recs) for m in range(n_modes)] for v in VARIANTS}
            print(f"{data['structure']} {name}: true modes found / modes selected per record: "
                  + "; ".join(f"{v} {found[v]} / {np.mean([r[0]['n_selected'][v] for r in recs]):.2f}"
                              for v in VARIANTS))
            nb = [r[0]["n_blocks"] for r in recs]
            print(f"{data['structure']} {name}: n_blocks {min(nb)}–{max(nb)} (median {np.median(nb):.0f}), "
                  f"gate 2/√n_b {2 / np.sqrt(max(nb)):.2f}–{2 / np.sqrt(min(nb)):.2f}")
            v = "block corr"
            for m in range(n_modes):
                rows = [r[m] for r in recs if v in r[m]]
                c_rep = np.array([r[v + " c_rep"] for r in rows])
                mem = [r[v + " c_members"] for r in rows]
                share = np.array([np.mean(c != 1) for c in mem])
                fired = c_rep[c_rep != 1]
                print(f"  mode {m + 1}: gate fired at the representative in {np.mean(c_rep != 1):.1%} of "
                      f"{len(rows)} records (median c where fired "
                      f"{np.median(fired) if fired.size else float('nan'):.2f}, range "
                      f"{(fired.min() if fired.size else float('nan')):.2f}–"
                      f"{(fired.max() if fired.size else float('nan')):.2f}); "
                      f"members with c ≠ 1: {np.mean(np.concatenate(mem) != 1):.1%} of all, "
                      f"≥ 1 in {np.mean(share > 0):.1%} of records, most in {np.mean(share > 0.5):.1%}; "
                      f"median c of all members {np.median(np.concatenate(mem)):.2f}; "
                      f"σ changed (f or ξ) in {np.mean([r[v][1] != r['default'][1] or r[v][3] != r['default'][3] for r in rows if 'default' in r]):.1%}")
                rho = np.array([r[m]["default rho_rep"] for r in recs if "default rho_rep" in r[m]])
                nb = np.array([r[m]["n_blocks"] for r in recs if "default rho_rep" in r[m]])
                c_would = np.where(np.abs(rho) > 2 / np.sqrt(nb), np.maximum(0.25, 1 + 2 * rho), 1.0)
                print(f"          default's representative: ρ median {np.median(rho):+.3f} (quartiles "
                      f"{np.quantile(rho, 0.25):+.3f}, {np.quantile(rho, 0.75):+.3f}); |ρ| > 2/√n_b in "
                      f"{np.mean(c_would != 1):.1%}; ungated 1 + 2ρ median {np.median(1 + 2 * rho):.2f}")
            for v in VARIANTS:
                fired = np.mean([r[m][v + " widened"] for r in recs for m in range(len(r)) if v in r[m]])
                print(f"{data['structure']} {name} {v}: σ widened by the order (order_discrepancy) for "
                      f"{100 * fired:.1f} % of the selected true modes")
            if "seconds" in data:
                print(f"{data['structure']} {name}: {data['seconds'][name]:.0f} s "
                      f"({data['seconds'][name] / len(recs):.2f} s per record, both identifications)")


if __name__ == "__main__":
    if sys.argv[1] == "--report":
        report(sys.argv[2:])
    else:
        run(int(sys.argv[1]), sys.argv[2], sys.argv[3],
            max_seconds=float(sys.argv[4]) if len(sys.argv) > 4 else None)
