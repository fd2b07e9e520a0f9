"""What this installation runs: :func:`show_config` (``modaluq.show_config()``).

The C++ core's CPU path and why it was chosen (``_dispatch``), the compile flags of every path
of the build, Eigen, the BLAS doing the core's large products and its threads, Python and
NumPy. ``modaluq --version`` prints the path (:func:`core_summary`).
"""

from __future__ import annotations

import os
import platform
import sys

from . import _core, _dispatch
from .version import __version__, core_version

__all__ = ["core_summary", "show_config"]


def _choice() -> dict:
    c = _dispatch.choice
    if c is None:  # an extension named _core*.so in the package shadows _core.py: no dispatch
        return {"path": getattr(_core, "cpu_path", "unknown"), "module": _core.__name__,
                "reason": f"a single-build extension ({os.path.basename(getattr(_core, '__file__', '') or '?')}) "
                          "shadows the dispatcher", "forced": False, "available": [], "features": {},
                "detected_by": ""}
    return {"path": c.path, "module": c.module, "reason": c.reason, "forced": c.forced,
            "available": list(c.available), "features": dict(c.features), "detected_by": c.detected_by}


def core_summary() -> str:
    """One line: the core's CPU path and why, e.g. ``x86-64-v3 (this CPU supports x86-64-v3 (...))``."""
    c = _choice()
    return f"{c['path']} ({c['reason']})"


def _blas() -> dict:
    """The BLAS libraries loaded in this process (threadpoolctl), the core's marked."""
    from threadpoolctl import threadpool_info  # here only: `import modaluq` stays light

    core_lib = getattr(_core, "blas_library", "")
    core_real = os.path.realpath(core_lib) if core_lib else ""
    libraries = []
    for info in threadpool_info():
        if info.get("user_api") != "blas":
            continue
        path = info.get("filepath", "")
        libraries.append({"library": info.get("internal_api"), "version": info.get("version"),
                          "threads": info.get("num_threads"), "threading_layer": info.get("threading_layer"),
                          "architecture": info.get("architecture"), "filepath": path,
                          "used_by_core": bool(core_real) and os.path.realpath(path) == core_real})
    return {"core_uses_blas": bool(getattr(_core, "uses_blas", False)), "core_library": core_lib,
            "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"), "libraries": libraries}


def show_config(file=None) -> dict:
    """Print what this installation runs and return it as a dict.

    Keys: ``modaluq`` (version, core version), ``core`` (the CPU path running, the module, why it
    was chosen, whether ``MODALUQ_CPU`` forced it, the paths installed, the CPU's features and how
    they were read), ``builds`` (compiler and flags of every path of the build), ``eigen`` (version,
    the SIMD sets compiled into the running core), ``blas`` (whether the core's large products go
    through a BLAS, its file, every BLAS library loaded with version and threads), ``python``,
    ``numpy``, ``machine``.

    >>> import io, modaluq
    >>> config = modaluq.show_config(file=io.StringIO())
    >>> config["core"]["path"] in ("baseline", "x86-64-v3", "native")
    True
    """
    import numpy

    out = {
        "modaluq": {"version": __version__, "core_version": core_version},
        "core": {**_choice(), "MODALUQ_CPU": os.environ.get(_dispatch.ENV)},
        "builds": dict(getattr(_core, "builds", {})),
        "eigen": {"version": getattr(_core, "eigen_version", None), "simd": getattr(_core, "eigen_simd", None)},
        "blas": _blas(),
        "python": {"version": platform.python_version(), "implementation": platform.python_implementation(),
                   "executable": sys.executable},
        "numpy": {"version": numpy.__version__},
        "machine": {"architecture": platform.machine(), "system": platform.system()},
    }
    (file or sys.stdout).write(_text(out))
    return out


def _text(c: dict) -> str:
    core, blas = c["core"], c["blas"]
    lines = [f"modaluq {c['modaluq']['version']} (C++ core {c['modaluq']['core_version']})",
             f"CPU path:  {core['path']} ({core['module']})",
             f"  why:     {core['reason']}"]
    if core["features"]:
        have = [f for f, ok in core["features"].items() if ok]
        lacks = [f for f, ok in core["features"].items() if not ok]
        lines.append(f"  CPU:     {', '.join(have) or '-'}" + (f"; lacks {', '.join(lacks)}" if lacks else "")
                     + f" ({core['detected_by']})")
    if core["MODALUQ_CPU"] is not None:
        lines.append(f"  {_dispatch.ENV}: {core['MODALUQ_CPU']}")
    elif "baseline" in core["available"] and core["path"] != "baseline":
        lines.append(f"  {_dispatch.ENV}: unset ({_dispatch.ENV}=baseline forces the baseline core)")
    lines.append("builds:")
    width = max((len(p) for p in c["builds"]), default=0)
    for path, flags in c["builds"].items():
        lines.append(f"  {path + ':':<{width + 1}} {flags}" + ("   <- running" if path == core["path"] else ""))
    lines.append(f"Eigen:     {c['eigen']['version']} (running core: {c['eigen']['simd']})")
    if blas["core_uses_blas"]:
        lines.append(f"BLAS:      the core's large products through {blas['core_library'] or 'a BLAS'} "
                     "(MODALUQ_USE_BLAS)")
    else:
        lines.append("BLAS:      the core's products are Eigen's (built without MODALUQ_USE_BLAS)")
    for lib in blas["libraries"]:
        lines.append(f"  {lib['library']} {lib['version']}, {lib['threads']} threads"
                     + (f" ({lib['threading_layer']})" if lib["threading_layer"] not in (None, "disabled") else "")
                     + f": {lib['filepath']}" + ("  <- the core's" if lib["used_by_core"] else ""))
    if blas["core_uses_blas"]:
        lines.append("  modaluq's compute calls run it on 1 thread" + (
            f" (OPENBLAS_NUM_THREADS={blas['OPENBLAS_NUM_THREADS']} is set: that value instead)"
            if blas["OPENBLAS_NUM_THREADS"] is not None else " (OPENBLAS_NUM_THREADS unset)"))
    lines.append(f"Python:    {c['python']['version']} ({c['python']['implementation']}), "
                 f"NumPy {c['numpy']['version']}, {c['machine']['system']} {c['machine']['architecture']}")
    return "\n".join(lines) + "\n"
