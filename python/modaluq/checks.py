"""Argument checks shared by every layer: each names the argument at fault.

``TypeError`` for the wrong kind of value (a string where a switch is expected, a float where a
count is), ``ValueError`` for a value out of range. Imports nothing from the package.
"""

from __future__ import annotations

import contextlib
import importlib
import math
import numbers
import os
from typing import Iterable, NamedTuple

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
    # 64 spread rows rule out almost every live channel; only the rest are compared sample by
    # sample (comparing all of a 10^6-sample record took a third of S1's time, docs/performance.md).
    rows = x[:: max(1, x.shape[0] // 64)]
    candidates = np.flatnonzero(np.all(rows == x[:1], axis=0))
    return [int(k) for k in candidates if np.all(x[:, k] == x[0, k])]


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
          "cryptography": "monitor", "pyuff": "io", "plotly": "report"}


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


# --------------------------------------------------------------------------- memory of a run
#: Environment variable that replaces the memory an identification may use (bytes, or with a
#: K, M, G or T suffix, powers of 1024): for a machine shared with other jobs, or to let a run
#: that the estimate refuses try anyway (docs/settings.md, "Memory").
MEMORY_LIMIT_ENV = "MODALUQ_MEMORY_LIMIT"
#: Noise-floor draws of the core (detail/noise_floor.hpp, kNoiseFloorDraws): each is one dH.
_NOISE_FLOOR_DRAWS = 20


class Cost(NamedTuple):
    """What :func:`estimate_cost` expects an identification to take."""

    bytes: int          #: peak memory the core allocates (the samples themselves not included)
    seconds: float      #: rough time on one core (within a factor of a few)
    parts: dict         #: bytes of the peak per setting that drives them (block_rows, n_blocks, orders)
    a: int              #: rows of H, p l
    b: int              #: columns of H, q r


def estimate_cost(n_samples: int, n_outputs: int, n_inputs: int, *, block_rows: int, past_block_rows=None,
                  n_references=None, orders, n_blocks, uncertainty: bool = True, threads: int = 1,
                  bootstrap_draws: int = 0, keep_shape_factor: bool = False) -> Cost:
    """Conservative estimate of the peak memory (and a rough time) of one identification.

    From the sizes the core allocates (cpp/include/modaluq, docs/settings.md "Memory"), with
    a = p l, b = q r, c = p m, E = ab + ac + c² + bc (the entries of R1..R4), s = min(a, b), n
    the largest order, n_b the blocks (0 without uncertainty), in float64:
    the covariance pass holds R1..R4 and the per-block covariances, E (1 + n_b); the SVD of H
    about 2 ab + 3 s² + 2 (a + b) s beside them; the propagation T_R (E n_b) and T_H (ab n_b)
    at once, then T_H with 20 noise-floor draws of dH (20 ab) and the Q matrices of every block
    at n (2 n_b (2 n² + l n)); each order, per thread, 6 n_b n² + 4 l n_b n + 4 a n; the result
    ~ sum_n n ((2 + 2l)² + 6l + 12) (n/2 poles per order, held once). The peak is the largest of
    these phases, plus the lag sums (n_b + threads)(p + q + 1) d (d + 1), d = l + m ((r + 1) for
    d + 1 output-only). With ``bootstrap_draws`` (docs/uq-math.md §5.6) T_H (ab n_b) stays through the
    orders, and each thread holds a perturbed H and its SVD (ab + svd); B SVDs and B eigenvalue
    problems per order are added to the time. With ``keep_shape_factor`` each pole also holds its
    shape factor, 2 l n_b values. ``n_samples`` 0: from covariances
    (streaming), no covariance pass. Measured peaks are 0.5 to 1 times it (tests/python/
    test_faults_resources.py).
    """
    l, m = int(n_outputs), int(n_inputs)
    p = int(block_rows)
    q = int(past_block_rows or p)
    r = int(n_references or l)
    order_list = sorted({int(o) for o in ([orders] if isinstance(orders, numbers.Integral) else orders)})
    a, b, c = p * l, q * r, p * m
    s = min(a, b)
    n = min(order_list[-1], max(a - l, 1), b)
    nb = int(n_blocks) if uncertainty else 0
    t = max(1, int(threads))
    E = a * b + a * c + c * c + b * c
    d = l + m
    # output-only with references: the lag products keep the reference columns only (lag_sums.hpp)
    lag_columns = (r if m == 0 else d) + 1
    lag_sums = (nb + t) * (p + q + 1) * d * lag_columns if n_samples else 0
    svd = 2 * a * b + 3 * s * s + 2 * (a + b) * s
    realization = 2 * (a + b) * s + 2 * a * n
    block_q = 2 * nb * (2 * n * n + l * n)
    per_order = t * (6 * nb * n * n + 4 * l * nb * n + 4 * a * n) if nb else t * 4 * a * n
    shape = (2 + 2 * l) ** 2 + 6 * l + 12 + (2 * l * nb if keep_shape_factor else 0) if nb else 2 * l + 6
    # about n/2 poles at order n (complex pairs), held once: Python's Modes view the core's arrays
    result = sum(min(o, n) for o in order_list) * shape // 2
    phases = {
        "covariances": lag_sums + E * (1 + nb) + E,
        "svd": E * (1 + nb) + E + a * b + svd,
        "propagation": E * (1 + nb) + a * b * nb + 2 * a * b + realization if nb else 0,
        "noise floor": E + a * b * nb + a * b + realization + (a + b) * s + _NOISE_FLOOR_DRAWS * a * b + block_q,
        "orders": E + a * b + realization + (a + b) * s + block_q + per_order,
    }
    boot = int(bootstrap_draws) if nb else 0
    if boot:
        phases["orders"] += a * b * nb
        phases["bootstrap"] = E + a * b * nb + a * b + realization + t * (a * b + svd + realization) + result
    if not nb:
        phases["noise floor"] = 0
    # Eigen's SVD and the allocator's slack: 1.3 x, from measured peaks (docs/settings.md)
    peak = 1.3 * 8 * (max(phases.values()) + result)
    # which setting drives the peak: H's size (block_rows), the blocks, the orders
    h_terms = 8 * (E + a * b + svd + realization + (_NOISE_FLOOR_DRAWS * a * b if nb else 0))
    blocks = 8 * (E * nb + a * b * nb) if nb else 0
    order_terms = 8 * (block_q + per_order + result)
    parts = {"block_rows": h_terms, "n_blocks": blocks, "orders": order_terms}
    flops = (2.0 * n_samples * (p + q) * d * d + 10.0 * a * b * s
             + (nb * (2.0 * E + 4.0 * a * b * n) + _NOISE_FLOOR_DRAWS * (2.0 * a * b * nb + 0.5 * a * b * s)
                if nb else 0.0)
             + sum(30.0 * min(o, n) ** 3 + 8.0 * nb * min(o, n) ** 2 * (n + l) for o in order_list)
             + boot * (10.0 * a * b * s + a * b * nb + sum(10.0 * min(o, n) ** 3 for o in order_list)))
    return Cost(bytes=int(peak), seconds=flops / 2e9, parts=parts, a=a, b=b)


def _parse_bytes(text: str) -> int:
    units = {"": 1, "K": 1024, "M": 1024**2, "G": 1024**3, "T": 1024**4}
    t = text.strip().upper().removesuffix("B").removesuffix("I")
    try:
        value = float(t[:-1] if t and t[-1] in units else t) * units[t[-1] if t and t[-1] in units else ""]
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{MEMORY_LIMIT_ENV} must be a size in bytes (e.g. 8G, 512M, 1000000000); got {text!r}")
    return int(value)


def available_memory() -> tuple[int, str]:
    """``(bytes, where from)``: the memory an identification may use: ``MODALUQ_MEMORY_LIMIT``
    if set, else the smallest of the physical memory (``os.sysconf``), the cgroup limit of
    a container and this process's address-space limit (``ulimit -v``)."""
    override = os.environ.get(MEMORY_LIMIT_ENV)
    if override:
        return _parse_bytes(override), f"{MEMORY_LIMIT_ENV}"
    found = []
    try:
        found.append((os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"), "physical memory"))
    except (ValueError, OSError, AttributeError):  # not POSIX: no limit known
        pass
    for cgroup in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(cgroup) as f:
                found.append((int(f.read().strip()), "the container's memory limit"))
        except (OSError, ValueError):  # absent, or "max"
            pass
    try:
        import resource
        for limit, name in ((resource.RLIMIT_AS, "address-space limit (ulimit -v)"),
                            (resource.RLIMIT_DATA, "data-segment limit (ulimit -d)")):
            soft = resource.getrlimit(limit)[0]
            if soft != resource.RLIM_INFINITY and soft > 0:
                found.append((soft, f"this process's {name}"))
    except ImportError:
        pass
    return min(found) if found else (2**63 - 1, "no limit known")


def _gb(x: float) -> str:
    return f"{x / 1e9:.3g} GB"


def check_cost(n_samples: int, n_outputs: int, n_inputs: int, settings, *, n_references=None) -> Cost:
    """Refuse ``settings`` whose estimated memory (:func:`estimate_cost`) exceeds
    :func:`available_memory`, naming the settings to lower; returns the estimate otherwise.
    ``settings`` is a complete :class:`modaluq.Settings` (block_rows, orders, n_blocks set)."""
    s = settings
    cost = estimate_cost(n_samples, n_outputs, n_inputs, block_rows=s.block_rows, past_block_rows=s.past_block_rows,
                         n_references=n_references if n_references is not None else
                         (len(s.references) if s.references else None),
                         orders=s.orders, n_blocks=s.n_blocks, uncertainty=s.uncertainty, threads=s.threads,
                         bootstrap_draws=s.bootstrap_draws, keep_shape_factor=s.keep_shape_factor)
    have, source = available_memory()
    if cost.bytes > have:
        raise ValueError(f"these settings would need about {_gb(cost.bytes)} of memory ({describe_cost(s, cost)}) "
                         f"but {_gb(have)} is available ({source}); lower {advice(s, cost)} "
                         f"(docs/settings.md, \"Memory\"; set {MEMORY_LIMIT_ENV} to change the limit)")
    return cost


def describe_cost(s, cost: Cost) -> str:
    """The sizes behind an estimate, in words."""
    n_max = max([s.orders] if isinstance(s.orders, numbers.Integral) else s.orders)
    blocks = f"{s.n_blocks} blocks" if s.uncertainty else "no uncertainty"
    minutes = cost.seconds / 60.0
    time = f"{cost.seconds:.0f} s" if minutes < 2 else f"{minutes:.0f} min"
    return (f"H is {cost.a} x {cost.b} for block_rows={s.block_rows}, {blocks}, orders up to {n_max}; "
            f"roughly {time} on one core")


def advice(s, cost: Cost) -> str:
    """The settings that drive the estimate, largest share first, with how to lower them."""
    words = {"block_rows": "block_rows (the memory grows with the square of the size of H, p l x q r)",
             "n_blocks": "n_blocks, or set uncertainty=False (the propagation holds a copy of H per block)",
             "orders": "the largest of orders"}
    shares = sorted(((v, k) for k, v in cost.parts.items() if v > 0), reverse=True)
    named = [k for v, k in shares if v >= 0.2 * shares[0][0]]
    return " or ".join(words[k] for k in named)


@contextlib.contextmanager
def naming_settings_on_memory_error(settings):
    """Re-raise a ``MemoryError`` of the core (a ``std::bad_alloc``, which names nothing) with
    the settings that made it and what to lower."""
    try:
        yield
    except MemoryError as exc:
        s = settings
        raise MemoryError(f"out of memory in the identification with block_rows={s.block_rows}, "
                          f"past_block_rows={s.past_block_rows or s.block_rows}, n_blocks={s.n_blocks}, "
                          f"uncertainty={s.uncertainty}, threads={s.threads}, orders up to "
                          f"{max([s.orders] if isinstance(s.orders, numbers.Integral) else s.orders)}: "
                          "lower block_rows, n_blocks or the orders, set uncertainty=False or threads=1 "
                          f"(docs/settings.md, \"Memory\"){': ' + str(exc) if str(exc) else ''}") from exc
