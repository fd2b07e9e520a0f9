"""The records of a batch: files found in folders and patterns, record objects, their times
and covariates, in the order they are tracked (docs/monitoring.md §1).

A record is a file (a path; a folder's recording files, sorted; a glob pattern) or an object
with ``load()`` or with ``y`` and ``fs``; each becomes a :class:`RecordTask` (small, picklable:
what a worker needs) with its name, time (from the object, the covariate table or the file name)
and covariates. Records are ordered by time where it is known. A file reached through several
symbolic links (or a link and its target) is one record; a dangling link is a record, which fails
at ``load``. :func:`file_state` and :func:`file_sha256` say which bytes a part was made from.
"""

from __future__ import annotations

import glob
import hashlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from ..io import SUPPORTED_EXTENSIONS

__all__ = ["RECORD_EXTENSIONS", "RecordTask", "covariate_matrix", "file_sha256", "file_state", "record_files",
           "record_tasks", "record_times", "time_from_name"]

#: Extensions a folder given to :func:`monitor` is searched for.
RECORD_EXTENSIONS = tuple(sorted(SUPPORTED_EXTENSIONS))

_TIME_IN_NAME = re.compile(r"(\d{4})-?(\d{2})-?(\d{2})[T_ -]?(\d{2})[-:_h]?(\d{2})(?:[-:_m]?(\d{2}))?")


def record_files(paths) -> list:
    """Paths, folders (their recording files, sorted) and glob patterns → a sorted list of files.

    A pattern or a folder that matches nothing is a ``ValueError`` naming it.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    out = []
    for p in paths:
        text = str(p)
        if any(c in text for c in "*?["):
            hits = sorted(glob.glob(text, recursive=True))
            if not hits:
                raise ValueError(f"records: the pattern {text!r} matches no file")
            out += [Path(h) for h in hits if Path(h).is_file() or _dangling(Path(h))]
        elif Path(text).is_dir():
            hits = sorted(f for f in Path(text).iterdir()
                          if (f.is_file() or _dangling(f)) and f.suffix.lower() in RECORD_EXTENSIONS)
            if not hits:
                raise ValueError(f"records: the folder {text!r} holds no recording file "
                                 f"({' '.join(RECORD_EXTENSIONS)})")
            out += hits
        elif not Path(text).exists() and (text.endswith(("/", os.sep)) or not Path(text).suffix):
            raise ValueError(f"records: no such file or folder: {text}")
        else:
            out.append(Path(text))  # a missing file is the record's failure, not the batch's (copied late)
    return out


def _dangling(path: Path) -> bool:
    """A symbolic link whose target does not exist: listed, so that its record fails at ``load``
    (a recording moved away is said, not skipped)."""
    return path.is_symlink() and not path.exists()


def file_state(path) -> Optional[tuple]:
    """``(size, mtime_ns)`` of a file (through links), or None when it cannot be read."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


def file_sha256(path, chunk: int = 1 << 20) -> str:
    """The SHA-256 of a file's bytes (hex), read in chunks of ``chunk`` bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def time_from_name(name: str):
    """The time a file name states (``2026-03-01_12-00-00``, ``20260301T1200``), or None."""
    m = _TIME_IN_NAME.search(name)
    if not m:
        return None
    y, mo, d, h, mi, s = (g or "00" for g in m.groups())
    try:
        return np.datetime64(f"{y}-{mo}-{d}T{h}:{mi}:{s}", "s")
    except ValueError:
        return None


@dataclass(frozen=True)
class RecordTask:
    """What a worker needs for one record (small, picklable)."""

    key: str                  #: unique: the absolute path (links resolved), or the record object's name
    name: str                 #: shown in tables and plots
    source: object            #: a path (str), or an object with ``load()`` or with ``y`` and ``fs``
    time: Optional[np.datetime64] = None
    covariates: dict = field(default_factory=dict)
    aliases: tuple = ()       #: other paths given that are this file (symbolic links), taken once


def record_tasks(records, covariates=None) -> list:
    """Records (paths, folders, patterns, record objects) → tasks with names, times and covariates."""
    if isinstance(records, (str, os.PathLike)) or _is_record_object(records):
        records = [records]
    if isinstance(records, np.ndarray) or not hasattr(records, "__iter__"):
        raise TypeError("records must be paths, folders, glob patterns or record objects (one, or a list of them); "
                        f"got {type(records).__name__}")
    records = list(records)
    items = []
    for r in records:
        if isinstance(r, (str, os.PathLike)):
            items += [(p, None) for p in record_files([r])]
        elif _is_record_object(r):
            items.append((None, r))
        else:
            raise TypeError(f"records: each record must be a path, a folder, a pattern, or an object with load() "
                            f"or with y and fs; got {type(r).__name__}")
    if not items:
        raise ValueError("records: no record given")
    items, aliases = _one_per_file(items)
    table = _covariate_table(covariates)
    tasks, matched = [], 0
    for k, (path, obj) in enumerate(items):
        if path is not None:
            key, name, source = str(path.resolve()), path.name, str(path)
            t, cov = time_from_name(path.name), {}
        else:
            name = str(getattr(obj, "name", None) or f"record-{k:05d}")
            key, source = name, obj
            t = getattr(obj, "time", None)
            cov = dict(getattr(obj, "covariates", None) or {})
        row = table.get(name) or (table.get(Path(name).stem) if path is not None else None)
        if row is not None:
            matched += 1
            row = dict(row)
            if row.get("time") is not None:
                t = row.pop("time")
            else:
                row.pop("time", None)
            cov.update(row)
        tasks.append(RecordTask(key=key, name=name, source=source,
                                time=None if t is None else np.datetime64(t, "s"), covariates=cov,
                                aliases=aliases.get(k, ())))
    if table and not matched:
        raise ValueError(f"covariates: no row of the table is a record (its 'record' column holds e.g. "
                         f"{next(iter(table))!r}; the records are named e.g. {tasks[0].name!r})")
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        dup = sorted({k for k in keys if keys.count(k) > 1})[:3]
        raise ValueError(f"records: the same record is given more than once: {', '.join(dup)}")
    if any(t.time is not None for t in tasks):
        # by time where it is known (stable: equal times keep the given order); records without a
        # time after them, in the order given (a note says so: run.py)
        tasks.sort(key=lambda t: (t.time is None, t.time if t.time is not None else np.datetime64(0, "s")))
    return tasks


def _one_per_file(items: list) -> tuple:
    """The items (``(path, None)`` or ``(None, object)``) with one path per file: of the paths that
    resolve to one file through symbolic links, the file itself (else the first given) is kept, and
    the others are its aliases (``{index in the returned items: (alias paths, ...)}``). A path given
    twice as such is left to be refused by :func:`record_tasks`."""
    groups = {}
    for k, (path, _) in enumerate(items):
        if path is not None:
            groups.setdefault(str(path.resolve()), []).append(k)
    dropped, alias_of = set(), {}
    for target, ks in groups.items():
        if len({os.path.abspath(items[k][0]) for k in ks}) < len(ks):
            continue  # the same path more than once: a mistake in the list, refused
        if len(ks) > 1:
            keep = next((k for k in ks if os.path.abspath(items[k][0]) == target), ks[0])
            alias_of[keep] = tuple(str(items[k][0]) for k in ks if k != keep)
            dropped.update(k for k in ks if k != keep)
    kept = [k for k in range(len(items)) if k not in dropped]
    return [items[k] for k in kept], {i: alias_of[k] for i, k in enumerate(kept) if k in alias_of}


def _is_record_object(r) -> bool:
    return hasattr(r, "load") or (hasattr(r, "y") and hasattr(r, "fs"))


def _covariate_table(covariates) -> dict:
    """``covariates``: None, a CSV path or a DataFrame with a ``record`` column (or index) → {name: {col: value}}."""
    if covariates is None:
        return {}
    import pandas as pd

    if isinstance(covariates, (str, os.PathLike)):
        try:
            covariates = pd.read_csv(covariates)
        except (OSError, ValueError) as exc:
            raise ValueError(f"covariates: cannot read {covariates}: {exc}") from None
    if not isinstance(covariates, pd.DataFrame):
        raise TypeError(f"covariates must be a CSV path or a pandas DataFrame; got {type(covariates).__name__}")
    df = covariates.copy()
    if "record" in df.columns:
        df = df.set_index("record")
    elif df.index.name != "record":
        columns = ", ".join(map(str, df.columns))
        raise ValueError("covariates: the table needs a 'record' column (the records' file names, or the names of "
                         f"record objects) to match its rows to the records; its columns: {columns}")
    out = {}
    for name, row in df.iterrows():
        entry = {}
        for col, v in row.items():
            if col == "time":
                entry["time"] = None if pd.isna(v) else np.datetime64(pd.Timestamp(v).to_datetime64(), "s")
            else:
                try:
                    entry[str(col)] = float(v)
                except (TypeError, ValueError):
                    raise ValueError(f"covariates: column {col!r} of record {name!r} is not a number: {v!r}") from None
        out[str(name)] = entry
    return out


def record_times(tasks: list) -> np.ndarray:
    """(n_records,) ``datetime64[s]`` of the tasks, NaT where unknown."""
    return np.array([np.datetime64(t.time, "s") if t.time is not None else np.datetime64("NaT", "s") for t in tasks])


def covariate_matrix(tasks: list) -> tuple:
    """``(names, X)``: the covariates' names (sorted) and their values, (n_records, n_covariates),
    NaN where a record has no value."""
    names = sorted({c for t in tasks for c in t.covariates})
    X = np.array([[t.covariates.get(c, np.nan) for c in names] for t in tasks], float).reshape(len(tasks), len(names))
    return names, X
