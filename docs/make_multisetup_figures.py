"""Figures and numbers of docs/multisetup.md: the simulated deck campaign (six setups, references L3
and R8) merged by modaluq.identify_setups, its stabilization diagram, two global shapes with their
±2σ on the deck (examples/geometry/deck_campaign.toml), and the table against the true modes.

    python docs/make_multisetup_figures.py
"""

import warnings
from pathlib import Path

import numpy as np

import modaluq
from modaluq.simulate.campaign import simulate_campaign

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"

camp = simulate_campaign(1)
setups = camp.frames()
with warnings.catch_warnings():
    warnings.simplefilter("ignore", modaluq.ModalUQWarning)
    result = modaluq.identify_setups(setups, fs=camp.fs, references=["L3", "R8"], block_rows=20,
                                     orders=range(2, 41, 2))
    selected = result.select_modes()
print(selected)
truth = camp.mode_shape[[camp.dofs.index(n) for n in result.output_names]]
print("| mode | true f (Hz) | f ± σ (Hz) | true ξ (%) | ξ ± σ (%) | MAC with the true shape (24 DOFs) |")
print("|---|---|---|---|---|---|")
for k, f0 in enumerate(camp.frequency_hz):
    i = int(np.argmin(np.abs(selected.frequency_hz - f0)))
    phi = selected.mode_shape[:, i]
    mac = abs(np.vdot(truth[:, k], phi)) ** 2 / (np.vdot(phi, phi).real * truth[:, k] @ truth[:, k])
    print(f"| {k + 1} | {f0:.2f} | {selected.frequency_hz[i]:.4f} ± {selected.frequency_std[i]:.4f} | "
          f"{100 * camp.damping_ratio[k]:.1f} | {100 * selected.damping_ratio[i]:.2f} ± "
          f"{100 * selected.damping_std[i]:.2f} | {mac:.4f} |")

ax = result.plot(criteria=None)
ax.figure.savefig(IMG / "multisetup_diagram.png", dpi=90)
geo = modaluq.Geometry.from_toml(ROOT / "examples/geometry/deck_campaign.toml")
for mode in (2, 5):
    fig = selected.plot_shape(mode, geometry=geo, magnify_envelope=5, elev=25, azim=-60)
    fig.savefig(IMG / f"multisetup_mode{mode}.png", dpi=90)
