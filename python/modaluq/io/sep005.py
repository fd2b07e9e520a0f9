"""SDyPy SEP005 time-series dictionaries <-> Recording.

SEP005 (SDyPy enhancement proposal 5) describes a channel as a dict with the compulsory keys
``data`` (1-D samples), ``name``, ``unit_str`` and either ``fs`` (Hz) or ``time`` (s), plus
optional ``quantity``, ``unit_tex``, ``start_timestamp``, ``end_timestamp``, ``group``.
A recording is a list of such dicts. No SEP005 package is needed.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ._common import check_fs_arg, fs_from_time, snap_fs
from .recording import Recording, check_fs

__all__ = ["from_sep005", "to_sep005"]

_ALIASES = {"fs": ("fs", "sampling_rate", "sample_rate"), "time": ("time", "t"),
            "data": ("data", "values", "y"), "name": ("name", "channel", "label"),
            "unit_str": ("unit_str", "unit", "units")}


def _get(d: Mapping, key: str):
    low = {str(k).lower(): k for k in d.keys()}
    for alias in _ALIASES.get(key, (key,)):
        if alias in low:
            return d[low[alias]]
    return None


def from_sep005(channels, *, fs=None, inputs=None, source: str = "SEP005",
                time_tolerance: float = 0.01) -> Recording:
    """Build a Recording from SEP005 channel dict(s).

    Parameters
    ----------
    channels : dict or list of dict
        One dict per channel (a single dict is one channel; as a tolerance, a single dict whose
        ``data`` is 2-D (n_samples, n_channels) with a list ``name``/``unit_str`` is accepted).
        Keys are matched case-insensitively; ``unit`` is accepted for ``unit_str``.
    fs : float, optional
        Overrides the channels' ``fs``/``time``.
    inputs : list of str/int, optional
        Known-input channels by ``name`` or index in the list.

    All channels must have the same length and the same sampling frequency (no resampling is
    done). ``None`` entries in ``data`` (allowed by SEP005) are missing samples and raise
    ValueError, as do NaN values.
    """
    check_fs_arg(fs)
    if not isinstance(source, str):
        raise TypeError(f"source must be a str, got {type(source).__name__}")
    if isinstance(channels, Mapping):
        channels = [channels]
    elif not isinstance(channels, (list, tuple)):
        raise TypeError("channels must be a SEP005 dict or a list of dicts, got "
                        f"{type(channels).__name__}")
    if not channels:
        raise ValueError(f"{source}: no channels given")
    cols, names, units, fss, lens = [], [], [], [], []
    for k, ch in enumerate(channels):
        if not isinstance(ch, Mapping):
            raise TypeError(f"channels[{k}] must be a dict, got {type(ch).__name__}")
        raw = _get(ch, "data")
        if raw is None:
            raise ValueError(f"{source}: channel {k} has no 'data'")
        try:
            a = np.asarray([np.nan if v is None else v for v in raw], dtype=np.float64) \
                if isinstance(raw, (list, tuple)) else np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: channel {k} 'data' is not numeric: {exc}") from None
        if a.ndim == 0 or a.size == 0:
            raise ValueError(f"{source}: channel {k} 'data' is empty or scalar")
        if a.ndim == 1:
            a = a[:, None]
        elif a.ndim == 2 and a.shape[0] < a.shape[1]:
            a = a.T
        elif a.ndim > 2:
            raise ValueError(f"{source}: channel {k} 'data' has shape {a.shape}")
        nm, un = _get(ch, "name"), _get(ch, "unit_str")
        nch = a.shape[1]

        def as_list(v, default):
            if v is None:
                return default
            if isinstance(v, (str, bytes)):
                v = v.decode() if isinstance(v, bytes) else v
                return [v] if nch == 1 else [f"{v}[{j}]" for j in range(nch)]
            v = [str(x) for x in v]
            if len(v) != nch:
                raise ValueError(f"{source}: channel {k} has {nch} columns but {len(v)} "
                                 "names/units")
            return v

        names.extend(as_list(nm, [f"ch{len(names) + j}" for j in range(nch)]))
        u = as_list(un, [""] * nch) if not isinstance(un, str) or nch == 1 else [un] * nch
        units.extend(u)
        ch_fs = _get(ch, "fs")
        if ch_fs is not None:
            try:
                ch_fs = check_fs(ch_fs, source)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{source}: channel {k} has an invalid 'fs': {exc}") from None
        elif fs is None:
            t = _get(ch, "time")
            if t is not None:
                t = np.asarray(t, dtype=np.float64).ravel()
                if t.size != a.shape[0]:
                    raise ValueError(f"{source}: channel {k} has {a.shape[0]} samples but "
                                     f"{t.size} time stamps")
                ch_fs = fs_from_time(t, source, tolerance=time_tolerance,
                                     what=f"'time' of channel {k}")
        fss.append(ch_fs)
        lens.append(a.shape[0])
        cols.append(a)
    if len(set(lens)) != 1:
        raise ValueError(f"{source}: channels have different lengths ({lens}); SEP005 channels "
                         "with different sampling must be resampled first")
    if fs is None:
        known = [(k, v) for k, v in enumerate(fss) if v is not None]
        if not known:
            raise ValueError(f"{source}: no channel has 'fs' or 'time'; pass fs=")
        if len(known) != len(fss):
            missing = [k for k, v in enumerate(fss) if v is None]
            raise ValueError(f"{source}: channels {missing} have neither 'fs' nor 'time'")
        ref = known[0][1]
        for k, v in known[1:]:
            if abs(v - ref) > 1e-6 * ref:
                raise ValueError(f"{source}: channels have different fs ({ref:g} Hz for channel "
                                 f"{known[0][0]}, {v:g} Hz for channel {k}); resample first")
        fs = snap_fs(ref, 1e-12)
    samples = np.hstack(cols) if len(cols) > 1 else cols[0]
    return Recording.from_arrays(samples, fs, names=names, units=units, inputs=inputs,
                                 source=source)


def to_sep005(rec: Recording) -> list[dict]:
    """Export a Recording as a list of SEP005 channel dicts (outputs first, then inputs)."""
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    out = []
    blocks = [(rec.y, rec.output_names, rec.output_units, "outputs")]
    if rec.u is not None:
        blocks.append((rec.u, rec.input_names, rec.input_units, "inputs"))
    for arr, names, units, grp in blocks:
        for j in range(arr.shape[1]):
            out.append({"data": arr[:, j].copy(), "name": names[j], "unit_str": units[j],
                        "fs": rec.fs, "group": grp})
    return out
