"""``modaluq identify``: from a measurement file to selected modes with their uncertainty.

Loads a file (any format of :mod:`modaluq.io`), runs the :class:`~modaluq.analysis.Analysis`
(SSI-cov over a range of model orders, stabilization diagram, automatic selection), prints the
modes with their standard deviations and optionally writes a diagram plot and JSON/CSV/NetCDF
reports. This module only translates options into settings and results into files and text.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

from .. import export
from .._core import NumericalError
from ..analysis import Analysis
from ..checks import require
from ..plot import plot_stabilization_diagram
from ..settings import ClusteringSettings, Settings, StabilityCriteria
from ..version import __version__
from .common import CliError, check_output_paths, integer_option, option_error, real_option

__all__ = ["parse_orders", "parse_read_options", "register", "run"]


#: Largest --dpi: a 9 x 6 inch diagram is then 10800 x 7200 pixels.
MAX_DPI = 1200


#: Largest order :func:`parse_orders` expands when the data are not known: a model of this order
#: needs a Hankel matrix of more than 10⁵ × 10⁵ entries (80 GB), beyond any machine.
MAX_ORDER = 100_000


def _order_spec(text: str):
    """``--orders`` as ``(orders, largest)``, a range not expanded, so that nothing is built
    before the largest order is checked. Raises ``ValueError`` naming ``--orders``."""
    if not isinstance(text, str):
        raise TypeError(f"--orders must be a string; got {type(text).__name__}")
    spec = text.strip()

    def integer(s, what="orders"):
        try:
            value = int(s.strip())
        except ValueError:
            raise ValueError(f"--orders {text!r}: {s.strip()!r} is not an integer "
                             "(use a:b:step, a:b, n or a comma list)") from None
        if value < 1:
            raise ValueError(f"--orders {text!r}: {what} must be >= 1; got {value}")
        return value

    if not spec:
        raise ValueError("--orders must not be empty (use a:b:step, a:b, n or a comma list)")
    if "," in spec:
        orders = [integer(s) for s in spec.split(",") if s.strip()]
        if not orders:
            raise ValueError(f"--orders {text!r} gives no order")
        return orders, max(orders)
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) not in (2, 3):
            raise ValueError(f"--orders {text!r}: expected a:b or a:b:step")
        a, b = integer(parts[0]), integer(parts[1])
        step = integer(parts[2], "step") if len(parts) == 3 else 1
        if b < a:
            raise ValueError(f"--orders {text!r}: the last order {b} is below the first {a}")
        orders = range(a, b + 1, step)
        return orders, orders[-1]
    order = integer(spec)
    return [order], order


def parse_orders(text: str, max_order: int | None = None, *, bound: str = "") -> list:
    """Parse a model-order specification into a sorted list of distinct positive integers.

    ``"a:b:s"`` is ``a, a+s, ...`` up to and **including** ``b``; ``"a:b"`` uses step 1;
    ``"n"`` is one order; ``"4,8,12"`` is a list. ``max_order`` is the largest order the
    settings and the data allow (default :data:`MAX_ORDER`); a larger one is refused before a
    range is expanded, with ``bound`` (e.g. ``" = min((p-1) l, q r)"``) after the limit in the
    message. Raises ``ValueError`` naming ``--orders``.

    Examples
    --------
    >>> parse_orders("2:10:2")
    [2, 4, 6, 8, 10]
    >>> parse_orders("12")
    [12]
    >>> parse_orders("4, 8,12")
    [4, 8, 12]
    """
    orders, largest = _order_spec(text)
    limit = MAX_ORDER if max_order is None else max_order
    if largest > limit:
        raise ValueError(f"--orders {text!r}: order {largest} is above the largest possible, {limit}{bound}")
    return sorted(set(orders))


def parse_read_options(items) -> dict:
    """``["dataset=/daq/acc", "transpose=true"]`` -> keyword arguments of the file reader.

    A value is read as JSON when it parses (numbers, ``true``/``false``, ``null``, lists such as
    ``[0,2]``), otherwise kept as a string.
    """
    import json

    out = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise ValueError(f"--read-option {item!r}: expected KEY=VALUE, e.g. dataset=/daq/acc")
        try:
            out[key] = json.loads(value)
        except ValueError:
            out[key] = value
    return out


def _check_outputs(args):
    """Fail fast (before any computation) on an unsupported, unwritable or destructive output path."""
    for p in args.out or []:
        kind = export.EXTENSIONS.get(Path(p).suffix.lower())
        if kind is None:
            raise ValueError(f"--out {p}: unsupported extension; use one of {', '.join(export.EXTENSIONS)}")
        if kind == "netcdf":
            for module in ("xarray", "netCDF4"):
                require(module, f"--out {p}")
    outputs = [("--out", p) for p in args.out or []]
    outputs += [(opt, p) for opt, p in (("--plot", args.plot), ("--plot-shapes", args.plot_shapes)) if p]
    for _, p in outputs:
        parent = Path(p).resolve().parent
        if not parent.is_dir():
            raise OSError(f"{p}: directory {parent} does not exist")
    check_output_paths(outputs, [args.file], overwrite=args.overwrite)
    for opt, p in (("--plot", args.plot), ("--plot-shapes", args.plot_shapes)):
        if p:
            from matplotlib.backend_bases import FigureCanvasBase
            ext = Path(p).suffix.lower().lstrip(".")
            if ext not in FigureCanvasBase.get_supported_filetypes():
                raise ValueError(f"{opt} {p}: unsupported image type {ext or '(none)'!r}; use e.g. .png, .pdf, .svg")


def _settings(args) -> tuple:
    """The options as the library's settings objects, an error naming the option."""
    options = set(vars(args))  # every option, by its parameter name
    try:
        settings = Settings(block_rows=args.block_rows, past_block_rows=args.past_block_rows, n_blocks=args.n_blocks,
                            uncertainty=not args.no_uncertainty, frequency_range=args.frequency_range,
                            start=args.start, stop=args.stop, decimate=args.decimate, detrend=args.detrend,
                            highpass=args.highpass)
        criteria = StabilityCriteria(
            max_frequency_change=args.max_frequency_change, max_damping_change=args.max_damping_change,
            min_mac=args.min_mac,
            frequency_std_factor=None if args.frequency_std_factor == 0 else args.frequency_std_factor,
            max_frequency_cov=None if args.max_frequency_cov == 0 else args.max_frequency_cov,
            max_damping_ratio=args.max_damping_ratio,
            damping_std_factor=None if args.damping_std_factor == 0 else args.damping_std_factor,
            match_window=args.match_window)
        clustering = ClusteringSettings(distance_threshold=args.distance_threshold,
                                        min_cluster_size=args.min_cluster_size)
    except (TypeError, ValueError) as exc:  # "min_mac must be ..." -> "--min-mac must be ..."
        raise option_error(exc, options) from None
    return settings, criteria, clustering


def run(args) -> int:
    """Execute ``modaluq identify`` for parsed ``args``; return the exit status."""
    from tqdm.auto import tqdm

    t_start = time.perf_counter()
    _check_outputs(args)
    settings, criteria, clustering = _settings(args)
    if args.orders is not None:
        _order_spec(args.orders)  # syntax, before the data are loaded; the bound needs them
    read_options = parse_read_options(args.read_option)
    options = set(vars(args))

    n_steps = 4 + bool(args.plot) + bool(args.plot_shapes) + len(args.out or [])
    # shown on stderr only when it is a terminal (disable=None), cleared when done (leave=False)
    progress = tqdm(total=n_steps, desc=f"loading {Path(args.file).name}", unit="step", file=sys.stderr,
                    leave=False, disable=True if args.no_progress else None,
                    bar_format="{desc}: {n}/{total} steps [{elapsed}]")

    def step(description: str) -> None:
        progress.set_description_str(description)
        progress.update()

    written = []
    with progress:
        try:
            analysis = Analysis.from_file(args.file, fs=args.fs, format=args.format, read_options=read_options,
                                          outputs=args.outputs, inputs=args.inputs, references=args.references,
                                          settings=settings, criteria=criteria, clustering=clustering)
            largest, why = analysis.largest_order()  # also refuses horizons longer than the record, by name
            if args.orders is not None:
                analysis = analysis.with_settings(orders=parse_orders(args.orders, largest, bound=why))
        except ValueError as exc:
            raise option_error(exc, options) from None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # kept in analysis.warnings, printed below
                analysis.run(check_horizons=args.check_horizons, progress=step)
        except NumericalError as exc:
            raise CliError(f"numerical failure in the identification: {exc}") from None

        if args.plot:
            step("plotting the diagram")
            fig = plot_stabilization_diagram(analysis.diagram, y=analysis.preprocessed.y, selected=analysis.selected,
                                             nperseg=args.nperseg)
            fig.savefig(args.plot, dpi=args.dpi)
            written.append(args.plot)
        if args.plot_shapes and analysis.selected.n_modes:
            step("plotting the mode shapes")
            analysis.selected.plot().savefig(args.plot_shapes, dpi=args.dpi)
            written.append(args.plot_shapes)
        if args.out:
            stamp = analysis.provenance(
                cli_arguments={k: v for k, v in vars(args).items() if k not in ("func", "command")})
            for p in args.out:
                step(f"writing {Path(p).name}")
                try:
                    export.write(p, analysis.diagram, analysis.selected, stamp=stamp, extra=analysis.report())
                except ImportError as exc:
                    raise CliError(f"--out {p}: {exc}") from None
                written.append(p)

    print(f"modaluq {__version__} identify: {args.file}")
    print(analysis.describe_run())
    for w in analysis.warnings:
        print(f"modaluq identify: warning: {w}", file=sys.stderr)
    print()
    print(analysis.describe_modes())
    for p in written:
        print(f"wrote {p}")
    print(f"({time.perf_counter() - t_start:.1f} s)")
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``identify`` subcommand to the ``modaluq`` command line."""
    p = subparsers.add_parser(
        "identify",
        help="identify modes with their uncertainty from a measurement file",
        description="Load a measurement file, run covariance-driven SSI over a range of model "
                    "orders with the analytic standard deviation of every modal parameter, build "
                    "the stabilization diagram, select the physical modes automatically and print "
                    "them with their standard deviations. Errors are one line and exit status 2.",
        epilog="Channels are given by name or 0-based index (a name wins). Criteria are fractions: "
               "0.01 = 1 %%. Example: modaluq identify run1.csv --inputs force --orders 2:60:2 "
               "--plot diagram.png --out modes.json --out diagram.nc",
    )
    p.add_argument("file", help="measurement file (.csv .tsv .txt .npy .npz .mat .h5 .uff .unv .tdms)")
    g = p.add_argument_group("data")
    g.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="sampling frequency in Hz (default: from the file, e.g. its time column)")
    g.add_argument("--format", default=None, choices=["csv", "numpy", "matlab", "hdf5", "uff", "tdms"],
                   help="file format (default: from the extension)")
    g.add_argument("--read-option", action="append", metavar="KEY=VALUE", default=None,
                   help="option of the file reader, e.g. dataset=/daq/acc (HDF5), variable=acc (MATLAB), "
                        "group=run1 (TDMS), time_column=clock (CSV); repeat for several")
    g.add_argument("--inputs", nargs="+", metavar="CH", default=None,
                   help="known-input channels (default: none, i.e. output-only, unless the file declares inputs)")
    g.add_argument("--outputs", nargs="+", metavar="CH", default=None,
                   help="output channels (default: every channel that is not an input)")
    g = p.add_argument_group("preprocessing (applied to outputs and inputs alike)")
    g.add_argument("--frequency-range", nargs=2, type=real_option(0, low_open=False), default=None,
                   metavar=("LO", "HI"), help="band of interest in Hz: decimation to about 3 x HI, the settings, "
                                              "the diagram and the plot follow it")
    g.add_argument("--start", type=real_option(0, low_open=False), default=None, metavar="S",
                   help="start of the time window, s from the first sample")
    g.add_argument("--stop", type=real_option(0), default=None, metavar="S", help="end of the time window, s")
    g.add_argument("--decimate", type=integer_option(1), default=None, metavar="Q",
                   help="integer decimation factor (default: from --frequency-range, else none)")
    g.add_argument("--detrend", choices=["constant", "linear"], default=None, help="detrend every channel")
    g.add_argument("--highpass", type=real_option(0), default=None, metavar="HZ",
                   help="corner of a zero-phase 4th-order Butterworth high-pass, Hz")
    g = p.add_argument_group("identification")
    g.add_argument("--block-rows", type=integer_option(2), default=None, metavar="P",
                   help="future block rows p (default: chosen from fs, the band and the record, "
                        "docs/settings.md); the largest order is (p-1) x n_outputs")
    g.add_argument("--past-block-rows", type=integer_option(1), default=None, metavar="Q",
                   help="past block rows q (default p)")
    g.add_argument("--orders", default=None, metavar="SPEC",
                   help="model orders: a:b:step (b included), a:b, n or a comma list "
                        "(default 2:M:2, M = min(100, (p-1) n_outputs, q n_references))")
    g.add_argument("--n-blocks", type=integer_option(2), default=None, metavar="NB",
                   help="blocks for the covariance of the uncertainty (default: blocks of half the decay "
                        "time of a 1 %%-damped mode at the band's lowest frequency, 10-50; docs/settings.md)")
    g.add_argument("--references", nargs="+", metavar="CH", default=None,
                   help="reference outputs of the past data matrix (default: all outputs)")
    g.add_argument("--no-uncertainty", action="store_true",
                   help="skip the uncertainty (the sigma criteria are then not applied)")
    g = p.add_argument_group("stabilization and mode selection")
    g.add_argument("--max-frequency-change", type=float, default=0.01, metavar="FRAC",
                   help="largest relative frequency change between orders (default 0.01)")
    g.add_argument("--max-damping-change", type=float, default=0.10, metavar="FRAC",
                   help="largest relative damping change between orders, with --damping-std-factor 0 or "
                        "without uncertainty (default 0.10)")
    g.add_argument("--min-mac", type=float, default=0.98, help="smallest MAC between orders (default 0.98)")
    g.add_argument("--damping-std-factor", type=float, default=2.0, metavar="K",
                   help="judge a damping change between orders against K x its combined std (default 2; "
                        "0: the relative test --max-damping-change)")
    g.add_argument("--match-window", type=float, default=0.05, metavar="FRAC",
                   help="a pole is compared only with poles of the previous order within this relative "
                        "frequency distance (default 0.05)")
    g.add_argument("--frequency-std-factor", type=float, default=2.0, metavar="K",
                   help="|df| <= K sqrt(std1^2 + std2^2) between orders (default 2; 0 switches it off)")
    g.add_argument("--max-frequency-cov", type=float, default=0.05, metavar="FRAC",
                   help="reject poles with std_f / f above this (default 0.05; 0 switches it off)")
    g.add_argument("--max-damping-ratio", type=float, default=0.20, metavar="FRAC",
                   help="reject poles with a damping ratio above this (default 0.20)")
    g.add_argument("--distance-threshold", type=float, default=0.02,
                   help="clustering cut on |df|/f + (1 - MAC) (default 0.02)")
    g.add_argument("--min-cluster-size", type=integer_option(1), default=None, metavar="N",
                   help="poles a mode needs (default: a quarter of the orders, at least 3)")
    g = p.add_argument_group("output")
    g.add_argument("--plot", metavar="IMAGE", default=None,
                   help="write the stabilization diagram over the output spectrum (.png, .pdf, .svg ...)")
    g.add_argument("--plot-shapes", metavar="IMAGE", default=None, help="write the selected mode shapes with ±1σ")
    g.add_argument("--check-horizons", action="store_true",
                   help="also select at 0.75 and 1.5 times block_rows and print each mode's spread across "
                        "the horizons beside its std (a bias from the horizon does not show in the std)")
    g.add_argument("--nperseg", type=integer_option(8), default=None, metavar="N",
                   help="Welch segment length of the diagram's spectrum, samples after decimation "
                        "(default: the spectrum function's)")
    g.add_argument("--dpi", type=real_option(0, MAX_DPI), default=120,
                   help=f"resolution of raster images (default 120, at most {MAX_DPI})")
    g.add_argument("--out", action="append", metavar="PATH", default=None,
                   help="write a report; .json (modes, sigma, spread, provenance stamp), .csv (modes) "
                        "or .nc (full diagram, NetCDF); repeat for several")
    g.add_argument("--overwrite", action="store_true",
                   help="replace existing output files (the input file is never overwritten)")
    g.add_argument("--no-progress", action="store_true", help="no progress display on stderr")
    p.set_defaults(func=run)
    return p
