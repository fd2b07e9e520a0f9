"""Plots: stabilization diagram (paper Figure 3) and mode shapes, each with ±1σ error bars.

Each function draws into the given Axes/Figure or a new one and returns the
:class:`matplotlib.figure.Figure`; nothing is shown or saved. A new figure is not registered with
pyplot: plotting in a loop does not pile up open figures and no GUI backend is started. It saves
with ``fig.savefig`` and displays in Jupyter like any figure; for a window, draw into Axes made
by pyplot (``fig, ax = plt.subplots(); result.plot(ax)``).

>>> import modaluq                                                     # doctest: +SKIP
>>> diagram = modaluq.stabilization_diagram(result)                    # doctest: +SKIP
>>> fig = diagram.plot(y=sim.y, selected=diagram.select_modes())       # doctest: +SKIP
>>> fig.savefig("diagram.png", dpi=120)                                # doctest: +SKIP
"""

from __future__ import annotations

import io

import numpy as np
from matplotlib.figure import Figure

from .checks import check_boolean, check_integer
from .indicators import mac_matrix
from .settings import PoleStatus
from .spectrum import output_spectrum_singular_values

__all__ = ["DIAGRAM_FIGSIZE", "STATUS_STYLE", "plot_mac", "plot_mode_shapes", "plot_stabilization_diagram"]

#: Size in inches of a new stabilization diagram (the command line's figures too).
DIAGRAM_FIGSIZE = (9.0, 6.0)

#: How each pole status is drawn: (marker, colour, face colour, marker size, legend label).
STATUS_STYLE = {
    "stable": ("o", "tab:green", "tab:green", 4.5, "stable (f, ξ, MAC)"),
    "stable_frequency": ("v", "tab:blue", "none", 4.5, "stable frequency"),
    "unstable": ("x", "tab:orange", "tab:orange", 4.0, "unstable"),
    "rejected": (".", "0.65", "0.65", 3.0, "rejected (ξ range, σ_f/f)"),
}


class StandaloneFigure(Figure):
    """A Figure pyplot does not know: nothing to close, nothing piles up in loops."""

    def _repr_png_(self):
        # Jupyter shows a Figure through the formatter pyplot's inline backend registers; without
        # pyplot imported there is none, and this makes the figure show anyway.
        buf = io.BytesIO()
        self.savefig(buf, format="png", bbox_inches="tight")
        return buf.getvalue()


def _axes(ax, figsize):
    if ax is None:
        fig = StandaloneFigure(figsize=figsize, layout="constrained")
        return fig, fig.add_subplot()
    return ax.figure, ax


#: Mode shapes of more channels than this are drawn as horizontal bars, one labelled row per channel.
HORIZONTAL_SHAPES_ABOVE = 6
#: The spectrum behind a diagram is drawn down to this fraction of its largest value in the band.
SPECTRUM_DECADES_FLOOR = 1e-6
#: an AutoMAC of more modes than this writes the values only in its cells (2 digits), no σ
MAC_CELL_SIGMA_MAX_MODES = 8
#: narrowest shaded ±σ band of a selected mode, as a fraction of the frequency axis
MIN_BAND_FRACTION = 0.004


def _check_identified_record(diagram, y) -> None:
    """Refuse a ``y`` that is not the record the diagram was identified from (by its length)."""
    n_identified = int(getattr(diagram, "n_samples", 0) or 0)
    shape = np.shape(y)
    if not n_identified or not shape or shape[0] == n_identified:
        return
    steps = (getattr(diagram, "result_settings", None) or {}).get("preprocessing", {}).get("steps", [])
    how = f" ({'; '.join(steps)})" if steps else ""
    raise ValueError(
        f"y has {shape[0]} samples but the diagram was identified from a record of {n_identified} samples at "
        f"{diagram.fs:g} Hz{how}: its spectrum would be drawn at the wrong frequencies. Pass the record "
        "identified (Analysis.preprocessed.y, or modaluq.preprocess.preprocess(y, fs=..., frequency_range=...).y), "
        "or spectrum=modaluq.spectrum.output_spectrum_singular_values(y, fs_of_y) for the raw record")


def plot_stabilization_diagram(diagram, ax=None, *, y=None, spectrum=None, selected=None, show_rejected=True,
                               nperseg=None, frequency_range=None, figsize=DIAGRAM_FIGSIZE):
    """Stabilization diagram: every pole at (frequency, model order) with ±σ_f horizontal bars.

    Poles are marked by :class:`~modaluq.PoleStatus` (see ``STATUS_STYLE``);
    non-rejected poles carry horizontal error bars of ±1 analytic standard deviation of the
    frequency (rejected poles are drawn without bars: theirs often span the whole axis). When
    output samples are given, the singular values of their cross power spectral density matrix
    are drawn behind on a logarithmic twin axis, like Figure 3 of the reference paper. Selected
    modes are marked by dotted vertical lines numbered at the top.

    Parameters
    ----------
    diagram : modaluq.Diagram
    ax : matplotlib.axes.Axes, optional
        Where to draw; a new figure when None.
    y : array_like, shape (n_samples, n_outputs), optional
        Output samples of the identification, for the spectrum background: the record
        identified, after any window or decimation (``Analysis.preprocessed.y``,
        ``modaluq.preprocess.preprocess(...).y``), drawn at the diagram's ``fs``. A ``y`` whose length
        differs from the identified record's (``diagram.n_samples``) raises ``ValueError``: its
        spectrum at the diagram's rate would put every peak at the wrong frequency (a raw record
        that ``identify(..., frequency_range=...)`` decimated). Draw a raw record with
        ``spectrum=output_spectrum_singular_values(raw, fs_raw)`` instead.
    spectrum : tuple (frequency_hz, singular_values), optional
        A precomputed :func:`~modaluq.spectrum.output_spectrum_singular_values` (instead of ``y``).
    selected : modaluq.SelectedModes, optional
        Modes to mark.
    show_rejected : bool
        Draw the rejected poles (grey dots), default True.
    nperseg : int, optional
        Welch segment length of the spectrum (see ``output_spectrum_singular_values``).
    frequency_range : (float, float), optional
        Horizontal limits in Hz; default the band given to ``identify`` (``frequency_range``),
        else 0 to fs/2.
    figsize : (float, float)
        Size in inches of a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        With a spectrum, the twin axes holding it comes right after ``ax`` in ``fig.axes``.
        The poles of each status are one errorbar container of ``ax.containers``, labelled
        ``"<label> (<count>)"``. Noise-coupled poles that are not rejected (their σ is not a
        first-order value, docs/uq-math.md §5.5) are drawn without a σ bar and ringed.
    """
    # known by its fields: the result types sit above the plots (their plot() methods call them)
    if not all(hasattr(diagram, k) for k in ("orders", "order", "frequency_hz", "status", "frequency_std")):
        raise TypeError(f"diagram must be a modaluq Diagram; got {type(diagram).__name__}")
    if y is not None and spectrum is not None:
        raise TypeError("pass y or spectrum, not both")
    show_rejected = check_boolean("show_rejected", show_rejected)
    fig, ax = _axes(ax, figsize)

    spec_ax = None
    if y is not None:
        _check_identified_record(diagram, y)
        spectrum = output_spectrum_singular_values(y, diagram.fs, nperseg=nperseg)
    if spectrum is not None:
        freq, sv = (np.asarray(a) for a in spectrum)
        if sv.ndim == 1:
            sv = sv[:, None]
        spec_ax = ax.twinx()
        for k in range(sv.shape[1]):
            spec_ax.semilogy(freq[1:], sv[1:, k], color="0.25" if k == 0 else "0.6",
                             lw=0.9 if k == 0 else 0.6, zorder=1, label="_nolegend_")
        spec_ax.set_ylabel("singular values of the output PSD matrix")
        # poles in front of the spectrum
        ax.set_zorder(spec_ax.get_zorder() + 1)
        ax.patch.set_visible(False)

    handles = []
    for status in PoleStatus:
        if status is PoleStatus.REJECTED and not show_rejected:
            continue
        mask = diagram.is_status(status)
        marker, colour, face, size, label = STATUS_STYLE[status.value]
        if not mask.any():
            continue
        f = diagram.frequency_hz[mask]
        n = diagram.order[mask]
        xerr = None
        if status is not PoleStatus.REJECTED and diagram.has_uncertainty:
            # a noise-coupled pole has no first-order σ: no bar (it is ringed below)
            xerr = np.where(diagram.noise_coupled[mask], 0.0, np.nan_to_num(diagram.frequency_std[mask], nan=0.0))
        # caps mark the ends of each bar, so a short one still reads as a bar, not as the marker
        h = ax.errorbar(f, n, xerr=xerr, fmt=marker, color=colour, mfc=face, ms=size, lw=0.8,
                        capsize=1.5 if xerr is not None else 0, elinewidth=0.8,
                        label=f"{label} ({int(mask.sum())})", zorder=3)
        handles.append(h)

    coupled = diagram.noise_coupled & ~diagram.is_status(PoleStatus.REJECTED)
    if coupled.any():
        ax.plot(diagram.frequency_hz[coupled], diagram.order[coupled], "o", mfc="none", mec="k", ms=8, mew=0.8,
                zorder=4, label=f"noise-coupled: no first-order σ ({int(coupled.sum())})")
    if frequency_range is None:  # the band the identification was given, else 0 to fs/2
        frequency_range = (diagram.result_settings or {}).get("frequency_range")
    lo, hi = (0.0, diagram.fs / 2) if frequency_range is None else map(float, frequency_range)
    if selected is not None:
        # Mode numbers on top; a number closer than 2 % of the axis to the previous one is
        # raised a line, so that close modes (a tower's bending pair) stay readable.
        last_x, raised = -np.inf, False
        # Each selected mode's ±σ_f (its cluster's, SelectedModes.std_words) as a shaded band, at least
        # MIN_BAND_FRACTION of the axis wide so that a σ far below a pixel is still seen.
        min_half = 0.5 * MIN_BAND_FRACTION * (hi - lo)
        for k, fk in enumerate(selected.frequency_hz):
            sk = float(selected.frequency_std[k]) if np.isfinite(selected.frequency_std[k]) else 0.0
            if diagram.has_uncertainty:
                half = max(sk, min_half)
                ax.axvspan(fk - half, fk + half, color="tab:purple", alpha=0.22, lw=0, zorder=1,
                           label=(f"selected mode ±1σ_f (at least {100 * MIN_BAND_FRACTION:g} % of the axis)"
                                  if k == 0 else None))
            ax.axvline(fk, color="k", ls=":", lw=0.8, zorder=2)
            raised = (fk - last_x) < 0.02 * (hi - lo) and not raised
            last_x = fk
            ax.annotate(str(k + 1), (fk, 1.0), xycoords=("data", "axes fraction"), xytext=(0, 11 if raised else 2),
                        textcoords="offset points", ha="center", va="bottom", fontsize=8)
    ax.set_xlim(lo, hi)
    if spec_ax is not None:
        # A useful dynamic range: six decades below the largest value in the shown band (a
        # spectrum over 20 decades leaves the peaks as a flat line).
        shown = (freq[1:] >= lo) & (freq[1:] <= hi)
        if shown.any():
            top = float(np.max(sv[1:][shown]))
            if top > 0:
                spec_ax.set_ylim(max(float(np.min(sv[1:][shown])), top * SPECTRUM_DECADES_FLOOR), top * 2.0)
    if diagram.orders:
        ax.set_ylim(0, max(diagram.orders) * 1.04 + 1)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("model order")
    kind = "±1σ bars" if diagram.has_uncertainty else "no uncertainty"
    ax.set_title(f"Stabilization diagram ({kind})", fontsize=10, pad=23 if selected is not None else 6)
    if handles:
        ax.legend(loc="lower right", fontsize=8, framealpha=0.85)  # every labelled artist, bands included
    return fig


def plot_mode_shapes(modes, fig=None, *, channel_positions=None, ncols=3, figsize=None):
    """Bar charts of mode shapes, real and imaginary parts, with ±1σ error bars.

    Shapes are normalised so that their largest-modulus component is 1 (its σ is 0 by
    construction). For lightly damped structures the imaginary parts are small; their bars make
    visible how far a shape is from a real (normal) mode, relative to its uncertainty.

    Parameters
    ----------
    modes : SelectedModes or Modes
        Anything with ``frequency_hz``, ``damping_ratio``, ``mode_shape`` (n_outputs × n_modes)
        and optionally ``mode_shape_std_real`` / ``mode_shape_std_imag``, ``frequency_std``,
        ``damping_std`` and ``output_names``.
    fig : matplotlib.figure.Figure, optional
        Drawn into (cleared first); a new figure when None.
    channel_positions : array_like, shape (n_outputs,), optional
        Positions of the sensors (any unit) for the horizontal axis; default the channel index.
    ncols : int
        Subplots per row.
    figsize : (float, float), optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    shape = np.asarray(modes.mode_shape)
    if shape.ndim != 2:
        raise ValueError(f"modes.mode_shape must be 2-D (n_outputs, n_modes); got shape {shape.shape}")
    n_out, n_modes = shape.shape
    names = tuple(getattr(modes, "output_names", ()) or (f"y{k}" for k in range(n_out)))
    sr = getattr(modes, "mode_shape_std_real", None)
    si = getattr(modes, "mode_shape_std_imag", None)
    sf = getattr(modes, "frequency_std", None)
    sx = getattr(modes, "damping_std", None)
    if channel_positions is None:
        x = np.arange(n_out, dtype=float)
    else:
        x = np.asarray(channel_positions, dtype=float)
        if x.shape != (n_out,):
            raise ValueError(f"channel_positions must have {n_out} entries; got shape {x.shape}")
    ncols = max(1, min(check_integer("ncols", ncols, minimum=1), n_modes))
    nrows = max(1, -(-n_modes // ncols))
    # Many channels: horizontal bars, one labelled row per channel (names side by side overlap).
    horizontal = n_out > HORIZONTAL_SHAPES_ABOVE
    if figsize is None:
        if horizontal:
            label_in = 0.07 * max(len(str(nm)) for nm in names)
            figsize = (2.6 * ncols + label_in + 0.6, (0.19 * n_out + 0.7) * nrows + 0.3)
        else:
            figsize = (3.4 * ncols, 2.6 * nrows + 0.3)
    if fig is None:
        fig = StandaloneFigure(figsize=figsize, layout="constrained")
    else:
        fig.clear()
    if n_modes == 0:
        fig.text(0.5, 0.5, "no modes", ha="center", va="center")
        return fig
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey=True, sharex=horizontal)
    spacing = np.min(np.diff(np.sort(x))) if n_out > 1 else 1.0
    w = 0.38 * spacing
    long_names = max(len(str(nm)) for nm in names) > 4 and n_out > 3
    for i in range(n_modes):
        ax = axes.flat[i]
        err_r = None if sr is None else np.nan_to_num(np.asarray(sr)[:, i])
        err_i = None if si is None else np.nan_to_num(np.asarray(si)[:, i])
        if horizontal:
            ax.barh(x - w / 2, shape[:, i].real, w, xerr=err_r, color="tab:blue", capsize=1.5,
                    error_kw={"lw": 0.7}, label="real")
            ax.barh(x + w / 2, shape[:, i].imag, w, xerr=err_i, color="tab:orange", capsize=1.5,
                    error_kw={"lw": 0.7}, label="imag")
            ax.axvline(0, color="k", lw=0.5)
            ax.set_yticks(x, names, fontsize=7)
            ax.grid(True, axis="x", alpha=0.3)
        else:
            ax.bar(x - w / 2, shape[:, i].real, w, yerr=err_r, color="tab:blue", capsize=2,
                   error_kw={"lw": 0.8}, label="real")
            ax.bar(x + w / 2, shape[:, i].imag, w, yerr=err_i, color="tab:orange", capsize=2,
                   error_kw={"lw": 0.8}, label="imag")
            ax.axhline(0, color="k", lw=0.5)
            ax.set_xticks(x, names, fontsize=8, rotation=90 if long_names else 0)
        f, xi = modes.frequency_hz[i], modes.damping_ratio[i]
        if sf is not None and np.isfinite(np.asarray(sf)[i]):
            t = f"{f:.4g} ± {np.asarray(sf)[i]:.2g} Hz, ξ {100 * xi:.3g} ± {100 * np.asarray(sx)[i]:.2g} %"
        else:
            t = f"{f:.4g} Hz, ξ {100 * xi:.3g} %"
        ax.set_title(f"mode {i + 1}: {t}", fontsize=8)
    for ax in list(axes.flat)[n_modes:]:
        ax.set_visible(False)
    if horizontal:
        axes.flat[0].set_xlim(-1.15, 1.15)
        axes.flat[0].invert_yaxis()  # first channel on top, as in a table
        axes.flat[0].legend(fontsize=7, loc="lower right")
        fig.supxlabel("mode shape (±1σ)", fontsize=9)
    else:
        axes.flat[0].set_ylim(-1.15, 1.15)
        axes.flat[0].legend(fontsize=7, loc="lower left")
        fig.supylabel("mode shape (±1σ)", fontsize=9)
    return fig


def plot_mac(modes, ax=None, *, figsize=None, title="AutoMAC"):
    """The MAC matrix of a set of modes (AutoMAC), each cell with its value and ±1σ.

    Parameters
    ----------
    modes : SelectedModes
        Or anything with ``mode_shape`` (n_outputs × n_modes), ``frequency_hz`` and optionally
        ``mode_covariance`` (n_modes, 2+2l, 2+2l) or ``mode_shape_covariance`` (n_modes, 2l, 2l).
    ax : matplotlib.axes.Axes, optional
    title : str

    The σ are those of :func:`modaluq.indicators.mac_matrix`: exact when ``modes`` carries
    ``mode_shape_factor`` (``identify(..., keep_shape_factor=True)``), else with the shapes'
    cross-covariance taken as 0 (said under the title). Returns the Figure.
    """
    shape = np.asarray(modes.mode_shape)
    if shape.ndim != 2:
        raise ValueError(f"modes.mode_shape must be 2-D (n_outputs, n_modes); got shape {shape.shape}")
    m = shape.shape[1]
    if figsize is None:
        figsize = (1.0 + 0.75 * max(m, 3), 0.8 + 0.7 * max(m, 3))
    fig, ax = _axes(ax, figsize)
    if m == 0:
        ax.text(0.5, 0.5, "no modes", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return fig
    cov = getattr(modes, "mode_shape_covariance", None)
    if cov is None:
        cov = getattr(modes, "mode_covariance", None)
    mm = mac_matrix(shape, cov, getattr(modes, "mode_shape_factor", None))
    im = ax.imshow(mm.mac, vmin=0.0, vmax=1.0, cmap="Blues", origin="upper")
    with_std = np.isfinite(mm.std).all()
    small = m > MAC_CELL_SIGMA_MAX_MODES
    for i in range(m):
        for j in range(m):
            v = mm.mac[i, j]
            text = f"{v:.2f}" if small else f"{v:.3f}"
            if with_std and i != j and not small:
                text += f"\n±{mm.std[i, j]:.2g}"
            ax.text(j, i, text, ha="center", va="center", fontsize=6 if small else 7,
                    color="white" if v > 0.6 else "black")
    f = np.asarray(modes.frequency_hz, float)
    labels = [f"{k + 1}\n{f[k]:.3g} Hz" for k in range(m)]
    ax.set_xticks(range(m), labels, fontsize=7)
    ax.set_yticks(range(m), labels, fontsize=7)
    ax.tick_params(length=0)
    fig.colorbar(im, ax=ax, shrink=0.8, label="MAC")
    if not with_std:
        note = "no σ (no shape covariance)"
    elif small:
        note = f"values only: more than {MAC_CELL_SIGMA_MAX_MODES} modes (σ: SelectedModes.mac_matrix())"
    else:
        note = ("±1σ, shapes taken as independent (cross-covariance not kept)" if mm.independent_approximation
                else "±1σ, with the shapes' cross-covariance")
    ax.set_title(f"{title}\n{note}", fontsize=9)
    return fig
