"""Streaming: feed a record in chunks (as an acquisition system delivers it), identify at the end.

Any split of the record gives the batch :func:`modaluq.identify` result to rounding, and the
memory held does not grow with the number of samples (only per-block lag sums are kept).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from . import _core
from ._blas import single_threaded as single_threaded_blas
from .checks import (
    as_samples,
    check_boolean,
    check_cost,
    check_integer,
    check_integers,
    naming_settings_on_memory_error,
)
from .identification import make_settings
from .results import Result, result_from_core, warn_all
from .settings import PREPROCESSING_FIELDS, Settings

__all__ = ["CovarianceAccumulator"]


class CovarianceAccumulator:
    """Accumulate the Hankel covariances of a record fed in chunks.

    Parameters
    ----------
    n_outputs, n_inputs : int
        Channels of ``y`` and of ``u`` (0 for output-only).
    block_rows, past_block_rows, references
        As in :func:`modaluq.identify`.
    block_length : int
        Hankel columns per uncertainty block, N_b (the total length is not known in advance,
        so the block length is given instead of the number of blocks). At least p + q.
    demean : bool
        Remove each channel's mean over the whole record (exact, without knowing it in advance).
    first_sample : int
        Index in the record of the first sample this accumulator will see; non-zero only for a
        span that is merged after another one (see :meth:`merge`).

    Examples
    --------
    >>> import modaluq
    >>> sim = modaluq.simulate(20_000, seed=1)
    >>> acc = modaluq.CovarianceAccumulator(3, 1, block_rows=15, block_length=400)
    >>> for start in range(0, 20_000, 4096):
    ...     acc.push(sim.y[start:start + 4096], sim.u[start:start + 4096])
    >>> result = acc.identify(fs=sim.fs, orders=12)
    """

    def __init__(self, n_outputs: int, n_inputs: int = 0, *, block_rows: int, past_block_rows: int | None = None,
                 references: Sequence[int] | None = None, block_length: int, demean: bool = True,
                 first_sample: int = 0):
        layout = _core.HankelLayout()
        layout.n_outputs = check_integer("n_outputs", n_outputs, minimum=1)
        layout.n_inputs = check_integer("n_inputs", n_inputs, minimum=0)
        layout.block_rows = check_integer("block_rows", block_rows, minimum=2)
        layout.past_block_rows = (0 if past_block_rows is None
                                  else check_integer("past_block_rows", past_block_rows, minimum=1))
        layout.references = [] if references is None else check_integers("references", references, minimum=0)
        # first_sample counts a whole stream (months of samples), not one array: only the core's
        # 64-bit index bounds it
        self._acc = _core.CovarianceAccumulator(layout,
                                                check_integer("block_length", block_length, minimum=1, maximum=2**50),
                                                check_boolean("demean", demean),
                                                check_integer("first_sample", first_sample, minimum=0, maximum=2**62))

    @property
    def n_samples(self) -> int:
        """Samples pushed so far."""
        return self._acc.n_samples

    @property
    def block_length(self) -> int:
        return self._acc.block_length

    @property
    def state_bytes(self) -> int:
        """Bytes of state held: it grows with the number of blocks, not with the samples."""
        return int(self._acc.state_bytes)

    def push(self, y, u=None) -> None:
        """Add samples: ``y`` is ``(n, n_outputs)``, ``u`` is ``(n, n_inputs)`` (omit when output-only)."""
        layout = self._acc.layout
        y = as_samples(y, "y", n_channels=layout.n_outputs)
        if layout.n_inputs:
            u = as_samples(u, "u", n_channels=layout.n_inputs)
            if u.shape[0] != y.shape[0]:
                raise ValueError(f"u must have as many samples as y ({y.shape[0]}); got {u.shape[0]}")
            u_t = u.T
        else:
            if u is not None:
                raise ValueError("u was given but this accumulator has n_inputs=0")
            u_t = np.empty((0, y.shape[0]))
        self._acc.push(y.T, u_t)

    def merge(self, following: "CovarianceAccumulator") -> None:
        """Append an accumulator over the span that directly follows this one."""
        if not isinstance(following, CovarianceAccumulator):
            raise TypeError(f"following must be a CovarianceAccumulator; got {type(following).__name__}")
        self._acc.merge(following._acc)

    def covariances(self, with_blocks: bool = True):
        """The covariances R1..R4 (and per-block covariances) of everything pushed so far."""
        return self._acc.finish(check_boolean("with_blocks", with_blocks))

    def identify(self, *, fs: float, orders, settings: Settings | None = None, **keywords) -> Result:
        """Identify from everything pushed so far (see :func:`modaluq.identify`).

        ``settings`` / ``keywords`` as there, except what the accumulator fixed when it was made
        (horizons, references, ``demean``) and the preprocessing (the samples are already summed).
        """
        s = make_settings(settings, dict(keywords, orders=orders), function="CovarianceAccumulator.identify")
        fixed = ("block_rows", "past_block_rows", "references", "demean") + PREPROCESSING_FIELDS
        default = Settings()
        given = [k for k in fixed if getattr(s, k) != getattr(default, k)]
        if given:
            raise TypeError(f"CovarianceAccumulator.identify: {given[0]} is fixed when the accumulator is made "
                            "(or, for preprocessing, before the samples are pushed)")
        layout = self._acc.layout
        check_cost(0, layout.n_outputs, layout.n_inputs,  # before finish(), which allocates the blocks
                   s.replace(block_rows=layout.block_rows, past_block_rows=layout.past_block_rows or None,
                             n_blocks=max(self._acc.n_samples // self._acc.block_length, 2)),
                   n_references=len(layout.references) or None)
        cov = self._acc.finish(s.uncertainty)
        s = s.replace(block_rows=layout.block_rows, past_block_rows=layout.past_block_rows or None,
                      references=tuple(layout.references) or None, demean=self._acc.demean,
                      n_blocks=max(int(cov.n_blocks), 2))
        o = s.to_core(fs)
        # the covariance pass uses no BLAS; the propagation does
        with single_threaded_blas(), naming_settings_on_memory_error(s):
            ident = _core.identify_covariances(cov, o)
        result = result_from_core(ident, s.record(o.fs, layout.n_outputs), layout.n_outputs, layout.n_inputs)
        warn_all(result)
        return result
