"""Helpers shared by the file loaders (path checks, error wrapping, fs from time stamps)."""

from __future__ import annotations

import contextlib
import importlib
import math
import os
import sys
from pathlib import Path

import numpy as np

from ..checks import check_boolean
from .errors import RecordingFileError, fail
from .recording import check_fs

__all__ = ["RecordingFileError", "fail", "check_path", "reading", "fs_from_time", "snap_fs",
           "pick_fs", "optional_import", "check_str_or_none", "parse_isolated"]


def check_path(path, param: str = "path") -> Path:
    """Validate ``path`` (str or os.PathLike), check it is a non-empty regular file."""
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{param} must be a str or os.PathLike, got {type(path).__name__}")
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file")
    if p.is_dir():
        raise RecordingFileError(f"{p}: is a directory, not a file")
    if p.stat().st_size == 0:
        raise RecordingFileError(f"{p}: file is empty (0 bytes)")
    return p


@contextlib.contextmanager
def reading(path, what: str):
    """Wrap exceptions raised by third-party readers into a ValueError naming the file.

    Our own :class:`RecordingFileError` passes through unchanged; everything else derived from
    :class:`Exception` (OSError, KeyError, struct.error, library-specific errors...) becomes
    ``RecordingFileError("<path>: cannot read as <what>: <original error> (corrupt, truncated,
    or another format?)")`` chained to the original exception.
    """
    try:
        yield
    except RecordingFileError:
        raise
    except (MemoryError, RecursionError) as exc:
        raise fail(path, f"cannot read as {what}: {type(exc).__name__} "
                         "(corrupt header with absurd sizes?)") from exc
    except Exception as exc:  # noqa: BLE001 - deliberately broad: wrap every library failure
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        detail = f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__
        raise fail(path, f"cannot read as {what}: {detail} (corrupt, truncated, or another "
                         "format?)") from exc


#: Time limit (s) of the isolated parse of a small file, and the seconds added per MB: a parser
#: reads far faster than 1 MB/s, so a corrupt 1 kB file that makes it loop is stopped in about
#: 5 s instead of the full ``PARSE_TIMEOUT``.
SMALL_FILE_PARSE_TIMEOUT, PARSE_SECONDS_PER_MB = 5.0, 1.0


def parse_timeout(size: int, limit: float | None = None) -> float:
    """Time limit (s) for parsing a file of ``size`` bytes in the isolated child:
    ``min(limit, SMALL_FILE_PARSE_TIMEOUT + PARSE_SECONDS_PER_MB * MB) + MB / 50``, where
    ``limit`` defaults to ``modaluq.io.PARSE_TIMEOUT`` (60 s). Small files get a few seconds,
    files from about 55 MB up the full limit, plus one second per 50 MB as before."""
    if limit is None:
        limit = float(getattr(sys.modules[__package__], "PARSE_TIMEOUT", 60.0))
    mb = size / 1e6
    return min(limit, SMALL_FILE_PARSE_TIMEOUT + PARSE_SECONDS_PER_MB * mb) + mb / 50


def parse_isolated(isolate, func, path, what: str, *args, **kwargs):
    """``func(*args, **kwargs)``, in a child process when ``isolate`` (see ``_isolate``), with
    the time limit :func:`parse_timeout` of the file's size."""
    if not check_boolean("isolate", isolate):
        return func(*args, **kwargs)
    from . import _isolate

    timeout = parse_timeout(Path(path).stat().st_size)
    return _isolate.run(func, path, what, *args, timeout=timeout, **kwargs)


def snap_fs(fs: float, rtol: float) -> float:
    """Return the 'roundest' number (fewest significant digits) within ``rtol`` of ``fs``.

    Used where fs is derived from a stored time increment of limited precision (e.g. UFF stores
    the increment with 6 significant digits, so 1/3.33333e-3 = 300.0003 is snapped to 300).
    """
    for k in range(1, 16):
        r = float(f"{fs:.{k}g}")
        if abs(r - fs) <= rtol * abs(fs):
            return r
    return fs


def fs_from_increment(dt, path, what: str = "time increment", rtol: float = 1e-12) -> float:
    try:
        dt = float(dt)
    except (TypeError, ValueError):
        raise fail(path, f"{what} {dt!r} is not a number") from None
    if not math.isfinite(dt) or dt <= 0:
        raise fail(path, f"{what} must be finite and > 0, got {dt!r}")
    return snap_fs(1.0 / dt, rtol)


def fs_from_time(t, path, *, tolerance: float = 0.01, what: str = "time column") -> float:
    """Sampling frequency from a time vector, after checking it is uniform.

    The time stamps may deviate from the least-squares uniform grid by at most
    ``tolerance * dt`` (default 1 % of a sample period); otherwise a ValueError naming the first
    offending sample is raised (gaps, jitter, non-increasing time).
    """
    t = np.asarray(t, dtype=np.float64).ravel()
    n = t.size
    if n < 2:
        raise fail(path, f"cannot derive fs from a {what} with {n} sample(s); pass fs=")
    if not np.isfinite(t).all():
        k = int(np.argmin(np.isfinite(t)))
        raise fail(path, f"{what} has a non-finite value at sample {k}")
    with np.errstate(over="ignore"):
        d = np.diff(t)
    if (d <= 0).any():
        k = int(np.argmax(d <= 0))
        raise fail(path, f"{what} is not strictly increasing (t[{k + 1}]={t[k + 1]!r} <= "
                         f"t[{k}]={t[k]!r})")
    k = np.arange(n, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        t = t - t[0]  # absolute times near the float limit would overflow the fit
        km, tm = k.mean(), t.mean()
        dt = float(np.dot(k - km, t - tm) / np.dot(k - km, k - km))
        dev = np.abs(t - (tm - dt * km + dt * k))
    if not (math.isfinite(dt) and dt > 0 and 0 < 1.0 / dt < math.inf):
        raise fail(path, f"{what} gives no usable sample period (dt={dt!r} s); pass fs=")
    worst = int(np.argmax(np.where(np.isnan(dev), np.inf, dev)))
    if not dev[worst] <= tolerance * dt:
        raise fail(path, f"{what} is not uniformly sampled: sample {worst} deviates by "
                         f"{dev[worst] / dt:.3g} sample periods from a uniform grid with "
                         f"dt={dt:.6g} s (tolerance {tolerance:g}); resample the data or pass "
                         "fs= explicitly")
    return snap_fs(1.0 / dt, 1e-9)


def pick_fs(fs_arg, fs_file, path, hint: str) -> float:
    """Explicit ``fs=`` wins; otherwise the value found in the file; otherwise an error."""
    if fs_arg is not None:
        return check_fs(fs_arg, str(path))
    if fs_file is None:
        raise fail(path, f"sampling frequency unknown: {hint}; pass fs=")
    try:
        return check_fs(fs_file, str(path))
    except (TypeError, ValueError) as exc:
        raise fail(path, f"invalid sampling frequency stored in file: {exc}") from None


def check_fs_arg(fs) -> None:
    """Validate a user-given fs early (TypeError/ValueError) so the message names ``fs``."""
    if fs is not None:
        check_fs(fs)


def optional_import(module: str, package: str, fmt: str):
    """Import an optional dependency, with an install hint if it is missing."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(
            f"reading {fmt} files needs the optional package '{package}' "
            f"(pip install {package})") from exc


def check_str_or_none(value, param: str) -> None:
    if value is not None and not isinstance(value, str):
        raise TypeError(f"{param} must be a str or None, got {type(value).__name__}")


def decode_str(v) -> str:
    """bytes / numpy scalar / 0-d array -> str."""
    if isinstance(v, np.ndarray):
        v = v.item() if v.size == 1 else v.tolist()
    if isinstance(v, (bytes, np.bytes_)):
        return bytes(v).decode("utf-8", "replace")
    return str(v)


def str_list(value, n: int | None = None) -> list[str] | None:
    """Array/list of strings (or bytes) -> list[str]; None if it cannot be interpreted."""
    if value is None:
        return None
    arr = np.asarray(value)
    if arr.dtype.kind not in "USO":
        return None
    if arr.ndim == 0:
        out = [decode_str(arr.item())]
    else:
        out = [decode_str(v).strip() for v in arr.ravel().tolist()]
    if n is not None and len(out) != n:
        return None
    return out
