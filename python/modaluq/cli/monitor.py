"""``modaluq monitor``: many records → tracked modes with σ, change statistics and alarms.

Option translation over :func:`modaluq.monitoring.monitor`; the preprocessing, identification and
selection options are those of ``modaluq identify``. Failures are listed on stderr (and in
``<stem>.failures.csv``); the exit status is 2 when no record could be identified. The monitoring
wing is imported when the command runs, not when the command line is built.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings

from ..version import __version__
from .common import CliError, check_image_paths, integer_option, option_error, real_option
from .identify import parse_orders, parse_read_options
from .options import add_analysis_options, analysis_settings

__all__ = ["register", "run"]

#: Failures printed on stderr one per line; beyond, their count (the table has them all).
SHOWN_FAILURES = 20

#: Tracking options (None when not given) -> the TrackingSettings field they set.
TRACKING_OPTIONS = {"reference_records": "reference_records", "false_alarm_rate": "false_alarm_rate",
                    "smoothing": "smoothing", "tracking_min_mac": "min_mac"}


class _TrackingDefaults(argparse.HelpFormatter):
    """Help that shows the tracking defaults of :class:`~modaluq.monitoring.TrackingSettings`
    (``{tracking.smoothing}`` in a help text), importing the wing only when help is printed."""

    def _get_help_string(self, action):
        text = super()._get_help_string(action)
        if text and "{tracking." in text:
            from ..monitoring import TrackingSettings

            text = text.format(tracking=TrackingSettings())
        return text


def run(args) -> int:
    """Execute ``modaluq monitor`` for parsed ``args``; return the exit status."""
    from ..monitoring import TrackingSettings, monitor  # the wing: only for this command
    from ..monitoring.parts import StoreInUseError

    options = set(vars(args))
    settings, criteria, clustering = analysis_settings(args)
    try:
        if args.orders is not None:
            settings = settings.replace(orders=parse_orders(args.orders))
        given = {field: getattr(args, option) for option, field in TRACKING_OPTIONS.items()
                 if getattr(args, option) is not None}  # the rest: TrackingSettings' defaults
        if args.reference_span:
            given["reference_span"] = tuple(args.reference_span)
        if args.inflate_to_reference:
            given["inflate_to_reference"] = True
        tracking = TrackingSettings(**given)
    except (TypeError, ValueError) as exc:
        raise option_error(exc, options) from None
    check_image_paths((("--plot", args.plot), ("--plot-control-chart", args.plot_control_chart)))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = monitor(args.paths, out=args.out, settings=settings, criteria=criteria, clustering=clustering,
                             tracking=tracking, covariates=args.covariates, fs=args.fs, format=args.format,
                             read_options=parse_read_options(args.read_option), outputs=args.outputs,
                             inputs=args.inputs, references=args.references,
                             check_harmonics=args.check_harmonics, threads=args.threads,
                             workers=args.workers, scheduler=args.scheduler, resume=not args.no_resume,
                             settle_seconds=args.settle_seconds,
                             poles=args.poles, progress=False if args.no_progress else None)
    except StoreInUseError as exc:  # another run on --out: it is named, nothing was touched
        raise CliError(f"{exc} (--out)") from None
    except ValueError as exc:
        raise option_error(exc, options) from None

    # every file first: a reader that stops reading the summary (| head) must not cost a plot
    written = list(result.written)
    if args.plot and result.reference is not None:
        result.plot_frequencies().savefig(args.plot, dpi=args.dpi)
        written.append(args.plot)
    if args.plot_control_chart and result.reference is not None:
        result.plot_control_chart().savefig(args.plot_control_chart, dpi=args.dpi)
        written.append(args.plot_control_chart)

    print(f"modaluq {__version__} monitor: {result.n_records} records")
    print(result.summary(notes=False))
    failures = result.failures
    for row in failures.head(SHOWN_FAILURES).itertuples():
        print(f"modaluq monitor: failed: {row.source} ({row.stage}): {row.error}", file=sys.stderr)
    if len(failures) > SHOWN_FAILURES:
        print(f"modaluq monitor: ... and {len(failures) - SHOWN_FAILURES} more failures (see the failures table)",
              file=sys.stderr)
    if len(failures):
        stages = failures["stage"].value_counts()
        print(f"modaluq monitor: {len(failures)} of {result.n_records} records failed ("
              + ", ".join(f"{n} at {stage}" for stage, n in stages.items()) + ")", file=sys.stderr)
    warned = [w for w in result.dataset["warnings"].values if w]
    if warned:
        print(f"modaluq monitor: {len(warned)} of {result.n_records} records have identification warnings (the "
              f"store's 'warnings' variable); the first: {warned[0].splitlines()[0]}", file=sys.stderr)
    alarms = result.alarms()
    if len(alarms):
        n = len(alarms)
        print(f"\n{n} alarm{'s' if n != 1 else ''} (record, mode, frequency, standardised changes of f and xi and "
              "their control statistic, the shape test's p-value; which test raised it):")

        def number(x, fmt):  # a value the store lacks (no change test of f and xi) as "-"
            return format(x, fmt) if math.isfinite(x) else "-"

        for row in alarms.head(30).itertuples():
            which = " and ".join(w for w, on in (("f, xi", row.frequency_damping_alarm), ("shape", row.shape_alarm))
                                 if on)
            print(f"  {row.record}  mode {row.mode}  {row.frequency_hz:.4f} Hz  "
                  f"z_f {number(row.frequency_change, '+.1f')}  z_xi {number(row.damping_change, '+.1f')}  "
                  f"{number(row.control, '.1f')}  p_shape {number(row.shape_p_value, '.2g')}  {which}")
        if len(alarms) > 30:
            print(f"  ... {len(alarms) - 30} more (the store's alarm and shape_alarm variables have them all)")
    for p in written:
        print(f"wrote {p}")
    if result.n_failed == result.n_records:
        raise CliError(f"no record could be identified ({result.n_failed} failed; the first: "
                       f"{failures.iloc[0]['source']}: {failures.iloc[0]['error']})")
    for note in result.notes:
        print(f"modaluq monitor: warning: {note}", file=sys.stderr)
    if result.reference is None:
        print(f"modaluq monitor: warning: no tracking: {result.dataset.attrs['tracking_error']}", file=sys.stderr)
    elif result.dataset.attrs.get("tracking_error"):
        print(f"modaluq monitor: warning: {result.dataset.attrs['tracking_error']}", file=sys.stderr)
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``monitor`` subcommand to the ``modaluq`` command line."""
    p = subparsers.add_parser(
        "monitor", formatter_class=_TrackingDefaults,
        help="identify many records, track the modes and test their changes",
        description="Identify every record (files, folders or glob patterns) with the same settings, track the "
                    "modes from record to record against a reference period with a sigma-aware assignment, and "
                    "test each mode's frequency and damping, and its shape, for a change at a stated false-alarm rate. "
                    "Results go to a NetCDF/Zarr store, with a table of the poles and one of the failures beside it; a "
                    "re-run skips the records already done. Exit status 2 when no record could be identified.",
        epilog="Example: modaluq monitor data/*.csv --out tracks.nc --reference-records 48 --covariates temps.csv "
               "--frequency-range 0.5 20 --workers 4  (docs/monitoring.md)",
    )
    p.add_argument("paths", nargs="+", metavar="PATH", help="record files, folders of them, or glob patterns")
    p.add_argument("--out", required=True, metavar="STORE",
                   help="the tracks: .nc (NetCDF) or .zarr; beside it STEM.poles.csv, STEM.failures.csv and the "
                        "part files STEM.parts/")
    add_analysis_options(p)
    g = p.add_argument_group("tracking and change test")
    g.add_argument("--reference-records", type=integer_option(3), default=None, metavar="K",
                   help="the first K identified records are the reference period "
                        "(default {tracking.reference_records})")
    g.add_argument("--reference-span", nargs=2, metavar=("START", "END"), default=None,
                   help="the records between these times (ISO 8601) are the reference period instead")
    g.add_argument("--covariates", metavar="CSV", default=None,
                   help="table with a 'record' column (file names), optionally 'time', and numeric columns "
                        "(temperature ...) the frequencies and damping ratios are regressed on")
    g.add_argument("--false-alarm-rate", type=real_option(0, 0.5), default=None, metavar="P",
                   help="probability of an alarm at a record and mode when nothing changed "
                        "(default {tracking.false_alarm_rate:g})")
    g.add_argument("--smoothing", type=real_option(0, 1), default=None, metavar="LAMBDA",
                   help="EWMA weight of the newest record in the control statistic (default {tracking.smoothing:g}; "
                        "1: each record tested on its own)")
    g.add_argument("--tracking-min-mac", type=real_option(0, 1, low_open=False), default=None, metavar="MAC",
                   help="smallest MAC between a record's mode and a reference mode (default {tracking.min_mac:g})")
    g.add_argument("--check-harmonics", action="store_true",
                   help="flag modes that may be harmonics of the excitation (costs about one more identification)")
    g.add_argument("--inflate-to-reference", action="store_true",
                   help="scale each mode's sigma up to its reduced chi2 in the reference period when that is above 1")
    g = p.add_argument_group("execution")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--threads", type=integer_option(1), default=None, metavar="N",
                   help="records at a time in this process (default: the cores)")
    x.add_argument("--workers", type=integer_option(1), default=None, metavar="N",
                   help="start a Dask LocalCluster of N one-thread worker processes (TLS with throw-away "
                        "certificates on 127.0.0.1, no HTTP server; docs/monitoring.md)")
    x.add_argument("--scheduler", default=None, metavar="ADDR", help="a running Dask scheduler, e.g. tcp://host:8786")
    g.add_argument("--settle-seconds", type=real_option(0, low_open=False), default=None, metavar="S",
                   help="a file modified less than S seconds before it is read is still being written: left "
                        "for the next run (default 5, or MODALUQ_SETTLE_SECONDS; 0 for files known complete)")
    g.add_argument("--no-resume", action="store_true",
                   help="start again: remove the part files of earlier runs (any settings) and run every record")
    g = p.add_argument_group("output")
    g.add_argument("--poles", metavar="PATH", default=None,
                   help="the table of every pole of the selected modes (.csv or .parquet; default STEM.poles.csv)")
    g.add_argument("--plot", metavar="IMAGE", default=None,
                   help="write the tracked frequencies with their sigma bands and alarms")
    g.add_argument("--plot-control-chart", metavar="IMAGE", default=None, help="write the control chart")
    g.add_argument("--dpi", type=real_option(0, 1200), default=120, help="resolution of raster images (default 120)")
    g.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run)
    return p
