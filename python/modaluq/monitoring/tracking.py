"""Mode tracking over many records, using each estimate's covariance (docs/monitoring.md §3).

A record's selected modes (:class:`RecordModes`) are assigned to **reference modes** learned from
a reference period (:func:`reference_period`); :func:`track` does both for a whole batch and puts
every record's modes on the reference modes' axis (:class:`Tracks`), which the change test
(:mod:`modaluq.monitoring.change`) and the store (:mod:`modaluq.monitoring.store`) read:

1. **Reference modes** (:func:`reference_modes`): the modes of the reference records are pooled
   and clustered on ``|Δf|/f + (1 - MAC)`` (average linkage, cut at
   ``TrackingSettings.reference_distance``); a cluster found in at least ``min_presence`` of the
   reference records is a reference mode. Its frequency, damping and shape are the cluster's
   medians; the **environmental scatter** is the part of the cluster's variance that the
   records' σ do not explain (temperature moves a frequency far more than its σ).
2. **Assignment** (:func:`assign`): cost = Mahalanobis distance between a record's mode and a
   reference mode on f, ξ and the shape (the shape aligned by a complex scale, each component
   with its σ), with the record's σ², the reference's σ² and the environmental scatter as
   variance; pairs with MAC < ``min_mac`` or ``|Δf|/f > max_frequency_deviation`` are
   forbidden; :func:`scipy.optimize.linear_sum_assignment` gives the cheapest one-to-one
   assignment. Unassigned modes stay with the record (``-1``).
3. **The shape test** (:func:`shape_test`): each assigned mode's shape against its reference
   mode's mean shape by the "same mode" test of two shapes (:func:`modaluq.indicators.mac_test`:
   is the MAC consistent with 1 given both shapes' σ and the environmental scatter?). Its p-value
   is kept per record and mode; below ``false_alarm_rate`` after the reference period it is a
   **shape alarm**: the shape changed by more than its σ and the environment explain. The
   gate stays the fixed ``min_mac``: a damaged mode's shape is no longer "the same" within σ, and
   it must stay tracked (docs/monitoring.md §3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize

from .. import _core
from ..checks import check_boolean, check_integer, check_real
from ..indicators import MacTest, mac_test
from ..stabilization import modal_assurance_criterion

__all__ = ["RecordModes", "ReferenceModes", "Tracks", "TrackingSettings", "after_reference", "assign",
           "reference_modes", "reference_period", "shape_test", "track"]

#: Variance floor of a shape component (the normalised component has σ = 0).
SHAPE_VARIANCE_FLOOR = 1e-6


@dataclass(frozen=True)
class TrackingSettings:
    """How records are tracked and tested (docs/monitoring.md §3, §4).

    Attributes
    ----------
    reference_records : int, default 20
        The first K records identified form the reference period (unless ``reference_span``).
    reference_span : (start, end), optional
        The records whose time lies in this span (inclusive; strings, ``datetime64`` or
        ``datetime``, anything :class:`numpy.datetime64` reads) form the reference period instead.
    min_mac : float, default 0.8
        Gate of the assignment: the smallest MAC between a record's mode and a reference mode.
    max_frequency_deviation : float, default 0.1
        Gate of the assignment: the largest |Δf|/f (wide, so that a damage does not lose its mode).
    min_presence : float, default 0.5
        A reference mode is selected in at least this fraction of the reference records.
    reference_distance : float, default 0.05
        Clustering cut of the reference period's modes on |Δf|/f + (1 − MAC).
    false_alarm_rate : float, default 0.01
        Probability of an alarm at one record and mode when nothing changed, for each of the two
        tests (the change test of f and ξ, the shape test): an alarm of either comes at up to twice
        this rate.
    smoothing : float, default 0.3
        EWMA weight of the newest record in the control statistic (1: each record on its own).
    inflate_to_reference : bool, default False
        Scale each mode's covariances by its reference reduced χ² (over f and ξ) when that is
        above its calibrated value ν/(ν − 2).
    """

    #: the first K successful records form the reference period (unless ``reference_span``)
    reference_records: int = 20
    #: ``(start, end)`` times (anything :class:`numpy.datetime64` reads): the reference period instead
    reference_span: tuple | None = None
    #: gate of the assignment: smallest MAC between a record's mode and a reference mode
    min_mac: float = 0.8
    #: gate of the assignment: largest |Δf|/f (large, so that a damage does not lose its mode)
    max_frequency_deviation: float = 0.1
    #: a reference mode is selected in at least this fraction of the reference records
    min_presence: float = 0.5
    #: clustering cut of the reference period's modes on |Δf|/f + (1 - MAC)
    reference_distance: float = 0.05
    #: probability of an alarm at a record when nothing changed (per record and mode)
    false_alarm_rate: float = 0.01
    #: EWMA weight of the newest record in the control statistic (1: each record on its own)
    smoothing: float = 0.3
    #: scale each mode's covariances by its reference reduced χ² (over f and ξ) when that is above
    #: its calibrated value ν/(ν-2)
    inflate_to_reference: bool = False

    def __post_init__(self):
        check_integer("reference_records", self.reference_records, minimum=3)
        if self.reference_span is not None:
            try:
                a, b = (np.datetime64(t, "s") for t in self.reference_span)
            except (TypeError, ValueError):
                raise ValueError(f"reference_span must be (start, end) times; got {self.reference_span!r}") from None
            if not b > a:
                raise ValueError(f"reference_span must end after it starts; got {self.reference_span!r}")
        check_real("min_mac", self.min_mac, low=0.0, high=1.0)
        check_real("max_frequency_deviation", self.max_frequency_deviation, low=0.0, low_open=True)
        check_real("min_presence", self.min_presence, low=0.0, high=1.0, low_open=True)
        check_real("reference_distance", self.reference_distance, low=0.0, low_open=True)
        check_real("false_alarm_rate", self.false_alarm_rate, low=0.0, high=0.5, low_open=True)
        check_real("smoothing", self.smoothing, low=0.0, high=1.0, low_open=True)
        check_boolean("inflate_to_reference", self.inflate_to_reference)

    def to_dict(self) -> dict:
        return {k: (list(map(str, v)) if k == "reference_span" and v is not None else v)
                for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class RecordModes:
    """One record's selected modes, as tracking reads them (plain arrays)."""

    frequency_hz: np.ndarray           #: (m,) Hz
    damping_ratio: np.ndarray          #: (m,) fraction
    frequency_std: np.ndarray          #: (m,) Hz (NaN without uncertainty)
    damping_std: np.ndarray            #: (m,) fraction
    frequency_damping_correlation: np.ndarray  #: (m,) correlation of f and ξ at the representative pole
    mode_shape: np.ndarray             #: (l, m) complex
    mode_shape_std_real: np.ndarray    #: (l, m)
    mode_shape_std_imag: np.ndarray    #: (l, m)

    @property
    def n_modes(self) -> int:
        return int(self.frequency_hz.size)

    def covariance(self) -> np.ndarray:
        """(m, 2, 2) covariance of [f, ξ] per mode."""
        sf, sx = self.frequency_std, self.damping_std
        c = np.nan_to_num(self.frequency_damping_correlation) * sf * sx
        return np.stack([np.stack([sf**2, c], -1), np.stack([c, sx**2], -1)], -2)


@dataclass(frozen=True)
class ReferenceModes:
    """The modes of the reference period and their scatter."""

    frequency_hz: np.ndarray           #: (k,) median over the reference records
    damping_ratio: np.ndarray          #: (k,)
    frequency_std: np.ndarray          #: (k,) median σ of one record
    damping_std: np.ndarray            #: (k,)
    mode_shape: np.ndarray             #: (l, k) complex, the member nearest the median frequency
    mode_shape_std: np.ndarray         #: (l, k) median |σ| of a component
    frequency_scatter: np.ndarray      #: (k,) environmental std of f beyond σ, Hz
    damping_scatter: np.ndarray        #: (k,) the same for ξ
    mode_shape_scatter: np.ndarray     #: (l, k) the same per shape component
    presence: np.ndarray               #: (k,) fraction of the reference records with the mode
    #: (l, k) complex: the mean of the reference records' shapes, each scaled onto ``mode_shape``
    #: (the shape test's reference: its error is σ/√K, not one record's)
    mode_shape_mean: np.ndarray
    #: (l, k) |σ| of a component of ``mode_shape_mean``: √(mean σ² / K) over its K records
    mode_shape_mean_std: np.ndarray

    @property
    def n_modes(self) -> int:
        return int(self.frequency_hz.size)


def _align(shape, target):
    """``shape`` scaled by the complex factor that brings it nearest ``target`` (least squares)."""
    alpha = np.vdot(shape, target) / max(np.vdot(shape, shape).real, 1e-300)
    return alpha * shape, abs(alpha)


def _excess_std(values, sigmas) -> float:
    """std of ``values`` beyond what their ``sigmas`` explain (0 when they explain it all)."""
    if values.size < 2:
        return 0.0
    extra = np.var(values, ddof=1) - np.nanmean(sigmas**2) if np.any(np.isfinite(sigmas)) else np.var(values, ddof=1)
    return float(np.sqrt(max(extra, 0.0)))


def reference_modes(records: list, settings: TrackingSettings | None = None) -> ReferenceModes:
    """The reference modes of a reference period's records (list of :class:`RecordModes`)."""
    s = settings or TrackingSettings()
    records = [r for r in records if r is not None]
    pooled = [(k, i) for k, r in enumerate(records) for i in range(r.n_modes)]
    if not pooled:
        raise ValueError("no mode was selected in any record of the reference period")
    l = records[0].mode_shape.shape[0]
    f = np.array([records[k].frequency_hz[i] for k, i in pooled])
    shapes = np.stack([records[k].mode_shape[:, i] for k, i in pooled], axis=1)
    if len(pooled) == 1:
        labels = np.array([1])
    else:
        mac = modal_assurance_criterion(shapes, shapes)
        d = np.abs(f[:, None] - f[None, :]) / np.maximum(f[:, None], f[None, :]) + (1.0 - mac)
        d = np.triu(d, 1)
        d = d + d.T  # the upper triangle, mirrored: exactly symmetric, zero diagonal
        # the core's clustering (selection.hpp's average linkage, cut at a height), as select_modes does
        labels = _core.cluster_labels(d, _core.Linkage.average, float(s.reference_distance))
    out = []
    for label in np.unique(labels):
        idx = np.flatnonzero(labels == label)
        median_f = np.median(f[idx])
        chosen = {}  # one member per record: the one nearest the cluster's median frequency
        for j in idx:
            k = pooled[j][0]
            if k not in chosen or abs(f[j] - median_f) < abs(f[chosen[k]] - median_f):
                chosen[k] = j
        presence = len(chosen) / len(records)
        if presence < s.min_presence:
            continue
        members = [pooled[j] for j in chosen.values()]
        fk = np.array([records[k].frequency_hz[i] for k, i in members])
        xk = np.array([records[k].damping_ratio[i] for k, i in members])
        sfk = np.array([records[k].frequency_std[i] for k, i in members])
        sxk = np.array([records[k].damping_std[i] for k, i in members])
        centre = members[int(np.argmin(np.abs(fk - np.median(fk))))]
        phi = records[centre[0]].mode_shape[:, centre[1]]
        aligned, stds = [], []
        for k, i in members:
            a, scale = _align(records[k].mode_shape[:, i], phi)
            aligned.append(a)
            stds.append(scale * np.hypot(records[k].mode_shape_std_real[:, i], records[k].mode_shape_std_imag[:, i]))
        aligned, stds = np.array(aligned), np.array(stds)
        mean_shape = aligned.mean(axis=0)
        shape_var = np.abs(aligned - mean_shape) ** 2
        shape_extra = (shape_var.sum(axis=0) / max(len(members) - 1, 1)
                       - (np.nanmean(stds**2, axis=0) if np.any(np.isfinite(stds)) else 0.0))
        out.append(dict(f=np.median(fk), xi=np.median(xk), sf=np.nanmedian(sfk) if np.any(np.isfinite(sfk)) else np.nan,
                        sx=np.nanmedian(sxk) if np.any(np.isfinite(sxk)) else np.nan, phi=phi,
                        phi_std=np.nanmedian(stds, axis=0) if np.any(np.isfinite(stds)) else np.full(l, np.nan),
                        f_env=_excess_std(fk, sfk), x_env=_excess_std(xk, sxk),
                        phi_env=np.sqrt(np.maximum(shape_extra, 0.0)), presence=presence, phi_mean=mean_shape,
                        phi_mean_std=np.sqrt(np.nanmean(stds**2, axis=0) / len(members)) if np.any(np.isfinite(stds))
                        else np.full(l, np.nan)))
    if not out:
        raise ValueError(f"no mode was selected in at least {s.min_presence:.0%} of the {len(records)} reference "
                         "records (lower min_presence, or check the records' selection)")
    out.sort(key=lambda m: m["f"])
    return ReferenceModes(
        frequency_hz=np.array([m["f"] for m in out]), damping_ratio=np.array([m["xi"] for m in out]),
        frequency_std=np.array([m["sf"] for m in out]), damping_std=np.array([m["sx"] for m in out]),
        mode_shape=np.stack([m["phi"] for m in out], axis=1),
        mode_shape_std=np.stack([m["phi_std"] for m in out], axis=1),
        frequency_scatter=np.array([m["f_env"] for m in out]), damping_scatter=np.array([m["x_env"] for m in out]),
        mode_shape_scatter=np.stack([m["phi_env"] for m in out], axis=1),
        presence=np.array([m["presence"] for m in out]),
        mode_shape_mean=np.stack([m["phi_mean"] for m in out], axis=1),
        mode_shape_mean_std=np.stack([m["phi_mean_std"] for m in out], axis=1))


def assignment_cost(modes: RecordModes, ref: ReferenceModes) -> tuple:
    """``(cost, mac)``, each (m, k): the Mahalanobis distance² of every record mode to every
    reference mode (f, ξ and the aligned shape), and their MAC."""
    m, k = modes.n_modes, ref.n_modes
    if not (m and k):
        return np.zeros((m, k)), np.zeros((m, k))
    mac = modal_assurance_criterion(modes.mode_shape, ref.mode_shape)

    def var(*parts):  # a missing σ (NaN) adds nothing
        return sum(np.nan_to_num(p) ** 2 for p in parts)

    vf = var(modes.frequency_std[:, None], ref.frequency_std, ref.frequency_scatter)
    vx = var(modes.damping_std[:, None], ref.damping_std, ref.damping_scatter)
    vf = np.maximum(vf, (1e-4 * ref.frequency_hz) ** 2)  # no σ at all: distances in 0.01 % of f
    vx = np.maximum(vx, 1e-8)
    cost = ((modes.frequency_hz[:, None] - ref.frequency_hz) ** 2 / vf
            + (modes.damping_ratio[:, None] - ref.damping_ratio) ** 2 / vx)
    # shapes: record mode i scaled by the complex α_ij that brings it nearest reference mode j
    phi, target = modes.mode_shape, ref.mode_shape                        # (l, m), (l, k)
    alpha = (phi.conj().T @ target) / np.maximum(np.sum(np.abs(phi) ** 2, axis=0), 1e-300)[:, None]
    aligned = alpha[None, :, :] * phi[:, :, None]                         # (l, m, k)
    sigma = np.hypot(modes.mode_shape_std_real, modes.mode_shape_std_imag)  # (l, m)
    v = (var(np.abs(alpha)[None, :, :] * sigma[:, :, None], ref.mode_shape_std[:, None, :],
             ref.mode_shape_scatter[:, None, :]) + SHAPE_VARIANCE_FLOOR)
    cost += np.sum(np.abs(aligned - target[:, None, :]) ** 2 / v, axis=0)
    return cost, mac


def shape_test(modes: RecordModes, i: int, ref: ReferenceModes, j: int) -> MacTest:
    """The "same mode" test of record mode ``i``'s shape against reference mode ``j``'s mean shape
    (:func:`modaluq.indicators.mac_test`). Variances: the record's σ of each component's real and
    imaginary part; for the reference, the σ of its mean over the K reference records and the
    environmental scatter, both per component and split evenly between the real and imaginary
    parts. The mean, not one record's shape: a single reference estimate's error would be shared
    by every later record, so that one campaign's alarms would come together (its rate only right
    on average over campaigns). Correlations between channels are not kept in the records' parts
    and are left out. The p-value is NaN when a σ is unknown."""
    record_var = np.concatenate([modes.mode_shape_std_real[:, i], modes.mode_shape_std_imag[:, i]]) ** 2
    half = 0.5 * (ref.mode_shape_mean_std[:, j] ** 2 + ref.mode_shape_scatter[:, j] ** 2)
    if not (np.all(np.isfinite(record_var)) and np.all(np.isfinite(half))):
        return mac_test(modes.mode_shape[:, i], ref.mode_shape_mean[:, j])
    return mac_test(modes.mode_shape[:, i], ref.mode_shape_mean[:, j], np.diag(record_var),
                    np.diag(np.concatenate([half, half])))


def after_reference(in_reference) -> np.ndarray:
    """(n_records,) bool: the records after the reference period began and not in it, those the
    change tests chart (a record before a ``reference_span`` is not tested)."""
    in_reference = np.asarray(in_reference, bool)
    return ~in_reference & (np.cumsum(in_reference) > 0)


def assign(modes: RecordModes, ref: ReferenceModes, settings: TrackingSettings | None = None) -> tuple:
    """``(reference_index, mac, cost)`` per record mode: the reference mode each is assigned to
    (-1: none passes the gates or a better pair took it), the MAC and the distance² to it."""
    s = settings or TrackingSettings()
    m = modes.n_modes
    index, mac_out, cost_out = np.full(m, -1), np.full(m, np.nan), np.full(m, np.nan)
    if m == 0 or ref.n_modes == 0:
        return index, mac_out, cost_out
    cost, mac = assignment_cost(modes, ref)
    deviation = np.abs(modes.frequency_hz[:, None] - ref.frequency_hz[None, :]) / ref.frequency_hz[None, :]
    allowed = (mac >= s.min_mac) & (deviation <= s.max_frequency_deviation) & np.isfinite(cost)
    big = 1e6 * (1.0 + np.max(np.where(allowed, cost, 0.0)))
    rows, cols = scipy.optimize.linear_sum_assignment(np.where(allowed, cost, big))
    for i, j in zip(rows, cols):
        if allowed[i, j]:
            index[i], mac_out[i], cost_out[i] = j, mac[i, j], cost[i, j]
    return index, mac_out, cost_out


def reference_period(done: np.ndarray, times: np.ndarray, settings: TrackingSettings) -> np.ndarray:
    """(n_records,) bool: the first ``reference_records`` records identified (``done``), or the
    records identified whose time (``datetime64[s]``, NaT when unknown) lies in ``reference_span``."""
    if settings.reference_span is not None:
        a, b = (np.datetime64(t, "s") for t in settings.reference_span)
        return done & (times >= a) & (times <= b)
    return done & (np.cumsum(done) <= settings.reference_records)


@dataclass(frozen=True)
class Tracks:
    """Every record's selected modes on the reference modes' axis: each (n_records, n_modes),
    the shapes (n_records, n_channels, n_modes); NaN where a record does not have the mode."""

    reference: ReferenceModes | None   #: None when the reference period gave none (``error`` says why)
    error: str                         #: why there is no reference ("" when there is one)
    in_reference: np.ndarray           #: (n_records,) bool: the reference period
    index: tuple                       #: per record, the tracked mode (0-based, -1: none) of each
                                       #: selected mode; None for a record not identified
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    frequency_std: np.ndarray
    damping_std: np.ndarray
    frequency_damping_correlation: np.ndarray
    mac_to_reference: np.ndarray
    mac_to_reference_std: np.ndarray   #: σ of the MAC to the reference mode (second order, :func:`shape_test`)
    shape_p_value: np.ndarray          #: p-value of the "same mode" test of the shape (:func:`shape_test`)
    shape_alarm: np.ndarray            #: bool: ``shape_p_value < false_alarm_rate`` after the reference period
    assignment_distance: np.ndarray    #: Mahalanobis distance² to the reference mode
    mode_shape: np.ndarray             #: complex
    mode_shape_std_real: np.ndarray
    mode_shape_std_imag: np.ndarray
    n_unassigned: np.ndarray           #: (n_records,) selected modes assigned to no reference mode

    @property
    def n_modes(self) -> int:
        return self.reference.n_modes if self.reference is not None else 0

    def place(self, values: list, fill, dtype=float) -> np.ndarray:
        """(n_records, n_modes): ``values`` (per record, one value per selected mode; None for a
        record not identified) on the tracked modes, ``fill`` where a record lacks the mode."""
        out = np.full((len(self.index), self.n_modes), fill, dtype)
        for k, idx in enumerate(self.index):
            if idx is None:
                continue
            for i, j in enumerate(idx):
                if j >= 0:
                    out[k, j] = values[k][i]
        return out

    def covariance(self) -> np.ndarray:
        """(n_records, n_modes, 2, 2): the covariance of each record's [f, ξ] (zero where absent)."""
        sf, sx = self.frequency_std, self.damping_std
        C = np.zeros(sf.shape + (2, 2))
        C[..., 0, 0], C[..., 1, 1] = sf**2, sx**2
        C[..., 0, 1] = C[..., 1, 0] = np.nan_to_num(self.frequency_damping_correlation) * sf * sx
        return C


def track(modes: list, in_reference: np.ndarray, n_channels: int, settings: TrackingSettings | None = None) -> Tracks:
    """The reference modes of the records ``in_reference``, and every record's modes assigned to
    them (``modes``: one :class:`RecordModes` per record, None for a record not identified).

    Without reference modes (fewer than 3 reference records, or no mode present in enough of
    them) the records stay untracked and :attr:`Tracks.error` says why.
    """
    s = settings or TrackingSettings()
    n, l = len(modes), n_channels
    ref, error = None, ""
    try:
        if in_reference.sum() < 3:
            raise ValueError(f"{int(in_reference.sum())} records identified in the reference period; at least 3 are "
                             "needed")
        ref = reference_modes([modes[k] for k in np.flatnonzero(in_reference)], s)
    except ValueError as exc:
        error = str(exc)
    k_modes = ref.n_modes if ref is not None else 0
    F, XI, SF, SX, RHO, MAC, MAC_STD, P_SHAPE, DIST = (np.full((n, k_modes), np.nan) for _ in range(9))
    SH = np.full((n, l, k_modes), np.nan + 0j)
    SHR, SHI = np.full((n, l, k_modes), np.nan), np.full((n, l, k_modes), np.nan)
    n_unassigned = np.zeros(n, int)
    index = [None] * n
    for k in range(n):
        if modes[k] is None:
            continue
        mk = modes[k]
        idx, mac, dist = assign(mk, ref, s) if ref is not None else (np.full(mk.n_modes, -1), None, None)
        index[k] = idx
        n_unassigned[k] = int((idx < 0).sum())
        for i, j in enumerate(idx):
            if j < 0:
                continue
            F[k, j], XI[k, j] = mk.frequency_hz[i], mk.damping_ratio[i]
            SF[k, j], SX[k, j], RHO[k, j] = mk.frequency_std[i], mk.damping_std[i], mk.frequency_damping_correlation[i]
            MAC[k, j], DIST[k, j] = mac[i], dist[i]
            t = shape_test(mk, i, ref, j)
            MAC_STD[k, j], P_SHAPE[k, j] = t.std, t.p_value
            SH[k, :, j] = mk.mode_shape[:, i]
            SHR[k, :, j], SHI[k, :, j] = mk.mode_shape_std_real[:, i], mk.mode_shape_std_imag[:, i]
    with np.errstate(invalid="ignore"):  # NaN: no test, no alarm
        shape_alarm = (P_SHAPE < s.false_alarm_rate) & after_reference(in_reference)[:, None]
    return Tracks(reference=ref, error=error, in_reference=in_reference, index=tuple(index), frequency_hz=F,
                  damping_ratio=XI, frequency_std=SF, damping_std=SX, frequency_damping_correlation=RHO,
                  mac_to_reference=MAC, mac_to_reference_std=MAC_STD, shape_p_value=P_SHAPE,
                  shape_alarm=shape_alarm, assignment_distance=DIST, mode_shape=SH, mode_shape_std_real=SHR,
                  mode_shape_std_imag=SHI, n_unassigned=n_unassigned)
