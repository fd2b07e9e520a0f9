"""``modaluq compare FIRST SECOND``: two records identified with the same settings, their modes
paired and compared against their σ (:func:`modaluq.compare_modes`); the report on stdout,
``--out DIR`` adds ``report.md`` and ``pairs.csv``."""

from __future__ import annotations

import argparse
import inspect
import sys
import warnings

from ..analysis import Analysis
from ..comparison import compare_modes
from ..io import SUPPORTED_EXTENSIONS
from .common import option_error, pairs_output, real_option, write_pairs_report
from .identify import parse_orders, parse_read_options
from .options import add_analysis_options, analysis_settings

__all__ = ["register", "run"]

#: compare_modes' defaults, shown in --help
DEFAULTS = {name: p.default for name, p in inspect.signature(compare_modes).parameters.items()}


def run(args) -> int:
    """Execute ``modaluq compare`` for parsed ``args``; return the exit status."""
    out = pairs_output(args.out, args.overwrite)
    settings, criteria, clustering = analysis_settings(args)
    read_options = parse_read_options(args.read_option)
    options = set(vars(args))
    given = (("max_frequency_difference", args.tolerance), ("pair_within_std", args.pair_within_std))
    pairing = {k: v for k, v in given if v is not None}
    runs = []
    for file in (args.first, args.second):
        if not args.no_progress:
            print(f"identifying {file} ...", file=sys.stderr)
        try:
            a = Analysis.from_file(file, fs=args.fs, format=args.format, read_options=read_options,
                                   outputs=args.outputs, inputs=args.inputs, references=args.references,
                                   settings=settings, criteria=criteria, clustering=clustering)
            if runs:  # the second record exactly as the first was identified
                a = a.identified_like(runs[0])
            elif args.orders is not None:
                largest, why = a.largest_order()
                a = a.with_settings(orders=parse_orders(args.orders, largest, bound=why))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                runs.append(a.run(check_harmonics=False, issue_warnings=False))
        except ValueError as exc:
            raise option_error(ValueError(f"{file}: {exc}"), options) from None
    try:
        comparison = compare_modes(runs[0], runs[1], **pairing)
    except ValueError as exc:
        raise option_error(exc, options) from None
    used = runs[0].result.settings
    text = (f"# {args.first} against {args.second}\n\nSettings of both: block_rows {used['block_rows']}, "
            f"past_block_rows {used['past_block_rows']}, n_blocks {used['n_blocks']}, orders "
            f"{min(used['orders'])}-{max(used['orders'])}\n\n" + comparison.report())
    write_pairs_report(out, text, comparison.to_dataframe())
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``compare`` subcommand to the ``modaluq`` command line."""
    p = subparsers.add_parser(
        "compare",
        help="two records' modes compared against their sigma: a change or noise?",
        description="Identify two records with the same settings (the first record's automatic choice, or the "
                    "options given), pair their selected modes and give per mode z = (x1 - x2) / sqrt(s1^2 + "
                    "s2^2) for the frequency and the damping ratio, and the 'same mode' test of the shapes. If "
                    "nothing but the noise changed and sigma is right, |z| > 1.96 for about 5 % of the modes; a "
                    "larger z is a change of the structure or of its conditions (temperature), or close modes "
                    "paired crosswise (docs/tutorial.md 9.7). Errors are one line and exit status 2.",
        epilog="Example: modaluq compare monday.csv tuesday.csv --frequency-range 1 20 --out comparison/",
    )
    p.add_argument("first", help=f"first record ({' '.join(SUPPORTED_EXTENSIONS)})")
    p.add_argument("second", help="second record, read with the same options")
    add_analysis_options(p)
    g = p.add_argument_group("pairing")
    g.add_argument("--tolerance", type=real_option(0, 1, high_open=True), default=None,
                   help="largest relative frequency difference that pairs two modes "
                        f"(default {DEFAULTS['max_frequency_difference']:g}; wider pairs a mode that moved more, "
                        "at the price of wrong pairs where modes are dense)")
    g.add_argument("--pair-within-std", type=real_option(0, low_open=False), default=None, metavar="K",
                   help="also pair two modes within K combined sigma_f where unambiguous; 0: the window alone "
                        f"(default {DEFAULTS['pair_within_std']:g})")
    p.add_argument("--out", metavar="DIR", default=None, help="directory for report.md and pairs.csv")
    p.add_argument("--overwrite", action="store_true", help="replace the files of an earlier run in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run)
    return p
