"""``modaluq identify``: from a measurement file to selected modes with their uncertainty.

Loads a file (any format of :mod:`modaluq.io`), runs SSI-cov over a range of model orders,
builds the stabilization diagram, selects the physical modes automatically, prints them with
their standard deviations and optionally writes a diagram plot and JSON/CSV/NetCDF reports.

Registered in :mod:`modaluq.cli` by :func:`register`.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

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


def _resolve_channels(tokens, names, option: str) -> list:
    """Channel names or 0-based indices (as strings) -> indices into ``names`` (a name wins)."""
    n = len(names)
    out = []
    for t in tokens:
        hits = [k for k, nm in enumerate(names) if nm == t]
        if len(hits) > 1:
            raise ValueError(f"{option}: channel name {t!r} is ambiguous (channels {hits}); give its index")
        if hits:
            out.append(hits[0])
            continue
        try:
            k = int(t)
        except ValueError:
            shown = ", ".join(repr(s) for s in names[:20]) + (", ..." if n > 20 else "")
            raise ValueError(f"{option}: channel {t!r} not found; channels are: {shown}") from None
        if not -n <= k < n:
            raise ValueError(f"{option}: channel index {k} is out of range for {n} channels")
        out.append(k % n)
    if len(set(out)) != len(out):
        raise ValueError(f"{option}: the same channel is given more than once: {' '.join(tokens)}")
    return out


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
    from .cli import check_output_paths
    from .export import EXTENSIONS, require

    for p in args.out or []:
        kind = EXTENSIONS.get(Path(p).suffix.lower())
        if kind is None:
            raise ValueError(f"--out {p}: unsupported extension; use one of {', '.join(EXTENSIONS)}")
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
            try:
                from matplotlib.backend_bases import FigureCanvasBase
            except ImportError:
                raise ValueError(f"{opt} needs matplotlib (pip install matplotlib)") from None
            ext = Path(p).suffix.lower().lstrip(".")
            if ext not in FigureCanvasBase.get_supported_filetypes():
                raise ValueError(f"{opt} {p}: unsupported image type {ext or '(none)'!r}; use e.g. .png, .pdf, .svg")


def _largest_order(block_rows, past_block_rows, n_samples, n_outputs, n_references):
    """The largest model order min((p-1) l, q r) and how it comes about (for messages)."""
    p, q = block_rows, past_block_rows or block_rows
    if p + q > n_samples:  # checked here so that no bound derived from absurd horizons is used
        raise ValueError(f"--block-rows {p} with --past-block-rows {q}: p + q = {p + q} exceeds the "
                         f"{n_samples} samples of the record")
    top = min((p - 1) * n_outputs, q * n_references)
    return top, (f" = min((p-1)·l, q·r) = min({p - 1}·{n_outputs}, {q}·{n_references}) for --block-rows {p}, "
                 f"--past-block-rows {q}, {n_outputs} outputs and {n_references} references")


def _describe_orders(orders) -> str:
    if len(orders) > 2:
        steps = set(np.diff(orders).tolist())
        if len(steps) == 1:
            return f"{orders[0]}..{orders[-1]} step {steps.pop()} ({len(orders)} orders)"
    return ", ".join(map(str, orders))


def run(args) -> int:
    """Execute ``modaluq identify`` for parsed ``args``; return the exit status."""
    from tqdm.auto import tqdm

    from . import __version__, export
    from ._core import NumericalError
    from .cli import _CliError
    from .auto_settings import choose_settings
    from .identification import identify
    from .io import load
    from .harmonics import harmonic_kurtosis, possible_harmonics
    from .horizons import check_horizons
    from .preprocess import preprocess
    from .stabilization import (ClusteringSettings, PoleStatus, StabilityCriteria, select_modes,
                                 stabilization_diagram)

    t_start = time.perf_counter()
    _check_outputs(args)
    try:
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
    except ValueError as exc:  # "min_mac must be ..." -> "--min-mac must be ..."
        param, _, rest = str(exc).partition(" ")
        raise ValueError(f"--{param.replace('_', '-')} {rest}") from None
    if args.orders is not None:
        _order_spec(args.orders)  # syntax, before the data are loaded; the bound needs them
    read_options = parse_read_options(args.read_option)

    n_steps = 4 + bool(args.plot) + bool(args.plot_shapes) + len(args.out or [])
    # shown on stderr only when it is a terminal (disable=None), cleared when done (leave=False)
    progress = tqdm(total=n_steps, desc=f"loading {Path(args.file).name}", unit="step", file=sys.stderr,
                    leave=False, disable=True if args.no_progress else None,
                    bar_format="{desc}: {n}/{total} steps [{elapsed}]")
    caught = []
    with progress:
        # ------------------------------------------------------------------ load
        try:
            rec = load(args.file, fs=args.fs, format=args.format, **read_options)
        except ImportError as exc:
            raise _CliError(str(exc)) from None
        names = list(rec.output_names) + list(rec.input_names)
        data = rec.y if rec.u is None else np.hstack([rec.y, rec.u])
        file_inputs = list(range(rec.n_outputs, rec.n_outputs + rec.n_inputs))
        out_idx = _resolve_channels(args.outputs, names, "--outputs") if args.outputs else None
        if args.inputs:
            in_idx = _resolve_channels(args.inputs, names, "--inputs")
        else:  # inputs the file declares itself (e.g. 'u' of an .npz), unless listed as outputs
            in_idx = [k for k in file_inputs if out_idx is None or k not in out_idx]
        if out_idx is None:
            out_idx = [k for k in range(len(names)) if k not in set(in_idx)]
        both = sorted(set(in_idx) & set(out_idx))
        if both:
            raise ValueError(f"--outputs and --inputs both select channel {names[both[0]]!r}")
        if not out_idx:
            raise ValueError("no output channel left: --inputs selects every channel")
        y = np.ascontiguousarray(data[:, out_idx])
        u = np.ascontiguousarray(data[:, in_idx]) if in_idx else None
        out_names = [names[k] for k in out_idx]
        in_names = [names[k] for k in in_idx]
        refs = _resolve_channels(args.references, out_names, "--references") if args.references else None
        # window, band, decimation: the identification and the spectrum use the processed samples
        pre = preprocess(y, u, fs=rec.fs, frequency_range=args.frequency_range, start=args.start, stop=args.stop,
                         decimate=args.decimate, detrend=args.detrend, highpass=args.highpass)
        y, u = pre.y, pre.u
        block_rows = args.block_rows
        if block_rows is None:  # chosen from the data (docs/settings.md)
            block_rows = choose_settings(pre.n_samples, pre.fs, len(out_idx), frequency_range=pre.frequency_range,
                                         n_references=len(refs) if refs else None, orders=(2,),
                                         n_blocks=2).block_rows
        largest, bound = _largest_order(block_rows, args.past_block_rows, pre.n_samples, len(out_idx),
                                        len(refs) if refs else len(out_idx))
        orders = None if args.orders is None else parse_orders(args.orders, largest, bound=bound)
        progress.update()

        # ------------------------------------------------------------------ identify
        progress.set_description_str("identifying")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                # block_rows None: identify chooses the same value from the same samples, and
                # records why (a chosen value is not warned about as if the user had set it)
                result = identify(y, u, fs=pre.fs, block_rows=args.block_rows,
                                  past_block_rows=args.past_block_rows, orders=orders,
                                  n_blocks=args.n_blocks, references=refs,
                                  uncertainty=not args.no_uncertainty, frequency_range=pre.frequency_range,
                                  decimate=1)
            except NumericalError as exc:
                raise _CliError(f"numerical failure in the identification: {exc}") from None
        # what was done to the file's samples (identify saw them already processed)
        result.settings["preprocessing"] = pre.settings()
        if result.settings["block_rows"] != block_rows:  # the same rule on the same samples
            raise RuntimeError(f"block_rows chosen twice differently: {block_rows} and "
                               f"{result.settings['block_rows']}")
        progress.update()

        progress.set_description_str("stabilization diagram")
        diagram = stabilization_diagram(result, criteria, output_names=out_names)
        progress.update()
        progress.set_description_str("clustering")
        selected = select_modes(diagram, clustering)
        # rotating machinery: kurtosis of the response filtered around each mode (harmonics.py)
        kurt = harmonic_kurtosis(y, pre.fs, selected.frequency_hz) if selected.n_modes else np.zeros(0)
        harmonic = (possible_harmonics(y, pre.fs, selected.frequency_hz, selected.damping_ratio)
                    if selected.n_modes else np.zeros(0, bool))
        progress.update()
        horizons = None
        if args.check_horizons and selected.n_modes:
            # the same record at 0.75, 1 and 1.5 times the horizon: a bias from the horizon
            # does not show in σ, but in how the estimate moves (horizons.py)
            progress.set_description_str("settings check")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                horizons = check_horizons(y, u, fs=pre.fs, frequency_range=pre.frequency_range,
                                          block_rows=result.settings["block_rows"],
                                          past_block_rows=args.past_block_rows, n_blocks=args.n_blocks,
                                          references=refs, uncertainty=not args.no_uncertainty, decimate=1,
                                          criteria=criteria, settings=clustering,
                                          progress=progress.set_description_str)

        # ------------------------------------------------------------------ plots
        written = []
        if args.plot or args.plot_shapes:
            # pyplot-free figures: no GUI backend is touched, nothing stays registered
            from matplotlib.figure import Figure
        if args.plot:
            progress.set_description_str("plotting the diagram")
            fig = Figure(figsize=(9.0, 6.0), layout="constrained")
            diagram.plot(ax=fig.add_subplot(), y=y, selected=selected, nperseg=args.nperseg)
            fig.savefig(args.plot, dpi=args.dpi)
            written.append(args.plot)
            progress.update()
        if args.plot_shapes and selected.n_modes:
            progress.set_description_str("plotting the mode shapes")
            fig = selected.plot()  # sized by the plot module (horizontal bars for many channels)
            fig.savefig(args.plot_shapes, dpi=args.dpi)
            written.append(args.plot_shapes)
            progress.update()
        elif args.plot_shapes:
            progress.update()

        # ------------------------------------------------------------------ reports
        if args.out:
            stamp = export.provenance(args.file, settings={
                "identification": result.settings, "stability": criteria.to_dict(),
                "clustering": clustering.to_dict(),
                "channels": {"outputs": out_names, "inputs": in_names,
                             "references": [out_names[k] for k in refs] if refs else out_names},
                "cli_arguments": {k: v for k, v in vars(args).items() if k not in ("func", "command")},
            })
            extra = {"input": {"n_samples": rec.n_samples, "fs_hz": rec.fs, "outputs": out_names,
                               "inputs": in_names, "source": rec.source},
                     "warnings": [str(w.message) for w in caught],
                     "possible_harmonics": [{"mode": k + 1, "frequency_hz": float(selected.frequency_hz[k]),
                                             "kurtosis": float(kurt[k])} for k in np.flatnonzero(harmonic)]}
            if horizons is not None:
                extra["horizon_check"] = {
                    "block_rows": list(horizons.block_rows),
                    "modes": [{"mode": i + 1,
                               "frequency_hz": [None if not np.isfinite(v) else float(v) for v in horizons.frequency_hz[i]],
                               "damping_ratio": [None if not np.isfinite(v) else float(v)
                                                 for v in horizons.damping_ratio[i]],
                               "frequency_spread": (None if not np.isfinite(horizons.frequency_spread[i])
                                                    else float(horizons.frequency_spread[i]))}
                              for i in range(selected.n_modes)]}
            for p in args.out:
                progress.set_description_str(f"writing {Path(p).name}")
                try:
                    export.write(p, diagram, selected, stamp=stamp, extra=extra)
                except ImportError as exc:
                    raise _CliError(f"--out {p}: {exc}") from None
                written.append(p)
                progress.update()

    # ---------------------------------------------------------------------- summary
    kind = "input/output" if in_names else "output-only"
    print(f"modaluq {__version__} identify: {args.file}")
    print(f"  {rec.n_samples} samples at {rec.fs:g} Hz ({rec.n_samples / rec.fs:g} s), {kind}; "
          f"outputs: {', '.join(out_names)}" + (f"; inputs: {', '.join(in_names)}" if in_names else ""))
    s = result.settings
    for step in s.get("preprocessing", {}).get("steps", []):
        print(f"  {step}")
    for why in s.get("chosen", []):
        print(f"  chosen: {why}")
    print(f"  block_rows={s['block_rows']}, past_block_rows={s['past_block_rows']}, "
          f"orders {_describe_orders(list(result.orders))}, "
          + (f"{result.n_blocks} blocks of {result.block_length} columns" if result.n_blocks else "no uncertainty"))
    counts = ", ".join(f"{st.value.replace('_', ' ')} {diagram.count(st)}" for st in PoleStatus)
    print(f"  stabilization diagram: {diagram.n_poles} poles ({counts})")
    if result.n_blocks:
        coupled = diagram.noise_coupled
        stable = np.array([st is PoleStatus.STABLE for st in diagram.status], dtype=bool)
        print(f"  noise floor: {result.significant_singular_values} significant singular values of H (an estimate "
              f"of the model order); {int(coupled.sum())} pole(s) noise-coupled, {int((coupled & stable).sum())} "
              f"of them stable (spurious or mixed with a spurious pole: no first-order std)")
    close = diagram.close_singular_value_orders
    if close:
        print(f"  orders cutting close singular values (their std less reliable): {_describe_orders(list(close))}")
    for w in caught:
        print(f"modaluq identify: warning: {w.message}", file=sys.stderr)
    print()
    if selected.n_modes:
        print(selected)
        for k in np.flatnonzero(harmonic):
            print(f"mode {k + 1} ({selected.frequency_hz[k]:.4g} Hz, xi {100 * selected.damping_ratio[k]:.2g} %) may be "
                  f"a harmonic of the excitation, not a structural mode: its filtered response has kurtosis "
                  f"{kurt[k]:.2f} (a sinusoid 1.5, a random mode 3; docs/settings.md)")
    else:
        print("no mode selected: no cluster of stable poles both reached "
              f"{selected.min_cluster_size} poles and had a frequency std within its bandwidth "
              "(try more orders, a longer record, a narrower band or looser criteria)")
    if horizons is not None:
        print()
        print(horizons)
    # the largest dropped clusters, with why: what a person checks against the diagram
    dropped = sorted(zip(selected.dropped_n_poles, selected.dropped_frequency_hz, selected.dropped_reason),
                     key=lambda t: (-t[0], t[1]))
    shown = [d for d in dropped if d[0] >= max(3, selected.min_cluster_size // 2) or "bandwidth" in d[2]][:8]
    if shown:
        print(f"dropped clusters ({len(dropped)} in all; the largest):")
        for n, f, why in sorted(shown, key=lambda t: t[1]):
            print(f"  {f:.4g} Hz: {why}")
    for p in written:
        print(f"wrote {p}")
    print(f"({time.perf_counter() - t_start:.1f} s)")
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``identify`` subcommand to the ``modaluq`` command line."""
    from .cli import integer_option, real_option

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
