"""The ``modaluq`` command line: one module per command, each a short function over the library.

Errors in the user's input are one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys

from ..buildinfo import core_summary
from ..version import __version__
from . import compare, demo, identify, info, monitor, validate
from .common import Parser

__all__ = ["build_parser", "main"]


class _Version(argparse.Action):
    """``--version``: the version and which build of the C++ core runs (argparse's own action would
    rewrap the lines)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"modaluq {__version__}\nC++ core: {core_summary()}\n"
              "(more: python -c 'import modaluq; modaluq.show_config()')")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The ``modaluq`` parser with every command registered."""
    p = Parser(
        prog="modaluq",
        description="Modal parameters with their uncertainty from vibration data (covariance-driven SSI).",
    )
    p.add_argument("--version", action=_Version, help="show the version and the C++ core's CPU path, and exit")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for command in (compare, demo, identify, info, monitor, validate):
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
