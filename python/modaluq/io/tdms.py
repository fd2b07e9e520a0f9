"""LabVIEW TDMS loader (npTDMS)."""

from __future__ import annotations

import logging
import struct

import numpy as np

from ._common import check_fs_arg, check_path, fail, fs_from_increment, fs_from_time, optional_import, pick_fs, reading
from .recording import Recording

__all__ = ["read_tdms"]

_TIME_NAMES = ("time", "t", "time_s", "timestamp")
_UNIT_PROPS = ("unit_string", "NI_UnitDescription", "unit", "units")


class _Collect(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(record.getMessage())


_LEAD_IN = 28
_TOC_BIG_ENDIAN = 1 << 6
_UNFINISHED = 0xFFFFFFFFFFFFFFFF


def _segment_problem(p) -> str | None:
    """Walk the chain of segment lead-ins; describe the first incomplete or corrupt one.

    npTDMS treats a lead-in cut short as the end of the file and only logs a cut inside the
    metadata, so a truncated file would silently lose its last segments."""
    size = p.stat().st_size
    pos = k = 0
    with open(p, "rb") as fh:
        while pos < size:
            fh.seek(pos)
            lead = fh.read(_LEAD_IN)
            where = f"segment {k} (byte {pos})"
            if len(lead) < _LEAD_IN:
                return f"{where} is cut short inside its lead-in ({len(lead)} of 28 bytes)"
            if lead[:4] != b"TDSm":
                return f"{where} does not start with 'TDSm' (corrupt)"
            endian = ">" if struct.unpack("<l", lead[4:8])[0] & _TOC_BIG_ENDIAN else "<"
            _, next_off, raw_off = struct.unpack(endian + "lQQ", lead[8:28])
            if next_off == _UNFINISHED:
                return f"{where} was never finished by the writer (length -1)"
            if raw_off > next_off:
                return f"{where} has its data offset past its end (corrupt)"
            if pos + _LEAD_IN + next_off > size:
                return (f"{where} declares {next_off} bytes but the file ends "
                        f"{size - pos - _LEAD_IN} bytes into it")
            pos += _LEAD_IN + next_off
            k += 1
    return None


def read_tdms(path, *, fs=None, inputs=None, group=None, channels=None, time_tolerance=0.01
              ) -> Recording:
    """Read the channels of one group of a TDMS file.

    Parameters
    ----------
    group : str, optional
        Group name; default the first group of the file.
    channels : list of str, optional
        Channel names to read (in this order); default all channels of the group except a
        time channel (named ``Time``/``t``, case-insensitive) when fs comes from it.
    fs : float, optional
        Overrides the file. Otherwise ``1 / wf_increment`` (channel property, equal for all
        channels), else a time channel of the group.
    inputs : list of str/int, optional
        Known inputs by channel name or index (among the channels read).

    Units come from the ``unit_string`` channel property. A truncated or unfinished file (any
    segment cut short, which npTDMS would skip silently) and channels of different lengths
    raise ValueError; the message says how many samples the complete part holds.
    """
    p = check_path(path)
    check_fs_arg(fs)
    if group is not None and not isinstance(group, str):
        raise TypeError(f"group must be a str or None, got {type(group).__name__}")
    if channels is not None and (isinstance(channels, str) or not isinstance(channels, (list, tuple))
                                 or not channels or
                                 not all(isinstance(c, str) for c in channels)):
        raise TypeError(f"channels must be a non-empty list of str, got {channels!r}")
    nptdms = optional_import("nptdms", "npTDMS", "TDMS")

    with open(p, "rb") as fh:
        if fh.read(4) != b"TDSm":
            raise fail(p, "not a TDMS file (does not start with 'TDSm')")
    problem = _segment_problem(p)
    handler = _Collect()
    log = logging.getLogger("nptdms")
    log.addHandler(handler)
    try:
        with reading(p, "TDMS file" + (f" ({problem})" if problem else "")):
            tf = nptdms.TdmsFile.read(str(p))
            groups = tf.groups()
            if not groups:
                raise fail(p, "the TDMS file has no groups")
            if group is None:
                g = groups[0]
            else:
                try:
                    g = tf[group]
                except KeyError:
                    raise fail(p, f"group {group!r} not found (groups: "
                                  f"{', '.join(repr(x.name) for x in groups)})") from None
            all_ch = g.channels()
            if not all_ch:
                raise fail(p, f"group {g.name!r} has no channels")
            by_name = {c.name: c for c in all_ch}
            if channels is not None:
                missing = [c for c in channels if c not in by_name]
                if missing:
                    raise fail(p, f"channel(s) {missing} not in group {g.name!r} (channels: "
                                  f"{', '.join(map(repr, by_name))})")
                chans = [by_name[c] for c in channels]
            else:
                chans = list(all_ch)
            tchan = None
            if channels is None:
                for c in chans:
                    if c.name.lower() in _TIME_NAMES:
                        tchan = c
                        break
            arrays, incs = {}, []
            for c in chans:
                arr = c[:]
                arrays[c.name] = arr
                if "wf_increment" in c.properties:
                    incs.append((c.name, c.properties["wf_increment"]))
    finally:
        log.removeHandler(handler)
    if problem:
        counts = sorted({len(a) for a in arrays.values()})
        readable = " or ".join(map(str, counts)) if counts else "no"
        raise fail(p, f"truncated or incomplete TDMS file: {problem}; the complete part holds "
                      f"{readable} samples per channel of group {g.name!r}; nothing was loaded")
    trunc = [m for m in handler.messages if "less data than expected" in m or "incomplete" in m
             or "not a multiple of the chunk size" in m or "truncat" in m.lower()]
    if trunc:
        raise fail(p, f"file is truncated or incomplete (npTDMS: {trunc[0]})")

    data_ch = [c for c in chans if c is not tchan]
    if not data_ch:
        raise fail(p, f"group {g.name!r} has only a time channel")
    for c in data_ch:
        a = np.asarray(arrays[c.name])
        if a.dtype.kind not in "iuf":
            raise fail(p, f"channel {c.name!r} has dtype {a.dtype}; real numbers needed (select "
                          "channels with channels=)")
    lens = {len(arrays[c.name]) for c in data_ch}
    if len(lens) != 1:
        raise fail(p, f"channels of group {g.name!r} have different lengths (" + ", ".join(
            f"{c.name}: {len(arrays[c.name])}" for c in data_ch) + "); truncated file?")
    n = lens.pop()
    if n == 0:
        raise fail(p, f"channels of group {g.name!r} hold no data")

    fs_file = None
    if fs is None:
        inc_data = [(nm, v) for nm, v in incs if tchan is None or nm != tchan.name]
        if inc_data:
            ref = float(inc_data[0][1])
            for nm, v in inc_data[1:]:
                if abs(float(v) - ref) > 1e-9 * abs(ref):
                    raise fail(p, f"channels have different wf_increment: {inc_data[0][0]!r} "
                                  f"{ref:g} s vs {nm!r} {float(v):g} s")
            fs_file = fs_from_increment(ref, p, "wf_increment")
        elif tchan is not None:
            tv = np.asarray(arrays[tchan.name])
            if tv.dtype.kind == "M":
                tv = (tv - tv[0]) / np.timedelta64(1, "ns") * 1e-9
            fs_file = fs_from_time(tv, p, tolerance=time_tolerance,
                                   what=f"time channel {tchan.name!r}")
    fs_v = pick_fs(fs, fs_file, p, "no wf_increment property and no time channel")

    names = [c.name for c in data_ch]
    units = []
    for c in data_ch:
        u = ""
        for k in _UNIT_PROPS:
            if k in c.properties:
                u = str(c.properties[k])
                break
        units.append(u)
    samples = np.column_stack([np.asarray(arrays[c.name], dtype=np.float64) for c in data_ch])
    return Recording.from_arrays(samples, fs_v, names=names, units=units, inputs=inputs,
                                 source=str(p))
