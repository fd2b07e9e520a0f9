"""Validation of the analytic standard deviations by Monte Carlo simulation.

:func:`monte_carlo` repeats the reference paper's simulation study (§5.1, Tables 1 and 2):
many independent records of the 6-DOF chain, each identified output-only and input/output,
and per mode the mean analytic standard deviation compared with the sample standard
deviation of the estimates.  ``modaluq validate`` runs it from the command line.
:func:`split_halves` checks σ on a measured record instead: its two halves identified alike
(``modaluq validate --split-halves FILE``); :func:`split_halves_windows` does it on consecutive
windows of several lengths, for many more mode pairs (``--windows 1 2 4 8``).

>>> from modaluq.validation import monte_carlo
>>> mc = monte_carlo(200, processes=2)                               # doctest: +SKIP
>>> print(mc.report())                                               # doctest: +SKIP
>>> mc.plot_histograms("histograms.png")                             # doctest: +SKIP
"""

from .montecarlo import MonteCarloResult, match_modes, monte_carlo, record_seed
from .paper import METHOD_LABELS, METHODS, PAPER_N_RECORDS, PAPER_N_SAMPLES, PAPER_ORDER, PAPER_TABLE_1, PAPER_TABLE_2
from .split_halves import PooledSplitHalves, SplitHalves, split_halves, split_halves_windows

__all__ = [
    "METHODS",
    "METHOD_LABELS",
    "MonteCarloResult",
    "PAPER_N_RECORDS",
    "PAPER_N_SAMPLES",
    "PAPER_ORDER",
    "PAPER_TABLE_1",
    "PAPER_TABLE_2",
    "match_modes",
    "monte_carlo",
    "record_seed",
    "PooledSplitHalves",
    "SplitHalves",
    "split_halves",
    "split_halves_windows",
]
