"""``modaluq validate``: the paper's Monte Carlo study from the command line, or, with
``--split-halves FILE``, the check of σ on a measured record (its two halves identified alike,
:func:`modaluq.validation.split_halves`; report on stdout, ``--out DIR`` adds ``report.md`` and
``pairs.csv``).

Prints the Markdown report on stdout,
the progress bar on stderr and, with ``--out DIR``, writes ``report.md``, ``results.csv``
(one row per record, method and mode), ``summary.csv`` (one row per method and mode),
``results.npz`` (everything, readable with ``MonteCarloResult.load``) and the histograms
``histograms_std.png`` and ``histograms_estimates.png``.  With several ``--order`` values, all
orders are identified from the same records; the report holds one section per order and the
other files carry the order in their name (``results_n24.csv``, ...).
"""

from __future__ import annotations

import inspect
import sys
from pathlib import Path

from ..checks import MAX_THREADS
from ..io import FORMATS
from ..validation import monte_carlo, split_halves, split_halves_windows
from .common import (
    CliError,
    check_output_paths,
    integer_option,
    option_error,
    pairs_output,
    real_option,
    write_pairs_report,
)

__all__ = ["register", "run"]

#: What ``monte_carlo`` does for an option not given (it is not passed), shown in ``--help``.
DEFAULTS = {name: p.default for name, p in inspect.signature(monte_carlo).parameters.items()}

#: Options (None when not given) -> the keyword of ``monte_carlo`` they set.
KEYWORDS = {"records": "n_records", "samples": "n_samples", "order": "order", "block_rows": "block_rows",
            "past_block_rows": "past_block_rows", "n_blocks": "n_blocks", "seed": "seed", "processes": "processes",
            "tolerance": "match_tolerance", "unknown_input_std": "unknown_input_std",
            "damping_ratio": "damping_ratio", "n_dof": "n_dof", "input_dofs": "input_dofs",
            "output_dofs": "output_dofs", "noise_coupling_limit": "noise_coupling_limit",
            "bootstrap_draws": "bootstrap_draws"}

#: Files written into ``--out``.
OUTPUT_FILES = ("report.md", "results.csv", "summary.csv", "results.npz", "histograms_std.png",
                "histograms_estimates.png")


def _file_names(orders) -> list:
    """OUTPUT_FILES, with the order in every name but report.md when there are several."""
    if len(orders) == 1:
        return list(OUTPUT_FILES)
    names = ["report.md"]
    for n in orders:
        names += [name.replace(".", f"_n{n}.", 1) for name in OUTPUT_FILES[1:]]
    return names


#: Options of the simulation only (refused with --split-halves) and of the record only (refused without).
SIMULATION_ONLY = ("records", "samples", "unknown_input_std", "damping_ratio", "n_dof", "input_dofs", "output_dofs",
                   "seed", "processes", "noise_coupling_limit")
RECORD_ONLY = ("fs", "format", "read_option", "inputs", "outputs", "frequency_range", "start", "stop",
               "representative", "shape_representative", "pair_within_std", "windows")


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def run_split_halves(args) -> int:
    """``modaluq validate --split-halves FILE``: the measured-record check of σ."""
    from ..analysis import Analysis
    from ..settings import ClusteringSettings, Settings
    from .identify import parse_read_options

    bad = [_option(k) for k in SIMULATION_ONLY if getattr(args, k) is not None] + (
        ["--no-freeze-noise"] if args.no_freeze_noise else [])
    if bad:
        raise CliError(f"{', '.join(bad)}: option(s) of the simulation, not of --split-halves")
    out = pairs_output(args.out, args.overwrite)
    options = set(vars(args))
    try:
        names = ("frequency_range", "start", "stop", "block_rows", "past_block_rows", "n_blocks", "bootstrap_draws")
        given = {k: getattr(args, k) for k in names if getattr(args, k) is not None}
        if args.block_correlation_correction:
            given["block_correlation_correction"] = True
        settings = Settings(**given, **({"orders": args.order} if args.order is not None else {}))
        clustering = ClusteringSettings(**{k: getattr(args, k) for k in ("representative", "shape_representative")
                                           if getattr(args, k) is not None},
                                        **({"order_discrepancy": False} if args.no_order_discrepancy else {}))
        analysis = Analysis.from_file(args.split_halves, fs=args.fs, format=args.format,
                                      read_options=parse_read_options(args.read_option), outputs=args.outputs,
                                      inputs=args.inputs, settings=settings, clustering=clustering)
        kw = {} if args.tolerance is None else {"max_frequency_difference": args.tolerance}
        if args.pair_within_std is not None:
            kw["pair_within_std"] = args.pair_within_std
        if args.windows is not None:
            check = split_halves_windows(analysis, args.windows, progress=not args.no_progress, **kw)
        else:
            if not args.no_progress:
                print(f"identifying the two halves of {args.split_halves} ...", file=sys.stderr)
            check = split_halves(analysis, **kw)
    except ValueError as exc:
        raise option_error(exc, options) from None
    write_pairs_report(out, check.report(), check.to_dataframe())
    return 0


def run(args) -> int:
    if args.split_halves is not None:
        return run_split_halves(args)
    bad = [_option(k) for k in RECORD_ONLY if getattr(args, k) is not None] + (
        ["--no-order-discrepancy"] if args.no_order_discrepancy else [])
    if bad:
        raise CliError(f"{', '.join(bad)}: option(s) of --split-halves FILE (a measured record)")
    given = {keyword: getattr(args, option) for option, keyword in KEYWORDS.items()
             if getattr(args, option) is not None}
    order = given.get("order", DEFAULTS["order"])
    orders = sorted(set([order] if isinstance(order, int) else order))
    names = _file_names(orders)
    out = None
    if args.out is not None:
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out must be a directory; {out} is a file")
        # before the run, not after it
        check_output_paths([("--out", out / name) for name in names], overwrite=args.overwrite)
    if args.no_freeze_noise:
        given["freeze_noise"] = False
    if args.block_correlation_correction:
        given["block_correlation_correction"] = True
    results = monte_carlo(**{**given, "order": orders}, progress=not args.no_progress)
    text = "\n".join(r.report() for r in results)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "report.md").write_text(text, encoding="utf-8")
        for n, r in zip(orders, results):
            tag = "" if len(orders) == 1 else f"_n{n}"
            r.write_csv(out / f"results{tag}.csv")
            r.write_csv(out / f"summary{tag}.csv", summary=True)
            r.save(out / f"results{tag}.npz")
            r.plot_histograms(out / f"histograms_std{tag}.png")
            r.plot_estimates(out / f"histograms_estimates{tag}.png")
    sys.stdout.write(text)
    if out is not None:
        print(f"\nwrote {', '.join(names)} to {out}", file=sys.stderr)
    return 0


def register(subparsers) -> None:
    """Add the ``validate`` subcommand to ``modaluq``'s subparsers.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        What ``ArgumentParser.add_subparsers`` returned.
    """
    v = subparsers.add_parser(
        "validate",
        help="Monte Carlo check of the analytic standard deviations (the paper's simulation study)",
        description="Simulate independent records of the paper's 6-DOF chain, identify each output-only and "
                    "input/output, and compare the mean analytic standard deviation of every frequency and "
                    "damping ratio with the sample standard deviation over the records (the paper's Tables 1 "
                    "and 2, printed beside ours).  The report goes to stdout, the progress bar to stderr.")
    d = DEFAULTS
    v.add_argument("--records", type=integer_option(1), default=None,
                   help=f"number of records (default {d['n_records']}; the paper used 10000)")
    v.add_argument("--samples", type=integer_option(1), default=None,
                   help=f"samples per record (default {d['n_samples']}, as the paper)")
    v.add_argument("--order", type=integer_option(1), nargs="+", default=None, metavar="N",
                   help="model order(s), e.g. --order 12 24 36: every order from the same records "
                        f"(default {d['order']})")
    v.add_argument("--block-rows", type=integer_option(2), default=None,
                   help=f"future block rows p (default {d['block_rows']})")
    v.add_argument("--past-block-rows", type=integer_option(1), default=None, help="past block rows q (default: p)")
    v.add_argument("--n-blocks", type=integer_option(2), default=None,
                   help=f"blocks for the uncertainty (default {d['n_blocks']})")
    v.add_argument("--unknown-input-std", type=real_option(0, low_open=False), default=None,
                   help="std of the unmeasured forces relative to the known input; 0: the known input is the "
                        f"only excitation (default {d['unknown_input_std']:g}, the paper's)")
    v.add_argument("--damping-ratio", type=real_option(0, 1, high_open=True), default=None,
                   help=f"modal damping ratio of every mode, a fraction (default {d['damping_ratio']:g})")
    v.add_argument("--n-dof", type=integer_option(1), default=None,
                   help=f"masses of the simulated chain (shear frame) (default {d['n_dof']}, the paper's)")
    v.add_argument("--input-dofs", type=integer_option(0), nargs="+", default=None, metavar="DOF",
                   help=f"0-based DOFs of the known input forces (default {' '.join(map(str, d['input_dofs']))})")
    v.add_argument("--output-dofs", type=integer_option(0), nargs="+", default=None, metavar="DOF",
                   help="0-based DOFs measured (default: 0 1 4 for 6 DOFs, else spread evenly)")
    v.add_argument("--noise-coupling-limit", type=real_option(1, low_open=False), default=None,
                   help="flag poles whose sigma the noise directions inflate more than this "
                        f"(default {d['noise_coupling_limit']:g})")
    v.add_argument("--no-freeze-noise", action="store_true",
                   help="plain first-order propagation, noise singular vectors free (for comparison)")
    v.add_argument("--block-correlation-correction", action="store_true",
                   help="correct each mode's sigma for the correlation of adjacent blocks "
                        "(docs/uq-math.md §3.1; identify's block_correlation_correction)")
    v.add_argument("--bootstrap-draws", type=integer_option(0), default=None,
                   help="sigma of f and xi above the noise floor from this many bootstrap draws "
                        "(0 = off, else >= 10; docs/uq-math.md §5.6; identify's bootstrap_draws)")
    v.add_argument("--seed", type=integer_option(0), default=None,
                   help=f"seed of the run; record k uses SeedSequence(seed, spawn_key=(k,)) (default {d['seed']})")
    v.add_argument("--processes", type=integer_option(1, MAX_THREADS), default=None,
                   help="worker processes (default: the CPUs available; 1 runs in this process)")
    v.add_argument("--tolerance", type=real_option(0, 1, high_open=True), default=None,
                   help="relative frequency window that matches an identified mode to a true one "
                        f"(default {d['match_tolerance']:g}); with --split-halves, the window that pairs the two "
                        "halves' modes (default 0.02)")
    g = v.add_argument_group(
        "split halves (a measured record)",
        "--split-halves FILE identifies the record's two halves alike and compares each mode's two estimates "
        "against their sigma: z = (x1 - x2) / sqrt(s1^2 + s2^2); if sigma is right, RMS z is about 1 and 95 % "
        "of the z are within +-1.96. Each half is also read with its own sigma, z = (x1 - x2) / (sqrt(2) s_h): "
        "the coverage of one record's interval, which the combined z can overstate when sigma scatters from "
        "record to record, and within the half's 95 % interval +- t sigma (t the Student-t quantile of its "
        "n_blocks - 1, as SelectedModes.intervals gives). --block-rows, --past-block-rows, --n-blocks, "
        "--order (the diagram's orders) "
        "and --tolerance (the relative frequency difference that pairs two modes, default 0.02) apply too.")
    within = inspect.signature(split_halves).parameters["pair_within_std"].default
    g.add_argument("--split-halves", metavar="FILE", default=None, help="the record (any format of modaluq identify)")
    g.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="sampling frequency in Hz (default: the file's)")
    g.add_argument("--format", default=None, choices=list(FORMATS), help="file format (default: from the extension)")
    g.add_argument("--read-option", action="append", metavar="KEY=VALUE", default=None,
                   help="option of the file reader, as for modaluq identify; repeat for several")
    g.add_argument("--inputs", nargs="+", metavar="CH", default=None, help="known-input channels (default: none)")
    g.add_argument("--outputs", nargs="+", metavar="CH", default=None, help="output channels (default: the others)")
    g.add_argument("--frequency-range", nargs=2, type=real_option(0, low_open=False), default=None,
                   metavar=("LO", "HI"), help="band of interest in Hz (as for modaluq identify)")
    g.add_argument("--start", type=real_option(0, low_open=False), default=None, metavar="S",
                   help="start of the window that is split, s")
    g.add_argument("--stop", type=real_option(0), default=None, metavar="S", help="end of that window, s")
    g.add_argument("--representative", choices=("median", "lowest"), default=None,
                   help="which pole of each mode's cluster is compared, as for modaluq identify (default median)")
    g.add_argument("--shape-representative", choices=("median", "lowest"), default=None,
                   help="which pole gives each mode's shape, as for modaluq identify (default lowest)")
    g.add_argument("--pair-within-std", type=real_option(0, low_open=False), default=None, metavar="K",
                   help="also pair two modes whose frequencies differ by at most K combined sigma_f, so that the "
                        f"relative window does not truncate z_f; 0: the window alone (default {within:g})")
    g.add_argument("--windows", type=integer_option(1), nargs="+", default=None, metavar="N",
                   help="cut the record (or --start/--stop) into N consecutive windows, for each N given, and "
                        "split each window into its halves: many more mode pairs (e.g. --windows 1 2 4 8); "
                        "default: the whole record's two halves only")
    g.add_argument("--no-order-discrepancy", action="store_true",
                   help="do not widen a mode's std by the difference between its representative and its lowest "
                        "sufficient order, as for modaluq identify")
    v.add_argument("--out", metavar="DIR", default=None,
                   help="directory for report.md, results.csv, summary.csv, results.npz and the histogram PNGs "
                        "(--split-halves: report.md and pairs.csv)")
    v.add_argument("--overwrite", action="store_true", help="replace the files of an earlier run in --out")
    v.add_argument("--no-progress", action="store_true", help="no progress bar")
    v.set_defaults(func=run)
