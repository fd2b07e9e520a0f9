"""modaluq.intervals and SelectedModes.intervals (the core's interval.hpp, docs/uq-math.md §14): the
95 % interval x ± t σ with t the Student-t quantile of n_blocks − 1 degrees of freedom.

The core's quantile against SciPy's; the selected modes' intervals, table line and exports against
f ± t σ formed here with SciPy's t; the refusals by name.
"""

import json

import numpy as np
import pytest
from scipy.stats import t as student_t

import modaluq
from modaluq import _core
from modaluq.intervals import interval_factor, normal_coverage
from modaluq.validation.statistics import blocks_used


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 7, 12, 14, 24, 49, 199, 4999])
def test_the_cores_quantile_and_probability_are_scipys(dof):
    for level in (0.01, 0.5, 0.9, 0.95, 0.99, 0.999):
        assert _core.student_t_quantile(level, dof) == pytest.approx(student_t.ppf(0.5 + 0.5 * level, dof),
                                                                     rel=1e-11)
    for x in (0.0, 0.4, 1.96, 3.0, 12.0):
        assert _core.student_t_probability(x, dof) == pytest.approx(2 * student_t.cdf(x, dof) - 1, abs=1e-13)


def test_interval_factor_takes_n_blocks_minus_one_degrees_of_freedom():
    assert interval_factor(15) == pytest.approx(student_t.ppf(0.975, 14), rel=1e-12)   # 2.145
    assert interval_factor(50, 0.9) == pytest.approx(student_t.ppf(0.95, 49), rel=1e-12)
    assert interval_factor(0) == pytest.approx(1.959963984540054, rel=1e-12)          # unknown: normal
    assert normal_coverage(15) == pytest.approx(2 * student_t.cdf(1.96, 14) - 1, rel=1e-12)  # 0.930
    assert normal_coverage(0) == pytest.approx(0.9500042097, rel=1e-9)
    assert modaluq.interval_factor is interval_factor


@pytest.mark.parametrize("kwargs, error, name", [
    (dict(n_blocks=1), ValueError, "n_blocks"), (dict(n_blocks=-3), ValueError, "n_blocks"),
    (dict(n_blocks=2.5), TypeError, "n_blocks"), (dict(n_blocks=True), TypeError, "n_blocks"),
    (dict(n_blocks=10, level=1.0), ValueError, "level"), (dict(n_blocks=10, level=0.0), ValueError, "level"),
    (dict(n_blocks=10, level=float("nan")), ValueError, "level"), (dict(n_blocks=10, level="95%"), TypeError, "level"),
    (dict(n_blocks=10, level=1 - 1e-10), ValueError, "level"),
])
def test_bad_arguments_are_refused_by_name(kwargs, error, name):
    with pytest.raises(error, match=name):
        interval_factor(**kwargs)


@pytest.fixture(scope="module")
def selected(chain):
    result = modaluq.identify(chain.y, chain.u, fs=chain.fs, orders=range(2, 31, 2), block_rows=15, n_blocks=30)
    return result, result.select_modes()


def test_selected_modes_intervals_are_f_plus_minus_t_sigma(selected):
    result, sel = selected
    assert sel.n_blocks == result.n_blocks == 30 and sel.n_modes >= 4
    t = student_t.ppf(0.975, 29)
    assert sel.interval_factor() == pytest.approx(t, rel=1e-12)
    iv = sel.intervals()
    np.testing.assert_allclose(iv["frequency_low_hz"], sel.frequency_hz - t * sel.frequency_std, rtol=1e-14)
    np.testing.assert_allclose(iv["frequency_high_hz"], sel.frequency_hz + t * sel.frequency_std, rtol=1e-14)
    np.testing.assert_allclose(iv["damping_low"], sel.damping_ratio - t * sel.damping_std, rtol=1e-12)
    np.testing.assert_allclose(iv["damping_high"], sel.damping_ratio + t * sel.damping_std, rtol=1e-12)
    assert list(iv.index) == list(range(1, sel.n_modes + 1))
    t90 = student_t.ppf(0.95, 29)
    np.testing.assert_allclose(sel.intervals(0.9)["frequency_high_hz"], sel.frequency_hz + t90 * sel.frequency_std,
                               rtol=1e-14)
    # the table says how to read it; the frame, the JSON and the NetCDF carry the 95 % bounds
    assert f"95 % intervals: value +- {t:.3f} std (Student t of 30 blocks)" in str(sel)
    df = sel.to_dataframe()
    np.testing.assert_allclose(df["frequency_high_95_hz"], iv["frequency_high_hz"], rtol=0)
    np.testing.assert_allclose(df["damping_low_95"], iv["damping_low"], rtol=0)
    d = json.loads(json.dumps(sel.to_dict()))
    assert d["interval_95"] == {"level": 0.95, "factor": pytest.approx(t, rel=1e-12), "n_blocks": 30}
    assert d["modes"][0]["frequency_interval_95_hz"] == pytest.approx(
        [iv["frequency_low_hz"].iloc[0], iv["frequency_high_hz"].iloc[0]], rel=1e-15)
    ds = result.stabilization_diagram().to_xarray(selected=sel)
    np.testing.assert_allclose(ds["selected_damping_high_95"].values, iv["damping_high"], rtol=0)
    assert ds["selected_frequency_low_95_hz"].attrs["units"] == "Hz"


def test_the_intervals_take_the_cores_count_of_blocks(chain):
    """6,000 samples in 150 blocks: the core cuts the remainder into whole blocks too (153), and
    every interval takes that count (SciPy's t of it − 1)."""
    result = modaluq.identify(chain.y, chain.u, fs=chain.fs, orders=range(2, 21, 2), block_rows=15, n_blocks=150)
    assert result.n_blocks > 150
    t = student_t.ppf(0.975, result.n_blocks - 1)
    sel = result.select_modes()
    assert sel.n_blocks == result.at_order(12).n_blocks == result.stabilization_diagram().n_blocks == result.n_blocks
    assert sel.interval_factor() == pytest.approx(t, rel=1e-12)
    assert result.at_order(12).interval_factor() == pytest.approx(t, rel=1e-12)


def test_without_uncertainty_there_is_no_interval(chain):
    result = modaluq.identify(chain.y, chain.u, fs=chain.fs, orders=range(2, 31, 2), block_rows=15,
                              uncertainty=False)
    sel = result.select_modes()
    assert sel.n_blocks == 0 and sel.n_modes >= 4
    assert np.isnan(sel.intervals().to_numpy()).all()
    assert "intervals" not in str(sel)
    assert sel.to_dict()["interval_95"] == {"level": 0.95, "factor": None, "n_blocks": 0}


@pytest.fixture(scope="module")
def long_chain():
    return modaluq.simulate(20_000, seed=7)


@pytest.mark.parametrize("n_samples, p, q, n_blocks", [(20_000, 12, 12, 200), (10_000, 15, 15, 50), (6_000, 15, 10, 31),
                                                       (6_000, 12, 12, 200), (4_003, 8, 8, 12)])
def test_the_blocks_a_monte_carlo_reads_are_the_cores(long_chain, n_samples, p, q, n_blocks):
    """MonteCarloResult reads its interval factor from the blocks the core formed, which can be more
    than the n_blocks asked for (the remainder cut into whole blocks too: 201 and 206 for 200 here):
    the rule against identify's count."""
    res = modaluq.identify(long_chain.y[:n_samples], fs=long_chain.fs, orders=[6], block_rows=p, past_block_rows=q,
                           n_blocks=n_blocks)
    settings = dict(n_samples=n_samples, block_rows=p, past_block_rows=q, n_blocks=n_blocks)
    assert blocks_used(settings) == res.n_blocks
    assert blocks_used(dict(n_blocks=n_blocks)) == n_blocks and blocks_used({}) == 0


def test_each_orders_modes_give_their_intervals(selected, chain):
    """Result.at_order(n): the same intervals per order (a diagram is read at every order)."""
    result, _ = selected
    t = student_t.ppf(0.975, 29)
    for order in (12, 24):
        m = result.at_order(order)
        assert m.n_blocks == 30 and m.interval_factor() == pytest.approx(t, rel=1e-12)
        iv = m.intervals()
        np.testing.assert_allclose(iv["frequency_low_hz"], m.frequency_hz - t * m.frequency_std, rtol=1e-14)
        np.testing.assert_allclose(iv["damping_high"], m.damping_ratio + t * m.damping_std, rtol=1e-12)
        assert str(m).endswith(f"95 % intervals: value +- {t:.3f} std (Student t of 30 blocks)")
    plain = modaluq.identify(chain.y, chain.u, fs=chain.fs, orders=[12], block_rows=15, uncertainty=False).at_order(12)
    assert plain.n_blocks == 0 and np.isnan(plain.intervals().to_numpy()).all() and "intervals" not in str(plain)
