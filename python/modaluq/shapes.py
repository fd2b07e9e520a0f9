"""Mode shapes drawn on the structure: a static 3-D figure with the ±2σ envelope, and an animation.

:func:`plot_shape` draws one mode on a :class:`~modaluq.geometry.Geometry`: the undeformed
structure faint, the deformed one at the phase of the largest motion, and at every moving node
the axes of its ±2σ ellipsoid (the node's 3×3 displacement covariance at that phase, exact when
the shape's covariance is known: docs/shapes.md). A complex mode is shown as it is: each node is
coloured by the phase of its motion (0° or 180°: in phase with the reference, as a real mode;
±90°: a quarter of a cycle late or early), and the title gives the largest phase lag. The
animation (:func:`animate_shape`) shows the whole cycle, ``Re(u e^{iα})``, with the envelope at
each phase.

Figures are :class:`~modaluq.plot.StandaloneFigure` (no pyplot state), as in :mod:`modaluq.plot`.

>>> fig = selected.plot_shape(1, geometry=geo)                    # doctest: +SKIP
>>> fig.savefig("mode1.png", dpi=120)                             # doctest: +SKIP
>>> selected.animate(1, geometry=geo, path="mode1.gif")          # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .atomic import write_atomically
from .checks import check_integer, check_real
from .geometry import mode_displacements
from .plot import StandaloneFigure

__all__ = ["animate_shape", "node_phases", "peak_phase", "plot_shape"]

#: the largest node displacement drawn, as a fraction of the structure's size (``scale=None``)
DISPLAY_FRACTION = 0.15
#: the envelope drawn: ± this many standard deviations
ENVELOPE_SIGMA = 2.0
#: principal σ smaller than this fraction of the largest one are not drawn (a measured direction
#: only: its ellipsoid is a segment)
ENVELOPE_MIN_AXIS = 1e-3
#: colour map of a node's phase (folded to -90°..90°: 0 = in phase or in antiphase)
PHASE_CMAP = "coolwarm"


def peak_phase(value: np.ndarray) -> float:
    """The phase α in [0, π) at which ``‖Re(u e^{iα})‖`` is largest (a real mode: 0)."""
    # ‖Re(u e^{iα})‖² = a cos²α + b sin²α - 2 c sinα cosα with a=‖Re u‖², b=‖Im u‖², c=Re u·Im u
    re, im = value.real.ravel(), value.imag.ravel()
    a, b, c = re @ re, im @ im, re @ im
    alpha = 0.5 * math.atan2(-2.0 * c, a - b)
    return alpha % math.pi


def node_phases(value: np.ndarray) -> np.ndarray:
    """Per node, the phase of its motion along its main direction, folded to (-90°, 90°] (deg).

    0: the node moves in phase (or in antiphase) with the reference, as in a real mode; ±90°: a
    quarter of a cycle apart. NaN for a node that does not move."""
    out = np.full(value.shape[0], np.nan)
    for n, u in enumerate(value):
        m = np.column_stack([u.real, u.imag])
        if not np.any(m):
            continue
        v = np.linalg.svd(m)[0][:, 0]  # main direction of the node's elliptic path
        ph = math.degrees(np.angle(v @ u))
        out[n] = (ph + 90.0) % 180.0 - 90.0
    return out


def _scale(geometry, value, scale):
    if scale is not None:
        return check_real("scale", scale, low=0, low_open=True)
    peak = float(np.max(np.linalg.norm(np.abs(value), axis=1), initial=0.0))
    return DISPLAY_FRACTION * geometry.size / peak if peak > 0 else 1.0


def _segments(xyz, index, pairs):
    return [[xyz[index[int(a)]], xyz[index[int(b)]]] for a, b in pairs]


def _envelope_segments(xyz, cov, moving, factor):
    """Per moving node, the principal axes of its ±``factor``σ ellipsoid as segments through it."""
    segs = []
    if cov is None:
        return segs
    for n in np.nonzero(moving)[0]:
        w, v = np.linalg.eigh(0.5 * (cov[n] + cov[n].T))
        w = np.clip(w, 0.0, None)
        top = float(np.sqrt(w.max(initial=0.0)))
        for j in range(3):
            s = math.sqrt(w[j])
            if top == 0 or s < ENVELOPE_MIN_AXIS * top:
                continue
            d = factor * s * v[:, j]
            segs.append([xyz[n] - d, xyz[n] + d])
    return segs


def _envelope_size(disp, alpha, sigma) -> str:
    """The longest ±σ axis drawn against the largest node motion (true scale): an envelope too
    small to see is then known to be small, not missing."""
    peak = float(np.max(np.linalg.norm(np.abs(disp.value), axis=1), initial=0.0))
    if peak == 0 or disp.covariance is None:
        return ""
    return f"\n(true size up to {100 * sigma * disp.largest_std(alpha) / peak:.2g} % of the largest motion)"


def _title(modes, k, disp, geometry, lag):
    f, xi = float(modes.frequency_hz[k]), float(modes.damping_ratio[k])
    sf = getattr(modes, "frequency_std", None)
    sx = getattr(modes, "damping_std", None)
    labels = getattr(modes, "mode_labels", None)  # e.g. "order 20, mode 3" (Result.plot_shape with order=)
    name = str(labels[k]) if labels is not None else f"mode {k + 1}"
    if sf is not None and np.isfinite(sf[k]):
        head = f"{name}: {f:.4g} ± {sf[k]:.2g} Hz, ξ {100 * xi:.3g} ± {100 * sx[k]:.2g} %"
    else:
        head = f"{name}: {f:.4g} Hz, ξ {100 * xi:.3g} %"
    if disp.covariance is None:
        env = "no σ"
    elif disp.exact:
        env = f"±{ENVELOPE_SIGMA:g}σ: shape covariance"
    else:
        env = f"±{ENVELOPE_SIGMA:g}σ: per-channel σ, correlations neglected"
    return (f"{geometry.name}\n" if geometry.name else "") + f"{head}\n{env}; largest phase lag {lag:.0f}°"


def _half_extents(pts):
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = 0.5 * (hi - lo)
    return 0.5 * (lo + hi), np.maximum(half, 0.05 * max(float(half.max()), 1e-12))  # a flat structure keeps some depth


def _figsize(geometry, figsize, square, wide, tall):
    """``figsize`` if given, else by the structure's shape: a long deck gets a wide figure, a tower a
    tall one (a square figure leaves most of its area empty around them)."""
    if figsize is not None:
        return figsize
    _, half = _half_extents(np.asarray(geometry.coordinates, float))
    horizontal, vertical = float(max(half[0], half[1])), float(half[2])
    return wide if horizontal >= 2.5 * vertical else tall if vertical >= 2.5 * horizontal else square


def _limits(ax, pts):
    from matplotlib.ticker import MaxNLocator

    mid, half = _half_extents(pts)
    for set_lim, m, h in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, half):
        set_lim(m - 1.05 * h, m + 1.05 * h)
    # a long, low structure drawn in a box of its own proportions fills little of the axes: zoom
    # in (a tower gets a tall figure instead, and a zoom would cut its top off)
    elongation = float(half.max() / np.median(half)) if np.argmax(half) < 2 else 1.0
    ax.set_box_aspect(tuple(half), zoom=float(np.clip(1.0 + 0.1 * (elongation - 1.0), 1.0, 1.5)))
    thin = half < 0.15 * half.max()
    for axis, t in zip((ax.xaxis, ax.yaxis, ax.zaxis), thin):
        axis.set_major_locator(MaxNLocator(4))
        if t:  # a side too short in the drawing for tick labels: its range goes in the axis label
            axis.set_ticklabels([])
    return [(m - h, m + h) if t else None for m, h, t in zip(mid, half, thin)]


class _Drawing:
    """The artists of one mode on one 3-D Axes, updated per phase (static plot and animation)."""

    def __init__(self, ax, geometry, disp, scale, sigma, envelope, show_sensors, magnify=1.0):
        from matplotlib import colormaps
        from matplotlib.colors import Normalize
        from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

        self.ax, self.geo, self.disp = ax, geometry, disp
        self.factor = _scale(geometry, disp.value, scale)
        self.sigma, self.envelope = sigma * magnify, envelope
        self.index = {int(n): i for i, n in enumerate(geometry.node_ids)}
        xyz = geometry.coordinates
        # undeformed, faint
        ax.add_collection3d(Line3DCollection(_segments(xyz, self.index, geometry.lines), colors="0.6",
                                             linewidths=0.8, alpha=0.45, linestyles="--"))
        if len(geometry.triangles):
            ax.add_collection3d(Poly3DCollection([[xyz[self.index[int(v)]] for v in t] for t in geometry.triangles],
                                                 facecolor="0.85", edgecolor="none", alpha=0.2))
        if show_sensors and geometry.n_channels:
            at = np.array([xyz[self.index[int(n)]] for n in geometry.channel_node])
            d = geometry.channel_direction * 0.06 * geometry.size
            ax.quiver(at[:, 0], at[:, 1], at[:, 2], d[:, 0], d[:, 1], d[:, 2], color="tab:green", lw=0.9,
                      arrow_length_ratio=0.3, label="sensor directions")
        still = ~disp.moving
        if still.any():
            ax.scatter(*xyz[still].T, s=14, facecolors="none", edgecolors="0.4", depthshade=False,
                       label="not measured (fixed)")
        # (made with a placeholder segment: an empty collection breaks add_collection3d's limits)
        dot = [[xyz[0], xyz[0]]]
        self.lines = Line3DCollection(dot, colors="tab:blue", linewidths=1.8)
        ax.add_collection3d(self.lines)
        self.faces = None
        if len(geometry.triangles):
            self.faces = Poly3DCollection([[xyz[0]] * 3], facecolor="tab:blue", edgecolor="none", alpha=0.25)
            ax.add_collection3d(self.faces)
        self.env = Line3DCollection(dot, colors="tab:red", linewidths=1.4, alpha=0.9)
        ax.add_collection3d(self.env)
        self.phase = node_phases(disp.value)
        self.cmap, self.norm = colormaps[PHASE_CMAP], Normalize(-90.0, 90.0)
        moving = disp.moving
        colours = self.cmap(self.norm(np.nan_to_num(self.phase[moving])))
        self.nodes = ax.scatter(*xyz[moving].T, s=26, c=colours, edgecolors="k", linewidths=0.6, depthshade=False,
                                zorder=5)
        # the axes hold the whole motion: the peak displacement at both signs, the envelope around it
        peak = np.abs(disp.value) * self.factor
        extra = 0.0 if disp.covariance is None else self.factor * self.sigma * float(
            np.sqrt(np.max(np.diagonal(disp.covariance, axis1=1, axis2=2), initial=0.0)))
        pts = np.vstack([xyz, xyz + peak + extra, xyz - peak - extra])
        ranges = _limits(ax, pts)
        for set_label, name, rng in zip((ax.set_xlabel, ax.set_ylabel, ax.set_zlabel), "xyz", ranges):
            label = f"{name} [{geometry.units}]"
            set_label(label if rng is None else f"{label} ({rng[0]:.2g} to {rng[1]:.2g})", fontsize=8)
        ax.tick_params(labelsize=7)

    def draw(self, alpha):
        xyz = self.geo.coordinates
        moved = xyz + self.factor * self.disp.at_phase(alpha)
        self.lines.set_segments(_segments(moved, self.index, self.geo.lines))
        if self.faces is not None:
            self.faces.set_verts([[moved[self.index[int(v)]] for v in t] for t in self.geo.triangles])
        cov = self.disp.covariance_at(alpha) if self.envelope else None
        self.env.set_segments(_envelope_segments(moved, cov, self.disp.moving, self.factor * self.sigma))
        m = moved[self.disp.moving]
        self.nodes._offsets3d = (m[:, 0], m[:, 1], m[:, 2])
        return self.lines, self.env, self.nodes


def plot_shape(modes, mode: int, geometry, *, ax=None, scale=None, sigma=ENVELOPE_SIGMA, envelope=True,
               magnify_envelope=1.0, show_sensors=True, elev=22.0, azim=-60.0, figsize=None):
    """Mode ``mode`` (from 1) of ``modes`` on ``geometry`` in 3-D: undeformed faint, deformed at
    the phase of the largest motion, the ±``sigma``σ ellipsoid axes at each moving node (red),
    nodes coloured by the phase of their motion, sensor directions (green arrows).

    Parameters
    ----------
    modes : SelectedModes
        Or anything with ``frequency_hz``, ``damping_ratio``, ``mode_shape`` and ``output_names``;
        its ``mode_covariance`` (exact envelope) or ``mode_shape_std_real/imag``; optional
        ``mode_labels`` (one title per mode, default "mode k").
    mode : int
        From 1, as in the tables.
    geometry : Geometry
        Its channels are matched to ``modes.output_names`` by name.
    ax : a 3-D Axes (``projection="3d"``), optional
    scale : float, optional
        Display factor from shape to length; default: the largest node motion is
        ``DISPLAY_FRACTION`` of the structure's size. The envelope is scaled alike.
    sigma : float
        Half-width of the envelope in standard deviations (default 2).
    magnify_envelope : float
        Draw the envelope this many times larger than the shape's scale (default 1: true to
        scale; the legend says the factor otherwise), for σ too small to see.
    figsize : (width, height) in inches, optional
        Default: 6.4 × 6.0, or 9.6 × 5.6 for a structure at least 2.5 times longer than high
        (a deck) and 5.6 × 7.6 for one 2.5 times higher than long (a tower).

    Returns
    -------
    matplotlib.figure.Figure
    """
    sigma = check_real("sigma", sigma, low=0)
    magnify = check_real("magnify_envelope", magnify_envelope, low=0, low_open=True)
    disp = mode_displacements(modes, mode, geometry)
    own_figure = ax is None
    if own_figure:
        fig = StandaloneFigure(figsize=_figsize(geometry, figsize, (6.4, 6.0), (9.6, 5.6), (5.6, 7.6)),
                               layout="constrained")
        ax = fig.add_subplot(projection="3d")
    fig = ax.figure
    drawing = _Drawing(ax, geometry, disp, scale, sigma, envelope, show_sensors, magnify)
    drawing.draw(peak_phase(disp.value))
    ax.view_init(elev=elev, azim=azim)
    lag = float(np.nanmax(np.abs(drawing.phase), initial=0.0)) if np.any(disp.moving) else 0.0
    if own_figure:  # constrained layout keeps a suptitle clear of a 3-D axes, not an Axes title
        fig.suptitle(_title(modes, mode - 1, disp, geometry, lag), fontsize=9)
    else:
        ax.set_title(_title(modes, mode - 1, disp, geometry, lag), fontsize=9)
    from matplotlib.cm import ScalarMappable

    cb = fig.colorbar(ScalarMappable(norm=drawing.norm, cmap=drawing.cmap), ax=ax, shrink=0.5, pad=0.06,
                      location="bottom", aspect=30)
    cb.set_label("phase of node motion [°] (0: as a real mode)", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    handles, labels = ax.get_legend_handles_labels()
    from matplotlib.lines import Line2D

    handles += [Line2D([], [], color="0.6", ls="--", lw=0.8), Line2D([], [], color="tab:blue", lw=1.8)]
    labels += ["undeformed", f"deformed (× {drawing.factor:.3g})"]
    if disp.covariance is not None and envelope:
        handles.append(Line2D([], [], color="tab:red", lw=1.4))
        labels.append(f"±{sigma:g}σ ellipsoid axes" + (f" (σ × {magnify:g})" if magnify != 1 else "")
                      + _envelope_size(disp, peak_phase(disp.value), sigma))
    if ax.figure is fig and len(fig.axes) <= 2:  # a figure of its own: the legend below the axes
        fig.legend(handles, labels, fontsize=7, loc="outside lower center", ncols=2, frameon=False)
    else:
        ax.legend(handles, labels, fontsize=7, loc="upper left")
    return fig


def animate_shape(modes, mode: int, geometry, *, path=None, frames: int = 24, fps: float = 12.0, scale=None,
                  sigma=ENVELOPE_SIGMA, envelope=True, magnify_envelope=1.0, show_sensors=False, elev=22.0,
                  azim=-60.0, figsize=None, dpi=80):
    """Mode ``mode`` (from 1) moving over one cycle (``frames`` phases), with the ±σ envelope at each.

    ``magnify_envelope`` as in :func:`plot_shape` (the title says it). ``path``: ``.gif``
    (Pillow) or ``.mp4`` (needs ffmpeg; ``ValueError`` naming ``path`` without it), written
    atomically. ``figsize``: by default from the structure's shape, as in :func:`plot_shape`
    (5.6 × 5.0, a deck 8.4 × 4.6, a tower 4.6 × 6.4). Returns the
    :class:`matplotlib.animation.FuncAnimation`.
    """
    from matplotlib.animation import FuncAnimation, writers

    frames = check_integer("frames", frames, minimum=2, maximum=1000)
    fps = check_real("fps", fps, low=0, low_open=True)
    kind = None
    if path is not None:
        kind = Path(path).suffix.lower()
        if kind not in (".gif", ".mp4"):
            raise ValueError(f"path {os.fspath(path)!r}: an animation is written as .gif or .mp4")
        if kind == ".mp4" and not writers.is_available("ffmpeg"):
            raise ValueError(f"path {os.fspath(path)!r}: writing .mp4 needs ffmpeg, which is not installed; "
                             "write a .gif")
    sigma = check_real("sigma", sigma, low=0)
    magnify = check_real("magnify_envelope", magnify_envelope, low=0, low_open=True)
    disp = mode_displacements(modes, mode, geometry)
    fig = StandaloneFigure(figsize=_figsize(geometry, figsize, (5.6, 5.0), (8.4, 4.6), (4.6, 6.4)),
                           layout="constrained")
    ax = fig.add_subplot(projection="3d")
    drawing = _Drawing(ax, geometry, disp, scale, sigma, envelope, show_sensors, magnify)
    ax.view_init(elev=elev, azim=azim)
    lag = float(np.nanmax(np.abs(drawing.phase), initial=0.0)) if np.any(disp.moving) else 0.0
    title = _title(modes, mode - 1, disp, geometry, lag)
    size = _envelope_size(disp, peak_phase(disp.value), sigma) if disp.covariance is not None and envelope else ""
    fig.suptitle(title + (f" (σ × {magnify:g})" if magnify != 1 else "")
                 + (f"\n±{sigma:g}σ {size[1:]}" if size else ""), fontsize=8)
    start = peak_phase(disp.value)
    phases = start + 2 * np.pi * np.arange(frames) / frames
    anim = FuncAnimation(fig, lambda i: drawing.draw(phases[i]), frames=frames, interval=1000.0 / fps, blit=False)
    if path is not None:
        def save(tmp):
            # the writers choose the format by the extension: written beside, then moved onto tmp
            named = tmp.with_name(tmp.name + kind)
            try:
                if kind == ".gif":
                    from matplotlib.animation import PillowWriter

                    anim.save(named, writer=PillowWriter(fps=fps), dpi=dpi)
                else:
                    anim.save(named, writer="ffmpeg", fps=fps, dpi=dpi)
                os.replace(named, tmp)
            finally:
                if named.exists():
                    named.unlink()

        write_atomically(Path(path), save)
    return anim
