"""What a recording file holds, without loading its samples: TDMS groups and channels, HDF5
groups and datasets, MATLAB variables, the arrays of an ``.npz`` (``modaluq info`` prints it).

Only metadata is read. HDF5 and MATLAB files are listed in the isolated parser process the
loaders use (a corrupt file that crashes or hangs the library becomes an error naming the file);
HDF5 links are not followed (``visititems`` walks hard links only), so a listing names only the
file's own objects.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._common import check_path, optional_import, parse_isolated, reading
from .errors import fail

__all__ = ["FileItem", "file_contents"]

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


@dataclass(frozen=True)
class FileItem:
    """One group, dataset, variable or channel of a file."""

    kind: str      #: "group", "dataset", "variable", "channel", "array"
    name: str      #: its path or name in the file
    detail: str    #: shape and type, length, or member count, in words


def file_contents(path, fmt: str) -> tuple:
    """The :class:`FileItem` of a file of format ``fmt`` (a name of ``modaluq.io.FORMATS``), in
    file order; ``()`` for formats without structure (CSV, UFF, ``.npy``)."""
    p = check_path(path)
    if fmt == "tdms":
        return _tdms(p)
    if fmt == "hdf5":
        with reading(p, "HDF5"):
            return tuple(FileItem(*t) for t in parse_isolated(True, _hdf5_items, p, "HDF5", str(p), False))
    if fmt == "matlab":
        with open(p, "rb") as f:
            head = f.read(520)
        if _HDF5_SIGNATURE in (head[:8], head[512:520]):  # v7.3: an HDF5 file behind a 512-byte header
            with reading(p, "MATLAB v7.3 (HDF5)"):
                return tuple(FileItem(*t) for t in parse_isolated(True, _hdf5_items, p, "MATLAB v7.3 (HDF5)",
                                                                  str(p), True))
        with reading(p, "MATLAB"):
            return tuple(FileItem(*t) for t in parse_isolated(True, _mat_v5_items, p, "MATLAB", str(p)))
    if fmt == "numpy" and p.suffix.lower() == ".npz":
        return _npz(p)
    return ()


def _hdf5_items(path: str, matlab: bool) -> list:
    """(kind, name, detail) of every group and dataset (run in the isolated parser process)."""
    import h5py

    out = []
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if matlab and name.split("/")[0].startswith("#"):  # MATLAB's own bookkeeping (#refs#)
                return
            if isinstance(obj, h5py.Dataset):
                kind = "variable" if matlab and "/" not in name else "dataset"
                out.append((kind, "/" + name, f"shape {obj.shape}, {obj.dtype}"))
            elif isinstance(obj, h5py.Group):
                out.append(("group", "/" + name, f"{len(obj)} members"))
        f.visititems(visit)
    return out


def _mat_v5_items(path: str) -> list:
    """(kind, name, detail) of the variables of a MATLAB v5 file (run in the isolated parser process)."""
    import scipy.io

    return [("variable", name, f"shape {tuple(shape)}, {cls}") for name, shape, cls in scipy.io.whosmat(path)]


def _tdms(p: Path) -> tuple:
    nptdms = optional_import("nptdms", "npTDMS", "TDMS")
    with reading(p, "TDMS"):
        tf = nptdms.TdmsFile.read_metadata(str(p))
    out = []
    for g in tf.groups():
        channels = g.channels()
        out.append(FileItem("group", g.name, f"{len(channels)} channels"))
        for c in channels:
            unit = c.properties.get("unit_string", "")
            out.append(FileItem("channel", f"{g.name}/{c.name}",
                                f"{len(c)} values" + (f", unit {unit}" if unit else "")))
    return tuple(out)


def _npz(p: Path) -> tuple:
    out = []
    try:
        with zipfile.ZipFile(p) as z:
            for name in z.namelist():
                with z.open(name) as fh:
                    version = np.lib.format.read_magic(fh)
                    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                            else np.lib.format.read_array_header_2_0)
                    shape, _, dtype = read(fh)
                out.append(FileItem("array", name[:-4] if name.endswith(".npy") else name,
                                    f"shape {shape}, {dtype}"))
    except (zipfile.BadZipFile, ValueError, OSError) as e:
        raise fail(p, f"not a readable .npz file ({e})") from None
    return tuple(out)
