"""Part files: every finished record kept on disk as soon as it arrives, so that a run restarts
where it stopped (docs/monitoring.md §1).

One JSON file per record in ``<store stem>.parts/``, named by a hash of the record's key, written
atomically by the driver process (a killed run leaves whole parts only); ``settings.json``
holds the fingerprint of the settings the parts were made with, and a run with other settings
refuses to mix them. A part holds plain values (:func:`jsonable`): the status, the failed stage
and its error, or the selected modes and their poles (:func:`record_modes` reads them back).

A part says "done" about bytes, not a path: it keeps the settings' hash it was made with and the
file's size, mtime and SHA-256 (:mod:`~modaluq.monitoring.worker`); :meth:`Parts.done` uses it
only while both still hold. One run at a time on a store: :func:`store_lock`.
"""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import json
import os
import shlex
import socket
import sys
from pathlib import Path

import numpy as np

from ..jsonvalues import dumps
from .records import file_sha256, file_state
from .tracking import RecordModes

__all__ = ["Parts", "StoreInUseError", "array_of", "record_modes", "store_lock"]


class StoreInUseError(RuntimeError):
    """Another run holds the store's lock (:func:`store_lock`); the message names it."""


@contextlib.contextmanager
def store_lock(store, command: str | None = None):
    """Hold the lock of the store ``store`` (the file ``<stem>.lock`` beside it, shared by the
    ``.nc`` and ``.zarr`` stores of one stem, like their parts) for the ``with`` block: an
    exclusive ``flock``, so a second run on the store is refused (:class:`StoreInUseError` naming
    the holder: pid, host, start, command) and the lock of a killed run is released with its
    process (the file left behind does not block). Where ``flock`` is missing (Windows) or the
    file system refuses it, the run goes on unlocked. The file is kept: deleting a lock file lets
    two runs hold two files of one name."""
    store = Path(store)
    path = store.with_name(store.stem + ".lock")
    try:
        import fcntl
    except ImportError:  # no flock here: concurrent runs are not detected
        yield
        return
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            locked = True
        except BlockingIOError:
            holder = " ".join(os.pread(fd, 4096, 0).decode(errors="replace").split()) or "holder not yet written"
            raise StoreInUseError(f"the store {store} is in use by another run: {holder} (lock file "
                                  f"{path}); wait for it to finish, or write to another store") from None
        except OSError:  # a file system without locks (some network mounts): go on unlocked
            locked = False
        if not locked:
            yield
            return
        started = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
        command = command if command is not None else shlex.join([os.path.basename(sys.argv[0] or "python")]
                                                                 + sys.argv[1:])
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()} since {started}: {command}\n".encode(), 0)
        try:
            yield
        finally:
            os.ftruncate(fd, 0)  # released: the file names no holder
    finally:
        os.close(fd)  # releases the flock


class Parts:
    """One file per record in ``folder``, written atomically; ``settings.json`` guards the mix
    (``config``: the records' :class:`~modaluq.monitoring.worker.TaskConfig`, by its fingerprint)."""

    def __init__(self, folder: Path, config, start_again: bool = False):
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        _remove_stale_temporaries(folder)
        stamp = folder / "settings.json"
        fingerprint = json.loads(dumps(config.fingerprint()))
        if start_again:  # resume=False: the parts of earlier runs (perhaps other settings) are dropped
            for old in folder.glob("*.json"):
                old.unlink()
        previous = None
        if stamp.exists():
            try:
                previous = json.loads(stamp.read_text())
            except ValueError:
                pass
        if previous != fingerprint:
            # other settings: refused where parts were made with them; a folder without any part
            # (no stamp, or a run that stopped before its first part) takes these
            if stamp.exists() and any(p.name != stamp.name for p in folder.glob("*.json")):
                changed = _changed_keys(previous, fingerprint)
                raise ValueError(f"the part files in {folder} were made with other settings ({', '.join(changed)} "
                                 "differ); run again with resume=False (--no-resume) to start again with these "
                                 "settings, or write to another store")
            _atomic_write(stamp, dumps(fingerprint, indent=1).encode())

    def path(self, key: str) -> Path:
        return self.folder / f"{hashlib.sha1(key.encode()).hexdigest()[:20]}.json"

    def read(self, key: str):
        p = self.path(key)
        try:
            part = json.loads(p.read_text())
        except (OSError, ValueError):
            return None  # absent (or, impossibly with atomic writes, torn): run it again
        return part if part.get("key") == key else None

    def done(self, task, settings_id: str):
        """The part of ``task`` (a :class:`~modaluq.monitoring.records.RecordTask`) when it says
        *done* about what the record is now, else None (run it): made with the settings of
        ``settings_id`` (:meth:`~modaluq.monitoring.worker.TaskConfig.fingerprint_id`) and, for a
        file, from its bytes: the same size and mtime, or else the same SHA-256 (a file touched or
        copied again; its part is brought up to date, so the file is hashed once)."""
        part = self.read(task.key)
        if part is None or part.get("status") != "done" or part.get("settings") != settings_id:
            return None
        if not isinstance(task.source, str):
            return part
        read, now = part.get("file"), file_state(task.source)
        if not isinstance(read, dict) or now is None:
            return None  # a part of an older modaluq (bytes unknown), or a file gone: run it again
        if (read.get("size"), read.get("mtime_ns")) == now:
            return part
        try:
            same = now[0] == read.get("size") and file_sha256(task.source) == read.get("sha256")
        except OSError:
            return None
        if not same:
            return None
        part["file"] = dict(read, mtime_ns=now[1])
        self.write(task.key, dumps(part))
        return part

    def write(self, key: str, text: str) -> None:
        """Write the part of ``key`` (``text``: its JSON)."""
        _atomic_write(self.path(key), text.encode())


def _changed_keys(old, new, prefix="") -> list:
    """The dotted keys whose values differ between two fingerprints (e.g. ``settings.frequency_range``)."""
    if not isinstance(old, dict) or not isinstance(new, dict):
        return [prefix or "the file"] if old != new else []
    keys = sorted(set(old) | set(new))
    return [c for k in keys for c in _changed_keys(old.get(k), new.get(k), f"{prefix}{k}" if not prefix
                                                   else f"{prefix}.{k}")]


def _remove_stale_temporaries(folder: Path) -> None:
    """Delete the half-written ``.<part>.<pid>.tmp`` files of writers that were killed: their
    records have no part and run again. A file of a process still alive on this machine is kept
    (two runs on one store are not supported, but one must not break the other's write)."""
    for tmp in folder.glob(".*.tmp"):
        try:
            pid = int(tmp.name.rsplit(".", 2)[-2])
        except ValueError:
            pid = None
        if pid is not None and pid != os.getpid() and _process_alive(pid):
            continue
        with contextlib.suppress(OSError):
            tmp.unlink()


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists, another user's
    return True


def _atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def array_of(value, dtype=float):
    if isinstance(value, dict) and set(value) == {"real", "imag"}:
        return np.asarray(value["real"], float) + 1j * np.asarray(value["imag"], float)
    return np.asarray(value, dtype)


def record_modes(part: dict) -> RecordModes:
    """The selected modes of a part (a record identified), as tracking reads them."""
    m = part["modes"]
    return RecordModes(**{k: array_of(m[k], complex if k == "mode_shape" else float) for k in (
        "frequency_hz", "damping_ratio", "frequency_std", "damping_std", "frequency_damping_correlation",
        "mode_shape", "mode_shape_std_real", "mode_shape_std_imag")})
