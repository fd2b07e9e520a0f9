"""Where the records run: one :class:`concurrent.futures.Executor` code path (docs/monitoring.md §2).

- default: a thread pool in this process (the core releases the GIL; the BLAS runs on one thread);
- a ``dask.distributed.Client`` (given, or active), a scheduler address, or a ``LocalCluster`` of
  ``workers`` processes, through the client's ``concurrent.futures`` executor. A cluster started
  here speaks mutual TLS only and serves no HTTP; one given keeps its own security (§2, security);
- any other :class:`concurrent.futures.Executor` (e.g. a ``ProcessPoolExecutor``).

A task that runs in another process sets that process up first (:func:`configure_worker_process`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import os
import socket
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
        from distributed import Client

        if scheduler is not None:
            with Client(scheduler) as client:
                yield client.get_executor(pure=False), True
            return
        workers = check_integer("workers", workers, minimum=1)
        with _secured_local_cluster(workers) as (cluster, security), \
                Client(cluster, security=security) as client:
            _check_http_closed(cluster.scheduler, client)
            yield client.get_executor(pure=False), True
        return
    threads = (os.cpu_count() or 1) if threads is None else check_integer("threads", threads, minimum=1)
    with concurrent.futures.ThreadPoolExecutor(max_workers=threads, thread_name_prefix="modaluq") as pool:
        yield pool, False


@contextlib.contextmanager
def _secured_local_cluster(workers):
    """A ``LocalCluster`` of ``workers`` one-thread processes that only its own client can use.

    Every comm (scheduler, nannies, workers, client) is mutual TLS with a throw-away certificate
    that exists only in this process's memory and is handed to the workers it starts: another local
    process cannot connect, let alone run code in the workers. Without ``cryptography`` no such
    certificate can be made, and the cluster is refused rather than started in plain TCP.

    Dask starts an HTTP server in the scheduler and in every worker even without a dashboard
    (port 8787 by default): it is given no routes, bound to a random localhost port (no clash with
    a running cluster's 8787) and closed as soon as the server has started (:func:`dask_setup`).
    """
    import dask
    from distributed import LocalCluster
    from distributed.security import Security

    require("cryptography", "a Dask cluster started by modaluq (workers=), secured by TLS,")
    security = Security.temporary()
    no_http = {"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []}
    this_module = __name__  # the preload: dask_setup below, run by the scheduler and each worker it starts
    with dask.config.set(no_http):
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1", protocol="tls",
            security=security, dashboard_address=None, preload=[this_module],
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0", "preload": [this_module]})
    with cluster:
        yield cluster, security


def dask_setup(server) -> None:
    """Dask preload of the scheduler and workers modaluq starts: close the HTTP server Dask opened
    (it serves nothing; see :func:`_secured_local_cluster`). Runs again in a restarted worker."""
    server.http_server.stop()


def _http_open(dask_worker=None, server=None) -> bool:
    """Whether the HTTP port of a scheduler or worker still accepts connections."""
    http = (server or dask_worker).http_server
    with contextlib.suppress(OSError), socket.create_connection((http.address, http.port), timeout=2):
        return True
    return False


def _check_http_closed(scheduler, client) -> None:
    """Refuse a cluster whose preload did not close an HTTP server (Dask only logs a failed preload)."""
    still_open = [scheduler.address] if _http_open(server=scheduler) else []
    still_open += [address for address, is_open in client.run(_http_open).items() if is_open]
    if still_open:
        raise RuntimeError(f"the HTTP server of {', '.join(still_open)} could not be closed; "
                           "modaluq does not run records on a cluster that serves HTTP")


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
