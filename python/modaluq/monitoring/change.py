"""The change test of tracked modes (docs/monitoring.md §4).

Per mode, the frequency and damping ratio are regressed on the covariates (or a constant) over
the reference period by weighted least squares with weights 1/σ² (:func:`change_test`); each
record's residual ``e = [f, ξ] - prediction`` has covariance ``S = C + P`` (C from the record's σ
and the f-ξ correlation of its pole, P the prediction's). Reported: the standardised changes
``e_f/√S_ff``, ``e_ξ/√S_ξξ``, the χ² ``eᵀS⁻¹e`` (2 degrees of freedom), and a multivariate EWMA
of the residuals (the control statistic, a χ² with 2 degrees of freedom at every record when
nothing changed): an alarm when it exceeds the ``1 - false_alarm_rate`` quantile
(:func:`alarm_limit`). The EWMA runs on the raw residuals, and its covariance (the records' C
weighted by the EWMA's weights, plus the reference's prediction error, which is common to every
record and does not average out) is exact. With ``smoothing=1`` the control statistic is the
record's own χ². The reduced χ² of the reference period says whether σ is calibrated on this
structure (:func:`miscalibrated`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.stats

from .tracking import TrackingSettings

__all__ = ["ChangeTest", "alarm_limit", "change_test", "miscalibrated"]


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


def miscalibrated(reduced_chi2_frequency, reduced_chi2_damping, n_reference: int, n_terms: int):
    """Modes whose reference reduced χ² (of f or ξ) is above its 99.9 % quantile: σ too small on
    this structure, or a covariate missing. Returns (mask, the quantile)."""
    dof = max(n_reference - n_terms, 1)
    high = scipy.stats.chi2.isf(0.001, dof) / dof
    red = np.fmax(np.asarray(reduced_chi2_frequency, float), np.asarray(reduced_chi2_damping, float))
    return np.nan_to_num(red) > high, high
