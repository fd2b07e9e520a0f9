"""The file formats are listed once, in modaluq.io.FILE_FORMATS: the loader's tables, the CLI's
``--format`` choices, the loader fuzzer and docs/loaders.md's table all say the same."""

import argparse
import importlib
import pathlib
import re
import sys

import modaluq.io as mio
from modaluq.cli import build_parser

ROOT = pathlib.Path(__file__).resolve().parents[3]


def test_loader_tables_come_from_the_registry():
    names = [f.name for f in mio.FILE_FORMATS]
    assert list(mio.FORMATS) == names and len(set(names)) == len(names)
    extensions = [e for f in mio.FILE_FORMATS for e in f.extensions]
    assert list(mio.SUPPORTED_EXTENSIONS) == extensions and len(set(extensions)) == len(extensions)
    for f in mio.FILE_FORMATS:
        assert all(e == e.lower() and e.startswith(".") for e in f.extensions)
        reader = getattr(importlib.import_module(f"modaluq.io.{f.module}"), f.reader)
        assert getattr(mio, f.reader) is reader


def test_cli_format_choices():
    parser = build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    seen = 0
    for sub in subparsers.choices.values():
        for action in sub._actions:
            if "--format" in action.option_strings:
                assert list(action.choices) == list(mio.FORMATS)
                seen += 1
    assert seen >= 1  # modaluq identify (and monitor) take --format


def test_docs_table():
    text = (ROOT / "docs" / "loaders.md").read_text(encoding="utf-8")
    section = text.split("### Formats", 1)[1].split("\n#", 1)[0]
    rows = [line for line in section.splitlines() if re.match(r"\| `\w+` \|", line)]
    documented = []
    for row in rows:
        name, extensions, reader, needs = (c.strip() for c in row.strip("|").split("|"))
        m = re.fullmatch(r"`(\w+)` \(`(\w+)`\)", reader)
        documented.append((name.strip("`"), tuple(extensions.strip("`").split()), m.group(1), m.group(2),
                           "" if needs == "numpy only" else needs))
    assert documented == [(f.name, f.extensions, f.reader, f.module, f.requires) for f in mio.FILE_FORMATS]


def test_the_fuzzer_seeds_every_format():
    sys.path.insert(0, str(ROOT / "tests" / "fuzz"))
    try:
        import fuzz_loaders
    finally:
        sys.path.pop(0)
    fuzzed = {mio.SUPPORTED_EXTENSIONS[ext] for ext, _ in fuzz_loaders.FORMATS.values()}
    assert fuzzed == set(mio.FORMATS)
