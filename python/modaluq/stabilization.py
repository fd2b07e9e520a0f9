"""Stabilization diagram: every pole of a multi-order :class:`~modaluq.Result`, judged.

The identification gives, at every model order n, a set of poles (frequency, damping ratio,
mode shape and their standard deviations). Physical modes show up at (almost) every order
with nearly the same parameters; spurious (noise, numerical) poles come and go.
:func:`stabilization_diagram` judges every pole, first on its own (:class:`~modaluq.StabilityCriteria`:
damping ratio in ``[min_damping_ratio, max_damping_ratio]``, coefficient of variation
``frequency_std / frequency_hz`` at most ``max_frequency_cov``), then against its match at the
previous identified order (relative frequency change, relative damping change, MAC, and the
frequency change measured in standard deviations, ``|Δf| <= k sqrt(σ1² + σ2²)``). Each pole
gets a :class:`~modaluq.PoleStatus` and, unless stable, a ``reason`` saying which test failed
and by how much. Grouping the stable poles into modes is :mod:`modaluq.selection`.

The poles and their judging are the C++ core's (``cpp/include/modaluq/stabilization.hpp``:
``poles_of`` the identification a :class:`~modaluq.Result` keeps, ``stabilization_diagram``), so
C++ software embedding the core gets the same diagram; this module reads it into a
:class:`Diagram` (tables, exports, plots), which keeps the core's diagram for the selection.
``tests/python/test_stabilization_core.py`` checks the core against an independent NumPy/SciPy
implementation. Everything is deterministic.

>>> import modaluq
>>> sim = modaluq.simulate(50_000, seed=2)
>>> result = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=21, orders=range(2, 61, 2))
>>> diagram = modaluq.stabilization_diagram(result)
>>> modes = diagram.select_modes()
>>> [round(float(f), 1) for f in modes.frequency_hz]
[1.9, 5.6, 8.7, 14.5, 15.8, 17.0]
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import _core
from .selection import select_modes
from .settings import STATUS_OF_CORE, PoleStatus, StabilityCriteria

__all__ = ["Diagram", "modal_assurance_criterion", "stabilization_diagram"]


def modal_assurance_criterion(shape_a, shape_b) -> np.ndarray:
    """Modal assurance criterion between every column of ``shape_a`` and every column of ``shape_b``.

    ``MAC_ij = |a_iᴴ b_j|² / ((a_iᴴ a_i)(b_jᴴ b_j))``, between 0 (orthogonal) and 1 (collinear),
    invariant to the complex scaling of either shape. Computed by the core
    (``stabilization.hpp``): the MAC the diagram and the selection use.

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
    return _core.modal_assurance_criterion(a.astype(complex, copy=False), b.astype(complex, copy=False))


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
    #: The core's diagram these arrays are read from (set by :func:`stabilization_diagram`); what
    #: :func:`modaluq.select_modes` clusters. ``None`` for a Diagram made otherwise (constructed,
    #: copied or unpickled): make it again with :func:`stabilization_diagram` to select modes.
    _core_diagram: object = field(default=None, init=False, repr=False, compare=False)
    #: the identification's modes (``Result.modes``) the poles were flattened from, for
    #: :meth:`pole_covariance`; not copied
    _modes: object = field(default=None, init=False, repr=False, compare=False)
    #: (n_poles,) correlation of f and ξ of each pole (``Modes.frequency_damping_correlation``; NaN
    #: without uncertainty); empty when unknown
    frequency_damping_correlation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (n_poles,) bool, the blocks are shorter than half the pole's decay time (``Modes.block_too_short``);
    #: empty when unknown
    block_too_short: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    #: (n_poles,) ρ of each pole (``Modes.noise_coupling``): its σ with the noise singular vectors free
    #: over its σ with them frozen, 1 at orders ≤ k*; NaN without uncertainty; empty when unknown
    noise_coupling: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: samples of the record identified (``Result.n_samples``: after any window or decimation);
    #: a ``y`` given to :meth:`plot` must have as many (0: unknown, not checked)
    n_samples: int = 0
    #: the identification's ``Result.low_signal_to_noise``: H is at the level of its own estimation
    #: noise, the modes cannot be told from noise (the tables of the selected modes say so)
    low_signal_to_noise: bool = False
    #: k*, the significant singular values of H (``Result.significant_singular_values``): poles at
    #: lower orders come from a model that cuts signal (``ClusteringSettings.representative``
    #: ``"lowest"`` reads its modes from this order up); 0: unknown
    noise_floor_order: int = 0
    #: (n_poles,) modal phase collinearity of each pole's shape (1: real) and its mean phase
    #: deviation, degrees (:mod:`modaluq.indicators`; ``StabilityCriteria.min_mpc``/``max_mpd_deg``
    #: can reject poles by them); empty when unknown (a Diagram constructed by hand)
    mpc: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mpd_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (n_poles, 2, n_blocks): each pole's first-order factor rows of f (Hz) and ξ
    #: (``Modes.frequency_damping_factor``), from which the selection forms the σ of a cluster's
    #: mean (``ClusteringSettings.cluster_std``); empty (0 poles) when unknown
    frequency_damping_factor: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 0)))
    #: blocks behind every σ (``Result.n_blocks``: the core's, which can be more than the ``n_blocks``
    #: asked for, the remainder of the record cut into whole blocks too); 0 without uncertainty or unknown
    n_blocks: int = 0

    @property
    def n_poles(self) -> int:
        return int(self.order.size)

    def pole_covariance(self, pole: int):
        """The ``(2+2l, 2+2l)`` covariance of ``[f, ξ, Re shape, Im shape]`` of pole ``pole`` (an
        index into these arrays), from the identification's :class:`~modaluq.Modes`; ``None`` when
        unknown (no uncertainty, or a Diagram constructed, copied or unpickled)."""
        return self._pole_field(pole, "covariance")

    def pole_shape_factor(self, pole: int):
        """The ``(2l, n_blocks)`` first-order factor V of ``[Re shape; Im shape]`` of pole ``pole``
        (``Modes.mode_shape_factor``): ``V_i V_jᵀ`` is the cross-covariance of two poles' shapes.
        ``None`` unless the identification ran with ``keep_shape_factor=True`` (or for a Diagram
        constructed, copied or unpickled)."""
        return self._pole_field(pole, "mode_shape_factor")

    def _pole_field(self, pole: int, name: str):
        """Pole ``pole``'s entry of the identification's per-mode array ``name`` (a field of
        :class:`~modaluq.Modes`), or None when unknown or not kept."""
        modes = self._modes
        if modes is None or not self.has_uncertainty:
            return None
        pole = int(pole)
        if not 0 <= pole < self.n_poles:
            raise IndexError(f"pole must be in [0, {self.n_poles}); got {pole}")
        first = 0  # poles are the modes of every order, in order (poles_of)
        for m in modes:
            k = int(np.size(m.frequency_hz))
            if pole < first + k:
                values = getattr(m, name)
                return None if values is None else values[pole - first]
            first += k
        return None

    @property
    def core_diagram(self):
        """The core's diagram these arrays were read from, which :func:`modaluq.select_modes`
        clusters (``None`` for a Diagram constructed, copied or unpickled). Editing the arrays
        in place does not change it: make the diagram again with :func:`stabilization_diagram`."""
        return self._core_diagram

    def __getstate__(self):
        state = dict(self.__dict__)  # the core's objects do not pickle
        state.pop("_core_diagram", None)
        state.pop("_modes", None)  # pole_covariance is for the diagram of a live identification
        return state

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

    def to_xarray(self, selected=None, attrs: dict | None = None):
        """The whole diagram (and optionally the selected modes) as an :class:`xarray.Dataset`
        (see :func:`modaluq.export.diagram_to_xarray`)."""
        from .export import diagram_to_xarray

        return diagram_to_xarray(self, selected, attrs)

    def select_modes(self, settings=None, **kwargs):
        """Shorthand for :func:`modaluq.select_modes` (``kwargs``: fields of :class:`~modaluq.ClusteringSettings`)."""
        return select_modes(self, settings, **kwargs)

    def plot(self, ax=None, *, y=None, spectrum=None, selected=None, show_rejected=True, nperseg=None,
             frequency_range=None):
        """Draw the diagram (poles with ±σ_f bars over the output spectrum when ``y`` is given).

        See :func:`modaluq.plot.plot_stabilization_diagram` for the parameters. Returns the Figure.
        """
        from .plot import plot_stabilization_diagram

        return plot_stabilization_diagram(self, ax=ax, y=y, spectrum=spectrum, selected=selected,
                                          show_rejected=show_rejected,
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
    # a Result is known by its fields: results.py sits above this module (its Result.stabilization_diagram
    # calls this function), and a module imports the types it makes, not those it takes
    if not all(hasattr(result, k) for k in ("modes", "fs", "n_outputs", "settings")):
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
    ident = getattr(result, "core_identification", None)  # the core's, kept by identify() (results.py)
    poles = _core.poles_of(ident) if ident is not None else _poles_of_modes(result, has_std)
    if poles.frequency_hz.size == 0:  # no pole: the shapes keep one row per channel all the same
        poles.mode_shape = np.zeros((n_out, 0), complex)
        poles.mode_shape_std_real = poles.mode_shape_std_imag = np.zeros((n_out, 0))

    core_criteria = criteria.to_core()
    # The band of interest given to identify (frequency_range): poles outside it are rejected.
    band = result.settings.get("frequency_range") if isinstance(result.settings, dict) else None
    if band is not None:
        core_criteria.frequency_range = (float(band[0]), float(band[1]))
    d = _core.stabilization_diagram(poles, core_criteria)
    p = d.poles
    n_poles = int(p.frequency_hz.size)
    status = np.empty(n_poles, dtype=object)
    status[:] = [STATUS_OF_CORE[s] for s in d.status]
    diagram = Diagram(
        order=np.asarray(p.order, np.int64), frequency_hz=p.frequency_hz, damping_ratio=p.damping_ratio,
        frequency_std=p.frequency_std, damping_std=p.damping_std,
        mode_shape=p.mode_shape, mode_shape_std_real=p.mode_shape_std_real,
        mode_shape_std_imag=p.mode_shape_std_imag, status=status,
        reason=np.array(d.reason, dtype=str) if n_poles else np.array([], dtype=str),
        matched_pole=np.asarray(d.matched_pole, np.int64),
        frequency_change=d.frequency_change, damping_change=d.damping_change, mac=d.mac,
        frequency_change_std=d.frequency_change_std, mpc=d.mpc, mpd_deg=d.mpd_deg,
        close_singular_values=np.asarray(p.close_singular_values, bool),
        noise_coupled=np.asarray(p.noise_coupled, bool), orders=tuple(int(o) for o in p.orders),
        fs=float(result.fs), output_names=names, criteria=criteria, has_uncertainty=has_std,
        result_settings=dict(result.settings),
        frequency_damping_correlation=p.frequency_damping_correlation, block_too_short=p.block_too_short,
        noise_coupling=p.noise_coupling,
        frequency_damping_factor=_factor_per_pole(p.frequency_damping_factor, n_poles),
        n_samples=int(getattr(result, "n_samples", 0)),
        n_blocks=int(getattr(result, "n_blocks", 0) or 0) if has_std else 0,
        low_signal_to_noise=bool(getattr(result, "low_signal_to_noise", False)),
        noise_floor_order=int(p.noise_floor_order),
    )
    object.__setattr__(diagram, "_core_diagram", d)
    object.__setattr__(diagram, "_modes", tuple(result.modes))
    return diagram


def _factor_per_pole(factor: np.ndarray, n_poles: int) -> np.ndarray:
    """The core's (2 n_b x n_poles) factor rows as (n_poles, 2, n_b) (a view), (0, 2, 0) when absent."""
    if factor.shape[1] != n_poles or n_poles == 0:
        return np.zeros((0, 2, 0))
    return factor.T.reshape(n_poles, 2, -1)


def _poles_of_modes(result, has_std: bool):
    """The core's ``Poles`` of a Result that does not hold the core's identification (one made by
    hand, copied or unpickled): its modes flattened as ``_core.poles_of`` flattens an
    identification (``test_stabilization.py`` checks the two agree bit for bit)."""
    modes = [m for m in result.modes if m.n_modes]
    n_out = int(result.n_outputs)

    def per_pole(values, dtype=float):  # one entry per pole
        return np.concatenate([np.asarray(v, dtype).reshape(-1) for v in values]) if modes else np.zeros(0, dtype)

    def per_column(values, dtype=float):  # one column per pole
        return (np.concatenate([np.asarray(v, dtype).reshape(n_out, -1) for v in values], axis=1) if modes
                else np.zeros((n_out, 0), dtype))

    def std(name):  # NaN without uncertainty
        return [getattr(m, name) if has_std else np.full(np.shape(m.mode_shape) if name.startswith("mode")
                                                         else m.n_modes, np.nan) for m in modes]

    p = _core.Poles()
    p.order = per_pole([np.full(m.n_modes, m.order) for m in modes], np.int64)
    p.frequency_hz = per_pole([m.frequency_hz for m in modes])
    p.damping_ratio = per_pole([m.damping_ratio for m in modes])
    p.frequency_std = per_pole(std("frequency_std"))
    p.damping_std = per_pole(std("damping_std"))
    p.mode_shape = per_column([m.mode_shape for m in modes], complex)
    p.mode_shape_std_real = per_column(std("mode_shape_std_real"))
    p.mode_shape_std_imag = per_column(std("mode_shape_std_imag"))
    p.close_singular_values = per_pole([np.full(m.n_modes, m.close_singular_values) for m in modes], bool)
    p.noise_coupled = per_pole([np.zeros(m.n_modes, bool) if m.noise_coupled is None else m.noise_coupled
                                for m in modes], bool)
    p.noise_floor_order = int(getattr(result, "significant_singular_values", 0) or 0)
    # as poles_of: NaN / False without uncertainty; empty when unknown (a Result made without them)
    rho = [getattr(m, "frequency_damping_correlation", None) for m in modes]
    slow = [getattr(m, "block_too_short", None) for m in modes]
    coupling = [getattr(m, "noise_coupling", None) for m in modes]
    if not has_std:
        p.frequency_damping_correlation = per_pole([np.full(m.n_modes, np.nan) for m in modes])
        p.block_too_short = per_pole([np.zeros(m.n_modes, bool) for m in modes], bool)
        p.noise_coupling = per_pole([np.full(m.n_modes, np.nan) for m in modes])
    else:
        if all(r is not None for r in rho):
            p.frequency_damping_correlation = per_pole(rho)
        if all(b is not None for b in slow):
            p.block_too_short = per_pole(slow, bool)
        if all(c is not None and np.size(c) == m.n_modes for c, m in zip(coupling, modes)):
            p.noise_coupling = per_pole(coupling)
        factors = [getattr(m, "frequency_damping_factor", None) for m in modes]
        if modes and all(u is not None for u in factors) and len({u.shape[2] for u in factors}) == 1:
            # (2 n_b x n_poles), column i [u_f; u_xi] of pole i, as poles_of stacks Modes::frequency_damping_factor
            p.frequency_damping_factor = np.concatenate([u.reshape(u.shape[0], -1) for u in factors]).T
    p.orders = [int(m.order) for m in result.modes]
    p.has_uncertainty = bool(has_std)
    return p
