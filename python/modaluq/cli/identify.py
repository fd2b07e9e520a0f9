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
from ..exchange import std_path_of
from ..io import SUPPORTED_EXTENSIONS
from ..spectrum import output_spectrum_singular_values
from ..version import __version__
from .common import CliError, check_image_paths, check_output_paths, integer_option, option_error, real_option
from .options import SETTINGS_OPTIONS, add_analysis_options, analysis_settings, stated_options

__all__ = ["parse_orders", "parse_read_options", "register", "run", "run_setups"]


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


#: --out extensions of Universal Files (modes as UFF 55 on the --geometry; docs/shapes.md §4)
UFF_EXTENSIONS = (".uff", ".unv")


def _check_outputs(args, has_geometry: bool = False, inputs=()):
    """Fail fast (before any computation) on an unsupported, unwritable or destructive output path.
    ``has_geometry``: a geometry comes from elsewhere than --geometry (a campaign file); ``inputs``:
    files read besides FILE or the campaign file (a campaign's setups), never overwritten."""
    for p in args.out or []:
        if Path(p).suffix.lower() in UFF_EXTENSIONS:
            if not (args.geometry or has_geometry):
                raise ValueError(f"--out {p}: a UFF file places the modes on a geometry: give --geometry")
            require("pyuff", f"--out {p}")
            continue
        kind = export.EXTENSIONS.get(Path(p).suffix.lower())
        if kind is None:
            raise ValueError(f"--out {p}: unsupported extension; use one of "
                             f"{', '.join((*export.EXTENSIONS, *UFF_EXTENSIONS))}")
        if kind == "netcdf":
            for module in ("xarray", "netCDF4"):
                require(module, f"--out {p}")
    if args.report:
        if Path(args.report).suffix.lower() not in (".html", ".htm"):
            raise ValueError(f"--report {args.report}: the report is an .html file")
        require("plotly", f"--report {args.report}")
    outputs = [("--out", p) for p in args.out or []]
    outputs += [("--out", str(std_path_of(p))) for p in args.out or [] if Path(p).suffix.lower() in UFF_EXTENSIONS]
    outputs += [("--report", args.report)] if args.report else []
    outputs += [(opt, p) for opt, p in (("--plot", args.plot), ("--plot-shapes", args.plot_shapes)) if p]
    for _, p in outputs:
        parent = Path(p).resolve().parent
        if not parent.is_dir():
            raise OSError(f"{p}: directory {parent} does not exist")
    sources = ([args.file] if args.file else [args.setups]) + list(inputs)
    check_output_paths(outputs, sources, overwrite=args.overwrite)
    check_image_paths((("--plot", args.plot), ("--plot-shapes", args.plot_shapes)))


def _progress(args, n_work_steps: int, path):
    """The progress display of a run (``n_work_steps`` before the outputs) and its ``step(text)``:
    shown on stderr only when it is a terminal (disable=None), cleared when done (leave=False)."""
    from tqdm.auto import tqdm  # on first use: importing it costs the command's start-up time

    n_steps = n_work_steps + bool(args.plot) + bool(args.plot_shapes) + len(args.out or []) + bool(args.report)
    progress = tqdm(total=n_steps, desc=f"loading {Path(path).name}", unit="step", file=sys.stderr,
                    leave=False, disable=True if args.no_progress else None,
                    bar_format="{desc}: {n}/{total} steps [{elapsed}]")

    def step(description: str) -> None:
        progress.set_description_str(description)
        progress.update()

    return progress, step


def run(args) -> int:
    """Execute ``modaluq identify`` for parsed ``args``; return the exit status."""
    t_start = time.perf_counter()
    if (args.file is None) == (args.setups is None):
        raise CliError("give a measurement FILE or --setups CAMPAIGN (a campaign file), not both or neither")
    if args.setups is not None:
        return run_setups(args, t_start)
    _check_outputs(args)
    geometry = None
    if args.geometry:
        from ..geometry import Geometry

        try:
            geometry = Geometry.from_file(args.geometry)
        except (OSError, ValueError) as exc:
            raise CliError(f"--geometry {args.geometry}: {exc}") from None
    settings, criteria, clustering = analysis_settings(args)
    if args.report:  # the report's AutoMAC gives the exact sigma, which needs the shapes' factors
        settings = settings.replace(keep_shape_factor=True)
    if args.orders is not None:
        _order_spec(args.orders)  # syntax, before the data are loaded; the bound needs them
    read_options = parse_read_options(args.read_option)
    options = set(vars(args))

    progress, step = _progress(args, 4, args.file)

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
        if geometry is not None:
            try:  # the record's channels against the geometry's, by name, before the identification
                geometry.channel_order(analysis.output_names)
            except ValueError as exc:
                raise CliError(f"--geometry {args.geometry}: {exc}") from None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # kept in analysis.warnings, printed below
                analysis.run(check_horizons=args.check_horizons, progress=step)
        except NumericalError as exc:
            raise CliError(f"numerical failure in the identification: {exc}") from None

        pre = analysis.preprocessed
        written = _write_outputs(
            args, analysis, geometry, step, background=lambda: {"y": pre.y},
            spectrum=lambda: output_spectrum_singular_values(pre.y, pre.fs, nperseg=args.nperseg),
            stamp=lambda: analysis.provenance(cli_arguments=stated_options(args, criteria, clustering)),
            title=f"modaluq identify {Path(args.file).name}")
    _print_run(analysis, args.file, written, t_start)
    return 0


def _write_outputs(args, analysis, geometry, step, *, background, spectrum, stamp, title) -> list:
    """The plots, --out files and --report of a run (an :class:`Analysis` or a
    :class:`CampaignAnalysis`: the same diagram and selected modes); the paths written.
    ``background()`` gives the diagram plot's spectrum keyword, ``spectrum()`` the report's."""
    written = []
    if args.plot:
        step("plotting the diagram")
        from ..plot import plot_stabilization_diagram  # matplotlib only when a plot is asked for

        fig = plot_stabilization_diagram(analysis.diagram, selected=analysis.selected, nperseg=args.nperseg,
                                         **background())
        fig.savefig(args.plot, dpi=args.dpi)
        written.append(args.plot)
    if args.plot_shapes and analysis.selected.n_modes:
        step("plotting the mode shapes")
        analysis.selected.plot().savefig(args.plot_shapes, dpi=args.dpi)
        written.append(args.plot_shapes)
    if args.out or args.report:
        stamp = stamp()
    for p in args.out or []:
        step(f"writing {Path(p).name}")
        try:
            if Path(p).suffix.lower() in UFF_EXTENSIONS:
                from ..exchange import write_uff

                written += [str(w) for w in write_uff(p, analysis.selected, geometry)]
                continue
            export.write(p, analysis.diagram, analysis.selected, stamp=stamp, extra=analysis.report(),
                         geometry=geometry)
        except ImportError as exc:
            raise CliError(f"--out {p}: {exc}") from None
        written.append(p)
    if args.report:
        step(f"writing {Path(args.report).name}")
        from ..htmlreport import write_html_report

        write_html_report(args.report, analysis.diagram, analysis.selected, geometry=geometry,
                          spectrum=spectrum(), title=title,
                          run_description=analysis.describe_run() + "\n\n" + analysis.describe_modes(),
                          warnings=analysis.warnings, stamp=stamp)
        written.append(args.report)
    return written


def _print_run(analysis, source, written, t_start) -> None:
    print(f"modaluq {__version__} identify: {source}")
    print(analysis.describe_run())
    for w in analysis.warnings:
        print(f"modaluq identify: warning: {w}", file=sys.stderr)
    print()
    print(analysis.describe_modes())
    for p in written:
        print(f"wrote {p}")
    print(f"({time.perf_counter() - t_start:.1f} s)")


#: Options of one record that a campaign file states per setup (or that do not apply to a merge).
NOT_WITH_SETUPS = (("outputs", "--outputs", "a campaign's outputs are every channel of its setups but the inputs"),
                   ("format", "--format", "give a setup's format in its [[setup]] entry"),
                   ("read_option", "--read-option", "give a setup's reader options in its [[setup]] entry"),
                   ("check_horizons", "--check-horizons", "the horizon check is for one record"),
                   ("bootstrap_draws", "--bootstrap-draws", "the bootstrap of sigma is for one record"))


def run_setups(args, t_start: float) -> int:
    """``modaluq identify --setups campaign.toml``: the campaign merged (identify_setups), then the
    same outputs as one record's."""
    from ..campaign_analysis import CampaignAnalysis
    from ..io import load_campaign

    for name, option, why in NOT_WITH_SETUPS:
        if getattr(args, name):
            raise CliError(f"{option} does not apply with --setups: {why}")
    settings, criteria, clustering = analysis_settings(args)  # checks the options, names them
    keywords = {name: getattr(settings, name) for name in SETTINGS_OPTIONS if getattr(args, name) is not None}
    if args.no_uncertainty:
        keywords["uncertainty"] = False
    if args.report:  # the report's AutoMAC gives the exact sigma, which needs the shapes' factors
        keywords["keep_shape_factor"] = True
    if args.orders is not None:
        keywords["orders"] = parse_orders(args.orders)
    options = set(vars(args))
    try:
        campaign = load_campaign(args.setups)
    except (ValueError, OSError) as exc:
        raise CliError(f"--setups {args.setups}: {exc}") from None
    _check_outputs(args, has_geometry=campaign.geometry is not None,
                   inputs=[rec.source for rec in campaign.setups if rec.source])
    geometry, geometry_path = None, args.geometry or campaign.geometry
    if geometry_path:
        from ..geometry import Geometry

        try:
            geometry = Geometry.from_file(geometry_path)
        except (OSError, ValueError) as exc:
            raise CliError(f"{'--geometry' if args.geometry else 'the campaign geometry'} {geometry_path}: {exc}") \
                from None
    try:
        analysis = CampaignAnalysis.from_campaign(campaign, fs=args.fs, references=args.references,
                                                  inputs=args.inputs, criteria=criteria, clustering=clustering,
                                                  **keywords)
    except ValueError as exc:  # the file's [settings] named as written there, the options as typed
        raise (exc if str(exc).startswith(campaign.source) else option_error(exc, options)) from None
    names = analysis.output_names
    if geometry is not None and len(set(names)) == len(names):  # (else the identification names the setup)
        try:  # every global DOF on the geometry, before the identification
            geometry.channel_order(names)
        except ValueError as exc:
            raise CliError(f"geometry {geometry_path}: {exc}") from None

    progress, step = _progress(args, 3, args.setups)

    with progress:
        try:
            analysis.run(progress=step, issue_warnings=False)
        except ValueError as exc:
            raise option_error(exc, options) from None
        except NumericalError as exc:
            raise CliError(f"numerical failure in the identification: {exc}") from None
        written = _write_outputs(
            args, analysis, geometry, step, background=lambda: {"spectrum": analysis.spectrum(args.nperseg)},
            spectrum=lambda: analysis.spectrum(args.nperseg),
            stamp=lambda: analysis.provenance(cli_arguments=stated_options(args, criteria, clustering)),
            title=f"modaluq identify --setups {Path(args.setups).name}")
    _print_run(analysis, args.setups, written, t_start)
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``identify`` subcommand to the ``modaluq`` command line."""
    p = subparsers.add_parser(
        "identify",
        help="identify modes with their uncertainty from a measurement file",
        description="Load a measurement file (or, with --setups, a campaign measured in several setups, "
                    "merged into global mode shapes), run covariance-driven SSI over a range of model "
                    "orders with the analytic standard deviation of every modal parameter, build "
                    "the stabilization diagram, select the physical modes automatically and print "
                    "them with their standard deviations. Errors are one line and exit status 2.",
        epilog="Channels are given by name or 0-based index (a name wins). Criteria are fractions: "
               "0.01 = 1 %%. Example: modaluq identify run1.csv --inputs force --orders 2:60:2 "
               "--plot diagram.png --out modes.json --out diagram.nc. A campaign in several setups: "
               "modaluq identify --setups campaign.toml --out modes.json (docs/multisetup.md); the options "
               "then replace the campaign file's references, inputs, fs, geometry and [settings].",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument("file", nargs="?", default=None,
                     help=f"measurement file ({' '.join(SUPPORTED_EXTENSIONS)}); or --setups")
    src.add_argument("--setups", metavar="CAMPAIGN", default=None,
                     help="a campaign file (TOML: references and one [[setup]] entry per setup with its file; "
                          "docs/multisetup.md) instead of FILE: the setups are merged into global mode shapes "
                          "with their sigma (modaluq.identify_setups) and written as for one record")
    add_analysis_options(p)
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
                   help="write a report; .json (modes, sigma, spread, provenance stamp), .csv (modes), "
                        ".nc (full diagram, NetCDF) or .uff (geometry and modes as UFF 15/82/55 on --geometry, "
                        "their std in NAME.std.uff); repeat for several")
    g.add_argument("--geometry", metavar="TOML", default=None,
                   help="the test geometry (nodes, lines, each channel's node and direction; docs/shapes.md): "
                        "the report animates the modes on it, --out modes.uff writes them as UFF 55, and .json/.nc "
                        "add every node's displacement with its sigma")
    g.add_argument("--report", metavar="HTML", default=None,
                   help="write one self-contained interactive HTML report (stabilization diagram with sigma, "
                        "modes, MAC with the sigma of each entry including the shapes' cross-covariance, the modes "
                        "animated on --geometry in 3-D); needs plotly")
    g.add_argument("--overwrite", action="store_true",
                   help="replace existing output files (the input file is never overwritten)")
    g.add_argument("--no-progress", action="store_true", help="no progress display on stderr")
    p.set_defaults(func=run)
    return p
