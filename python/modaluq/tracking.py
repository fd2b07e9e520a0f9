"""Mode tracking and change detection over many records, using each estimate's covariance.

A record's selected modes (:class:`RecordModes`) are assigned to **reference modes** learned from
a reference period, and each tracked mode's frequency and damping ratio are tested against what
the reference predicts (docs/monitoring.md):

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
3. **Change test** (:func:`change_test`): per mode, the frequency and damping ratio are
   regressed on the covariates (or a constant) over the reference period by weighted least
   squares with weights 1/σ²; each record's residual ``e = [f, ξ] - prediction`` has covariance
   ``S = C + P`` (C from the record's σ and the f-ξ correlation of its pole, P the prediction's).
   Reported: the standardised changes ``e_f/√S_ff``, ``e_ξ/√S_ξξ``, the χ² ``eᵀS⁻¹e`` (2 degrees
   of freedom), and a multivariate EWMA of the residuals (the control statistic, a χ²
   with 2 degrees of freedom at every record when nothing changed): an alarm when it exceeds the
   ``1 - false_alarm_rate`` quantile. The EWMA runs on the raw residuals, and its covariance
   (the records' C weighted by the EWMA's weights, plus the reference's prediction error, which
   is common to every record and does not average out) is exact. With ``smoothing=1`` the control
   statistic is the record's own χ². The reduced χ² of the reference period says whether σ is
   calibrated on this structure.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.cluster.hierarchy
import scipy.optimize
import scipy.stats

from .checks import check_boolean, check_integer, check_real
from .stabilization import modal_assurance_criterion

__all__ = ["ChangeTest", "RecordModes", "ReferenceModes", "TrackingSettings", "alarm_limit", "assign",
           "change_test", "reference_modes"]

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
        Probability of an alarm at one record and mode when nothing changed.
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


def alarm_limit(false_alarm_rate: float, dof) -> np.ndarray:
    """The ``1 - false_alarm_rate`` quantile of ``eᵀ Ŝ⁻¹ e`` for a 2-vector ``e`` whose covariance
    ``Ŝ`` is estimated with ``dof`` degrees of freedom: Hotelling's T², ``2ν/(ν-1) F(2, ν-1)``.

    A record's σ comes from the sample covariance of ``n_blocks`` blocks (ν = n_blocks - 1), so
    its χ² has heavier tails than χ²(2) (mean 2ν/(ν-3): 2.375 for 20 blocks); with the χ²(2) limit
    the false alarms at 1 % would be 1.6 (50 blocks) to 2.9 (20 blocks) times the rate stated.
    ``dof = inf`` gives the χ²(2) quantile.
    """
    nu = np.asarray(dof, float)
    chi2 = scipy.stats.chi2.isf(false_alarm_rate, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        hotelling = 2 * nu / (nu - 1) * scipy.stats.f.isf(false_alarm_rate, 2, np.maximum(nu - 1, 1e-9))
    return np.where(np.isfinite(nu), np.where(nu > 2, hotelling, np.inf), chi2)


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
        np.fill_diagonal(d, 0.0)
        tree = scipy.cluster.hierarchy.linkage(scipy.spatial.distance.squareform(d, checks=False), "average")
        labels = scipy.cluster.hierarchy.fcluster(tree, s.reference_distance, criterion="distance")
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
        shape_var = np.abs(aligned - aligned.mean(axis=0)) ** 2
        shape_extra = (shape_var.sum(axis=0) / max(len(members) - 1, 1)
                       - (np.nanmean(stds**2, axis=0) if np.any(np.isfinite(stds)) else 0.0))
        out.append(dict(f=np.median(fk), xi=np.median(xk), sf=np.nanmedian(sfk) if np.any(np.isfinite(sfk)) else np.nan,
                        sx=np.nanmedian(sxk) if np.any(np.isfinite(sxk)) else np.nan, phi=phi,
                        phi_std=np.nanmedian(stds, axis=0) if np.any(np.isfinite(stds)) else np.full(l, np.nan),
                        f_env=_excess_std(fk, sfk), x_env=_excess_std(xk, sxk),
                        phi_env=np.sqrt(np.maximum(shape_extra, 0.0)), presence=presence))
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
        presence=np.array([m["presence"] for m in out]))


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


@dataclass(frozen=True)
class ChangeTest:
    """The change statistics of tracked modes, each (n_records, n_modes) unless said."""

    expected_frequency_hz: np.ndarray     #: the reference's prediction at each record's covariates
    expected_damping_ratio: np.ndarray
    frequency_change: np.ndarray          #: standardised: residual / its std
    damping_change: np.ndarray
    chi2: np.ndarray                      #: the record's own χ² over f and ξ (2 degrees of freedom)
    control: np.ndarray                   #: the control statistic (EWMA of the residuals, χ²(2) scaled)
    alarm: np.ndarray                     #: bool: control above the limit (never in the reference period)
    control_limit: np.ndarray             #: the alarm limit of each record's control statistic
    reference_reduced_chi2: np.ndarray    #: (n_modes,) over f and ξ in the reference period (1 when calibrated)
    reference_reduced_chi2_frequency: np.ndarray  #: (n_modes,)
    reference_reduced_chi2_damping: np.ndarray    #: (n_modes,)
    coefficients_frequency: np.ndarray    #: (n_modes, 1 + n_covariates) Hz, per covariate unit (centred)
    coefficients_damping: np.ndarray      #: (n_modes, 1 + n_covariates)
    covariate_mean: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: (n_covariates,) centring


def change_test(frequency, damping, covariance, reference, covariates=None,
                settings: TrackingSettings | None = None, dof=None) -> ChangeTest:
    """The change test of every tracked mode (docs/monitoring.md §4).

    Parameters
    ----------
    frequency, damping : (n_records, n_modes), NaN where the mode was not found
    covariance : (n_records, n_modes, 2, 2) of [f, ξ]
    reference : (n_records,) bool, the reference period
    covariates : (n_records, n_covariates), optional; NaN makes a record unusable for the test
    dof : (n_records,), optional
        Degrees of freedom of each record's covariance (``n_blocks - 1``); the alarm limit is
        then Hotelling's (:func:`alarm_limit`), for the EWMA with the Welch-Satterthwaite
        degrees of freedom of its weighted covariances. Default: covariances known exactly.
    """
    s = settings or TrackingSettings()
    f = np.asarray(frequency, float)
    x = np.asarray(damping, float)
    C = np.array(covariance, float)
    ref = np.asarray(reference, bool)
    n_rec, n_modes = f.shape
    X = np.zeros((n_rec, 0)) if covariates is None else np.asarray(covariates, float).reshape(n_rec, -1)
    mean_X = np.nanmean(X[ref], axis=0) if X.shape[1] else np.zeros(0)
    D = np.column_stack([np.ones(n_rec), X - mean_X])
    p = D.shape[1]
    known = ref & np.all(np.isfinite(D), axis=1)
    if p > 1 and known.sum() >= p and np.linalg.matrix_rank(D[known]) < p:
        raise ValueError("covariates: constant or collinear over the reference period, so their effect cannot be "
                         "learned from it (a reference period spanning their range is needed, or leave them out)")
    nan = np.full((n_rec, n_modes), np.nan)
    out = {k: nan.copy() for k in ("ef", "ex", "zf", "zx", "chi2", "control")}
    limit_dof = nan.copy()  # degrees of freedom of each control statistic's covariance
    nu = np.full(n_rec, np.inf) if dof is None else np.asarray(dof, float).reshape(n_rec)
    red, red_f, red_x = (np.full(n_modes, np.nan) for _ in range(3))
    bf, bx = np.full((n_modes, p), np.nan), np.full((n_modes, p), np.nan)
    lam = s.smoothing
    expected_f, expected_x = nan.copy(), nan.copy()
    for j in range(n_modes):
        usable = np.isfinite(f[:, j]) & np.isfinite(x[:, j]) & np.all(np.isfinite(D), axis=1)
        vf, vx = C[:, j, 0, 0], C[:, j, 1, 1]
        usable &= (vf > 0) & (vx > 0) & np.isfinite(vf) & np.isfinite(vx)
        r = ref & usable
        if r.sum() <= p:
            continue
        # weighted least squares of f and of ξ on the covariates over the reference period
        Df = D[r] / np.sqrt(vf[r])[:, None]
        Dx = D[r] / np.sqrt(vx[r])[:, None]
        try:
            Gf, Gx = np.linalg.inv(Df.T @ Df), np.linalg.inv(Dx.T @ Dx)
        except np.linalg.LinAlgError:
            continue  # this mode's reference records do not span the covariates: no test for it
        bf[j] = Gf @ (Df.T @ (f[r, j] / np.sqrt(vf[r])))
        bx[j] = Gx @ (Dx.T @ (x[r, j] / np.sqrt(vx[r])))
        # covariance of the two coefficient vectors (f and ξ are correlated within a record)
        cfx = Gf @ (D[r].T * (C[r, j, 0, 1] / (vf[r] * vx[r]))) @ D[r] @ Gx
        ef = f[:, j] - D @ bf[j]
        ex = x[:, j] - D @ bx[j]
        expected_f[:, j], expected_x[:, j] = D @ bf[j], D @ bx[j]
        dof = r.sum() - p
        red_f[j] = np.sum(ef[r] ** 2 / vf[r]) / dof
        red_x[j] = np.sum(ex[r] ** 2 / vx[r]) / dof
        residuals = np.column_stack([ef[r], ex[r]])
        red[j] = sum(float(e @ np.linalg.solve(c, e)) for e, c in zip(residuals, C[r, j])) / (2 * dof)
        # calibrated, the reduced χ² is about ν/(ν-2) (σ estimated from ν degrees of freedom, which
        # the Hotelling limit already allows for): inflate only beyond that
        nu_ref = np.median(nu[r])
        calibrated = nu_ref / (nu_ref - 2) if np.isfinite(nu_ref) and nu_ref > 2 else 1.0
        scale = max(1.0, red[j] / calibrated) if s.inflate_to_reference else 1.0

        def prediction_cov(d):  # covariance of the reference's prediction at design row d
            return np.array([[d @ Gf @ d, d @ cfx @ d], [d @ cfx @ d, d @ Gx @ d]])

        # the control statistic: an EWMA of the raw residuals, V = λ e + (1-λ) V, whose covariance
        # is known exactly: Σ w_i² C_i (independent parts) + P(Σ w_i d_i) (the reference's error,
        # common to every record, does not average out)
        V, A, d_ewma = np.zeros(2), np.zeros((2, 2)), np.zeros(p)
        w2, w4_nu = 0.0, 0.0  # Σ w_i² and Σ w_i⁴/ν_i: the EWMA covariance's degrees of freedom
        for k in np.flatnonzero(usable):
            P = prediction_cov(D[k])
            # a reference record took part in the fit: its residual has covariance C - P
            S = scale * (C[k, j] - P if ref[k] else C[k, j] + P)
            e = np.array([ef[k], ex[k]])
            try:
                L = np.linalg.cholesky(S)
            except np.linalg.LinAlgError:
                continue
            w = np.linalg.solve(L, e)
            out["ef"][k, j], out["ex"][k, j] = e
            out["zf"][k, j], out["zx"][k, j] = e[0] / np.sqrt(S[0, 0]), e[1] / np.sqrt(S[1, 1])
            out["chi2"][k, j] = float(w @ w)
            if ref[k] or not ref[:k].any():
                continue  # in or before the reference period: no control chart
            V = lam * e + (1 - lam) * V
            A = lam**2 * scale * C[k, j] + (1 - lam) ** 2 * A
            d_ewma = lam * D[k] + (1 - lam) * d_ewma
            SV = A + scale * prediction_cov(d_ewma)
            out["control"][k, j] = float(V @ np.linalg.solve(SV, V))
            w2 = lam**2 + (1 - lam) ** 2 * w2
            w4_nu = lam**4 / nu[k] + (1 - lam) ** 4 * w4_nu
            limit_dof[k, j] = w2**2 / w4_nu if w4_nu > 0 else np.inf
    charted = ~np.isnan(limit_dof)
    limit = nan.copy()
    limit[charted] = alarm_limit(s.false_alarm_rate, limit_dof[charted])  # one vectorised call
    alarm = np.zeros((n_rec, n_modes), bool)
    alarm[charted] = out["control"][charted] > limit[charted]
    return ChangeTest(expected_frequency_hz=expected_f, expected_damping_ratio=expected_x,
                      frequency_change=out["zf"], damping_change=out["zx"], chi2=out["chi2"], control=out["control"],
                      alarm=alarm, control_limit=limit, reference_reduced_chi2=red,
                      reference_reduced_chi2_frequency=red_f, reference_reduced_chi2_damping=red_x,
                      coefficients_frequency=bf, coefficients_damping=bx, covariate_mean=mean_X)
