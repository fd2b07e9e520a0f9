"""HDF5 loader (h5py), and the checks on HDF5 objects that the MATLAB v7.3 loader shares: a
file is read only from its own bytes (no external link, external raw storage or virtual dataset
unless ``allow_external=True``), and a dataset must have been written and be no larger than the
file can hold (docs/loaders.md, "What an HDF5 file may point at")."""

from __future__ import annotations

import math
import os

import numpy as np

from ..checks import check_boolean
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

__all__ = ["read_hdf5", "FS_ATTRIBUTE_NAMES", "MAX_COMPRESSION_RATIO"]

#: Attributes (exact spelling, searched on the dataset, then its parent groups up to the file).
FS_ATTRIBUTE_NAMES = ("fs", "Fs", "FS", "sampling_rate", "sample_rate", "sampling_frequency",
                      "SamplingRate")
_DT_ATTRS = ("dt", "sampling_interval", "wf_increment")
_NAME_ATTRS = ("channel_names", "names", "labels", "channels")
_UNIT_ATTRS = ("units", "unit", "channel_units")
_TIME_NAMES = ("t", "time", "time_s", "times")


#: Largest ratio of a dataset's bytes to the bytes it occupies in the file that is believed
#: (gzip's best, on all-zero data, is about 1030); a larger claim is a corrupt or crafted header.
MAX_COMPRESSION_RATIO = 1000
#: Datasets up to this size are not held to the ratio (scalars, headers, fill-valued stubs).
_RATIO_FLOOR = 1 << 20
#: Soft links followed within one path before it is refused as a loop.
_MAX_SOFT_LINKS = 40


def _physical_memory() -> int | None:
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):  # not POSIX
        return None


def h5_get(group, name: str, p, allow_external: bool = False):
    """``group[name]`` resolved one link at a time, so that no link leaving the file is
    followed: an external link (or a soft link through one) raises a RecordingFileError naming
    the file, the path and the link's target, unless ``allow_external``. None if ``name`` does
    not exist. h5py's ``group[name]`` and ``name in group`` would open the linked file."""
    h5py = optional_import("h5py", "h5py", "HDF5")
    cur = group.file if name.startswith("/") else group
    parts = [s for s in name.split("/") if s not in ("", ".")]
    walked, hops = cur.name.rstrip("/"), 0
    while parts:
        part = parts.pop(0)
        if not isinstance(cur, h5py.Group):
            return None
        link = cur.get(part, getlink=True)
        here = f"{walked}/{part}"
        if link is None:
            return None
        if isinstance(link, h5py.SoftLink):
            hops += 1
            if hops > _MAX_SOFT_LINKS:
                raise fail(p, f"{name!r}: more than {_MAX_SOFT_LINKS} soft links (a loop?)")
            target = link.path
            parts = [s for s in target.split("/") if s not in ("", ".")] + parts
            if target.startswith("/"):
                cur, walked = cur.file, ""
            continue
        if isinstance(link, h5py.ExternalLink):
            if not allow_external:
                raise fail(p, f"{here!r} is an external link to {link.path!r} in the file "
                              f"{link.filename!r}; links leaving the file are refused "
                              "(allow_external=True follows them)")
        elif not isinstance(link, h5py.HardLink):
            raise fail(p, f"{here!r} is a {type(link).__name__}, a link class this reader "
                          "does not follow")
        cur, walked = cur[part], here
    return cur


def check_h5_dataset(ds, p, allow_external: bool = False) -> None:
    """Refuse, before any sample is read, a dataset whose data would not come from this file's
    bytes: external raw storage and virtual datasets (unless ``allow_external``), a declared size
    the file cannot hold (more than MAX_COMPRESSION_RATIO times its bytes in the file, or more
    than the machine's memory) and chunks or storage never written (they would read as zeros)
    unless the writer set a fill value explicitly."""
    h5py = optional_import("h5py", "h5py", "HDF5")
    name, shape = ds.name, ds.shape
    if ds.external and not allow_external:
        files = ", ".join(repr(e[0]) for e in ds.external)
        raise fail(p, f"dataset {name!r} keeps its data in other files ({files}); external "
                      "storage is refused (allow_external=True reads it)")
    if ds.is_virtual and not allow_external:
        try:
            files = ", ".join(sorted({repr(m.file_name) for m in ds.virtual_sources()}))
        except Exception:  # noqa: BLE001 - only for the message
            files = "unknown files"
        raise fail(p, f"dataset {name!r} is a virtual dataset mapping {files}; virtual datasets "
                      "are refused (allow_external=True reads them)")
    if shape is None:  # a null dataspace holds nothing
        return
    count = math.prod(shape)
    nbytes = count * ds.dtype.itemsize
    what = f"dataset {name!r} declares {'x'.join(map(str, shape))} {ds.dtype} ({nbytes:,} bytes)"
    mem = _physical_memory()
    if mem is not None and nbytes + 8 * count > mem:  # the samples, then their float64 copy
        raise fail(p, f"{what}, more than this machine's memory ({mem:,} bytes) can hold; "
                      "refused before reading")
    if ds.external or ds.is_virtual:
        return  # allowed: the data lie in the other files
    stored = ds.id.get_storage_size()
    file_size = os.stat(p).st_size
    if nbytes > _RATIO_FLOOR and (nbytes > MAX_COMPRESSION_RATIO * stored or
                                  nbytes > MAX_COMPRESSION_RATIO * file_size):
        raise fail(p, f"{what} but holds {stored:,} bytes of it in a file of {file_size:,} "
                      f"bytes (more than modaluq.io.hdf5.MAX_COMPRESSION_RATIO = "
                      f"{MAX_COMPRESSION_RATIO} times smaller): corrupt or crafted header, "
                      "refused before reading")
    dcpl = ds.id.get_create_plist()
    if dcpl.fill_value_defined() == h5py.h5d.FILL_VALUE_USER_DEFINED or count == 0:
        return  # unwritten elements read as the fill value the writer chose
    if ds.chunks is None:
        if dcpl.get_layout() != h5py.h5d.COMPACT and stored < nbytes:
            raise fail(p, f"{what} but none of it was written (no storage allocated, no fill "
                          "value set): it would read as zeros; refused")
        return
    _check_chunks_written(ds, p, shape, count)


def _check_chunks_written(ds, p, shape, count) -> None:
    chunk = ds.chunks
    offsets = []
    if hasattr(ds.id, "chunk_iter"):  # h5py >= 3.8: one pass over the chunk index
        ds.id.chunk_iter(lambda info: offsets.append(info.chunk_offset))
    elif hasattr(ds.id, "get_chunk_info"):  # walks the index each call: fine for usual counts
        offsets = [ds.id.get_chunk_info(i).chunk_offset for i in range(ds.id.get_num_chunks())]
    else:  # libhdf5 < 1.10.5 cannot list chunks: only the size checks apply
        return
    covered = sum(math.prod(min(c, n - o) for o, c, n in zip(off, chunk, shape))
                  for off in offsets)
    if covered >= count:
        return
    axis = int(np.argmax(shape))  # the samples axis of a pre-sized recording
    spans = sorted({(off[axis], min(off[axis] + chunk[axis], shape[axis])) for off in offsets})
    merged = []
    for a, b in spans:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    rows = ", ".join(f"{a}..{b - 1}" for a, b in merged) or "none"
    expected = math.prod(-(-n // c) for n, c in zip(shape, chunk))
    raise fail(p, f"dataset {ds.name!r} is only partly written: rows {rows} of {shape[axis]} "
                  f"(axis {axis}; {len(offsets)} of {expected} chunks) hold data, the rest was "
                  "never written and no fill value was set, so it would read as zeros; refused "
                  "(a recording still being written, or cut short?)")


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


def _read_arrays(p, paths, transpose, time_tolerance, want_fs, allow_external=False):
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
                ds = h5_get(f, dp, p, allow_external)
                if ds is None:
                    top = ", ".join(f"/{k}" for k in f.keys()) or "none"
                    raise fail(p, f"dataset {dp!r} not found (top level: {top})")
                if not isinstance(ds, h5py.Dataset):
                    raise fail(p, f"{dp!r} is a group, not a dataset (members: "
                                  f"{', '.join(ds.keys())})")
                if ds.dtype.kind not in "iuf":
                    raise fail(p, f"dataset {dp!r} has dtype {ds.dtype}; real numbers needed")
                check_h5_dataset(ds, p, allow_external)
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
                    parent = h5_get(f, paths[0], p, allow_external).parent
                    for k in parent.keys():
                        if k.lower() not in _TIME_NAMES:
                            continue
                        o = h5_get(parent, k, p, allow_external)
                        if isinstance(o, h5py.Dataset) and o.dtype.kind in "iuf" and \
                                o.size == n:
                            check_h5_dataset(o, p, allow_external)
                            fs_file = fs_from_time(o[()], p, tolerance=time_tolerance,
                                                   what=f"time dataset {o.name!r}")
                            break
    return blocks, auto_names, auto_units, fs_file


def read_hdf5(path, *, fs=None, inputs=None, dataset=None, names=None, units=None,
              transpose=None, time_tolerance=0.01, isolate=True,
              allow_external=False) -> Recording:
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
        becomes a ValueError naming the file (time limit: see ``modaluq.io.PARSE_TIMEOUT``);
        False parses in this process (saves a few ms per file).
    allow_external : bool
        False (default): external links, external raw storage and virtual datasets, which make
        HDF5 read other files (any path), are refused with a ValueError naming the dataset and
        the target. True follows them, for files you trust.

    Whatever ``allow_external``, a dataset declaring more bytes than the file can hold
    (``MAX_COMPRESSION_RATIO``) or than the machine's memory, and a dataset only partly written
    (unwritten chunks and no fill value set), are refused before their samples are read.
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
    allow_external = check_boolean("allow_external", allow_external)
    optional_import("h5py", "h5py", "HDF5")
    blocks, auto_names, auto_units, fs_file = parse_isolated(
        isolate, _read_arrays, p, "HDF5", p, paths, transpose, time_tolerance, fs is None,
        allow_external)
    fs_v = pick_fs(fs, fs_file, p, "no fs/sampling_rate attribute on the dataset or file")
    samples = np.hstack(blocks) if len(blocks) > 1 else blocks[0]
    return Recording.from_arrays(samples, fs_v, names=names if names is not None else auto_names,
                                 units=units if units is not None else auto_units,
                                 inputs=inputs, source=str(p))
