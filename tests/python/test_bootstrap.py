"""The bootstrap of σ_f and σ_ξ above the noise floor (docs/uq-math.md §5.6): the core equals the
NumPy reference's definition (tests/python/oracle.py ``bootstrap_std``: its own SVD, least squares
and eigenvalues), orders up to k* are untouched, and bad values are refused by name."""

import pathlib
import sys

import numpy as np
import pytest

import modaluq

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import oracle  # noqa: E402

DRAWS = 30
KW = dict(block_rows=8, orders=[8, 12, 16, 20], n_blocks=20)


@pytest.fixture(scope="module", params=["OO", "IO"])
def runs(request):
    record = modaluq.simulate(6000, seed=11)
    u = record.u if request.param == "IO" else None
    plain = modaluq.identify(record.y, u, fs=record.fs, **KW)
    boot = modaluq.identify(record.y, u, fs=record.fs, bootstrap_draws=DRAWS, **KW)
    ref = oracle.identify_factor(record.y, u, fs=record.fs, block_rows=8, orders=KW["orders"], n_blocks=20,
                                 bootstrap_draws=DRAWS)
    return plain, boot, ref


def test_off_by_default():
    assert modaluq.Settings().bootstrap_draws == 0


def test_core_equals_the_reference(runs):
    plain, boot, ref = runs
    k_star = boot.significant_singular_values
    assert k_star == ref[KW["orders"][0]]["significant_singular_values"]
    assert k_star < max(KW["orders"])
    n_boot = 0
    for n in KW["orders"]:
        b, r = boot.at_order(n), ref[n]
        np.testing.assert_allclose(b.frequency_hz, r["frequency_hz"], rtol=1e-10)
        np.testing.assert_array_equal(b.bootstrapped, r["bootstrapped"])
        np.testing.assert_allclose(b.frequency_std, r["frequency_std"], rtol=1e-7)
        np.testing.assert_allclose(b.damping_std, r["damping_std"], rtol=1e-7)
        np.testing.assert_allclose(b.covariance, r["covariance"], rtol=1e-6, atol=1e-14 * np.abs(r["covariance"]).max())
        n_boot += int(b.bootstrapped.sum())
        if n <= k_star:
            assert not b.bootstrapped.any()
    assert n_boot > 0


def test_orders_up_to_the_floor_are_untouched_and_shapes_stay_first_order(runs):
    plain, boot, _ = runs
    for n in KW["orders"]:
        a, b = plain.at_order(n), boot.at_order(n)
        np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
        np.testing.assert_array_equal(a.mode_shape_std_real, b.mode_shape_std_real)
        keep = ~b.bootstrapped
        np.testing.assert_array_equal(a.frequency_std[keep], b.frequency_std[keep])
        np.testing.assert_array_equal(a.damping_std[keep], b.damping_std[keep])
        # the correlation of f and ξ is kept where σ was replaced
        np.testing.assert_allclose(a.frequency_damping_correlation, b.frequency_damping_correlation, rtol=1e-12)
        if n <= boot.significant_singular_values:
            np.testing.assert_array_equal(a.covariance, b.covariance)


@pytest.mark.parametrize("draws", [-1, 5, 9.5, True])
def test_bad_draws_are_refused_by_name(draws):
    record = modaluq.simulate(2000, seed=1)
    with pytest.raises((ValueError, TypeError), match="bootstrap_draws"):
        modaluq.identify(record.y, fs=record.fs, bootstrap_draws=draws, **KW)


def test_a_campaign_refuses_it():
    record = modaluq.simulate(6000, seed=2)
    import pandas as pd
    setups = [pd.DataFrame(record.y[:3000], columns=["a", "b", "c"]),
              pd.DataFrame(record.y[3000:], columns=["a", "b", "d"])]
    with pytest.raises(ValueError, match="bootstrap_draws applies to one record"):
        modaluq.identify_setups(setups, fs=record.fs, references=["a", "b"], block_rows=8, orders=[4, 6],
                                n_blocks=12, bootstrap_draws=20)


def test_monte_carlo_carries_the_option_into_its_report():
    from modaluq.validation import monte_carlo

    res = monte_carlo(4, order=[12, 24], block_rows=15, n_blocks=50, processes=1, progress=False, n_bootstrap=20,
                      bootstrap_draws=20)
    assert res[1].settings["bootstrap_draws"] == 20
    assert "bootstrap draws" in res[1].report()
