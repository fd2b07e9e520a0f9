"""σ_f of the same physical mode read at every order of a diagram, plain and frozen, on two shared
records (docs/validation.md, "On the shared records").  Usage: python issue11_records.py DATA_DIR"""
import sys
import warnings
from pathlib import Path

import numpy as np

import modaluq

warnings.simplefilter("ignore", modaluq.ModalUQWarning)
data = Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data")


def table(title, y, fs, targets, block_rows, orders, n_blocks, unit=1e3, unit_name="mHz"):
    print(f"\n{title}\n")
    print("| mode | propagation | k* | " + " | ".join(f"n = {n}" for n in orders) + " | max/min |")
    print("|---|---|---|" + "---|" * (len(orders) + 1))
    runs = {fr: modaluq.identify(y, fs=fs, block_rows=block_rows, orders=orders, n_blocks=n_blocks,
                                 freeze_noise=fr) for fr in (False, True)}
    for f0 in targets:
        for fr, r in runs.items():
            cells, vals = [], []
            for m in r.modes:
                i = int(np.argmin(np.abs(m.frequency_hz - f0))) if m.n_modes else -1
                if i < 0 or abs(m.frequency_hz[i] - f0) > 0.02 * f0:
                    cells.append("–")
                    continue
                vals.append(m.frequency_std[i] * unit)
                cells.append(f"{vals[-1]:.2f}" + (" (flag)" if m.noise_coupled[i] else ""))
            spread = f"{max(vals) / min(vals):.1f}" if vals else "–"
            print(f"| {f0:.3f} Hz | {'frozen' if fr else 'plain'} | {r.significant_singular_values} | "
                  + " | ".join(cells) + f" | {spread} |")


d = np.load(data / "koma_shearframe_sim.npz")
table("koma shear frame (simulated, 5 modes, true order 10): σ_f in mHz, block_rows 40, 40 blocks",
      d["y"], float(d["fs"]), d["fn_ref_discrete_hz"], 40, list(range(10, 81, 10)), 40)
s = np.load(data / "cessipy_smartphone_slab.npz")
a, b = s["recommended_slice"]
table("smartphone slab (measured, 3 channels, the 17.8 Hz mode): σ_f in mHz, block_rows 60, 30 blocks",
      s["y"][a:b], float(s["fs"]), [17.8], 60, list(range(8, 61, 8)), 30)
