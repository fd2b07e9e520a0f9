"""Monte Carlo check of the σ the engineer reads: the selected modes of the engineer's call
(`identify(y, u, fs, frequency_range=(1, 20)).select_modes()`, automatic settings) over N
independent records of the paper's chain. For each true mode: the std of the selected frequency
and damping across records against the median (over records) of the reported σ (itself the
median over the mode's cluster), and the coverage of ±1.96 σ around the Monte Carlo mean.
Usage: python studies/selected_sigma_mc.py [N] [seconds] [bootstrap draws]
(default 100 records of 400 s, no bootstrap: about 10 min on one core; with draws, σ above the
noise floor from identify's bootstrap, docs/uq-math.md §5.6, and a second table with the
selection's ``cluster_std="mean"`` from the same identifications)
"""
import sys
import warnings

import numpy as np

import modaluq
from modaluq.settings import ClusteringSettings


def main(n_records=100, duration=400.0, bootstrap_draws=0):
    """Print the table of each configuration (input/output, output-only) over ``n_records``
    records of ``duration`` seconds; return the (records, modes, 4) arrays of f, σ_f, ξ, σ_ξ
    (with draws, also under "<configuration>, cluster mean")."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _run(n_records, duration, bootstrap_draws)


def _row(sel, truth):
    """f, σ_f, ξ, σ_ξ of the selected mode within 2 % of each true frequency (NaN: none)."""
    row = np.full((len(truth), 4), np.nan)
    for k, f0 in enumerate(truth):
        j = np.flatnonzero(np.abs(sel.frequency_hz / f0 - 1) < 0.02)
        if j.size:
            j = j[np.argmin(np.abs(sel.frequency_hz[j] - f0))]
            row[k] = sel.frequency_hz[j], sel.frequency_std[j], sel.damping_ratio[j], sel.damping_std[j]
    return row


def _table(a, truth, title, n_records):
    print(f"\n{title}")
    print("| mode | f (Hz) | found | std f (MC) | median σ_f | ratio | coverage f | std ξ (MC) | median σ_ξ "
          "| ratio | coverage ξ |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for k, f0 in enumerate(truth):
        ok = np.isfinite(a[:, k, 0])
        sf, ssf = np.std(a[ok, k, 0], ddof=1), np.median(a[ok, k, 1])
        sx, ssx = np.std(a[ok, k, 2], ddof=1), np.median(a[ok, k, 3])
        cf = np.mean(np.abs(a[ok, k, 0] - a[ok, k, 0].mean()) <= 1.96 * a[ok, k, 1])
        cx = np.mean(np.abs(a[ok, k, 2] - a[ok, k, 2].mean()) <= 1.96 * a[ok, k, 3])
        print(f"| {k + 1} | {f0:.3f} | {ok.sum()}/{n_records} | {sf:.2e} | {ssf:.2e} | {ssf / sf:.2f} | {cf:.2f} | "
              f"{sx:.2e} | {ssx:.2e} | {ssx / sx:.2f} | {cx:.2f} |")


def _run(n_records, duration, bootstrap_draws=0):
    out = {}
    variants = {"": None} if not bootstrap_draws else {"": None, ", cluster mean": ClusteringSettings(cluster_std="mean")}
    for with_input in (True, False):
        rows = {v: [] for v in variants}
        truth = None
        for seed in range(n_records):
            sim = modaluq.simulate(int(duration * 50), seed=1000 + seed)
            truth = np.sort(sim.frequency_hz)
            res = modaluq.identify(sim.y, sim.u if with_input else None, fs=sim.fs,
                                   frequency_range=(1, 20), bootstrap_draws=bootstrap_draws)
            for v, clustering in variants.items():
                rows[v].append(_row(res.select_modes(settings=clustering), truth))
        name = "input/output" if with_input else "output-only"
        for v in variants:
            a = np.array(rows[v])  # (N, modes, 4)
            out[name + v] = a
            _table(a, truth, f"{name}, {n_records} records of {duration:g} s, band 1-20 Hz, automatic settings"
                   + (f", {bootstrap_draws} bootstrap draws" if bootstrap_draws else "") + v, n_records)
    return out


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100, float(sys.argv[2]) if len(sys.argv) > 2 else 400.0,
         int(sys.argv[3]) if len(sys.argv) > 3 else 0)
