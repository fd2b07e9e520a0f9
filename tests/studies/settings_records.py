"""The table "On the shared records" of docs/settings.md: automatic settings on three shared records.
Usage: python tests/studies/settings_records.py DATA_DIR"""
import numpy as np, modaluq, warnings
warnings.simplefilter("ignore")
import sys
D=sys.argv[1].rstrip('/')+'/' if len(sys.argv) > 1 else '../shared/data/'
def line(name, r, ref=None):
    sel=r.stabilization_diagram().select_modes()
    s=r.settings
    print(f"| {name} | {s['preprocessing']['decimation']} → {r.fs:.4g} Hz | {s['block_rows']} ({s['block_rows']/r.fs:.3g} s) | 2..{r.orders[-1]} | {s['n_blocks']} | {r.significant_singular_values} | {' '.join(f'{f:.4g}' for f in sel.frequency_hz)} | {' '.join(f'{100*x:.2g}' for x in sel.damping_ratio)} |" + ("" if ref is None else f" {' '.join(f'{f:.4g}' for f in ref)} |"))
d=np.load(D+'koma_shearframe_sim.npz'); line("koma frame, band 0.1–1.5 Hz", modaluq.identify(d['y'], fs=float(d['fs']), frequency_range=(0.1, 1.5)), d['fn_ref_discrete_hz'])
d=np.load(D+'ssicov_lysefjord_bridge_sim.npz'); line("bridge, band 0.15–1.5 Hz", modaluq.identify(d['y'], fs=float(d['fs']), frequency_range=(0.15, 1.5)), d['fn_ref_discrete_hz'])
s=np.load(D+'cessipy_smartphone_slab.npz'); a,b=s['recommended_slice']
line("slab, band 10–30 Hz", modaluq.identify(s['y'][a:b], fs=float(s['fs']), frequency_range=(10, 30)))
line("slab, band 10–30 Hz, block_rows 80", modaluq.identify(s['y'][a:b], fs=float(s['fs']), frequency_range=(10, 30), block_rows=80))
