"""Monte Carlo check of the σ the engineer reads: the selected modes of the engineer's call
(`identify(y, u, fs, frequency_range=(1, 20)).select_modes()`, automatic settings) over N
independent records of the paper's chain. For each true mode: the std of the selected frequency
and damping across records against the median (over records) of the reported σ (itself the
median over the mode's cluster). Usage: python studies/selected_sigma_mc.py [N] [seconds]
"""
import sys
import warnings

import numpy as np

import modaluq

warnings.simplefilter("ignore")
N = int(sys.argv[1]) if len(sys.argv) > 1 else 100
duration = float(sys.argv[2]) if len(sys.argv) > 2 else 400.0
for with_input in (True, False):
    rows = []
    truth = None
    for seed in range(N):
        sim = modaluq.simulate(int(duration * 50), seed=1000 + seed)
        truth = np.sort(sim.frequency_hz)
        sel = modaluq.identify(sim.y, sim.u if with_input else None, fs=sim.fs,
                               frequency_range=(1, 20)).select_modes()
        row = np.full((len(truth), 4), np.nan)
        for k, f0 in enumerate(truth):
            j = np.flatnonzero(np.abs(sel.frequency_hz / f0 - 1) < 0.02)
            if j.size:
                j = j[np.argmin(np.abs(sel.frequency_hz[j] - f0))]
                row[k] = sel.frequency_hz[j], sel.frequency_std[j], sel.damping_ratio[j], sel.damping_std[j]
        rows.append(row)
    a = np.array(rows)  # (N, modes, 4)
    print(f"\n{'input/output' if with_input else 'output-only'}, {N} records of {duration:g} s, band 1-20 Hz, "
          f"automatic settings")
    print("| mode | f (Hz) | found | std f (MC) | median σ_f | ratio | std ξ (MC) | median σ_ξ | ratio |")
    print("|---|---|---|---|---|---|---|---|---|")
    for k, f0 in enumerate(truth):
        ok = np.isfinite(a[:, k, 0])
        sf, ssf = np.std(a[ok, k, 0], ddof=1), np.median(a[ok, k, 1])
        sx, ssx = np.std(a[ok, k, 2], ddof=1), np.median(a[ok, k, 3])
        print(f"| {k + 1} | {f0:.3f} | {ok.sum()}/{N} | {sf:.2e} | {ssf:.2e} | {ssf / sf:.2f} | {sx:.2e} | "
              f"{ssx:.2e} | {ssx / sx:.2f} |")
