"""``modaluq info FILE``: what a recording holds, before identifying it.

Prints the file's groups, datasets or variables (TDMS, HDF5, MATLAB, ``.npz``), then the record
as ``modaluq identify`` would read it with the same ``--format``, ``--read-option``, ``--fs`` and
``--inputs``: every channel with its unit and role (output or input), the sampling rate and the
length in samples and seconds. Nothing is identified. A file the reader cannot take as is (an HDF5 file of
several datasets without ``--read-option dataset=...``) still gets its listing, then the reader's
error on one line and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..io import FORMATS, SUPPORTED_EXTENSIONS, load
from ..io.contents import file_contents
from .identify import parse_read_options

__all__ = ["describe_recording", "register", "run"]

#: what the items of each format are called in the listing
_ITEMS = {"tdms": "groups and channels", "hdf5": "groups and datasets", "matlab": "variables",
          "numpy": "arrays"}


def _format_of(path: str, fmt: str | None) -> str:
    if fmt is not None:
        return fmt
    ext = Path(path).suffix.lower()
    if ext not in SUPPORTED_EXTENSIONS:
        raise ValueError(f"{path}: unsupported file extension {ext or '(none)'!r}; supported: "
                         f"{', '.join(SUPPORTED_EXTENSIONS)} (or --format)")
    return SUPPORTED_EXTENSIONS[ext]


def describe_recording(rec) -> list:
    """The lines describing a loaded :class:`~modaluq.io.Recording`: rate, length, channels."""
    n = int(rec.y.shape[0])
    lines = [f"  rate: {rec.fs:g} Hz", f"  length: {n} samples ({n / rec.fs:g} s)",
             f"  channels: {rec.n_outputs} output{'s' if rec.n_outputs != 1 else ''}, "
             f"{rec.n_inputs} input{'s' if rec.n_inputs != 1 else ''}"]
    rows = ([(k, name, unit, "output") for k, (name, unit) in enumerate(zip(rec.output_names, rec.output_units))]
            + [(rec.n_outputs + k, name, unit, "input")
               for k, (name, unit) in enumerate(zip(rec.input_names, rec.input_units))])
    width = max(len("name"), *(len(r[1]) for r in rows))
    unit_width = max(len("unit"), *(len(r[2] or "-") for r in rows))
    lines.append(f"  {'#':>4}  {'name':<{width}}  {'unit':<{unit_width}}  role")
    lines += [f"  {k:>4}  {name:<{width}}  {(unit or '-'):<{unit_width}}  {role}" for k, name, unit, role in rows]
    return lines


def run(args) -> int:
    """Execute ``modaluq info`` for parsed ``args``; return the exit status."""
    read_options = parse_read_options(args.read_option)
    fmt = _format_of(args.file, args.format)
    items = file_contents(args.file, fmt)
    size = Path(args.file).stat().st_size
    print(f"{args.file}: {fmt} file, {size} bytes")
    if items:
        print(f"{_ITEMS.get(fmt, 'contents')} ({len(items)}):")
        for it in items:
            indent = "    " if it.kind == "channel" else "  "
            print(f"{indent}{it.kind} {it.name}: {it.detail}")
    sys.stdout.flush()  # the listing stands even when the reader refuses the file below
    shown = " ".join([f"--read-option {o}" for o in args.read_option or []]
                     + ([f"--inputs {' '.join(args.inputs)}"] if args.inputs else []))
    inputs = [int(c) if c.lstrip("-").isdigit() else c for c in args.inputs] if args.inputs else None
    rec = load(args.file, fs=args.fs, format=args.format, inputs=inputs, **read_options)
    print("read as modaluq identify reads it" + (f" ({shown})" if shown else "") + ":")
    print("\n".join(describe_recording(rec)))
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``info`` subcommand to the ``modaluq`` command line."""
    p = subparsers.add_parser(
        "info",
        help="list a file's channels, rate and length (and its groups, datasets or variables)",
        description="List what a measurement file holds, without identifying: its groups and channels "
                    "(TDMS), groups and datasets (HDF5), variables (MATLAB) or arrays (.npz), then every "
                    "channel as modaluq identify reads it, with unit and role (output or input), the "
                    "sampling rate and the length in samples and seconds. Errors are one line and exit "
                    "status 2.",
        epilog="Example: modaluq info tower.tdms --read-option group=acceleration",
    )
    p.add_argument("file", help=f"measurement file ({' '.join(SUPPORTED_EXTENSIONS)})")
    p.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="sampling frequency in Hz (default: from the file, e.g. its time column)")
    p.add_argument("--format", default=None, choices=list(FORMATS), help="file format (default: from the extension)")
    p.add_argument("--read-option", action="append", metavar="KEY=VALUE", default=None,
                   help="option of the file reader, as for modaluq identify (dataset=/daq/acc, variable=acc, "
                        "group=run1, time_column=clock); repeat for several")
    p.add_argument("--inputs", nargs="+", metavar="CH", default=None,
                   help="known-input channels by name or index, as for modaluq identify (default: those the "
                        "file declares)")
    p.set_defaults(func=run)
    return p
