"""The block-correlation correction (docs/uq-math.md §3.1): each mode's σ scaled by √c, c from the
lag-1 autocorrelation of its own f and ξ block terms, recomputed here in NumPy from the
uncorrected run's factor rows."""

import numpy as np
import pytest

import modaluq


def _scale(factor):
    """c of (3.4) from one mode's (2, n_b) factor rows [u_f; u_ξ], 1 inside the gate."""
    nb = factor.shape[1]
    rho = [u[:-1] @ u[1:] / (u @ u) for u in factor if u @ u > 0]
    if not rho:
        return 1.0
    rho = np.mean(rho) + 1.0 / nb
    return max(0.25, 1.0 + 2.0 * rho) if abs(rho) > 2.0 / np.sqrt(nb) else 1.0


@pytest.fixture(scope="module")
def runs():
    # where the gate opens: the measured input is the only force, 200 short blocks
    # (docs/validation.md, "Issue 27", (d))
    record = modaluq.simulate(20_000, seed=3, unknown_input_std=0.0)
    kw = dict(fs=record.fs, block_rows=15, orders=[6, 12, 18], n_blocks=200)
    return (modaluq.identify(record.y, record.u, **kw),
            modaluq.identify(record.y, record.u, block_correlation_correction=True, **kw))


def test_off_by_default():
    assert modaluq.Settings().block_correlation_correction is False


def test_corrected_sigma_is_the_plain_one_times_sqrt_c(runs):
    plain, corrected = runs
    changed = 0
    for n in (6, 12, 18):
        a, b = plain.at_order(n), corrected.at_order(n)
        np.testing.assert_array_equal(a.block_correlation_scale, 1.0)
        np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
        c = np.array([_scale(u) for u in a.frequency_damping_factor])
        np.testing.assert_allclose(b.block_correlation_scale, c, rtol=1e-12)
        np.testing.assert_allclose(b.frequency_std, np.sqrt(c) * a.frequency_std, rtol=1e-12)
        np.testing.assert_allclose(b.damping_std, np.sqrt(c) * a.damping_std, rtol=1e-12)
        np.testing.assert_allclose(b.covariance, c[:, None, None] * a.covariance, rtol=1e-10, atol=1e-300)
        changed += int(np.sum(c != 1))
    assert changed > 0  # the gate opened for some poles


def test_monte_carlo_carries_the_option_into_its_report():
    from modaluq.validation import monte_carlo

    res = monte_carlo(5, order=12, block_rows=15, n_blocks=50, processes=1, progress=False, n_bootstrap=20,
                      block_correlation_correction=True)
    assert res.settings["block_correlation_correction"] is True
    assert "adjacent blocks" in res.report()
