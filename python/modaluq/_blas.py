"""One BLAS thread during modaluq's compute calls.

When the extension is built with OpenBLAS (``_core.uses_blas``), its large products would run on
OpenBLAS's default of one thread per core. modaluq's own parallelism is the ``threads`` option; a
multi-threaded BLAS under it, or under several worker processes, oversubscribes the cores, and
OpenBLAS's spinning threads then slow a run down several times (docs/performance.md). So each
compute call runs with the BLAS limited to one thread (threadpoolctl), and the previous setting is
restored afterwards. Setting ``OPENBLAS_NUM_THREADS`` yourself opts out: your value is used.
"""

from __future__ import annotations

import contextlib
import os

from . import _core

_controller = None


def _blas_controller():
    global _controller
    if _controller is None:
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    return _controller


def single_threaded():
    """Context manager: the BLAS libraries of this process on one thread, unless the user chose."""
    if not getattr(_core, "uses_blas", False) or "OPENBLAS_NUM_THREADS" in os.environ:
        return contextlib.nullcontext()
    return _blas_controller().limit(limits=1, user_api="blas")
