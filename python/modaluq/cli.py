"""The ``modaluq`` command line.

Errors in the user's input are one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from .identification import MAX_COUNT

__all__ = ["main"]


class _CliError(ValueError):
    """A problem with the user's input: printed as one line, exit status 2.

    A ValueError, so that it is caught as one even when this module runs as ``__main__`` (``python
    -m modaluq.cli``) and the subcommands raise the ``modaluq.cli`` copy of the class.
    """


class _Parser(argparse.ArgumentParser):
    """argparse, but its errors are one line too (no usage block): ``--help`` shows the usage."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def integer_option(minimum: int, maximum: int = MAX_COUNT):
    """An argparse ``type``: an integer in [minimum, maximum] (argparse names the option)."""

    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if not minimum <= value <= maximum:
            raise argparse.ArgumentTypeError(f"must be in [{minimum}, {maximum}]; got {value}")
        return value

    return parse


def real_option(low: float, high: float = math.inf, *, high_open: bool = False, low_open: bool = True):
    """An argparse ``type``: a finite number in (low, high] (or [low, ...), (..., high))."""

    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        above = low < value if low_open else low <= value
        below = value < high if high_open else value <= high
        if not (math.isfinite(value) and above and below):
            raise argparse.ArgumentTypeError(f"must be in {'(' if low_open else '['}{low:g}, {high:g}"
                                             f"{')' if high_open else ']'}; got {text}")
        return value

    return parse


def check_output_paths(outputs, inputs=(), *, overwrite=False) -> None:
    """Refuse, before any work, output files that would destroy data.

    ``outputs`` are ``(option, path)`` pairs. An output that is one of ``inputs`` (the same file
    by any path: links, ``./``, another spelling) is refused even with ``--overwrite``; so is
    one file given for two outputs; an existing file is refused unless ``overwrite``.
    """
    def same(a, b):
        try:
            return os.path.samefile(a, b)
        except OSError:  # either does not exist (yet)
            return Path(a).resolve() == Path(b).resolve()

    seen = []
    for option, path in outputs:
        for source in inputs:
            if same(path, source):
                raise _CliError(f"{option} {path} is the input file {source}; refusing to overwrite it")
        for other_option, other in seen:
            if same(path, other):
                raise _CliError(f"{option} {path} is also the file of {other_option} {other}")
        if os.path.lexists(path) and not overwrite:
            raise _CliError(f"{option} {path} exists; pass --overwrite to replace it")
        seen.append((option, path))


def _modes_vs_truth(modes, true_f, true_xi) -> str:
    """Identified modes matched to the nearest true frequency, as a table."""
    lines = [f"{'true f [Hz]':>11}  {'f [Hz]':>8}  {'std f':>7}  {'|err|/std':>9}  "
             f"{'true xi [%]':>11}  {'xi [%]':>7}  {'std xi':>7}"]
    for ft, xt in zip(true_f, true_xi):
        if modes.n_modes == 0:
            lines.append(f"{ft:>11.3f}  {'-':>8}")
            continue
        i = int(np.argmin(np.abs(modes.frequency_hz - ft)))
        f, xi = modes.frequency_hz[i], modes.damping_ratio[i]
        if abs(f - ft) > 0.05 * ft:
            lines.append(f"{ft:>11.3f}  {'(not found)':>8}")
            continue
        if modes.has_uncertainty:
            sf, sx = modes.frequency_std[i], modes.damping_std[i]
            lines.append(f"{ft:>11.3f}  {f:>8.3f}  {sf:>7.4f}  {abs(f - ft) / sf:>9.2f}  "
                         f"{100 * xt:>11.2f}  {100 * xi:>7.2f}  {100 * sx:>7.2f}")
        else:
            lines.append(f"{ft:>11.3f}  {f:>8.3f}  {'':>7}  {'':>9}  {100 * xt:>11.2f}  {100 * xi:>7.2f}")
    return "\n".join(lines)


def _demo(args) -> int:
    from . import identify, simulate

    t0 = time.perf_counter()
    sim = simulate(args.samples, seed=args.seed)
    t_sim = time.perf_counter() - t0
    print(f"Simulated the paper's 6-DOF chain: {sim.n_samples} samples at {sim.fs:g} Hz, "
          f"outputs at DOFs {[d + 1 for d in sim.output_dofs]} (acceleration), known force at DOF "
          f"{[d + 1 for d in sim.input_dofs]} ({t_sim:.2f} s)")
    print(f"SSI-cov with block_rows={args.block_rows}, order {args.order}, {args.n_blocks} blocks for the uncertainty\n")
    for label, u in (("output-only", None), ("input/output", sim.u)):
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = identify(sim.y, u, fs=sim.fs, block_rows=args.block_rows, orders=args.order,
                              n_blocks=args.n_blocks)
        dt = time.perf_counter() - t0
        print(f"{label} ({dt * 1e3:.0f} ms, std = analytic standard deviation from this one record):")
        print(_modes_vs_truth(result.at_order(args.order), sim.frequency_hz, sim.damping_ratio))
        for w in caught:
            print(f"  warning: {w.message}")
        print()
    print("Output-only SSI sees the weakly observed first mode poorly; the known input fixes that.")
    return 0


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    p = _Parser(
        prog="modaluq",
        description="Modal parameters with their uncertainty from vibration data (covariance-driven SSI).",
    )
    p.add_argument("--version", action="version", version=f"modaluq {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    d = sub.add_parser("demo", help="simulate the paper's 6-DOF chain and identify it (output-only and input/output)",
                       description="Simulate the 6-DOF mass-spring chain of the reference paper, identify it "
                                   "output-only and input/output at one model order, and print the modes with "
                                   "their standard deviations next to the true values.")
    d.add_argument("--samples", type=integer_option(1), default=100_000,
                   help="record length in samples (default 100000)")
    d.add_argument("--seed", type=integer_option(0), default=1, help="random seed (default 1)")
    d.add_argument("--block-rows", type=integer_option(2), default=15,
                   help="future and past block rows p = q (default 15)")
    d.add_argument("--order", type=integer_option(1), default=12, help="model order (default 12)")
    d.add_argument("--n-blocks", type=integer_option(2), default=50, help="blocks for the uncertainty (default 50)")
    d.set_defaults(func=_demo)

    # Further subcommands register themselves (one module each).
    from .cli_identify import register as register_identify
    from .validation.cli import register as register_validate

    register_identify(sub)
    register_validate(sub)
    return p


def main(argv=None) -> int:
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or an argument error already printed as one line
        return exc.code
    try:
        return args.func(args)
    except (ValueError, TypeError, OSError, ImportError) as e:  # _CliError is a ValueError
        message = " ".join(str(e).splitlines())  # one line even for a multi-line message
        print(f"modaluq {args.command}: error: {message}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"modaluq {args.command}: error: out of memory (fewer orders or block rows, or a shorter record?)",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("modaluq: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
