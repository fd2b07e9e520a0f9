"""Settings check: the same record selected with two or three horizons (``block_rows``).

σ measures the estimation noise of one identification. A bias from the horizon (lags too short
to resolve two close modes, or so long that noise dominates) does not show in σ: it shows as a
change of the estimate when the horizon changes. :func:`check_horizons` identifies the record
with the chosen ``block_rows`` and with shorter and longer ones, matches every selected mode
across the runs (nearest frequency within ``match_window``, shapes with MAC >= ``min_mac``) and
reports, beside each mode's σ, the spread of its estimates across the horizons.

>>> import warnings, modaluq
>>> sim = modaluq.simulate(40_000, seed=4)
>>> with warnings.catch_warnings():  # the slow spurious poles of the high orders are warned about
...     warnings.simplefilter("ignore", modaluq.ModalUQWarning)
...     check = modaluq.check_horizons(sim.y, sim.u, fs=sim.fs, frequency_range=(1, 20))
>>> check.block_rows
(75, 100, 150)
>>> int(check.found.sum(axis=1).min())  # every mode found at every horizon
3
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .checks import check_real
from .identification import identify, make_settings
from .results import ModalUQWarning
from .selection import SelectedModes, select_modes
from .settings import Settings
from .stabilization import modal_assurance_criterion, stabilization_diagram

__all__ = ["HorizonCheck", "check_horizons"]


@dataclass(frozen=True, repr=False)
class HorizonCheck:
    """Every mode selected at the reference horizon, found again (or not) at the others."""

    block_rows: tuple               #: the horizons tried, ascending; the reference is among them
    reference_block_rows: int       #: the horizon whose modes are listed
    selected: SelectedModes         #: the modes at the reference horizon
    frequency_hz: np.ndarray        #: (n_modes, n_horizons) Hz, NaN where not found
    damping_ratio: np.ndarray       #: (n_modes, n_horizons) fraction, NaN where not found
    found: np.ndarray               #: (n_modes, n_horizons) bool

    @property
    def frequency_spread(self) -> np.ndarray:
        """(n_modes,) Hz: sample std (ddof 1) of the frequency across the horizons that found the mode."""
        return _spread(self.frequency_hz)

    @property
    def damping_spread(self) -> np.ndarray:
        """(n_modes,) fraction: sample std of the damping ratio across the horizons."""
        return _spread(self.damping_ratio)

    def to_dataframe(self):
        """One row per mode (numbered from 1): f and ξ with σ, their spread across horizons, and
        the estimate at each horizon (``frequency_hz_p<block_rows>`` ...)."""
        import pandas as pd

        sel = self.selected
        data = {"frequency_hz": sel.frequency_hz, "frequency_std": sel.frequency_std,
                "frequency_spread_horizons": self.frequency_spread,
                "damping_ratio": sel.damping_ratio, "damping_std": sel.damping_std,
                "damping_spread_horizons": self.damping_spread}
        for j, p in enumerate(self.block_rows):
            data[f"frequency_hz_p{p}"] = self.frequency_hz[:, j]
        for j, p in enumerate(self.block_rows):
            data[f"damping_ratio_p{p}"] = self.damping_ratio[:, j]
        return pd.DataFrame(data, index=pd.RangeIndex(1, sel.n_modes + 1, name="mode"))

    def table(self) -> str:
        head = (f"{'mode':>4}  {'f [Hz]':>9}  {'std f':>8}  {'spread f':>8}  {'xi [%]':>7}  {'std xi':>7}  "
                f"{'spread xi':>9}  " + "  ".join(f"{'f p=' + str(p):>9}" for p in self.block_rows))
        lines = [head + "   (spread: across the horizons)"]
        fs, xs = self.frequency_spread, self.damping_spread
        sel = self.selected

        def cell(x, w, d):
            return f"{x:>{w}.{d}f}" if np.isfinite(x) else f"{'-':>{w}}"

        for i in range(sel.n_modes):
            lines.append(f"{i + 1:>4}  {sel.frequency_hz[i]:>9.4f}  {cell(sel.frequency_std[i], 8, 4)}  "
                         f"{cell(fs[i], 8, 4)}  {100 * sel.damping_ratio[i]:>7.3f}  "
                         f"{cell(100 * sel.damping_std[i], 7, 3)}  {cell(100 * xs[i], 9, 3)}  "
                         + "  ".join(cell(self.frequency_hz[i, j], 9, 4) for j in range(len(self.block_rows))))
        return "\n".join(lines)

    def __str__(self) -> str:
        return (f"settings check: block_rows {', '.join(str(p) for p in self.block_rows)} "
                f"(modes of block_rows = {self.reference_block_rows})\n" + self.table())

    def __repr__(self) -> str:
        return f"HorizonCheck(block_rows={self.block_rows}, n_modes={self.selected.n_modes})"


def _spread(values: np.ndarray) -> np.ndarray:
    out = np.full(values.shape[0], np.nan)
    for i, row in enumerate(values):
        row = row[np.isfinite(row)]
        if row.size >= 2:
            out[i] = np.std(row, ddof=1)
    return out


def check_horizons(y, u=None, *, fs: float, settings: Settings | None = None, factors=(0.75, 1.0, 1.5),
                   match_window: float = 0.05, min_mac: float = 0.8, criteria=None, clustering=None, progress=None,
                   **keywords) -> HorizonCheck:
    """Identify and select the record at ``block_rows`` times each factor, and match the modes.

    Parameters
    ----------
    y, u, fs, settings, **keywords
        As :func:`modaluq.identify` (``orders`` and ``n_blocks`` are chosen per horizon unless
        given). ``block_rows`` is the reference horizon (default: the automatic choice for the
        band, docs/settings.md).
    factors : sequence of float
        Multiples of the reference horizon to try (default 0.75, 1, 1.5); 1 is added if absent.
    match_window : float
        Largest relative frequency difference for a mode to be found again (fraction).
    min_mac : float
        Smallest MAC between the shapes of the mode and its match.
    criteria, clustering
        :class:`~modaluq.StabilityCriteria` and :class:`~modaluq.ClusteringSettings` (defaults).
    progress : callable, optional
        Called with a sentence before each identification.

    Returns
    -------
    HorizonCheck
    """
    factors = tuple(check_real("factors", f, low=0, low_open=True) for f in np.atleast_1d(factors))
    if 1.0 not in factors:
        factors = factors + (1.0,)
    check_real("match_window", match_window, low=0, low_open=True)
    check_real("min_mac", min_mac, low=0, high=1)
    s = make_settings(settings, keywords, function="check_horizons")
    ref = identify(y, u, fs=fs, settings=s)
    p_ref = int(ref.settings["block_rows"])
    horizons = sorted({max(2, int(round(p_ref * f))) for f in factors})
    selections = {}
    for p in horizons:
        if progress is not None:
            progress(f"block_rows = {p}")
        if p == p_ref:
            r = ref
        else:
            with warnings.catch_warnings():  # the reference run's warnings are the ones that matter
                warnings.simplefilter("ignore", ModalUQWarning)
                r = identify(y, u, fs=fs, settings=s.replace(block_rows=p))
        selections[p] = select_modes(stabilization_diagram(r, criteria), clustering)
    base = selections[p_ref]
    n = base.n_modes
    f = np.full((n, len(horizons)), np.nan)
    xi = np.full((n, len(horizons)), np.nan)
    for j, p in enumerate(horizons):
        other = selections[p]
        if other.n_modes == 0:
            continue
        mac = modal_assurance_criterion(base.mode_shape, other.mode_shape)
        for i in range(n):
            rel = np.abs(other.frequency_hz - base.frequency_hz[i]) / base.frequency_hz[i]
            ok = (rel <= match_window) & (mac[i] >= min_mac)
            if ok.any():
                k = int(np.flatnonzero(ok)[np.argmin(rel[ok])])
                f[i, j], xi[i, j] = other.frequency_hz[k], other.damping_ratio[k]
    return HorizonCheck(block_rows=tuple(horizons), reference_block_rows=p_ref, selected=base,
                        frequency_hz=f, damping_ratio=xi, found=np.isfinite(f))
