"""Universal File Format (UFF/UNV) dataset 58 time records, read with pyuff."""

from __future__ import annotations

import mmap
import re

import numpy as np

from ._common import check_fs_arg, check_path, fail, fs_from_time, optional_import, pick_fs, reading, snap_fs
from .recording import Recording

__all__ = ["read_uff"]

_DIRS = {0: "", 1: "+X", 2: "+Y", 3: "+Z", 4: "+RX", 5: "+RY", 6: "+RZ",
         -1: "-X", -2: "-Y", -3: "-Z", -4: "-RX", -5: "-RY", -6: "-RZ"}
_FUNC = {0: "general or unknown", 1: "time response", 2: "auto spectrum", 3: "cross spectrum",
         4: "frequency response function", 5: "transmissibility", 6: "coherence",
         7: "auto correlation", 8: "cross correlation", 9: "power spectral density",
         10: "energy spectral density", 11: "probability density function", 12: "spectrum",
         13: "cumulative frequency distribution", 14: "peaks valley", 15: "stress/cycles",
         16: "strain/cycles", 17: "orbit", 18: "mode indicator function", 19: "force pattern",
         20: "partial power", 21: "partial coherence", 22: "eigenvalue", 23: "eigenvector",
         24: "shock response spectrum", 25: "finite impulse response filter",
         26: "multiple coherence", 27: "order function"}
_TAG = re.compile(rb"    -1")
_BLANKS = re.compile(rb" *")
_NON_BLANK = re.compile(rb"\S")
#: The increment is stored as E13.5 text (6 significant digits): fs is snapped within this.
_INC_RTOL = 5.1e-6


def _clean(s) -> str:
    s = "" if s is None else str(s).strip()
    return "" if s.upper() == "NONE" else s


def _node_name(rec) -> str:
    ent = _clean(rec.get("rsp_ent_name"))
    node = rec.get("rsp_node", "")
    d = _DIRS.get(int(rec.get("rsp_dir", 0) or 0), str(rec.get("rsp_dir", "")))
    return f"{ent + ':' if ent else ''}{node}{d}"


def _check_complete(p) -> None:
    """Every dataset is framed by two ``    -1`` lines; a dangling opening tag or anything but
    blanks after the last closing tag means the file was cut (pyuff silently drops it)."""
    with open(p, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as raw:
        n = len(raw)  # scanned in place: no copy of the file (it may be large)
        tags = 0
        last = -1
        for m in _TAG.finditer(raw):
            i = m.start()
            end = i + 6
            # same rule as pyuff: the tag ends the line, or is padded with blanks to column 80
            if end == n or raw[end] in (10, 13) or (
                    i + 80 <= n and _BLANKS.fullmatch(raw, end, i + 80)):
                tags += 1
                last = i
        if not tags:
            raise fail(p, "no UFF dataset delimiters ('    -1' lines) found: not a UFF file")
        if tags % 2:
            raise fail(p, f"incomplete dataset at byte {last} (odd number of '-1' delimiters): "
                          "truncated file?")
        if _NON_BLANK.search(raw, last + 6):
            raise fail(p, "unexpected content after the last dataset (truncated or corrupt "
                          "file?)")


def read_uff(path, *, fs=None, inputs=None, names=None, units=None, records=None,
             time_tolerance=0.01) -> Recording:
    """Read UFF/UNV dataset-58 time-response records; each record is one channel.

    Parameters
    ----------
    fs : float, optional
        Overrides the abscissa increment stored in the records (the increment is written as
        E13.5 text, i.e. with 6 significant digits, so the derived fs is snapped to the
        roundest value consistent with that precision: 1/3.33333e-3 gives exactly 300 Hz).
    inputs : list of str/int, optional
        Known inputs by channel name or by record index (among the type-58 records).
    records : list of int, optional
        Indices (among the type-58 records, in file order) of the records to read; default all.
    names, units : sequence of str, optional
        Default names: the record's ID line 1 when it is set (not empty/``NONE``) and unique,
        else ``<entity:>node+dir`` from the response DOF (e.g. ``12+Z``); default units: the
        ordinate axis units label.

    All records must be real time records (function type 1, or 0 = general) with the same
    number of points and the same abscissa spacing; other dataset types in the file (units,
    nodes, ...) are ignored.
    """
    p = check_path(path)
    check_fs_arg(fs)
    if records is not None and (not isinstance(records, (list, tuple, range)) or
                                not all(isinstance(r, int) and not isinstance(r, bool)
                                        for r in records)):
        raise TypeError(f"records must be a list of int, got {records!r}")
    pyuff = optional_import("pyuff", "pyuff", "UFF")

    with reading(p, "UFF file"):
        _check_complete(p)
        uf = pyuff.UFF(str(p))
        types = list(np.asarray(uf.get_set_types()).ravel())
        idx58 = [i for i, t in enumerate(types) if int(t) == 58]
        if not idx58:
            if not types:
                raise fail(p, "no UFF datasets found (not a UFF file, or corrupt)")
            raise fail(p, "no dataset 58 (function at nodal DOF) records; dataset types found: "
                          f"{sorted(set(int(t) for t in types))}")
        if records is not None:
            try:
                idx58 = [idx58[r] for r in records]
            except IndexError:
                raise ValueError(f"{p}: records={list(records)!r} out of range for "
                                 f"{len(idx58)} type-58 records") from None
            if not idx58:
                raise ValueError(f"{p}: records selects no record")
        recs = uf.read_sets(idx58)
        if isinstance(recs, dict):
            recs = [recs]

    data, incs = [], []
    for k, rec in enumerate(recs):
        if not isinstance(rec, dict) or "data" not in rec:
            raise fail(p, f"type-58 record {k} could not be read")
        ft = int(rec.get("func_type", 0) or 0)
        if ft not in (0, 1):
            raise fail(p, f"record {k} is function type {ft} ({_FUNC.get(ft, 'unknown')}), not a "
                          "time response (1)")
        d = np.asarray(rec["data"])
        if np.iscomplexobj(d):
            raise fail(p, f"record {k} holds complex data; time records must be real")
        npts = rec.get("num_pts")
        if npts is not None and int(npts) != d.size:
            raise fail(p, f"record {k} declares {int(npts)} points but holds {d.size} (truncated?)")
        if d.size == 0:
            raise fail(p, f"record {k} holds no data")
        data.append(d.astype(np.float64).ravel())
        if int(rec.get("abscissa_spacing", 1) or 0) == 1 and rec.get("abscissa_inc"):
            incs.append(float(rec["abscissa_inc"]))
        elif fs is None:
            x = np.asarray(rec.get("x", []), dtype=np.float64)
            if x.size != d.size:
                raise fail(p, f"record {k} has uneven abscissa without matching x values")
            incs.append(1.0 / fs_from_time(x, p, tolerance=time_tolerance,
                                           what=f"abscissa of record {k}"))
        else:
            incs.append(None)

    lens = {d.size for d in data}
    if len(lens) != 1:
        raise fail(p, "records have different lengths: " + ", ".join(
            f"{k}: {d.size}" for k, d in enumerate(data)))
    known = [v for v in incs if v is not None]
    fs_file = None
    if known:
        ref = known[0]
        for k, v in enumerate(incs):
            if v is not None and abs(v - ref) > 2 * _INC_RTOL * ref:
                raise fail(p, f"records have different abscissa increments: record 0 {ref:g} s, "
                              f"record {k} {v:g} s")
        if ref <= 0:
            raise fail(p, f"abscissa increment must be > 0, got {ref!r}")
        fs_file = snap_fs(1.0 / ref, _INC_RTOL)
    fs_v = pick_fs(fs, fs_file, p, "records have no abscissa increment")

    if names is None:
        ids = [_clean(r.get("id1")) for r in recs]
        if all(ids) and len(set(ids)) == len(ids):
            names = ids
        else:
            names = [_node_name(r) for r in recs]
            if len(set(names)) != len(names):
                names = [f"{nm}#{k}" for k, nm in enumerate(names)]
    if units is None:
        units = [_clean(r.get("ordinate_axis_units_lab")) for r in recs]
    samples = np.column_stack(data)
    return Recording.from_arrays(samples, fs_v, names=names, units=units, inputs=inputs,
                                 source=str(p))
