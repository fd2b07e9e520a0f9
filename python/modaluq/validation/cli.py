"""``modaluq validate``: the paper's Monte Carlo study from the command line.

Registered by :func:`register` from ``modaluq.cli``.  Prints the Markdown report on stdout,
the progress bar on stderr and, with ``--out DIR``, writes ``report.md``, ``results.csv``
(one row per record, method and mode), ``summary.csv`` (one row per method and mode),
``results.npz`` (everything, readable with ``MonteCarloResult.load``) and the histograms
``histograms_std.png`` and ``histograms_estimates.png``.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

__all__ = ["register"]

#: Files written into ``--out``.
OUTPUT_FILES = ("report.md", "results.csv", "summary.csv", "results.npz", "histograms_std.png",
                "histograms_estimates.png")


def _validate(args) -> int:
    from .montecarlo import monte_carlo

    for option, value, minimum in (("--records", args.records, 1), ("--samples", args.samples, 1),
                                   ("--order", args.order, 1), ("--block-rows", args.block_rows, 2),
                                   ("--past-block-rows", args.past_block_rows, 1), ("--n-blocks", args.n_blocks, 2),
                                   ("--seed", args.seed, 0), ("--processes", args.processes, 1)):
        if value is not None and value < minimum:
            raise ValueError(f"{option} must be >= {minimum}; got {value}")
    if not 0 < args.tolerance < 1:
        raise ValueError(f"--tolerance must lie in (0, 1); got {args.tolerance}")
    out = None
    if args.out is not None:
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out must be a directory; {out} is a file")
        # Found before the run, not after it: the PNGs need matplotlib.
        if importlib.util.find_spec("matplotlib") is None:
            raise ValueError("--out writes PNG histograms, which need matplotlib: pip install 'modaluq[plot]'")
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
    v = subparsers.add_parser(
        "validate",
        help="Monte Carlo check of the analytic standard deviations (the paper's simulation study)",
        description="Simulate independent records of the paper's 6-DOF chain, identify each output-only and "
                    "input/output, and compare the mean analytic standard deviation of every frequency and "
                    "damping ratio with the sample standard deviation over the records (the paper's Tables 1 "
                    "and 2, printed beside ours).  The report goes to stdout, the progress bar to stderr.")
    v.add_argument("--records", type=int, default=200, help="number of records (default 200; the paper used 10000)")
    v.add_argument("--samples", type=int, default=10_000, help="samples per record (default 10000, as the paper)")
    v.add_argument("--order", type=int, default=12, help="model order (default 12)")
    v.add_argument("--block-rows", type=int, default=15, help="future block rows p (default 15)")
    v.add_argument("--past-block-rows", type=int, default=None, help="past block rows q (default: p)")
    v.add_argument("--n-blocks", type=int, default=50, help="blocks for the uncertainty (default 50)")
    v.add_argument("--seed", type=int, default=0, help="seed of the run; record k uses SeedSequence(seed, "
                                                       "spawn_key=(k,)) (default 0)")
    v.add_argument("--processes", type=int, default=None,
                   help="worker processes (default: the CPUs available; 1 runs in this process)")
    v.add_argument("--tolerance", type=float, default=0.05,
                   help="relative frequency window that matches an identified mode to a true one (default 0.05)")
    v.add_argument("--out", metavar="DIR", default=None,
                   help="directory for report.md, results.csv, summary.csv, results.npz and the histogram PNGs")
    v.add_argument("--no-progress", action="store_true", help="no progress bar")
    v.set_defaults(func=_validate)
