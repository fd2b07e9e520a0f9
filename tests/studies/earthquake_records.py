"""Meloland and Painter Street (earthquake records, ground motion as input): which of the data
README's "sanity check" frequencies modaluq finds, and in how many of six independent-ish views
of the record: output-only and with the ground motion as input, each with all deck channels,
the vertical deck channels only, and the transverse (and longitudinal) deck channels only.

A frequency found within 2 % in most views is consistent across the excitation model and the
sensor set, which a spurious pole is not; docs/settings.md ("Earthquake records") uses this.
Usage: python tests/studies/earthquake_records.py [DATA_DIR]
"""
import sys
import warnings

import numpy as np

import modaluq

warnings.simplefilter("ignore")
D = (sys.argv[1].rstrip("/") if len(sys.argv) > 1 else "../shared/data") + "/"
RECORDS = {
    "Meloland": ("cesmd_meloland_overpass_2016.npz", (1.0, 20.0),
                 [1.47, 2.98, 3.2, 3.97, 4.1, 4.3, 4.5, 6.0, 15.8, 17.16, 17.3]),
    "Painter Street": ("cesmd_painter_st_overpass_2016.npz", (1.0, 15.0),
                       [3.30, 3.9, 4.3, 4.7, 5.8, 7.1, 10.5, 10.8, 14.9]),
}
for name, (file, band, sanity) in RECORDS.items():
    d = np.load(D + file)
    names = [str(n) for n in d["channel_names"]]
    views = {"all": list(range(len(names))),
             "vertical": [i for i, n in enumerate(names) if "|Up|" in n],
             "horizontal": [i for i, n in enumerate(names) if "|Up|" not in n]}
    found = {}
    for view, cols in views.items():
        for io in (False, True):
            r = modaluq.identify(d["y"][:, cols], d["u"] if io else None, fs=float(d["fs"]), frequency_range=band)
            sel = r.select_modes()
            found[f"{view}, {'ground input' if io else 'output-only'}"] = sel
    print(f"\n## {name} (band {band[0]:g}-{band[1]:g} Hz)\n")
    print("| README | " + " | ".join(found) + " | views |")
    print("|---" * (len(found) + 2) + "|")
    for f0 in sanity:
        cells, n = [], 0
        for sel in found.values():
            k = np.flatnonzero(np.abs(sel.frequency_hz / f0 - 1) < 0.02)
            if k.size:
                k = k[np.argmin(np.abs(sel.frequency_hz[k] - f0))]
                cells.append(f"{sel.frequency_hz[k]:.3f} ({100 * sel.damping_ratio[k]:.1f} %)")
                n += 1
            else:
                cells.append("–")
        print(f"| {f0:g} | " + " | ".join(cells) + f" | {n}/{len(found)} |")
    others = sorted({round(float(f), 2) for sel in found.values() for f in sel.frequency_hz
                     if not np.any(np.abs(np.array(sanity) / f - 1) < 0.02)})
    print(f"\nother selected frequencies (Hz): {others}")
