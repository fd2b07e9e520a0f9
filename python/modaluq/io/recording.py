"""The :class:`Recording` container returned by every loader of :mod:`modaluq.io`."""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from ..checks import check_sampling_frequency

__all__ = ["Recording"]


def check_fs(fs, source: str = "") -> float:
    """A sampling frequency from a file or an argument: a finite real number > 0, or a one-element
    array of one (a file stores it so); ``source`` (the file) prefixes a range error."""
    if isinstance(fs, np.ndarray):
        if fs.size != 1 or fs.dtype.kind not in "iuf":
            raise TypeError(f"fs must be a real number in Hz; got an array of shape {fs.shape} "
                            f"and dtype {fs.dtype}")
        fs = fs.reshape(()).item()
    try:
        return check_sampling_frequency(fs)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}" if source else str(exc)) from None


def _as_str_tuple(values, n: int, what: str, default) -> tuple[str, ...]:
    """Normalise names/units to a tuple of ``n`` strings.

    ``values`` may be None (-> ``default(i)``), a single string (units only, broadcast) or a
    sequence of strings of length ``n``.
    """
    if values is None:
        return tuple(default(i) for i in range(n))
    if isinstance(values, str):
        if what.endswith("units"):
            return (values,) * n
        raise TypeError(f"{what} must be a sequence of strings, not a single string")
    if isinstance(values, np.ndarray):
        values = values.tolist()
    try:
        values = list(values)
    except TypeError:
        raise TypeError(f"{what} must be a sequence of strings, got {type(values).__name__}") from None
    out = []
    for v in values:
        if isinstance(v, bytes):
            v = v.decode("utf-8", "replace")
        if not isinstance(v, str):
            raise TypeError(f"{what} must contain strings, got {type(v).__name__} ({v!r})")
        out.append(v)
    if len(out) != n:
        raise ValueError(f"{what} has {len(out)} entries but there are {n} channels")
    return tuple(out)


def _as_samples(samples, what: str = "samples") -> np.ndarray:
    """Return ``samples`` as a 2-D float64 C-contiguous array (1-D -> one column)."""
    if isinstance(samples, (str, bytes)) or samples is None:
        raise TypeError(f"{what} must be a numeric array, got {type(samples).__name__}")
    arr = np.asarray(samples)
    if arr.dtype == object:
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError):
            raise TypeError(f"{what} must be a numeric array, got an array of objects") from None
    if arr.dtype.kind == "c":
        raise TypeError(f"{what} must be real, got complex dtype {arr.dtype}")
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{what} must be a real numeric array, got dtype {arr.dtype}")
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise ValueError(f"{what} must be 1-D or 2-D (n_samples, n_channels), got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _none_if_empty(v):
    if v is None or (isinstance(v, (tuple, list)) and len(v) == 0):
        return None
    if isinstance(v, np.ndarray) and v.size == 0:
        return None
    return v


def _first_nonfinite(arr: np.ndarray) -> tuple[int, int] | None:
    bad = ~np.isfinite(arr)
    if not bad.any():
        return None
    r, c = np.argwhere(bad)[0]
    return int(r), int(c)


def _resolve_inputs(inputs, names: Sequence[str], source: str = "") -> list[int]:
    """Turn an ``inputs`` selection (names and/or indices) into column indices (given order)."""
    n = len(names)
    if inputs is None:
        return []
    if isinstance(inputs, (str, numbers.Integral)) and not isinstance(inputs, (bool, np.bool_)):
        inputs = [inputs]
    elif isinstance(inputs, np.ndarray):
        inputs = inputs.tolist()
    elif not isinstance(inputs, (list, tuple, range)):
        raise TypeError(
            "inputs must be a list of channel names (str) or indices (int), "
            f"got {type(inputs).__name__}")
    where = f"{source}: " if source else ""
    idx: list[int] = []
    for item in inputs:
        if isinstance(item, (bool, np.bool_)):
            raise TypeError(f"inputs entries must be channel names (str) or indices (int), got {item!r}")
        if isinstance(item, numbers.Integral):
            i = int(item)
            if not -n <= i < n:
                raise ValueError(f"{where}input index {i} is out of range for {n} channels")
            idx.append(i % n)
        elif isinstance(item, str):
            hits = [k for k, nm in enumerate(names) if nm == item]
            if not hits:
                shown = ", ".join(repr(s) for s in names[:20]) + (", ..." if n > 20 else "")
                raise ValueError(f"{where}input channel {item!r} not found; channels are: {shown}")
            if len(hits) > 1:
                raise ValueError(f"{where}input channel name {item!r} is ambiguous (columns {hits}); "
                                 "select it by index")
            idx.append(hits[0])
        else:
            raise TypeError(
                f"inputs entries must be channel names (str) or indices (int), got {type(item).__name__}")
    if len(set(idx)) != len(idx):
        raise ValueError(f"{where}inputs selects the same channel more than once: {list(inputs)!r}")
    if len(idx) == n:
        raise ValueError(f"{where}inputs selects all {n} channels; at least one output is needed")
    return idx


def _summ(names: Iterable[str], k: int = 3, width: int = 24) -> str:
    names = [n if len(n) <= width else n[:width - 3] + "..." for n in names]
    s = ", ".join(names[:k])
    return s + (f", ... (+{len(names) - k})" if len(names) > k else "")


@dataclass(frozen=True, eq=False)
class Recording:
    """A multichannel, uniformly sampled recording ready for system identification.

    Attributes
    ----------
    y : ndarray, shape (n_samples, n_outputs)
        Output (response) channels, float64, C-contiguous.
    u : ndarray, shape (n_samples, n_inputs) or None
        Known (measured) input channels, or None for output-only data.
    fs : float
        Sampling frequency in Hz.
    output_names, input_names, output_units, input_units : tuple of str
        One entry per column of ``y`` / ``u``; units are ``''`` when unknown.
    source : str
        File path or a short description of where the data came from.

    Construction validates everything: shapes must agree, ``fs`` must be finite and > 0 and the
    samples must be finite (NaN/Inf raise ``ValueError`` naming the channel and the sample).
    Missing names default to ``y0, y1, ...`` and ``u0, u1, ...``; missing units to ``''``.
    """

    y: np.ndarray
    u: np.ndarray | None
    fs: float
    output_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    output_units: tuple[str, ...] = ()
    input_units: tuple[str, ...] = ()
    source: str = ""

    def __post_init__(self):
        set_ = object.__setattr__
        if not isinstance(self.source, str):
            raise TypeError(f"source must be a string, got {type(self.source).__name__}")
        src = self.source
        fs = check_fs(self.fs, src)
        y = _as_samples(self.y, "y")
        if y.shape[0] < 1 or y.shape[1] < 1:
            raise ValueError(f"{src + ': ' if src else ''}y is empty (shape {y.shape})")
        u = self.u
        if u is not None:
            u = _as_samples(u, "u")
            if u.shape[1] == 0:
                u = None
            elif u.shape[0] != y.shape[0]:
                raise ValueError(f"{src + ': ' if src else ''}u has {u.shape[0]} samples but y has "
                                 f"{y.shape[0]}")
        n_out, n_in = y.shape[1], (0 if u is None else u.shape[1])
        onames = _as_str_tuple(_none_if_empty(self.output_names), n_out, "output_names",
                               lambda i: f"y{i}")
        inames = _as_str_tuple(_none_if_empty(self.input_names), n_in, "input_names",
                               lambda i: f"u{i}")
        ounits = _as_str_tuple(_none_if_empty(self.output_units), n_out, "output_units",
                               lambda i: "")
        iunits = _as_str_tuple(_none_if_empty(self.input_units), n_in, "input_units",
                               lambda i: "")
        for arr, names, kind in ((y, onames, "output"), (u, inames, "input")):
            if arr is None:
                continue
            bad = _first_nonfinite(arr)
            if bad is not None:
                r, c = bad
                raise ValueError(
                    f"{src + ': ' if src else ''}non-finite value ({arr[r, c]}) in {kind} channel "
                    f"{names[c]!r} at sample {r} (0-based)")
        set_(self, "y", y)
        set_(self, "u", u)
        set_(self, "fs", fs)
        set_(self, "output_names", onames)
        set_(self, "input_names", inames)
        set_(self, "output_units", ounits)
        set_(self, "input_units", iunits)

    # ------------------------------------------------------------------ derived quantities
    @property
    def n_samples(self) -> int:
        return int(self.y.shape[0])

    @property
    def n_outputs(self) -> int:
        return int(self.y.shape[1])

    @property
    def n_inputs(self) -> int:
        return 0 if self.u is None else int(self.u.shape[1])

    @property
    def duration(self) -> float:
        """Length of the record in seconds, ``n_samples / fs``."""
        return self.n_samples / self.fs

    @property
    def dt(self) -> float:
        return 1.0 / self.fs

    @property
    def t(self) -> np.ndarray:
        """Time vector in seconds, starting at 0."""
        return np.arange(self.n_samples) / self.fs

    def __repr__(self) -> str:
        parts = [f"{self.n_samples} samples", f"fs={self.fs:g} Hz", f"{self.duration:g} s",
                 f"{self.n_outputs} output{'s' * (self.n_outputs != 1)} "
                 f"[{_summ(self.output_names)}]"]
        if self.n_inputs:
            parts.append(f"{self.n_inputs} input{'s' * (self.n_inputs != 1)} "
                         f"[{_summ(self.input_names)}]")
        if self.source:
            src = self.source if len(self.source) <= 60 else "..." + self.source[-57:]
            parts.append(f"source={src!r}")
        return "Recording(" + ", ".join(parts) + ")"

    # ------------------------------------------------------------------ construction helper
    @classmethod
    def from_arrays(cls, samples, fs, names=None, units=None, inputs=None, source: str = ""
                    ) -> "Recording":
        """Build a Recording from one sample matrix whose columns are all the channels.

        Parameters
        ----------
        samples : array_like, shape (n_samples, n_channels) or (n_samples,)
        fs : float
            Sampling frequency in Hz.
        names : sequence of str, optional
            One name per column; default ``ch0, ch1, ...``.
        units : str or sequence of str, optional
            One unit per column (a single string applies to all); default ``''``.
        inputs : list of str/int, optional
            Columns that are known inputs, by name or by (0-based, negative allowed) index;
            ``u`` holds them in the order given. The remaining columns, in their original order,
            are the outputs.
        source : str
            Where the data came from (used in error messages and the repr).
        """
        if not isinstance(source, str):
            raise TypeError(f"source must be a string, got {type(source).__name__}")
        fs = check_fs(fs, source)
        arr = _as_samples(samples)
        n_ch = arr.shape[1]
        if arr.shape[0] == 0 or n_ch == 0:
            raise ValueError(f"{source + ': ' if source else ''}no samples (shape {arr.shape})")
        names_t = _as_str_tuple(names, n_ch, "names", lambda i: f"ch{i}")
        units_t = _as_str_tuple(units, n_ch, "units", lambda i: "")
        in_idx = _resolve_inputs(inputs, names_t, source)
        in_set = set(in_idx)
        out_idx = [i for i in range(n_ch) if i not in in_set]
        u = arr[:, in_idx] if in_idx else None
        return cls(
            y=arr[:, out_idx] if in_idx else arr,
            u=u,
            fs=fs,
            output_names=tuple(names_t[i] for i in out_idx),
            input_names=tuple(names_t[i] for i in in_idx),
            output_units=tuple(units_t[i] for i in out_idx),
            input_units=tuple(units_t[i] for i in in_idx),
            source=source,
        )
