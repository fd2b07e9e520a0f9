"""Campaign files: the setups of a multi-setup test, their files and their reference channels.

A campaign file is TOML (docs/multisetup.md, "The campaign file")::

    references = ["L3", "R8"]         # measured in every setup
    inputs = ["F5"]                   # optional: measured-input channels (input/output)
    fs = 25.0                         # optional, Hz: checked against each file's own rate
    geometry = "deck.toml"            # optional: the test geometry (docs/shapes.md)

    [settings]                        # optional: keywords of modaluq.identify_setups
    block_rows = 20
    orders = [2, 4, 6, 8, 10, 12]

    [[setup]]
    file = "setup1.csv"               # relative paths: from the campaign file's folder
    name = "span 1"                   # optional (default: the file's name)
    channels = ["L3", "R8", "L1", "L2", "L4", "L5"]   # optional: renames the file's channels
    format = "csv"                    # optional: the reader (default: from the extension)
    read_options = { time_column = "t" }              # optional: options of the reader

:func:`load_campaign` reads it and every setup's file into a :class:`Campaign`, which
``modaluq.identify_setups`` takes as it is. Every error names the file, the setup entry and the
key. This module reads files only; the settings are checked where they are used.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path

from ._common import check_path
from .errors import RecordingFileError
from .recording import Recording

__all__ = ["Campaign", "load_campaign", "load_setup", "CAMPAIGN_KEYS", "SETUP_KEYS"]

#: Keys of a campaign file's top level, and of each ``[[setup]]`` entry.
CAMPAIGN_KEYS = ("references", "inputs", "fs", "geometry", "settings", "setup")
SETUP_KEYS = ("file", "name", "channels", "format", "read_options")

#: Relative tolerance between a given rate and a file's own (a rate from a time column is rounded).
FS_RTOL = 1e-9


@dataclass(frozen=True, eq=False)
class Campaign:
    """A campaign read by :func:`load_campaign`.

    Attributes
    ----------
    setups : tuple of Recording
        One per ``[[setup]]`` entry, its channels renamed as the entry says.
    names : tuple of str
        The setups' names (``name``, else the file's name).
    references, inputs : tuple of str
        Channel names: the references (in every setup) and the measured inputs.
    fs : float or None
        The campaign's rate in Hz if it states one (each setup's ``Recording.fs`` is checked
        against it).
    geometry : pathlib.Path or None
        The geometry file, resolved against the campaign file's folder.
    settings : dict
        The ``[settings]`` table as written: keywords of ``modaluq.identify_setups``.
    source : str
        The campaign file.
    """

    setups: tuple
    names: tuple
    references: tuple
    inputs: tuple = ()
    fs: float | None = None
    geometry: Path | None = None
    settings: dict = field(default_factory=dict)
    source: str = ""

    def __repr__(self) -> str:
        return (f"Campaign({self.source or 'arrays'}: {len(self.setups)} setups, references "
                f"{list(self.references)}" + (f", inputs {list(self.inputs)}" if self.inputs else "") + ")")


def _rename(rec: Recording, channels, where: str) -> Recording:
    """``rec`` with its channels (outputs then inputs, as the file holds them) renamed:
    ``channels`` a list of every new name in order, or a table ``{old = new}``."""
    old = list(rec.output_names) + list(rec.input_names)
    if isinstance(channels, dict):
        unknown = [k for k in channels if k not in old]
        if unknown:
            raise ValueError(f"{where}, channels: the file has no channel {unknown[0]!r} (its channels: {old})")
        bad = [v for v in channels.values() if not isinstance(v, str) or not v]
        if bad:
            raise ValueError(f"{where}, channels: new names must be non-empty strings; got {bad[0]!r}")
        new = [channels.get(c, c) for c in old]
    elif isinstance(channels, list):
        if not all(isinstance(c, str) and c for c in channels):
            raise ValueError(f"{where}, channels: must be a list of non-empty strings")
        if len(channels) != len(old):
            raise ValueError(f"{where}, channels: {len(channels)} names for the {len(old)} channels of the "
                             f"file ({old})")
        new = list(channels)
    else:
        raise ValueError(f"{where}, channels: must be a list of names (one per channel of the file) or a table "
                         f"{{old = \"new\"}}; got {type(channels).__name__}")
    if len(set(new)) != len(new):
        twice = sorted({c for c in new if new.count(c) > 1})
        raise ValueError(f"{where}, channels: the name(s) {twice} are given to more than one channel")
    n_out = rec.n_outputs
    return Recording(y=rec.y, u=rec.u, fs=rec.fs, output_names=tuple(new[:n_out]), input_names=tuple(new[n_out:]),
                     output_units=rec.output_units, input_units=rec.input_units, source=rec.source)


def load_setup(path, *, fs: float | None = None, channels=None, format: str | None = None,
               where: str = "", **read_options) -> Recording:
    """One setup's file as a :class:`Recording`, its rate checked against ``fs`` and its
    channels renamed by ``channels`` (a list, one name per channel in file order, or a dict
    ``{old: new}``).

    The file's own rate wins the check: a file that states a rate other than ``fs`` (relative
    difference above 1e-9) is a ValueError; ``fs`` is used for a file that states none.
    ``where`` (e.g. ``"setup 2 ('span 3')"``) starts every message.
    """
    from . import load  # the package's dispatcher (this module is imported lazily by it)

    prefix = f"{where}: " if where else ""
    try:
        rec = load(path, format=format, **read_options)
    except RecordingFileError:
        if fs is None:
            raise
        rec = load(path, fs=fs, format=format, **read_options)  # a file without its rate: fs is it
    if fs is not None and not math.isclose(rec.fs, float(fs), rel_tol=FS_RTOL):
        raise ValueError(f"{prefix}{path} is sampled at {rec.fs:g} Hz but fs is {float(fs):g} Hz "
                         "(every setup must have the campaign's rate: resample it, or correct fs)")
    if channels is not None:
        rec = _rename(rec, channels, where or str(path))
    return rec


def _names(value, key: str, where: str) -> tuple:
    if isinstance(value, str) or not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise ValueError(f"{where}: {key} must be a list of channel names, e.g. {key} = [\"L3\", \"R8\"]; "
                         f"got {value!r}")
    if len(set(value)) != len(value):
        raise ValueError(f"{where}: {key} names a channel twice: {value}")
    return tuple(value)


def load_campaign(path) -> Campaign:
    """Read a campaign file (module docstring; docs/multisetup.md) and every setup's file.

    Relative paths (``file``, ``geometry``) are resolved against the campaign file's folder.
    Raises ValueError (the campaign file, the
    setup entry and the key in the message), FileNotFoundError for a missing file.
    """
    try:
        import tomllib  # Python 3.11+
    except ImportError:  # pragma: no cover - 3.9/3.10
        import tomli as tomllib
    path = check_path(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a text (TOML) file: {exc}") from None
    folder = path.resolve().parent
    unknown = [k for k in doc if k not in CAMPAIGN_KEYS]
    if unknown:
        raise ValueError(f"{path}: unknown key {unknown[0]!r} (a campaign file has {', '.join(CAMPAIGN_KEYS)}; "
                         "a setup's keys go in a [[setup]] entry)")
    if "references" not in doc:
        raise ValueError(f"{path}: references is missing: name the reference channels, e.g. references = [\"L3\"]")
    references = _names(doc["references"], "references", str(path))
    inputs = _names(doc["inputs"], "inputs", str(path)) if "inputs" in doc else ()
    fs = doc.get("fs")
    if fs is not None:
        if isinstance(fs, bool) or not isinstance(fs, numbers.Real) or not (math.isfinite(fs) and fs > 0):
            raise ValueError(f"{path}: fs must be a rate in Hz (a number > 0); got {fs!r}")
        fs = float(fs)
    geometry = None
    if "geometry" in doc:
        if not isinstance(doc["geometry"], str) or not doc["geometry"]:
            raise ValueError(f"{path}: geometry must be a file name; got {doc['geometry']!r}")
        geometry = folder / doc["geometry"]
        if not geometry.is_file():
            raise FileNotFoundError(f"{path}: geometry: no such file {geometry}")
    settings = doc.get("settings", {})
    if not isinstance(settings, dict):
        raise ValueError(f"{path}: settings must be a table ([settings]); got {type(settings).__name__}")
    entries = doc.get("setup")
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        raise ValueError(f"{path}: no setup: give one [[setup]] entry (with its file = \"...\") per setup")

    setups, names = [], []
    for j, entry in enumerate(entries):
        where = f"{path}: setup {j}"
        unknown = [k for k in entry if k not in SETUP_KEYS]
        if unknown:
            raise ValueError(f"{where}: unknown key {unknown[0]!r} (a [[setup]] entry has {', '.join(SETUP_KEYS)})")
        file = entry.get("file")
        if not isinstance(file, str) or not file:
            raise ValueError(f"{where}: file is missing or not a file name: file = \"setup{j + 1}.csv\"")
        name = entry.get("name", Path(file).name)
        if not isinstance(name, str) or not name:
            raise ValueError(f"{where}: name must be a non-empty string; got {name!r}")
        where = f"{path}: setup {j} ({name!r})"
        if name in names:
            raise ValueError(f"{where}: name: setup {names.index(name)} has the same name")
        fmt = entry.get("format")
        if fmt is not None and not isinstance(fmt, str):
            raise ValueError(f"{where}: format must be a reader's name, e.g. \"csv\"; got {fmt!r}")
        options = entry.get("read_options", {})
        if not isinstance(options, dict):
            raise ValueError(f"{where}: read_options must be a table, e.g. read_options = {{ time_column = \"t\" }}")
        bad = [k for k in options if k in ("fs", "format", "inputs", "path")]
        if bad:
            raise ValueError(f"{where}: read_options: {bad[0]!r} is not a reader option here "
                             "(fs and inputs are the campaign's, format the entry's)")
        file_path = folder / file
        if not file_path.is_file():
            raise FileNotFoundError(f"{where}: file: no such file {file_path}")
        try:
            rec = load_setup(file_path, fs=fs, channels=entry.get("channels"), format=fmt, where=where, **options)
        except TypeError as exc:  # an unknown reader option: say where it came from
            raise ValueError(f"{where}: read_options: {exc}") from None
        setups.append(rec)
        names.append(name)
    return Campaign(setups=tuple(setups), names=tuple(names), references=references, inputs=inputs, fs=fs,
                    geometry=geometry, settings=dict(settings), source=str(path))
