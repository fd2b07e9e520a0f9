"""Confidence intervals from a σ estimated on blocks (the core's ``interval.hpp``, docs/uq-math.md §14).

Every σ of modaluq is the sample standard deviation of ``n_blocks`` block values, scaled: for a
Gaussian estimate linear in the blocks, (x − x_true)/σ follows Student's t with ``n_blocks − 1``
degrees of freedom, not the normal law. So x ± 1.96 σ covers P(|t| ≤ 1.96), 93.0 % with 15
blocks and 94.4 % with 50, and the interval that covers 95 % is x ± t σ with the t quantile:

>>> round(interval_factor(15), 3), round(interval_factor(50), 3)
(2.145, 2.01)

σ itself is left as it is (it estimates the standard deviation); the quantile belongs to the
interval. ``n_blocks=0`` means unknown (PoSER's merged modes when a setup's count is unknown, a
``SelectedModes`` made by hand): the normal quantile.
"""

from __future__ import annotations

import statistics

import numpy as np

from . import _core
from .checks import check_integer, check_real

__all__ = ["interval_factor", "interval_table", "interval_words", "normal_coverage"]


def interval_factor(n_blocks: int, level: float = 0.95) -> float:
    """The factor of a ``level`` interval x ± factor σ for a σ from ``n_blocks`` blocks.

    The Student-t quantile with ``n_blocks − 1`` degrees of freedom (``n_blocks ≥ 2``); the normal
    quantile (1.96 at 0.95) for ``n_blocks=0``, unknown. ``level`` is in (0, 1 − 1e-9].
    """
    n = check_integer("n_blocks", n_blocks, minimum=0)
    level = check_real("level", level, low=0.0, high=_core.max_interval_level, low_open=True)
    if n == 1:
        raise ValueError("n_blocks must be >= 2 (a σ needs two blocks) or 0 (unknown); got 1")
    return float(_core.interval_factor(n, level))


def normal_coverage(n_blocks: int, factor: float = 1.96) -> float:
    """The share of records whose x ± ``factor`` σ holds the truth when σ comes from
    ``n_blocks`` blocks: P(|t_{n_blocks−1}| ≤ factor) (0.930 for 1.96 at 15 blocks; the normal
    law's for ``n_blocks=0``)."""
    n = check_integer("n_blocks", n_blocks, minimum=0)
    factor = check_real("factor", factor, low=0.0)
    if n == 0:
        return 2.0 * statistics.NormalDist().cdf(factor) - 1.0
    if n == 1:
        raise ValueError("n_blocks must be >= 2 (a σ needs two blocks) or 0 (unknown); got 1")
    return float(_core.student_t_probability(factor, n - 1))


def interval_table(frequency_hz, frequency_std, damping_ratio, damping_std, factor: float):
    """The intervals x ± factor σ of f and ξ, one row per mode (numbered from 1, as every table):
    ``frequency_low_hz``, ``frequency_high_hz`` (Hz), ``damping_low``, ``damping_high`` (fraction);
    NaN where σ is. What ``SelectedModes.intervals`` and ``Modes.intervals`` return."""
    import pandas as pd

    f, sf, xi, sxi = (np.asarray(v, float) for v in (frequency_hz, frequency_std, damping_ratio, damping_std))
    return pd.DataFrame({"frequency_low_hz": f - factor * sf, "frequency_high_hz": f + factor * sf,
                         "damping_low": xi - factor * sxi, "damping_high": xi + factor * sxi},
                        index=pd.RangeIndex(1, f.size + 1, name="mode"))


def interval_words(n_blocks: int, level: float = 0.95) -> str:
    """The line under a table of modes that says how to read its ``level`` intervals."""
    t = interval_factor(n_blocks, level)
    law = f"Student t of {n_blocks} blocks" if n_blocks >= 2 else "normal quantile: the number of blocks is unknown"
    return f"{100 * level:g} % intervals: value +- {t:.3f} std ({law})"
