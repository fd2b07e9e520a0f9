"""File loaders: turn measurement files into a :class:`Recording`.

>>> from modaluq.io import load
>>> rec = load("bridge.npz")                       # doctest: +SKIP
>>> rec = load("run1.csv", inputs=["hammer"])      # doctest: +SKIP

Each format lives in its own module and imports its optional dependency (h5py, pyuff,
npTDMS, scipy) only when that format is read, so a missing package matters only for it.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path

from .errors import RecordingFileError
from .recording import Recording

__all__ = ["Recording", "RecordingFileError", "load", "FileFormat", "FILE_FORMATS", "SUPPORTED_EXTENSIONS",
           "FORMATS", "PARSE_TIMEOUT",
           "read_csv", "read_numpy", "read_npy", "read_npz", "read_matlab", "read_hdf5",
           "read_uff", "read_tdms", "from_sep005", "to_sep005", "Campaign", "load_campaign"]

#: Time limit (s) for one file parsed in an isolated child process (MATLAB, HDF5 readers with
#: ``isolate=True``, the default), plus one second per 50 MB of file; a small file gets less
#: (5 s plus 1 s per MB, ``_common.parse_timeout``). Past it the parser is killed and a
#: RecordingFileError says so. See docs/reliability.md.
PARSE_TIMEOUT = 60.0


@dataclass(frozen=True)
class FileFormat:
    """A file format :func:`load` reads: its ``format=`` name, the module and reader function
    (``modaluq.io.<module>.<reader>``), the file extensions (lower case) and what it needs
    beyond numpy."""

    name: str
    module: str
    reader: str
    extensions: tuple
    requires: str = ""


#: Every file format, in the order the docs list them: the one list that ``load``, the CLI's
#: ``--format`` choices, docs/loaders.md's table (a test compares them) and the loader fuzzer
#: read. A new format is a module with its reader and one entry here (docs/architecture.md).
FILE_FORMATS = (
    FileFormat("csv", "csv", "read_csv", (".csv", ".tsv", ".txt")),
    FileFormat("numpy", "numpy_", "read_numpy", (".npy", ".npz")),
    FileFormat("matlab", "matlab", "read_matlab", (".mat",), "scipy; h5py for v7.3"),
    FileFormat("hdf5", "hdf5", "read_hdf5", (".h5", ".hdf5", ".hdf", ".he5"), "h5py"),
    FileFormat("uff", "uff", "read_uff", (".uff", ".unv"), "pyuff"),
    FileFormat("tdms", "tdms", "read_tdms", (".tdms",), "npTDMS"),
)

#: format name -> (module, reader function)
FORMATS = {f.name: (f.module, f.reader) for f in FILE_FORMATS}

#: file extension (lower case) -> format name
SUPPORTED_EXTENSIONS = {ext: f.name for f in FILE_FORMATS for ext in f.extensions}

# reader name -> module, imported on first use
_LAZY = {**{f.reader: f.module for f in FILE_FORMATS},
         "read_npy": "numpy_", "read_npz": "numpy_", "from_sep005": "sep005", "to_sep005": "sep005",
         "Campaign": "campaign", "load_campaign": "campaign"}


def __getattr__(name):  # PEP 562: import format modules on first use
    if name in _LAZY:
        mod = importlib.import_module(f".{_LAZY[name]}", __name__)
        return getattr(mod, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


def load(path, *, fs=None, inputs=None, format=None, **format_options) -> Recording:
    """Load a recording, choosing the reader from the file extension.

    Parameters
    ----------
    path : str or os.PathLike
    fs : float, optional
        Sampling frequency in Hz; overrides what the file says (required when it says nothing).
    inputs : list of str/int, optional
        Channels that are known inputs, by name or index; the others are outputs.
    format : str, optional
        Force a reader (a name of :data:`FILE_FORMATS`: 'csv', 'numpy', 'matlab', 'hdf5',
        'uff', 'tdms') regardless of the extension.
    **format_options
        Passed to the reader (e.g. ``dataset=`` for HDF5, ``variable=`` for MATLAB,
        ``group=`` for TDMS, ``time_column=`` for CSV).

    Raises
    ------
    ValueError
        Unknown extension (the message lists the supported ones), or a corrupt, truncated,
        empty or wrongly laid-out file (the message names the file).
    TypeError
        An argument of the wrong type (the message names the parameter).
    FileNotFoundError
        The file does not exist.
    """
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be a str or os.PathLike, got {type(path).__name__}"
                        + (" (for SEP005 dicts use modaluq.io.from_sep005)"
                           if isinstance(path, (dict, list)) else ""))
    if format is not None:
        if not isinstance(format, str):
            raise TypeError(f"format must be a str, got {type(format).__name__}")
        fmt = format.lower()
        if fmt not in FORMATS:
            raise ValueError(f"unknown format {format!r}; supported: {', '.join(FORMATS)}")
    else:
        ext = Path(path).suffix.lower()
        if ext not in SUPPORTED_EXTENSIONS:
            raise ValueError(
                f"{path}: unsupported file extension {ext or '(none)'!r}; supported: "
                f"{', '.join(SUPPORTED_EXTENSIONS)} (or pass format=)")
        fmt = SUPPORTED_EXTENSIONS[ext]
    mod_name, func_name = FORMATS[fmt]
    mod = importlib.import_module(f".{mod_name}", __name__)
    return getattr(mod, func_name)(path, fs=fs, inputs=inputs, **format_options)
