"""Delimited text loader (CSV, TSV, semicolon- or whitespace-separated)."""

from __future__ import annotations

import codecs
import csv as _csv
import numbers
import re

import numpy as np

from ._common import check_fs_arg, check_path, fail, fs_from_time, pick_fs
from .recording import Recording

__all__ = ["read_csv", "TIME_COLUMN_NAMES"]

#: Header names (case-insensitive, unit removed) recognised as the time column.
TIME_COLUMN_NAMES = ("time", "t", "times", "timestamp", "seconds", "s")
#: Units of a time column (``time [min]``, ``t (ms)``, ``time/ns``, ``Time_msec``) in seconds.
TIME_UNITS = {
    **dict.fromkeys(("s", "sec", "secs", "second", "seconds"), 1.0),
    **dict.fromkeys(("ms", "msec", "msecs", "millisecond", "milliseconds"), 1e-3),
    **dict.fromkeys(("us", "µs", "μs", "usec", "microsecond", "microseconds"), 1e-6),
    **dict.fromkeys(("ns", "nsec", "nanosecond", "nanoseconds"), 1e-9),
    **dict.fromkeys(("min", "mins", "minute", "minutes"), 60.0),
    **dict.fromkeys(("h", "hr", "hrs", "hour", "hours"), 3600.0),
    **dict.fromkeys(("d", "day", "days"), 86400.0),
}

_CANDIDATES = ("\t", ";", ",", "|")
_UNIT_RE = re.compile(r"^(.*?)\s*(?:\[([^\]]*)\]|\(([^)]*)\))\s*$")
_DELIM_NAMES = {"\t": "tab", ";": "semicolon", ",": "comma", "|": "pipe", None: "whitespace"}


def _split_header(line: str, delim):
    if delim is None:
        out: list[str] = []
        for tok in line.split():  # "acc1 [m/s^2]" -> one header cell with its unit
            if out and re.fullmatch(r"\[[^\]]*\]|\([^)]*\)", tok):
                out[-1] = f"{out[-1]} {tok}"
            else:
                out.append(tok.strip('"'))
        return out
    return [f.strip() for f in next(_csv.reader([line], delimiter=delim, quotechar='"'))]


def _split(line: str, delim):
    if delim is None:
        return line.split()
    return [f.strip().strip('"').strip() for f in line.split(delim)]


def _sniff(header: str, sample: list[str], decimal: str):
    """Choose the delimiter: tab, semicolon, comma, pipe (in this order), else whitespace."""
    first = sample[0] if sample else header
    for c in _CANDIDATES:
        if c == decimal:
            continue
        nh = len(_split_header(header, c)) - 1
        if nh >= 1 and first.count(c) == nh:
            return c
    nh = len(_split_header(header, None))
    if nh > 1 and len(first.split()) == nh:
        return None
    for c in _CANDIDATES:  # header and first row disagree: trust the header
        if c != decimal and c in header:
            return c
    return None


def _name_unit(field: str) -> tuple[str, str]:
    m = _UNIT_RE.match(field)
    if m and m.group(1):
        unit = m.group(2) if m.group(2) is not None else m.group(3)
        return m.group(1).strip(), unit.strip()
    return field.strip(), ""


def _time_unit(name: str, unit: str):
    """``(is_time, unit)`` for a header cell split into name and bracketed unit: whether it
    names a time column and the unit it states ('' if none). ``time/ns`` and ``Time_msec``
    carry the unit in the name; a unit-like name alone (``seconds``, ``s``) is seconds."""
    n = name.strip().lower()
    if n in TIME_COLUMN_NAMES:
        return True, unit.strip() or ("s" if n in TIME_UNITS else "")
    if not unit:
        base, sep, u = n.rpartition("/")
        if sep and base.strip() in TIME_COLUMN_NAMES:  # "time/ns": any unit, checked later
            return True, u.strip()
        base, sep, u = n.rpartition("_")
        if sep and base in TIME_COLUMN_NAMES and u in TIME_UNITS:  # "time_x" is not time
            return True, u
    return False, ""


def _time_scale(path, column: str, unit: str) -> float:
    """Seconds per time-column unit (none stated: seconds); ValueError for an unknown one."""
    if not unit:
        return 1.0
    scale = TIME_UNITS.get(unit.lower())
    if scale is None:
        raise fail(path, f"time column {column!r}: unknown time unit {unit!r}; understood: "
                         "s, ms, us, ns, min, h, d (and spellings like sec, msec, minutes, "
                         "hours); pass fs= to ignore it, or time_column=False if the column is "
                         "not time")
    return scale


def _cell_error(path, lineno: int, colname: str, cell: str) -> Exception:
    s = cell.strip()
    if s == "":
        problem = "empty cell"
    elif s.lower() in ("nan", "-nan", "+nan"):
        problem = f"NaN value ({s!r})"
    elif s.lower().lstrip("+-") in ("inf", "infinity"):
        problem = f"infinite value ({s!r})"
    else:
        problem = f"cannot parse {s!r} as a number"
    return fail(path, f"line {lineno}, column {colname!r}: {problem}")


def _locate_problem(path, lines, linenos, delim, decimal, colnames):
    """Slow scan for the first bad line/cell (used only when the fast parser failed)."""
    n = len(colnames)
    for line, ln in zip(lines, linenos):
        fields = _split(line, delim)
        if len(fields) != n:
            if len(fields) < n:
                missing = ", ".join(repr(c) for c in colnames[len(fields):])
                raise fail(path, f"line {ln}: {len(fields)} fields but the header has {n}; "
                                 f"missing column(s) {missing} (truncated file?)")
            raise fail(path, f"line {ln}: {len(fields)} fields but the header has {n} "
                             f"(delimiter {_DELIM_NAMES.get(delim, repr(delim))})")
        for f, cname in zip(fields, colnames):
            s = f.replace(decimal, ".") if decimal != "." else f
            try:
                v = float(s)
            except ValueError:
                raise _cell_error(path, ln, cname, f) from None
            if not np.isfinite(v):
                raise _cell_error(path, ln, cname, f)
    return None


#: Bytes read (and decoded) at a time: the parse holds one such batch of lines besides the array.
CHUNK_BYTES = 1 << 20
_LINE_END = re.compile(r"\r\n|\r|\n")  # a bare CR ends a line too (classic Mac)


def _scan(path, encoding) -> tuple[int, str]:
    """First, cheap pass over the bytes: ``(lines, encoding)``, an upper bound on the data rows
    (the lines of the file) and the encoding to decode with. Refuses binary content and, for
    an explicit ``encoding``, bytes it cannot decode, before anything is parsed."""
    if encoding is not None:
        try:
            decoder = codecs.getincrementaldecoder(encoding)()
        except LookupError as exc:
            raise fail(path, f"cannot decode as {encoding}: {exc}") from None
    else:
        decoder = codecs.getincrementaldecoder("utf-8-sig")()
    line_ends, offset, after_cr = 0, 0, False
    with open(path, "rb") as f:
        while True:
            chunk = f.read(CHUNK_BYTES)
            if offset < 65536 and b"\x00" in chunk[:65536 - offset]:
                raise fail(path, "binary content (NUL bytes): not a delimited text file")
            offset += len(chunk)
            if decoder is not None:
                try:
                    decoder.decode(chunk, final=not chunk)
                except UnicodeDecodeError:
                    if encoding is not None:  # the whole file's error, with its position
                        try:
                            path.read_bytes().decode(encoding)
                        except UnicodeDecodeError as exc:
                            raise fail(path, f"cannot decode as {encoding}: {exc}") from None
                        raise
                    decoder = None  # not UTF-8: Latin-1, which decodes any byte
            if not chunk:
                break
            line_ends += (chunk.count(b"\n") + chunk.count(b"\r") - chunk.count(b"\r\n")
                          - (after_cr and chunk[:1] == b"\n"))
            after_cr = chunk[-1:] == b"\r"
    return line_ends + 1, encoding or ("utf-8-sig" if decoder is not None else "latin-1")


def _content_lines(path, encoding: str, comment):
    """The non-blank, non-comment lines of the file and their 1-based line numbers, a batch of
    about CHUNK_BYTES at a time. The lines are those ``re.split(r"\r\n|\r|\n", text)`` gives
    for the whole text: a batch never ends between a CR and the LF that may follow it."""
    decoder = codecs.getincrementaldecoder(encoding)()
    carry, lineno = "", 0
    with open(path, "rb") as f:
        while True:
            chunk = f.read(CHUNK_BYTES)
            text = carry + decoder.decode(chunk, final=not chunk)
            if chunk:
                end = max(text.rfind("\n"), text.rfind("\r", 0, len(text) - 1)) + 1
                carry, lines = text[end:], _LINE_END.split(text[:end])[:-1] if end else []
            else:
                carry, lines = "", _LINE_END.split(text)
            del text
            batch, numbers_ = [], []
            for line in lines:
                lineno += 1
                s = line.strip()
                if s and not (comment is not None and s.startswith(comment)):
                    batch.append(line)
                    numbers_.append(lineno)
            yield batch, numbers_
            if not chunk:
                return


def _parse_batch(path, lines, linenos, delim, decimal, colnames):
    """``lines`` parsed into a ``(len(lines), len(colnames))`` array; a ValueError naming the
    line and column of the first empty, NaN, infinite or unparsable cell."""
    ncol = len(colnames)
    work = [d.replace(",", ".") for d in lines] if decimal == "," else lines
    try:
        values = np.loadtxt(work, delimiter=delim, dtype=np.float64, ndmin=2, quotechar='"',
                            comments=None)
    except Exception:  # noqa: BLE001 - fall back to the slow scan that names line/column
        values = None
    if values is None or values.shape != (len(lines), ncol):
        _locate_problem(path, lines, linenos, delim, decimal, colnames)
        raise fail(path, "could not parse the numeric data (inconsistent rows?)")
    bad = ~np.isfinite(values)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        fields = _split(lines[r], delim)
        raise _cell_error(path, linenos[r], colnames[c], fields[c] if len(fields) == ncol else "nan")
    return values


def _grow(a, rows: int):
    out = np.empty((rows,) + a.shape[1:], dtype=a.dtype)
    out[:a.shape[0]] = a
    return out


def _trim(a, rows: int):
    """The first ``rows`` rows of ``a``, shrunk in place (no copy: its pages are returned)."""
    if rows != a.shape[0]:
        a.resize((rows,) + a.shape[1:], refcheck=False)  # no view of a exists
    return a


def _time_column(path, time_column, names, units, fields):
    """Index of the time column (None if there is none) from the header alone."""
    ncol = len(names)
    if time_column is None:
        for k, (nm, un) in enumerate(zip(names, units)):
            if _time_unit(nm, un)[0]:
                return k
        return None
    if time_column is False:
        return None
    if isinstance(time_column, str):
        matches = [k for k, nm in enumerate(names) if nm == time_column or fields[k] == time_column]
        if not matches:
            raise fail(path, f"time_column {time_column!r} not found; columns are: "
                             f"{', '.join(map(repr, names))}")
        return matches[0]
    k = int(time_column)
    if not -ncol <= k < ncol:
        raise ValueError(f"{path}: time_column index {k} out of range for {ncol} columns")
    return k % ncol


def read_csv(path, *, fs=None, inputs=None, time_column=None, delimiter=None, decimal=".",
             comment="#", time_tolerance=0.01, encoding=None) -> Recording:
    """Read a delimited text file whose first (non-comment) row holds the channel names.

    Parameters
    ----------
    fs : float, optional
        Sampling frequency. Required when the file has no time column; when given it takes
        precedence over the time column (which is still removed from the channels).
    inputs : list of str/int, optional
        Known-input channels, by header name or by index among the data columns (the time
        column excluded).
    time_column : str, int, False or None
            None: auto-detect a column named ``time``, ``t``, ``times``, ``timestamp``, ``seconds``
        or ``s`` (case-insensitive), with an optional unit: ``time [min]``, ``t (ms)``,
        ``time/ns``, ``Time_msec`` (see TIME_UNITS; none means seconds, an unknown one is a
        ValueError unless ``fs`` is given). A name or a 0-based index among all columns picks it
        explicitly; False means there is no time column.
    delimiter : str, optional
        Field separator; default sniffed among tab, ``;``, ``,``, ``|`` and whitespace.
    decimal : str
        Decimal mark, ``'.'`` (default) or ``','`` (then the delimiter cannot be ``,``).
    comment : str or None
        Lines starting with this string are ignored (default ``'#'``).
    time_tolerance : float
        Allowed deviation of the time stamps from a uniform grid, in sample periods.
    encoding : str, optional
        Text encoding; default UTF-8 (with or without BOM), falling back to Latin-1.

    Header cells like ``acc1 [m/s^2]`` or ``acc1 (m/s^2)`` give name ``acc1`` and unit
    ``m/s^2``. Any empty, NaN or unparsable cell raises ``ValueError`` naming the file, the
    1-based line number in the file (the header counts) and the column.

    The file is read in batches of ``CHUNK_BYTES`` and parsed into one preallocated array, so
    the memory held is about the array's (docs/loaders.md).
    """
    p = check_path(path)
    check_fs_arg(fs)
    if delimiter is not None and (not isinstance(delimiter, str) or len(delimiter) == 0):
        raise TypeError(f"delimiter must be a non-empty str or None, got {delimiter!r}")
    if not isinstance(decimal, str) or decimal not in (".", ","):
        raise TypeError(f"decimal must be '.' or ',', got {decimal!r}")
    if delimiter == decimal:
        raise ValueError("delimiter and decimal cannot both be ','")
    if comment is not None and (not isinstance(comment, str) or comment == ""):
        raise TypeError(f"comment must be a non-empty str or None, got {comment!r}")
    if time_column is not None and time_column is not False and (
            isinstance(time_column, bool) or not isinstance(time_column, (str, numbers.Integral))):
        raise TypeError("time_column must be a column name (str), an index (int), False or None, "
                        f"got {time_column!r}")
    if isinstance(time_tolerance, bool) or not isinstance(time_tolerance, numbers.Real) or \
            not time_tolerance > 0:
        raise TypeError(f"time_tolerance must be a positive number, got {time_tolerance!r}")
    if encoding is not None and not isinstance(encoding, str):
        raise TypeError(f"encoding must be a str or None, got {type(encoding).__name__}")

    nrows_max, text_encoding = _scan(p, encoding)
    content = _content_lines(p, text_encoding, comment)  # read on below, batch by batch
    hdr_idx = None
    first: list[str] = []  # the first data lines: the delimiter is sniffed from them
    first_nos: list[int] = []
    for batch, linenos in content:
        if hdr_idx is None and batch:
            hdr_idx, header = linenos[0] - 1, batch[0]
            batch, linenos = batch[1:], linenos[1:]
        first += batch
        first_nos += linenos
        if first:
            break
    if hdr_idx is None:
        raise fail(p, "no header row (the file holds only blank or comment lines)")
    if not first:
        raise fail(p, f"no data rows after the header (line {hdr_idx + 1})")

    try:
        if delimiter is None:
            delim = _sniff(header, first[:20], decimal)
        elif delimiter.isspace() and delimiter != "\t":
            delim = None  # any run of spaces
        else:
            delim = delimiter
        fields = _split_header(header, delim)
    except _csv.Error as exc:  # e.g. a header cell over the csv module's 128 KiB limit
        raise fail(p, f"line {hdr_idx + 1}: cannot split the header row: {exc}") from None
    # tolerate a trailing delimiter on every line ("a,b,c," / "1,2,3,")
    trailing = len(fields) > 1 and fields[-1] == "" and delim is not None
    if trailing:
        fields = fields[:-1]
    names, units = zip(*(_name_unit(f) for f in fields))
    names, units = list(names), list(units)
    for k, nm in enumerate(names):
        if nm == "":
            raise fail(p, f"line {hdr_idx + 1}: header cell {k + 1} is empty; every column needs "
                          "a name")

    def _is_num(s):
        try:
            float(s.replace(decimal, "."))
        except ValueError:
            return False
        return True

    if all(_is_num(nm) for nm in names):
        raise fail(p, f"line {hdr_idx + 1}: the first row is numeric ({header.strip()[:40]!r}); "
                      "a header row of channel names is required")

    ncol = len(names)
    # The time column is found from the header alone, so that the data are parsed straight into
    # the final channel array; an error about it is raised after the parse, as a bad cell
    # found by the parse is reported first.
    tcol, time_error = None, None
    try:
        tcol = _time_column(p, time_column, names, units, fields)
    except ValueError as exc:
        time_error = exc
    if tcol is not None and ncol == 1:
        time_error = fail(p, "the only column is the time column; no channels to load")
        tcol = None
    keep = [k for k in range(ncol) if k != tcol]
    # ------------------------------------------------------------ chunked numeric parse
    # Into one preallocated array (rows counted by _scan) a batch of lines at a time: the
    # peak is the array plus one batch, not the text, its lines and a parsed copy (docs/loaders.md).
    values = np.empty((nrows_max, len(keep)), dtype=np.float64)
    times = np.empty(nrows_max, dtype=np.float64) if tcol is not None and fs is None else None
    n = 0

    def parse(batch, linenos):
        nonlocal values, times, n
        if not batch:
            return
        if trailing:
            batch = [ln[:-len(delim)] if ln.rstrip().endswith(delim) else ln for ln in
                     (d.rstrip() for d in batch)]
        block = _parse_batch(p, batch, linenos, delim, decimal, names)
        if n + len(batch) > values.shape[0]:  # an encoding whose line ends are other bytes (EBCDIC)
            grow = max(n + len(batch), 2 * values.shape[0])
            values = _grow(values, grow)
            times = None if times is None else _grow(times, grow)
        values[n:n + len(batch)] = block if tcol is None else block[:, keep]
        if times is not None:
            times[n:n + len(batch)] = block[:, tcol]
        n += len(batch)

    parse(first, first_nos)
    del first, first_nos
    for batch, linenos in content:
        parse(batch, linenos)
    if time_error is not None:
        raise time_error
    values = _trim(values, n)
    fs_file = None
    if tcol is not None:
        if fs is None:
            times = _trim(times, n)
            is_time, unit = _time_unit(names[tcol], units[tcol])
            scale = _time_scale(p, fields[tcol], unit if is_time else units[tcol])
            times *= scale  # in place: the same numbers as times * scale, without a copy
            fs_file = fs_from_time(times, p, tolerance=float(time_tolerance),
                                   what=f"time column {names[tcol]!r}")
            del times
        names = [names[k] for k in keep]
        units = [units[k] for k in keep]
    fs_v = pick_fs(fs, fs_file, p, "no time column found (looked for "
                   f"{', '.join(TIME_COLUMN_NAMES[:3])}, ...; or give time_column=)")
    return Recording.from_arrays(values, fs_v, names=names, units=units, inputs=inputs,
                                 source=str(p))
