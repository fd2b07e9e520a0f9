"""Result types of an identification: :class:`Modes` (one model order) and :class:`Result` (a run).

Plain frozen dataclasses over the core's arrays: they print, convert to pandas and, through
convenience methods, form the stabilization diagram, select modes and plot. This module sits
above :mod:`~modaluq.stabilization` and :mod:`~modaluq.selection` (which take a Result by its
fields), so those methods import downwards (docs/architecture.md).
"""

from __future__ import annotations

import dataclasses
import enum
import warnings
from dataclasses import dataclass, field

import numpy as np

from .checks import check_boolean
from .intervals import interval_factor, interval_table, interval_words
from .selection import select_modes
from .stabilization import stabilization_diagram

__all__ = ["IdentificationWarning", "ModalUQWarning", "Modes", "Result", "SlowDecay", "result_from_core", "warn_all"]


class ModalUQWarning(UserWarning):
    """A result is computed but a quality flag is set (see ``Result.warnings``)."""


class IdentificationWarning(str, enum.Enum):
    """What one of the core's ``Result.warnings`` is about (``identify.hpp``); the numbers it
    words are fields of the :class:`Result` (``slow_decay``, ``signal_to_noise`` ...)."""

    INPUT_RANK_DEFICIENT = "input_rank_deficient"  #: ``input_rank_deficient``, ``input_rank``
    TOO_FEW_BLOCKS = "too_few_blocks"              #: ``too_few_blocks``, ``n_blocks``
    LOW_SIGNAL_TO_NOISE = "low_signal_to_noise"    #: ``low_signal_to_noise``, ``signal_to_noise``
    DEGENERATE_ORDERS = "degenerate_orders"        #: ``Modes.degenerate`` of some orders, ``numerical_rank``
    SLOW_DECAY = "slow_decay"                      #: ``slow_decay``

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class SlowDecay:
    """The core's finding of poles that decay more slowly than the blocks are long
    (``Modes.block_too_short``, over every order): their σ are less reliable."""

    n_poles: int               #: poles flagged, every order
    block_seconds: float       #: length of one block, s
    longest_decay_s: float     #: largest decay time 1/(2π f ξ) of the flagged poles, s
    record_seconds: float      #: the record's Hankel columns / fs, s
    #: record_seconds / (longest_decay_s / 2): the most blocks each as long as half that decay time
    fitting_n_blocks: int

    @property
    def record_too_short(self) -> bool:
        """Fewer than 2 such blocks fit: only a longer record helps."""
        return self.fitting_n_blocks < 2

    @classmethod
    def _from_core(cls, s) -> "SlowDecay | None":
        if not s.n_poles:
            return None
        return cls(n_poles=int(s.n_poles), block_seconds=float(s.block_seconds),
                   longest_decay_s=float(s.longest_decay_s), record_seconds=float(s.record_seconds),
                   fitting_n_blocks=int(s.fitting_n_blocks))


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, repr=False)
class Modes:
    """The modes identified at one model order, sorted by frequency.

    One mode per complex-conjugate pair of eigenvalues. Frequencies in Hz, damping ratios as
    fractions (0.02 = 2 %), mode shapes normalised so that their largest-modulus component is
    exactly 1. The ``*_std`` fields and ``covariance`` are first-order (delta-method) standard
    deviations and covariances from the block sample covariance of the data covariances; they
    are ``None`` when the identification ran with ``uncertainty=False``.
    """

    order: int                                   #: model order n
    frequency_hz: np.ndarray                     #: (n_modes,) natural frequencies, Hz
    damping_ratio: np.ndarray                    #: (n_modes,) damping ratios, fraction
    mode_shape: np.ndarray                       #: (n_outputs, n_modes) complex
    eigenvalue: np.ndarray                       #: (n_modes,) discrete-time eigenvalues of A
    reference_component: np.ndarray              #: (n_modes,) component of each shape scaled to 1
    frequency_std: np.ndarray | None = None      #: (n_modes,) Hz
    damping_std: np.ndarray | None = None        #: (n_modes,) fraction
    mode_shape_std_real: np.ndarray | None = None  #: (n_outputs, n_modes)
    mode_shape_std_imag: np.ndarray | None = None  #: (n_outputs, n_modes)
    covariance: np.ndarray | None = None         #: (n_modes, 2+2l, 2+2l) of [f, xi, Re shape, Im shape]
    #: (n_modes, 2, n_blocks): per mode the first-order factor rows u_f (Hz) and u_ξ (fraction) of f
    #: and ξ, one column per block (of every setup, setup by setup, for a merge): ``covariance[:, :2, :2]``
    #: is ``U Uᵀ``. What the selection's σ of a cluster's mean is formed from (docs/uq-math.md §13.10)
    frequency_damping_factor: np.ndarray | None = None
    #: (n_modes, 2l, n_blocks): per mode the first-order factor rows V of [Re shape; Im shape], one
    #: column per block: ``covariance[:, 2:, 2:]`` is ``V Vᵀ``, and ``V_i V_jᵀ`` the cross-covariance
    #: of two poles' shapes (the exact σ of an AutoMAC entry). ``None`` unless
    #: ``keep_shape_factor=True`` (2l·n_blocks values per pole)
    mode_shape_factor: np.ndarray | None = None
    #: (n_modes,) correlation of f and ξ from ``covariance`` (the core's; NaN where a variance is 0)
    frequency_damping_correlation: np.ndarray | None = None
    block_too_short: np.ndarray | None = None    #: (n_modes,) blocks shorter than half the decay time
    singular_value_gap: float = float("nan")     #: (s_n - s_{n+1}) / its std
    close_singular_values: bool = False          #: the order cuts significant singular values within 3 std
    noise_coupling: np.ndarray | None = None     #: (n_modes,) σ unfrozen / frozen (docs/uq-math.md §5.5)
    noise_coupled: np.ndarray | None = None      #: (n_modes,) no first-order sigma: unfrozen (large) sigma kept
    #: (n_modes,) variance factor c of the block-correlation correction (docs/uq-math.md §3.1); 1 when off
    block_correlation_scale: np.ndarray | None = None
    #: (n_modes,) σ_f and σ_ξ are the bootstrap's (``bootstrap_draws``, docs/uq-math.md §5.6), not first-order
    bootstrapped: np.ndarray | None = None
    degenerate: bool = False                     #: no modes: above the numerical rank of H, or A not decomposable
    note: str = ""                               #: why the order is degenerate
    #: blocks behind the σ (``Result.n_blocks``): the intervals x ± t σ take the Student-t quantile
    #: of ``n_blocks − 1`` (:meth:`intervals`); 0 without uncertainty or unknown (the normal quantile)
    n_blocks: int = 0

    @classmethod
    def _from_core(cls, m) -> "Modes":
        # A run with uncertainty fills the std arrays of every order; a degenerate order has no
        # gap statistic, but its (empty) covariance has the (2+2l)^2 rows of a run with uncertainty.
        has_std = m.frequency_std.size == m.frequency_hz.size and (
            not np.isnan(m.singular_value_gap) or m.covariance.shape[0] > 0)
        l = m.mode_shape.shape[0]
        npar = 2 + 2 * l
        cov = None
        if has_std:
            # Column i of the core's (npar^2 x n_modes) matrix is mode i's symmetric covariance.
            cov = np.ascontiguousarray(m.covariance.T).reshape(-1, npar, npar)
        factor = None
        rows = m.frequency_damping_factor
        if has_std and rows.shape[1] == m.frequency_hz.size:
            # column i of the core's (2 n_b x n_modes) matrix is [u_f; u_xi] of mode i
            factor = rows.T.reshape(rows.shape[1], 2, rows.shape[0] // 2)
        shape_factor = None
        rows = m.mode_shape_factor
        if has_std and rows.shape[1] == m.frequency_hz.size and rows.shape[1] > 0:
            # column i of the core's (2l n_b x n_modes) matrix is mode i's 2l x n_b factor, column-major
            shape_factor = rows.T.reshape(rows.shape[1], rows.shape[0] // (2 * l), 2 * l).transpose(0, 2, 1)
        return cls(
            order=int(m.order),
            frequency_hz=m.frequency_hz,
            damping_ratio=m.damping_ratio,
            mode_shape=m.mode_shape,
            eigenvalue=m.eigenvalue,
            reference_component=m.reference_component,
            frequency_std=m.frequency_std if has_std else None,
            damping_std=m.damping_std if has_std else None,
            mode_shape_std_real=m.mode_shape_std_real if has_std else None,
            mode_shape_std_imag=m.mode_shape_std_imag if has_std else None,
            covariance=cov,
            frequency_damping_factor=factor,
            mode_shape_factor=shape_factor,
            frequency_damping_correlation=m.frequency_damping_correlation if has_std else None,
            block_too_short=m.block_too_short if has_std else None,
            singular_value_gap=float(m.singular_value_gap),
            close_singular_values=bool(m.close_singular_values),
            noise_coupling=m.noise_coupling if has_std else None,
            noise_coupled=m.noise_coupled if has_std else None,
            block_correlation_scale=m.block_correlation_scale if has_std else None,
            bootstrapped=m.bootstrapped if has_std else None,
            degenerate=bool(m.degenerate),
            note=str(m.note),
        )

    @property
    def n_modes(self) -> int:
        return int(self.frequency_hz.size)

    @property
    def has_uncertainty(self) -> bool:
        return self.frequency_std is not None

    def __len__(self) -> int:
        return self.n_modes

    def to_dataframe(self, output_names=None):
        """One row per mode (numbered from 1): frequency, damping and (when computed) their
        standard deviations, and the shape in columns ``mode_shape_<channel>``."""
        import pandas as pd

        data = {
            "order": np.full(self.n_modes, self.order),
            "frequency_hz": self.frequency_hz,
            "damping_ratio": self.damping_ratio,
        }
        if self.has_uncertainty:
            data["frequency_std"] = self.frequency_std
            data["damping_std"] = self.damping_std
        l = self.mode_shape.shape[0]
        names = tuple(output_names) if output_names is not None else tuple(f"y{k}" for k in range(l))
        for k in range(l):
            data[f"mode_shape_{names[k]}"] = self.mode_shape[k]
        return pd.DataFrame(data, index=pd.RangeIndex(1, self.n_modes + 1, name="mode"))

    def interval_factor(self, level: float = 0.95) -> float:
        """The factor t of the ``level`` intervals x ± t σ: the Student-t quantile of ``n_blocks − 1``
        (:func:`modaluq.intervals.interval_factor`; docs/uq-math.md §14)."""
        return interval_factor(self.n_blocks, level)

    def intervals(self, level: float = 0.95):
        """The ``level`` intervals of f and ξ at this order, one row per mode, as
        :meth:`SelectedModes.intervals <modaluq.SelectedModes.intervals>`: ``frequency_low_hz`` …
        ``damping_high``, x ± t σ; NaN without uncertainty. Above the true order σ itself falls
        short (docs/validation.md, issue 27 (e)): no quantile makes up for that."""
        nan = np.full(self.n_modes, np.nan)
        unc = self.has_uncertainty
        return interval_table(self.frequency_hz, self.frequency_std if unc else nan, self.damping_ratio,
                              self.damping_std if unc else nan, self.interval_factor(level))

    def table(self) -> str:
        """The modes as a plain-text table (frequency in Hz, damping in %)."""
        unc = self.has_uncertainty
        head = f"{'mode':>4}  {'f [Hz]':>10}" + (f"  {'std f':>9}" if unc else "") + f"  {'xi [%]':>7}"
        head += f"  {'std xi':>7}" if unc else ""
        lines = [head]
        for i in range(self.n_modes):
            row = f"{i + 1:>4}  {self.frequency_hz[i]:>10.4f}"
            if unc:
                row += f"  {self.frequency_std[i]:>9.4f}"
            row += f"  {100 * self.damping_ratio[i]:>7.3f}"
            if unc:
                row += f"  {100 * self.damping_std[i]:>7.3f}"
                if self.noise_coupled is not None and self.noise_coupled[i]:
                    row += "  noise-coupled: no first-order std"
            lines.append(row)
        return "\n".join(lines)

    def __str__(self) -> str:
        if self.degenerate:
            return f"order {self.order}: no modes ({self.note})"
        flag = "  (order cuts close singular values: std not meaningful)" if self.close_singular_values else ""
        text = f"order {self.order}: {self.n_modes} modes{flag}\n{self.table()}"
        if self.has_uncertainty and self.n_modes:
            text += "\n" + interval_words(self.n_blocks)
        return text

    def __repr__(self) -> str:
        f = np.array2string(self.frequency_hz, precision=3, separator=", ")
        return f"Modes(order={self.order}, n_modes={self.n_modes}, frequency_hz={f})"


@dataclass(frozen=True, repr=False)
class Result:
    """What :func:`identify` returns: the modes at every requested order and the run's status."""

    modes: tuple                      #: tuple of :class:`Modes`, ascending order
    fs: float                         #: sampling frequency, Hz
    settings: dict                    #: every setting of the run, for the record
    singular_values: np.ndarray       #: of the subspace matrix H
    n_samples: int
    n_outputs: int
    n_inputs: int
    n_columns: int                    #: Hankel columns N
    n_blocks: int                     #: blocks of the uncertainty (0 without)
    block_length: int                 #: Hankel columns per block (0 without)
    channel_mean: np.ndarray          #: mean removed per channel [y, u]
    input_rank: int = 0               #: numerical rank of R3 (input/output only)
    input_condition: float = 0.0      #: condition number of R3 (input/output only)
    input_rank_deficient: bool = False
    too_few_blocks: bool = False
    numerical_rank: int = 0           #: singular values of H above max(a, b) eps s_1; higher orders are degenerate
    signal_to_noise: float = float("nan")  #: s_1 of H over its standard deviation (NaN without uncertainty)
    low_signal_to_noise: bool = False  #: signal_to_noise < 3: the modes cannot be told from estimation noise
    #: k*, the noise floor of H (docs/uq-math.md §5.5): singular values above their own estimation error;
    #: an estimate of the model order (0 without uncertainty)
    significant_singular_values: int = 0
    warnings: tuple = field(default_factory=tuple)
    output_names: tuple = ()          #: one name per output channel (default y0, y1, ...)
    #: per entry of ``warnings``, what it is about: an :class:`IdentificationWarning` for the core's
    #: (the first entries), None for those Python adds after them (horizons, chosen settings)
    warning_codes: tuple = ()
    #: the core's finding of poles decaying more slowly than the blocks are long; None when none is
    slow_decay: SlowDecay | None = None
    #: The core's ``Identification`` these modes were read from, set by :func:`identify` and
    #: ``CovarianceAccumulator.identify`` (:func:`result_from_core`): the diagram is made from it
    #: by the core (``_core.poles_of``). ``None`` for a Result made otherwise (by hand,
    #: ``dataclasses.replace``, unpickled): the diagram then flattens :attr:`modes`
    #: (:func:`modaluq.stabilization_diagram`).
    _identification: object = field(default=None, init=False, repr=False, compare=False)

    @property
    def orders(self) -> tuple:
        return tuple(m.order for m in self.modes)

    def at_order(self, order: int) -> Modes:
        """The modes identified at model order ``order`` (one of ``orders``)."""
        for m in self.modes:
            if m.order == order:
                return m
        raise ValueError(f"order {order} was not identified; identified orders: {list(self.orders)}")

    def __iter__(self):
        return iter(self.modes)

    @property
    def core_identification(self):
        """The core's ``Identification`` these modes were read from (``None`` for a Result made
        otherwise): what :func:`modaluq.stabilization_diagram` hands to ``_core.poles_of``."""
        return self._identification

    def __getstate__(self):
        # the core's objects do not pickle; a copy falls back to its modes (same numbers)
        state = dict(self.__dict__)
        state.pop("_identification", None)
        return state

    def __len__(self) -> int:
        return len(self.modes)

    def to_dataframe(self):
        """Every pole of every order, one row each (long format: order, mode, f, xi, std...)."""
        import pandas as pd

        frames = [m.to_dataframe(self.output_names or None).reset_index() for m in self.modes if m.n_modes]
        if not frames:
            return pd.DataFrame(columns=["order", "mode", "frequency_hz", "damping_ratio"])
        return pd.concat(frames, ignore_index=True)

    def stabilization_diagram(self, criteria=None, **kwargs):
        """The stabilization diagram of this run (see :func:`modaluq.stabilization_diagram`)."""
        return stabilization_diagram(self, criteria, **kwargs)

    def select_modes(self, criteria=None, settings=None):
        """Physical modes chosen automatically from the stable poles (see :func:`modaluq.select_modes`)."""
        return select_modes(self.stabilization_diagram(criteria), settings)

    def plot(self, ax=None, *, y=None, criteria=None, select: bool = True, **kwargs):
        """Draw the stabilization diagram with ±σ_f bars (over the output spectrum when ``y`` is given).

        ``select=True`` also marks the automatically selected modes. Returns the Figure.
        """
        diagram = self.stabilization_diagram(criteria)
        selected = None
        if check_boolean("select", select):
            selected = select_modes(diagram)
        return diagram.plot(ax, y=y, selected=selected, **kwargs)

    def _shape_source(self, mode: int, order, criteria, settings):
        """What :meth:`plot_shape` and :meth:`animate` draw: the selected modes (``order=None``) or
        the modes of one order, with the number of the mode in it."""
        if order is None:
            return self.select_modes(criteria, settings), mode
        if criteria is not None or settings is not None:
            raise ValueError("criteria and settings choose the selected modes: give them without order=")
        m = self.at_order(order)
        if not m.n_modes:
            raise ValueError(f"order {order} has no modes" + (f" ({m.note})" if m.note else ""))
        return _OrderShapes(m, self.output_names or tuple(f"y{k}" for k in range(self.n_outputs))), mode

    def plot_shape(self, mode: int, geometry, *, order=None, criteria=None, settings=None, ax=None, **kwargs):
        """Mode ``mode`` on ``geometry`` in 3-D with its ±2σ envelope (:func:`modaluq.shapes.plot_shape`).

        ``mode`` counts from 1 as in the tables: by default the automatically **selected** modes,
        as ``print(result)`` and :meth:`plot` number them (``criteria`` and ``settings`` as in
        :meth:`select_modes`); with ``order=n`` the poles of that model order, as
        ``print(result.at_order(n))`` numbers them (to look at a pole the selection left out).
        Returns the Figure."""
        from .shapes import plot_shape

        modes, k = self._shape_source(mode, order, criteria, settings)
        return plot_shape(modes, k, geometry, ax=ax, **kwargs)

    def animate(self, mode: int, geometry, *, path=None, order=None, criteria=None, settings=None, **kwargs):
        """Mode ``mode`` moving on ``geometry`` over one cycle, written to ``path`` (.gif, or .mp4
        with ffmpeg) when given (:func:`modaluq.shapes.animate_shape`); ``mode``, ``order``,
        ``criteria`` and ``settings`` as in :meth:`plot_shape`. Returns the animation."""
        from .shapes import animate_shape

        modes, k = self._shape_source(mode, order, criteria, settings)
        return animate_shape(modes, k, geometry, path=path, **kwargs)

    def __str__(self) -> str:
        kind = "input/output" if self.n_inputs else "output-only"
        lines = [
            f"modaluq SSI-cov ({kind}): {self.n_samples} samples at {self.fs:g} Hz, "
            f"{self.n_outputs} outputs" + (f", {self.n_inputs} inputs" if self.n_inputs else ""),
            f"block_rows={self.settings['block_rows']}, past_block_rows={self.settings['past_block_rows']}, "
            f"orders {self.orders[0]}..{self.orders[-1]} ({len(self.orders)}), "
            + (f"{self.n_blocks} blocks of {self.block_length} columns" if self.n_blocks else "no uncertainty"),
        ]
        lines += [f"warning: {w}" for w in self.warnings]
        if self.significant_singular_values:
            lines.append(f"noise floor: {self.significant_singular_values} significant singular values of H")
        if len(self.modes) <= 3:
            lines += [str(m) for m in self.modes]
            return "\n".join(lines)
        # A diagram: what an engineer reads from it is the selected modes, not its highest order.
        selected = None
        if self._has_modes():
            try:
                selected = self.stabilization_diagram().select_modes()
            except (ValueError, ImportError):  # e.g. SciPy missing: fall back to one order
                selected = None
        if selected is not None and selected.n_modes:
            lines.append(str(selected))
            lines.append(f"(selected from the stabilization diagram of {len(self.modes)} orders; "
                         "result.at_order(n) gives one order)")
        else:
            lines.append(f"no mode selected from the {len(self.modes)} orders; highest order shown "
                         "(result.at_order(n) gives the others)")
            lines.append(str(self.modes[-1]))
        return "\n".join(lines)

    def _has_modes(self) -> bool:
        """Whether any order has modes (a diagram can be formed)."""
        return any(m.n_modes for m in self.modes)

    def __repr__(self) -> str:
        return (f"Result(orders={list(self.orders)[:6]}{'...' if len(self.orders) > 6 else ''}, "
                f"n_samples={self.n_samples}, n_outputs={self.n_outputs}, n_inputs={self.n_inputs})")


@dataclass(frozen=True)
class _OrderShapes:
    """The modes of one order as :mod:`modaluq.shapes` takes them: with the channel names and
    each pole's covariance, titled "order n, mode k" (numbered as ``print(result.at_order(n))``)."""

    modes: Modes
    output_names: tuple

    def __getattr__(self, name):
        return getattr(self.modes, name)

    @property
    def mode_covariance(self):
        return self.modes.covariance

    @property
    def mode_labels(self) -> tuple:
        return tuple(f"order {self.modes.order}, mode {k + 1}" for k in range(self.modes.n_modes))


def result_from_core(ident, settings, n_outputs, n_inputs, extra_warnings=(), output_names=(), worded=None) -> Result:
    """The :class:`Result` of the core's ``Identification`` ``ident``, which it keeps. ``worded``
    maps an :class:`IdentificationWarning` to Python's sentence for it, in place of the core's
    (the code stays)."""
    codes = tuple(IdentificationWarning(c.name) for c in ident.warning_codes)
    core_words = tuple((worded or {}).get(c, w) for c, w in zip(codes, ident.warnings))
    result = Result(
        output_names=tuple(output_names) or tuple(f"y{k}" for k in range(n_outputs)),
        # each order's modes know the blocks behind their σ (their intervals' quantile)
        modes=tuple(dataclasses.replace(Modes._from_core(m), n_blocks=int(ident.n_blocks)) for m in ident.modes),
        fs=settings["fs"],
        settings=settings,
        singular_values=ident.singular_values,
        n_samples=int(ident.n_samples),
        n_outputs=n_outputs,
        n_inputs=n_inputs,
        n_columns=int(ident.n_columns),
        n_blocks=int(ident.n_blocks),
        block_length=int(ident.block_length),
        channel_mean=ident.channel_mean,
        input_rank=int(ident.input_rank),
        input_condition=float(ident.input_condition),
        input_rank_deficient=bool(ident.input_rank_deficient),
        too_few_blocks=bool(ident.too_few_blocks),
        numerical_rank=int(ident.numerical_rank),
        signal_to_noise=float(ident.signal_to_noise),
        low_signal_to_noise=bool(ident.low_signal_to_noise),
        significant_singular_values=int(ident.significant_singular_values),
        warnings=core_words + tuple(extra_warnings),
        warning_codes=codes + (None,) * len(extra_warnings),
        slow_decay=SlowDecay._from_core(ident.slow_decay),
    )
    object.__setattr__(result, "_identification", ident)
    return result


def warn_all(result: Result, stacklevel: int = 3) -> None:
    for w in result.warnings:
        warnings.warn(w, ModalUQWarning, stacklevel=stacklevel)
