"""Run a fragile third-party parser out of process, so that its crash or hang becomes a
``RecordingFileError`` naming the file instead of killing or freezing the caller.

SciPy's MATLAB v5 reader can segfault and HDF5 can loop forever (ignoring Ctrl-C) on a corrupt
file (docs/reliability.md). Design: one helper process per Python process, started on first use
as ``sys.executable -c ...`` (not multiprocessing's spawn/forkserver, which re-import the user's
``__main__`` script in every child), imports numpy, scipy.io and h5py once and forks a fresh
child per file, so each parse costs one fork and starts from clean library state. The helper
enforces the time limit (SIGKILL) and relays the child's pickled result, or reports how it died.
Where ``os.fork`` is missing (Windows) the helper parses in itself and is restarted after a
crash or hang.
"""

from __future__ import annotations

import atexit
import gc
import importlib
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

from .errors import fail

_PRELOAD = ("numpy", "scipy.io", "h5py", "modaluq.io.matlab", "modaluq.io.hdf5")
_LEN = struct.Struct("<Q")


# ---------------------------------------------------------------------------- framing
def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _send(fd: int, payload: bytes) -> None:
    _write_all(fd, _LEN.pack(len(payload)))
    _write_all(fd, payload)


def _read_exact(fd: int, n: int, deadline: float | None = None) -> bytes | None:
    """``n`` bytes from ``fd``; None on EOF; TimeoutError after ``deadline`` (monotonic)."""
    buf = bytearray()
    while len(buf) < n:
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                raise TimeoutError
        chunk = os.read(fd, min(n - len(buf), 1 << 20))
        if not chunk:
            return None
        buf += chunk
    return bytes(buf)


def _recv(fd: int, deadline: float | None = None) -> bytes | None:
    head = _read_exact(fd, _LEN.size, deadline)
    return None if head is None else _read_exact(fd, _LEN.unpack(head)[0], deadline)


# ---------------------------------------------------------------------------- helper side
def _call(ref, args, kwargs) -> bytes:
    """Run ``module:qualname(*args, **kwargs)``; pickled ("ok", result) or ("err", exc)."""
    try:
        func = getattr(importlib.import_module(ref[0]), ref[1])
        out = ("ok", func(*args, **kwargs))
    except BaseException as exc:  # noqa: BLE001 - everything goes back to the caller
        out = ("err", exc)
    try:
        data = pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL)
        pickle.loads(data)  # some exception classes pickle but cannot be rebuilt
        return data
    except Exception as exc:  # noqa: BLE001
        what = f"{type(out[1]).__name__}: {out[1]}" if out[0] == "err" else \
            f"unpicklable result ({exc})"
        return pickle.dumps(("err", RuntimeError(what)))


def _run_forked(ref, args, kwargs, timeout: float, fd_out: int) -> None:
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: parse, send the result, exit without cleanup handlers
        try:
            gc.disable()  # short-lived: a collection would only copy pages
            os.close(r)
            _send(w, _call(ref, args, kwargs))
        finally:
            os._exit(0)
    os.close(w)
    try:
        reply = _recv(r, time.monotonic() + timeout)
    except TimeoutError:
        os.kill(pid, signal.SIGKILL)
        reply = pickle.dumps(("timeout", timeout))
    finally:
        os.close(r)
    if reply is not None:  # a complete answer: reply before the child has finished exiting
        _send(fd_out, reply)
    status = os.waitpid(pid, 0)[1]
    if reply is None:  # no complete answer: say how the child ended
        _send(fd_out, pickle.dumps(("signal", os.WTERMSIG(status)) if os.WIFSIGNALED(status)
                                   else ("exit", os.WEXITSTATUS(status))))


def _serve() -> None:
    """Helper main loop: requests on stdin, replies on stdout (fd 1 then goes to stderr, so a
    library that prints cannot corrupt the protocol)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the caller decides what Ctrl-C kills
    fd_in, fd_out = sys.stdin.fileno(), os.dup(sys.stdout.fileno())
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    for mod in _PRELOAD:
        try:
            importlib.import_module(mod)
        except ImportError:
            pass
    gc.freeze()  # children's collections then leave the preloaded objects' pages unshared
    _send(fd_out, b"ready")
    while True:
        req = _recv(fd_in)
        if req is None:
            return
        ref, args, kwargs, timeout = pickle.loads(req)
        if hasattr(os, "fork"):
            _run_forked(ref, args, kwargs, timeout, fd_out)
        else:  # the parent enforces the time limit by killing us
            _send(fd_out, _call(ref, args, kwargs))


# ---------------------------------------------------------------------------- caller side
_LOCK = threading.Lock()
_helper: subprocess.Popen | None = None
_helper_pid_owner = None


def _stop() -> None:
    global _helper
    h, _helper = _helper, None
    if h is None or _helper_pid_owner != os.getpid():
        return
    try:
        if hasattr(os, "killpg"):
            os.killpg(h.pid, signal.SIGKILL)  # the helper and a child it is waiting for
        else:
            h.kill()
    except OSError:
        pass
    for f in (h.stdin, h.stdout):
        f.close()
    h.wait()


def _start() -> subprocess.Popen:
    global _helper, _helper_pid_owner
    # modaluq.io imports nothing from the rest of the package: a bare package stub skips
    # modaluq/__init__ (scipy.signal...), which halves the helper's memory and so the fork time
    pkg = str(Path(__file__).resolve().parents[1])
    code = ("import sys, types; m = types.ModuleType('modaluq'); "
            f"m.__path__ = [{pkg!r}]; sys.modules['modaluq'] = m; "
            "from modaluq.io._isolate import _serve; _serve()")
    kw = {"start_new_session": True} if os.name == "posix" else {}
    h = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, **kw)
    _helper, _helper_pid_owner = h, os.getpid()
    if _recv(h.stdout.fileno(), time.monotonic() + 120) != b"ready":
        _stop()
        raise OSError("the modaluq.io parser helper process failed to start (see its error "
                      "above); isolate=False parses in this process")
    return h


atexit.register(lambda: _stop())


def run(func, path, what: str, *args, timeout: float, **kwargs):
    """``func(*args, **kwargs)`` in a forked child of the helper; its return value (pickled).

    Exceptions raised by ``func`` are re-raised here. A crash, a non-zero exit or a run over
    ``timeout`` seconds raises ``RecordingFileError("<path>: the <what> parser ...")``.
    """
    ref = (func.__module__, func.__qualname__)
    req = pickle.dumps((ref, args, kwargs, float(timeout)), protocol=pickle.HIGHEST_PROTOCOL)
    with _LOCK:
        try:
            if _helper is None or _helper_pid_owner != os.getpid() or _helper.poll() is not None:
                _start()
            _send(_helper.stdin.fileno(), req)
            reply = _recv(_helper.stdout.fileno(), time.monotonic() + timeout + 30)
        except TimeoutError:
            _stop()
            reply = pickle.dumps(("timeout", timeout))
        except BaseException:  # Ctrl-C or a broken pipe: the protocol state is unknown
            _stop()
            raise
        if reply is None:  # the helper itself died (no fork: the parser took it down)
            code = _helper.wait()
            _stop()
            reply = pickle.dumps(("signal", -code) if code < 0 else ("exit", code))
    kind, value = pickle.loads(reply)
    if kind == "ok":
        return value
    if kind == "err":
        raise value
    if kind == "signal":
        try:
            name = signal.Signals(value).name
        except ValueError:
            name = "unknown"
        raise fail(path, f"the {what} parser crashed (signal {value}, {name}): the file is "
                         "corrupt or triggers a bug in the parser; nothing was loaded")
    if kind == "timeout":
        raise fail(path, f"the {what} parser did not finish within {value:.0f} s (corrupt file?); "
                         "it was stopped. The limit grows with the file's size up to "
                         "modaluq.io.PARSE_TIMEOUT (docs/reliability.md); isolate=False parses "
                         "without a limit")
    raise fail(path, f"the {what} parser exited unexpectedly (status {value})")
