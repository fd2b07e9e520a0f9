"""Write identification reports: JSON (with a provenance stamp), CSV and NetCDF.

- **JSON** (:func:`write_json`): a provenance stamp (modaluq version, every setting, the input
  file's SHA-256, a UTC timestamp) and the selected modes with their analytic σ and the spread
  across their cluster, mode shapes per channel.
- **CSV** (:func:`write_csv`): one row per selected mode (``SelectedModes.to_dataframe()``);
  plain table, no comment lines (the stamp lives in the JSON and NetCDF files).
- **NetCDF-4** (:func:`write_netcdf`, needs xarray and netCDF4, extra ``export``): the full
  stabilization diagram, every pole with status, reason and σ, plus the selected modes, with
  the stamp as global attributes.

>>> from modaluq import export                                          # doctest: +SKIP
>>> stamp = export.provenance("run1.csv", settings={"identification": result.settings})  # doctest: +SKIP
>>> export.write("modes.json", diagram, selected, stamp=stamp)          # doctest: +SKIP
"""

from __future__ import annotations

import datetime
import hashlib
import importlib
import json
import os
import platform
from pathlib import Path

import numpy as np

__all__ = ["EXTENSIONS", "file_sha256", "provenance", "report", "require", "write", "write_csv", "write_json",
           "write_netcdf"]

#: file extension -> what :func:`write` writes
EXTENSIONS = {".json": "json", ".csv": "csv", ".nc": "netcdf", ".nc4": "netcdf"}

#: optional dependency -> the extra of modaluq that installs it
EXTRAS = {"xarray": "export", "netCDF4": "export"}


def require(module: str, purpose: str = "this"):
    """Import an optional dependency, or raise an ImportError that says which extra installs it.

    modaluq is installed from its source tree (it is not on the package index), hence the
    ``pip install ".[extra]"`` in the message.
    """
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        extra = EXTRAS.get(module, "all")
        raise ImportError(f"{purpose} needs {module}, which is not installed: run pip install \".[{extra}]\" "
                          f"in the modaluq source directory (or pip install {module})") from exc


def file_sha256(path, chunk_bytes: int = 1 << 20) -> str:
    """SHA-256 checksum (hex) of a file's bytes, read in chunks of ``chunk_bytes``."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(chunk_bytes), b""):
            h.update(block)
    return h.hexdigest()


def _jsonable(x):
    """Convert NumPy scalars/arrays, enums, paths and non-finite floats into JSON values."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
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
        return _jsonable(x.value)
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
    from . import __version__

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
    stamp["settings"] = _jsonable(settings or {})
    return stamp


def report(diagram, selected, *, stamp: dict | None = None, extra: dict | None = None) -> dict:
    """The JSON report as a dict: stamp, diagram summary, selected modes (see :func:`write_json`)."""
    from .stabilization import PoleStatus

    out = {"stamp": stamp if stamp is not None else provenance()}
    if extra:
        out.update(_jsonable(extra))
    if diagram is not None:
        out["diagram"] = {
            "orders": list(diagram.orders),
            "n_poles": diagram.n_poles,
            "status_counts": {s.value: diagram.count(s) for s in PoleStatus},
            "close_singular_value_orders": list(diagram.close_singular_value_orders),
            "noise_coupled_poles": int(np.count_nonzero(diagram.noise_coupled)),
            "criteria": diagram.criteria.to_dict(),
            "has_uncertainty": bool(diagram.has_uncertainty),
            "output_names": list(diagram.output_names),
        }
    sel = selected.to_dict()
    out["clustering"] = {k: sel[k] for k in ("clustering", "min_cluster_size", "dropped_clusters")}
    out["units"] = {"frequency_hz": "Hz", "damping_ratio": "fraction (0.02 = 2 %)",
                    "std": "analytic (delta-method) standard deviation, median over the poles of the mode's cluster that are not noise-coupled and not at a close cut",
                    "spread": "sample standard deviation across the poles of the mode's cluster",
                    "mode_shape": "normalised: largest-modulus component = 1"}
    out["modes"] = sel["modes"]
    return _jsonable(out)


def write_json(path, diagram, selected, *, stamp: dict | None = None, extra: dict | None = None) -> Path:
    """Write :func:`report` to ``path`` as indented UTF-8 JSON; return the path."""
    path = Path(path)
    text = json.dumps(report(diagram, selected, stamp=stamp, extra=extra), indent=2, allow_nan=False)
    path.write_text(text + "\n", encoding="utf-8")
    return path


def write_csv(path, selected) -> Path:
    """Write the selected modes (one row each, with σ and spread) as CSV; return the path."""
    path = Path(path)
    selected.to_dataframe().to_csv(path, index=True)  # the index is the mode number, from 1
    return path


def write_netcdf(path, diagram, selected=None, *, stamp: dict | None = None) -> Path:
    """Write the full diagram (every pole, status, reason, σ) and the selected modes to NetCDF-4."""
    require("netCDF4", "writing NetCDF")  # xarray's own message would name an "engine", not the package
    path = Path(path)
    ds = diagram.to_xarray(selected, attrs={"stamp": json.dumps(_jsonable(stamp or provenance()))})
    ds.to_netcdf(path, engine="netcdf4")
    return path


def write(path, diagram, selected, *, stamp: dict | None = None, extra: dict | None = None) -> Path:
    """Write by extension: ``.json`` (:func:`write_json`), ``.csv`` (:func:`write_csv`), ``.nc``
    (:func:`write_netcdf`). Raises ``ValueError`` naming ``path`` for another extension."""
    kind = EXTENSIONS.get(Path(path).suffix.lower())
    if kind is None:
        raise ValueError(f"path {os.fspath(path)!r}: unsupported extension; use one of "
                         f"{', '.join(EXTENSIONS)}")
    if kind == "json":
        return write_json(path, diagram, selected, stamp=stamp, extra=extra)
    if kind == "csv":
        return write_csv(path, selected)
    return write_netcdf(path, diagram, selected, stamp=stamp)
