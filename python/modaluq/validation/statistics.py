"""The statistics of a Monte Carlo run and its result type, :class:`MonteCarloResult`.

:func:`~modaluq.validation.monte_carlo` (``montecarlo.py``) simulates and identifies the
records; this module summarises its per-record arrays (σ̄_est / σ_MC per mode and method, with
a bootstrap standard error), saves and loads them, and writes the tables and figures.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from ..atomic import csv_cell
from ..checks import check_boolean
from ..intervals import interval_factor
from ..jsonvalues import dumps
from .paper import METHOD_LABELS, METHODS

__all__ = ["MonteCarloResult"]

# Bootstrap resamples of the records for the standard error of the std ratio.
DEFAULT_BOOTSTRAP = 1000


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


def blocks_used(settings: dict) -> int:
    """The blocks the core formed for a run's records (``Result.n_blocks``): block length
    ⌊N_c / n_blocks⌋ over N_c = n_samples − (block_rows + past_block_rows − 1) Hankel columns,
    so more than ``n_blocks`` when the remainder holds whole blocks (``compute_covariances`` in
    covariance.hpp). The ``n_blocks`` asked for where the run's settings lack the horizons; 0
    without it."""
    n_b = int(settings.get("n_blocks") or 0)
    n, p, q = (settings.get(k) for k in ("n_samples", "block_rows", "past_block_rows"))
    if n_b < 2 or not all(isinstance(v, int) and v > 0 for v in (n, p, q)):
        return n_b
    columns = n - (p + q - 1)
    return columns // (columns // n_b) if columns >= n_b else n_b


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
    n_bootstrap: int = DEFAULT_BOOTSTRAP

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
    #: (2, n_modes) share of the unflagged records whose |estimate - mean| <= 1.96 × their own σ
    #: (0.95 when σ is right and the estimates are normal)
    frequency_coverage_unflagged: np.ndarray = field(init=False)
    damping_coverage_unflagged: np.ndarray = field(init=False)
    #: (2, n_modes) the same share for the 95 % interval ± t σ (``SelectedModes.intervals``: t the
    #: Student-t quantile with n_blocks − 1 degrees of freedom; 1.96 when n_blocks is unknown)
    frequency_coverage_interval_unflagged: np.ndarray = field(init=False)
    damping_coverage_interval_unflagged: np.ndarray = field(init=False)
    #: the factor t of those intervals (the Student-t quantile of the core's blocks − 1, :func:`blocks_used`)
    interval_factor_95: float = field(init=False)

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
        t95 = interval_factor(blocks_used(self.settings), 0.95)
        set_(self, "interval_factor_95", t95)
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
            for key, factor in (("coverage_unflagged", 1.96), ("coverage_interval_unflagged", t95)):
                with np.errstate(invalid="ignore"):
                    cover = np.where(ok, np.abs(z) <= factor, False).sum(axis=1) / ok.sum(axis=1)
                set_(self, f"{name}_{key}", np.where(ok.sum(axis=1) >= 2, cover, np.nan))
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
        np.savez_compressed(path, meta=np.array(dumps(meta)),
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
    return csv_cell(x)  # text that a spreadsheet would run as a formula is escaped
