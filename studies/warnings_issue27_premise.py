"""Issue 27, item 4: does a selected mode whose blocks are shorter than its decay time get a low σ?

The paper's chain with mode 1 at ξ = 0.1 % (decay time 82 s), 400 s at 50 Hz, block_rows 40,
cut into N blocks: the std of mode 1's estimates over 20 seeds against their median σ
(docs/settings.md, "Warnings that mean something").

Usage: nice -n 19 python studies/warnings_issue27_premise.py N_BLOCKS   (200 and 20; about 1 CPU min each)
"""
import sys
import warnings

import numpy as np

import modaluq
from modaluq import Analysis, Settings


def main(n_blocks: int, seeds=range(20)):
    rows = []
    for seed in seeds:
        sim = modaluq.simulate(20_000, seed=seed, damping_ratio=[0.001] + [0.02] * 5)
        a = Analysis.from_arrays(sim.y, fs=sim.fs, settings=Settings(frequency_range=(1, 20), n_blocks=n_blocks,
                                                                     block_rows=40))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a.run(check_harmonics=False, issue_warnings=False)
        sel, f0 = a.selected, sim.frequency_hz[0]
        k = int(np.argmin(abs(sel.frequency_hz - f0))) if sel.n_modes else None
        if k is None or abs(sel.frequency_hz[k] - f0) / f0 > 0.03:
            continue
        rows.append((sel.frequency_hz[k], sel.frequency_std[k], sel.damping_ratio[k], sel.damping_std[k],
                     len(a.warnings) > 0))
    r = np.array(rows, float)
    print(f"{n_blocks} blocks: mode 1 found in {len(r)} of {len(seeds)} runs, warned in {int(r[:, 4].sum())}; "
          f"std of the estimates / median sigma: f {np.std(r[:, 0], ddof=1) / np.median(r[:, 1]):.2f}, "
          f"xi {np.std(r[:, 2], ddof=1) / np.median(r[:, 3]):.2f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
