"""Issue 27, item 4: does a selected mode whose blocks are shorter than its decay time get a low σ?

Each case is run with many short blocks and with 20 long ones; the std of the mode's estimates
over the seeds is compared with their median σ (ratio > 1: σ under-estimated). The table of
docs/settings.md ("Warnings that mean something") comes from

    nice -n 19 python studies/warnings_issue27_premise.py CASE N_BLOCKS [N_SEEDS]

CASE: ``chain`` (the paper's chain, mode 1 at ξ 0.1 %, block_rows 40), ``chain12`` (the same at
block_rows 12, which allows 800 blocks), ``mass-XI`` (one mass, 7.1 Hz, ξ = XI as a fraction, 1 %
sensor noise, block_rows 20, output-only), e.g. ``mass-0.0005``. About 1 CPU min per 20 seeds.
"""
import sys
import warnings

import numpy as np

import modaluq
from modaluq import Analysis, Settings


def case(name, seed):
    """(simulation, settings) of one case."""
    if name in ("chain", "chain12"):
        sim = modaluq.simulate(20_000, seed=seed, damping_ratio=[0.001] + [0.02] * 5)
        if name == "chain":  # the automatic orders
            return sim, dict(frequency_range=(1, 20), block_rows=40)
        return sim, dict(frequency_range=(1, 20), block_rows=12, orders=tuple(range(2, 34, 2)))
    xi = float(name.split("-", 1)[1])
    sim = modaluq.simulate(20_000, seed=seed, n_dof=1, damping_ratio=xi, noise_std=0.01, input_dofs=())
    return sim, dict(block_rows=20, orders=tuple(range(2, 11, 2)))


def main(name="chain", n_blocks=200, seeds=range(20)):
    rows = []
    for seed in seeds:
        sim, settings = case(name, seed)
        a = Analysis.from_arrays(sim.y, fs=sim.fs, settings=Settings(n_blocks=n_blocks, **settings))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a.run(check_harmonics=False, issue_warnings=False)
        sel, f0 = a.selected, sim.frequency_hz[0]
        k = int(np.argmin(abs(sel.frequency_hz - f0))) if sel.n_modes else None
        if k is None or abs(sel.frequency_hz[k] - f0) / f0 > 0.03:
            continue
        rows.append((sel.frequency_hz[k], sel.frequency_std[k], sel.damping_ratio[k], sel.damping_std[k]))
    r = np.array(rows, float).reshape(-1, 4)
    tau = 1.0 / (2 * np.pi * sim.frequency_hz[0] * sim.damping_ratio[0])
    block_s = a.result.block_length / a.result.fs  # Hankel columns per block
    ratio = (f"f {np.std(r[:, 0], ddof=1) / np.median(r[:, 1]):.2f}, xi {np.std(r[:, 2], ddof=1) / np.median(r[:, 3]):.2f}"
             if len(r) > 2 else "too few found")
    print(f"{name}, {n_blocks} blocks of {block_s:.3g} s (decay time {tau:.3g} s, blocks of 1/{tau / block_s:.0f} of it): "
          f"mode 1 found in {len(r)} of {len(seeds)} runs; std of the estimates / median sigma: {ratio}")
    return r


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "chain", int(args[1]) if len(args) > 1 else 200,
         range(int(args[2]) if len(args) > 2 else 20))
