"""MATLAB ``.mat`` loader: v4/v5/v7 through scipy.io.loadmat, v7.3 (HDF5) through h5py."""

from __future__ import annotations

import math
import mmap
import numbers
import struct
import zlib

import numpy as np

from ..checks import check_boolean
from ._common import (
    check_fs_arg,
    check_path,
    fail,
    fs_from_time,
    optional_import,
    parse_isolated,
    pick_fs,
    reading,
    str_list,
)
from .hdf5 import check_h5_dataset, h5_get
from .recording import Recording

__all__ = ["read_matlab", "FS_VARIABLE_NAMES"]

#: Scalar variables (case-insensitive) that give the sampling frequency.
FS_VARIABLE_NAMES = ("fs", "sampling_rate", "samplingrate", "sample_rate", "samplerate",
                     "sampling_frequency", "fsamp")
_DT_NAMES = ("dt", "sampling_interval")
_TIME_NAMES = ("t", "time", "time_s", "tt")
_NAME_VARS = ("channel_names", "names", "labels", "channels")
_UNIT_VARS = ("units", "channel_units", "unit")


def _is_hdf5(p) -> bool:
    with open(p, "rb") as fh:
        head = fh.read(8)
        if head == b"\x89HDF\r\n\x1a\n":
            return True
        # v7.3 files carry a 512-byte MATLAB text header (the HDF5 user block)
        for off in (512, 1024, 2048):
            fh.seek(off)
            if fh.read(8) == b"\x89HDF\r\n\x1a\n":
                return True
    return False


# ---------------------------------------------------------------------------- v5 (scipy)
#: MAT v5 data types (miINT8 ... miUTF32); 8, 10 and 11 are reserved.
_MI_TYPES = frozenset((1, 2, 3, 4, 5, 6, 7, 9, 12, 13, 14, 15, 16, 17, 18))
_MI_MATRIX, _MI_COMPRESSED = 14, 15
#: MATLAB array classes (mxCELL_CLASS ...); sparse (5) and opaque classes are not size-checked.
_MX_CELL, _MX_STRUCT, _MX_OBJECT, _MX_CHAR, _MX_DOUBLE, _MX_UINT64 = 1, 2, 3, 4, 6, 15


def _check_v5_elements(p, buf, start, end, endian, depth=0) -> list:
    """Walk the data-element tags of ``buf[start:end]`` (recursing into miMATRIX): every type
    must exist and every size fit its container. SciPy indexes a C table with the type read from
    the file, so an unknown type (one flipped byte) segfaults it. Returns the elements as
    ``(type, size, body offset)``."""
    if depth > 64:
        raise fail(p, "MATLAB file nests arrays more than 64 deep (corrupt?)")
    pos, out = start, []
    while pos < end:
        if end - pos < 8:
            raise fail(p, f"MATLAB data element at byte {pos} is cut short (truncated file?)")
        word, size = struct.unpack_from(endian + "II", buf, pos)
        if word >> 16:  # small data element: type and size packed into the first word
            mtype, size, body, nxt = word & 0xFFFF, word >> 16, pos + 4, pos + 8
            if size > 4:
                raise fail(p, f"MATLAB data element at byte {pos} is corrupt (small element of "
                              f"{size} bytes)")
        else:
            mtype, body = word, pos + 8
            nxt = body + size + (-size % 8)
        if mtype not in _MI_TYPES:
            raise fail(p, f"MATLAB data element at byte {pos} has unknown type {mtype} "
                          "(corrupt file)")
        if body + size > end:
            raise fail(p, f"MATLAB data element at byte {pos} declares {size} bytes but its "
                          f"container ends at byte {end} (truncated or corrupt file)")
        if mtype == _MI_MATRIX:
            _check_v5_matrix(p, buf, pos, _check_v5_elements(p, buf, body, body + size, endian,
                                                              depth + 1), endian)
        out.append((mtype, size, body))
        pos = min(nxt, end)
    return out


def _check_v5_matrix(p, buf, pos, kids, endian) -> None:
    """The element count given by an array's dimensions must match its content: SciPy allocates
    and loops over prod(dims) before it reads, so one corrupt dimension (1e9 instead of 1) costs
    minutes and gigabytes before the error."""
    if len(kids) < 2:
        return  # an empty miMATRIX is an empty array
    (_, fsize, fbody), (_, dsize, dbody) = kids[0], kids[1]
    if fsize < 4 or dsize < 4:
        raise fail(p, f"MATLAB array at byte {pos} has no class or dimensions (corrupt file)")
    flags = struct.unpack_from(endian + "I", buf, fbody)[0]
    cls, is_complex = flags & 0xFF, bool(flags & 0x800)
    dims = struct.unpack_from(f"{endian}{dsize // 4}i", buf, dbody)
    if min(dims) < 0:
        raise fail(p, f"MATLAB array at byte {pos} has negative dimensions {dims} (corrupt file)")
    n = math.prod(dims)
    if cls in (_MX_CELL, _MX_STRUCT, _MX_OBJECT):
        head = {_MX_CELL: 3, _MX_STRUCT: 5, _MX_OBJECT: 6}[cls]
        nf = 1
        if cls != _MX_CELL and len(kids) >= head:
            fnl, names = kids[head - 2], kids[head - 1]
            fnl = struct.unpack_from(endian + "i", buf, fnl[2])[0] if fnl[1] >= 4 else 0
            nf = names[1] // fnl if fnl > 0 else 0
        if len(kids) < head or len(kids) - head != n * nf:
            raise fail(p, f"MATLAB array at byte {pos}: its dimensions {dims} call for {n * nf} "
                          f"elements but it holds {max(len(kids) - head, 0)} (corrupt file)")
    elif cls == _MX_CHAR or _MX_DOUBLE <= cls <= _MX_UINT64:
        # every element takes at least one byte; a complex array (flag 0x800) has an imaginary
        # part too, which SciPy reads without checking that it is there
        parts = (3, 4) if is_complex and cls != _MX_CHAR else (3,)
        for k in parts:
            if n and (len(kids) <= k or kids[k][1] < n):
                raise fail(p, f"MATLAB array at byte {pos}: its dimensions {dims} call for {n} "
                              f"{'imaginary' if k == 4 else ''} elements but its data holds "
                              f"{kids[k][1] if len(kids) > k else 0} bytes (corrupt file)")


def _validate_v5(p) -> None:
    """Check the framing of a MAT v5/v7 file before SciPy parses it (v4 files are left alone)."""
    with open(p, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        buf = memoryview(mm)  # no copy of a large file
        try:
            _validate_v5_buffer(p, buf)
        finally:
            buf.release()


def _validate_v5_buffer(p, buf) -> None:
    if len(buf) < 4 or 0 in bytes(buf[:4]):
        return  # MAT v4 (no text header): SciPy reads it with numpy only
    if len(buf) < 128:
        raise fail(p, f"MATLAB v5 header is cut short ({len(buf)} of 128 bytes)")
    endian = {b"IM": "<", b"MI": ">"}.get(bytes(buf[126:128]))
    if endian is None:
        raise fail(p, "not a MATLAB v5 file (bad endian indicator at byte 126)")
    pos = 128
    while pos < len(buf):
        if len(buf) - pos < 8:
            raise fail(p, f"MATLAB variable at byte {pos} is cut short (truncated file?)")
        mtype, size = struct.unpack_from(endian + "II", buf, pos)
        if pos + 8 + size > len(buf):
            raise fail(p, f"MATLAB variable at byte {pos} declares {size} bytes but only "
                          f"{len(buf) - pos - 8} remain (truncated file?)")
        if mtype == _MI_COMPRESSED:  # decompress only as much as the inner element declares
            z = zlib.decompressobj()
            try:
                head = z.decompress(buf[pos + 8:pos + 8 + size], 8)
                if len(head) == 8:
                    inner = struct.unpack_from(endian + "II", head)[1]
                    inner_buf = head + z.decompress(z.unconsumed_tail, inner)
                    _check_v5_elements(p, inner_buf, 0, len(inner_buf), endian)
            except zlib.error as exc:
                raise fail(p, f"MATLAB variable at byte {pos}: corrupt compressed data "
                              f"({exc})") from None
        else:
            _check_v5_elements(p, buf, pos, pos + 8 + size, endian)
        pos += 8 + size


def _load_v5(p) -> dict:
    sio = optional_import("scipy.io", "scipy", "MATLAB .mat")
    with reading(p, "MATLAB .mat file"):
        d = sio.loadmat(str(p), simplify_cells=True)
    if not isinstance(d, dict):
        raise fail(p, "unexpected content")
    return {k: v for k, v in d.items() if not k.startswith("__")}


def _get_path(tree: dict, name: str, p):
    """Variable lookup, supporting dotted struct fields (``data.acc``)."""
    cur = tree
    parts = name.split(".")
    for i, part in enumerate(parts):
        if not isinstance(cur, dict) or part not in cur:
            where = ".".join(parts[:i]) or "the file"
            avail = ", ".join(sorted(cur)) if isinstance(cur, dict) else "none (not a struct)"
            raise fail(p, f"variable {name!r} not found in {where} (available: {avail})")
        cur = cur[part]
    return cur


# ---------------------------------------------------------------------------- v7.3 (h5py)
class _H5Mat:
    """Minimal reader of MATLAB v7.3 variables as a lazy dict-like tree."""

    def __init__(self, f, p, allow_external=False):
        self.f, self.p, self.allow_external = f, p, allow_external

    def get(self, grp, name):
        """``grp[name]`` without following a link out of the file (``hdf5.h5_get``)."""
        return h5_get(grp, name, self.p, self.allow_external)

    def deref(self, ref):
        """The object a cell's reference points at, which must be in this file."""
        obj = self.f[ref]
        if obj.file.filename != self.f.filename and not self.allow_external:
            raise fail(self.p, f"a reference points into the file {obj.file.filename!r}; "
                               "references leaving the file are refused (allow_external=True "
                               "follows them)")
        return obj

    def keys(self, grp=None):
        grp = self.f if grp is None else grp
        return [k for k in grp.keys() if not k.startswith("#")]

    def convert(self, obj):
        h5py = optional_import("h5py", "h5py", "MATLAB v7.3 .mat")
        if isinstance(obj, h5py.Group):
            cls = obj.attrs.get("MATLAB_class", b"struct")
            cls = cls.decode() if isinstance(cls, bytes) else str(cls)
            if "MATLAB_sparse" in obj.attrs:
                return _Unsupported("sparse matrix")
            if cls != "struct":
                return _Unsupported(f"MATLAB {cls} object")
            return {k: self.convert(self.get(obj, k)) for k in self.keys(obj)}
        cls = obj.attrs.get("MATLAB_class", b"")
        cls = cls.decode() if isinstance(cls, bytes) else str(cls)
        if np.any(np.asarray(obj.attrs.get("MATLAB_empty", 0))):
            return np.zeros((0, 0))
        check_h5_dataset(obj, self.p, self.allow_external)
        data = obj[()]
        if cls == "char":
            a = np.asarray(data, dtype=np.uint16).T  # MATLAB (rows, chars)
            if a.ndim == 1:
                a = a[None, :]
            rows = ["".join(map(chr, r)).rstrip("\x00 ") for r in a]
            return rows[0] if len(rows) == 1 else rows
        if cls == "cell" or data.dtype == h5py.ref_dtype or data.dtype.kind == "O":
            refs = np.asarray(data).T.ravel()
            return [self.convert(self.deref(r)) for r in refs]
        if data.dtype.names is not None:
            if set(data.dtype.names) >= {"real", "imag"}:
                return _Unsupported("complex array")
            return _Unsupported(f"compound dtype {data.dtype}")
        arr = np.asarray(data)
        if cls == "logical":
            arr = arr.astype(bool)
        return arr.T  # MATLAB writes column-major: HDF5 shape is the reverse of MATLAB's


class _Unsupported:
    def __init__(self, what):
        self.what = what

    def __repr__(self):
        return f"<{self.what}>"


def _load_v73(p, allow_external=False) -> dict:
    h5py = optional_import("h5py", "h5py", "MATLAB v7.3 .mat")
    with reading(p, "MATLAB v7.3 (HDF5) .mat file"):
        with h5py.File(str(p), "r") as f:
            m = _H5Mat(f, p, allow_external)
            return {k: m.convert(m.get(f, k)) for k in m.keys()}


# ---------------------------------------------------------------------------- common
def _numeric(v) -> bool:
    return isinstance(v, np.ndarray) and v.dtype.kind in "iuf" and v.size > 0


def _scalar(v):
    if isinstance(v, (numbers.Real,)) and not isinstance(v, bool):
        return float(v)
    if _numeric(v) and v.size == 1:
        return float(v.ravel()[0])
    return None


def _orient(a: np.ndarray, transpose, name, p) -> np.ndarray:
    if a.ndim == 1:
        return a[:, None]
    if a.ndim != 2:
        a2 = np.squeeze(a)
        if a2.ndim > 2:
            raise fail(p, f"variable {name!r} has shape {a.shape}; a 2-D (samples x channels) "
                          "array is needed")
        a = a2 if a2.ndim == 2 else a2.reshape(-1, 1)
    if transpose is None:
        return a.T if a.shape[0] < a.shape[1] else a
    return a.T if transpose else a


def _describe(v) -> str:
    if isinstance(v, np.ndarray):
        return f"{v.dtype} {'x'.join(map(str, v.shape))}"
    if isinstance(v, dict):
        return "struct"
    if isinstance(v, list):
        return "cell"
    if isinstance(v, str):
        return "char"
    return type(v).__name__


def read_matlab(path, *, fs=None, inputs=None, variable=None, names=None, units=None,
                transpose=None, time_tolerance=0.01, isolate=True,
                allow_external=False) -> Recording:
    """Read channels from a MATLAB ``.mat`` file (v4/v5/v7 or v7.3).

    Parameters
    ----------
    variable : str or list of str, optional
        Variable(s) holding the samples; struct fields with dots (``'data.acc'``). Several
        variables are concatenated column-wise (each 1-D -> one channel named after it).
        Default: the only 2-D numeric matrix in the file (else the only numeric vector that is
        not a time vector); otherwise a ValueError lists the candidates.
    fs : float, optional
        Overrides the file. Otherwise a scalar variable named fs/Fs/sampling_rate (any case),
        else ``dt``, else a time vector ``t``/``time`` of matching length.
    transpose : bool or None
        None (default): samples run along the longer dimension (MATLAB data is often stored
        channels x samples). True/False force transposing/not transposing the variable.
    names, units : sequence of str, optional
        Channel names/units; default from a variable ``channel_names``/``names`` and ``units``
        (cell array of strings or char matrix) when their length matches, else ``ch0, ch1, ...``.
    isolate : bool
        Parse in a child process (default), so that a crash or a hang of SciPy or HDF5 on a
        corrupt file becomes a ValueError naming the file (time limit: see
        ``modaluq.io.PARSE_TIMEOUT``); False parses in this process (saves a few ms per file).
    allow_external : bool
        v7.3 (HDF5) files: False (default) refuses external links, external raw storage and
        virtual datasets, which make HDF5 read other files, naming the variable and the target;
        True follows them. Partly written or impossibly large datasets are refused either way,
        as by :func:`modaluq.io.read_hdf5`.
    """
    p = check_path(path)
    check_fs_arg(fs)
    if variable is not None:
        if isinstance(variable, str):
            variables = [variable]
        elif isinstance(variable, (list, tuple)) and variable and \
                all(isinstance(v, str) for v in variable):
            variables = list(variable)
        else:
            raise TypeError(f"variable must be a str or a non-empty list of str, got {variable!r}")
    else:
        variables = None
    if transpose is not None and not isinstance(transpose, bool):
        raise TypeError(f"transpose must be True, False or None, got {transpose!r}")
    allow_external = check_boolean("allow_external", allow_external)

    if _is_hdf5(p):
        tree = parse_isolated(isolate, _load_v73, p, "MATLAB v7.3 (HDF5)", p, allow_external)
    else:
        _validate_v5(p)
        tree = parse_isolated(isolate, _load_v5, p, "MATLAB", p)
    if not tree:
        raise fail(p, "the .mat file holds no variables")

    if variables is None:
        nums = {k: v for k, v in tree.items()
                if _numeric(v) and v.size > 1 and k.lower() not in FS_VARIABLE_NAMES}
        mats = [k for k, v in nums.items() if np.squeeze(v).ndim == 2]
        vecs = [k for k, v in nums.items() if np.squeeze(v).ndim == 1
                and k.lower() not in _TIME_NAMES]
        if len(mats) == 1:
            variables = mats
        elif not mats and len(vecs) == 1:
            variables = vecs
        else:
            cands = ", ".join(f"{k} ({_describe(v)})" for k, v in tree.items())
            why = "several 2-D numeric arrays" if len(mats) > 1 else "no unique 2-D numeric array"
            raise fail(p, f"{why}; choose one with variable= (variables: {cands})")

    blocks, auto_names = [], []
    for var in variables:
        v = _get_path(tree, var, p)
        if isinstance(v, _Unsupported):
            raise fail(p, f"variable {var!r} is a {v.what}; a real numeric array is needed")
        if isinstance(v, (numbers.Real,)) and not isinstance(v, bool):
            v = np.asarray([float(v)])
        if not _numeric(v):
            raise fail(p, f"variable {var!r} is {_describe(v)}, not a real numeric array")
        a = _orient(np.asarray(v, dtype=np.float64), transpose, var, p)
        blocks.append(a)
        if a.shape[1] == 1:
            auto_names.append(var)
        else:
            auto_names.extend(f"{var}[{j}]" if len(variables) > 1 else f"ch{j}"
                              for j in range(a.shape[1]))
    lens = {b.shape[0] for b in blocks}
    if len(lens) != 1:
        raise fail(p, "variables have different lengths: " +
                   ", ".join(f"{v}: {b.shape[0]}" for v, b in zip(variables, blocks)))
    samples = np.hstack(blocks) if len(blocks) > 1 else blocks[0]
    n, nch = samples.shape

    fs_file, lower = None, {k.lower(): k for k in tree}
    if fs is None:
        for nm in FS_VARIABLE_NAMES:
            if nm in lower and _scalar(tree[lower[nm]]) is not None:
                fs_file = _scalar(tree[lower[nm]])
                break
        else:
            for nm in _DT_NAMES:
                if nm in lower and _scalar(tree[lower[nm]]):
                    fs_file = 1.0 / _scalar(tree[lower[nm]])
                    break
            else:
                for nm in _TIME_NAMES:
                    tv = tree.get(lower.get(nm, ""), None)
                    if _numeric(tv) and tv.size == n and lower[nm] not in variables:
                        fs_file = fs_from_time(tv, p, tolerance=time_tolerance,
                                               what=f"time variable {lower[nm]!r}")
                        break
    fs_v = pick_fs(fs, fs_file, p, "no scalar variable fs/Fs/sampling_rate, dt or time vector t")

    if names is None:
        for nm in _NAME_VARS:
            if nm in lower:
                cand = tree[lower[nm]]
                lst = [cand] if isinstance(cand, str) else (
                    cand if isinstance(cand, list) else str_list(cand))
                if lst is not None and len(lst) == nch and all(isinstance(s, str) for s in lst):
                    names = [s.strip() for s in lst]
                    break
        else:
            names = auto_names
    if units is None:
        for nm in _UNIT_VARS:
            if nm in lower:
                cand = tree[lower[nm]]
                lst = [cand] * nch if isinstance(cand, str) else (
                    cand if isinstance(cand, list) else str_list(cand))
                if lst is not None and len(lst) == nch and all(isinstance(s, str) for s in lst):
                    units = [s.strip() for s in lst]
                    break
    return Recording.from_arrays(samples, fs_v, names=names, units=units, inputs=inputs,
                                 source=str(p))
