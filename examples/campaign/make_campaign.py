#!/usr/bin/env python
"""Write the simulated deck campaign of docs/multisetup.md as CSV files next to campaign.toml.

    python examples/campaign/make_campaign.py              # setup1.csv ... setup6.csv here (~5 MB)
    modaluq identify --setups examples/campaign/campaign.toml --out modes.json --report campaign.html

The campaign is :func:`modaluq.simulate.campaign.simulate_campaign` (seed 1): a 65 m deck, 24
vertical DOFs, references L3 and R8, the other 22 DOFs roved in six setups of 8-12 minutes at
25 Hz. Each file holds what a data logger writes: a time column and the sensors by their logger
names (``ref_a``, ``ref_b``, ``acc1`` ...); campaign.toml names them by DOF. ``--out DIR`` writes
the files and a copy of campaign.toml into DIR instead; ``--duration-scale`` shortens the setups
(the tests use it).
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def write(out: Path, *, duration_scale: float = 1.0, seed: int = 1) -> Path:
    """Write setup1.csv ... and campaign.toml (a copy, its geometry path made absolute when
    ``out`` is not this folder) into ``out``; return the campaign file."""
    from modaluq.simulate.campaign import DEFAULT_DURATIONS, simulate_campaign

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    camp = simulate_campaign(seed, durations=tuple(d * duration_scale for d in DEFAULT_DURATIONS))
    for j, s in enumerate(camp.setups):
        n, m = s.y.shape
        header = ["time [s]", "ref_a", "ref_b"] + [f"acc{k}" for k in range(1, m - 1)]
        data = np.column_stack([np.arange(n) / camp.fs, s.y])
        np.savetxt(out / f"setup{j + 1}.csv", data, delimiter=",", header=",".join(header), comments="",
                   fmt=["%.2f"] + ["%.6g"] * m)
    toml = (HERE / "campaign.toml").read_text(encoding="utf-8")
    if out.resolve() != HERE:
        geometry = (HERE / "../geometry/deck_campaign.toml").resolve().as_posix()
        toml = re.sub(r'^geometry = "[^"]*"', f'geometry = "{geometry}"', toml, flags=re.M)
        (out / "campaign.toml").write_text(toml, encoding="utf-8")
    return out / "campaign.toml"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(HERE), help="folder of the files (default: this one)")
    ap.add_argument("--duration-scale", type=float, default=1.0, help="setup lengths times this (default 1)")
    args = ap.parse_args(argv)
    path = write(Path(args.out), duration_scale=args.duration_scale)
    print(f"wrote {path} and its {len(list(path.parent.glob('setup*.csv')))} setups in {os.path.dirname(path)}")  # noqa: T201
    return 0


if __name__ == "__main__":
    sys.exit(main())
