"""``modaluq.simulate`` (a subpackage: the chain's mechanics in ``_chain.py``) and
``modaluq.validation`` (the run in ``montecarlo.py``, the statistics and result in
``statistics.py``) were split into modules: the import paths and the numbers are those of before.

The pinned values were computed by the package before the split (same seeds); they were equal
bit for bit, the tolerance only allows another machine's rounding.
"""

import importlib

import numpy as np

import modaluq
from modaluq.validation import MonteCarloResult, match_modes, monte_carlo, record_seed


def test_import_paths():
    simulate = importlib.import_module("modaluq.simulate")
    chain = importlib.import_module("modaluq.simulate._chain")
    assert modaluq.simulate is simulate.simulate and modaluq.Simulation is simulate.Simulation
    for name in ("chain_system", "state_space", "modal_parameters", "acceleration_response"):
        assert getattr(simulate, name) is getattr(chain, name) and name in simulate.__all__
    montecarlo = importlib.import_module("modaluq.validation.montecarlo")
    statistics = importlib.import_module("modaluq.validation.statistics")
    assert montecarlo.MonteCarloResult is statistics.MonteCarloResult is MonteCarloResult
    assert (montecarlo.match_modes, montecarlo.monte_carlo, montecarlo.record_seed) == (match_modes, monte_carlo,
                                                                                         record_seed)


def test_simulate_numbers_unchanged():
    s = modaluq.simulate(3000, seed=11)
    np.testing.assert_allclose(s.y[[0, 1500, -1]], [
        [-29.802339670923626, -71.73579805539465, -24.478543910488852],
        [-18.82270613298892, -109.13023094891388, -60.20753002067858],
        [-63.755606272284986, -76.08210126736955, 22.37830476195191]], rtol=1e-12)
    np.testing.assert_allclose(s.u[-1], [-0.5098234925044234], rtol=1e-12)


def test_monte_carlo_numbers_unchanged():
    r = monte_carlo(4, processes=1, progress=False, n_bootstrap=20)
    np.testing.assert_allclose(r.frequency_hz[1, :, 0],
                               [1.927084037296412, 1.9290528399708233, 1.9294909755311502, 1.9306024191998428],
                               rtol=1e-12)
    c = r.summary_columns()
    np.testing.assert_allclose(c["frequency_std_ratio"][:6], [1.1073105381920072, 1.4447630789850774,
                                                              1.1410652945035038, 0.968219608936426,
                                                              1.1854671720292111, 1.1093631890664095], rtol=1e-9)
    np.testing.assert_allclose(c["frequency_std_ratio_se"][:6], [0.7159025754593703, 3.0394240347122343,
                                                                 4.356804362386885, 0.47141497418488965,
                                                                 0.9164473557322877, 3.9185944856377994], rtol=1e-9)
