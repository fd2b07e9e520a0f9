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
   hierarchical clustering (average linkage) on the distance
   ``|f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)``, cut at ``distance_threshold``; clusters with
   fewer than ``min_cluster_size`` members, or whose frequency is less certain than the
   half-power bandwidth of the peak they claim, are dropped (and listed with the reason), and
   each remaining cluster is reported at one representative pole, with the median analytic
   standard deviation of its reliable poles next to the spread of its members.

Both steps run in the C++ core (``cpp/include/modaluq/stabilization.hpp`` and ``selection.hpp``),
so C++ software embedding the core gets the same diagram and the same modes; this module
translates the results into :class:`Diagram` and :class:`SelectedModes` (tables, exports,
plots). ``tests/python/test_stabilization_core.py`` checks the core against an independent
NumPy/SciPy implementation. Everything is deterministic: no random initialisation, ties broken
by order and index.

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

from . import _core
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


#: the core's status (stabilization.hpp) -> PoleStatus, and back
_STATUS_OF_CORE = {
    _core.PoleStatus.stable: PoleStatus.STABLE, _core.PoleStatus.stable_frequency: PoleStatus.STABLE_FREQUENCY,
    _core.PoleStatus.unstable: PoleStatus.UNSTABLE, _core.PoleStatus.rejected: PoleStatus.REJECTED,
}
_CORE_OF_STATUS = {v: k for k, v in _STATUS_OF_CORE.items()}


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


# --------------------------------------------------------------------------- criteria


@dataclass(frozen=True)
class StabilityCriteria:
    """Thresholds of the stabilization diagram (all dimensionless fractions unless stated).

    A pole is first checked on its own; failing any of these makes it ``REJECTED``:

    - ``damping_ratio < min_damping_ratio`` (default 0: negative damping is unstable, not a
      structural mode) or ``damping_ratio > max_damping_ratio`` (default 0.20 = 20 %: lightly
      damped structures rarely exceed a few percent; heavily damped poles are usually noise);
    - ``frequency_std / frequency_hz > max_frequency_cov`` (default 0.05 = 5 %, a loose backstop:
      whether a column's σ is too large is judged by the selection against the bandwidth f ξ
      of its peak, :class:`ClusteringSettings`. The earlier 2 % cut the columns of well-damped
      modes into pieces; on Painter Street it hid the 10.8 Hz column). Skipped when the result
      carries no uncertainty; a pole whose σ is not finite is rejected.

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
    - damping stable, with uncertainty, when ``|Δξ| <= damping_std_factor * sqrt(σ_ξ² + σ_ξ,prev²)``
      (default k = 2) and ``|Δξ| / |ξ_prev| <= max_damping_change_with_std`` (default 0.5, a
      loose backstop): a damping ratio with σ_ξ = 50 % of ξ moves by more than 10 % between
      orders on noise alone, so a fixed relative bound breaks the columns of physical modes
      into pieces (on the shared records the σ test keeps 10–60 % more poles per mode and adds
      no spurious mode; the clusters of spurious poles it lets through are dropped by their σ,
      see :class:`ClusteringSettings`). Without uncertainty, or with ``damping_std_factor=None``,
      ``|Δξ| / |ξ_prev| <= max_damping_change`` (default 0.10 = 10 %; the 5 % often used makes
      physical poles flicker);
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
        k of the σ test on the damping change (default 2), or None for the relative test.
    max_damping_change_with_std : float
        Backstop on the relative damping change when the σ test is used (fraction).
    match_window : float
        Largest relative frequency distance to a pole of the previous order that can be its match.
    """

    max_frequency_change: float = 0.01
    max_damping_change: float = 0.10
    min_mac: float = 0.98
    frequency_std_factor: float | None = 2.0
    max_frequency_cov: float | None = 0.05
    min_damping_ratio: float = 0.0
    max_damping_ratio: float = 0.20
    damping_std_factor: float | None = 2.0
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

    def _to_core(self):
        c = _core.StabilityCriteria()
        for f in fields(self):
            value = getattr(self, f.name)
            setattr(c, f.name, None if value is None else float(value))
        return c


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
    per_cluster_min_size : bool
        With ``min_cluster_size=None``, count the orders from each cluster's own lowest order
        (True: a mode that first appears at a high order needs fewer poles) instead of from the
        lowest order of any clustered pole (False, default).
    max_frequency_std_per_bandwidth : float or None
        Clusters whose median ``σ_f / (f ξ)`` exceeds this are dropped (default 1): the frequency
        is then less certain than the half-power half-bandwidth ``f ξ`` of the peak the pole
        claims. A structural mode identified from a record of ``T`` seconds has about
        ``1 / sqrt(2π f T ξ)`` (0.05–0.4 on the shared records), while spurious poles, whose σ
        the noise directions inflate, have 2–5. None switches it off; skipped without uncertainty.
    merge_fragments : bool
        Join clusters that are pieces of one mode (default True; skipped without uncertainty):
        median frequencies within ``fragment_std_factor`` (default 3) combined σ_f, shapes with
        MAC >= ``fragment_min_mac`` (default 0.8), and at most ``fragment_max_shared`` (default
        0.25) of the smaller piece's orders in common. A mode has one pole per order, so two
        clusters present at the same orders are two modes, however close (a fore-aft/side-side
        pair of a tower); pieces arise where a mode's shape varies with the order (close modes,
        few sensors) and the frequency-and-MAC distance splits its column into parts each too
        small to be selected (the wind turbine's 1.6 Hz column, docs/settings.md).
    fragment_std_factor, fragment_min_mac, fragment_max_shared : float
        See ``merge_fragments``.
    drop_doublets : bool
        Drop the later of two selected clusters within ``doublet_window`` (default 0.05 = 5 %)
        in frequency whose shapes have MAC >= ``doublet_min_mac`` (default 0.8). Above the true
        order one mode is often fitted by a pair of poles with the same shape, the twin a few
        per cent away and often lightly damped; the twin appears at higher orders than the mode.
        "Later": the higher first order, then fewer poles. On the paper's chain, output-only,
        this removes the twins selected in 5 of 12 records (docs/settings.md);
        two physical modes that close and that alike in shape are not told apart by the
        sensors anyway. The dropped twin is listed with its reason.
    doublet_window, doublet_min_mac : float
        See ``drop_doublets``.
    statuses : tuple of PoleStatus
        Which poles are clustered (default only ``STABLE``).
    linkage : str
        Linkage method (the clustering is the core's, selection.hpp; it equals
        :func:`scipy.cluster.hierarchy.linkage` + ``fcluster``): default ``"average"``;
        ``"single"`` chains neighbouring poles, ``"complete"`` is stricter, ``"weighted"`` is WPGMA.
    """

    distance_threshold: float = 0.02
    min_cluster_size: int | None = None
    min_cluster_fraction: float = 0.25
    per_cluster_min_size: bool = False
    max_frequency_std_per_bandwidth: float | None = 1.0
    merge_fragments: bool = True
    drop_doublets: bool = True
    doublet_window: float = 0.05
    doublet_min_mac: float = 0.8
    fragment_std_factor: float = 3.0
    fragment_min_mac: float = 0.8
    fragment_max_shared: float = 0.25
    statuses: tuple = (PoleStatus.STABLE,)
    linkage: str = "average"

    def __post_init__(self):
        _real("distance_threshold", self.distance_threshold, low=0, low_open=True)
        if self.min_cluster_size is not None:
            _integer("min_cluster_size", self.min_cluster_size, minimum=1)
        _real("min_cluster_fraction", self.min_cluster_fraction, low=0, high=1, low_open=True)
        _real("max_frequency_std_per_bandwidth", self.max_frequency_std_per_bandwidth, low=0, low_open=True,
              allow_none=True)
        for name in ("per_cluster_min_size", "merge_fragments", "drop_doublets"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise TypeError(f"{name} must be True or False; got {getattr(self, name)!r}")
        _real("doublet_window", self.doublet_window, low=0)
        _real("doublet_min_mac", self.doublet_min_mac, low=0, high=1)
        _real("fragment_std_factor", self.fragment_std_factor, low=0)
        _real("fragment_min_mac", self.fragment_min_mac, low=0, high=1)
        _real("fragment_max_shared", self.fragment_max_shared, low=0, high=1)
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
                "per_cluster_min_size": bool(self.per_cluster_min_size),
                "max_frequency_std_per_bandwidth": self.max_frequency_std_per_bandwidth,
                "merge_fragments": bool(self.merge_fragments), "drop_doublets": bool(self.drop_doublets),
                "doublet_window": self.doublet_window, "doublet_min_mac": self.doublet_min_mac,
                "fragment_std_factor": self.fragment_std_factor,
                "fragment_min_mac": self.fragment_min_mac, "fragment_max_shared": self.fragment_max_shared,
                "statuses": [s.value for s in self.statuses], "linkage": self.linkage}

    def _to_core(self):
        c = _core.ClusteringOptions()
        c.distance_threshold = float(self.distance_threshold)
        c.min_cluster_size = int(self.min_cluster_size or 0)
        c.min_cluster_fraction = float(self.min_cluster_fraction)
        c.per_cluster_min_size = bool(self.per_cluster_min_size)
        c.max_frequency_std_per_bandwidth = (None if self.max_frequency_std_per_bandwidth is None
                                             else float(self.max_frequency_std_per_bandwidth))
        c.merge_fragments = bool(self.merge_fragments)
        c.drop_doublets = bool(self.drop_doublets)
        c.doublet_window = float(self.doublet_window)
        c.doublet_min_mac = float(self.doublet_min_mac)
        c.fragment_std_factor = float(self.fragment_std_factor)
        c.fragment_min_mac = float(self.fragment_min_mac)
        c.fragment_max_shared = float(self.fragment_max_shared)
        c.statuses = [_CORE_OF_STATUS[s] for s in self.statuses]
        c.linkage = getattr(_core.Linkage, self.linkage)
        return c


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
            pole_vars["mode_of_pole"] = (("pole",), sel.mode_of_pole + 1,
                                         {"long_name": "selected mode number of each pole (as the mode "
                                                       "coordinate, from 1; 0: none)"})
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
            coords["mode"] = np.arange(1, sel.n_modes + 1)  # numbered from 1, as in every table and plot
        ds = xr.Dataset({k: xr.Variable(d, v, a) for k, (d, v, a) in pole_vars.items()}, coords=coords)
        gattrs = {"fs_hz": self.fs, "criteria": json.dumps(self.criteria.to_dict()),
                  "identification_settings": json.dumps(self.result_settings, default=str)}
        if selected is not None:
            gattrs["clustering"] = json.dumps(selected.settings.to_dict())
        for k, v in (attrs or {}).items():
            gattrs[k] = v if isinstance(v, (str, int, float)) else json.dumps(v, default=str)
        ds.attrs.update(gattrs)
        return ds

    def _to_core(self):
        """The core's Diagram (selection.hpp reads poles and statuses) from these arrays."""
        p = _core.Poles()
        p.order = np.asarray(self.order, np.int64)
        p.frequency_hz = np.asarray(self.frequency_hz, float)
        p.damping_ratio = np.asarray(self.damping_ratio, float)
        p.frequency_std = np.asarray(self.frequency_std, float)
        p.damping_std = np.asarray(self.damping_std, float)
        p.mode_shape = np.asarray(self.mode_shape, complex)
        p.mode_shape_std_real = np.asarray(self.mode_shape_std_real, float)
        p.mode_shape_std_imag = np.asarray(self.mode_shape_std_imag, float)
        p.close_singular_values = np.asarray(self.close_singular_values, bool)
        p.noise_coupled = np.asarray(self.noise_coupled, bool)
        p.orders = [int(n) for n in self.orders]
        p.has_uncertainty = bool(self.has_uncertainty)
        d = _core.Diagram()
        d.poles = p
        d.status = [_CORE_OF_STATUS[s] for s in self.status]
        return d

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
        One name per output channel, used in tables, plots and exports (default
        ``result.output_names``: the names given to :func:`modaluq.identify`, else ``y0, y1, ...``).

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
        names = tuple(getattr(result, "output_names", ())) or tuple(f"y{k}" for k in range(n_out))
    else:
        names = tuple(str(s) for s in output_names)
        if len(names) != n_out:
            raise ValueError(f"output_names must have {n_out} entries (one per output); got {len(names)}")
    has_std = all(m.has_uncertainty for m in result.modes)

    # Flatten the orders into the core's Poles; the judging is the core's (stabilization.hpp).
    cols = {k: [] for k in ("order", "f", "xi", "sf", "sxi", "close", "coupled")}
    shapes, shapes_sr, shapes_si = [], [], []
    for m in result.modes:
        n = m.n_modes
        cols["order"].append(np.full(n, m.order, dtype=np.int64))
        cols["f"].append(np.asarray(m.frequency_hz, float))
        cols["xi"].append(np.asarray(m.damping_ratio, float))
        nan = np.full(n, np.nan)
        cols["sf"].append(np.asarray(m.frequency_std, float) if has_std else nan)
        cols["sxi"].append(np.asarray(m.damping_std, float) if has_std else nan)
        cols["close"].append(np.full(n, bool(m.close_singular_values)))
        coupled = getattr(m, "noise_coupled", None)
        cols["coupled"].append(np.zeros(n, bool) if coupled is None else np.asarray(coupled, bool).reshape(n))
        shapes.append(np.asarray(m.mode_shape, complex).reshape(n_out, n))
        nan2 = np.full((n_out, n), np.nan)
        shapes_sr.append(np.asarray(m.mode_shape_std_real, float).reshape(n_out, n) if has_std else nan2)
        shapes_si.append(np.asarray(m.mode_shape_std_imag, float).reshape(n_out, n) if has_std else nan2)
    poles = _core.Poles()
    poles.order = _concat(cols["order"], np.int64)
    poles.frequency_hz = _concat(cols["f"])
    poles.damping_ratio = _concat(cols["xi"])
    poles.frequency_std = _concat(cols["sf"])
    poles.damping_std = _concat(cols["sxi"])
    poles.close_singular_values = _concat(cols["close"], bool)
    poles.noise_coupled = _concat(cols["coupled"], bool)
    poles.mode_shape = np.concatenate(shapes, axis=1) if shapes else np.zeros((n_out, 0), complex)
    poles.mode_shape_std_real = np.concatenate(shapes_sr, axis=1) if shapes else np.zeros((n_out, 0))
    poles.mode_shape_std_imag = np.concatenate(shapes_si, axis=1) if shapes else np.zeros((n_out, 0))
    poles.orders = [int(m.order) for m in result.modes]
    poles.has_uncertainty = bool(has_std)

    core_criteria = criteria._to_core()
    # The band of interest given to identify (frequency_range): poles outside it are rejected.
    band = result.settings.get("frequency_range") if isinstance(result.settings, dict) else None
    if band is not None:
        core_criteria.frequency_range = (float(band[0]), float(band[1]))
    d = _core.stabilization_diagram(poles, core_criteria)
    p = d.poles
    n_poles = int(p.frequency_hz.size)
    status = np.empty(n_poles, dtype=object)
    status[:] = [_STATUS_OF_CORE[s] for s in d.status]
    return Diagram(
        order=np.asarray(p.order, np.int64), frequency_hz=p.frequency_hz, damping_ratio=p.damping_ratio,
        frequency_std=p.frequency_std, damping_std=p.damping_std,
        mode_shape=p.mode_shape, mode_shape_std_real=p.mode_shape_std_real,
        mode_shape_std_imag=p.mode_shape_std_imag, status=status,
        reason=np.array(d.reason, dtype=str) if n_poles else np.array([], dtype=str),
        matched_pole=np.asarray(d.matched_pole, np.int64),
        frequency_change=d.frequency_change, damping_change=d.damping_change, mac=d.mac,
        frequency_change_std=d.frequency_change_std,
        close_singular_values=np.asarray(p.close_singular_values, bool),
        noise_coupled=np.asarray(p.noise_coupled, bool), orders=tuple(int(o) for o in p.orders),
        fs=float(result.fs), output_names=names, criteria=criteria, has_uncertainty=has_std,
        result_settings=dict(result.settings),
    )


def _concat(parts, dtype=float) -> np.ndarray:
    return np.concatenate(parts).astype(dtype, copy=False) if parts else np.zeros(0, dtype)


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
    #: (diagram.n_poles,) index (from 0, into these arrays) of each pole's mode, -1 if none;
    #: the mode's number in tables and exports is this + 1
    mode_of_pole: np.ndarray
    dropped_frequency_hz: np.ndarray   #: median frequency of each dropped cluster, Hz
    dropped_n_poles: np.ndarray        #: size of each dropped cluster
    min_cluster_size: int              #: the size threshold actually applied (the smallest, per cluster)
    output_names: tuple
    settings: ClusteringSettings = field(default_factory=ClusteringSettings)
    has_uncertainty: bool = True
    dropped_reason: tuple = ()         #: why each cluster was dropped, in words
    #: (n_modes,) median σ_f / (f ξ) over the cluster (NaN without uncertainty)
    frequency_std_per_bandwidth: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def n_modes(self) -> int:
        return int(self.frequency_hz.size)

    def __len__(self) -> int:
        return self.n_modes

    def to_dataframe(self):
        """One row per mode, numbered from 1 (the index ``mode``, as in every table, plot and
        export): f, σ_f, spread, ξ, σ_ξ, spread, cluster size and orders, and the shape per
        channel in columns ``mode_shape_<channel>_real`` ...."""
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
        return pd.DataFrame(data, index=pd.RangeIndex(1, self.n_modes + 1, name="mode"))

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
            "dropped_clusters": [{"frequency_hz": num(f), "n_poles": int(n), "reason": str(r)}
                                 for f, n, r in zip(self.dropped_frequency_hz, self.dropped_n_poles,
                                                    self.dropped_reason)],
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
            # counted by the reason each carries (selection.hpp words them)
            too_small = sum(1 for r in self.dropped_reason if "fewer than" in r)
            too_uncertain = sum(1 for r in self.dropped_reason if "half-power bandwidth" in r)
            twins = sum(1 for r in self.dropped_reason if r.startswith("a twin of"))
            parts = []
            if too_small:
                parts.append(f"{too_small} with fewer than {self.min_cluster_size} poles")
            if too_uncertain:
                parts.append(f"{too_uncertain} whose frequency std exceeds the peak's half-power bandwidth")
            if twins:
                parts.append(f"{twins} twin{'' if twins == 1 else 's'} of a selected mode")
            s += f"\n{self.dropped_n_poles.size} cluster(s) dropped: " + ", ".join(parts)
        return s

    def __repr__(self) -> str:
        f = np.array2string(self.frequency_hz, precision=3, separator=", ")
        return f"SelectedModes(n_modes={self.n_modes}, frequency_hz={f})"

    def plot(self, fig=None, *, channel_positions=None):
        """Mode shapes with ±σ error bars; see :func:`modaluq.plot.mode_shapes`. Returns the Figure."""
        from .plot import mode_shapes

        return mode_shapes(self, fig=fig, channel_positions=channel_positions)



def select_modes(diagram: Diagram, settings: ClusteringSettings | None = None, **kwargs) -> SelectedModes:
    """Group the stable poles of a diagram into physical modes (deterministic).

    Method:

    1. take the poles whose status is in ``settings.statuses`` (default: ``STABLE``);
    2. distance ``d_ij = |f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)`` between every pair;
    3. agglomerative clustering (``settings.linkage``) cut at ``settings.distance_threshold``:
       the core's nearest-neighbour chain, equal to :func:`scipy.cluster.hierarchy.linkage` +
       :func:`~scipy.cluster.hierarchy.fcluster` with criterion ``"distance"``;
    4. a physical mode appears once per order: when a cluster holds several poles of one order
       (a mode doubled by a spurious twin), keep the one nearest to the cluster's median
       frequency. (Penalising same-order pairs in the distance instead would split such a mode
       into two clusters.)
    5. drop clusters with fewer than ``min_cluster_size`` members, and clusters whose median
       ``σ_f / (f ξ)`` exceeds ``max_frequency_std_per_bandwidth`` (default 1: the frequency is
       less certain than the half-power bandwidth of the peak; spurious poles, whose σ the noise
       directions inflate, have 2–5, structural modes 0.05–0.7 on the shared records); each is
       reported in ``dropped_frequency_hz`` / ``dropped_n_poles`` / ``dropped_reason``;
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
    if not isinstance(diagram, Diagram):
        raise TypeError(f"diagram must be a Diagram (from stabilization_diagram); got {type(diagram).__name__}")
    if settings is None:
        settings = ClusteringSettings(**kwargs)
    elif kwargs:
        raise TypeError("pass either settings= or its fields as keyword arguments, not both")
    elif not isinstance(settings, ClusteringSettings):
        raise TypeError(f"settings must be a ClusteringSettings; got {type(settings).__name__}")

    sel = _core.select_modes(diagram._to_core(), settings._to_core())
    return SelectedModes(
        frequency_hz=sel.frequency_hz, damping_ratio=sel.damping_ratio, mode_shape=sel.mode_shape,
        frequency_std=sel.frequency_std, damping_std=sel.damping_std,
        mode_shape_std_real=sel.mode_shape_std_real, mode_shape_std_imag=sel.mode_shape_std_imag,
        frequency_spread=sel.frequency_spread, damping_spread=sel.damping_spread,
        mode_shape_spread_real=sel.mode_shape_spread_real, mode_shape_spread_imag=sel.mode_shape_spread_imag,
        min_mac=sel.min_mac, representative_order=np.asarray(sel.representative_order, np.int64),
        representative_pole=np.asarray(sel.representative_pole, np.int64),
        n_poles=np.asarray(sel.n_poles, np.int64), order_min=np.asarray(sel.order_min, np.int64),
        order_max=np.asarray(sel.order_max, np.int64),
        members=tuple(np.asarray(m, dtype=np.int64) for m in sel.members),
        mode_of_pole=np.asarray(sel.mode_of_pole, np.int64),
        dropped_frequency_hz=sel.dropped_frequency_hz, dropped_n_poles=np.asarray(sel.dropped_n_poles, np.int64),
        min_cluster_size=int(sel.min_cluster_size), output_names=diagram.output_names, settings=settings,
        has_uncertainty=diagram.has_uncertainty, dropped_reason=tuple(sel.dropped_reason),
        frequency_std_per_bandwidth=sel.frequency_std_per_bandwidth,
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
