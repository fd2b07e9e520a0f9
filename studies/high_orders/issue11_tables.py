"""Markdown tables of docs/validation.md "Above the true order" from validate_runs.sh's output.

Usage: python studies/high_orders/issue11_tables.py OUT_DIR > tables.md
"""
import sys
from pathlib import Path

import numpy as np

from modaluq.validation import METHOD_LABELS, METHODS, MonteCarloResult

CASES = [
    ("chain", "chain, paper case (unknown forces 10 %, ξ = 2 %)"),
    ("chain-known-only", "chain, known input only (`--unknown-input-std 0`)"),
    ("chain-xi0.2", "chain, ξ = 0.2 %"),
    ("frame", "4-storey frame, two inputs"),
    ("frame-known-only", "4-storey frame, two inputs, known inputs only"),
]


def cells(a, digits=2):
    return " ".join("–" if not np.isfinite(x) else f"{x:.{digits}f}" for x in a)


def table(out: Path, name: str, title: str) -> list:
    runs = sorted(out.glob(f"{name}/results_n*.npz"), key=lambda p: int(p.stem.split("_n")[1]))
    if not runs:
        runs = sorted(out.glob(f"{name}/results.npz"))
    lines = [f"**{title}**", "",
             "| order | method | flagged % | f: mean, median σ/σ_MC | f: RMS(z) | ξ: mean, median σ/σ_MC | ξ: RMS(z) | shape: median σ/σ_MC |",
             "|---|---|---|---|---|---|---|---|"]
    for path in runs:
        r = MonteCarloResult.load(path)
        for m, method in enumerate(METHODS):
            lines.append(
                f"| {r.settings['order']} | {METHOD_LABELS[method]} | {cells(100 * r.noise_coupled_share[m], 1)} | "
                f"{cells(r.frequency_std_ratio_unflagged[m])}<br>{cells(r.frequency_std_ratio_median_unflagged[m])} | "
                f"{cells(r.frequency_rms_z_unflagged[m])} | "
                f"{cells(r.damping_std_ratio_unflagged[m])}<br>{cells(r.damping_std_ratio_median_unflagged[m])} | "
                f"{cells(r.damping_rms_z_unflagged[m])} | {cells(r.mode_shape_std_ratio_median[m])} |")
    return lines + [""]


def blocks_table(out: Path) -> list:
    lines = ["| case | order | method | n_blocks | f: mean σ/σ_MC | ξ: mean σ/σ_MC |", "|---|---|---|---|---|---|"]
    for case, label in (("chain", "paper case"), ("chain-known-only", "known input only")):
        for order in (12, 24):
            for m, method in enumerate(METHODS):
                for nb in (25, 50, 100, 200):
                    d = out / (case if nb == 50 else f"{case}-nb{nb}")
                    p = d / f"results_n{order}.npz"
                    if not p.exists():
                        continue
                    r = MonteCarloResult.load(p)
                    lines.append(f"| {label} | {order} | {METHOD_LABELS[method]} | {nb} | "
                                 f"{cells(r.frequency_std_ratio_unflagged[m])} | {cells(r.damping_std_ratio_unflagged[m])} |")
    return lines


if __name__ == "__main__":
    out = Path(sys.argv[1])
    text = []
    for name, title in CASES:
        text += table(out, name, title)
    text += blocks_table(out)
    print("\n".join(text))
