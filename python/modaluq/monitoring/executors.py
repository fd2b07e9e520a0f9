"""Where the records run: one :class:`concurrent.futures.Executor` code path (docs/monitoring.md §2).

- default: a thread pool in this process (the core releases the GIL; the BLAS runs on one thread);
- a ``dask.distributed.Client`` (given, or active), a scheduler address, or a ``LocalCluster`` of
  ``workers`` processes, through the client's ``concurrent.futures`` executor;
- any other :class:`concurrent.futures.Executor` (e.g. a ``ProcessPoolExecutor``).

A task that runs in another process sets that process up first (:func:`configure_worker_process`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import os
import sys

from ..checks import check_integer, require

__all__ = ["WORKER_MMAP_THRESHOLD", "WORKER_TRIM_THRESHOLD", "cancel_queued", "configure_worker_process",
           "executor_for"]


@contextlib.contextmanager
def executor_for(executor, threads, workers, scheduler):
    """``(executor, remote)``: the executor the tasks go to, and whether they run in other processes."""
    given = sum(x is not None for x in (executor, threads, workers, scheduler))
    if given > 1:
        raise ValueError("give at most one of executor=, threads=, workers= and scheduler=")
    if given == 0 and "distributed" in sys.modules:
        try:  # "use an active Client"
            executor = sys.modules["distributed"].default_client()
        except ValueError:
            executor = None
    if executor is not None:
        if type(executor).__name__ == "Client" and hasattr(executor, "get_executor"):
            yield executor.get_executor(pure=False), True
        elif isinstance(executor, concurrent.futures.Executor):
            yield executor, not isinstance(executor, concurrent.futures.ThreadPoolExecutor)
        else:
            raise TypeError("executor must be a concurrent.futures.Executor or a dask.distributed.Client; "
                            f"got {type(executor).__name__}")
        return
    if workers is not None or scheduler is not None:
        require("distributed", "workers= or scheduler=")
        from distributed import Client, LocalCluster

        if scheduler is not None:
            with Client(scheduler) as client:
                yield client.get_executor(pure=False), True
            return
        workers = check_integer("workers", workers, minimum=1)
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) \
                as cluster, Client(cluster) as client:
            yield client.get_executor(pure=False), True
        return
    threads = (os.cpu_count() or 1) if threads is None else check_integer("threads", threads, minimum=1)
    with concurrent.futures.ThreadPoolExecutor(max_workers=threads, thread_name_prefix="modaluq") as pool:
        yield pool, False


def cancel_queued(futures) -> None:
    """Cancel the futures not yet started (those done or running are left alone)."""
    for fut in futures:
        fut.cancel()


#: glibc ``mallopt`` parameters and the values a worker process gets (see configure_worker_process)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
WORKER_MMAP_THRESHOLD = 32 << 20
WORKER_TRIM_THRESHOLD = 64 << 20


def configure_worker_process() -> None:
    """One BLAS thread, and glibc's allocator tuned for the core's large temporaries; for the
    whole worker process (these settings stay for its later tasks, which is what we want).

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``. In glibc that also freezes
    the mmap threshold at 128 KiB, so every large temporary of an identification is a fresh
    ``mmap`` whose pages fault in again: a record then took 1.14 s instead of 0.83 s here.
    glibc's own dynamic maximum of the mmap threshold (32 MiB) restores the speed; a trim
    threshold of 64 MiB still returns memory to the system after a record (docs/monitoring.md §2).
    """
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")
    if sys.platform.startswith("linux"):
        import ctypes
        import ctypes.util

        with contextlib.suppress(OSError, AttributeError, TypeError):  # not glibc (musl): nothing to tune
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            libc.mallopt(_M_MMAP_THRESHOLD, WORKER_MMAP_THRESHOLD)
            libc.mallopt(_M_TRIM_THRESHOLD, WORKER_TRIM_THRESHOLD)
