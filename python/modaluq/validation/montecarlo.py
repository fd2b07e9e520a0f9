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
import json
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

__all__ = ["METHODS", "METHOD_LABELS", "MonteCarloResult", "match_modes", "monte_carlo", "record_seed"]


# Records per task when chunk_size is not given: at most this many, and at least ~4 tasks per
# process so that the progress bar moves and the processes finish together.
_MAX_CHUNK = 20
# Bootstrap resamples of the records for the standard error of the std ratio.
_DEFAULT_BOOTSTRAP = 1000
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


# --------------------------------------------------------------------------- statistics


def _summary(values, stds, rng, n_bootstrap):
    """Per-mode statistics of one parameter of one method (values, stds: (n_records, n_modes))."""
    n_modes = values.shape[1]
    out = {k: np.full(n_modes, np.nan) for k in
           ("mean", "mean_se", "std_mc", "std_est", "std_est_spread", "std_est_median", "ratio", "ratio_se",
            "ratio_median")}
    out["n"] = np.zeros(n_modes, dtype=np.int64)
    for i in range(n_modes):
        ok = np.isfinite(values[:, i]) & np.isfinite(stds[:, i])
        v, s = values[ok, i], stds[ok, i]
        n = v.size
        out["n"][i] = n
        if n < 2:
            continue
        sd = float(np.std(v, ddof=1))
        out["mean"][i] = float(np.mean(v))
        out["mean_se"][i] = sd / math.sqrt(n)
        out["std_mc"][i] = sd
        out["std_est"][i] = float(np.mean(s))
        out["std_est_spread"][i] = float(np.std(s, ddof=1))
        out["std_est_median"][i] = float(np.median(s))
        out["ratio"][i] = out["std_est"][i] / sd if sd > 0 else np.nan
        out["ratio_median"][i] = out["std_est_median"][i] / sd if sd > 0 else np.nan
        if n_bootstrap >= 2 and sd > 0:
            # Records are the independent unit: resample them (estimate and its std together).
            ratios = np.empty(n_bootstrap)
            for b0 in range(0, n_bootstrap, 250):
                idx = rng.integers(0, n, size=(min(250, n_bootstrap - b0), n))
                with np.errstate(divide="ignore", invalid="ignore"):  # a resample of one value: sd 0
                    ratios[b0:b0 + idx.shape[0]] = s[idx].mean(axis=1) / v[idx].std(axis=1, ddof=1)
            ratios = ratios[np.isfinite(ratios)]
            if ratios.size >= 2:
                out["ratio_se"][i] = float(np.std(ratios, ddof=1))
    return out


# --------------------------------------------------------------------------- result


_ARRAY_FIELDS = ("true_frequency_hz", "true_damping_ratio", "frequency_hz", "damping_ratio",
                 "frequency_std", "damping_std", "n_identified", "failed", "close_singular_values",
                 "n_warnings", "noise_coupled", "mode_shape", "mode_shape_std_real", "mode_shape_std_imag",
                 "reference_component")


def _shape_ratio(shape, std_re, std_im, ref, use):
    """Per mode, the median over the non-reference shape components (real and imaginary parts)
    of median(analytic std) / sample std, over the records in ``use`` whose reference
    component is the mode's most frequent one (so that all are normalised alike)."""
    n_modes = shape.shape[1]
    out = np.full(n_modes, np.nan)
    for i in range(n_modes):
        ok = use[:, i] & (ref[:, i] >= 0)
        if ok.sum() < 3:
            continue
        k = np.bincount(ref[ok, i]).argmax()
        ok &= ref[:, i] == k
        if ok.sum() < 3:
            continue
        ratios = []
        for c in range(shape.shape[2]):
            if c == k:
                continue
            for part, std in ((shape[ok, i, c].real, std_re[ok, i, c]), (shape[ok, i, c].imag, std_im[ok, i, c])):
                sd = np.std(part, ddof=1)
                if sd > 0:
                    ratios.append(np.median(std) / sd)
        if ratios:
            out[i] = float(np.median(ratios))
    return out


@dataclass(frozen=True, repr=False, eq=False)
class MonteCarloResult:
    """What :func:`monte_carlo` returns: per-record estimates and their summary.

    The per-record arrays have shape ``(2, n_records, n_modes)``: axis 0 is the method,
    ``METHODS = ("output-only", "input/output")``, axis 2 the true mode in ascending
    frequency.  A true mode not matched in a record (or a record whose identification failed)
    is NaN.  Frequencies and their std in Hz; damping ratios and their std as fractions
    (0.02 = 2 %).

    The summary arrays (computed on construction) have shape ``(2, n_modes)`` and use only the
    records where the mode was matched: ``*_mean`` and its standard error ``*_mean_se``
    (= σ_MC / √n), ``*_std_mc`` the sample std (ddof = 1) of the estimates (σ_MC),
    ``*_std_est`` the mean of the analytic std (σ̄_est), ``*_std_est_spread`` their sample std
    over the records (the paper's "±"), ``*_std_est_median``, ``*_std_ratio`` =
    σ̄_est / σ_MC and ``*_std_ratio_se`` its bootstrap standard error (``n_bootstrap``
    resamples of the matched records; 0 disables it).
    """

    true_frequency_hz: np.ndarray        #: (n_modes,) Hz
    true_damping_ratio: np.ndarray       #: (n_modes,) fraction
    frequency_hz: np.ndarray             #: (2, n_records, n_modes) Hz, NaN = missed
    damping_ratio: np.ndarray            #: (2, n_records, n_modes) fraction
    frequency_std: np.ndarray            #: (2, n_records, n_modes) analytic std, Hz
    damping_std: np.ndarray              #: (2, n_records, n_modes) analytic std, fraction
    n_identified: np.ndarray             #: (2, n_records) modes found at the order
    failed: np.ndarray                   #: (2, n_records) identification raised NumericalError
    close_singular_values: np.ndarray    #: (2, n_records) order cuts close singular values
    n_warnings: np.ndarray               #: (2, n_records) entries in Result.warnings
    settings: dict                       #: the run's settings
    noise_coupled: np.ndarray | None = None        #: (2, n_records, n_modes) the pole's flag (docs/uq-math.md §5.5)
    mode_shape: np.ndarray | None = None           #: (2, n_records, n_modes, n_outputs) normalised shapes
    mode_shape_std_real: np.ndarray | None = None  #: (2, n_records, n_modes, n_outputs)
    mode_shape_std_imag: np.ndarray | None = None  #: (2, n_records, n_modes, n_outputs)
    reference_component: np.ndarray | None = None  #: (2, n_records, n_modes) component scaled to 1, -1 = missed
    elapsed_s: float = float("nan")      #: wall time of the run, s
    processes: int = 1                   #: worker processes used
    machine: str = ""                    #: platform and CPU count of the run
    n_bootstrap: int = _DEFAULT_BOOTSTRAP

    n_matched: np.ndarray = field(init=False)               #: (2, n_modes)
    n_missed: np.ndarray = field(init=False)                #: (2, n_modes)
    frequency_mean: np.ndarray = field(init=False)          #: Hz
    frequency_mean_se: np.ndarray = field(init=False)       #: Hz
    frequency_std_mc: np.ndarray = field(init=False)        #: Hz
    frequency_std_est: np.ndarray = field(init=False)       #: Hz
    frequency_std_est_spread: np.ndarray = field(init=False)  #: Hz
    frequency_std_est_median: np.ndarray = field(init=False)  #: Hz
    frequency_std_ratio: np.ndarray = field(init=False)
    frequency_std_ratio_se: np.ndarray = field(init=False)
    damping_mean: np.ndarray = field(init=False)            #: fraction
    damping_mean_se: np.ndarray = field(init=False)
    damping_std_mc: np.ndarray = field(init=False)
    damping_std_est: np.ndarray = field(init=False)
    damping_std_est_spread: np.ndarray = field(init=False)
    damping_std_est_median: np.ndarray = field(init=False)
    damping_std_ratio: np.ndarray = field(init=False)
    damping_std_ratio_se: np.ndarray = field(init=False)
    frequency_std_ratio_median: np.ndarray = field(init=False)  #: median analytic std / σ_MC
    damping_std_ratio_median: np.ndarray = field(init=False)
    #: (2, n_modes) share of the matched records where the pole is flagged noise_coupled
    noise_coupled_share: np.ndarray = field(init=False)
    #: (2, n_modes) mean and median ratios over the records where the pole is not flagged
    #: (σ_MC from those records too): what a user who drops flagged poles gets
    frequency_std_ratio_unflagged: np.ndarray = field(init=False)
    frequency_std_ratio_median_unflagged: np.ndarray = field(init=False)
    damping_std_ratio_unflagged: np.ndarray = field(init=False)
    damping_std_ratio_median_unflagged: np.ndarray = field(init=False)
    #: (2, n_modes) median over the shape components of median(std) / σ_MC, unflagged records
    mode_shape_std_ratio_median: np.ndarray = field(init=False)
    #: (2, n_modes) RMS over the unflagged records of (estimate - mean) / the record's own σ: 1
    #: when every record's σ is its scatter, even when σ differs from record to record
    frequency_rms_z_unflagged: np.ndarray = field(init=False)
    damping_rms_z_unflagged: np.ndarray = field(init=False)

    def __post_init__(self):
        rng = np.random.default_rng(np.random.SeedSequence([int(self.settings.get("seed", 0)), 1]))
        n_methods, n_modes = len(METHODS), self.true_frequency_hz.size
        stats = {}
        for name, values, stds in (("frequency", self.frequency_hz, self.frequency_std),
                                   ("damping", self.damping_ratio, self.damping_std)):
            per_method = [_summary(values[m], stds[m], rng, int(self.n_bootstrap)) for m in range(n_methods)]
            for key in per_method[0]:
                stats[(name, key)] = np.stack([pm[key] for pm in per_method])
        set_ = object.__setattr__
        set_(self, "n_matched", stats[("frequency", "n")])
        set_(self, "n_missed", self.n_records - stats[("frequency", "n")])
        for name in ("frequency", "damping"):
            set_(self, f"{name}_mean", stats[(name, "mean")])
            set_(self, f"{name}_mean_se", stats[(name, "mean_se")])
            set_(self, f"{name}_std_mc", stats[(name, "std_mc")])
            set_(self, f"{name}_std_est", stats[(name, "std_est")])
            set_(self, f"{name}_std_est_spread", stats[(name, "std_est_spread")])
            set_(self, f"{name}_std_est_median", stats[(name, "std_est_median")])
            set_(self, f"{name}_std_ratio", stats[(name, "ratio")])
            set_(self, f"{name}_std_ratio_se", stats[(name, "ratio_se")])
        if n_modes and not np.array_equal(stats[("frequency", "n")], stats[("damping", "n")]):
            raise ValueError("frequency and damping arrays must be missing in the same places")
        for name in ("frequency", "damping"):
            set_(self, f"{name}_std_ratio_median", stats[(name, "ratio_median")])
        shape = self.frequency_hz.shape
        coupled = np.zeros(shape, dtype=bool) if self.noise_coupled is None else np.asarray(self.noise_coupled)
        set_(self, "noise_coupled", coupled)
        matched = np.isfinite(self.frequency_hz)
        with np.errstate(invalid="ignore"):
            set_(self, "noise_coupled_share", (coupled & matched).sum(axis=1) / matched.sum(axis=1))
        for name, values, stds in (("frequency", self.frequency_hz, self.frequency_std),
                                   ("damping", self.damping_ratio, self.damping_std)):
            clean = [_summary(np.where(coupled[m], np.nan, values[m]), stds[m], rng, 0) for m in range(n_methods)]
            set_(self, f"{name}_std_ratio_unflagged", np.stack([c["ratio"] for c in clean]))
            set_(self, f"{name}_std_ratio_median_unflagged", np.stack([c["ratio_median"] for c in clean]))
            with np.errstate(invalid="ignore", divide="ignore"):
                v = np.where(coupled, np.nan, values)
                z = (v - np.nanmean(v, axis=1, keepdims=True)) / stds if v.shape[1] else v
                ok = np.isfinite(z)
                rms = np.sqrt(np.where(ok, z * z, 0).sum(axis=1) / ok.sum(axis=1))
            set_(self, f"{name}_rms_z_unflagged", np.where(ok.sum(axis=1) >= 2, rms, np.nan))
        if self.mode_shape is not None and self.mode_shape_std_real is not None:
            set_(self, "mode_shape_std_ratio_median", np.stack([
                _shape_ratio(self.mode_shape[m], self.mode_shape_std_real[m], self.mode_shape_std_imag[m],
                             self.reference_component[m], matched[m] & ~coupled[m]) for m in range(n_methods)]))
        else:
            set_(self, "mode_shape_std_ratio_median", np.full((n_methods, n_modes), np.nan))

    # ---- shape

    @property
    def n_records(self) -> int:
        """Number of simulated records."""
        return int(self.frequency_hz.shape[1])

    @property
    def n_modes(self) -> int:
        """Number of true modes."""
        return int(self.true_frequency_hz.size)

    @staticmethod
    def method_index(method: str) -> int:
        """Index of ``method`` ("output-only"/"OO" or "input/output"/"IO") on axis 0."""
        for i, name in enumerate(METHODS):
            if method in (name, METHOD_LABELS[name]):
                return i
        raise ValueError(f"method must be one of {METHODS} (or OO/IO); got {method!r}")

    # ---- export

    def _columns(self) -> dict:
        """Per record, method and mode, one row each (long format), as column arrays."""
        n_m, n_r, n_k = self.frequency_hz.shape
        method, record, mode = np.meshgrid(np.arange(n_m), np.arange(n_r), np.arange(n_k), indexing="ij")
        method, record, mode = method.ravel(), record.ravel(), mode.ravel()
        return {
            "record": record,
            "method": np.array(METHODS, dtype=object)[method],
            "mode": mode + 1,
            "true_frequency_hz": self.true_frequency_hz[mode],
            "true_damping_ratio": self.true_damping_ratio[mode],
            "matched": np.isfinite(self.frequency_hz).ravel(),
            "frequency_hz": self.frequency_hz.ravel(),
            "frequency_std": self.frequency_std.ravel(),
            "damping_ratio": self.damping_ratio.ravel(),
            "damping_std": self.damping_std.ravel(),
        }

    def to_dataframe(self):
        """The per-record estimates as a pandas DataFrame, one row per record, method and mode.

        Columns: ``record`` (0-based), ``method``, ``mode`` (1-based), ``true_frequency_hz``,
        ``true_damping_ratio``, ``matched``, ``frequency_hz``, ``frequency_std`` (Hz),
        ``damping_ratio``, ``damping_std`` (fraction); unmatched modes are NaN.
        """
        import pandas as pd

        return pd.DataFrame(self._columns())

    def summary_dataframe(self):
        """The per-mode summary as a pandas DataFrame, one row per method and mode (SI units)."""
        import pandas as pd

        return pd.DataFrame(self.summary_columns())

    def summary_columns(self) -> dict:
        """The per-mode summary as column arrays (one entry per method and mode, SI units)."""
        n_k = self.n_modes
        cols = {
            "method": np.repeat(np.array(METHODS, dtype=object), n_k),
            "mode": np.tile(np.arange(1, n_k + 1), len(METHODS)),
            "true_frequency_hz": np.tile(self.true_frequency_hz, len(METHODS)),
            "true_damping_ratio": np.tile(self.true_damping_ratio, len(METHODS)),
            "n_matched": self.n_matched.ravel(),
            "n_missed": self.n_missed.ravel(),
        }
        for name in ("frequency", "damping"):
            for key in ("mean", "mean_se", "std_mc", "std_est", "std_est_spread", "std_est_median",
                        "std_ratio", "std_ratio_se"):
                cols[f"{name}_{key}"] = getattr(self, f"{name}_{key}").ravel()
        return cols

    def write_csv(self, path, *, summary: bool = False) -> None:
        """Write the per-record table (or, with ``summary=True``, the per-mode summary) as CSV."""
        import csv

        cols = self.summary_columns() if check_boolean("summary", summary) else self._columns()
        names = list(cols)
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(names)
            for row in zip(*(cols[n] for n in names)):
                w.writerow([_csv_cell(x) for x in row])

    def save(self, path) -> None:
        """Save the run to a ``.npz`` file (arrays plus the settings as JSON); see :meth:`load`."""
        meta = {"settings": self.settings, "elapsed_s": self.elapsed_s, "processes": self.processes,
                "machine": self.machine, "n_bootstrap": self.n_bootstrap, "methods": list(METHODS)}
        np.savez_compressed(path, meta=np.array(json.dumps(meta)),
                            **{name: getattr(self, name) for name in _ARRAY_FIELDS})

    @classmethod
    def load(cls, path) -> "MonteCarloResult":
        """Read a run written by :meth:`save` (the summary is recomputed, identically)."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            # runs saved before a field existed load with it absent
            arrays = {name: data[name] if name in data.files else None for name in _ARRAY_FIELDS}
        if tuple(meta.get("methods", METHODS)) != METHODS:
            raise ValueError(f"{path}: methods {meta.get('methods')} differ from {METHODS}")
        return cls(**arrays, settings=meta["settings"], elapsed_s=float(meta["elapsed_s"]),
                   processes=int(meta["processes"]), machine=str(meta["machine"]),
                   n_bootstrap=int(meta["n_bootstrap"]))

    # ---- report and plots

    def report(self) -> str:
        """The run as Markdown: the paper's Tables 1 and 2 with its values beside ours."""
        from .report import markdown_report

        return markdown_report(self)

    def plot_histograms(self, path, *, dpi: int = 72) -> str:
        """Histograms of the estimated std per mode with the sample std marked (PNG).

        See :func:`modaluq.validation.report.plot_histograms`.
        """
        from .report import plot_histograms

        return plot_histograms(self, path, dpi=dpi)

    def plot_estimates(self, path, *, dpi: int = 72) -> str:
        """Histograms of the estimates per mode with the normal density of the mean analytic std (PNG).

        See :func:`modaluq.validation.report.plot_estimates`.
        """
        from .report import plot_estimates

        return plot_estimates(self, path, dpi=dpi)

    def __repr__(self) -> str:
        s = self.settings
        return (f"MonteCarloResult(n_records={self.n_records}, n_samples={s.get('n_samples')}, "
                f"order={s.get('order')}, block_rows={s.get('block_rows')}, n_blocks={s.get('n_blocks')}, "
                f"missed={self.n_missed.sum(axis=1).tolist()} (OO, IO))")


def _csv_cell(x):
    if isinstance(x, (float, np.floating)):
        return "" if not np.isfinite(x) else repr(float(x))
    if isinstance(x, (np.integer, np.bool_)):
        return x.item()
    return x


# --------------------------------------------------------------------------- the run


def monte_carlo(n_records: int = 200, *, n_samples: int = 10_000, order=12, block_rows: int = 15,
                past_block_rows: int | None = None, n_blocks: int = 50, seed: int = 0,
                processes: int | None = None, progress: bool = True, match_tolerance: float = 0.05,
                n_bootstrap: int = _DEFAULT_BOOTSTRAP, chunk_size: int | None = None,
                mp_context: str = "spawn", unknown_input_std: float = 0.1, damping_ratio: float = 0.02,
                n_dof: int = 6, input_dofs=(0,), output_dofs=None, freeze_noise: bool = Settings.freeze_noise,
                noise_coupling_limit: float = Settings.noise_coupling_limit):
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
    freeze_noise, noise_coupling_limit
        Passed to :func:`modaluq.identify` (``freeze_noise=False``: the plain first-order
        propagation, for comparison).

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
                        noise_coupling_limit=noise_coupling_limit)
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
                                   "noise_coupling_limit": settings.noise_coupling_limit},
                         elapsed_s=elapsed, processes=processes, machine=machine, n_bootstrap=n_bootstrap)
        for n in orders)
    return results[0] if single else results


def _store(arrays: dict, chunk_output) -> None:
    indices, part, _ = chunk_output
    for n, by_name in arrays.items():
        for name, target in by_name.items():
            target[:, indices] = part[n][name]
