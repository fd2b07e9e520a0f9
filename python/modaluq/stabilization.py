"""Stabilization diagram and automatic mode selection from one multi-order :class:`~modaluq.Result`.

The identification gives, at every model order n, a set of poles (frequency, damping ratio,
mode shape and their standard deviations). Physical modes show up at (almost) every order
with nearly the same parameters; spurious (noise, numerical) poles come and go. This module

1. **judges every pole** (:func:`stabilization_diagram`), first on its own (:class:`StabilityCriteria`:
   damping ratio in ``[min_damping_ratio, max_damping_ratio]``, coefficient of variation
   ``frequency_std / frequency_hz`` at most ``max_frequency_cov``), then against its match at the
   previous identified order (relative frequency change, relative damping change, MAC, and the
   frequency change measured in standard deviations, ``|Δf| <= k sqrt(σ1² + σ2²)``). Each pole
   gets a :class:`PoleStatus` and, unless stable, a ``reason`` saying which test failed and by
   how much;
2. **groups the stable poles into physical modes** (:func:`select_modes`) by agglomerative
   hierarchical clustering (:func:`scipy.cluster.hierarchy.linkage`, average linkage) on the
   distance ``|f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)``, cut at ``distance_threshold``;
   clusters with fewer than ``min_cluster_size`` members are dropped (and listed), and each
   remaining cluster is reported at one representative pole with its analytic standard
   deviations, next to the spread (sample standard deviation) of its members.

Everything is deterministic: no random initialisation, ties broken by order and index.

>>> import modaluq
>>> sim = modaluq.simulate(50_000, seed=2)
>>> result = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=21, orders=range(2, 61, 2))
>>> diagram = modaluq.stabilization_diagram(result)
>>> modes = diagram.select_modes()
>>> [round(float(f), 1) for f in modes.frequency_hz]
[1.9, 5.6, 8.7, 14.5, 15.8, 17.0]
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field, fields

import numpy as np

from .identification import _integer, _real

__all__ = [
    "ClusteringSettings",
    "Diagram",
    "PoleStatus",
    "SelectedModes",
    "StabilityCriteria",
    "modal_assurance_criterion",
    "output_spectrum_singular_values",
    "select_modes",
    "stabilization_diagram",
]


class PoleStatus(str, enum.Enum):
    """Outcome of the stability checks for one pole (a ``str``, so it prints and exports as text).

    STABLE
        Passes its own checks and every check against its match at the previous order.
    STABLE_FREQUENCY
        Frequency stable (relative change and, with uncertainty, the σ test), but the damping
        change or the MAC fails.
    UNSTABLE
        Lowest order, no acceptable pole at the previous order, or the frequency test fails.
    REJECTED
        Physically implausible (damping out of range) or too uncertain (σ_f / f too large);
        never compared and never selected.
    """

    STABLE = "stable"
    STABLE_FREQUENCY = "stable_frequency"
    UNSTABLE = "unstable"
    REJECTED = "rejected"

    def __str__(self) -> str:  # "stable", not "PoleStatus.STABLE"
        return self.value


# --------------------------------------------------------------------------- helpers


def modal_assurance_criterion(shape_a, shape_b) -> np.ndarray:
    """Modal assurance criterion between every column of ``shape_a`` and every column of ``shape_b``.

    ``MAC_ij = |a_iᴴ b_j|² / ((a_iᴴ a_i)(b_jᴴ b_j))``, between 0 (orthogonal) and 1 (collinear),
    invariant to the complex scaling of either shape.

    Parameters
    ----------
    shape_a : array_like, shape (n_outputs, m) or (n_outputs,)
        Mode shapes (complex or real) as columns.
    shape_b : array_like, shape (n_outputs, k) or (n_outputs,)

    Returns
    -------
    ndarray, shape (m, k)
        Dimensionless; a 1-D input counts as one column.

    Examples
    --------
    >>> modal_assurance_criterion([1, 2j], [[2], [4j]])
    array([[1.]])
    """
    a = np.asarray(shape_a)
    b = np.asarray(shape_b)
    a = a[:, None] if a.ndim == 1 else a
    b = b[:, None] if b.ndim == 1 else b
    if a.ndim != 2 or b.ndim != 2 or a.shape[0] != b.shape[0]:
        raise ValueError(f"shape_a and shape_b must have the same number of rows (outputs); "
                         f"got shapes {np.shape(shape_a)} and {np.shape(shape_b)}")
    cross = np.abs(a.conj().T @ b) ** 2
    na = np.real(np.sum(a.conj() * a, axis=0))
    nb = np.real(np.sum(b.conj() * b, axis=0))
    denom = np.outer(na, nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        mac = np.where(denom > 0, cross / np.where(denom > 0, denom, 1.0), 0.0)
    return np.clip(mac, 0.0, 1.0)


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %"


# --------------------------------------------------------------------------- criteria


@dataclass(frozen=True)
class StabilityCriteria:
    """Thresholds of the stabilization diagram (all dimensionless fractions unless stated).

    A pole is first checked on its own; failing any of these makes it ``REJECTED``:

    - ``damping_ratio < min_damping_ratio`` (default 0: negative damping is unstable, not a
      structural mode) or ``damping_ratio > max_damping_ratio`` (default 0.20 = 20 %: lightly
      damped structures rarely exceed a few percent; heavily damped poles are usually noise);
    - ``frequency_std / frequency_hz > max_frequency_cov`` (default 0.02 = 2 %; with the
      analytic σ of SSI-cov, a structural mode identified from a record of a few hundred
      periods typically has a coefficient of variation well below 1 %, spurious poles of
      several percent). Skipped when the result carries no uncertainty; a pole whose σ is not
      finite is rejected.

    The other poles are compared with the pole of the previous identified order that minimises
    ``|Δf| / f_prev + (1 - MAC)`` among that order's non-rejected poles within ``match_window``
    in frequency (default 0.05 = 5 %); with none there, the pole is ``UNSTABLE`` ("no match").
    It is

    - frequency stable when ``|Δf| / f_prev <= max_frequency_change`` (default 0.01 = 1 %) **and**,
      with uncertainty, ``|Δf| <= frequency_std_factor * sqrt(σ_f² + σ_f,prev²)`` (default
      k = 2: a change larger than twice the combined standard deviation is statistically
      significant at about 95 % even if the two estimates were independent, and estimates at
      consecutive orders from the same data are positively correlated, so the test is
      conservative towards keeping a pole). ``frequency_std_factor=None`` switches it off;
    - damping stable when ``|Δξ| / |ξ_prev| <= max_damping_change`` (default 0.10 = 10 %: damping
      ratios are far less precise than frequencies, so the 5 % often used makes physical poles
      flicker). With ``damping_std_factor=k`` (and uncertainty) instead when
      ``|Δξ| <= k * sqrt(σ_ξ² + σ_ξ,prev²)`` and ``|Δξ| / |ξ_prev| <= max_damping_change_with_std``
      (default 0.5, a loose backstop): a damping ratio with σ_ξ = 50 % of ξ moves by more than
      10 % between orders on noise alone. Not the default yet: without the fixed 10 % more
      spurious poles pass as stable, and the selection does not yet reject them by their σ
      (issue 12);
    - shape stable when ``MAC >= min_mac`` (default 0.98).

    ``STABLE`` needs all three; frequency alone gives ``STABLE_FREQUENCY``.

    Parameters
    ----------
    max_frequency_change : float
        Largest relative frequency change between consecutive orders (fraction).
    max_damping_change : float
        Largest relative damping-ratio change between consecutive orders (fraction).
    min_mac : float
        Smallest MAC between the shapes at consecutive orders (0..1).
    frequency_std_factor : float or None
        k of the σ test on the frequency change (dimensionless), or None to skip it.
    max_frequency_cov : float or None
        Largest coefficient of variation σ_f / f (fraction), or None to skip it.
    min_damping_ratio, max_damping_ratio : float
        Accepted range of the damping ratio (fraction, 0.02 = 2 %).
    damping_std_factor : float or None
        k of the σ test on the damping change (e.g. 2), or None (default) for the relative test.
    max_damping_change_with_std : float
        Backstop on the relative damping change when the σ test is used (fraction).
    match_window : float
        Largest relative frequency distance to a pole of the previous order that can be its match.
    """

    max_frequency_change: float = 0.01
    max_damping_change: float = 0.10
    min_mac: float = 0.98
    frequency_std_factor: float | None = 2.0
    max_frequency_cov: float | None = 0.02
    min_damping_ratio: float = 0.0
    max_damping_ratio: float = 0.20
    damping_std_factor: float | None = None
    max_damping_change_with_std: float = 0.5
    match_window: float = 0.05

    def __post_init__(self):
        _real("max_frequency_change", self.max_frequency_change, low=0)
        _real("max_damping_change", self.max_damping_change, low=0)
        _real("min_mac", self.min_mac, low=0, high=1)
        _real("frequency_std_factor", self.frequency_std_factor, low=0, low_open=True, allow_none=True)
        _real("max_frequency_cov", self.max_frequency_cov, low=0, low_open=True, allow_none=True)
        _real("damping_std_factor", self.damping_std_factor, low=0, low_open=True, allow_none=True)
        _real("max_damping_change_with_std", self.max_damping_change_with_std, low=0)
        _real("match_window", self.match_window, low=0, low_open=True)
        lo = _real("min_damping_ratio", self.min_damping_ratio, low=-1, high=1)
        hi = _real("max_damping_ratio", self.max_damping_ratio, low=-1, high=1)
        if hi <= lo:
            raise ValueError(f"max_damping_ratio must be > min_damping_ratio ({lo}); got {hi}")

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class ClusteringSettings:
    """How :func:`select_modes` groups poles into modes.

    Parameters
    ----------
    distance_threshold : float
        Cut height of the dendrogram on the distance ``|f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)``
        (dimensionless; default 0.02, e.g. 1 % in frequency plus MAC 0.99). Poles of one cluster
        are on average closer than this to each other (average linkage).
    min_cluster_size : int or None
        Clusters with fewer members (after keeping one pole per order) are dropped. Default
        (None): ``min_cluster_fraction`` of the identified orders from the lowest order that holds
        a clustered pole upwards, rounded up, and at least 3.
    min_cluster_fraction : float
        Used when ``min_cluster_size`` is None (default 0.25): a physical mode should be stable
        over at least a quarter of the orders that can hold it. Spurious poles seldom stay
        stable over more than a few consecutive orders, while a physical mode can lose
        stability over a range of orders where a spurious pole splits it (seen with few sensors
        at orders far above the true one), so a higher fraction drops real modes.
    statuses : tuple of PoleStatus
        Which poles are clustered (default only ``STABLE``).
    linkage : str
        Linkage method of :func:`scipy.cluster.hierarchy.linkage` (default ``"average"``;
        ``"single"`` chains neighbouring poles, ``"complete"`` is stricter).
    """

    distance_threshold: float = 0.02
    min_cluster_size: int | None = None
    min_cluster_fraction: float = 0.25
    statuses: tuple = (PoleStatus.STABLE,)
    linkage: str = "average"

    def __post_init__(self):
        _real("distance_threshold", self.distance_threshold, low=0, low_open=True)
        if self.min_cluster_size is not None:
            _integer("min_cluster_size", self.min_cluster_size, minimum=1)
        _real("min_cluster_fraction", self.min_cluster_fraction, low=0, high=1, low_open=True)
        if isinstance(self.statuses, (str, PoleStatus)):
            object.__setattr__(self, "statuses", (self.statuses,))
        try:
            object.__setattr__(self, "statuses", tuple(PoleStatus(s) for s in self.statuses))
        except (TypeError, ValueError):
            raise ValueError(f"statuses must hold PoleStatus values {[s.value for s in PoleStatus]}; "
                             f"got {self.statuses!r}") from None
        if not self.statuses:
            raise ValueError("statuses must not be empty")
        if self.linkage not in ("single", "complete", "average", "weighted"):
            raise ValueError(f"linkage must be 'single', 'complete', 'average' or 'weighted'; got {self.linkage!r}")

    def to_dict(self) -> dict:
        return {"distance_threshold": self.distance_threshold, "min_cluster_size": self.min_cluster_size,
                "min_cluster_fraction": self.min_cluster_fraction,
                "statuses": [s.value for s in self.statuses], "linkage": self.linkage}


# --------------------------------------------------------------------------- diagram


@dataclass(frozen=True, repr=False)
class Diagram:
    """Every pole of every order of one identification, with its stability status.

    One entry per pole in the flat arrays below (ordered by model order, then frequency);
    ``mode_shape*`` have one column per pole. Standard deviations are ``NaN`` when the
    identification ran without uncertainty. Comparison columns (``matched_pole`` ...) refer to
    the matched pole at the previous order and are ``-1`` / ``NaN`` when there is none.
    """

    order: np.ndarray                 #: (n_poles,) model order n of each pole
    frequency_hz: np.ndarray          #: (n_poles,) Hz
    damping_ratio: np.ndarray         #: (n_poles,) fraction
    frequency_std: np.ndarray         #: (n_poles,) Hz (NaN without uncertainty)
    damping_std: np.ndarray           #: (n_poles,) fraction
    mode_shape: np.ndarray            #: (n_outputs, n_poles) complex, largest component 1
    mode_shape_std_real: np.ndarray   #: (n_outputs, n_poles)
    mode_shape_std_imag: np.ndarray   #: (n_outputs, n_poles)
    status: np.ndarray                #: (n_poles,) object array of PoleStatus
    reason: np.ndarray                #: (n_poles,) str, '' for stable poles
    matched_pole: np.ndarray          #: (n_poles,) index of the matched pole at the previous order, -1 if none
    frequency_change: np.ndarray      #: (n_poles,) |Δf| / f_prev, fraction
    damping_change: np.ndarray        #: (n_poles,) |Δξ| / |ξ_prev|, fraction
    mac: np.ndarray                   #: (n_poles,) MAC with the matched pole
    frequency_change_std: np.ndarray  #: (n_poles,) |Δf| / sqrt(σ_f² + σ_f,prev²), dimensionless
    close_singular_values: np.ndarray  #: (n_poles,) bool, the pole's order cuts close singular values
    #: (n_poles,) bool, no first-order σ: the pole depends on noise directions (docs/uq-math.md §5.5)
    noise_coupled: np.ndarray
    orders: tuple                     #: identified orders, ascending
    fs: float                         #: sampling frequency, Hz
    output_names: tuple               #: one name per output channel
    criteria: StabilityCriteria = field(default_factory=StabilityCriteria)
    has_uncertainty: bool = True
    result_settings: dict = field(default_factory=dict)  #: ``Result.settings`` of the identification

    @property
    def n_poles(self) -> int:
        return int(self.order.size)

    def __len__(self) -> int:
        return self.n_poles

    @property
    def n_outputs(self) -> int:
        return int(self.mode_shape.shape[0])

    @property
    def close_singular_value_orders(self) -> tuple:
        """Orders that cut the singular values inside a cluster (their σ are not meaningful)."""
        return tuple(n for n in self.orders if np.any(self.close_singular_values[self.order == n]))

    def count(self, status) -> int:
        """Number of poles with ``status`` (a :class:`PoleStatus` or its string value)."""
        s = PoleStatus(status)
        return int(sum(1 for x in self.status if x is s))

    def is_status(self, status) -> np.ndarray:
        """Boolean mask of the poles with ``status``."""
        s = PoleStatus(status)
        return np.fromiter((x is s for x in self.status), dtype=bool, count=self.n_poles)

    def to_dataframe(self):
        """One row per pole: order, frequency, damping, their σ, status, reason, comparison values.

        Mode shapes are in columns ``mode_shape_<channel>`` (complex).
        """
        import pandas as pd

        data = {
            "order": self.order,
            "frequency_hz": self.frequency_hz,
            "damping_ratio": self.damping_ratio,
            "frequency_std": self.frequency_std,
            "damping_std": self.damping_std,
            "status": [s.value for s in self.status],
            "reason": self.reason,
            "matched_pole": self.matched_pole,
            "frequency_change": self.frequency_change,
            "damping_change": self.damping_change,
            "mac": self.mac,
            "frequency_change_std": self.frequency_change_std,
            "close_singular_values": self.close_singular_values,
            "noise_coupled": self.noise_coupled,
        }
        for k, name in enumerate(self.output_names):
            data[f"mode_shape_{name}"] = self.mode_shape[k]
        return pd.DataFrame(data, index=pd.RangeIndex(self.n_poles, name="pole"))

    def to_xarray(self, selected: "SelectedModes | None" = None, attrs: dict | None = None):
        """The whole diagram (and optionally the selected modes) as an :class:`xarray.Dataset`.

        Dimensions ``pole`` and ``channel`` (and ``mode`` with ``selected``, whose variables are
        prefixed ``selected_``); mode shapes are split into ``*_real`` / ``*_imag`` variables so
        that the dataset writes to NetCDF-4.
        ``attrs`` (e.g. a provenance stamp) become global attributes; nested values are stored
        as JSON strings.
        """
        import json

        from .export import require

        xr = require("xarray", "Diagram.to_xarray")

        pole_vars = {
            "order": (("pole",), self.order, {"long_name": "model order"}),
            "frequency_hz": (("pole",), self.frequency_hz, {"units": "Hz"}),
            "damping_ratio": (("pole",), self.damping_ratio, {"units": "1", "long_name": "damping ratio (fraction)"}),
            "frequency_std": (("pole",), self.frequency_std, {"units": "Hz"}),
            "damping_std": (("pole",), self.damping_std, {"units": "1"}),
            "status": (("pole",), np.array([s.value for s in self.status], dtype=object), {}),
            "reason": (("pole",), np.asarray(self.reason, dtype=object), {}),
            "matched_pole": (("pole",), self.matched_pole,
                             {"long_name": "index of the matched pole at the previous order (-1: none)"}),
            "frequency_change": (("pole",), self.frequency_change, {"units": "1"}),
            "damping_change": (("pole",), self.damping_change, {"units": "1"}),
            "mac": (("pole",), self.mac, {"units": "1"}),
            "frequency_change_std": (("pole",), self.frequency_change_std, {"units": "1"}),
            "close_singular_values": (("pole",), self.close_singular_values.astype(np.int8), {}),
            "noise_coupled": (("pole",), self.noise_coupled.astype(np.int8),
                              {"long_name": "sigma not first-order meaningful: pole coupled to noise directions"}),
            "mode_shape_real": (("channel", "pole"), self.mode_shape.real, {}),
            "mode_shape_imag": (("channel", "pole"), self.mode_shape.imag, {}),
            "mode_shape_std_real": (("channel", "pole"), self.mode_shape_std_real, {}),
            "mode_shape_std_imag": (("channel", "pole"), self.mode_shape_std_imag, {}),
        }
        coords = {"pole": np.arange(self.n_poles), "channel": list(self.output_names)}
        if selected is not None:
            sel = selected
            pole_vars["mode_of_pole"] = (("pole",), sel.mode_of_pole,
                                         {"long_name": "selected mode of each pole (-1: none)"})
            for name in ("frequency_hz", "damping_ratio", "frequency_std", "damping_std",
                         "frequency_spread", "damping_spread", "representative_order",
                         "representative_pole", "n_poles", "order_min", "order_max", "min_mac"):
                pole_vars[f"selected_{name}"] = (("mode",), getattr(sel, name), {})
            for name, values in (("mode_shape_real", sel.mode_shape.real), ("mode_shape_imag", sel.mode_shape.imag),
                                 ("mode_shape_std_real", sel.mode_shape_std_real),
                                 ("mode_shape_std_imag", sel.mode_shape_std_imag),
                                 ("mode_shape_spread_real", sel.mode_shape_spread_real),
                                 ("mode_shape_spread_imag", sel.mode_shape_spread_imag)):
                pole_vars[f"selected_{name}"] = (("channel", "mode"), values, {})
            coords["mode"] = np.arange(sel.n_modes)
        ds = xr.Dataset({k: xr.Variable(d, v, a) for k, (d, v, a) in pole_vars.items()}, coords=coords)
        gattrs = {"fs_hz": self.fs, "criteria": json.dumps(self.criteria.to_dict()),
                  "identification_settings": json.dumps(self.result_settings, default=str)}
        if selected is not None:
            gattrs["clustering"] = json.dumps(selected.settings.to_dict())
        for k, v in (attrs or {}).items():
            gattrs[k] = v if isinstance(v, (str, int, float)) else json.dumps(v, default=str)
        ds.attrs.update(gattrs)
        return ds

    def select_modes(self, settings: ClusteringSettings | None = None, **kwargs) -> "SelectedModes":
        """Shorthand for :func:`select_modes` (``kwargs`` are fields of :class:`ClusteringSettings`)."""
        return select_modes(self, settings, **kwargs)

    def plot(self, ax=None, *, y=None, spectrum=None, selected=None, show_rejected=True, nperseg=None,
             frequency_range=None):
        """Draw the diagram (poles with ±σ_f bars over the output spectrum when ``y`` is given).

        See :func:`modaluq.plot.stabilization_diagram` for the parameters. Returns the Figure.
        """
        from .plot import stabilization_diagram as _plot

        return _plot(self, ax=ax, y=y, spectrum=spectrum, selected=selected, show_rejected=show_rejected,
                     nperseg=nperseg, frequency_range=frequency_range)

    def __repr__(self) -> str:
        counts = ", ".join(f"{s.value}={self.count(s)}" for s in PoleStatus)
        return (f"Diagram(orders {self.orders[0]}..{self.orders[-1]} ({len(self.orders)}), "
                f"{self.n_poles} poles: {counts})")


def _pole_checks(f, xi, sf, c: StabilityCriteria, has_std: bool) -> list:
    reasons = []
    if xi < c.min_damping_ratio:
        reasons.append(f"damping ratio {_pct(xi)} < {_pct(c.min_damping_ratio)}")
    if xi > c.max_damping_ratio:
        reasons.append(f"damping ratio {_pct(xi)} > {_pct(c.max_damping_ratio)}")
    if has_std and c.max_frequency_cov is not None:
        if not np.isfinite(sf):
            reasons.append("frequency std not finite")
        elif sf / f > c.max_frequency_cov:
            reasons.append(f"frequency std/f {_pct(sf / f)} > {_pct(c.max_frequency_cov)}")
    return reasons


def stabilization_diagram(result, criteria: StabilityCriteria | None = None, *,
                          output_names=None, **kwargs) -> Diagram:
    """Judge every pole of a multi-order identification (see :class:`StabilityCriteria`).

    Parameters
    ----------
    result : modaluq.Result
        From :func:`modaluq.identify` with several orders (``orders=range(2, 61, 2)``...).
    criteria : StabilityCriteria, optional
        Thresholds; default ``StabilityCriteria()``. Alternatively pass its fields as keyword
        arguments (``max_frequency_change=0.02``...).
    output_names : sequence of str, optional
        One name per output channel (default ``y0, y1, ...``), used in tables, plots and exports.

    Returns
    -------
    Diagram
        Every pole with its :class:`PoleStatus` and, for the others than stable, the reason.
    """
    from .identification import Result

    if not isinstance(result, Result):
        raise TypeError(f"result must be a modaluq.Result (from modaluq.identify); got {type(result).__name__}")
    if criteria is None:
        criteria = StabilityCriteria(**kwargs)
    elif kwargs:
        raise TypeError("pass either criteria= or its fields as keyword arguments, not both")
    elif not isinstance(criteria, StabilityCriteria):
        raise TypeError(f"criteria must be a StabilityCriteria; got {type(criteria).__name__}")
    n_out = int(result.n_outputs)
    if output_names is None:
        names = tuple(f"y{k}" for k in range(n_out))
    else:
        names = tuple(str(s) for s in output_names)
        if len(names) != n_out:
            raise ValueError(f"output_names must have {n_out} entries (one per output); got {len(names)}")
    has_std = all(m.has_uncertainty for m in result.modes)
    c = criteria
    k_std = c.frequency_std_factor if has_std else None

    cols = {k: [] for k in ("order", "f", "xi", "sf", "sxi", "close", "coupled")}
    shapes, shapes_sr, shapes_si = [], [], []
    for m in result.modes:
        n = m.n_modes
        cols["order"].append(np.full(n, m.order, dtype=np.int64))
        cols["f"].append(np.asarray(m.frequency_hz, float))
        cols["xi"].append(np.asarray(m.damping_ratio, float))
        nan = np.full(n, np.nan)
        cols["sf"].append(np.asarray(m.frequency_std, float) if m.has_uncertainty else nan)
        cols["sxi"].append(np.asarray(m.damping_std, float) if m.has_uncertainty else nan)
        cols["close"].append(np.full(n, bool(m.close_singular_values)))
        coupled = getattr(m, "noise_coupled", None)
        cols["coupled"].append(np.zeros(n, bool) if coupled is None else np.asarray(coupled, bool).reshape(n))
        shapes.append(np.asarray(m.mode_shape, complex).reshape(n_out, n))
        nan2 = np.full((n_out, n), np.nan)
        shapes_sr.append(np.asarray(m.mode_shape_std_real, float).reshape(n_out, n) if m.has_uncertainty else nan2)
        shapes_si.append(np.asarray(m.mode_shape_std_imag, float).reshape(n_out, n) if m.has_uncertainty else nan2)
    order = np.concatenate(cols["order"])
    f = np.concatenate(cols["f"])
    xi = np.concatenate(cols["xi"])
    sf = np.concatenate(cols["sf"])
    sxi = np.concatenate(cols["sxi"])
    close = np.concatenate(cols["close"])
    coupled = np.concatenate(cols["coupled"])
    shape = np.concatenate(shapes, axis=1)
    n_poles = f.size

    status = np.empty(n_poles, dtype=object)
    reason = np.empty(n_poles, dtype=object)
    matched = np.full(n_poles, -1, dtype=np.int64)
    df = np.full(n_poles, np.nan)
    dxi = np.full(n_poles, np.nan)
    mac = np.full(n_poles, np.nan)
    dz = np.full(n_poles, np.nan)

    # The band of interest given to identify (frequency_range): poles outside it are rejected.
    band = result.settings.get("frequency_range") if isinstance(result.settings, dict) else None
    valid = np.zeros(n_poles, dtype=bool)
    for i in range(n_poles):
        r = _pole_checks(f[i], xi[i], sf[i], c, has_std)
        if band is not None and not band[0] <= f[i] <= band[1]:
            r = [f"outside the band {band[0]:g}-{band[1]:g} Hz"] + r
        if r:
            status[i], reason[i] = PoleStatus.REJECTED, "; ".join(r)
        valid[i] = not r

    orders = tuple(int(m.order) for m in result.modes)
    for j, n in enumerate(orders):
        cur = np.flatnonzero((order == n) & valid)
        if j == 0:
            for i in cur:
                status[i], reason[i] = PoleStatus.UNSTABLE, "lowest order: no previous order to compare"
            continue
        prev = np.flatnonzero((order == orders[j - 1]) & valid)
        if prev.size == 0:
            for i in cur:
                status[i], reason[i] = PoleStatus.UNSTABLE, f"no accepted pole at the previous order {orders[j - 1]}"
            continue
        if cur.size == 0:
            continue
        mac_cp = modal_assurance_criterion(shape[:, cur], shape[:, prev])
        rel_cp = np.abs(f[cur][:, None] - f[prev][None, :]) / f[prev][None, :]
        cost = np.where(rel_cp <= c.match_window, rel_cp + (1.0 - mac_cp), np.inf)
        best = np.argmin(cost, axis=1)  # first minimum: deterministic
        for a, i in enumerate(cur):
            if not np.isfinite(cost[a, best[a]]):  # nothing of the previous order nearby
                status[i] = PoleStatus.UNSTABLE
                reason[i] = (f"no match: no pole within {_pct(c.match_window)} in frequency at the previous "
                             f"order {orders[j - 1]}")
                continue
            p = prev[best[a]]
            matched[i] = p
            df[i] = rel_cp[a, best[a]]
            mac[i] = mac_cp[a, best[a]]
            dxi[i] = abs(xi[i] - xi[p]) / abs(xi[p]) if xi[p] != 0 else (0.0 if xi[i] == 0 else np.inf)
            why = []
            if df[i] > c.max_frequency_change:
                why.append(f"frequency change {_pct(df[i])} > {_pct(c.max_frequency_change)}")
            if k_std is not None:
                comb = math.hypot(sf[i], sf[p])
                dz[i] = abs(f[i] - f[p]) / comb if comb > 0 else np.inf
                if dz[i] > k_std:
                    why.append(f"frequency change {abs(f[i] - f[p]):.3g} Hz > {k_std:g} x combined std "
                               f"{comb:.3g} Hz")
            if why:
                status[i] = PoleStatus.UNSTABLE
            else:
                k_xi = c.damping_std_factor if has_std else None
                comb_xi = math.hypot(sxi[i], sxi[p]) if k_xi is not None else np.nan
                if k_xi is not None and np.isfinite(comb_xi):
                    if abs(xi[i] - xi[p]) > k_xi * comb_xi:
                        why.append(f"damping change {abs(xi[i] - xi[p]):.3g} > {k_xi:g} x combined std {comb_xi:.3g}")
                    elif dxi[i] > c.max_damping_change_with_std:
                        why.append(f"damping change {_pct(dxi[i])} > {_pct(c.max_damping_change_with_std)}")
                elif dxi[i] > c.max_damping_change:
                    why.append(f"damping change {_pct(dxi[i])} > {_pct(c.max_damping_change)}")
                if mac[i] < c.min_mac:
                    why.append(f"MAC {mac[i]:.4f} < {c.min_mac:g}")
                status[i] = PoleStatus.STABLE_FREQUENCY if why else PoleStatus.STABLE
            reason[i] = ("; ".join(why) + f" (vs order {orders[j - 1]})") if why else ""

    return Diagram(
        order=order, frequency_hz=f, damping_ratio=xi, frequency_std=sf, damping_std=sxi,
        mode_shape=shape, mode_shape_std_real=np.concatenate(shapes_sr, axis=1),
        mode_shape_std_imag=np.concatenate(shapes_si, axis=1), status=status,
        reason=reason.astype(str) if n_poles else np.array([], dtype=str), matched_pole=matched,
        frequency_change=df, damping_change=dxi, mac=mac, frequency_change_std=dz,
        close_singular_values=close, noise_coupled=coupled, orders=orders, fs=float(result.fs), output_names=names,
        criteria=c, has_uncertainty=has_std, result_settings=dict(result.settings),
    )


# --------------------------------------------------------------------------- mode selection


@dataclass(frozen=True, repr=False)
class SelectedModes:
    """Physical modes chosen automatically from a :class:`Diagram`, sorted by frequency.

    Each mode is one cluster of poles. Its ``frequency_hz``, ``damping_ratio``, ``mode_shape``
    and their ``*_std`` are those of one **representative** pole (analytic, delta-method σ at
    ``representative_order``); the ``*_spread`` fields are the sample standard deviations
    (ddof=1) across the cluster's members, a measure of the order-to-order scatter shown beside
    the analytic σ (0 for a single member).
    """

    frequency_hz: np.ndarray           #: (n_modes,) Hz
    damping_ratio: np.ndarray          #: (n_modes,) fraction
    mode_shape: np.ndarray             #: (n_outputs, n_modes) complex, largest component 1
    frequency_std: np.ndarray          #: (n_modes,) Hz, analytic (NaN without uncertainty)
    damping_std: np.ndarray            #: (n_modes,) fraction, analytic
    mode_shape_std_real: np.ndarray    #: (n_outputs, n_modes)
    mode_shape_std_imag: np.ndarray    #: (n_outputs, n_modes)
    frequency_spread: np.ndarray       #: (n_modes,) Hz, std across the cluster
    damping_spread: np.ndarray         #: (n_modes,) fraction, std across the cluster
    mode_shape_spread_real: np.ndarray  #: (n_outputs, n_modes), std across the cluster
    mode_shape_spread_imag: np.ndarray  #: (n_outputs, n_modes)
    min_mac: np.ndarray                #: (n_modes,) smallest MAC between representative and a member
    representative_order: np.ndarray   #: (n_modes,) model order of the representative pole
    representative_pole: np.ndarray    #: (n_modes,) index of the representative in the diagram
    n_poles: np.ndarray                #: (n_modes,) members of the cluster
    order_min: np.ndarray              #: (n_modes,) lowest order in the cluster
    order_max: np.ndarray              #: (n_modes,) highest order in the cluster
    members: tuple                     #: per mode, the diagram indices of its poles
    mode_of_pole: np.ndarray           #: (diagram.n_poles,) mode index of each pole, -1 if none
    dropped_frequency_hz: np.ndarray   #: median frequency of each dropped (too small) cluster, Hz
    dropped_n_poles: np.ndarray        #: size of each dropped cluster
    min_cluster_size: int              #: the size threshold actually applied
    output_names: tuple
    settings: ClusteringSettings = field(default_factory=ClusteringSettings)
    has_uncertainty: bool = True

    @property
    def n_modes(self) -> int:
        return int(self.frequency_hz.size)

    def __len__(self) -> int:
        return self.n_modes

    def to_dataframe(self):
        """One row per mode: f, σ_f, spread, ξ, σ_ξ, spread, cluster size and orders."""
        import pandas as pd

        data = {
            "frequency_hz": self.frequency_hz, "frequency_std": self.frequency_std,
            "frequency_spread": self.frequency_spread,
            "damping_ratio": self.damping_ratio, "damping_std": self.damping_std,
            "damping_spread": self.damping_spread,
            "representative_order": self.representative_order, "n_poles": self.n_poles,
            "order_min": self.order_min, "order_max": self.order_max, "min_mac": self.min_mac,
        }
        for k, name in enumerate(self.output_names):
            data[f"mode_shape_{name}_real"] = self.mode_shape[k].real
            data[f"mode_shape_{name}_imag"] = self.mode_shape[k].imag
            data[f"mode_shape_{name}_std_real"] = self.mode_shape_std_real[k]
            data[f"mode_shape_{name}_std_imag"] = self.mode_shape_std_imag[k]
        return pd.DataFrame(data, index=pd.RangeIndex(self.n_modes, name="mode"))

    def to_dict(self) -> dict:
        """Plain-Python (JSON-ready) description: one dict per mode, shapes per channel."""
        def num(x):
            x = float(x)
            return x if math.isfinite(x) else None

        modes = []
        for i in range(self.n_modes):
            shape = {}
            for k, name in enumerate(self.output_names):
                shape[name] = {
                    "real": num(self.mode_shape[k, i].real), "imag": num(self.mode_shape[k, i].imag),
                    "std_real": num(self.mode_shape_std_real[k, i]),
                    "std_imag": num(self.mode_shape_std_imag[k, i]),
                    "spread_real": num(self.mode_shape_spread_real[k, i]),
                    "spread_imag": num(self.mode_shape_spread_imag[k, i]),
                }
            modes.append({
                "mode": i + 1,
                "frequency_hz": num(self.frequency_hz[i]), "frequency_std": num(self.frequency_std[i]),
                "frequency_spread": num(self.frequency_spread[i]),
                "damping_ratio": num(self.damping_ratio[i]), "damping_std": num(self.damping_std[i]),
                "damping_spread": num(self.damping_spread[i]),
                "representative_order": int(self.representative_order[i]),
                "n_poles": int(self.n_poles[i]), "order_min": int(self.order_min[i]),
                "order_max": int(self.order_max[i]), "min_mac": num(self.min_mac[i]),
                "mode_shape": shape,
            })
        return {
            "modes": modes,
            "dropped_clusters": [{"frequency_hz": num(f), "n_poles": int(n)}
                                 for f, n in zip(self.dropped_frequency_hz, self.dropped_n_poles)],
            "min_cluster_size": int(self.min_cluster_size),
            "clustering": self.settings.to_dict(),
        }

    def table(self) -> str:
        """Plain-text table: f and ξ with their analytic σ and the spread across the cluster."""
        head = (f"{'mode':>4}  {'f [Hz]':>9}  {'std f':>8}  {'spread f':>8}  {'xi [%]':>7}  "
                f"{'std xi':>7}  {'spread xi':>9}  {'order':>5}  {'poles':>5}")
        def cell(x, width, digits):
            return f"{x:>{width}.{digits}f}" if np.isfinite(x) else f"{'-':>{width}}"

        lines = [head]
        for i in range(self.n_modes):
            lines.append(
                f"{i + 1:>4}  {self.frequency_hz[i]:>9.4f}  {cell(self.frequency_std[i], 8, 4)}  "
                f"{cell(self.frequency_spread[i], 8, 4)}  {100 * self.damping_ratio[i]:>7.3f}  "
                f"{cell(100 * self.damping_std[i], 7, 3)}  {cell(100 * self.damping_spread[i], 9, 3)}  "
                f"{int(self.representative_order[i]):>5}  {int(self.n_poles[i]):>5}")
        return "\n".join(lines)

    def __str__(self) -> str:
        s = f"{self.n_modes} modes (std: analytic, median over the cluster; spread: across the cluster)\n"
        s += self.table()
        if self.dropped_n_poles.size:
            s += (f"\n{self.dropped_n_poles.size} cluster(s) with fewer than {self.min_cluster_size} "
                  "poles dropped")
        return s

    def __repr__(self) -> str:
        f = np.array2string(self.frequency_hz, precision=3, separator=", ")
        return f"SelectedModes(n_modes={self.n_modes}, frequency_hz={f})"

    def plot(self, fig=None, *, channel_positions=None):
        """Mode shapes with ±σ error bars; see :func:`modaluq.plot.mode_shapes`. Returns the Figure."""
        from .plot import mode_shapes

        return mode_shapes(self, fig=fig, channel_positions=channel_positions)


def _default_min_cluster_size(diagram: Diagram, in_set: np.ndarray, fraction: float) -> int:
    if not in_set.any():
        return 3
    first = int(diagram.order[in_set].min())
    n_after = sum(1 for n in diagram.orders if n >= first)
    return max(3, int(math.ceil(fraction * n_after - 1e-9)))


def select_modes(diagram: Diagram, settings: ClusteringSettings | None = None, **kwargs) -> SelectedModes:
    """Group the stable poles of a diagram into physical modes (deterministic).

    Method:

    1. take the poles whose status is in ``settings.statuses`` (default: ``STABLE``);
    2. distance ``d_ij = |f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)`` between every pair;
    3. agglomerative clustering (:func:`scipy.cluster.hierarchy.linkage`, ``settings.linkage``)
       cut at ``settings.distance_threshold`` (:func:`~scipy.cluster.hierarchy.fcluster`,
       criterion ``"distance"``);
    4. a physical mode appears once per order: when a cluster holds several poles of one order
       (a mode doubled by a spurious twin), keep the one nearest to the cluster's median
       frequency. (Penalising same-order pairs in the distance instead would split such a mode
       into two clusters.)
    5. drop clusters with fewer than ``min_cluster_size`` members (reported in
       ``dropped_frequency_hz`` / ``dropped_n_poles``);
    6. the representative of a cluster is its member nearest to the cluster's median frequency
       among the members at orders that do **not** cut close singular values (whose σ are
       meaningful), or among all members when every member's order does; ties go to the higher
       order. Its frequency, damping ratio and shape are reported; the ``frequency_std`` and
       ``damping_std`` reported are the **median over the cluster's reliable poles** (not at
       a close cut, not noise-coupled), so that they do not depend on the order the mode is
       read at; the ``*_spread`` beside them is how much the estimate moves with the order.

    Noise-coupled poles (``Diagram.noise_coupled``, docs/uq-math.md §5.5) are clustered (a weak
    physical mode below the noise floor has them at every order) but never give the σ.

    Parameters
    ----------
    diagram : Diagram
        From :func:`stabilization_diagram`.
    settings : ClusteringSettings, optional
        Or its fields as keyword arguments (``distance_threshold=0.03`` ...).

    Returns
    -------
    SelectedModes
        Sorted by frequency; empty when no pole qualifies.
    """
    import scipy.cluster.hierarchy as sch
    from scipy.spatial.distance import squareform

    if not isinstance(diagram, Diagram):
        raise TypeError(f"diagram must be a Diagram (from stabilization_diagram); got {type(diagram).__name__}")
    if settings is None:
        settings = ClusteringSettings(**kwargs)
    elif kwargs:
        raise TypeError("pass either settings= or its fields as keyword arguments, not both")
    elif not isinstance(settings, ClusteringSettings):
        raise TypeError(f"settings must be a ClusteringSettings; got {type(settings).__name__}")

    in_set = np.zeros(diagram.n_poles, dtype=bool)
    for s in settings.statuses:
        in_set |= diagram.is_status(s)
    min_size = settings.min_cluster_size or _default_min_cluster_size(diagram, in_set,
                                                                     settings.min_cluster_fraction)
    idx = np.flatnonzero(in_set)
    f, xi, order = diagram.frequency_hz, diagram.damping_ratio, diagram.order
    shape = diagram.mode_shape

    clusters = []
    if idx.size == 1:
        clusters = [idx]
    elif idx.size > 1:
        fi = f[idx]
        dist = np.abs(fi[:, None] - fi[None, :]) / np.maximum(fi[:, None], fi[None, :])
        dist += 1.0 - modal_assurance_criterion(shape[:, idx], shape[:, idx])
        np.fill_diagonal(dist, 0.0)
        dist = 0.5 * (dist + dist.T)
        z = sch.linkage(squareform(dist, checks=False), method=settings.linkage)
        labels = sch.fcluster(z, t=settings.distance_threshold, criterion="distance")
        for lab in np.unique(labels):
            clusters.append(idx[labels == lab])

    kept, dropped = [], []
    for members in clusters:
        med = np.median(f[members])
        # one pole per order: the one nearest to the median frequency (ties: lower index)
        keep = []
        for n in np.unique(order[members]):
            at_n = members[order[members] == n]
            keep.append(at_n[np.argmin(np.abs(f[at_n] - med))])
        members = np.sort(np.asarray(keep, dtype=np.int64))
        if members.size < min_size:
            dropped.append((float(np.median(f[members])), members.size))
        else:
            kept.append(members)

    kept.sort(key=lambda m: float(np.median(f[m])))
    dropped.sort()
    n_out = diagram.n_outputs
    n_modes = len(kept)
    rep = np.zeros(n_modes, dtype=np.int64)
    f_spread = np.zeros(n_modes)
    xi_spread = np.zeros(n_modes)
    sh_spread_r = np.zeros((n_out, n_modes))
    sh_spread_i = np.zeros((n_out, n_modes))
    min_mac = np.zeros(n_modes)
    sf_med = np.full(n_modes, np.nan)
    sxi_med = np.full(n_modes, np.nan)
    mode_of_pole = np.full(diagram.n_poles, -1, dtype=np.int64)
    for k, members in enumerate(kept):
        mode_of_pole[members] = k
        med = np.median(f[members])
        # the representative's σ is read from it: not at a cut inside a cluster, not noise-coupled
        candidates = members[~(diagram.close_singular_values[members] | diagram.noise_coupled[members])]
        if candidates.size == 0:
            candidates = members
        # nearest to the median; ties -> higher order (candidates ascend in order, take last)
        gap = np.abs(f[candidates] - med)
        rep[k] = candidates[np.flatnonzero(gap == gap.min())[-1]]
        # σ robust to the order it is read at: the median over the cluster's reliable poles
        # (the representative's own σ is that of one order, which above the true order varies)
        reliable = members[~(diagram.close_singular_values[members] | diagram.noise_coupled[members])
                           & np.isfinite(diagram.frequency_std[members])]
        if reliable.size:
            sf_med[k] = np.median(diagram.frequency_std[reliable])
            sxi_med[k] = np.median(diagram.damping_std[reliable])
        else:
            sf_med[k], sxi_med[k] = diagram.frequency_std[rep[k]], diagram.damping_std[rep[k]]
        ddof = 1 if members.size > 1 else 0
        f_spread[k] = np.std(f[members], ddof=ddof)
        xi_spread[k] = np.std(xi[members], ddof=ddof)
        ref = int(np.argmax(np.abs(shape[:, rep[k]])))
        aligned = shape[:, members] / shape[ref, members][None, :]
        sh_spread_r[:, k] = np.std(aligned.real, axis=1, ddof=ddof)
        sh_spread_i[:, k] = np.std(aligned.imag, axis=1, ddof=ddof)
        min_mac[k] = modal_assurance_criterion(shape[:, rep[k]], shape[:, members]).min()

    def empty_if_none(a):
        return a if a.size else np.zeros(0)

    return SelectedModes(
        frequency_hz=f[rep], damping_ratio=xi[rep], mode_shape=shape[:, rep],
        frequency_std=sf_med, damping_std=sxi_med,
        mode_shape_std_real=diagram.mode_shape_std_real[:, rep],
        mode_shape_std_imag=diagram.mode_shape_std_imag[:, rep],
        frequency_spread=f_spread, damping_spread=xi_spread,
        mode_shape_spread_real=sh_spread_r, mode_shape_spread_imag=sh_spread_i,
        min_mac=min_mac, representative_order=order[rep], representative_pole=rep,
        n_poles=np.array([m.size for m in kept], dtype=np.int64),
        order_min=np.array([order[m].min() for m in kept], dtype=np.int64),
        order_max=np.array([order[m].max() for m in kept], dtype=np.int64),
        members=tuple(kept), mode_of_pole=mode_of_pole,
        dropped_frequency_hz=empty_if_none(np.array([d[0] for d in dropped])),
        dropped_n_poles=np.array([d[1] for d in dropped], dtype=np.int64),
        min_cluster_size=int(min_size), output_names=diagram.output_names, settings=settings,
        has_uncertainty=diagram.has_uncertainty,
    )


# --------------------------------------------------------------------------- spectrum


def output_spectrum_singular_values(y, fs: float, *, nperseg: int | None = None):
    """Singular values of the cross power spectral density matrix of the outputs (Welch).

    ``G(f)`` (``n_outputs × n_outputs``) is estimated with :func:`scipy.signal.csd` (Hann
    window, 50 % overlap, one-sided, density scaling), and its singular values at each frequency
    are returned, largest first. Their peaks indicate the modes; this is the background of the
    stabilization diagram (paper Figure 3).

    Parameters
    ----------
    y : array_like, shape (n_samples, n_outputs)
        Output samples (units u).
    fs : float
        Sampling frequency, Hz.
    nperseg : int, optional
        Samples per Welch segment; default the power of two nearest to ``n_samples / 64``
        (about 120 averaged segments), clipped to [256, 8192] and to ``n_samples``. The
        frequency resolution is ``fs / nperseg``.

    Returns
    -------
    frequency_hz : ndarray, shape (n_frequencies,)
    singular_values : ndarray, shape (n_frequencies, n_outputs)
        In u²/Hz, descending along the second axis.
    """
    import scipy.signal

    from .identification import _sampling_frequency, as_samples

    y = as_samples(y, "y")
    fs = _sampling_frequency(fs)
    if not np.all(np.isfinite(y)):
        raise ValueError("y must be finite (NaN or Inf found)")
    n = y.shape[0]
    if nperseg is None:
        nperseg = int(2 ** round(math.log2(max(n / 64, 1))))
        nperseg = min(max(nperseg, 256), 8192, n)
    else:  # at most the record: scipy would shorten it silently
        nperseg = _integer("nperseg", nperseg, minimum=2, maximum=n)
    y = y - y.mean(axis=0)
    freq, g = scipy.signal.csd(y[:, :, None], y[:, None, :], fs=fs, nperseg=int(nperseg), axis=0)
    # g has shape (n_freq, l, l)
    sv = np.linalg.svd(g, compute_uv=False)
    return freq, sv
