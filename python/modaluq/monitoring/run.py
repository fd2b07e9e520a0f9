"""The run: :func:`monitor` (records → tasks on an executor → parts → tracks, change test, store)
and its result, :class:`Monitoring` (docs/monitoring.md).

:func:`monitor` runs one task per record (:func:`~modaluq.monitoring.worker.process_record`) on an
executor (:mod:`~modaluq.monitoring.executors`), keeps every finished record in a part file as soon
as it arrives (:mod:`~modaluq.monitoring.parts`), then tracks the modes
(:mod:`~modaluq.monitoring.tracking`) and tests their changes (:mod:`~modaluq.monitoring.change`)
into one :class:`xarray.Dataset` written as NetCDF or Zarr, with a long table of the selected
modes' poles and a table of the failures beside it (:mod:`~modaluq.monitoring.store`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import json
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from .._blas import single_threaded
from ..checks import check_boolean, check_instance, check_real
from ..jsonvalues import dumps
from ..results import ModalUQWarning
from ..settings import ClusteringSettings, Settings, StabilityCriteria
from . import store
from .change import change_test, miscalibrated
from .executors import cancel_queued, executor_for
from .parts import Parts, record_modes, store_lock
from .records import covariate_matrix, record_tasks, record_times
from .tracking import ReferenceModes, TrackingSettings, after_reference, reference_period, track
from .worker import TaskConfig, process_record
from .worker import settle_seconds as _settle_seconds

__all__ = ["Monitoring", "monitor"]


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
        """The alarms as a table, one row per record and mode with an alarm of either test: record,
        time, mode, frequency_hz, frequency_change, damping_change (standardised), control (the
        statistic), sigma_confirmed (False: the mode's σ of f and ξ is not confirmed by the
        reference period, its alarms are more frequent than the rate stated), shape_p_value (the
        shape test against the reference mode), and which test raised it: frequency_damping_alarm
        (the change test of f and ξ, an EWMA), shape_alarm (the shape test, each record on its own).
        With nothing changed, each test raises alarms at ``false_alarm_rate`` per record and mode,
        so a row of either comes at up to twice that rate. Without the change test of f and ξ (its
        regression could not be made) its columns are NaN and only shape alarms are listed."""
        import pandas as pd

        columns = ["record", "time", "mode", "frequency_hz", "frequency_change", "damping_change", "control",
                   "sigma_confirmed", "shape_p_value", "frequency_damping_alarm", "shape_alarm"]
        ds = self.dataset
        if ds.sizes["mode"] == 0:
            return pd.DataFrame(columns=columns)
        n_rec, n_mode = ds.sizes["record"], ds.sizes["mode"]
        k, j = (a.ravel() for a in np.indices((n_rec, n_mode)))  # rows: record-major, as the arrays below

        def per_record_and_mode(name, fill=np.nan):
            values = ds[name].transpose("record", "mode").values if name in ds else np.full((n_rec, n_mode), fill)
            return values.ravel()

        shape_p, shape_alarm = _shape_test_of(ds)
        confirmed = ds["sigma_confirmed"].values.astype(bool) if "sigma_confirmed" in ds else None
        df = pd.DataFrame({
            "record": ds["record"].values[k], "time": ds["time"].values[k], "mode": ds["mode"].values[j],
            **{name: per_record_and_mode(name) for name in ("frequency_hz", "frequency_change", "damping_change",
                                                            "control")},
            "sigma_confirmed": pd.array(confirmed[j] if confirmed is not None else [pd.NA] * len(j), dtype="boolean"),
            "shape_p_value": shape_p.ravel(),
            "frequency_damping_alarm": per_record_and_mode("alarm", False).astype(bool),
            "shape_alarm": shape_alarm.ravel()})
        return df[df["frequency_damping_alarm"] | df["shape_alarm"]].reset_index(drop=True)[columns]

    def plot_frequencies(self, **kwargs):
        """Tracked frequencies against time with ±σ bands and the alarms marked (a Figure)."""
        from .plot import plot_tracked_frequencies  # matplotlib only when a plot is asked for

        return plot_tracked_frequencies(self.dataset, **kwargs)

    def plot_control_chart(self, **kwargs):
        """The control statistic of every tracked mode against its alarm limit (a Figure)."""
        from .plot import plot_control_chart

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
            lines.append(" mode  f_ref [Hz]  found  shape alarms / tested")
            shape_counts = _shape_alarm_counts(ds)
            for j in range(ds.sizes["mode"]):
                found = int(np.isfinite(ds["frequency_hz"].values[:, j]).sum())
                lines.append(f" {j + 1:4d}  {ds['reference_frequency_hz'].values[j]:10.4f}  {found:5d}  "
                             f"{shape_counts[j]}")
            return "\n".join(lines)
        limits = ds["control_limit"].values if "control_limit" in ds else np.zeros(0)
        shown = f"{np.nanmedian(limits):.2f}" if np.isfinite(limits).any() else "none"
        lines.append(f"reference: {int(ref.sum())} records; alarms at a false-alarm rate of "
                     f"{self.tracking.false_alarm_rate:g} per record and mode (median limit {shown}, "
                     f"EWMA weight {self.tracking.smoothing:g})")
        lines.append(" mode  f_ref [Hz]  xi_ref [%]  found   reduced chi2 (f, xi)   f, xi alarms / tested   "
                     "shape alarms / tested")
        after = ~ref & (ds["status"].values == "done")
        flagged, high = miscalibrated(ds["reference_reduced_chi2_frequency"].values,
                                      ds["reference_reduced_chi2_damping"].values, int(ref.sum()),
                                      ds.sizes.get("term", 1))
        shape_counts = _shape_alarm_counts(ds)
        for j in range(ds.sizes["mode"]):
            found = np.isfinite(ds["frequency_hz"].values[:, j])
            tested = after & np.isfinite(ds["control"].values[:, j])
            n_alarm = int(ds["alarm"].values[after, j].sum())
            red = (ds["reference_reduced_chi2_frequency"].values[j], ds["reference_reduced_chi2_damping"].values[j])
            flag = " !" if flagged[j] else ""
            lines.append(f" {j + 1:4d}  {ds['reference_frequency_hz'].values[j]:10.4f}  "
                         f"{100 * ds['reference_damping_ratio'].values[j]:10.3f}  {int(found.sum()):5d}   "
                         f"{red[0]:9.2f} {red[1]:9.2f}{flag:2s}  {n_alarm:5d} of {int(tested.sum()):<14d}"
                         f"{shape_counts[j]:>8s}")
        if flagged.any():
            lines.append(f" !: reduced chi2 above {high:.2f}, its 99.9 % quantile (see the note)")
        return "\n".join(lines)


def _shape_test_of(ds) -> tuple:
    """(shape_p_value, shape_alarm), each (record, mode), of a store; a store written before the
    shape test has neither: p-values unknown, no alarm."""
    if "shape_p_value" not in ds:
        shape = (ds.sizes["record"], ds.sizes["mode"])
        return np.full(shape, np.nan), np.zeros(shape, bool)
    return (ds["shape_p_value"].transpose("record", "mode").values,
            ds["shape_alarm"].transpose("record", "mode").values.astype(bool))


def _shape_alarm_counts(ds) -> list:
    """Per mode ``"a of t"``: its shape alarms among the records after the reference period with a
    shape test; ``"-"`` for a store written before the shape test."""
    if "shape_p_value" not in ds:
        return ["-"] * ds.sizes["mode"]
    p, alarm = _shape_test_of(ds)
    after = after_reference(ds["in_reference"].values)
    return [f"{int(alarm[after, j].sum())} of {int(np.isfinite(p[after, j]).sum())}" for j in range(p.shape[1])]


def monitor(records, *, out=None, settings: Settings | None = None, criteria: StabilityCriteria | None = None,
            clustering: ClusteringSettings | None = None, tracking: TrackingSettings | None = None,
            covariates=None, fs: float | None = None, format: str | None = None, read_options: dict | None = None,
            outputs=None, inputs=None, references=None, check_harmonics: bool = False, executor=None,
            threads: int | None = None, workers: int | None = None, scheduler: str | None = None, resume: bool = True,
            poles=None, progress: bool | None = None, settle_seconds: float | None = None) -> Monitoring:
    """Identify every record, track the modes, test their changes (docs/monitoring.md).

    Parameters
    ----------
    records : paths, folders, glob patterns, or record objects (one, or a list)
        A record object has ``load()`` returning something with ``y``, ``fs`` (and optionally
        ``u``, ``output_names``), or has those itself; its ``name``, ``time``, ``covariates``
        (a dict) and ``output_names`` are used when present
        (:class:`~modaluq.monitoring.simulator.SimulatedRecord`). Records are taken by time
        where it is known (from the object, the covariate table, or the file name:
        ``..._2026-03-01_12-00-00.csv``); records without a time come after them in the order
        given (a note says so), a folder's files by name.
    out : path, optional
        ``.nc`` (NetCDF) or ``.zarr`` store of the tracks; beside it ``<stem>.failures.csv``, the
        pole table ``<stem>.poles.csv`` (or ``poles=``, ``.csv`` or ``.parquet``) and the part
        files ``<stem>.parts/`` that make a run restartable (a ``.nc`` and a ``.zarr`` store of
        one stem share them). Without ``out`` nothing is written and nothing is resumed. One run
        at a time: the run holds ``<stem>.lock``; another run on the store is refused
        (:class:`~modaluq.monitoring.parts.StoreInUseError`, naming it).
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
        Skip the records whose part file says they are done with these settings about the
        file's bytes as they are now (failed ones, files changed since, are run again). False:
        start again, the part files of earlier runs (whatever their settings) are removed first.
        A file modified less than :data:`~modaluq.monitoring.worker.SETTLE_SECONDS` ago, or
        while it was read, is still being written: left out (a note says so) for the next run.
    progress : bool, optional
        A progress bar on stderr (default: when stderr is a terminal).
    settle_seconds : float, optional
        A file modified less than this many seconds before it is read is still being written
        (default :data:`~modaluq.monitoring.worker.SETTLE_SECONDS`, 5 s, or the environment variable
        ``MODALUQ_SETTLE_SECONDS``). 0 for files known to be complete (e.g. just written by a script).

    Returns
    -------
    Monitoring
        Its :attr:`~Monitoring.notes` (also issued as :class:`ModalUQWarning`) say what limits the
        tests: records without a time or a covariate value, a reference period that takes every
        record, modes whose σ the reference period does not confirm.
    """
    t0 = time.perf_counter()
    resume = check_boolean("resume", resume)
    tracking = check_instance("tracking", tracking, TrackingSettings)
    config = TaskConfig(settings=check_instance("settings", settings, Settings),
                        criteria=check_instance("criteria", criteria, StabilityCriteria),
                        clustering=check_instance("clustering", clustering, ClusteringSettings),
                        check_harmonics=check_boolean("check_harmonics", check_harmonics),
                        read={k: v for k, v in dict(fs=fs, format=format, read_options=read_options, outputs=outputs,
                                                    inputs=inputs, references=references).items() if v is not None})
    settle = _settle_seconds() if settle_seconds is None else check_real("settle_seconds", settle_seconds, low=0)
    config = dataclasses.replace(config, settle_seconds=settle)
    out_paths = store.output_paths(out, poles)
    if out_paths:  # a store a killed writer left half swapped is put back; dead writers' temporaries removed
        store.recover(out_paths)
    tasks = record_tasks(records, covariates)
    with store_lock(out_paths["store"]) if out_paths else contextlib.nullcontext():  # one run at a time
        return _run(tasks, config, out_paths, tracking, executor, threads, workers, scheduler, resume, progress, t0)


def _run(tasks, config, out_paths, tracking, executor, threads, workers, scheduler, resume, progress, t0):
    """:func:`monitor` once its arguments are checked (and its store locked)."""
    parts = Parts(out_paths["parts"], config, start_again=not resume) if out_paths else None

    results = {}
    if parts is not None and resume:
        settings_id = config.fingerprint_id()
        for task in tasks:
            part = parts.done(task, settings_id)  # None: not done, other settings, or its file changed
            if part is not None:
                results[task.key] = part
    todo = [t for t in tasks if t.key not in results]
    n_run = len(todo)
    if todo:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="records", unit="record",
                   file=sys.stderr, disable=None if progress is None else not progress, smoothing=0.05)
        # the records' warnings are caught per task (analysis.warnings); on the thread pool these
        # catches interleave and could leave the caller's filters changed: restore them after the run
        with bar, warnings.catch_warnings(), executor_for(executor, threads, workers, scheduler) as (pool, remote), \
                (contextlib.nullcontext() if remote else single_threaded()), contextlib.ExitStack() as stack:
            cfg = dataclasses.replace(config, worker_process=remote)
            futures = {pool.submit(process_record, task, cfg): task for task in todo}
            n_failed = 0
            stack.callback(cancel_queued, futures)  # Ctrl-C or a failed write: the queued records are not run
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
                text = dumps(part)
                part = json.loads(text)  # the same values whether read back from a part or not
                if parts is not None:
                    parts.write(part["key"], text)
                results[task.key] = part
                n_failed += part["status"] != "done"
                bar.set_postfix_str(f"{n_failed} failed", refresh=False)
                bar.update()
    # a file still being written is not a record yet: left out of the store, read by the next run
    writing = [t for t in tasks if results[t.key]["status"] == "writing"]
    tasks = [t for t in tasks if results[t.key]["status"] != "writing"]
    if not tasks:  # nothing to track: the store is not written
        raise ValueError(f"records: every record file is still being written ({_names(writing, [True] * len(writing))}"
                         f": modified less than {config.settle_seconds:g} s ago or while being read); run again later")
    ordered = [results[t.key] for t in tasks]
    result = _consolidate(tasks, ordered, tracking, first_notes=_file_notes(tasks, writing, config.settle_seconds))
    result.n_run = n_run - len(writing)
    if out_paths:
        result.written = store.write(result, out_paths)
    result.seconds = time.perf_counter() - t0
    for note in result.notes:
        warnings.warn(note, ModalUQWarning, stacklevel=3)  # the caller of monitor
    return result


def _file_notes(tasks: list, writing: list, settle: float) -> list:
    """Notes on the files: records reached through several links (taken once), files still being
    written (``writing``: their tasks, modified less than ``settle`` seconds ago or while read; left
    for the next run)."""
    notes = [f"records: {', '.join(Path(a).name for a in t.aliases)} "
             f"{'is' if len(t.aliases) == 1 else 'are'} the same file as {t.name} (symbolic links): taken once, "
             f"as {t.name}" for t in tasks if t.aliases]
    if writing:
        notes.append(f"{len(writing)} record file(s) still being written, left for the next run "
                     f"({_names(writing, np.ones(len(writing), bool))}): modified less than {settle:g} s "
                     "ago or while being read")
    return notes


def _consolidate(tasks: list, parts: list, tracking: TrackingSettings, first_notes=()) -> Monitoring:
    """The records' parts (in the tasks' order) → tracks, change test, store tables and notes
    (``first_notes``: the files' notes, before the tests')."""
    done = np.array([p["status"] == "done" for p in parts])
    channels = next((tuple(p["output_names"]) for p in parts if p["status"] == "done"), ())
    for k, p in enumerate(parts):  # a record with other channels cannot be tracked with the rest
        if done[k] and tuple(p["output_names"]) != channels:
            parts[k] = dict(p, status="failed", stage="track",
                            error=f"channels {p['output_names']} differ from the first record's {list(channels)}")
            done[k] = False
    times = record_times(tasks)
    cov_names, X = covariate_matrix(tasks)
    modes = [record_modes(p) if done[k] else None for k, p in enumerate(parts)]
    tracks = track(modes, reference_period(done, times, tracking), len(channels), tracking)
    in_ref, error = tracks.in_reference, tracks.error
    # the covariance of a record's [f, ξ] is a sample covariance over its blocks: n_blocks - 1 dof
    dof = np.array([p.get("n_blocks", 0) - 1 if done[k] and p.get("n_blocks", 0) > 1 else np.inf
                    for k, p in enumerate(parts)], float)
    test = None
    if tracks.reference is not None:
        try:
            test = change_test(tracks.frequency_hz, tracks.damping_ratio, tracks.covariance(), in_ref,
                               X if cov_names else None, tracking, dof=dof)
        except ValueError as exc:  # the records stay identified and tracked; only the test is missing
            error = f"no change test: {exc}"
    flagged = None  # (modes whose σ the reference does not confirm, the quantile)
    if test is not None:
        flagged = miscalibrated(test.reference_reduced_chi2_frequency, test.reference_reduced_chi2_damping,
                                int(in_ref.sum()), 1 + len(cov_names))
    notes = list(first_notes) + _notes(tasks, done, in_ref, X, cov_names, tracking, flagged)
    ds = store.dataset(tasks, parts, done, tracks, test, channels=channels, times=times, covariate_names=cov_names,
                       covariates=X, miscalibrated=flagged, tracking=tracking, error=error, notes=notes)
    return Monitoring(dataset=ds, poles=store.pole_table(tasks, parts, done, times, tracks),
                      failures=store.failure_table(tasks, parts, done), reference=tracks.reference,
                      tracking=tracking, notes=tuple(notes))


def _names(tasks, which, shown=3) -> str:
    k = np.flatnonzero(which)
    return ", ".join(tasks[i].name for i in k[:shown]) + (f" and {len(k) - shown} more" if len(k) > shown else "")


def _notes(tasks, done, in_ref, X, cov_names, tracking: TrackingSettings, flagged) -> list:
    """What limits the run's tests, said rather than silent: records without a time among
    records with one, a reference period that takes every record, records without covariates,
    modes whose σ the reference period does not confirm (``flagged``: :func:`miscalibrated`'s)."""
    notes = []
    if flagged is not None:
        mask, high = flagged
        if mask.any():
            modes = ", ".join(str(j + 1) for j in np.flatnonzero(mask))
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
