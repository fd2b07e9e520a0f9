"""Which build of the C++ core this process runs (docs/architecture.md, "The C++ core's CPU paths").

The core is compiled once per CPU path (bindings/CMakeLists.txt): ``baseline`` (the compiler's
default: SSE2 on x86-64), ``x86-64-v3`` (AVX2, FMA, BMI1/2, F16C, MOVBE, LZCNT; x86-64 only) or,
in a ``MODALUQ_NATIVE=ON`` build, ``native`` alone. :func:`load` picks one from the CPU's features
as NumPy and SciPy do, and ``_core.py`` makes it ``modaluq._core``. The environment variable
``MODALUQ_CPU`` overrides the choice: ``baseline`` forces the baseline, ``x86-64-v3`` forces that
path (an error if this CPU cannot run it). Only one core can be loaded in a process: pybind11
registers the core's C++ types once, so a second core fails to import (the tests compare the paths
in child processes).

The CPU's features come from ``modaluq._core_cpuinfo`` (libgcc's ``__builtin_cpu_supports``, which
counts AVX only when the OS saves its registers), else from the ``flags`` of ``/proc/cpuinfo``
(Linux lists AVX only when the OS enables it).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import platform
from dataclasses import dataclass, field

ENV = "MODALUQ_CPU"

#: Each path and its module, in the order of preference (the first this CPU runs wins).
MODULES = {"native": "_core_native", "x86-64-v3": "_core_x86_64_v3", "baseline": "_core_baseline"}

#: What x86-64-v3 code may use, in libgcc's names (movbe, lzcnt and the level as a whole only
#: where the compiler can ask: GCC >= 12).
X86_64_V3 = ("sse3", "ssse3", "sse4.1", "sse4.2", "popcnt", "avx", "avx2", "fma", "bmi", "bmi2", "f16c",
             "movbe", "lzcnt", "x86-64-v3")

#: libgcc's names of the /proc/cpuinfo flags (the fallback).
_CPUINFO_FLAGS = {"pni": "sse3", "ssse3": "ssse3", "sse4_1": "sse4.1", "sse4_2": "sse4.2", "popcnt": "popcnt",
                  "avx": "avx", "avx2": "avx2", "fma": "fma", "bmi1": "bmi", "bmi2": "bmi2", "f16c": "f16c",
                  "movbe": "movbe", "abm": "lzcnt"}


@dataclass(frozen=True)
class Choice:
    """The core's path this process runs, and why."""

    path: str  #: ``baseline``, ``x86-64-v3`` or ``native``
    module: str  #: the extension module's own name, e.g. ``modaluq._core_x86_64_v3``
    reason: str  #: why this path, in words
    forced: bool  #: chosen by ``MODALUQ_CPU`` rather than from the CPU
    available: tuple  #: the paths this install holds
    features: dict = field(default_factory=dict)  #: {feature: bool} as detected ({}: not asked or unknown)
    detected_by: str = ""  #: ``__builtin_cpu_supports`` or ``/proc/cpuinfo`` ("" if not asked)


#: Set by :func:`load`.
choice: Choice | None = None


def available_paths() -> tuple:
    """The paths whose core this install holds, most capable first."""
    return tuple(p for p, m in MODULES.items() if importlib.util.find_spec(f"{__package__}.{m}") is not None)


def cpu_features() -> tuple[dict, str]:
    """``({feature: bool}, how)``: this CPU's x86 features in libgcc's names, ``({}, "")`` if unknown."""
    try:
        found = importlib.import_module(f"{__package__}._core_cpuinfo").features()
        if found:
            return found, "__builtin_cpu_supports"
    except ImportError:  # a build without it: ask Linux
        pass
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    flags = set(line.partition(":")[2].split())
                    return {name: flag in flags for flag, name in _CPUINFO_FLAGS.items()}, "/proc/cpuinfo"
    except OSError:
        pass
    return {}, ""


def missing_for_v3(features: dict) -> list:
    """The x86-64-v3 features this CPU lacks (those it was asked about); all of them if unknown."""
    if not features:
        return ["(the CPU's features could not be read)"]
    return [f for f in X86_64_V3 if f in features and not features[f]]


def choose(environ=None) -> Choice:
    """The path to run: ``MODALUQ_CPU`` if set, else the most capable one this CPU runs."""
    environ = os.environ if environ is None else environ
    available = available_paths()
    if not available:
        raise ImportError(f"modaluq's C++ core is not built in {os.path.dirname(__file__)} "
                          f"(no {', '.join(MODULES.values())}): install the package (pip install .)")
    wanted = environ.get(ENV, "").strip()
    if wanted and wanted not in MODULES:
        raise ValueError(f"{ENV} must be one of {', '.join(repr(p) for p in MODULES if p != 'native')} "
                         f"(or unset: chosen from the CPU), got {wanted!r}")
    features, how = cpu_features() if "x86-64-v3" in available else ({}, "")
    lacks = missing_for_v3(features) if "x86-64-v3" in available else []

    def made(path, reason, forced=False):
        return Choice(path, f"{__package__}.{MODULES[path]}", reason, forced, available, features, how)

    if wanted:
        if wanted not in available:
            native = " (built with MODALUQ_NATIVE=ON: only the native core)" if available == ("native",) else ""
            raise ValueError(f"{ENV}={wanted}: this install has no {wanted} core{native}; "
                             f"it has {', '.join(available)} (unset {ENV} to choose from the CPU)")
        if wanted == "x86-64-v3" and lacks:
            raise ValueError(f"{ENV}=x86-64-v3, but this CPU (or its OS) lacks {', '.join(lacks)} "
                             f"({how or 'not detected'}): that core would stop with an illegal instruction; "
                             f"unset {ENV} or set it to baseline")
        return made(wanted, f"forced by {ENV}={wanted}", forced=True)
    if available == ("native",):
        return made("native", "the only core of this install (MODALUQ_NATIVE=ON: -march=native, this CPU only)")
    if "x86-64-v3" in available:
        if not features:
            return made("baseline", "this CPU's features could not be read: the baseline, which every x86-64 runs")
        if not lacks:
            return made("x86-64-v3", f"this CPU supports x86-64-v3 ({how})")
        return made("baseline", f"this CPU lacks x86-64-v3: no {', '.join(lacks)} ({how})")
    return made("baseline", f"the only core of this install (no x86-64-v3 build on "
                            f"{platform.machine() or 'this architecture'})")


def load():
    """Import the chosen core and record the choice (:data:`choice`)."""
    global choice
    c = choose()
    module = importlib.import_module(c.module)
    choice = c
    return module
