"""NumPy ``.npy`` / ``.npz`` loader (never unpickles)."""

from __future__ import annotations

import numpy as np

from ._common import check_fs_arg, check_path, fail, pick_fs, reading, str_list
from .recording import Recording

__all__ = ["read_numpy", "read_npy", "read_npz"]

_NPY_MAGIC = b"\x93NUMPY"
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def _load_array(obj, key, path):
    """One array out of an NpzFile (``key``) or a .npy file (``obj`` = path, ``key`` None),
    refusing pickles with a clear message."""
    try:
        arr = obj[key] if key is not None else np.load(obj, allow_pickle=False)
    except ValueError as exc:
        if "pickle" in str(exc).lower():
            what = f"array {key!r}" if key is not None else "the array"
            raise fail(path, f"{what} holds Python objects (pickled object array); refusing to "
                             "load it with allow_pickle=False") from exc
        raise
    if not isinstance(arr, np.ndarray):  # NpzFile returns a member without the .npy magic raw
        raise fail(path, f"member {key!r} of the archive is not .npy data")
    return arr


def read_npy(path, *, fs=None, inputs=None, names=None, units=None) -> Recording:
    """Read a ``.npy`` file holding a (n_samples, n_channels) or (n_samples,) array.

    ``fs`` is required (a .npy file has no metadata).
    """
    return read_numpy(path, fs=fs, inputs=inputs, names=names, units=units)


def read_npz(path, *, fs=None, inputs=None, names=None, units=None) -> Recording:
    """Read a ``.npz`` archive laid out like the datasets in ``shared/data`` (see read_numpy)."""
    return read_numpy(path, fs=fs, inputs=inputs, names=names, units=units)


def read_numpy(path, *, fs=None, inputs=None, names=None, units=None) -> Recording:
    """Read ``.npy`` or ``.npz`` (detected from the file's magic bytes, not its extension).

    ``.npz`` keys: ``y`` (n_samples, n_outputs) required; optional ``u`` (n_samples, n_inputs),
    ``fs`` (scalar), ``channel_names``/``units`` (per column of y) and ``input_names``/
    ``input_units`` (per column of u). Other keys are ignored. Always ``allow_pickle=False``.

    Channel pool for ``inputs=`` selection: the columns of ``y`` followed by those of ``u``.
    By default (``inputs=None``) the stored ``u`` are the inputs; pass ``inputs=[]`` to treat all
    channels as outputs, or names/indices to choose others. ``names``/``units`` override the
    stored ones (one entry per pooled column).
    """
    p = check_path(path)
    check_fs_arg(fs)
    src = str(p)
    with open(p, "rb") as fh:
        head = fh.read(8)
    if head.startswith(_NPY_MAGIC):
        with reading(p, "NumPy .npy file"):
            arr = _load_array(p, None, p)
        if arr.dtype.names is not None:
            raise fail(p, f"structured arrays are not supported (fields {arr.dtype.names})")
        if arr.dtype.kind not in "iuf":
            raise fail(p, f"array has dtype {arr.dtype}; a real numeric array is needed")
        if arr.ndim not in (1, 2) or arr.size == 0:
            raise fail(p, f"array must be (n_samples,) or (n_samples, n_channels), got shape "
                          f"{arr.shape}")
        fs_v = pick_fs(fs, None, p, "a .npy file stores no sampling frequency")
        return Recording.from_arrays(arr, fs_v, names=names, units=units, inputs=inputs,
                                     source=src)
    if not head.startswith(_ZIP_MAGIC):
        raise fail(p, "not a NumPy file (no .npy magic '\\x93NUMPY' and not a .npz zip archive)")

    with reading(p, "NumPy .npz archive"):
        # our own handle: np.load leaves its file open when the archive is corrupt
        with open(p, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            keys = list(z.files)
            if "y" not in keys:
                raise fail(p, f".npz archive has no 'y' array (keys: {', '.join(keys) or 'none'})")
            data = {k: _load_array(z, k, p) for k in
                    ("y", "u", "fs", "channel_names", "units", "input_names", "input_units")
                    if k in keys}
    y = data["y"]
    if y.dtype.kind not in "iuf" or y.ndim not in (1, 2) or y.size == 0:
        raise fail(p, f"'y' must be a non-empty real (n_samples, n_outputs) array, got dtype "
                      f"{y.dtype} shape {y.shape}")
    if y.ndim == 1:
        y = y[:, None]
    u = data.get("u")
    if u is not None:
        if u.dtype.kind not in "iuf" or u.ndim not in (1, 2):
            raise fail(p, f"'u' must be a real (n_samples, n_inputs) array, got dtype {u.dtype} "
                          f"shape {u.shape}")
        if u.ndim == 1:
            u = u[:, None]
        if u.shape[0] != y.shape[0]:
            raise fail(p, f"'u' has {u.shape[0]} samples but 'y' has {y.shape[0]}")
        if u.shape[1] == 0:
            u = None
    n_y = y.shape[1]
    n_u = 0 if u is None else u.shape[1]

    fs_file = data.get("fs")
    if fs_file is not None:
        if fs_file.size != 1 or fs_file.dtype.kind not in "iuf":
            raise fail(p, f"'fs' must be a numeric scalar, got dtype {fs_file.dtype} shape "
                          f"{fs_file.shape}")
        fs_file = float(fs_file.reshape(()))
    fs_v = pick_fs(fs, fs_file, p, "the archive has no 'fs' key")

    def meta(key, n, default):
        if key not in data:
            return default
        vals = str_list(data[key])
        if vals is None:
            raise fail(p, f"'{key}' must be an array of strings, got dtype {data[key].dtype}")
        if len(vals) == 1 and n > 1 and key.endswith("units"):
            vals = vals * n
        if len(vals) != n:
            raise fail(p, f"'{key}' has {len(vals)} entries but there are {n} columns")
        return vals

    pool_names = (meta("channel_names", n_y, [f"ch{i}" for i in range(n_y)])
                  + meta("input_names", n_u, [f"u{i}" for i in range(n_u)]))
    pool_units = meta("units", n_y, [""] * n_y) + meta("input_units", n_u, [""] * n_u)
    if names is not None:
        pool_names = names
    if units is not None:
        pool_units = units
    samples = y if u is None else np.hstack([y, u])
    if inputs is None:
        inputs = list(range(n_y, n_y + n_u))
    return Recording.from_arrays(samples, fs_v, names=pool_names, units=pool_units,
                                 inputs=inputs, source=src)
