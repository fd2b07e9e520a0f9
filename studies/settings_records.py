"""The table "On the shared records" of docs/settings.md: each record identified the way an
engineer would, with only fs, the inputs where there are any, and a frequency band.

Usage: python studies/settings_records.py [DATA_DIR]   (default ../shared/data; about 1 min)
"""
import sys
import warnings
from pathlib import Path

import numpy as np

import modaluq
from modaluq.io import load

#: The rows of the table, in order (``main(records=...)`` picks some).
RECORDS = ("koma", "bridge", "slab", "Meloland", "Painter Street", "wind turbine", "chain 50 Hz", "chain 1000 Hz")


def line(name, r, ref=None):
    sel = r.stabilization_diagram().select_modes()
    s = r.settings
    dec = s.get("preprocessing", {}).get("decimation", 1)
    cells = [name, f"{dec} → {r.fs:.4g} Hz", f"{s['block_rows']} ({s['block_rows'] / r.fs:.3g} s)",
             f"2..{r.orders[-1]}", str(s["n_blocks"]), str(r.significant_singular_values),
             " ".join(f"{f:.4g}" for f in sel.frequency_hz), " ".join(f"{100 * x:.2g}" for x in sel.damping_ratio),
             "" if ref is None else " ".join(f"{f:.4g}" for f in ref)]
    print("| " + " | ".join(cells) + " |")


def rows(data, record):
    """Print the table's rows of one record."""
    if record == "koma":
        d = np.load(data / "koma_shearframe_sim.npz")
        line("koma frame, band 0.1–1.5 Hz", modaluq.identify(d["y"], fs=float(d["fs"]), frequency_range=(0.1, 1.5)),
             d["fn_ref_discrete_hz"])
    elif record == "bridge":
        d = np.load(data / "ssicov_lysefjord_bridge_sim.npz")
        line("bridge, band 0.15–1.5 Hz", modaluq.identify(d["y"], fs=float(d["fs"]), frequency_range=(0.15, 1.5)),
             d["fn_ref_discrete_hz"])
    elif record == "slab":
        s = np.load(data / "cessipy_smartphone_slab.npz")
        a, b = s["recommended_slice"][:2]
        line("slab, band 10–30 Hz", modaluq.identify(s["y"][a:b], fs=float(s["fs"]), frequency_range=(10, 30)))
    elif record in ("Meloland", "Painter Street"):
        file, band = {"Meloland": ("cesmd_meloland_overpass_2016.npz", (1, 20)),
                      "Painter Street": ("cesmd_painter_st_overpass_2016.npz", (1, 15))}[record]
        e = np.load(data / file)
        line(f"{record}, output-only, band {band[0]}–{band[1]} Hz",
             modaluq.identify(e["y"], fs=float(e["fs"]), frequency_range=band))
        line(f"{record}, ground motion as input",
             modaluq.identify(e["y"], e["u"], fs=float(e["fs"]), frequency_range=band))
    elif record == "wind turbine":
        rec = load(data / "owi_offshore_wind_turbine_tower_2020.tdms")
        line("wind turbine (TDMS), band 0.2–5 Hz", modaluq.identify(rec.y, fs=float(rec.fs), frequency_range=(0.2, 5)))
    elif record in ("chain 50 Hz", "chain 1000 Hz"):
        fs, n = {"chain 50 Hz": (50.0, 100_000), "chain 1000 Hz": (1000.0, 400_000)}[record]
        sim = modaluq.simulate(n, seed=1, fs=fs)
        truth = np.sort(sim.frequency_hz)
        line(f"paper chain at {fs:g} Hz, input/output, band 1–20 Hz",
             modaluq.identify(sim.y, sim.u, fs=fs, frequency_range=(1, 20)), truth)
        line(f"paper chain at {fs:g} Hz, output-only", modaluq.identify(sim.y, fs=fs, frequency_range=(1, 20)), truth)
    else:
        raise ValueError(f"record {record!r}: one of {RECORDS}")


def main(data_dir="../shared/data", records=RECORDS):
    """Print the table for ``records`` (names of :data:`RECORDS`) read from ``data_dir``."""
    print("| record | decimation | block_rows (lags) | orders | n_blocks | k* | selected f (Hz) | ξ (%) | "
          "reference f (Hz) |")
    print("|---|---|---|---|---|---|---|---|---|")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for record in records:
            rows(Path(data_dir), record)


if __name__ == "__main__":
    main(*sys.argv[1:2])
