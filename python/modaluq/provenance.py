"""Provenance: what produced a result (modaluq version, settings, the input file's checksum, time).

Every report (JSON, NetCDF) carries one stamp; :func:`jsonable` (from :mod:`modaluq.jsonvalues`,
re-exported here) turns NumPy values, enums and paths into plain JSON values for it, a
non-finite number into ``null``.
"""

from __future__ import annotations

import datetime
import hashlib
import platform
from pathlib import Path

import numpy as np

from .jsonvalues import jsonable
from .version import __version__

__all__ = ["file_sha256", "jsonable", "provenance"]


def file_sha256(path, chunk_bytes: int = 1 << 20) -> str:
    """SHA-256 checksum (hex) of a file's bytes, read in chunks of ``chunk_bytes``."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(chunk_bytes), b""):
            h.update(block)
    return h.hexdigest()


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
