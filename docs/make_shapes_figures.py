"""Figures of docs/shapes.md: modes of three shared records on their geometries (examples/geometry/),
static and animated, and a screenshot of the HTML report in headless Chromium (when installed).

    python docs/make_shapes_figures.py [DATA_DIR]     # default /work/shared/data
"""

import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import modaluq
from modaluq.htmlreport import write_html_report
from modaluq.spectrum import output_spectrum_singular_values

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"
DATA = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("/work/shared/data")


def analysis(name, **settings):
    a = modaluq.Analysis.from_file(DATA / name, settings=modaluq.Settings(**settings))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ModalUQWarning)
        a.run()
    return a


frame = analysis("koma_shearframe_sim.npz", keep_shape_factor=True)  # the AutoMAC's exact σ
geo = modaluq.Geometry.from_toml(ROOT / "examples/geometry/koma_shearframe.toml")
frame.selected.plot_shape(2, geometry=geo, magnify_envelope=10).savefig(IMG / "shapes_frame_mode2.png", dpi=100)

frame.selected.plot_mac().savefig(IMG / "shapes_frame_automac.png", dpi=100)

deck = analysis("ssicov_lysefjord_bridge_sim.npz")
dgeo = modaluq.Geometry.from_toml(ROOT / "examples/geometry/lysefjord_deck.toml")
deck.selected.plot_shape(2, geometry=dgeo, magnify_envelope=10, elev=20, azim=-110).savefig(
    IMG / "shapes_deck_mode2.png", dpi=100)

tower = analysis("owi_offshore_wind_turbine_tower_2020.tdms")
tgeo = modaluq.Geometry.from_toml(ROOT / "examples/geometry/owi_tower.toml")
tower.selected.plot_shape(1, geometry=tgeo, elev=15, azim=-35).savefig(IMG / "shapes_tower_mode1.png", dpi=100)
tower.selected.animate(1, geometry=tgeo, path=IMG / "shapes_tower_mode1.gif", frames=16, dpi=60, elev=15, azim=-35)

chromium = shutil.which("chromium")
if chromium:
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "tower.html"
        pre = tower.preprocessed
        write_html_report(report, tower.diagram, tower.selected, geometry=tgeo,
                          spectrum=output_spectrum_singular_values(pre.y, pre.fs),
                          title="modaluq identify owi_offshore_wind_turbine_tower_2020.tdms",
                          run_description=tower.describe_run(), warnings=tower.warnings)
        shot = Path(tmp) / "shot.png"
        import numpy as np
        from PIL import Image

        for _ in range(4):  # a loaded machine may take the screenshot before the first mode is drawn
            subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                            "--hide-scrollbars", f"--screenshot={shot}", "--window-size=1200,2300",
                            "--virtual-time-budget=30000", report.as_uri()], capture_output=True, timeout=180)
            img = Image.open(shot).convert("RGB")
            if np.asarray(img)[-300:].std() > 10:  # the 3-D mode at the bottom of the page
                break
        img.resize((900, 1725)).save(IMG / "shapes_report.png", optimize=True)
print("wrote", *sorted(p.name for p in IMG.glob("shapes_*")))
