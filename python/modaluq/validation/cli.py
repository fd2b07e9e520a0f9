"""``modaluq validate``: the paper's Monte Carlo study from the command line.

Registered by :func:`register` from ``modaluq.cli``.  Prints the Markdown report on stdout,
the progress bar on stderr and, with ``--out DIR``, writes ``report.md``, ``results.csv``
(one row per record, method and mode), ``summary.csv`` (one row per method and mode),
``results.npz`` (everything, readable with ``MonteCarloResult.load``) and the histograms
``histograms_std.png`` and ``histograms_estimates.png``.
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["register"]

#: Files written into ``--out``.
OUTPUT_FILES = ("report.md", "results.csv", "summary.csv", "results.npz", "histograms_std.png",
                "histograms_estimates.png")


def _validate(args) -> int:
    from ..cli import check_output_paths
    from .montecarlo import monte_carlo

    out = None
    if args.out is not None:
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out must be a directory; {out} is a file")
        # before the run, not after it
        check_output_paths([("--out", out / name) for name in OUTPUT_FILES], overwrite=args.overwrite)
    result = monte_carlo(args.records, n_samples=args.samples, order=args.order, block_rows=args.block_rows,
                         past_block_rows=args.past_block_rows, n_blocks=args.n_blocks, seed=args.seed,
                         processes=args.processes, progress=not args.no_progress,
                         match_tolerance=args.tolerance)
    text = result.report()
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "report.md").write_text(text, encoding="utf-8")
        result.write_csv(out / "results.csv")
        result.write_csv(out / "summary.csv", summary=True)
        result.save(out / "results.npz")
        result.plot_histograms(out / "histograms_std.png")
        result.plot_estimates(out / "histograms_estimates.png")
    sys.stdout.write(text)
    if out is not None:
        print(f"\nwrote {', '.join(OUTPUT_FILES)} to {out}", file=sys.stderr)
    return 0


def register(subparsers) -> None:
    """Add the ``validate`` subcommand to ``modaluq``'s subparsers.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        What ``ArgumentParser.add_subparsers`` returned.
    """
    from ..cli import integer_option, real_option
    from ..identification import MAX_THREADS

    v = subparsers.add_parser(
        "validate",
        help="Monte Carlo check of the analytic standard deviations (the paper's simulation study)",
        description="Simulate independent records of the paper's 6-DOF chain, identify each output-only and "
                    "input/output, and compare the mean analytic standard deviation of every frequency and "
                    "damping ratio with the sample standard deviation over the records (the paper's Tables 1 "
                    "and 2, printed beside ours).  The report goes to stdout, the progress bar to stderr.")
    v.add_argument("--records", type=integer_option(1), default=200,
                   help="number of records (default 200; the paper used 10000)")
    v.add_argument("--samples", type=integer_option(1), default=10_000,
                   help="samples per record (default 10000, as the paper)")
    v.add_argument("--order", type=integer_option(1), default=12, help="model order (default 12)")
    v.add_argument("--block-rows", type=integer_option(2), default=15, help="future block rows p (default 15)")
    v.add_argument("--past-block-rows", type=integer_option(1), default=None, help="past block rows q (default: p)")
    v.add_argument("--n-blocks", type=integer_option(2), default=50, help="blocks for the uncertainty (default 50)")
    v.add_argument("--seed", type=integer_option(0), default=0,
                   help="seed of the run; record k uses SeedSequence(seed, spawn_key=(k,)) (default 0)")
    v.add_argument("--processes", type=integer_option(1, MAX_THREADS), default=None,
                   help="worker processes (default: the CPUs available; 1 runs in this process)")
    v.add_argument("--tolerance", type=real_option(0, 1, high_open=True), default=0.05,
                   help="relative frequency window that matches an identified mode to a true one (default 0.05)")
    v.add_argument("--out", metavar="DIR", default=None,
                   help="directory for report.md, results.csv, summary.csv, results.npz and the histogram PNGs")
    v.add_argument("--overwrite", action="store_true", help="replace the files of an earlier run in --out")
    v.add_argument("--no-progress", action="store_true", help="no progress bar")
    v.set_defaults(func=_validate)
