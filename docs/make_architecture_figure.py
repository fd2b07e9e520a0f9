"""Draw docs/img/architecture.png: the Python package's layers and the C++ core's stages.

    python docs/make_architecture_figure.py

The layers are those of tests/python/test_architecture.py (LAYERS), which fails when the code
leaves them; this script only draws them.
"""

from pathlib import Path

from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

# (label, modules) from the top layer down: each imports only the layers below it
PYTHON = [
    ("command line", "cli/  (identify · monitor · demo · validate)"),
    ("monitoring wing", "monitoring/  (run · records · worker · executors · parts · tracking · change · store · plot)"),
    ("analysis", "analysis · horizons · validation/"),
    ("identification", "identification · streaming"),
    ("result types", "results"),
    ("stabilization", "stabilization"),
    ("selection", "selection"),
    ("plot and export", "plot · export"),
    ("settings, signal", "settings · preprocess · auto_settings · spectrum · harmonics · provenance"),
    ("checks, JSON", "checks · jsonvalues"),
    ("C++ core", "_core (pybind11: translation only) · _blas · version"),
]
SIDE = [("side leaves", "io/  (file loaders)\nsimulate\nmonitoring/simulator"), ]
CPP = ["covariance.hpp\nlag sums, blocks", "subspace.hpp\nH (OO or IO)", "realization.hpp\nSVD → Γ, A, C",
       "modal.hpp\nf, ξ, shapes", "uncertainty.hpp\nΣ → σ per order", "stabilization.hpp\njudge poles",
       "selection.hpp\ncluster → modes"]


def box(ax, x, y, w, h, text, colour, size=8.5, weight="normal"):
    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0,rounding_size=0.01",
                                fc=colour, ec="0.35", lw=0.8))
    ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=size, weight=weight)


def main(path=Path(__file__).resolve().parent / "img" / "architecture.png"):
    fig = Figure(figsize=(11, 7.2), layout="constrained")
    ax = fig.add_subplot()
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.axis("off")
    ax.set_title("modaluq: Python layers (imports go down only) over the header-only C++ core", fontsize=11)
    n = len(PYTHON)
    top, bottom, h = 0.93, 0.30, 0.04
    step = (top - bottom) / (n - 1)
    for i, (label, mods) in enumerate(PYTHON):
        y = top - i * step - h / 2
        colour = "#dbe8f6" if i < n - 1 else "#f6e3c9"
        ax.text(0.015, y + h / 2, label, ha="left", va="center", fontsize=8.5, color="0.3")
        box(ax, 0.17, y, 0.56, h, mods, colour)
        if i < n - 1:
            ax.add_patch(FancyArrowPatch((0.45, y - 0.002), (0.45, y - step + h + 0.002), arrowstyle="-|>",
                                         mutation_scale=10, color="0.45", lw=0.8))
    for label, mods in SIDE:
        box(ax, 0.78, 0.50, 0.19, 0.10, mods, "#e4f1dc")
        ax.text(0.875, 0.615, f"{label}: only checks below them", ha="center", fontsize=8, color="0.3")
    ax.text(0.875, 0.45, "used by analysis (io), validation,\ndemo (simulate), monitoring (its simulator)",
            ha="center", va="top", fontsize=7.5, color="0.35")
    ax.text(0.875, 0.86, "no upward edge: a result type sits\nabove what its convenience methods reach:\n"
            "Result.plot() → Diagram.select_modes()\n→ SelectedModes.to_dict();\nfunctions take types by their fields",
            ha="center", va="center", fontsize=7.5, color="0.35", bbox=dict(fc="white", ec="0.7", lw=0.6))
    # the C++ pipeline, wired once in identify.hpp
    ax.text(0.5, 0.19, "C++ core (cpp/include/modaluq, header-only, sans-IO): one straight line, wired in identify.hpp; "
            "internals in detail/", ha="center", fontsize=8.5)
    w, gap = 0.12, 0.02
    x0 = (1 - (len(CPP) * w + (len(CPP) - 1) * gap)) / 2
    for k, label in enumerate(CPP):
        x = x0 + k * (w + gap)
        box(ax, x, 0.04, w, 0.11, label, "#f6e3c9", size=7.5)
        if k:
            ax.add_patch(FancyArrowPatch((x - gap + 0.001, 0.095), (x - 0.001, 0.095), arrowstyle="-|>",
                                         mutation_scale=8, color="0.45", lw=0.8))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
