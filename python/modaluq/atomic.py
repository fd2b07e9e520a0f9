"""How the package writes its output files: atomically, and CSV cells that cannot run as formulas.

**Atomic.** An output (a file, or a directory such as a Zarr store) is written to a temporary
beside it, ``<name>.tmp-<pid>``, and put in place by a rename only once it is complete
(:func:`write_temporary`, then :func:`commit`; :func:`write_atomically` does both). A reader
sees the previous output or the new one, never a part of one. A directory cannot replace
another in one rename, so :func:`commit` swaps it with two: the old one to ``<name>.old-<pid>``,
the new one into place, then the old one removed; :func:`recover` puts a ``.old-<pid>`` back if a
writer died between the two renames, and removes the temporaries of writers no longer alive.
A failed write removes its temporary and raises :class:`OSError` naming the output; the
previous output is left as it was. The temporaries carry the writer's pid, so two processes
writing the same output do not write into each other's temporary (which one's output is left
is the later commit's).

**CSV cells.** A cell that starts with ``=``, ``+``, ``-``, ``@``, a tab or a carriage return
is taken by a spreadsheet as a formula (a record named ``=HYPERLINK(...)``); :func:`csv_cell`
prefixes such text with a single quote (OWASP's "CSV injection" rule). Numbers, and text that
reads as one (``-0.5``), are left as they are.

>>> csv_cell("=1+2"), csv_cell("-0.5"), csv_cell(-0.5), csv_cell("record_1")
("'=1+2", '-0.5', -0.5, 'record_1')
"""

from __future__ import annotations

import errno
import gc
import os
import re
import shutil
import traceback
from pathlib import Path

__all__ = ["FORMULA_STARTS", "commit", "csv_cell", "csv_safe", "discard", "recover", "temporary",
           "write_atomically", "write_temporary"]

#: first characters that make a spreadsheet read a cell as a formula
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value):
    """``value`` as a CSV cell that no spreadsheet runs as a formula: text starting with one of
    :data:`FORMULA_STARTS` gets a leading ``'``, unless it reads as a number; anything else as is."""
    if not isinstance(value, str) or not value.startswith(FORMULA_STARTS):
        return value
    try:
        float(value)
        return value  # a number written as text (-0.5, +1e3) is a number, not a formula
    except ValueError:
        return "'" + value


def csv_safe(frame):
    """A copy of a :class:`pandas.DataFrame` with its text cells (and a text index) passed through
    :func:`csv_cell`; numeric columns untouched. What every ``to_csv`` of the package writes."""
    out = frame.copy()
    for name in out.columns:
        if out[name].dtype.kind not in "biufcmM":  # text (object or string dtype): numbers and times as they are
            out[name] = out[name].map(csv_cell)
    if out.index.dtype.kind not in "biufcmM":
        out.index = out.index.map(csv_cell)
    return out


def temporary(path, kind: str = "tmp") -> Path:
    """The temporary of this process beside ``path``: ``<name>.<kind>-<pid>``."""
    path = Path(path)
    return path.with_name(f"{path.name}.{kind}-{os.getpid()}")


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            path.unlink()
        except FileNotFoundError:
            pass


def discard(tmp) -> None:
    """Remove a temporary (file or directory), if it exists."""
    _remove(Path(tmp))


def _fsync_tree(path: Path) -> None:
    """Flush a file, or every file of a directory, to the disk (a rename is only as durable as this)."""
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    for f in files:
        fd = os.open(f, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


#: Free bytes below which a writer's failure that is no OSError (netCDF says "NetCDF: HDF error")
#: is reported as the full disk it is.
FULL_DISK_BYTES = 1 << 16


def _disk_full(folder: Path) -> bool:
    try:
        return shutil.disk_usage(folder).free < FULL_DISK_BYTES
    except OSError:
        return False


def _failure(path: Path, exc: BaseException, *, disk_full: bool = False) -> OSError:
    """An :class:`OSError` (of ``exc``'s class when it is one) naming ``path``; ``exc`` becomes its cause.
    ``disk_full``: the writer's own error hid a full disk (ENOSPC)."""
    what = exc.strerror if isinstance(exc, OSError) and exc.strerror else f"{type(exc).__name__}: {exc}"
    if disk_full:
        what = f"No space left on device: {what}"
    message = f"{path}: cannot write it ({what}); the previous {path.name}, if any, is left as it was"
    code = errno.ENOSPC if disk_full else getattr(exc, "errno", None)
    cls = type(exc) if isinstance(exc, OSError) else OSError
    try:
        return cls(code, message) if code is not None else cls(message)
    except TypeError:  # an OSError subclass with another constructor
        return OSError(code, message) if code is not None else OSError(message)


def write_temporary(path, writer) -> Path:
    """Call ``writer(tmp)`` to write ``path``'s content into its temporary (:func:`temporary`) and
    return ``tmp``; nothing is put in place yet (:func:`commit`). If ``writer`` fails (full disk:
    ENOSPC, or any other error) the temporary is removed and an :class:`OSError` naming ``path``
    is raised, with the writer's error as its cause."""
    path = Path(path)
    tmp = temporary(path)
    _remove(tmp)  # a leftover of a dead process that had this pid
    try:
        writer(tmp)
        _fsync_tree(tmp)
    except BaseException as exc:
        full = not isinstance(exc, OSError) and _disk_full(tmp.parent)  # before the temporary gives space back
        _release(exc)
        _remove(tmp)
        _free_held(tmp)
        if not isinstance(exc, Exception):  # Ctrl-C: not a write error
            raise
        raise _failure(path, exc, disk_full=full) from exc
    return tmp


def _release(exc: BaseException) -> None:
    """Let go of what the failed writer still holds open. Its frames, kept alive by the exception's
    traceback, reference its file objects (a netCDF4 dataset whose close failed on a full disk keeps
    the temporary's space even after it is removed, so the next output fails for want of space):
    clear those frames and collect, which closes them."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        traceback.clear_frames(exc.__traceback__)
        exc = exc.__cause__ or exc.__context__
    gc.collect()


def _free_held(tmp: Path) -> None:
    """Give back the space of a removed temporary that a library still holds open. netCDF's C
    library keeps its file open when closing fails on a full disk, and no Python object is left to
    close it: the space would stay in use until the process ends (a notebook, a service), and the
    outputs written after the failure would fail too. Linux names such a descriptor in /proc;
    truncating the removed file through it frees the space (nothing can read it any more)."""
    fds = Path("/proc/self/fd")
    if not fds.is_dir():
        return
    target = os.path.abspath(tmp)
    for fd in fds.iterdir():
        try:
            link = os.readlink(fd)
            if link in (target, f"{target} (deleted)") and not os.path.exists(target):
                os.ftruncate(int(fd.name), 0)
        except (OSError, ValueError):
            continue


def commit(tmp, path) -> Path:
    """Put a complete temporary in place of ``path``. A file: one rename (:func:`os.replace`). A
    directory: the old one renamed to ``<name>.old-<pid>``, ``tmp`` renamed to ``path``, the old
    one removed, so that at every moment ``path`` or its ``.old-<pid>`` is a complete output."""
    tmp, path = Path(tmp), Path(path)
    if not tmp.is_dir():
        os.replace(tmp, path)
    else:
        old = temporary(path, "old")
        for _ in range(100):  # another writer may put its own in place between our two renames
            _remove(old)
            try:
                os.rename(path, old)
            except FileNotFoundError:
                pass
            try:
                os.rename(tmp, path)
                break
            except OSError:  # ENOTEMPTY / EEXIST: a concurrent writer's output is there now
                if not path.exists():
                    raise
        else:
            raise OSError(f"{path}: cannot put the new output in place, other writers keep replacing it")
        _remove(old)
    _fsync_dir(path.parent)
    return path


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems cannot sync a directory; the rename is done all the same
        pass
    finally:
        os.close(fd)


def write_atomically(path, writer) -> Path:
    """:func:`write_temporary` then :func:`commit`: ``path`` is the old content or the new, never a part."""
    return commit(write_temporary(path, writer), path)


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return False  # a leftover of a dead process that had our pid: we write one output at a time
    if os.name == "nt":
        return True  # Windows' os.kill(pid, 0) would end the process: a leftover there is left alone
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # exists, another user's
    return True


def recover(path) -> list:
    """Clean up after writers of ``path`` that died: if ``path`` is missing, the newest
    ``<name>.old-<pid>`` of a dead writer is put back (it died between the two renames of
    :func:`commit`); the other ``.tmp-<pid>`` / ``.old-<pid>`` of dead writers are removed, as are
    the temporaries of earlier versions (``.<name>.<pid>.tmp``). Returns what was done, one line each."""
    path = Path(path)
    pattern = re.compile(rf"^(?:{re.escape(path.name)}\.(tmp|old)-(\d+)|\.{re.escape(path.name)}\.(\d+)\.tmp)$")
    found = []
    try:
        names = os.listdir(path.parent)
    except FileNotFoundError:
        return []
    for name in names:
        m = pattern.match(name)
        if m:
            kind, pid = (m.group(1), int(m.group(2))) if m.group(1) else ("tmp", int(m.group(3)))
            if not _alive(pid):
                found.append((kind, path.parent / name))
    done = []
    olds = sorted((p for kind, p in found if kind == "old"), key=lambda p: p.stat().st_mtime, reverse=True)
    if olds and not path.exists():
        os.rename(olds[0], path)
        done.append(f"{path}: put back from {olds[0].name}, left by a writer that died")
        found = [(k, p) for k, p in found if p != olds[0]]
    for _, p in found:
        _remove(p)
        done.append(f"{p}: removed, the temporary of a writer that died")
    return done
