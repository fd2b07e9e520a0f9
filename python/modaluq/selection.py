"""Automatic mode selection: the stable poles of a diagram grouped into physical modes.

:func:`select_modes` groups the stable poles by agglomerative hierarchical clustering (average
linkage) on the distance ``|f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)``, cut at
``distance_threshold`` (:class:`~modaluq.ClusteringSettings`); clusters with fewer than
``min_cluster_size`` members, or whose frequency is less certain than the half-power bandwidth
of the peak they claim, are dropped (and listed with the reason), and each remaining cluster is
reported at one representative pole, with the analytic standard deviation of its reliable
poles (their median for one record, the σ of their mean for a multi-setup merge:
``ClusteringSettings.cluster_std``) next to the spread of its members.

The clustering runs in the C++ core (``cpp/include/modaluq/selection.hpp``); this module
translates its result into :class:`SelectedModes`. The core says why a cluster was dropped
by a code (:class:`DropReason`) and the numbers behind it; :func:`dropped_reason_text` words
them (docs/architecture.md, "the seam").
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass, field

import numpy as np

from . import _core
from .indicators import mac_matrix, mean_phase_deviation, modal_phase_collinearity, shape_covariance
from .intervals import interval_factor, interval_table, interval_words
from .settings import ClusteringSettings

__all__ = ["DropReason", "SelectedModes", "default_cluster_std", "dropped_reason_text", "select_modes"]

#: ``ClusteringSettings.cluster_std`` in words, for tables and exports
CLUSTER_STD_WORDS = {"median": "median over the cluster", "mean": "of the mean over the cluster"}
#: the words with ``ClusteringSettings.representative == "lowest"`` (the mode is one pole, σ included)
LOWEST_STD_WORDS = "the pole's own, at the lowest sufficient order"


def default_cluster_std(diagram) -> str:
    """``ClusteringSettings.cluster_std`` when it is None, for the poles of ``diagram``: ``"mean"``
    for a multi-setup merge (:func:`modaluq.identify_setups`, whose ``Result.settings`` lists the
    setups), whose poles decorrelate across orders (docs/uq-math.md §13.10), else ``"median"``
    (one record, the core's default)."""
    settings = getattr(diagram, "result_settings", None)
    return "mean" if isinstance(settings, dict) and settings.get("setups") else "median"


class DropReason(str, enum.Enum):
    """Why :func:`select_modes` dropped a cluster (the core's ``DropReason``, selection.hpp)."""

    #: fewer poles (one per order) than the minimum size: ``dropped_n_poles < dropped_min_size``
    TOO_FEW_POLES = "too_few_poles"
    #: median σ_f / (f ξ) above ``max_frequency_std_per_bandwidth``: the frequency is less certain
    #: than the peak's half-power bandwidth
    FREQUENCY_STD_ABOVE_BANDWIDTH = "frequency_std_above_bandwidth"
    #: a twin of a kept mode (same shape, close in frequency, from higher orders): ``dropped_twin_*``
    TWIN = "twin"
    #: a lightly damped twin born of the noise (``drop_noise_twins``: less than half as damped as a kept
    #: mode, inside its half-power band, first seen above the noise floor): ``dropped_twin_*`` as for TWIN
    NOISE_TWIN = "noise_twin"

    def __str__(self) -> str:
        return self.value


def _percent(x: float) -> str:
    return "%.3g %%" % (100.0 * x)  # as the core's detail::percent


def dropped_reason_text(sel: "SelectedModes", k: int) -> str:
    """Why dropped cluster ``k`` of ``sel`` was dropped, in words, from its code and numbers
    (the words of selection.hpp's ``dropped_reason``)."""
    code = sel.dropped_code[k]
    if code is DropReason.TOO_FEW_POLES:
        n = int(sel.dropped_n_poles[k])
        return f"{n} {'pole' if n == 1 else 'poles'}, fewer than {int(sel.dropped_min_size[k])}"
    if code is DropReason.FREQUENCY_STD_ABOVE_BANDWIDTH:
        return ("frequency std %.3g x the half-power bandwidth f xi (more than %g)"
                % (sel.dropped_frequency_std_per_bandwidth[k], sel.max_frequency_std_per_bandwidth))
    if code in (DropReason.TWIN, DropReason.NOISE_TWIN):
        f, twin_f = float(sel.dropped_frequency_hz[k]), float(sel.dropped_twin_frequency_hz[k])
        away, first, twin_first = (_percent(abs(f - twin_f) / twin_f), sel.dropped_first_order[k],
                                   sel.order_min[int(sel.dropped_twin_mode[k])])
        if code is DropReason.TWIN:
            return ("a twin of the %.4g Hz mode: same shape (MAC %.2f), %s away, from order %d (the mode from order %d)"
                    % (twin_f, sel.dropped_twin_mac[k], away, first, twin_first))
        return ("a lightly damped twin of the %.4g Hz mode born of the noise: less than half as damped, inside its "
                "half-power band (%s away), from order %d above the noise floor (the mode from order %d)"
                % (twin_f, away, first, twin_first))
    raise ValueError(f"dropped_code[{k}] is not a DropReason: {code!r}")


def largest_dropped_clusters(sel: "SelectedModes", most: int = 8) -> list[str]:
    """Lines listing the largest dropped clusters of ``sel`` with why (what a person checks
    against the diagram): clusters of at least max(3, min_cluster_size / 2) poles, and every
    one dropped for its frequency std; empty when there is none."""
    dropped = sorted(zip(sel.dropped_n_poles, sel.dropped_frequency_hz, sel.dropped_reason, sel.dropped_code),
                     key=lambda t: (-t[0], t[1]))
    shown = [d for d in dropped if d[0] >= max(3, sel.min_cluster_size // 2)
             or d[3] is DropReason.FREQUENCY_STD_ABOVE_BANDWIDTH][:most]
    if not shown:
        return []
    return [f"dropped clusters ({len(dropped)} in all; the largest):"] + \
        [f"  {f:.4g} Hz: {why}" for _, f, why, _ in sorted(shown, key=lambda t: t[1])]


@dataclass(frozen=True, repr=False)
class SelectedModes:
    """Physical modes chosen automatically from a :class:`Diagram`, sorted by frequency.

    Each mode is one cluster of poles. Its ``frequency_hz`` and ``damping_ratio`` are those of
    one **representative** pole, its ``mode_shape`` and the shape's σ those of the **shape pole**
    (by default the cluster's pole at the lowest sufficient order, or the representative where it
    is lower and holds every selected mode, ``settings.shape_representative``; analytic, delta-method σ at
    ``shape_order``); ``frequency_std`` and ``damping_std`` are the cluster's
    (``settings.cluster_std``: the median of its reliable poles' σ, or the σ of their mean),
    widened where the model order moves the estimate beyond them (``order_discrepancy``);
    the ``*_spread`` fields are the sample standard deviations (ddof=1) across the cluster's
    members, a measure of the order-to-order scatter shown beside the analytic σ (0 for a
    single member).
    """

    frequency_hz: np.ndarray           #: (n_modes,) Hz
    damping_ratio: np.ndarray          #: (n_modes,) fraction
    mode_shape: np.ndarray             #: (n_outputs, n_modes) complex, largest component 1
    #: (n_modes,) Hz, analytic: over the cluster's reliable poles, their median σ or the σ of their
    #: mean (``settings.cluster_std``; NaN without uncertainty), widened where :attr:`order_discrepancy`
    frequency_std: np.ndarray
    damping_std: np.ndarray            #: (n_modes,) fraction, analytic, as ``frequency_std``
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
    dropped_reason: tuple = ()         #: why each cluster was dropped, in words (:func:`dropped_reason_text`)
    #: (n_modes,) median σ_f / (f ξ) over the cluster (NaN without uncertainty)
    frequency_std_per_bandwidth: np.ndarray = field(default_factory=lambda: np.zeros(0))
    dropped_code: tuple = ()           #: why each cluster was dropped, a :class:`DropReason`
    #: the minimum size that applied to each dropped cluster
    dropped_min_size: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: lowest order of each dropped cluster
    dropped_first_order: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: median σ_f / (f ξ) of each dropped cluster (NaN where not judged: no uncertainty or no limit)
    dropped_frequency_std_per_bandwidth: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: DropReason.TWIN, NOISE_TWIN: the mode (index from 0 into these arrays) the cluster is a twin of, else -1
    dropped_twin_mode: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: DropReason.TWIN, NOISE_TWIN: that mode's median frequency over its cluster, Hz, else NaN
    dropped_twin_frequency_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: DropReason.TWIN, NOISE_TWIN: MAC between the two clusters' shapes, else NaN
    dropped_twin_mac: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: the limit on σ_f / (f ξ) applied (NaN: no such test, or no uncertainty)
    max_frequency_std_per_bandwidth: float = float("nan")
    #: (n_modes,) correlation of f and ξ (NaN without uncertainty): with ``frequency_std`` and
    #: ``damping_std``, the covariance of [f, ξ]. That of the representative pole, or with
    #: ``settings.cluster_std == "mean"`` that of the members' mean (from the same factor rows)
    frequency_damping_correlation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (n_modes,) bool, the blocks are shorter than half the representative pole's decay time
    #: 1/(2π f ξ) (the core's ``block_too_short``): its σ are less reliable
    block_too_short: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    #: (n_modes,) bool, every pole of the mode's cluster is noise-coupled (``Diagram.noise_coupled``:
    #: no first-order σ, docs/uq-math.md §5.5): a column that may be noise, not a mode. Such a
    #: cluster is still selected (a weak physical mode below the noise floor looks the same: the
    #: simulated chain's 1.93 Hz mode on 20,000 samples); tables mark it, exports carry the flag.
    noise_coupled: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    #: (n_modes,) bool, ``frequency_std`` or ``damping_std`` was widened by the difference between
    #: the representative and the cluster's lowest sufficient member, which exceeded 1.96 of their
    #: combined σ (``settings.order_discrepancy``): the estimate moves with the model order
    order_discrepancy: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    #: (n_modes,) bool, every reliable pole of the mode depends on the frozen noise directions
    #: (``Diagram.noise_coupling`` above ``settings.unanchored_noise_coupling`` at every order: the
    #: noise floor k* is below the mode's own singular values): ``frequency_std`` and ``damping_std``
    #: are at least the poles' median ρ σ, the unfrozen σ's bound
    unanchored: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    #: (n_modes, 2+2l, 2+2l) covariance of [f, ξ, Re shape, Im shape] of each shape pole
    #: (``Diagram.pole_covariance``; the representative's when ``shape_representative`` is
    #: ``"median"``), or None without uncertainty. With ``settings.cluster_std == "mean"``, a shape
    #: pole other than the representative, or σ widened (:attr:`order_discrepancy`, :attr:`unanchored`), its f and ξ
    #: entries are the mode's: the [f, ξ] block from
    #: ``frequency_std``, ``damping_std`` and ``frequency_damping_correlation``, and their
    #: covariance with the shape the pole's correlation at those σ (the mean is formed for f and ξ only).
    mode_covariance: np.ndarray | None = None
    #: (n_modes, 2l, n_blocks) each shape pole's first-order factor of [Re shape, Im shape]
    #: (``Diagram.pole_shape_factor``): the exact σ of the AutoMAC (:meth:`mac_matrix`). None unless
    #: the identification kept it (``keep_shape_factor=True``)
    mode_shape_factor: np.ndarray | None = None
    #: (n_modes,) modal phase collinearity of each shape (1: real, 0: circular) and its σ
    #: (second order, :mod:`modaluq.indicators`; NaN without ``mode_covariance``)
    mpc: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mpc_std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (n_modes,) mean phase deviation of each shape, degrees (0: real), and its first-order σ
    mpd_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mpd_std_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: the identification's ``Result.low_signal_to_noise``: H is within 3 σ of its own estimation
    #: noise, so any of these modes may be noise (the table's heading says so)
    low_signal_to_noise: bool = False
    #: (n_modes,) index in the diagram of the pole whose shape and shape σ the mode reports
    #: (``settings.shape_representative``): by default the lowest sufficient member (the
    #: representative where it is lower and of order ≥ 2 m), with ``"median"`` ``representative_pole``
    shape_pole: np.ndarray | None = None
    shape_order: np.ndarray | None = None  #: (n_modes,) its model order
    #: blocks the σ were estimated from (``Result.n_blocks``, the core's count): an interval x ± t σ
    #: takes the Student-t quantile with ``n_blocks − 1`` degrees of freedom (:meth:`intervals`).
    #: (PoSER's merged modes: the fewest of a setup). 0: unknown (made by hand) or no uncertainty:
    #: the normal quantile
    n_blocks: int = 0

    #: the columns of the 95 % intervals in :meth:`to_dataframe` and the exports (:meth:`intervals`)
    INTERVAL_95_COLUMNS = ("frequency_low_95_hz", "frequency_high_95_hz", "damping_low_95", "damping_high_95")
    #: the heading of :meth:`__str__` when :attr:`low_signal_to_noise`
    LOW_SIGNAL_TO_NOISE_HEADING = ("H is within 3 std of its estimation noise: these modes cannot be told from "
                                   "noise and may all be noise")
    #: the legend line below a table that marks noise-coupled modes
    NOISE_COUPLED_LEGEND = ("noise?: every pole of the mode is noise-coupled (below the noise floor of H, no "
                            "first-order std): noise, or a mode too weak to tell from it (docs/settings.md)")
    #: the legend line below a table that marks modes whose σ the model order widened
    ORDER_DISCREPANCY_LEGEND = ("widened: f or xi at the representative's order and at the lowest sufficient "
                                "order differ by more than 1.96 of the two poles' combined std; the std includes "
                                "that difference (order_discrepancy, docs/settings.md)")
    #: the legend line below a table that marks unanchored modes
    UNANCHORED_LEGEND = ("rho*std: every pole of the mode depends on the frozen noise directions (the noise floor k* "
                         "is below the mode); its std are the unfrozen bound rho*std (unanchored_noise_coupling, "
                         "docs/settings.md)")

    def __post_init__(self):
        # one flag per mode; unknown (a SelectedModes made by hand without it): none flagged
        for name in ("noise_coupled", "order_discrepancy", "unanchored"):
            flags = np.asarray(getattr(self, name), bool)
            if flags.shape != np.shape(self.frequency_hz):
                flags = np.zeros(np.shape(self.frequency_hz), bool)
            object.__setattr__(self, name, flags)
        # unknown (made by hand): the shape is the representative's
        if self.shape_pole is None:
            object.__setattr__(self, "shape_pole", np.asarray(self.representative_pole, np.int64))
        if self.shape_order is None:
            object.__setattr__(self, "shape_order", np.asarray(self.representative_order, np.int64))
        for name in ("mpc", "mpc_std", "mpd_deg", "mpd_std_deg"):  # unknown: NaN per mode
            values = np.asarray(getattr(self, name), float)
            if values.shape != np.shape(self.frequency_hz):
                values = np.full(np.shape(self.frequency_hz), np.nan)
            object.__setattr__(self, name, values)

    @property
    def n_modes(self) -> int:
        return int(self.frequency_hz.size)

    def interval_factor(self, level: float = 0.95) -> float:
        """The factor t of the ``level`` intervals x ± t σ (:func:`modaluq.intervals.interval_factor`):
        the Student-t quantile with ``n_blocks − 1`` degrees of freedom, since each σ is estimated
        from ``n_blocks`` blocks (2.14 at 15 blocks, 2.01 at 50); the normal 1.96 when
        ``n_blocks`` is unknown (0)."""
        return interval_factor(self.n_blocks, level)

    def intervals(self, level: float = 0.95):
        """The ``level`` confidence intervals of f and ξ, one row per mode (numbered from 1):
        ``frequency_low_hz``, ``frequency_high_hz`` (Hz), ``damping_low``, ``damping_high``
        (fraction), x ± t σ with t = :meth:`interval_factor`. With σ from ``n_blocks`` blocks
        they cover ``level`` where x ± 1.96 σ covers less (93.0 % at 15 blocks); NaN without
        uncertainty (docs/uq-math.md §14)."""
        return interval_table(self.frequency_hz, self.frequency_std, self.damping_ratio, self.damping_std,
                              self.interval_factor(level))

    def interval_words(self, level: float = 0.95) -> str:
        """The line under the tables that says how to read a ``level`` interval from them."""
        return interval_words(self.n_blocks, level)

    def __len__(self) -> int:
        return self.n_modes

    def to_dataframe(self):
        """One row per mode, numbered from 1 (the index ``mode``, as in every table, plot and
        export): f, σ_f, spread, ξ, σ_ξ, spread, the 95 % intervals (``frequency_low_95_hz`` ...,
        :meth:`intervals`), cluster size and orders, and the shape per
        channel in columns ``mode_shape_<channel>_real`` ...; ``noise_coupled`` flags a mode every
        pole of which is noise-coupled (:attr:`noise_coupled`), ``order_discrepancy`` one whose σ
        the model order widened (:attr:`order_discrepancy`), ``low_signal_to_noise`` (the same
        in every row) an identification whose modes cannot be told from noise."""
        import pandas as pd

        data = {
            "frequency_hz": self.frequency_hz, "frequency_std": self.frequency_std,
            "frequency_spread": self.frequency_spread,
            "damping_ratio": self.damping_ratio, "damping_std": self.damping_std,
            "damping_spread": self.damping_spread,
            # the 95 % intervals x ± t σ (intervals(): the Student-t quantile of the blocks)
            **dict(zip(self.INTERVAL_95_COLUMNS, self.intervals(0.95).to_numpy().T)),
            "representative_order": self.representative_order, "shape_order": self.shape_order,
            "n_poles": self.n_poles,
            "order_min": self.order_min, "order_max": self.order_max, "min_mac": self.min_mac,
            "noise_coupled": self.noise_coupled, "order_discrepancy": self.order_discrepancy,
            "mpc": self.mpc, "mpc_std": self.mpc_std, "mpd_deg": self.mpd_deg, "mpd_std_deg": self.mpd_std_deg,
            "low_signal_to_noise": np.full(self.n_modes, bool(self.low_signal_to_noise)),
        }
        for k, name in enumerate(self.output_names):
            data[f"mode_shape_{name}_real"] = self.mode_shape[k].real
            data[f"mode_shape_{name}_imag"] = self.mode_shape[k].imag
            data[f"mode_shape_{name}_std_real"] = self.mode_shape_std_real[k]
            data[f"mode_shape_{name}_std_imag"] = self.mode_shape_std_imag[k]
        return pd.DataFrame(data, index=pd.RangeIndex(1, self.n_modes + 1, name="mode"))

    def to_dict(self) -> dict:
        """Plain-Python (JSON-ready) description (see :func:`modaluq.export.selected_modes_to_dict`)."""
        from .export import selected_modes_to_dict

        return selected_modes_to_dict(self)

    def table(self) -> str:
        """Plain-text table: f and ξ with their analytic σ and the spread across the cluster; a
        mode every pole of which is noise-coupled is marked ``noise?`` after its row, one whose σ the
        model order widened (:attr:`order_discrepancy`) ``widened``, each with a legend line below
        (nothing is added when no mode is)."""
        head = (f"{'mode':>4}  {'f [Hz]':>9}  {'std f':>8}  {'spread f':>8}  {'xi [%]':>7}  "
                f"{'std xi':>7}  {'spread xi':>9}  {'order':>5}  {'poles':>5}")
        def cell(x, width, digits):
            return f"{x:>{width}.{digits}f}" if np.isfinite(x) else f"{'-':>{width}}"

        lines = [head]
        flags = self.noise_coupled
        for i in range(self.n_modes):
            lines.append(
                f"{i + 1:>4}  {self.frequency_hz[i]:>9.4f}  {cell(self.frequency_std[i], 8, 4)}  "
                f"{cell(self.frequency_spread[i], 8, 4)}  {100 * self.damping_ratio[i]:>7.3f}  "
                f"{cell(100 * self.damping_std[i], 7, 3)}  {cell(100 * self.damping_spread[i], 9, 3)}  "
                f"{int(self.representative_order[i]):>5}  {int(self.n_poles[i]):>5}"
                + ("  noise?" if flags[i] else "") + ("  widened" if self.order_discrepancy[i] else "")
                + ("  rho*std" if self.unanchored[i] else ""))
        if flags.any():
            lines.append(self.NOISE_COUPLED_LEGEND)
        if self.order_discrepancy.any():
            lines.append(self.ORDER_DISCREPANCY_LEGEND)
        if self.unanchored.any():
            lines.append(self.UNANCHORED_LEGEND)
        if self.has_uncertainty and self.n_modes:
            lines.append(self.interval_words())
        return "\n".join(lines)

    @property
    def std_words(self) -> str:
        """How ``frequency_std`` and ``damping_std`` were formed, in words ("median over the cluster")."""
        if self.settings.representative == "lowest":
            return LOWEST_STD_WORDS
        return CLUSTER_STD_WORDS.get(self.settings.cluster_std, CLUSTER_STD_WORDS["median"])

    def __str__(self) -> str:
        s = f"{self.n_modes} modes (std: analytic, {self.std_words}; spread: across the cluster)\n"
        if self.low_signal_to_noise:
            s = f"{self.n_modes} modes ({self.LOW_SIGNAL_TO_NOISE_HEADING}; std: analytic, {self.std_words}; " \
                "spread: across the cluster)\n"
        s += self.table()
        if self.settings.shape_representative == "lowest" and self.settings.representative != "lowest":
            s += ("\nshapes: each cluster's pole at the lowest sufficient order (the representative's where lower "
                  "and of order >= 2 x modes), with its own std (orders "
                  + ", ".join(str(int(o)) for o in self.shape_order) + ")")
        if self.dropped_n_poles.size:
            # counted by the core's code of each
            too_small = self.dropped_code.count(DropReason.TOO_FEW_POLES)
            too_uncertain = self.dropped_code.count(DropReason.FREQUENCY_STD_ABOVE_BANDWIDTH)
            twins = self.dropped_code.count(DropReason.TWIN)
            noise_twins = self.dropped_code.count(DropReason.NOISE_TWIN)
            parts = []
            if too_small:
                parts.append(f"{too_small} with fewer than {self.min_cluster_size} poles")
            if too_uncertain:
                parts.append(f"{too_uncertain} whose frequency std exceeds the peak's half-power bandwidth")
            if twins:
                parts.append(f"{twins} twin{'' if twins == 1 else 's'} of a selected mode")
            if noise_twins:
                parts.append(f"{noise_twins} lightly damped twin{'' if noise_twins == 1 else 's'} born of the noise")
            s += f"\n{self.dropped_n_poles.size} cluster(s) dropped: " + ", ".join(parts)
        return s

    def __repr__(self) -> str:
        f = np.array2string(self.frequency_hz, precision=3, separator=", ")
        return f"SelectedModes(n_modes={self.n_modes}, frequency_hz={f})"

    def plot_shape(self, mode: int, geometry, *, ax=None, **kwargs):
        """Mode ``mode`` (from 1, as in the tables) on ``geometry`` in 3-D with its ±2σ envelope;
        see :func:`modaluq.shapes.plot_shape`. Returns the Figure."""
        from .shapes import plot_shape

        return plot_shape(self, mode, geometry, ax=ax, **kwargs)

    def animate(self, mode: int, geometry, *, path=None, **kwargs):
        """Mode ``mode`` (from 1) moving on ``geometry`` over one cycle; written to ``path`` (.gif,
        or .mp4 with ffmpeg) when given. See :func:`modaluq.shapes.animate_shape`. Returns the animation."""
        from .shapes import animate_shape

        return animate_shape(self, mode, geometry, path=path, **kwargs)

    def mac_matrix(self):
        """The AutoMAC of these modes with the σ of each entry (:func:`modaluq.indicators.mac_matrix`):
        exact with ``mode_shape_factor`` (``identify(..., keep_shape_factor=True)``), else with the
        cross-covariance of two modes taken as 0."""
        return mac_matrix(self.mode_shape, self.mode_covariance, self.mode_shape_factor)

    def plot_mac(self, ax=None, **kwargs):
        """The AutoMAC with ±1σ per cell; see :func:`modaluq.plot.plot_mac`. Returns the Figure."""
        from .plot import plot_mac

        return plot_mac(self, ax, **kwargs)

    def plot(self, fig=None, *, channel_positions=None):
        """Mode shapes with ±σ error bars; see :func:`modaluq.plot.plot_mode_shapes`. Returns the Figure."""
        from .plot import plot_mode_shapes

        return plot_mode_shapes(self, fig=fig, channel_positions=channel_positions)


def select_modes(diagram, settings: ClusteringSettings | None = None, **kwargs) -> SelectedModes:
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
       reported in ``dropped_frequency_hz`` / ``dropped_n_poles`` / ``dropped_code`` (a
       :class:`DropReason`, with the numbers in ``dropped_*``) / ``dropped_reason`` (in words);
    6. the representative of a cluster is its member nearest to the cluster's median frequency
       among the members at orders that do **not** cut close singular values (whose σ are
       meaningful), or among all members when every member's order does; ties go to the higher
       order. Its frequency, damping ratio and shape are reported; the ``frequency_std`` and
       ``damping_std`` reported are the cluster's, from its **reliable poles** (not at a close
       cut, not noise-coupled; when most of the cluster is noise-coupled, the coupled poles count
       too, with their unfrozen σ, for the representative and the shape pole as well), so that
       they do not depend on the order the mode is read at:
       the median of their σ (``settings.cluster_std="median"``, one record's default) or the σ
       of their mean (``"mean"``, a multi-setup merge's default: its poles decorrelate across
       orders and the representative scatters like their mean, docs/uq-math.md §13.10); the
       ``*_spread`` beside them is how much the estimate moves with the order. Where the
       representative's f or ξ and the lowest sufficient member's differ by more than 1.96 of
       the two poles' combined σ, the difference is added to the σ in quadrature
       (``settings.order_discrepancy``, :attr:`SelectedModes.order_discrepancy`).
    7. a mode every member of which is noise-coupled is flagged (:attr:`SelectedModes.noise_coupled`,
       from ``Diagram.noise_coupled`` of its members), not dropped: the selection does not change.

    Noise-coupled poles (``Diagram.noise_coupled``, docs/uq-math.md §5.5) are clustered (a weak
    physical mode below the noise floor has them at every order) but give the σ only where they
    are most of their cluster.

    Parameters
    ----------
    diagram : Diagram
        From :func:`stabilization_diagram`.
    settings : ClusteringSettings, optional
        Or its fields as keyword arguments (``distance_threshold=0.03`` ...). Its
        ``cluster_std=None`` (default) becomes :func:`default_cluster_std` of the diagram, the
        value the returned ``settings`` hold.

    Returns
    -------
    SelectedModes
        Sorted by frequency; empty when no pole qualifies.
    """
    # the core's diagram, kept by stabilization_diagram (stabilization.py sits above this module)
    core_diagram = getattr(diagram, "core_diagram", None)
    if not isinstance(core_diagram, _core.Diagram):
        raise TypeError(f"diagram must be a Diagram made by stabilization_diagram (a constructed, copied or "
                        f"unpickled one is not: make it again with stabilization_diagram(result)); "
                        f"got {type(diagram).__name__}")
    if settings is None:
        settings = ClusteringSettings(**kwargs)
    elif kwargs:
        raise TypeError("pass either settings= or its fields as keyword arguments, not both")
    elif not isinstance(settings, ClusteringSettings):
        raise TypeError(f"settings must be a ClusteringSettings; got {type(settings).__name__}")
    if settings.cluster_std is None:
        settings = dataclasses.replace(settings, cluster_std=default_cluster_std(diagram))

    sel = _core.select_modes(core_diagram, settings.to_core())
    modes = SelectedModes(
        frequency_hz=sel.frequency_hz, damping_ratio=sel.damping_ratio, mode_shape=sel.mode_shape,
        frequency_std=sel.frequency_std, damping_std=sel.damping_std,
        mode_shape_std_real=sel.mode_shape_std_real, mode_shape_std_imag=sel.mode_shape_std_imag,
        frequency_spread=sel.frequency_spread, damping_spread=sel.damping_spread,
        mode_shape_spread_real=sel.mode_shape_spread_real, mode_shape_spread_imag=sel.mode_shape_spread_imag,
        min_mac=sel.min_mac, representative_order=np.asarray(sel.representative_order, np.int64),
        representative_pole=np.asarray(sel.representative_pole, np.int64),
        shape_pole=np.asarray(sel.shape_pole, np.int64), shape_order=np.asarray(sel.shape_order, np.int64),
        n_poles=np.asarray(sel.n_poles, np.int64), order_min=np.asarray(sel.order_min, np.int64),
        order_max=np.asarray(sel.order_max, np.int64),
        members=tuple(np.asarray(m, dtype=np.int64) for m in sel.members),
        mode_of_pole=np.asarray(sel.mode_of_pole, np.int64),
        dropped_frequency_hz=sel.dropped_frequency_hz, dropped_n_poles=np.asarray(sel.dropped_n_poles, np.int64),
        min_cluster_size=int(sel.min_cluster_size), output_names=diagram.output_names, settings=settings,
        has_uncertainty=diagram.has_uncertainty,
        frequency_std_per_bandwidth=sel.frequency_std_per_bandwidth,
        dropped_code=tuple(DropReason(c.name) for c in sel.dropped_code),
        dropped_min_size=np.asarray(sel.dropped_min_size, np.int64),
        dropped_first_order=np.asarray(sel.dropped_first_order, np.int64),
        dropped_frequency_std_per_bandwidth=sel.dropped_frequency_std_per_bandwidth,
        dropped_twin_mode=np.asarray(sel.dropped_twin_mode, np.int64),
        dropped_twin_frequency_hz=sel.dropped_twin_frequency_hz, dropped_twin_mac=sel.dropped_twin_mac,
        max_frequency_std_per_bandwidth=float(sel.max_frequency_std_per_bandwidth),
        frequency_damping_correlation=sel.frequency_damping_correlation,
        block_too_short=np.asarray(sel.block_too_short, bool),
        order_discrepancy=np.asarray(sel.order_discrepancy, bool),
        unanchored=np.asarray(sel.unanchored, bool),
        # from the diagram's per-pole flags: every member of the cluster noise-coupled
        noise_coupled=np.array([m.size > 0 and bool(np.asarray(diagram.noise_coupled, bool)[m].all())
                                for m in (np.asarray(m, np.int64) for m in sel.members)], dtype=bool),
        low_signal_to_noise=bool(getattr(diagram, "low_signal_to_noise", False)),
        n_blocks=int(diagram.n_blocks),  # 0 without uncertainty (stabilization_diagram)
    )
    # the words from the codes and numbers (the core's own words are for its C++ users)
    reasons = tuple(dropped_reason_text(modes, k) for k in range(len(modes.dropped_code)))
    return dataclasses.replace(modes, dropped_reason=reasons, **_shape_indicators(diagram, modes))


def _shape_indicators(diagram, modes: SelectedModes) -> dict:
    """The covariances of the shape poles (by default the lowest sufficient members,
    ``shape_representative``; from the diagram's identification) and the MPC and MPD of every selected shape
    with their σ. Where the f and ξ come from another pole, or from the cluster's mean, the
    covariance's [f, ξ] block is the mode's (:func:`_with_cluster_std`)."""
    covs = None
    pole_covariance = getattr(diagram, "pole_covariance", None)
    if modes.n_modes and modes.has_uncertainty and pole_covariance is not None:
        found = [pole_covariance(int(p)) for p in modes.shape_pole]
        if all(c is not None for c in found):
            covs = np.stack(found)
            # per mode: one whose shape pole is its representative keeps that pole's covariance,
            # unless its σ are the cluster mean's, were widened by the model order or raised to ρσ
            which = (np.asarray(modes.shape_pole) != np.asarray(modes.representative_pole)) | (
                modes.settings.cluster_std == "mean") | modes.order_discrepancy | modes.unanchored
            covs = _with_cluster_std(covs, modes, which)
    factors = None
    pole_shape_factor = getattr(diagram, "pole_shape_factor", None)
    if covs is not None and pole_shape_factor is not None:
        found = [pole_shape_factor(int(p)) for p in modes.shape_pole]
        if all(v is not None for v in found):
            factors = np.stack(found)
    mpc, mpd = [], []
    for k in range(modes.n_modes):
        shape_cov = None if covs is None else shape_covariance(covs[k])
        mpc.append(modal_phase_collinearity(modes.mode_shape[:, k], shape_cov))
        mpd.append(mean_phase_deviation(modes.mode_shape[:, k], shape_cov))
    return dict(mode_covariance=covs, mode_shape_factor=factors,
                mpc=np.array([m.value for m in mpc]), mpc_std=np.array([m.std for m in mpc]),
                mpd_deg=np.array([m.value for m in mpd]), mpd_std_deg=np.array([m.std for m in mpd]))


def _with_cluster_std(covs: np.ndarray, modes: SelectedModes, which: np.ndarray) -> np.ndarray:
    """The shape poles' covariances ``covs`` with, for the modes ``which``, their f and ξ entries
    the modes': the [f, ξ] block from ``frequency_std``, ``damping_std`` and
    ``frequency_damping_correlation``, and the f and ξ rows against the shape scaled from the
    pole's σ to the mode's (the pole's correlations with its shape kept)."""
    out = covs.copy()
    for k in np.flatnonzero(which):
        sf, sx, rho = modes.frequency_std[k], modes.damping_std[k], modes.frequency_damping_correlation[k]
        own = np.sqrt(np.clip(np.diag(covs[k])[:2], 0.0, None))
        scale = np.divide([sf, sx], own, out=np.zeros(2), where=own > 0)
        out[k, :2, 2:] *= scale[:, None]
        out[k, 2:, :2] *= scale[None, :]
        out[k, 0, 0], out[k, 1, 1] = sf * sf, sx * sx
        out[k, 0, 1] = out[k, 1, 0] = (rho if np.isfinite(rho) else 0.0) * sf * sx
    return out
