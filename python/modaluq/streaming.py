"""Streaming: feed a record in chunks (as an acquisition system delivers it), identify at the end.

Any split of the record gives the batch :func:`modaluq.identify` result to rounding, and the
memory held does not grow with the number of samples (only per-block lag sums are kept).

A stream can be checkpointed and resumed bit for bit: ``pickle``, :meth:`CovarianceAccumulator.save`
and :meth:`CovarianceAccumulator.load` store the accumulator's whole state (format
``CHECKPOINT_FORMAT``, version ``CHECKPOINT_VERSION``; the fields are listed in
``docs/reliability.md``, "Streaming state").
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import zipfile
from typing import Any, Mapping, Sequence

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

#: ``format`` entry of a checkpoint (pickle state or ``save`` file).
CHECKPOINT_FORMAT = "modaluq.CovarianceAccumulator"
#: Version of the checkpoint layout written now; ``load`` reads only this version.
CHECKPOINT_VERSION = 1
# Scalars of a checkpoint besides format and version, and the arrays of the core's state
# (_core.CovarianceAccumulatorState; layout of each in docs/reliability.md).
_SCALARS = ("n_outputs", "n_inputs", "block_rows", "past_block_rows", "block_length", "first_sample", "end_sample")
_ARRAYS = ("shift", "total_sum", "head", "tail", "block_index", "block_count", "block_sums", "window_start",
           "window_samples")
# What a caller of load may require of a checkpoint: the constructor's parameters.
_EXPECTABLE = ("n_outputs", "n_inputs", "block_rows", "past_block_rows", "references", "block_length", "demean",
               "first_sample")


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

    A copy (``copy.copy`` or ``copy.deepcopy``) has its own state. ``pickle`` and
    :meth:`save` / :meth:`load` checkpoint the stream: pushing the rest into the restored
    accumulator gives, bit for bit, what the uninterrupted one gives.

    >>> import pickle
    >>> resumed = pickle.loads(pickle.dumps(acc))
    >>> resumed.n_samples
    20000

    A sample beyond ``MAX_SAMPLE_MAGNITUDE`` (1e60) in magnitude is refused by :meth:`push`
    with a ``ValueError`` naming it, and nothing of that push is added: its products would
    overflow the covariances or the identification, and the accumulator would be useless from
    then on.
    """

    #: Largest magnitude of a sample :meth:`push` accepts (the core's kMaxSampleMagnitude).
    MAX_SAMPLE_MAGNITUDE: float = _core.CovarianceAccumulator.max_sample_magnitude

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
        """Add samples: ``y`` is ``(n, n_outputs)``, ``u`` is ``(n, n_inputs)`` (omit when output-only).

        A non-finite sample, or one beyond ``MAX_SAMPLE_MAGNITUDE`` in magnitude, raises
        ``ValueError`` naming ``y`` or ``u``, the sample (counted from the start of the stream) and
        the channel; the accumulator is then as before the call.
        """
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

    # ------------------------------------------------------------------ copies and checkpoints

    def __copy__(self) -> "CovarianceAccumulator":
        # The state is numbers: a shallow copy sharing it would let pushes into one change the other.
        twin = object.__new__(type(self))
        twin._acc = self._acc.__copy__()
        return twin

    def __deepcopy__(self, memo) -> "CovarianceAccumulator":
        return self.__copy__()

    def __getstate__(self) -> dict[str, Any]:
        """The checkpoint: ``format``, ``version``, the layout, the block length, ``demean``, the
        sample range and the state arrays (the same mapping :meth:`save` writes)."""
        core = self._acc.export_state()
        layout = core.layout
        state: dict[str, Any] = {
            "format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION,
            "n_outputs": layout.n_outputs, "n_inputs": layout.n_inputs, "block_rows": layout.block_rows,
            "past_block_rows": layout.past_block_rows, "references": np.asarray(layout.references, dtype=np.int64),
            "block_length": core.block_length, "demean": core.demean, "first_sample": core.first_sample,
            "end_sample": core.end_sample}
        for name in _ARRAYS:
            state[name] = np.array(getattr(core, name))
        return state

    def __setstate__(self, state: Mapping[str, Any]) -> None:
        self._acc = _accumulator_from_checkpoint(state, "CovarianceAccumulator checkpoint")

    def save(self, path: str | os.PathLike) -> None:
        """Write a checkpoint of the stream to ``path`` (an ``.npz`` archive, written to a temporary
        beside it and renamed, so ``path`` is always either the old file or the whole new one).

        :meth:`load` reads it back; the entries are those of ``pickle``'s state (``format``,
        ``version``, layout, ``block_length``, ``demean``, sample range, state arrays).
        """
        path = os.fspath(path)
        state = self.__getstate__()
        directory = os.path.dirname(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp", dir=directory)
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, **state)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except BaseException as exc:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            if isinstance(exc, OSError) and not exc.filename:
                raise OSError(exc.errno, f"cannot write the checkpoint {path}: {exc.strerror or exc}", path) from exc
            raise

    @classmethod
    def load(cls, path: str | os.PathLike, **expected) -> "CovarianceAccumulator":
        """Read a checkpoint written by :meth:`save` and return the accumulator, ready to continue.

        Keywords (``n_outputs``, ``n_inputs``, ``block_rows``, ``past_block_rows``, ``references``,
        ``block_length``, ``demean``, ``first_sample``) are what the caller expects of the
        checkpoint: one that differs is refused naming the setting, so a stream is never resumed
        with other settings. A file of another format or version, or whose arrays do not fit its
        layout, is refused with a ``ValueError`` naming the file and what is wrong.
        """
        unknown = sorted(set(expected) - set(_EXPECTABLE))
        if unknown:
            raise TypeError(f"CovarianceAccumulator.load() got unexpected keyword argument(s) {', '.join(unknown)}; "
                            f"it checks {', '.join(_EXPECTABLE)}")
        path = os.fspath(path)
        with open(path, "rb") as fh:  # a missing file is the OSError naming it
            magic = fh.read(4)
        if magic != b"PK\x03\x04":  # np.load would take it for a .npy or a pickle
            raise ValueError(f"{path}: not a CovarianceAccumulator checkpoint (not an .npz archive)")
        try:
            archive = np.load(path, allow_pickle=False)
        except (ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{path}: not a CovarianceAccumulator checkpoint (not an .npz archive: {exc})") from None
        with archive:
            try:
                state = {name: archive[name] for name in archive.files}
            except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
                raise ValueError(f"{path}: the checkpoint cannot be read: {exc}") from None
        acc = object.__new__(cls)
        acc._acc = _accumulator_from_checkpoint(state, path)
        _check_expected(acc._acc, expected, path)
        return acc

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


def _accumulator_from_checkpoint(state: Mapping[str, Any], source: str) -> "_core.CovarianceAccumulator":
    """The core accumulator of a checkpoint mapping, after checking its format and version; every
    error is a ``ValueError`` starting with ``source``."""
    if not isinstance(state, Mapping):
        raise ValueError(f"{source}: not a CovarianceAccumulator checkpoint (a {type(state).__name__})")

    def entry(name):
        try:
            return np.asarray(state[name])
        except KeyError:
            raise ValueError(f"{source}: the checkpoint has no entry {name!r}") from None

    def scalar(name, kinds):
        value = entry(name)
        if value.ndim != 0 or value.dtype.kind not in kinds:
            raise ValueError(f"{source}: {name} must be a single {'boolean' if kinds == 'b' else 'integer'}; "
                             f"got {value.dtype} of shape {value.shape}")
        return value.item()

    fmt = entry("format")
    if fmt.ndim != 0 or fmt.dtype.kind != "U" or str(fmt) != CHECKPOINT_FORMAT:
        raise ValueError(f"{source}: not a CovarianceAccumulator checkpoint (format {fmt!r}, expected "
                         f"{CHECKPOINT_FORMAT!r})")
    version = scalar("version", "iu")
    if version != CHECKPOINT_VERSION:
        raise ValueError(f"{source}: checkpoint version {version} is not supported: this modaluq reads version "
                         f"{CHECKPOINT_VERSION} (write it again with the modaluq that made it, or restart the stream)")
    values = {name: scalar(name, "iu") for name in _SCALARS}
    demean = bool(scalar("demean", "b"))
    references = entry("references")
    if references.ndim != 1 or (references.size and references.dtype.kind not in "iu"):
        raise ValueError(f"{source}: references must be a 1-D array of integers; got {references.dtype} of shape "
                         f"{references.shape}")
    arrays = {}
    for name in _ARRAYS:
        value = entry(name)
        integer = name in ("block_index", "block_count", "window_start")
        if value.dtype.kind not in ("iu" if integer else "f"):
            raise ValueError(f"{source}: {name} must hold {'integers' if integer else 'floats'}; got {value.dtype}")
        arrays[name] = value.astype(np.int64 if integer else np.float64, copy=False)
    try:  # the core checks the rest (shapes against the layout, blocks, counts, finite values)
        layout = _core.HankelLayout()
        for name in ("n_outputs", "n_inputs", "block_rows", "past_block_rows"):
            setattr(layout, name, values[name])
        layout.references = [int(r) for r in references]
        core = _core.CovarianceAccumulatorState()
        core.layout = layout
        core.block_length = values["block_length"]
        core.first_sample = values["first_sample"]
        core.end_sample = values["end_sample"]
        core.demean = demean
        for name, value in arrays.items():
            setattr(core, name, value)
        return _core.CovarianceAccumulator.from_state(core)
    except (ValueError, TypeError, OverflowError) as exc:  # TypeError: an integer beyond int64
        raise ValueError(f"{source}: {exc}") from None


def _check_expected(acc: "_core.CovarianceAccumulator", expected: Mapping[str, Any], source: str) -> None:
    """Refuse a checkpoint whose settings differ from those the caller expects, naming the first."""
    layout = acc.layout
    have = dict(n_outputs=layout.n_outputs, n_inputs=layout.n_inputs, block_rows=layout.block_rows,
                past_block_rows=layout.past_block_rows or layout.block_rows,
                references=tuple(layout.references) or None, block_length=acc.block_length, demean=acc.demean,
                first_sample=acc.first_sample)
    for name in _EXPECTABLE:
        if name not in expected:
            continue
        want = expected[name]
        if name == "past_block_rows" and want is None:
            want = have["block_rows"]
        elif name == "references" and want is not None:
            want = tuple(int(r) for r in want) or None
        if want != have[name]:
            raise ValueError(f"{source}: {name} is {have[name]}, expected {want} (a checkpoint of other settings)")
