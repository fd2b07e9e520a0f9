"""σ above the true order (issue 11, docs/uq-math.md §5.5): a CI-sized Monte Carlo.

100 records per case, the true order and 2x and 3x it, output-only and input/output, with and
without unmeasured forces, on the paper's chain and a 4-storey shear frame with two inputs.
With 100 records σ_MC itself is uncertain by ~7 % (more for heavy tails), so the bands here
are wider than the doc's 400-record numbers (docs/validation.md, "Above the true order"),
which they were derived from: they fail on the plain first-order propagation, whose mean ratio
is 3-20 above the true order, and pass with margin on the frozen one.
"""

import numpy as np
import pytest

from modaluq.validation import monte_carlo

N_RECORDS = 100
CASES = {
    # name: (monte_carlo keywords, true order)
    "chain": (dict(), 12),
    "chain, known input only": (dict(unknown_input_std=0.0), 12),
    "frame, two inputs": (dict(n_dof=4, input_dofs=(0, 3)), 8),
}


def _run(kw, true_order, **extra):
    orders = [true_order, 2 * true_order, 3 * true_order]
    return dict(zip(orders, monte_carlo(N_RECORDS, order=orders, seed=11, processes=2, progress=False,
                                        n_bootstrap=0, **kw, **extra)))


@pytest.fixture(scope="module", params=list(CASES), ids=list(CASES))
def case(request):
    kw, n0 = CASES[request.param]
    return request.param, n0, _run(kw, n0)


def _cells(res, key):
    """The (method, mode) cells of a summary array, flattened."""
    return np.asarray(getattr(res, key)).ravel()


@pytest.mark.slow
def test_sigma_is_calibrated_at_the_true_order_and_above(case):
    name, n0, runs = case
    for n, res in runs.items():
        label = f"{name}, order {n}"
        # Frequency: the typical mode within the band, none off by the plain
        # propagation's factors (3-17 above the true order).
        ratio = _cells(res, "frequency_std_ratio_unflagged")
        assert 0.8 <= np.nanmedian(ratio) <= 1.25, (label, np.round(ratio, 2))
        assert np.all((ratio > 0.5) & (ratio < 4.0)), (label, np.round(ratio, 2))
        # Each record's error in units of its own σ (RMS 1 for a right σ), f and ξ. ξ's pooled
        # ratio is not asserted per mode: with 100 records a few mixed poles with outlying
        # damping dominate σ_MC of ξ (docs/validation.md).
        for par in ("frequency", "damping"):
            rms = _cells(res, f"{par}_rms_z_unflagged")
            assert 0.7 <= np.nanmedian(rms) <= 1.3, (label, par, np.round(rms, 2))
            assert np.all((rms > 0.3) & (rms < 4.0)), (label, par, np.round(rms, 2))
        xi = _cells(res, "damping_std_ratio_unflagged")
        assert 0.7 <= np.nanmedian(xi) <= 1.3, (label, np.round(xi, 2))


@pytest.mark.slow
def test_few_physical_poles_are_flagged(case):
    name, n0, runs = case
    for n, res in runs.items():
        share = res.noise_coupled_share
        # At the true order only a mode whose singular values fall below the noise floor in some
        # records can be flagged (output-only mode 1 of the chain).
        assert np.all(share <= (0.1 if n == n0 else 0.2)), (name, n, np.round(share, 3))
        assert np.mean(share) <= (0.02 if n == n0 else 0.1), (name, n, np.round(share, 3))


@pytest.mark.slow
def test_mode_shape_sigma_at_the_true_order_and_twice_it(case):
    name, n0, runs = case
    for n in (n0, 2 * n0):
        ratio = _cells(runs[n], "mode_shape_std_ratio_median")
        assert 0.75 <= np.nanmedian(ratio) <= 1.3, (name, n, np.round(ratio, 2))


@pytest.mark.slow
def test_plain_propagation_is_what_the_freeze_fixes():
    """The same records without the freeze: the issue's heavy tail, identical at the true order."""
    kw, n0 = CASES["chain"]
    plain = _run(kw, n0, freeze_noise=False)
    frozen = _run(kw, n0)
    # At the true order nothing is frozen, except in the records whose noise floor k* falls below
    # it (output-only mode 1 of the chain judged noise): identical σ in the others.
    a, b = plain[n0].frequency_std, frozen[n0].frequency_std
    same = np.all((a == b) | (np.isnan(a) & np.isnan(b)), axis=2)  # (method, record)
    assert same[1].mean() >= 0.95 and same[0].mean() >= 0.8, same.mean(axis=1)
    worst_plain = max(np.nanmax(plain[3 * n0].frequency_std_ratio[m]) for m in range(2))
    worst_frozen = max(np.nanmax(frozen[3 * n0].frequency_std_ratio_unflagged[m]) for m in range(2))
    assert worst_plain > 3.0 and worst_frozen < 2.5, (worst_plain, worst_frozen)
