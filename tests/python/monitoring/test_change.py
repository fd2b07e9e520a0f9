"""The change test (modaluq.monitoring.change) on Gaussian residuals whose truth is set here.

Every expected value comes from the construction: the regression coefficients chosen, the χ²
laws of Gaussian residuals.
"""

import numpy as np
import pytest
import scipy.stats

from modaluq.monitoring.change import alarm_limit, change_test
from modaluq.monitoring.tracking import TrackingSettings


def gaussian_campaign(rng, n, *, sf=0.01, sx=0.002, rho=0.3, slope=0.05, shift=0.0, shift_from=None):
    """f = 5 + slope (T - 10) + e_f, ξ = 0.02 + e_ξ, with [e_f, e_ξ] ~ N(0, C) exactly."""
    T = 10 + 6 * np.sin(np.arange(n) / 5.0) + rng.standard_normal(n)
    C = np.array([[sf**2, rho * sf * sx], [rho * sf * sx, sx**2]])
    e = rng.multivariate_normal([0, 0], C, size=n)
    f = 5 + slope * (T - 10) + e[:, 0]
    if shift_from is not None:
        f[shift_from:] += shift
    xi = 0.02 + e[:, 1]
    return f[:, None], xi[:, None], np.broadcast_to(C, (n, 1, 2, 2)).copy(), T[:, None]


def test_regression_on_a_covariate_recovers_the_slope_and_the_reduced_chi2_is_one():
    rng = np.random.default_rng(5)
    n, K = 400, 200
    f, xi, C, T = gaussian_campaign(rng, n)
    ref = np.arange(n) < K
    test = change_test(f, xi, C, ref, T)
    slope, se = test.coefficients_frequency[0, 1], 0.01 / np.sqrt(np.sum((T[ref, 0] - T[ref, 0].mean()) ** 2))
    assert abs(slope - 0.05) < 4 * se
    # reduced χ² of K - 2 degrees of freedom: 1 within 4 of its standard deviations sqrt(2 / (K - 2))
    for red in (test.reference_reduced_chi2_frequency, test.reference_reduced_chi2_damping):
        assert abs(red[0] - 1) < 4 * np.sqrt(2 / (K - 2))
    # without the covariate, the temperature's effect shows as a reduced χ² far above 1
    assert change_test(f, xi, C, ref).reference_reduced_chi2_frequency[0] > 10


@pytest.mark.parametrize("smoothing", [1.0, 0.3])
def test_false_alarm_rate_is_the_rate_stated_with_known_covariances(smoothing):
    # many independent campaigns: the control statistic is χ²(2) at each record, so the alarm
    # rate is the false_alarm_rate; the count is binomial for smoothing 1, and correlated
    # (variance at most (2 - λ)/λ times the binomial) for the EWMA
    rng = np.random.default_rng(6)
    s = TrackingSettings(smoothing=smoothing, false_alarm_rate=0.05)
    alarms, n_tests, controls = 0, 0, []
    for _ in range(60):
        f, xi, C, T = gaussian_campaign(rng, 120)
        ref = np.arange(120) < 40
        t = change_test(f, xi, C, ref, T, s)
        alarms += int(t.alarm[~ref].sum())
        n_tests += int((~ref).sum())
        controls.append(t.control[~ref, 0])
    p = s.false_alarm_rate
    inflation = (2 - smoothing) / smoothing
    tolerance = 4 * np.sqrt(n_tests * p * (1 - p) * inflation)
    assert abs(alarms - n_tests * p) < tolerance, (alarms, n_tests * p, tolerance)
    # the control statistic's mean is that of χ²(2): 2 (the reference's error included)
    assert abs(np.mean(np.concatenate(controls)) - 2) < 4 * 2 * np.sqrt(inflation / n_tests)


def test_a_shift_of_three_sigma_is_detected_by_the_ewma_in_nine_records_of_ten():
    rng = np.random.default_rng(7)
    detected, n = 0, 0
    for _ in range(20):
        f, xi, C, T = gaussian_campaign(rng, 140, shift=-0.03, shift_from=60)  # -3 σ_f
        t = change_test(f, xi, C, np.arange(140) < 40, T, TrackingSettings(smoothing=0.3))
        detected += int(t.alarm[60:, 0].sum())
        n += 80
    assert detected / n >= 0.9
    # the record's own χ² test (smoothing 1) cannot: a 3 σ shift exceeds its 1 % limit about half the time
    f, xi, C, T = gaussian_campaign(rng, 2000, shift=-0.03, shift_from=60)
    t = change_test(f, xi, C, np.arange(2000) < 40, T, TrackingSettings(smoothing=1.0))
    power = scipy.stats.ncx2.sf(scipy.stats.chi2.isf(0.01, 2), 2, 9 / (1 - 0.09))  # ρ = 0.3 whitens 9 to 9/(1-ρ²)
    assert abs(t.alarm[60:, 0].mean() - power) < 0.05


def test_hotelling_limit_for_covariances_from_few_blocks():
    # the record's χ² with a covariance estimated from n blocks: T² = 2ν/(ν-1) F(2, ν-1), ν = n - 1;
    # checked by drawing the sample covariance itself
    rng = np.random.default_rng(8)
    nu, p = 19, 0.05
    x = rng.standard_normal((20000, 2))
    w = rng.standard_normal((20000, nu, 2))
    S = np.einsum("kni,knj->kij", w, w) / nu
    t2 = np.einsum("ki,kij,kj->k", x, np.linalg.inv(S), x)
    limit = alarm_limit(p, nu)
    assert abs(np.mean(t2 > limit) - p) < 4 * np.sqrt(p * (1 - p) / 20000)
    assert alarm_limit(p, np.inf) == pytest.approx(scipy.stats.chi2.isf(p, 2))
    assert limit > alarm_limit(p, np.inf)


def test_inflate_to_reference_restores_the_rate_when_sigma_is_too_small():
    # every record's σ is half the truth (covariances 4 times too small): the reference's reduced χ²
    # says about 4, the alarms are far too frequent, and inflate_to_reference brings them back
    rng = np.random.default_rng(9)
    p = 0.05
    counts = {False: 0, True: 0}
    reduced, n_tests = [], 0
    for _ in range(30):
        f, xi, C, T = gaussian_campaign(rng, 120)
        ref = np.arange(120) < 60
        for inflate in (False, True):
            t = change_test(f, xi, C / 4, ref, T, TrackingSettings(smoothing=1.0, false_alarm_rate=p,
                                                                    inflate_to_reference=inflate))
            counts[inflate] += int(t.alarm[~ref].sum())
        reduced.append(t.reference_reduced_chi2[0])
        n_tests += int((~ref).sum())
    assert abs(np.mean(reduced) - 4) < 0.4
    assert counts[False] > 5 * n_tests * p
    assert abs(counts[True] - n_tests * p) < 4 * np.sqrt(n_tests * p * (1 - p)) + 0.2 * n_tests * p, counts
    # σ calibrated: nothing changes (the reduced χ² stays near its calibrated value)
    f, xi, C, T = gaussian_campaign(rng, 400)
    ref = np.arange(400) < 300
    plain, inflated = (change_test(f, xi, C, ref, T, TrackingSettings(inflate_to_reference=i)) for i in (False, True))
    np.testing.assert_allclose(inflated.control[~ref], plain.control[~ref], rtol=0.1)


def test_a_covariate_constant_over_the_reference_is_a_value_error_naming_it():
    rng = np.random.default_rng(10)
    f, xi, C, T = gaussian_campaign(rng, 60)
    T[:30] = 12.0  # the reference period saw one temperature only
    with pytest.raises(ValueError, match="covariates: constant or collinear over the reference period"):
        change_test(f, xi, C, np.arange(60) < 30, T)
