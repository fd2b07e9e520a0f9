"""HDF5 loader (h5py)."""

from __future__ import annotations

import numpy as np

from ._common import (
    check_fs_arg,
    check_path,
    fail,
    fs_from_increment,
    fs_from_time,
    optional_import,
    parse_isolated,
    pick_fs,
    reading,
    str_list,
)
from .recording import Recording

__all__ = ["read_hdf5", "FS_ATTRIBUTE_NAMES"]

#: Attributes (exact spelling, searched on the dataset, then its parent groups up to the file).
FS_ATTRIBUTE_NAMES = ("fs", "Fs", "FS", "sampling_rate", "sample_rate", "sampling_frequency",
                      "SamplingRate")
_DT_ATTRS = ("dt", "sampling_interval", "wf_increment")
_NAME_ATTRS = ("channel_names", "names", "labels", "channels")
_UNIT_ATTRS = ("units", "unit", "channel_units")
_TIME_NAMES = ("t", "time", "time_s", "times")


def _attr_scalar(obj, keys):
    for k in keys:
        if k in obj.attrs:
            v = np.asarray(obj.attrs[k])
            if v.dtype.kind in "iuf" and v.size == 1:
                return k, float(v.ravel()[0])
    return None, None


def _find_fs(ds, p):
    """fs from attributes of ``ds`` or its ancestors (closest wins); None if absent."""
    obj = ds
    while True:
        k, v = _attr_scalar(obj, FS_ATTRIBUTE_NAMES)
        if v is not None:
            return v, f"attribute {k!r} of {obj.name!r}"
        k, v = _attr_scalar(obj, _DT_ATTRS)
        if v is not None:
            return fs_from_increment(v, p, f"attribute {k!r} of {obj.name!r}"), \
                f"attribute {k!r} of {obj.name!r}"
        if obj.name == "/":
            return None, None
        obj = obj.parent


def _strs(obj, keys, n):
    for k in keys:
        if k in obj.attrs:
            lst = str_list(obj.attrs[k])
            if lst is not None and len(lst) == 1 and n > 1 and k in _UNIT_ATTRS:
                lst = lst * n
            if lst is not None and len(lst) == n:
                return lst
    return None


def _read_arrays(p, paths, transpose, time_tolerance, want_fs):
    """Everything that touches h5py (run in a child process when isolated): the blocks of
    samples, their default names and units, and fs found in the file (None if not wanted)."""
    h5py = optional_import("h5py", "h5py", "HDF5")
    with reading(p, "HDF5 file"):
        with h5py.File(str(p), "r") as f:
            if paths is None:
                found = []
                f.visititems(lambda nm, o: found.append((nm, o.shape, o.dtype))
                             if isinstance(o, h5py.Dataset) else None)
                num = [(nm, sh, dt) for nm, sh, dt in found if dt.kind in "iuf" and
                       np.prod(sh) > 1]
                mats = [nm for nm, sh, dt in num if len([s for s in sh if s > 1]) == 2]
                vecs = [nm for nm, sh, dt in num if len([s for s in sh if s > 1]) == 1 and
                        nm.rsplit("/", 1)[-1].lower() not in _TIME_NAMES]
                if len(mats) == 1:
                    paths = mats
                elif not mats and len(vecs) == 1:
                    paths = vecs
                else:
                    cands = ", ".join(f"/{nm} ({dt} {'x'.join(map(str, sh))})"
                                      for nm, sh, dt in found) or "none"
                    why = "several 2-D numeric datasets" if len(mats) > 1 else \
                        "no unique 2-D numeric dataset"
                    raise fail(p, f"{why}; choose with dataset= (datasets: {cands})")
            blocks, auto_names, auto_units, fs_found = [], [], [], []
            for dp in paths:
                if dp not in f:
                    top = ", ".join(f"/{k}" for k in f.keys()) or "none"
                    raise fail(p, f"dataset {dp!r} not found (top level: {top})")
                ds = f[dp]
                if not isinstance(ds, h5py.Dataset):
                    raise fail(p, f"{dp!r} is a group, not a dataset (members: "
                                  f"{', '.join(ds.keys())})")
                if ds.dtype.kind not in "iuf":
                    raise fail(p, f"dataset {dp!r} has dtype {ds.dtype}; real numbers needed")
                a = np.asarray(ds[()], dtype=np.float64)
                if a.size == 0:
                    raise fail(p, f"dataset {dp!r} is empty (shape {a.shape})")
                a = np.squeeze(a) if a.ndim > 2 else a
                if a.ndim == 0:
                    a = a.reshape(1, 1)
                elif a.ndim == 1:
                    a = a[:, None]
                elif a.ndim > 2:
                    raise fail(p, f"dataset {dp!r} has shape {a.shape}; 1-D or 2-D needed")
                elif transpose is None and a.shape[0] < a.shape[1] or transpose:
                    a = a.T
                blocks.append(a)
                base = ds.name.rsplit("/", 1)[-1]
                nch = a.shape[1]
                nm = _strs(ds, _NAME_ATTRS, nch)
                if nm is None and nch == 1 and "name" in ds.attrs:
                    nm = str_list(ds.attrs["name"], 1)
                if nm is None:
                    nm = [base] if nch == 1 else (
                        [f"{base}[{j}]" for j in range(nch)] if len(paths) > 1 else
                        [f"ch{j}" for j in range(nch)])
                auto_names.extend(nm)
                auto_units.extend(_strs(ds, _UNIT_ATTRS, nch) or [""] * nch)
                if want_fs:
                    fs_found.append(_find_fs(ds, p))
            lens = {b.shape[0] for b in blocks}
            if len(lens) != 1:
                raise fail(p, "datasets have different lengths: " +
                           ", ".join(f"{d}: {b.shape[0]}" for d, b in zip(paths, blocks)))
            n = blocks[0].shape[0]
            fs_file = None
            if want_fs:
                vals = [(v, w) for v, w in fs_found if v is not None]
                if vals:
                    fs_file = vals[0][0]
                    for v, w in vals[1:]:
                        if abs(v - fs_file) > 1e-9 * fs_file:
                            raise fail(p, f"datasets disagree on fs: {fs_file:g} Hz "
                                          f"({vals[0][1]}) vs {v:g} Hz ({w})")
                else:
                    parent = f[paths[0]].parent
                    for k in parent.keys():
                        o = parent[k]
                        if k.lower() in _TIME_NAMES and isinstance(o, h5py.Dataset) and \
                                o.dtype.kind in "iuf" and o.size == n:
                            fs_file = fs_from_time(o[()], p, tolerance=time_tolerance,
                                                   what=f"time dataset {o.name!r}")
                            break
    return blocks, auto_names, auto_units, fs_file


def read_hdf5(path, *, fs=None, inputs=None, dataset=None, names=None, units=None,
              transpose=None, time_tolerance=0.01, isolate=True) -> Recording:
    """Read channels from an HDF5 file.

    Parameters
    ----------
    dataset : str or list of str, optional
        Path(s) of the dataset(s) to read, e.g. ``'/acc'`` or ``['/ch/a1', '/ch/a2']``.
        A 2-D dataset gives one channel per column, a 1-D dataset one channel; several datasets
        are concatenated column-wise and must have the same length. Default: the only numeric
        2-D dataset in the file (else the only numeric 1-D one that is not named like a time
        vector); otherwise a ValueError lists the candidates.
    fs : float, optional
        Overrides the file. Otherwise an attribute ``fs``/``sampling_rate`` (also ``Fs``,
        ``sample_rate``, or the increment ``dt``/``wf_increment``) on the dataset, else on its
        parent groups up to the file; else a sibling dataset ``t``/``time`` of matching length.
    transpose : bool or None
        None: samples run along the longer dimension of a 2-D dataset. True/False force it.
    names, units : sequence of str, optional
        Default from dataset attributes ``channel_names``/``names`` and ``units``; for several 1-D
        datasets the dataset's ``name`` attribute or its basename.
    isolate : bool
        Parse in a child process (default), so that a crash or a hang of HDF5 on a corrupt file
        becomes a ValueError naming the file (time limit ``modaluq.io.PARSE_TIMEOUT``); False
        parses in this process (saves a few ms per file).
    """
    p = check_path(path)
    check_fs_arg(fs)
    if dataset is not None:
        if isinstance(dataset, str):
            paths = [dataset]
        elif isinstance(dataset, (list, tuple)) and dataset and \
                all(isinstance(d, str) for d in dataset):
            paths = list(dataset)
        else:
            raise TypeError(f"dataset must be a str or a non-empty list of str, got {dataset!r}")
    else:
        paths = None
    if transpose is not None and not isinstance(transpose, bool):
        raise TypeError(f"transpose must be True, False or None, got {transpose!r}")
    optional_import("h5py", "h5py", "HDF5")
    blocks, auto_names, auto_units, fs_file = parse_isolated(
        isolate, _read_arrays, p, "HDF5", p, paths, transpose, time_tolerance, fs is None)
    fs_v = pick_fs(fs, fs_file, p, "no fs/sampling_rate attribute on the dataset or file")
    samples = np.hstack(blocks) if len(blocks) > 1 else blocks[0]
    return Recording.from_arrays(samples, fs_v, names=names if names is not None else auto_names,
                                 units=units if units is not None else auto_units,
                                 inputs=inputs, source=str(p))
