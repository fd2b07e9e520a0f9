"""The monitoring plots: tracked frequencies with their σ bands, and the control chart.

Each draws a :class:`xarray.Dataset` of :func:`~modaluq.monitor` (``Monitoring.dataset``, or a
store read with :func:`~modaluq.load_tracks`) into the given Figure or a new one, one panel per
tracked mode sharing the time axis, and returns the Figure (nothing is shown or saved; a new
figure is not registered with pyplot, as in :mod:`modaluq.plot`).
"""

from __future__ import annotations

import numpy as np

from ..checks import check_integer
from ..plot import StandaloneFigure

__all__ = ["TRACK_ROW_HEIGHT", "plot_control_chart", "plot_tracked_frequencies"]

#: Size in inches of a new monitoring figure per tracked mode row.
TRACK_ROW_HEIGHT = 1.6


def _time_axis(ds):
    """The records' times when every one is known, else their index."""
    t = ds["time"].values if "time" in ds.coords else None
    if t is not None and not np.isnat(t).any():
        return t, "time"
    return np.arange(ds.sizes["record"]), "record"


def _track_panels(ds, fig, modes, figsize):
    """A figure of one panel per tracked mode sharing the time axis: (fig, axes, modes, (x, xlabel))."""
    modes = list(ds["mode"].values) if modes is None else [check_integer("modes", m, minimum=1) for m in modes]
    n = max(len(modes), 1)
    if fig is None:
        fig = StandaloneFigure(figsize=figsize or (9.0, 1.2 + TRACK_ROW_HEIGHT * n), layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    return fig, axes, modes, _time_axis(ds)


def _finish_track_axes(fig, axes, xlabel: str, ncol: int) -> None:
    """One legend of every panel's entries (an alarm may be in any panel), below the panels so
    that it covers no record, and readable dates."""
    entries = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    fig.legend(entries.values(), entries.keys(), loc="outside lower center", fontsize="small", ncol=ncol,
               frameon=False)
    if xlabel == "time":  # full dates overlap on a multi-day axis: only what changes between ticks
        import matplotlib.dates as mdates

        locator = mdates.AutoDateLocator()
        axes[-1].xaxis.set_major_locator(locator)
        axes[-1].xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    axes[-1].set_xlabel(xlabel)


def plot_tracked_frequencies(ds, fig=None, *, modes=None, figsize=None):
    """Each tracked mode's frequency against time (one panel per mode), with its ±σ band, the
    reference's prediction, the reference period shaded and the alarms marked.

    ``ds`` is :attr:`modaluq.monitoring.Monitoring.dataset` (or :func:`modaluq.monitoring.load_tracks`);
    ``modes`` the 1-based modes to draw (default all).
    """
    fig, axes, modes, (x, xlabel) = _track_panels(ds, fig, modes, figsize)
    if not modes:
        axes[0].text(0.5, 0.5, "no tracked mode", ha="center", va="center", transform=axes[0].transAxes)
        return fig
    ref = ds["in_reference"].values
    for ax, mode in zip(axes, modes):
        d = ds.sel(mode=mode)
        f, sf = d["frequency_hz"].values, d["frequency_std"].values
        ax.fill_between(x, f - sf, f + sf, color="tab:blue", alpha=0.25, lw=0, label="±σ of the record")
        ax.plot(x, f, ".", color="tab:blue", ms=3, label="identified")
        if "expected_frequency_hz" in d:
            ax.plot(x, d["expected_frequency_hz"].values, "-", color="0.3", lw=0.8, label="reference prediction")
        if ref.any():
            r = np.flatnonzero(ref)
            ax.axvspan(x[r[0]], x[r[-1]], color="0.9", zorder=0, label="reference period")
        alarm = d["alarm"].values.astype(bool)
        if alarm.any():
            ax.plot(x[alarm], f[alarm], "v", color="tab:red", ms=5, label="alarm")
        shape_alarm = d["shape_alarm"].values.astype(bool) if "shape_alarm" in d else np.zeros(f.shape, bool)
        if shape_alarm.any():
            ax.plot(x[shape_alarm], f[shape_alarm], "D", mfc="none", color="tab:purple", ms=8, mew=1.2,
                    label="shape alarm")  # larger than the alarm triangle: both show where both fire
        ax.set_ylabel(f"mode {mode}\nf [Hz]")
        ax.grid(alpha=0.3)
    _finish_track_axes(fig, axes, xlabel, ncol=5)
    rate = ds.attrs.get("false_alarm_rate", float("nan"))
    fig.suptitle(f"tracked frequencies, {rate:g} false alarms per record and mode\n(alarm: the control statistic of f "
                 "and ξ above its limit; shape alarm: the shape against the reference's beyond σ)", fontsize="medium")
    return fig


def plot_control_chart(ds, fig=None, *, modes=None, figsize=None):
    """The control statistic (χ² with 2 degrees of freedom when nothing changed) of each tracked
    mode against time, with the alarm limit and each record's own χ² (2 degrees of freedom)."""
    fig, axes, modes, (x, xlabel) = _track_panels(ds, fig, modes, figsize)
    if not modes or "control" not in ds:
        axes[0].text(0.5, 0.5, "no tracked mode", ha="center", va="center", transform=axes[0].transAxes)
        return fig
    for ax, mode in zip(axes, modes):
        d = ds.sel(mode=mode)
        c = d["control"].values
        ax.semilogy(x, np.maximum(c, 1e-3), "-", color="tab:blue", lw=0.9, label="control statistic")
        ax.semilogy(x, np.maximum(d["chi2"].values, 1e-3), ".", color="0.6", ms=2.5, label="χ² of the record")
        limit = d["control_limit"].values
        ax.plot(x, limit, color="tab:red", lw=1, ls="--", label="alarm limit")
        alarm = d["alarm"].values.astype(bool)
        if alarm.any():
            ax.plot(x[alarm], c[alarm], "v", color="tab:red", ms=4, label="alarm")
        ax.set_ylabel(f"mode {mode}\nχ²")
        # every point on the axis: the records' own χ² can exceed the smoothed statistic by far
        shown = np.concatenate([c, limit, d["chi2"].values])
        top = np.nanmax(shown[np.isfinite(shown)], initial=10.0)
        ax.set_ylim(1e-2, 2 * top)
        ax.grid(alpha=0.3, which="major")
    _finish_track_axes(fig, axes, xlabel, ncol=4)
    fig.suptitle("control chart (multivariate EWMA of f and ξ against the reference)", fontsize="medium")
    return fig
