"""Monitoring: many records → tracked modes with σ, change statistics and alarms.

:func:`monitor` runs one task per record (load → preprocess → identify → select, the
:class:`~modaluq.Analysis` of ``modaluq identify`` with the same settings objects) on an executor,
keeps every finished record in a part file as soon as it arrives, then tracks the modes and tests
their changes (:mod:`modaluq.tracking`) into one :class:`xarray.Dataset` written as NetCDF or Zarr,
with a long table of the selected modes' poles and a table of the failures beside it
(docs/monitoring.md).

Executors, one code path (:class:`concurrent.futures.Executor`):

- default: a thread pool in this process (the core releases the GIL; the BLAS runs on one thread);
- a ``dask.distributed.Client`` (given, or active), a scheduler address, or a ``LocalCluster`` of
  ``workers`` processes, through the client's ``concurrent.futures`` executor;
- any other :class:`concurrent.futures.Executor` (e.g. a ``ProcessPoolExecutor``).

Part files (``<store stem>.parts/``) make a run restartable: a record whose part says it is done
is not run again (``resume=True``), a failed one is; the parts are written by this process, one
file per record, atomically (a killed run leaves whole parts only). The parts remember the
settings they were made with, and a run with other settings refuses to mix them.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import glob
import hashlib
import json
import os
import re
import sys
import time
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
import scipy.stats

from ._blas import single_threaded
from .analysis import Analysis
from .checks import check_boolean, check_integer, require
from .io import SUPPORTED_EXTENSIONS
from .plot import plot_control_chart, plot_tracked_frequencies
from .results import ModalUQWarning
from .settings import ClusteringSettings, Settings, StabilityCriteria
from .tracking import RecordModes, ReferenceModes, TrackingSettings, assign, change_test, reference_modes
from .version import __version__

__all__ = ["Monitoring", "RecordTask", "load_tracks", "monitor", "process_record", "record_files"]

#: Extensions a folder given to :func:`monitor` is searched for.
RECORD_EXTENSIONS = tuple(sorted(SUPPORTED_EXTENSIONS))

#: complex variables of the dataset, stored as their real and imaginary parts (NetCDF has no complex type)
COMPLEX_SHAPES = {"mode_shape": "mode shape of the record, largest component 1",
                  "reference_mode_shape": "mode shape of the reference, largest component 1"}

_TIME_IN_NAME = re.compile(r"(\d{4})-?(\d{2})-?(\d{2})[T_ -]?(\d{2})[-:_h]?(\d{2})(?:[-:_m]?(\d{2}))?")


# ------------------------------------------------------------------------------ records


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
            out += [Path(h) for h in hits if Path(h).is_file()]
        elif Path(text).is_dir():
            hits = sorted(f for f in Path(text).iterdir() if f.is_file() and f.suffix.lower() in RECORD_EXTENSIONS)
            if not hits:
                raise ValueError(f"records: the folder {text!r} holds no recording file "
                                 f"({' '.join(RECORD_EXTENSIONS)})")
            out += hits
        elif not Path(text).exists() and (text.endswith(("/", os.sep)) or not Path(text).suffix):
            raise ValueError(f"records: no such file or folder: {text}")
        else:
            out.append(Path(text))  # a missing file is the record's failure, not the batch's (copied late)
    return out


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

    key: str                  #: unique: the absolute path, or the record object's name
    name: str                 #: shown in tables and plots
    source: object            #: a path (str), or an object with ``load()`` or with ``y`` and ``fs``
    time: Optional[np.datetime64] = None
    covariates: dict = field(default_factory=dict)


@dataclass(frozen=True)
class TaskConfig:
    """The settings every record is run with (the part files remember them)."""

    settings: Settings = field(default_factory=Settings)
    criteria: StabilityCriteria = field(default_factory=StabilityCriteria)
    clustering: ClusteringSettings = field(default_factory=ClusteringSettings)
    read: dict = field(default_factory=dict)  #: fs, format, read_options, outputs, inputs, references
    check_harmonics: bool = False             #: flag modes that may be harmonics (costs about an identification)
    worker_process: bool = False              #: the task runs in a worker process (Dask, process pools)

    def fingerprint(self) -> dict:
        return {"modaluq": __version__, "settings": self.settings.to_dict(), "criteria": self.criteria.to_dict(),
                "clustering": self.clustering.to_dict(), "read": _jsonable(self.read),
                "check_harmonics": self.check_harmonics}


def _tasks(records, covariates) -> list:
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
                                time=None if t is None else np.datetime64(t, "s"), covariates=cov))
    if table and not matched:
        raise ValueError(f"covariates: no row of the table is a record (its 'record' column holds e.g. "
                         f"{next(iter(table))!r}; the records are named e.g. {tasks[0].name!r})")
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        dup = sorted({k for k in keys if keys.count(k) > 1})[:3]
        raise ValueError(f"records: the same record is given more than once: {', '.join(dup)}")
    if any(t.time is not None for t in tasks):
        # by time where it is known (stable: equal times keep the given order); records without a
        # time after them, in the order given (a note says so: _notes)
        tasks.sort(key=lambda t: (t.time is None, t.time if t.time is not None else np.datetime64(0, "s")))
    return tasks


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


# ------------------------------------------------------------------------------ one record


def process_record(task: RecordTask, config: TaskConfig) -> dict:
    """Run one record; never raises. Returns plain values: the status, the stage that failed and
    its error, or the selected modes and their poles."""
    t0 = time.perf_counter()
    stage = "load"
    out = {"key": task.key, "name": task.name, "status": "failed", "stage": "", "error": "", "warnings": []}
    try:
        if config.worker_process:
            _configure_worker_process()
        analysis = _analysis(task, config)
        stage = "preprocess"
        analysis.preprocess()

        def step(what):
            nonlocal stage
            stage = "identify" if what == "identifying" else "select"

        # the identification's warnings are kept, as text, in analysis.warnings and not issued:
        # Python's warning filters are global, and records run at once on threads would mix them
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # anything else a record's steps may warn of
            analysis.run(check_harmonics=config.check_harmonics, progress=step, issue_warnings=False)
        stage = "select"
        out.update(_modes_of(analysis))
        out.update(status="done", stage="", warnings=list(analysis.warnings))
    except MemoryError:
        out.update(stage=stage, error="out of memory")
    except Exception as exc:  # the record's failure, kept with its stage; the batch goes on
        out.update(stage=stage, error=f"{type(exc).__name__}: {' '.join(str(exc).split())}")
        if not isinstance(exc, (ValueError, TypeError, OSError)):
            out["traceback"] = traceback.format_exc(limit=6)
    out["seconds"] = time.perf_counter() - t0
    return out


#: glibc ``mallopt`` parameters and the values a worker process gets (see _configure_worker_process)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
WORKER_MMAP_THRESHOLD = 32 << 20
WORKER_TRIM_THRESHOLD = 64 << 20


def _configure_worker_process() -> None:
    """One BLAS thread, and glibc's allocator tuned for the core's large temporaries; for the
    whole worker process (these settings stay for its later tasks, which is what we want).

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``. In glibc that also freezes
    the mmap threshold at 128 KiB, so every large temporary of an identification is a fresh
    ``mmap`` whose pages fault in again: a record then took 1.14 s instead of 0.83 s here.
    glibc's own dynamic maximum of the mmap threshold (32 MiB) restores the speed; a trim
    threshold of 64 MiB still returns memory to the system after a record (docs/monitoring.md §2).
    """
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")
    if sys.platform.startswith("linux"):
        import ctypes
        import ctypes.util

        with contextlib.suppress(OSError, AttributeError, TypeError):  # not glibc (musl): nothing to tune
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            libc.mallopt(_M_MMAP_THRESHOLD, WORKER_MMAP_THRESHOLD)
            libc.mallopt(_M_TRIM_THRESHOLD, WORKER_TRIM_THRESHOLD)


def _analysis(task: RecordTask, config: TaskConfig) -> Analysis:
    read = dict(config.read)
    common = dict(references=read.get("references"), settings=config.settings, criteria=config.criteria,
                  clustering=config.clustering)
    if isinstance(task.source, str):
        return Analysis.from_file(task.source, fs=read.get("fs"), format=read.get("format"),
                                  read_options=read.get("read_options"), outputs=read.get("outputs"),
                                  inputs=read.get("inputs"), **common)
    rec = task.source.load() if hasattr(task.source, "load") else task.source
    u = getattr(rec, "u", None)
    if u is not None and np.asarray(u).size == 0:
        u = None
    names = getattr(rec, "output_names", None) or getattr(task.source, "output_names", None) or None
    return Analysis.from_arrays(rec.y, u, fs=rec.fs, output_names=names, **common)


def _modes_of(analysis: Analysis) -> dict:
    """The selected modes (with the f-ξ correlation of each representative pole) and their poles."""
    sel, d, res = analysis.selected, analysis.diagram, analysis.result
    m = sel.n_modes
    rho = np.full(m, np.nan)
    first_of_order = {o: int(np.flatnonzero(d.order == o)[0]) for o in np.unique(d.order)}
    for i in range(m):
        pole = int(sel.representative_pole[i])
        order = int(d.order[pole])
        modes = res.at_order(order)
        j = pole - first_of_order[order]
        if modes.covariance is not None and 0 <= j < modes.n_modes \
                and np.isclose(modes.frequency_hz[j], d.frequency_hz[pole], rtol=1e-12):
            c = modes.covariance[j]
            if c[0, 0] > 0 and c[1, 1] > 0:
                rho[i] = c[0, 1] / np.sqrt(c[0, 0] * c[1, 1])
    members = [np.asarray(mem, np.int64) for mem in sel.members]
    pole_mode = np.concatenate([np.full(len(mem), i + 1) for i, mem in enumerate(members)]) if m else np.zeros(0, int)
    pole_index = np.concatenate(members) if m else np.zeros(0, np.int64)
    return {
        "output_names": list(analysis.output_names), "fs_hz": float(analysis.fs), "n_blocks": int(res.n_blocks),
        "n_samples": int(analysis.y.shape[0]),
        "modes": {
            "frequency_hz": sel.frequency_hz, "damping_ratio": sel.damping_ratio,
            "frequency_std": sel.frequency_std, "damping_std": sel.damping_std,
            "frequency_damping_correlation": rho, "mode_shape": sel.mode_shape,
            "mode_shape_std_real": sel.mode_shape_std_real, "mode_shape_std_imag": sel.mode_shape_std_imag,
            "n_poles": sel.n_poles, "representative_order": sel.representative_order,
            "possible_harmonic": (analysis.possible_harmonic if analysis.possible_harmonic.size == m
                                  else np.zeros(m, bool)),
        },
        "poles": {
            "selected_mode": pole_mode, "order": d.order[pole_index],
            "representative": np.isin(pole_index, sel.representative_pole),
            "frequency_hz": d.frequency_hz[pole_index], "damping_ratio": d.damping_ratio[pole_index],
            "frequency_std": d.frequency_std[pole_index], "damping_std": d.damping_std[pole_index],
        },
    }


# ------------------------------------------------------------------------------ part files


class _Parts:
    """One file per record in ``folder``, written atomically; ``settings.json`` guards the mix."""

    def __init__(self, folder: Path, config: TaskConfig, start_again: bool = False):
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        _remove_stale_temporaries(folder)
        stamp = folder / "settings.json"
        fingerprint = json.loads(json.dumps(config.fingerprint()))
        if start_again:  # resume=False: the parts of earlier runs (perhaps other settings) are dropped
            for old in folder.glob("*.json"):
                old.unlink()
        if stamp.exists():
            try:
                previous = json.loads(stamp.read_text())
            except ValueError:
                previous = None
            if previous != fingerprint:
                changed = _changed_keys(previous, fingerprint)
                raise ValueError(f"the part files in {folder} were made with other settings ({', '.join(changed)} "
                                 "differ); run again with resume=False (--no-resume) to start again with these "
                                 "settings, or write to another store")
        else:
            _atomic_write(stamp, json.dumps(fingerprint, indent=1).encode())

    def path(self, key: str) -> Path:
        return self.folder / f"{hashlib.sha1(key.encode()).hexdigest()[:20]}.json"

    def read(self, key: str):
        p = self.path(key)
        try:
            part = json.loads(p.read_text())
        except (OSError, ValueError):
            return None  # absent (or, impossibly with atomic writes, torn): run it again
        return part if part.get("key") == key else None

    def write(self, key: str, text: str) -> None:
        """Write the part of ``key`` (``text``: its JSON)."""
        _atomic_write(self.path(key), text.encode())


def _changed_keys(old, new, prefix="") -> list:
    """The dotted keys whose values differ between two fingerprints (e.g. ``settings.frequency_range``)."""
    if not isinstance(old, dict) or not isinstance(new, dict):
        return [prefix or "the file"] if old != new else []
    keys = sorted(set(old) | set(new))
    return [c for k in keys for c in _changed_keys(old.get(k), new.get(k), f"{prefix}{k}" if not prefix
                                                   else f"{prefix}.{k}")]


def _remove_stale_temporaries(folder: Path) -> None:
    """Delete the half-written ``.<part>.<pid>.tmp`` files of writers that were killed: their
    records have no part and run again. A file of a process still alive on this machine is kept
    (two runs on one store are not supported, but one must not break the other's write)."""
    for tmp in folder.glob(".*.tmp"):
        try:
            pid = int(tmp.name.rsplit(".", 2)[-2])
        except ValueError:
            pid = None
        if pid is not None and pid != os.getpid() and _process_alive(pid):
            continue
        with contextlib.suppress(OSError):
            tmp.unlink()


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists, another user's
    return True


def _atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _jsonable(x):
    """Arrays (complex ones as {"real", "imag"}) and NumPy scalars → JSON values; NaN stays NaN."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        if np.iscomplexobj(x):
            return {"real": x.real.tolist(), "imag": x.imag.tolist()}
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, (Settings, StabilityCriteria, ClusteringSettings)):
        return x.to_dict()
    return x


def _array(value, dtype=float):
    if isinstance(value, dict) and set(value) == {"real", "imag"}:
        return np.asarray(value["real"], float) + 1j * np.asarray(value["imag"], float)
    return np.asarray(value, dtype)


# ------------------------------------------------------------------------------ executors


@contextlib.contextmanager
def _executor(executor, threads, workers, scheduler):
    """``(executor, remote)``: the executor the tasks go to, and whether they run in other processes."""
    given = sum(x is not None for x in (executor, threads, workers, scheduler))
    if given > 1:
        raise ValueError("give at most one of executor=, threads=, workers= and scheduler=")
    if given == 0 and "distributed" in sys.modules:
        try:  # "use an active Client"
            executor = sys.modules["distributed"].default_client()
        except ValueError:
            executor = None
    if executor is not None:
        if type(executor).__name__ == "Client" and hasattr(executor, "get_executor"):
            yield executor.get_executor(pure=False), True
        elif isinstance(executor, concurrent.futures.Executor):
            yield executor, not isinstance(executor, concurrent.futures.ThreadPoolExecutor)
        else:
            raise TypeError("executor must be a concurrent.futures.Executor or a dask.distributed.Client; "
                            f"got {type(executor).__name__}")
        return
    if workers is not None or scheduler is not None:
        require("distributed", "workers= or scheduler=")
        from distributed import Client, LocalCluster

        if scheduler is not None:
            with Client(scheduler) as client:
                yield client.get_executor(pure=False), True
            return
        workers = check_integer("workers", workers, minimum=1)
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) \
                as cluster, Client(cluster) as client:
            yield client.get_executor(pure=False), True
        return
    threads = (os.cpu_count() or 1) if threads is None else check_integer("threads", threads, minimum=1)
    with concurrent.futures.ThreadPoolExecutor(max_workers=threads, thread_name_prefix="modaluq") as pool:
        yield pool, False


# ------------------------------------------------------------------------------ the run


@dataclass(repr=False)
class Monitoring:
    """The tracked modes of a batch of records: the dataset, the poles, the failures."""

    dataset: object                    #: xarray.Dataset (record × mode [× channel])
    poles: object                      #: pandas.DataFrame, one row per pole of every selected mode
    failures: object                   #: pandas.DataFrame: record, source, stage, error
    reference: Optional[ReferenceModes] = None
    tracking: TrackingSettings = field(default_factory=TrackingSettings)
    notes: tuple = ()                  #: what limits the run's tests (records not tested, order, reference)
    written: tuple = ()                #: files written
    seconds: float = 0.0               #: wall time of the run
    n_run: int = 0                     #: records run by this call (the rest came from part files)

    @property
    def n_records(self) -> int:
        return int(self.dataset.sizes["record"])

    @property
    def n_failed(self) -> int:
        return len(self.failures)

    def alarms(self):
        """The alarms as a table: record, time, mode, frequency_hz, frequency_change,
        damping_change (standardised), control (the statistic), sigma_confirmed (False: the mode's σ
        is not confirmed by the reference period, its alarms are more frequent than the rate stated)."""
        import pandas as pd

        columns = ["record", "time", "mode", "frequency_hz", "frequency_change", "damping_change", "control",
                   "sigma_confirmed"]
        ds = self.dataset
        if ds.sizes["mode"] == 0 or "control" not in ds:
            return pd.DataFrame(columns=columns)
        df = ds[["frequency_hz", "frequency_change", "damping_change", "control", "alarm"]].to_dataframe()
        df = df[df["alarm"].astype(bool)].drop(columns="alarm").reset_index()
        df["sigma_confirmed"] = ds["sigma_confirmed"].sel(mode=df["mode"].values).values.astype(bool)
        return df[columns]

    def plot_frequencies(self, **kwargs):
        """Tracked frequencies against time with ±σ bands and the alarms marked (a Figure)."""
        return plot_tracked_frequencies(self.dataset, **kwargs)

    def plot_control_chart(self, **kwargs):
        """The control statistic of every tracked mode against its alarm limit (a Figure)."""
        return plot_control_chart(self.dataset, **kwargs)

    def __str__(self) -> str:
        return self.summary()

    def __repr__(self) -> str:  # a notebook cell ending in the result shows the summary, not the Dataset
        return f"<modaluq Monitoring: {self.n_records} records>\n{self.summary()}"

    def summary(self, notes: bool = True) -> str:
        """The run, the reference modes with their reduced χ² and alarm counts, and (``notes``)
        what limits the tests (:attr:`notes`)."""
        text = self._summary()
        if notes and self.notes:
            text += "\n" + "\n".join(f"note: {n}" for n in self.notes)
        return text

    def _summary(self) -> str:
        ds = self.dataset
        n_done = int((ds["status"] == "done").sum())
        lines = [f"{self.n_records} records: {n_done} identified, {self.n_failed} failed "
                 f"({self.n_run} run now, {self.seconds:.1f} s)"]
        if self.reference is None:
            lines.append("no tracking: " + ds.attrs.get("tracking_error", "no reference modes"))
            return "\n".join(lines)
        ref = ds["in_reference"].values
        if "control" not in ds:  # tracked, but the change test could not be made
            lines.append(f"reference: {int(ref.sum())} records; {ds.attrs.get('tracking_error', '')}")
            lines.append(" mode  f_ref [Hz]  found")
            for j in range(ds.sizes["mode"]):
                found = int(np.isfinite(ds["frequency_hz"].values[:, j]).sum())
                lines.append(f" {j + 1:4d}  {ds['reference_frequency_hz'].values[j]:10.4f}  {found:5d}")
            return "\n".join(lines)
        limits = ds["control_limit"].values if "control_limit" in ds else np.zeros(0)
        shown = f"{np.nanmedian(limits):.2f}" if np.isfinite(limits).any() else "none"
        lines.append(f"reference: {int(ref.sum())} records; alarms at a false-alarm rate of "
                     f"{self.tracking.false_alarm_rate:g} per record and mode (median limit {shown}, "
                     f"EWMA weight {self.tracking.smoothing:g})")
        lines.append(" mode  f_ref [Hz]  xi_ref [%]  found   reduced chi2 (f, xi)   alarms of the records tested")
        after = ~ref & (ds["status"].values == "done")
        flagged, high = _miscalibrated(ds["reference_reduced_chi2_frequency"].values,
                                       ds["reference_reduced_chi2_damping"].values, int(ref.sum()),
                                       ds.sizes.get("term", 1))
        for j in range(ds.sizes["mode"]):
            found = np.isfinite(ds["frequency_hz"].values[:, j])
            tested = after & np.isfinite(ds["control"].values[:, j])
            n_alarm = int(ds["alarm"].values[after, j].sum())
            red = (ds["reference_reduced_chi2_frequency"].values[j], ds["reference_reduced_chi2_damping"].values[j])
            flag = " !" if flagged[j] else ""
            lines.append(f" {j + 1:4d}  {ds['reference_frequency_hz'].values[j]:10.4f}  "
                         f"{100 * ds['reference_damping_ratio'].values[j]:10.3f}  {int(found.sum()):5d}   "
                         f"{red[0]:9.2f} {red[1]:9.2f}{flag:2s}  {n_alarm:5d} of {int(tested.sum())}")
        if flagged.any():
            lines.append(f" !: reduced chi2 above {high:.2f}, its 99.9 % quantile (see the note)")
        return "\n".join(lines)


def _miscalibrated(reduced_chi2_frequency, reduced_chi2_damping, n_reference: int, n_terms: int):
    """Modes whose reference reduced χ² (of f or ξ) is above its 99.9 % quantile: σ too small on
    this structure, or a covariate missing. Returns (mask, the quantile)."""
    dof = max(n_reference - n_terms, 1)
    high = scipy.stats.chi2.isf(0.001, dof) / dof
    red = np.fmax(np.asarray(reduced_chi2_frequency, float), np.asarray(reduced_chi2_damping, float))
    return np.nan_to_num(red) > high, high


def monitor(records, *, out=None, settings: Settings | None = None, criteria: StabilityCriteria | None = None,
            clustering: ClusteringSettings | None = None, tracking: TrackingSettings | None = None,
            covariates=None, fs: float | None = None, format: str | None = None, read_options: dict | None = None,
            outputs=None, inputs=None, references=None, check_harmonics: bool = False, executor=None,
            threads: int | None = None, workers: int | None = None, scheduler: str | None = None, resume: bool = True,
            poles=None, progress: bool | None = None) -> Monitoring:
    """Identify every record, track the modes, test their changes (docs/monitoring.md).

    Parameters
    ----------
    records : paths, folders, glob patterns, or record objects (one, or a list)
        A record object has ``load()`` returning something with ``y``, ``fs`` (and optionally
        ``u``, ``output_names``), or has those itself; its ``name``, ``time``, ``covariates``
        (a dict) and ``output_names`` are used when present
        (:class:`~modaluq.monitoring_simulator.SimulatedRecord`). Records are taken by time
        where it is known (from the object, the covariate table, or the file name:
        ``..._2026-03-01_12-00-00.csv``); records without a time come after them in the order
        given (a note says so), a folder's files by name.
    out : path, optional
        ``.nc`` (NetCDF) or ``.zarr`` store of the tracks; beside it ``<stem>.failures.csv``, the
        pole table ``<stem>.poles.csv`` (or ``poles=``, ``.csv`` or ``.parquet``) and the part
        files ``<stem>.parts/`` that make a run restartable (a ``.nc`` and a ``.zarr`` store of
        one stem share them). Without ``out`` nothing is written and nothing is resumed.
    settings, criteria, clustering :
        As for :class:`~modaluq.Analysis` / ``modaluq identify``: the same for every record.
    tracking : TrackingSettings, optional
        Reference period, gates, false-alarm rate, EWMA weight.
    covariates : CSV path or DataFrame, optional
        One row per record (column ``record``: the file name, or the record's name), an optional
        ``time`` column, and numeric columns (temperature, ...) the change test regresses on.
    fs, format, read_options, outputs, inputs, references :
        How files are read and which channels are used (:meth:`~modaluq.Analysis.from_file`).
    check_harmonics : bool, default False
        Flag the modes that may be harmonics of the excitation (``possible_harmonic``); it filters
        each record around each mode, about the cost of the identification itself.
    executor, threads, workers, scheduler :
        Where the records run (give at most one): ``threads=N`` a pool of N threads in this
        process; ``executor=`` a :class:`concurrent.futures.Executor` or a
        ``dask.distributed.Client``; ``workers=N`` a Dask ``LocalCluster`` of N one-thread
        processes; ``scheduler="tcp://host:port"``. None of them: an active Dask client if
        there is one, else a thread pool of one thread per core.
    resume : bool, default True
        Skip the records whose part file says they are done (failed ones are run again). False:
        start again, the part files of earlier runs (whatever their settings) are removed first.
    progress : bool, optional
        A progress bar on stderr (default: when stderr is a terminal).

    Returns
    -------
    Monitoring
        Its :attr:`~Monitoring.notes` (also issued as :class:`ModalUQWarning`) say what limits the
        tests: records without a time or a covariate value, a reference period that takes every
        record, modes whose σ the reference period does not confirm.
    """
    t0 = time.perf_counter()
    resume = check_boolean("resume", resume)
    tracking = _typed(tracking, TrackingSettings, "tracking")
    config = TaskConfig(settings=_typed(settings, Settings, "settings"),
                        criteria=_typed(criteria, StabilityCriteria, "criteria"),
                        clustering=_typed(clustering, ClusteringSettings, "clustering"),
                        check_harmonics=check_boolean("check_harmonics", check_harmonics),
                        read={k: v for k, v in dict(fs=fs, format=format, read_options=read_options, outputs=outputs,
                                                    inputs=inputs, references=references).items() if v is not None})
    out_paths = _output_paths(out, poles)
    tasks = _tasks(records, covariates)
    parts = _Parts(out_paths["parts"], config, start_again=not resume) if out_paths else None

    results = {}
    if parts is not None and resume:
        for task in tasks:
            part = parts.read(task.key)
            if part is not None and part["status"] == "done":
                results[task.key] = part
    todo = [t for t in tasks if t.key not in results]
    n_run = len(todo)
    if todo:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="records", unit="record",
                   file=sys.stderr, disable=None if progress is None else not progress, smoothing=0.05)
        # the records' warnings are caught per task (analysis.warnings); on the thread pool these
        # catches interleave and could leave the caller's filters changed: restore them after the run
        with bar, warnings.catch_warnings(), _executor(executor, threads, workers, scheduler) as (pool, remote), \
                (contextlib.nullcontext() if remote else single_threaded()), contextlib.ExitStack() as stack:
            cfg = dataclasses.replace(config, worker_process=remote)
            futures = {pool.submit(process_record, task, cfg): task for task in todo}
            n_failed = 0
            stack.callback(_cancel, futures)  # Ctrl-C or a failed write: the queued records are not run
            for fut in concurrent.futures.as_completed(futures):
                task = futures[fut]
                try:
                    part = fut.result()
                except BaseException as exc:  # a worker that died, a task the cluster gave up on
                    if isinstance(exc, KeyboardInterrupt):
                        raise
                    part = {"key": task.key, "name": task.name, "status": "failed", "stage": "worker",
                            "error": f"{type(exc).__name__}: {' '.join(str(exc).split())}", "warnings": []}
                part.update(time=None if task.time is None else str(task.time), covariates=task.covariates,
                            source=task.source if isinstance(task.source, str) else task.name)
                text = json.dumps(_jsonable(part))
                part = json.loads(text)  # the same values whether read back from a part or not
                if parts is not None:
                    parts.write(part["key"], text)
                results[task.key] = part
                n_failed += part["status"] != "done"
                bar.set_postfix_str(f"{n_failed} failed", refresh=False)
                bar.update()
    ordered = [results[t.key] for t in tasks]
    result = _consolidate(tasks, ordered, tracking)
    result.n_run = n_run
    if out_paths:
        result.written = _write(result, out_paths)
    result.seconds = time.perf_counter() - t0
    for note in result.notes:
        warnings.warn(note, ModalUQWarning, stacklevel=2)
    return result


def _cancel(futures) -> None:
    """Cancel the futures not yet started (those done or running are left alone)."""
    for fut in futures:
        fut.cancel()


def _typed(value, cls, parameter):
    if value is None:
        return cls()
    if not isinstance(value, cls):
        raise TypeError(f"{parameter} must be a modaluq {cls.__name__}; got {type(value).__name__}")
    return value


def _output_paths(out, poles) -> dict:
    if out is None:
        if poles is not None:
            raise ValueError("poles= needs out= (the pole table is written beside the store)")
        return {}
    out = Path(out)
    kind = {".nc": "netcdf", ".zarr": "zarr"}.get(out.suffix.lower())
    if kind is None:
        raise ValueError(f"out {out}: use a .nc (NetCDF) or .zarr store")
    if not out.resolve().parent.is_dir():
        raise ValueError(f"out {out}: the folder {out.resolve().parent} does not exist")
    require("xarray", f"out {out}")
    require("netCDF4" if kind == "netcdf" else "zarr", f"out {out}")
    poles = Path(poles) if poles is not None else out.with_name(out.stem + ".poles.csv")
    if poles.suffix.lower() not in (".csv", ".parquet"):
        raise ValueError(f"poles {poles}: use a .csv or .parquet file")
    if poles.suffix.lower() == ".parquet":
        require("pyarrow", f"poles {poles}")
    return {"store": out, "kind": kind, "poles": poles, "failures": out.with_name(out.stem + ".failures.csv"),
            "parts": out.with_name(out.stem + ".parts")}


# ------------------------------------------------------------------------------ consolidation


def _record_modes(part) -> RecordModes:
    m = part["modes"]
    return RecordModes(**{k: _array(m[k], complex if k == "mode_shape" else float) for k in (
        "frequency_hz", "damping_ratio", "frequency_std", "damping_std", "frequency_damping_correlation",
        "mode_shape", "mode_shape_std_real", "mode_shape_std_imag")})


def _consolidate(tasks, parts, tracking: TrackingSettings) -> Monitoring:
    import pandas as pd
    import xarray as xr

    n = len(tasks)
    done = np.array([p["status"] == "done" for p in parts])
    channels = next((tuple(p["output_names"]) for p in parts if p["status"] == "done"), ())
    for k, p in enumerate(parts):  # a record with other channels cannot be tracked with the rest
        if done[k] and tuple(p["output_names"]) != channels:
            parts[k] = dict(p, status="failed", stage="track",
                            error=f"channels {p['output_names']} differ from the first record's {list(channels)}")
            done[k] = False
    times = np.array([np.datetime64(t.time, "s") if t.time is not None else np.datetime64("NaT", "s") for t in tasks])
    cov_names = sorted({c for t in tasks for c in t.covariates})
    X = np.array([[t.covariates.get(c, np.nan) for c in cov_names] for t in tasks], float).reshape(n, len(cov_names))
    modes = [_record_modes(p) if done[k] else None for k, p in enumerate(parts)]

    # the reference period: the first K records identified, or the records in the given span
    if tracking.reference_span is not None:
        a, b = (np.datetime64(t, "s") for t in tracking.reference_span)
        in_ref = done & (times >= a) & (times <= b)
    else:
        in_ref = done & (np.cumsum(done) <= tracking.reference_records)
    ref, error = None, ""
    try:
        if in_ref.sum() < 3:
            raise ValueError(f"{int(in_ref.sum())} records identified in the reference period; at least 3 are needed")
        ref = reference_modes([modes[k] for k in np.flatnonzero(in_ref)], tracking)
    except ValueError as exc:
        error = str(exc)
    k_modes = ref.n_modes if ref is not None else 0
    l = len(channels)
    F = np.full((n, k_modes), np.nan)
    XI, SF, SX, RHO, MAC, DIST, NP = (np.full((n, k_modes), np.nan) for _ in range(7))
    HARM = np.zeros((n, k_modes), bool)
    SH = np.full((n, l, k_modes), np.nan + 0j)
    SHR, SHI = np.full((n, l, k_modes), np.nan), np.full((n, l, k_modes), np.nan)
    n_unassigned = np.zeros(n, int)
    tracked_of_pole = {}
    for k in range(n):
        if modes[k] is None:
            continue
        mk = modes[k]
        idx, mac, dist = assign(mk, ref, tracking) if ref is not None else (np.full(mk.n_modes, -1), None, None)
        tracked_of_pole[k] = idx
        n_unassigned[k] = int((idx < 0).sum())
        for i, j in enumerate(idx):
            if j < 0:
                continue
            F[k, j], XI[k, j] = mk.frequency_hz[i], mk.damping_ratio[i]
            SF[k, j], SX[k, j], RHO[k, j] = mk.frequency_std[i], mk.damping_std[i], mk.frequency_damping_correlation[i]
            MAC[k, j], DIST[k, j] = mac[i], dist[i]
            NP[k, j] = parts[k]["modes"]["n_poles"][i]
            HARM[k, j] = bool(parts[k]["modes"].get("possible_harmonic", [False] * mk.n_modes)[i])
            SH[k, :, j] = mk.mode_shape[:, i]
            SHR[k, :, j], SHI[k, :, j] = mk.mode_shape_std_real[:, i], mk.mode_shape_std_imag[:, i]
    C = np.zeros((n, k_modes, 2, 2))
    C[..., 0, 0], C[..., 1, 1] = SF**2, SX**2
    C[..., 0, 1] = C[..., 1, 0] = np.nan_to_num(RHO) * SF * SX
    # the covariance of a record's [f, ξ] is a sample covariance over its blocks: n_blocks - 1 dof
    dof = np.array([p.get("n_blocks", 0) - 1 if done[k] and p.get("n_blocks", 0) > 1 else np.inf
                    for k, p in enumerate(parts)], float)
    test = None
    if ref is not None:
        try:
            test = change_test(F, XI, C, in_ref, X if cov_names else None, tracking, dof=dof)
        except ValueError as exc:  # the records stay identified and tracked; only the test is missing
            error = f"no change test: {exc}"

    miscalibrated = None  # (modes whose σ the reference does not confirm, the quantile)
    if test is not None:
        miscalibrated = _miscalibrated(test.reference_reduced_chi2_frequency, test.reference_reduced_chi2_damping,
                                       int(in_ref.sum()), 1 + len(cov_names))
    rec_dims, rm, rcm = ("record",), ("record", "mode"), ("record", "channel", "mode")
    data = {
        "status": (rec_dims, np.array([p["status"] for p in parts], dtype=object)),
        "failed_stage": (rec_dims, np.array([p.get("stage", "") for p in parts], dtype=object)),
        "error": (rec_dims, np.array([p.get("error", "") for p in parts], dtype=object)),
        "warnings": (rec_dims, np.array(["\n".join(p.get("warnings", [])) for p in parts], dtype=object),
                     {"long_name": "the identification's warnings, one per line"}),
        "in_reference": (rec_dims, in_ref),
        "n_blocks": (rec_dims, np.array([p.get("n_blocks", 0) if done[k] else 0 for k, p in enumerate(parts)])),
        "n_modes_selected": (rec_dims, np.array([len(p["modes"]["frequency_hz"]) if done[k] else 0
                                                 for k, p in enumerate(parts)])),
        "n_unassigned": (rec_dims, n_unassigned),
        "frequency_hz": (rm, F, {"units": "Hz"}), "damping_ratio": (rm, XI, {"units": "1"}),
        "frequency_std": (rm, SF, {"units": "Hz"}), "damping_std": (rm, SX, {"units": "1"}),
        "frequency_damping_correlation": (rm, RHO), "mac_to_reference": (rm, MAC),
        "assignment_distance": (rm, DIST, {"long_name": "Mahalanobis distance squared to the reference mode"}),
        "n_poles": (rm, NP), "possible_harmonic": (rm, HARM),
        "mode_shape": (rcm, SH, {"long_name": COMPLEX_SHAPES["mode_shape"]}),
        "mode_shape_real": (rcm, SH.real), "mode_shape_imag": (rcm, SH.imag),
        "mode_shape_std_real": (rcm, SHR), "mode_shape_std_imag": (rcm, SHI),
    }
    for c, col in zip(cov_names, X.T):
        data[c] = (rec_dims, col, {"long_name": f"covariate {c}"})
    if test is not None:
        data.update({
            "expected_frequency_hz": (rm, test.expected_frequency_hz, {"units": "Hz"}),
            "expected_damping_ratio": (rm, test.expected_damping_ratio, {"units": "1"}),
            "frequency_change": (rm, test.frequency_change, {"long_name": "standardised frequency change"}),
            "damping_change": (rm, test.damping_change, {"long_name": "standardised damping change"}),
            "chi2": (rm, test.chi2, {"long_name": "chi-squared of f and xi against the reference (2 dof)"}),
            "control": (rm, test.control, {"long_name": "MEWMA control statistic (Hotelling T2 of f and xi)"}),
            "alarm": (rm, test.alarm),
            "control_limit": (rm, test.control_limit, {"long_name": "alarm limit of the control statistic"}),
            "reference_reduced_chi2": (("mode",), test.reference_reduced_chi2),
            "reference_reduced_chi2_frequency": (("mode",), test.reference_reduced_chi2_frequency),
            "reference_reduced_chi2_damping": (("mode",), test.reference_reduced_chi2_damping),
            "sigma_confirmed": (("mode",), ~miscalibrated[0],
                                {"long_name": "the reference reduced chi2 of f and xi is within its 99.9 % "
                                              "quantile (false: sigma too small here or a covariate missing; "
                                              "alarms too frequent)"}),
            "frequency_coefficients": (("mode", "term"), test.coefficients_frequency,
                                       {"units": "Hz (constant), Hz per covariate unit (the others)"}),
            "damping_coefficients": (("mode", "term"), test.coefficients_damping,
                                     {"units": "1 (constant), 1 per covariate unit (the others)"}),
        })
    else:
        data["alarm"] = (rm, np.zeros((n, k_modes), bool))
    if ref is not None:
        data.update({
            "reference_frequency_hz": (("mode",), ref.frequency_hz, {"units": "Hz"}),
            "reference_damping_ratio": (("mode",), ref.damping_ratio, {"units": "1"}),
            "reference_mode_shape": (("channel", "mode"), ref.mode_shape,
                                     {"long_name": COMPLEX_SHAPES["reference_mode_shape"]}),
            "reference_mode_shape_real": (("channel", "mode"), ref.mode_shape.real),
            "reference_mode_shape_imag": (("channel", "mode"), ref.mode_shape.imag),
            "reference_presence": (("mode",), ref.presence),
            "frequency_scatter": (("mode",), ref.frequency_scatter, {"units": "Hz"}),
            "damping_scatter": (("mode",), ref.damping_scatter, {"units": "1"}),
        })
    # nanoseconds: what a NetCDF or Zarr store gives back, so the dataset equals the store read again
    coords = {"record": [t.name for t in tasks], "time": (rec_dims, times.astype("datetime64[ns]")),
              "mode": np.arange(1, k_modes + 1), "channel": list(channels)}
    if test is not None:
        coords["term"] = ["constant"] + cov_names
    attrs = {"title": "modaluq monitoring: tracked modes", "modaluq_version": __version__,
             "false_alarm_rate": tracking.false_alarm_rate,
             "smoothing": tracking.smoothing, "tracking": json.dumps(tracking.to_dict()),
             "covariate_names": json.dumps(cov_names), "tracking_error": error}
    notes = _notes(tasks, done, in_ref, X, cov_names, tracking, miscalibrated)
    attrs["notes"] = json.dumps(notes)
    ds = xr.Dataset(data, coords=coords, attrs=attrs)
    ds["status"] = ds["status"].astype(str)
    ds["failed_stage"] = ds["failed_stage"].astype(str)
    ds["error"] = ds["error"].astype(str)
    ds["warnings"] = ds["warnings"].astype(str)

    rows = []
    for k, p in enumerate(parts):
        if not done[k]:
            continue
        pl = p["poles"]
        idx = tracked_of_pole.get(k, np.zeros(0, int))
        for r in range(len(pl["order"])):
            sm = int(pl["selected_mode"][r])
            tm = int(idx[sm - 1]) + 1 if sm - 1 < len(idx) else 0
            rows.append({"record": tasks[k].name, "time": times[k], "selected_mode": sm,
                         "tracked_mode": tm if tm > 0 else np.nan, "representative": bool(pl["representative"][r]),
                         "order": int(pl["order"][r]), "frequency_hz": pl["frequency_hz"][r],
                         "damping_ratio": pl["damping_ratio"][r], "frequency_std": pl["frequency_std"][r],
                         "damping_std": pl["damping_std"][r]})
    poles = pd.DataFrame(rows, columns=["record", "time", "selected_mode", "tracked_mode", "representative", "order",
                                        "frequency_hz", "damping_ratio", "frequency_std", "damping_std"])
    poles["tracked_mode"] = poles["tracked_mode"].astype("Int64")
    failures = pd.DataFrame([{"record": tasks[k].name, "source": p.get("source", tasks[k].name),
                              "stage": p.get("stage", ""), "error": p.get("error", "")}
                             for k, p in enumerate(parts) if not done[k]],
                            columns=["record", "source", "stage", "error"])
    return Monitoring(dataset=ds, poles=poles, failures=failures, reference=ref, tracking=tracking, notes=tuple(notes))


def _names(tasks, which, shown=3) -> str:
    k = np.flatnonzero(which)
    return ", ".join(tasks[i].name for i in k[:shown]) + (f" and {len(k) - shown} more" if len(k) > shown else "")


def _notes(tasks, done, in_ref, X, cov_names, tracking: TrackingSettings, miscalibrated) -> list:
    """What limits the run's tests, said rather than silent: records without a time among
    records with one, a reference period that takes every record, records without covariates,
    modes whose σ the reference period does not confirm."""
    notes = []
    if miscalibrated is not None:
        flagged, high = miscalibrated
        if flagged.any():
            modes = ", ".join(str(j + 1) for j in np.flatnonzero(flagged))
            then = ("their covariances were scaled up to it (inflate_to_reference)" if tracking.inflate_to_reference
                    else "their alarms are more frequent than the rate stated (inflate_to_reference, "
                         "--inflate-to-reference, scales their σ up to it)")
            notes.append(f"mode(s) {modes}: the reduced chi2 of the reference period is above {high:.2f}, its "
                         "99.9 % quantile: sigma is too small on this structure or a covariate (temperature ...) "
                         f"is missing; {then}")
    untimed = done & np.array([t.time is None for t in tasks])
    if untimed.any() and any(t.time is not None for t in tasks):
        notes.append(f"{int(untimed.sum())} of {int(done.sum())} identified records have no time "
                     f"({_names(tasks, untimed)}): they are placed after the records with a time, in the order given")
    if tracking.reference_span is None and done.any() and int(done.sum()) <= tracking.reference_records:
        notes.append(f"the reference period takes all {int(done.sum())} identified records (reference_records "
                     f"{tracking.reference_records}): no record after it is tested")
    if cov_names:
        lacking = done & ~np.all(np.isfinite(X), axis=1)
        if lacking.any():
            n_ref = int((lacking & in_ref).sum())
            ref_part = (f"; {n_ref} of the {int(in_ref.sum())} reference records {'is' if n_ref == 1 else 'are'} "
                        "left out of the fit" if n_ref else "")
            notes.append(f"{int(lacking.sum())} records have no value of a covariate ({', '.join(cov_names)}) "
                         f"({_names(tasks, lacking)}): they are tracked but not tested, no alarm is possible{ref_part}")
    return notes


def _write(result: Monitoring, paths: dict) -> tuple:
    ds = result.dataset.drop_vars(list(COMPLEX_SHAPES), errors="ignore")  # stored as real and imaginary parts
    store = paths["store"]
    tmp = store.with_name(f".{store.name}.{os.getpid()}.tmp")
    if paths["kind"] == "netcdf":
        ds.to_netcdf(tmp)
        os.replace(tmp, store)
    else:
        import shutil

        import zarr

        # Zarr format 2 (the only one of zarr < 3): its string arrays (record names, status) are
        # specified and readable by every Zarr library; zarr 3 warns that its own v3 strings are not
        fmt = {"zarr_format": 2} if int(zarr.__version__.split(".")[0]) >= 3 else {}
        ds.to_zarr(tmp, mode="w", consolidated=True, **fmt)
        if store.exists():
            shutil.rmtree(store)
        os.replace(tmp, store)
    if paths["poles"].suffix.lower() == ".parquet":
        result.poles.to_parquet(paths["poles"], index=False)
    else:
        result.poles.to_csv(paths["poles"], index=False)
    result.failures.to_csv(paths["failures"], index=False)
    return (str(store), str(paths["poles"]), str(paths["failures"]))


def load_tracks(path):
    """A monitoring store (.nc or .zarr) as an :class:`xarray.Dataset`, with the complex
    ``mode_shape`` and ``reference_mode_shape`` rebuilt from their real and imaginary parts."""
    require("xarray", "load_tracks")
    import xarray as xr

    path = Path(path)
    ds = xr.open_zarr(path) if path.suffix.lower() == ".zarr" else xr.open_dataset(path)
    ds = ds.load()
    ds.close()
    for name, long_name in COMPLEX_SHAPES.items():
        if f"{name}_real" in ds:
            ds[name] = ds[f"{name}_real"] + 1j * ds[f"{name}_imag"]
            ds[name].attrs["long_name"] = long_name
    if "alarm" in ds:
        ds["alarm"] = ds["alarm"].astype(bool)
    return ds
