"""Provenance: what produced a result (modaluq version, settings, the input file's checksum, time).

Every report (JSON, NetCDF) carries one stamp; :func:`jsonable` turns NumPy values, enums and
paths into plain JSON values for it.
"""

from __future__ import annotations

import datetime
import hashlib
import os
import platform
from pathlib import Path

import numpy as np

from .version import __version__

__all__ = ["file_sha256", "jsonable", "provenance"]


def file_sha256(path, chunk_bytes: int = 1 << 20) -> str:
    """SHA-256 checksum (hex) of a file's bytes, read in chunks of ``chunk_bytes``."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(chunk_bytes), b""):
            h.update(block)
    return h.hexdigest()


def jsonable(x):
    """Convert NumPy scalars/arrays, enums, paths and non-finite floats into JSON values."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        x = float(x)
        return x if np.isfinite(x) else None
    if isinstance(x, os.PathLike):
        return os.fspath(x)
    if x is None or isinstance(x, str):
        return x
    if hasattr(x, "value"):  # enum
        return jsonable(x.value)
    return str(x)


def provenance(source=None, *, settings: dict | None = None) -> dict:
    """A provenance stamp: modaluq version, UTC timestamp, settings and the input's checksum.

    Parameters
    ----------
    source : str or os.PathLike, optional
        The input data file; its absolute path, size in bytes and SHA-256 are recorded.
    settings : dict, optional
        Every setting of the analysis (identification, stability criteria, clustering...).

    Returns
    -------
    dict
        JSON-ready.
    """
    stamp = {
        "modaluq_version": __version__,
        "created_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "python_version": platform.python_version(),
        "numpy_version": np.__version__,
    }
    if source is not None:
        p = Path(source)
        stamp["input_file"] = {"path": str(p.resolve()), "size_bytes": p.stat().st_size,
                               "sha256": file_sha256(p)}
    stamp["settings"] = jsonable(settings or {})
    return stamp
