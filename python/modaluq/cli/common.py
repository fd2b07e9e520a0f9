"""What every ``modaluq`` command shares: one-line errors, option types, output-path checks.

The library names a parameter at fault in its messages (``min_mac must be <= 1``);
:func:`option_error` turns that name into the option the user typed (``--min-mac``).
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path

from ..checks import MAX_COUNT

__all__ = ["CliError", "Parser", "check_output_paths", "integer_option", "option_error", "pairs_output",
           "real_option", "write_pairs_report"]


class CliError(ValueError):
    """A problem with the user's input: printed as one line, exit status 2.

    A ValueError, so that ``main`` prints it as one line like any other mistake in the input.
    """


class Parser(argparse.ArgumentParser):
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
                raise CliError(f"{option} {path} is the input file {source}; refusing to overwrite it")
        for other_option, other in seen:
            if same(path, other):
                raise CliError(f"{option} {path} is also the file of {other_option} {other}")
        if os.path.lexists(path) and not overwrite:
            raise CliError(f"{option} {path} exists; pass --overwrite to replace it")
        seen.append((option, path))


def option_error(exc: Exception, options) -> Exception:
    """``exc`` with the library's parameter names that are ``options`` written as the options the
    user typed: ``block_rows 5`` → ``--block-rows 5``, ``outputs: ...`` → ``--outputs: ...``.

    A name with an underscore is unambiguous anywhere in the message, except as the part of a
    dotted key (``clustering.shape_representative``, a settings fingerprint's), which is left as
    it is; a plain word (``outputs``) only where the message starts with it, alone or as
    ``outputs and inputs``.
    """
    def option(m):
        return "--" + m.group().replace("_", "-") if m.group() in options else m.group()

    text = re.sub(r"(?<![.\w])[a-z]+(?:_[a-z]+)+\b", option, str(exc))
    text = re.sub(r"^[a-z]+\b(?= and [a-z]+\b)|^[a-z]+\b", option, text)
    text = re.sub(r"^(--[a-z-]+ and )([a-z]+)\b", lambda m: m.group(1) + option(re.match(r".*", m.group(2))), text)
    return type(exc)(text)


def check_image_paths(images) -> None:
    """Refuse, before any work, an image (``(option, path)`` pairs; None skipped) whose folder does
    not exist or whose type matplotlib cannot write."""
    from matplotlib.backend_bases import FigureCanvasBase

    for option, path in images:
        if not path:
            continue
        parent = Path(path).resolve().parent
        if not parent.is_dir():
            raise OSError(f"{path}: directory {parent} does not exist")
        ext = Path(path).suffix.lower().lstrip(".")
        if ext not in FigureCanvasBase.get_supported_filetypes():
            raise ValueError(f"{option} {path}: unsupported image type {ext or '(none)'!r}; use e.g. .png, .pdf, .svg")


#: The files a pairs report (``compare``, ``validate --split-halves``) writes into ``--out``.
PAIRS_FILES = ("report.md", "pairs.csv")


def pairs_output(out, overwrite: bool):
    """``--out`` of a pairs report as a Path (None when not given), checked before any work."""
    if out is None:
        return None
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out must be a directory; {out} is a file")
    check_output_paths([("--out", out / name) for name in PAIRS_FILES], overwrite=overwrite)
    return out


def write_pairs_report(out, text: str, table) -> None:
    """The report on stdout and, with ``out``, ``report.md`` and ``pairs.csv`` (the DataFrame ``table``)."""
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "report.md").write_text(text, encoding="utf-8")
        table.to_csv(out / "pairs.csv", index=False)
    sys.stdout.write(text)
    if out is not None:
        print(f"\nwrote {', '.join(PAIRS_FILES)} to {out}", file=sys.stderr)
