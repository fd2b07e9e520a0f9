"""JSON values: the one rule for every JSON text the package writes.

JSON has no NaN and no infinity (``json.dumps`` would write the non-standard tokens ``NaN`` and
``Infinity``, which strict readers refuse), so **the package writes a non-finite number as
``null``**: a mode's σ that could not be computed, a damping ratio of a pole that is not one,
an empty statistic. Read back, ``null`` where a number is expected is NaN (:func:`number`;
``numpy.asarray(values, float)`` does the same for a list). The reports (``export.write_json``),
the provenance stamps, the NetCDF attributes that hold JSON and the Monte Carlo run files all
follow it (docs/architecture.md, "JSON").

>>> import numpy as np
>>> dumps({"f": np.float64(1.5), "std": np.nan, "n": np.int64(3), "shape": np.array([1 + 2j])})
'{"f": 1.5, "std": null, "n": 3, "shape": {"real": [1.0], "imag": [2.0]}}'
>>> number(None), number(2)
(nan, 2.0)
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

__all__ = ["dumps", "finite_or_none", "jsonable", "number"]


def finite_or_none(x) -> float | None:
    """``float(x)``, or ``None`` (JSON ``null``) when it is NaN or infinite."""
    x = float(x)
    return x if math.isfinite(x) else None


def number(x) -> float:
    """A number read from JSON: ``None`` (``null``, a non-finite value written) is NaN."""
    return math.nan if x is None else float(x)


def jsonable(x):
    """``x`` as plain JSON values.

    Dicts (keys as strings), lists and tuples recursively; NumPy arrays as (nested) lists, a
    complex array or number as ``{"real": ..., "imag": ...}``; NumPy scalars as Python ones;
    a non-finite float as ``None``; paths as strings; enums by their value; objects with a
    ``to_dict()`` (the settings) by it; anything else as ``str(x)``.
    """
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        if np.iscomplexobj(x):
            return {"real": jsonable(x.real), "imag": jsonable(x.imag)}
        return jsonable(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return finite_or_none(x)
    if isinstance(x, (np.complexfloating, complex)):
        return {"real": finite_or_none(x.real), "imag": finite_or_none(x.imag)}
    if isinstance(x, os.PathLike):
        return os.fspath(x)
    if x is None or isinstance(x, str):
        return x
    if hasattr(x, "value"):  # enum
        return jsonable(x.value)
    if not isinstance(x, type) and callable(getattr(x, "to_dict", None)):  # a settings object, not its class
        return jsonable(x.to_dict())
    return str(x)


def dumps(x, **kwargs) -> str:
    """JSON text of :func:`jsonable` ``(x)`` (``kwargs`` as for :func:`json.dumps`, e.g. ``indent``).

    ``allow_nan=False``: a NaN left would be a bug of :func:`jsonable`, not a silent ``NaN`` token.
    """
    return json.dumps(jsonable(x), allow_nan=False, **kwargs)
