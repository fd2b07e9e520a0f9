"""Monte Carlo check of the analytic standard deviations: the paper's simulation study (§5.1).

Many independent records of the 6-DOF chain (:func:`modaluq.simulate`) are each identified
output-only and input/output, on the same record, at one model order.  The identified modes
are matched to the six true modes, and per mode and method the sample standard deviation of
the estimates over the records (σ_MC) is compared with the mean of the analytic
(delta-method) standard deviations computed from each record alone (σ̄_est).  If the
analytic standard deviation is right, σ̄_est / σ_MC is 1 to within Monte Carlo error.

Records run in worker processes, a chunk of records per task; the result does not depend on
the number of processes or the chunking, because record ``k`` always draws its random
numbers from ``numpy.random.SeedSequence(seed, spawn_key=(k,))`` (the ``k``-th child of
``SeedSequence(seed).spawn``).
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import os
import platform
import time
import warnings
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field

import numpy as np

from .._core import NumericalError
from ..checks import MAX_THREADS, check_boolean, check_integer, check_real
from ..identification import identify
from ..results import ModalUQWarning
from ..settings import Settings
from ..simulate import simulate
from .paper import METHOD_LABELS, METHODS
from .statistics import DEFAULT_BOOTSTRAP, MonteCarloResult

__all__ = ["METHODS", "METHOD_LABELS", "MonteCarloResult", "match_modes", "monte_carlo", "record_seed"]


# Records per task when chunk_size is not given: at most this many, and at least ~4 tasks per
# process so that the progress bar moves and the processes finish together.
_MAX_CHUNK = 20
# Thread-count variables of the BLAS/OpenMP libraries numpy and scipy may load.  The workers
# multiply small matrices (the simulation); a multi-threaded BLAS in each of several processes
# makes them several times slower, so the workers start with these set to 1.
_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                     "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


# --------------------------------------------------------------------------- helpers


def record_seed(seed: int, k: int) -> np.random.SeedSequence:
    """The seed of record ``k`` of a Monte Carlo run started with ``seed``.

    Parameters
    ----------
    seed : int
        The run's seed (>= 0).
    k : int
        Record index (0-based).

    Returns
    -------
    numpy.random.SeedSequence
        ``SeedSequence(seed, spawn_key=(k,))``, the same as ``SeedSequence(seed).spawn(k + 1)[k]``:
        records are statistically independent, and record ``k`` is the same in every run with
        this seed, whatever the number of records, processes or chunks.
    """
    return np.random.SeedSequence(seed, spawn_key=(int(k),))


def match_modes(frequency_hz, true_frequency_hz, tolerance: float = 0.05) -> np.ndarray:
    """Match identified modes to true modes by nearest frequency within a tolerance.

    True mode ``i`` (frequency ``f_i``) owns the open window ``|f - f_i| < w_i`` with
    ``w_i = min(tolerance * f_i, half the distance to the nearest other true frequency)``;
    the windows therefore never overlap and an identified mode is matched to at most one
    true mode.  Within its window a true mode takes the nearest identified mode; a true mode
    with no identified mode in its window is a miss.

    Parameters
    ----------
    frequency_hz : array_like, shape (n_identified,)
        Identified frequencies in Hz (any order; may be empty).
    true_frequency_hz : array_like, shape (n_true,)
        True frequencies in Hz, distinct.
    tolerance : float, default 0.05
        Half-width of the windows relative to the true frequency (0.05 = ±5 %), in (0, 1).

    Returns
    -------
    ndarray of int, shape (n_true,)
        Index into ``frequency_hz`` of the mode matched to each true mode, -1 for a miss.

    Examples
    --------
    >>> match_modes([5.5, 2.01, 9.9], [2.0, 5.6, 8.7])
    array([ 1,  0, -1])
    """
    tolerance = _fraction("tolerance", tolerance)
    f = np.asarray(frequency_hz, dtype=np.float64).reshape(-1)
    ft = np.asarray(true_frequency_hz, dtype=np.float64).reshape(-1)
    if ft.size == 0:
        raise ValueError("true_frequency_hz must not be empty")
    if np.unique(ft).size != ft.size:
        raise ValueError(f"true_frequency_hz must be distinct; got {ft}")
    width = tolerance * np.abs(ft)
    if ft.size > 1:
        order = np.argsort(ft)
        gaps = np.diff(ft[order]) / 2
        half_gap = np.full(ft.size, np.inf)
        half_gap[order[:-1]] = gaps
        half_gap[order[1:]] = np.minimum(half_gap[order[1:]], gaps)
        width = np.minimum(width, half_gap)
    out = np.full(ft.size, -1, dtype=np.intp)
    if f.size == 0:
        return out
    dist = np.abs(f[None, :] - ft[:, None])           # (n_true, n_identified)
    nearest = np.argmin(np.where(np.isfinite(dist), dist, np.inf), axis=1)
    hit = dist[np.arange(ft.size), nearest] < width
    out[hit] = nearest[hit]
    return out


def _fraction(name, value) -> float:
    return check_real(name, value, low=0.0, high=1.0, low_open=True, high_open=True)


@contextlib.contextmanager
def _single_threaded_blas_environment():
    """Set the BLAS/OpenMP thread variables to 1 in ``os.environ`` (restored on exit).

    Processes started meanwhile with the "spawn" or "forkserver" method load their BLAS with
    one thread; this process's BLAS, already loaded, is not affected.
    """
    saved = {name: os.environ.get(name) for name in _THREAD_VARIABLES}
    try:
        for name in _THREAD_VARIABLES:
            os.environ[name] = "1"
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _in_process_blas_limit():
    """Limit this process's BLAS libraries to one thread while records run here."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def _available_cpus() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


# --------------------------------------------------------------------------- one record


@dataclass(frozen=True)
class _Config:
    """Everything a worker needs to process a record (picklable)."""

    n_samples: int
    orders: tuple
    settings: Settings  # of the identification (orders included)
    seed: int
    match_tolerance: float
    simulation: dict = field(default_factory=dict)  # keywords of modaluq.simulate


def _empty_arrays(n_records: int, n_modes: int, n_outputs: int) -> dict:
    shape = (len(METHODS), n_records, n_modes)
    return {
        "frequency_hz": np.full(shape, np.nan),
        "damping_ratio": np.full(shape, np.nan),
        "frequency_std": np.full(shape, np.nan),
        "damping_std": np.full(shape, np.nan),
        "n_identified": np.zeros(shape[:2], dtype=np.int64),
        "failed": np.zeros(shape[:2], dtype=bool),
        "close_singular_values": np.zeros(shape[:2], dtype=bool),
        "n_warnings": np.zeros(shape[:2], dtype=np.int64),
        "noise_coupled": np.zeros(shape, dtype=bool),
        "mode_shape": np.full(shape + (n_outputs,), np.nan, dtype=np.complex128),
        "mode_shape_std_real": np.full(shape + (n_outputs,), np.nan),
        "mode_shape_std_imag": np.full(shape + (n_outputs,), np.nan),
        "reference_component": np.full(shape, -1, dtype=np.int64),
    }


def _run_chunk(indices, cfg: _Config):
    """Simulate and identify the records ``indices`` at every order of ``cfg.orders``.

    Returns ``(indices, {order: arrays}, truth)`` (record axis = 1 of every array), ``truth``
    the simulation's true ``frequency_hz``, ``damping_ratio``, ``fs`` and ``n_outputs``.
    """
    indices = [int(k) for k in indices]
    arrays = truth = None
    for j, k in enumerate(indices):
        sim = simulate(cfg.n_samples, seed=record_seed(cfg.seed, k), **cfg.simulation)
        if arrays is None:
            truth = {"frequency_hz": sim.frequency_hz, "damping_ratio": sim.damping_ratio, "fs": sim.fs,
                     "n_outputs": sim.n_outputs}
            arrays = {n: _empty_arrays(len(indices), sim.frequency_hz.size, sim.n_outputs) for n in cfg.orders}
        true_f = truth["frequency_hz"]
        for m, u in enumerate((None, sim.u)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ModalUQWarning)
                try:
                    result = identify(sim.y, u, fs=sim.fs, settings=cfg.settings)
                except NumericalError:
                    for a in arrays.values():
                        a["failed"][m, j] = True
                    continue
            for n, a in arrays.items():
                modes = result.at_order(n)
                a["n_identified"][m, j] = modes.n_modes
                a["close_singular_values"][m, j] = modes.close_singular_values
                a["n_warnings"][m, j] = len(result.warnings)
                idx = match_modes(modes.frequency_hz, true_f, cfg.match_tolerance)
                hit = idx >= 0
                a["frequency_hz"][m, j, hit] = modes.frequency_hz[idx[hit]]
                a["damping_ratio"][m, j, hit] = modes.damping_ratio[idx[hit]]
                a["mode_shape"][m, j, hit] = modes.mode_shape[:, idx[hit]].T
                a["reference_component"][m, j, hit] = modes.reference_component[idx[hit]]
                if modes.has_uncertainty:
                    a["frequency_std"][m, j, hit] = modes.frequency_std[idx[hit]]
                    a["damping_std"][m, j, hit] = modes.damping_std[idx[hit]]
                    a["noise_coupled"][m, j, hit] = modes.noise_coupled[idx[hit]]
                    a["mode_shape_std_real"][m, j, hit] = modes.mode_shape_std_real[:, idx[hit]].T
                    a["mode_shape_std_imag"][m, j, hit] = modes.mode_shape_std_imag[:, idx[hit]].T
    return indices, arrays, truth


# --------------------------------------------------------------------------- the run


def monte_carlo(n_records: int = 200, *, n_samples: int = 10_000, order=12, block_rows: int = 15,
                past_block_rows: int | None = None, n_blocks: int = 50, seed: int = 0,
                processes: int | None = None, progress: bool = True, match_tolerance: float = 0.05,
                n_bootstrap: int = DEFAULT_BOOTSTRAP, chunk_size: int | None = None,
                mp_context: str = "spawn", unknown_input_std: float = 0.1, damping_ratio: float = 0.02,
                n_dof: int = 6, input_dofs=(0,), output_dofs=None, freeze_noise: bool = Settings.freeze_noise,
                noise_coupling_limit: float = Settings.noise_coupling_limit,
                block_correlation_correction: bool = Settings.block_correlation_correction,
                bootstrap_draws: int = Settings.bootstrap_draws):
    """Monte Carlo study of the analytic standard deviations (the paper's §5.1).

    Simulates ``n_records`` independent records of the paper's 6-DOF chain
    (:func:`modaluq.simulate`: 3 acceleration outputs, 1 known input force, 50 Hz), identifies
    each record output-only and input/output at model order ``order``, matches the identified
    modes to the 6 true modes (:func:`match_modes`) and summarises, per mode and method, the
    mean estimate, its sample std σ_MC and the mean analytic std σ̄_est.

    Parameters
    ----------
    n_records : int, default 200
        Number of independent records (>= 1; the summary needs >= 2 matched records per mode).
    n_samples : int, default 10_000
        Samples per record (the paper's N = 10,000).
    order : int or sequence of int, default 12
        Model order (12 = six modes, as in the paper).  Several orders are identified from
        the same records (one SVD per record); a sequence returns one result per order.
    block_rows : int, default 15
        Future block rows p.
    past_block_rows : int, optional
        Past block rows q (default p).
    n_blocks : int, default 50
        Blocks for the covariance of the data covariances.
    seed : int, default 0
        Seed (>= 0) of the run; record ``k`` uses :func:`record_seed` ``(seed, k)``.  The
        same seed gives identical arrays whatever ``processes`` and ``chunk_size`` are.
    processes : int, optional
        Worker processes (default: the CPUs available to this process).  1 runs everything in
        this process.
    progress : bool, default True
        Show a tqdm progress bar (on stderr).
    match_tolerance : float, default 0.05
        Relative half-width of the frequency window that matches an identified mode to a true
        mode (see :func:`match_modes`); modes outside every window count as misses.
    n_bootstrap : int, default 1000
        Bootstrap resamples for the standard error of σ̄_est / σ_MC (0: no standard error).
    chunk_size : int, optional
        Records per task sent to a worker (default: at most 20, at least ~4 tasks per process).
    mp_context : str, default "spawn"
        :mod:`multiprocessing` start method of the workers.  With "spawn" (and "forkserver")
        the workers start with ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` and the like set
        to 1: a multi-threaded BLAS in every worker makes the run several times slower.  With
        "fork" the workers inherit this process's BLAS threads.
    unknown_input_std : float, default 0.1
        Std of the unmeasured forces relative to the known input (:func:`modaluq.simulate`);
        0 makes the known input the only excitation (a shaker test).
    damping_ratio : float, default 0.02
        Modal damping ratio of every mode (fraction).
    n_dof, input_dofs, output_dofs
        The structure (:func:`modaluq.simulate`): the paper's 6-DOF chain by default; e.g.
        ``n_dof=4, input_dofs=(0, 3)`` is a 4-storey shear frame with two known inputs.
    freeze_noise, noise_coupling_limit, block_correlation_correction, bootstrap_draws
        Passed to :func:`modaluq.identify` (``freeze_noise=False``: the plain first-order
        propagation, for comparison; ``block_correlation_correction=True``: σ corrected for the
        correlation of adjacent blocks, docs/uq-math.md §3.1; ``bootstrap_draws=100``: σ_f, σ_ξ
        above the noise floor from the bootstrap, docs/uq-math.md §5.6).

    Returns
    -------
    MonteCarloResult or tuple of MonteCarloResult
        Per-record arrays and the per-mode summary; ``.report()``, ``.to_dataframe()``,
        ``.plot_histograms(path)``.  A tuple (one per order, ascending) when ``order`` is a
        sequence.

    Raises
    ------
    TypeError, ValueError
        A bad parameter (the message names it), including settings the identification refuses
        (order too high for the horizons, records too short for the blocks), found on the first
        record before any worker starts.

    Notes
    -----
    Record 0 is computed in this process before the workers start.  With the default "spawn"
    start method every worker is a fresh interpreter that imports the caller's main module, so
    a script that calls this with ``processes > 1`` needs the usual
    ``if __name__ == "__main__":`` guard.  While the workers run, the BLAS thread variables are
    set to 1 in ``os.environ`` (restored afterwards); in this process, BLAS is limited to one
    thread only if ``threadpoolctl`` is installed.

    Examples
    --------
    >>> from modaluq.validation import monte_carlo
    >>> mc = monte_carlo(4, processes=1, progress=False)
    >>> mc.frequency_hz.shape                # (method, record, mode)
    (2, 4, 6)
    >>> print(mc.report())                   # doctest: +SKIP
    """
    n_records = check_integer("n_records", n_records, minimum=1)
    n_samples = check_integer("n_samples", n_samples, minimum=1)
    single = np.ndim(order) == 0
    orders = tuple(sorted({check_integer("order", n, minimum=1) for n in ([order] if single else order)}))
    if not orders:
        raise ValueError("order must name at least one model order")
    unknown_input_std = check_real("unknown_input_std", unknown_input_std, low=0)
    damping_ratio = check_real("damping_ratio", damping_ratio, low=0, high=1, low_open=True, high_open=True)
    simulation = {"unknown_input_std": unknown_input_std, "damping_ratio": damping_ratio,
                  "n_dof": check_integer("n_dof", n_dof, minimum=1),
                  "input_dofs": tuple(check_integer("input_dofs", d, minimum=0) for d in input_dofs)}
    if output_dofs is not None:
        simulation["output_dofs"] = tuple(check_integer("output_dofs", d, minimum=0) for d in output_dofs)
    settings = Settings(block_rows=block_rows, past_block_rows=past_block_rows, orders=orders,
                        n_blocks=check_integer("n_blocks", n_blocks, minimum=2), freeze_noise=freeze_noise,
                        noise_coupling_limit=noise_coupling_limit,
                        block_correlation_correction=block_correlation_correction,
                        bootstrap_draws=bootstrap_draws)
    seed = check_integer("seed", seed, minimum=0)
    processes = _available_cpus() if processes is None else check_integer("processes", processes, minimum=1,
                                                                      maximum=MAX_THREADS)
    progress = check_boolean("progress", progress)
    match_tolerance = _fraction("match_tolerance", match_tolerance)
    n_bootstrap = check_integer("n_bootstrap", n_bootstrap, minimum=0)
    if chunk_size is not None:
        chunk_size = check_integer("chunk_size", chunk_size, minimum=1)
    if mp_context not in multiprocessing.get_all_start_methods():
        raise ValueError(f"mp_context must be one of {multiprocessing.get_all_start_methods()}; "
                         f"got {mp_context!r}")

    cfg = _Config(n_samples=n_samples, orders=orders, settings=settings, seed=seed, match_tolerance=match_tolerance,
                  simulation=simulation)
    processes = min(processes, n_records)
    if chunk_size is None:
        chunk_size = max(1, min(_MAX_CHUNK, math.ceil(n_records / (4 * processes))))

    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    # Record 0 runs here first: a setting the identification refuses raises its ValueError now,
    # before any worker starts, and fixes the number of true modes.
    with _in_process_blas_limit():
        first = _run_chunk([0], cfg)
    truth = first[2]
    arrays = {n: _empty_arrays(n_records, truth["frequency_hz"].size, truth["n_outputs"]) for n in orders}
    _store(arrays, first)
    rest = list(range(1, n_records))
    chunks = [rest[i:i + chunk_size] for i in range(0, len(rest), chunk_size)]
    with tqdm(total=n_records, desc="modaluq Monte Carlo", unit="record", disable=not progress,
              dynamic_ncols=True) as bar:
        bar.update(1)
        if processes == 1 or not chunks:
            with _in_process_blas_limit():
                for chunk in chunks:
                    _store(arrays, _run_chunk(chunk, cfg))
                    bar.update(len(chunk))
        else:
            ctx = multiprocessing.get_context(mp_context)
            with _single_threaded_blas_environment(), \
                    ProcessPoolExecutor(max_workers=min(processes, len(chunks)), mp_context=ctx) as pool:
                pending = {pool.submit(_run_chunk, chunk, cfg) for chunk in chunks}
                try:
                    while pending:
                        done, pending = wait(pending, return_when=FIRST_COMPLETED)
                        for fut in done:
                            out = fut.result()  # re-raises a worker's exception here
                            _store(arrays, out)
                            bar.update(len(out[0]))
                except BaseException:
                    for fut in pending:
                        fut.cancel()
                    raise
    elapsed = time.perf_counter() - t0

    paper_case = simulation == {"unknown_input_std": 0.1, "damping_ratio": 0.02, "n_dof": 6, "input_dofs": (0,)}
    described = "modaluq.simulate defaults (paper §5.1 chain)" if paper_case else \
        "modaluq.simulate(" + ", ".join(f"{k}={v!r}" for k, v in simulation.items()) + ")"
    machine = f"{platform.system()} {platform.machine()}, {_available_cpus()} CPU(s) available, " \
              f"Python {platform.python_version()}"
    results = tuple(
        MonteCarloResult(true_frequency_hz=truth["frequency_hz"], true_damping_ratio=truth["damping_ratio"],
                         **arrays[n],
                         settings={"n_records": n_records, "n_samples": n_samples, "fs": float(truth["fs"]),
                                   "order": n, "block_rows": settings.block_rows,
                                   "past_block_rows": settings.past_block_rows or settings.block_rows,
                                   "n_blocks": settings.n_blocks,
                                   "seed": seed, "match_tolerance": match_tolerance, "simulation": described,
                                   "simulate_keywords": {k: list(v) if isinstance(v, tuple) else v
                                                         for k, v in simulation.items()},
                                   "paper_case": paper_case, "freeze_noise": settings.freeze_noise,
                                   "noise_coupling_limit": settings.noise_coupling_limit,
                                   "block_correlation_correction": settings.block_correlation_correction,
                                   "bootstrap_draws": settings.bootstrap_draws},
                         elapsed_s=elapsed, processes=processes, machine=machine, n_bootstrap=n_bootstrap)
        for n in orders)
    return results[0] if single else results


def _store(arrays: dict, chunk_output) -> None:
    indices, part, _ = chunk_output
    for n, by_name in arrays.items():
        for name, target in by_name.items():
            target[:, indices] = part[n][name]
