"""One record → one part: load, preprocess, identify, select (the :class:`~modaluq.Analysis` of
``modaluq identify`` with the same settings objects), in a worker thread or process.

:func:`process_record` never raises: a record's failure is kept with the stage it failed at
(``load``, ``preprocess``, ``identify``, ``select``) and its error, and the batch goes on. What it
returns is plain values (docs/monitoring.md §1), sent back to the driver, which keeps it as the
record's part (:mod:`modaluq.monitoring.parts`).

A file's part says which bytes it was made from (``file``: size, mtime in ns, SHA-256) and with
which settings (``settings``: :meth:`TaskConfig.fingerprint_id`). A file modified less than
:data:`SETTLE_SECONDS` ago, or whose size or mtime changed while it was read, is "still being
written": its status is ``writing``, nothing is identified from it, and the next run reads it again.
"""

from __future__ import annotations

import hashlib
import os
import time
import traceback
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..analysis import Analysis
from ..jsonvalues import dumps, jsonable
from ..settings import ClusteringSettings, Settings, StabilityCriteria
from ..version import __version__
from .executors import configure_worker_process
from .records import RecordTask, file_sha256, file_state

__all__ = ["SETTLE_SECONDS", "TaskConfig", "process_record", "settle_seconds"]

#: A file modified less than this many seconds ago is taken to be still being written (an
#: acquisition appending to it, a copy under way) and left for the next run. The environment
#: variable ``MODALUQ_SETTLE_SECONDS`` overrides it (the tests set 0 for files they just wrote).
SETTLE_SECONDS = 5.0


def settle_seconds() -> float:
    """:data:`SETTLE_SECONDS`, or ``MODALUQ_SETTLE_SECONDS`` when set (a number >= 0)."""
    text = os.environ.get("MODALUQ_SETTLE_SECONDS")
    if text is None:
        return SETTLE_SECONDS
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value >= 0:
        raise ValueError(f"MODALUQ_SETTLE_SECONDS must be a number of seconds >= 0; got {text!r}")
    return value


#: Settings added after monitoring stores were made, with the value that gives the behaviour from
#: before them: a part's fingerprint leaves them out at that value (``--no-order-discrepancy``
#: with ``--no-drop-noise-twins`` resumes a store made before 2026-11-27, ``--no-reassign-borrowed-poles``
#: one made before 2026-11-28, ``--no-unanchored-sigma`` one made before 2026-12-07; docs/monitoring.md).
ADDED_SETTINGS = {"clustering": {"order_discrepancy": False, "drop_noise_twins": False,
                                 "reassign_borrowed_poles": False, "unanchored_noise_coupling": None}}


@dataclass(frozen=True)
class TaskConfig:
    """The settings every record is run with (the part files remember them)."""

    settings: Settings = field(default_factory=Settings)
    criteria: StabilityCriteria = field(default_factory=StabilityCriteria)
    clustering: ClusteringSettings = field(default_factory=ClusteringSettings)
    read: dict = field(default_factory=dict)  #: fs, format, read_options, outputs, inputs, references
    check_harmonics: bool = False             #: flag modes that may be harmonics (costs about an identification)
    worker_process: bool = False              #: the task runs in a worker process (Dask, process pools)
    settle_seconds: float = SETTLE_SECONDS    #: a file modified more recently is still being written

    def fingerprint(self) -> dict:
        """The settings that make a part (not where or how fast it runs). A setting added after
        stores were made is left out at the value that gives the behaviour before it
        (:data:`ADDED_SETTINGS`), so that those stores resume with it."""
        clustering = self.clustering.to_dict()
        for key, before in ADDED_SETTINGS["clustering"].items():
            if clustering.get(key) == before:
                del clustering[key]
        return {"modaluq": __version__, "settings": self.settings.to_dict(), "criteria": self.criteria.to_dict(),
                "clustering": clustering, "read": jsonable(self.read), "check_harmonics": self.check_harmonics}

    def fingerprint_id(self) -> str:
        """A short hash of :meth:`fingerprint`, kept in every part: a part made with other settings is not used."""
        return hashlib.sha256(dumps(self.fingerprint()).encode()).hexdigest()[:20]


def process_record(task: RecordTask, config: TaskConfig) -> dict:
    """Run one record; never raises. Returns plain values: the status, the stage that failed and
    its error, or the selected modes and their poles."""
    t0 = time.perf_counter()
    stage = "load"
    out = {"key": task.key, "name": task.name, "status": "failed", "stage": "", "error": "", "warnings": [],
           "settings": config.fingerprint_id()}
    try:
        if config.worker_process:
            configure_worker_process()
        if isinstance(task.source, str):
            before = _settled_state(task.source, config.settle_seconds)
            if isinstance(before, str):
                out.update(status="writing", error=before, seconds=time.perf_counter() - t0)
                return out
            digest = file_sha256(task.source) if before is not None else None
        analysis = _analysis(task, config)
        if isinstance(task.source, str) and before is not None:
            after = file_state(task.source)
            if after != before:  # appended to, or replaced, while it was read: not these bytes
                out.update(status="writing", error=f"{task.source} changed while it was read (size, mtime "
                                                   f"{before[0]}, {before[1]} ns -> {_shown(after)})",
                           seconds=time.perf_counter() - t0)
                return out
            out["file"] = {"size": before[0], "mtime_ns": before[1], "sha256": digest}
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


def _settled_state(path: str, settle: float):
    """``(size, mtime_ns)`` of a file that can be read as it is; why not (text) when it was modified
    less than ``settle`` seconds ago (or has a time in the future, beyond that); None when it
    cannot be read (the loader says why). A dangling symbolic link is an ``OSError`` naming it."""
    if os.path.islink(path) and not os.path.exists(path):
        raise FileNotFoundError(f"{path} is a dangling symbolic link (to {os.readlink(path)}, which does not exist)")
    state = file_state(path)
    if state is None:
        return None
    age = time.time() - state[1] / 1e9
    if abs(age) < settle:
        return f"{path} was modified {age:.1f} s ago (less than {settle:g} s)"
    return state


def _shown(state) -> str:
    return "gone" if state is None else f"{state[0]}, {state[1]} ns"


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
    """The selected modes (with the f-ξ correlation of each representative pole, the core's) and their poles."""
    sel, d, res = analysis.selected, analysis.diagram, analysis.result
    m = sel.n_modes
    members = [np.asarray(mem, np.int64) for mem in sel.members]
    pole_mode = np.concatenate([np.full(len(mem), i + 1) for i, mem in enumerate(members)]) if m else np.zeros(0, int)
    pole_index = np.concatenate(members) if m else np.zeros(0, np.int64)
    return {
        "output_names": list(analysis.output_names), "fs_hz": float(analysis.fs), "n_blocks": int(res.n_blocks),
        "n_samples": int(analysis.y.shape[0]),
        "modes": {
            "frequency_hz": sel.frequency_hz, "damping_ratio": sel.damping_ratio,
            "frequency_std": sel.frequency_std, "damping_std": sel.damping_std,
            "frequency_damping_correlation": sel.frequency_damping_correlation, "mode_shape": sel.mode_shape,
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
