"""Argument checks shared by every layer: each names the argument at fault.

``TypeError`` for the wrong kind of value (a string where a switch is expected, a float where a
count is), ``ValueError`` for a value out of range. Imports nothing from the package.
"""

from __future__ import annotations

import importlib
import math
import numbers
from typing import Iterable

import numpy as np

#: Largest value of a count (samples, channels, block rows, blocks, orders, indices): products of
#: two counts then stay inside the core's 64-bit indices, so a typo is refused here, by name,
#: rather than overflowing there.
MAX_COUNT = 2**31 - 1
#: Largest ``threads``: above any machine's cores, low enough that a typo is refused.
MAX_THREADS = 256


def as_samples(x, name: str, *, allow_none: bool = False, n_channels: int | None = None):
    """Return ``x`` as a C-contiguous float64 ``(n_samples, n_channels)`` array.

    A 1-D array is one channel. Complex, boolean or non-numeric data raise ``TypeError``; more
    than two dimensions, a masked value of a :class:`numpy.ma.MaskedArray` (missing data, which
    SSI-cov cannot take) or the wrong number of channels raise ``ValueError``; all name the
    argument. With ``n_channels`` (a chunk of a stream, which may hold fewer samples than
    channels) ``x`` must have that many columns; without it ``x`` is a whole record, which must
    have more samples than channels (otherwise it is taken for a transposed array). No copy is
    made when ``x`` already is a C-contiguous float64 array.
    """
    if x is None:
        if allow_none:
            return None
        raise TypeError(f"{name} must be an array of samples, got None")
    mask = np.ma.getmaskarray(x) if isinstance(x, np.ma.MaskedArray) else None
    arr = np.asarray(x)  # a MaskedArray's data, mask dropped: checked below
    if np.iscomplexobj(arr):
        raise TypeError(f"{name} must be real; got complex data (dtype {arr.dtype})")
    if arr.dtype.kind == "b":  # True/False are not measurements (astype(float) if 0/1 is meant)
        raise TypeError(f"{name} must hold real numbers; got booleans (dtype bool)")
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold real numbers; got dtype {arr.dtype}")
    transposable = arr.ndim == 2
    if arr.ndim == 1:
        arr = arr[:, None]
    elif arr.ndim != 2:
        raise ValueError(f"{name} must have shape (n_samples, n_channels) or (n_samples,); got shape {arr.shape}")
    if mask is not None and mask.any():
        sample, channel = np.argwhere(mask.reshape(arr.shape))[0]
        raise ValueError(f"{name}: sample {sample}, channel {channel} is masked (missing data); SSI-cov needs "
                         "every sample: fill the gap or analyse the parts on either side of it")
    if n_channels is not None:
        if arr.shape[1] != n_channels:
            hint = f"; did you mean {name}.T?" if transposable and arr.shape[0] == n_channels else ""
            raise ValueError(f"{name} must have {n_channels} channels (columns); got shape {arr.shape}{hint}")
    elif arr.shape[1] == 0:
        raise ValueError(f"{name} must have at least one channel; got shape {arr.shape}")
    elif arr.shape[0] == 0:
        raise ValueError(f"{name} must have at least one sample; got shape {arr.shape}")
    elif arr.shape[1] > arr.shape[0]:
        raise ValueError(f"{name} has shape {arr.shape}: more channels ({arr.shape[1]}) than samples "
                         f"({arr.shape[0]}); samples are rows, channels columns: did you mean {name}.T?")
    return np.ascontiguousarray(arr, dtype=np.float64)


def constant_channels(x) -> list[int]:
    """Columns of a ``(n_samples, n_channels)`` array whose samples are all equal (an all-zero or
    constant channel: a dead or disconnected sensor, which carries no dynamics)."""
    x = np.asarray(x)
    if x.ndim != 2 or x.shape[0] == 0:
        return []
    return np.flatnonzero(np.all(x == x[:1], axis=0)).tolist()


def constant_channel_warning(x, names, what: str) -> str | None:
    """The warning naming the constant channels of ``x`` (``names`` one per column, ``what``
    ``"output"`` or ``"input"``), or None when there is none."""
    dead = constant_channels(x)
    if not dead:
        return None
    names = list(names) if len(names) == np.shape(x)[1] else [f"{what[0]}{k}" for k in range(np.shape(x)[1])]
    listed = ", ".join(f"{names[k]!r} (all samples {float(np.asarray(x)[0, k]):g})" for k in dead)
    return (f"{what} channel{'s' if len(dead) > 1 else ''} {listed} "
            f"{'are' if len(dead) > 1 else 'is'} constant: a dead or disconnected sensor? "
            f"{'They carry' if len(dead) > 1 else 'It carries'} no dynamics (mode shape entries 0); "
            f"leave {'them' if len(dead) > 1 else 'it'} out of the {what}s")


def check_boolean(name, value) -> bool:
    # bool("False") is True: a string or a number where a switch is expected is a mistake.
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False; got {value!r}")
    return bool(value)


def check_instance(name, value, cls):
    """``value`` if it is a ``cls``; a ``cls()`` (its defaults) for ``None``; else ``TypeError``.

    For the settings objects an analysis takes (``settings=``, ``criteria=``, ``clustering=``):
    a dict or a keyword's value in their place is refused by name, not half-used.
    """
    if value is None:
        return cls()
    if not isinstance(value, cls):
        # named as users import it: modaluq.Settings, not modaluq.settings.Settings
        raise TypeError(f"{name} must be a {cls.__module__.partition('.')[0]}.{cls.__name__}; "
                        f"got {type(value).__name__}")
    return value


def check_integer(name, value, *, minimum=None, maximum=MAX_COUNT):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer; got {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}; got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}; got {value}")
    return value


def check_integers(name, values, *, minimum=None, maximum=MAX_COUNT) -> list[int]:
    if isinstance(values, numbers.Integral) and not isinstance(values, (bool, np.bool_)):
        values = [values]
    if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
        raise TypeError(f"{name} must be an integer or an iterable of integers; got {values!r}")
    out = [check_integer(name, v, minimum=minimum, maximum=maximum) for v in values]
    if not out:
        raise ValueError(f"{name} must not be empty")
    return out


def check_real(name, value, *, low=None, high=None, low_open=False, high_open=False, allow_none=False):
    if value is None and allow_none:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number; got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite; got {value}")
    if low is not None and (value < low or (low_open and value == low)):
        raise ValueError(f"{name} must be {'>' if low_open else '>='} {low}; got {value}")
    if high is not None and (value > high or (high_open and value == high)):
        raise ValueError(f"{name} must be {'<' if high_open else '<='} {high}; got {value}")
    return value


def check_sampling_frequency(fs) -> float:
    if isinstance(fs, (bool, np.bool_)) or not isinstance(fs, numbers.Real):
        raise TypeError(f"fs must be a real number in Hz; got {fs!r}")
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"fs must be finite and > 0 Hz; got {fs}")
    return fs


#: optional dependency -> the extra of modaluq that installs it
EXTRAS = {"xarray": "export", "netCDF4": "export", "distributed": "monitor", "zarr": "monitor", "pyarrow": "monitor",
          "cryptography": "monitor"}


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
