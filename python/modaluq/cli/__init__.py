"""The ``modaluq`` command line: one module per command, each a short function over the library.

Errors in the user's input are one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys

from ..version import __version__
from . import demo, identify, info, monitor, validate
from .common import Parser

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The ``modaluq`` parser with every command registered."""
    p = Parser(
        prog="modaluq",
        description="Modal parameters with their uncertainty from vibration data (covariance-driven SSI).",
    )
    p.add_argument("--version", action="version", version=f"modaluq {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for command in (demo, identify, info, monitor, validate):
        command.register(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or an argument error already printed as one line
        return exc.code
    try:
        return args.func(args)
    except BrokenPipeError:
        # the reader of stdout stopped (| head): the files were written before the summary, so
        # this is no failure; send the rest of the output nowhere
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except (ValueError, TypeError, OSError, ImportError) as e:  # CliError is a ValueError
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
