"""The store: the tracked results as one :class:`xarray.Dataset` (record × mode [× channel]),
written as NetCDF or Zarr, with the table of the selected modes' poles and the table of the
failures beside it (docs/monitoring.md §5); :func:`load_tracks` reads a store back.

The Dataset's schema is here (:func:`dataset`): per record its status, failed stage, error,
warnings, covariates and whether it is in the reference period; per record and tracked mode f, ξ,
their σ and correlation, the MAC (with its σ) and distance to the reference mode, the shape
test's p-value, the change statistics and the alarms (of f and ξ, and of the shape); per tracked
mode the reference and its calibration. NetCDF has no complex type: the complex shapes
(:data:`COMPLEX_SHAPES`) are stored as their real and imaginary parts.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from .. import atomic
from ..checks import require
from ..jsonvalues import dumps
from ..version import __version__

__all__ = ["COMPLEX_SHAPES", "dataset", "failure_table", "load_tracks", "output_paths", "pole_table", "recover",
           "write"]

#: complex variables of the dataset, stored as their real and imaginary parts (NetCDF has no complex type)
COMPLEX_SHAPES = {"mode_shape": "mode shape of the record, largest component 1",
                  "reference_mode_shape": "mode shape of the reference, largest component 1"}


def output_paths(out, poles) -> dict:
    """The files of a store ``out`` (``.nc`` or ``.zarr``): the store, the pole table (``poles``,
    default ``<stem>.poles.csv``), the failures table and the part files' folder; {} without ``out``."""
    if out is None:
        if poles is not None:
            raise ValueError("poles= needs out= (the pole table is written beside the store)")
        return {}
    out = Path(out)
    kind = {".nc": "netcdf", ".zarr": "zarr"}.get(out.suffix.lower())
    if kind is None:
        raise ValueError(f"out {out}: use a .nc (NetCDF) or .zarr store")
    if not out.resolve().parent.is_dir():
        raise ValueError(f"out {out}: the folder {out.resolve().parent} does not exist")
    require("xarray", f"out {out}")
    require("netCDF4" if kind == "netcdf" else "zarr", f"out {out}")
    poles = Path(poles) if poles is not None else out.with_name(out.stem + ".poles.csv")
    if poles.suffix.lower() not in (".csv", ".parquet"):
        raise ValueError(f"poles {poles}: use a .csv or .parquet file")
    if poles.suffix.lower() == ".parquet":
        require("pyarrow", f"poles {poles}")
    return {"store": out, "kind": kind, "poles": poles, "failures": out.with_name(out.stem + ".failures.csv"),
            "parts": out.with_name(out.stem + ".parts")}


def dataset(tasks: list, parts: list, done: np.ndarray, tracks, test, *, channels: tuple, times: np.ndarray,
            covariate_names: list, covariates: np.ndarray, miscalibrated, tracking, error: str, notes: list):
    """The store's Dataset of a batch: its records (``tasks``, ``parts``; ``done``: identified),
    their modes on the tracked modes (:class:`~modaluq.monitoring.tracking.Tracks`), the change
    test (:class:`~modaluq.monitoring.change.ChangeTest`, or None) with the modes whose σ the
    reference does not confirm (``miscalibrated``: (mask, quantile), or None), the covariates
    (names; values (n_records, n_covariates)), the tracking settings, the tracking error and the notes."""
    import xarray as xr

    n, k_modes, ref = len(tasks), tracks.n_modes, tracks.reference
    NP = tracks.place([p["modes"]["n_poles"] if done[k] else None for k, p in enumerate(parts)], np.nan)
    HARM = tracks.place([p["modes"].get("possible_harmonic", [False] * len(p["modes"]["frequency_hz"]))
                         if done[k] else None for k, p in enumerate(parts)], False, bool)
    SH = tracks.mode_shape
    rec_dims, rm, rcm = ("record",), ("record", "mode"), ("record", "channel", "mode")
    data = {
        "status": (rec_dims, np.array([p["status"] for p in parts], dtype=object)),
        "failed_stage": (rec_dims, np.array([p.get("stage", "") for p in parts], dtype=object)),
        "error": (rec_dims, np.array([p.get("error", "") for p in parts], dtype=object)),
        "warnings": (rec_dims, np.array(["\n".join(p.get("warnings", [])) for p in parts], dtype=object),
                     {"long_name": "the identification's warnings, one per line"}),
        "in_reference": (rec_dims, tracks.in_reference),
        "n_blocks": (rec_dims, np.array([p.get("n_blocks", 0) if done[k] else 0 for k, p in enumerate(parts)])),
        "n_modes_selected": (rec_dims, np.array([len(p["modes"]["frequency_hz"]) if done[k] else 0
                                                 for k, p in enumerate(parts)])),
        "n_unassigned": (rec_dims, tracks.n_unassigned),
        "frequency_hz": (rm, tracks.frequency_hz, {"units": "Hz"}),
        "damping_ratio": (rm, tracks.damping_ratio, {"units": "1"}),
        "frequency_std": (rm, tracks.frequency_std, {"units": "Hz"}),
        "damping_std": (rm, tracks.damping_std, {"units": "1"}),
        "frequency_damping_correlation": (rm, tracks.frequency_damping_correlation),
        "mac_to_reference": (rm, tracks.mac_to_reference),
        "mac_to_reference_std": (rm, tracks.mac_to_reference_std,
                                 {"long_name": "std of the MAC to the reference mode (second order)"}),
        "shape_p_value": (rm, tracks.shape_p_value,
                          {"long_name": "p-value of the same-mode test of the shape against the reference mode's"}),
        "shape_alarm": (rm, tracks.shape_alarm,
                        {"long_name": "after the reference period, shape_p_value below the false-alarm rate"}),
        "assignment_distance": (rm, tracks.assignment_distance,
                                {"long_name": "Mahalanobis distance squared to the reference mode"}),
        "n_poles": (rm, NP), "possible_harmonic": (rm, HARM),
        "mode_shape": (rcm, SH, {"long_name": COMPLEX_SHAPES["mode_shape"]}),
        "mode_shape_real": (rcm, SH.real), "mode_shape_imag": (rcm, SH.imag),
        "mode_shape_std_real": (rcm, tracks.mode_shape_std_real),
        "mode_shape_std_imag": (rcm, tracks.mode_shape_std_imag),
    }
    for c, col in zip(covariate_names, covariates.T):
        data[c] = (rec_dims, col, {"long_name": f"covariate {c}"})
    if test is not None:
        data.update({
            "expected_frequency_hz": (rm, test.expected_frequency_hz, {"units": "Hz"}),
            "expected_damping_ratio": (rm, test.expected_damping_ratio, {"units": "1"}),
            "frequency_change": (rm, test.frequency_change, {"long_name": "standardised frequency change"}),
            "damping_change": (rm, test.damping_change, {"long_name": "standardised damping change"}),
            "chi2": (rm, test.chi2, {"long_name": "chi-squared of f and xi against the reference (2 dof)"}),
            "control": (rm, test.control, {"long_name": "MEWMA control statistic (Hotelling T2 of f and xi)"}),
            "alarm": (rm, test.alarm),
            "control_limit": (rm, test.control_limit, {"long_name": "alarm limit of the control statistic"}),
            "reference_reduced_chi2": (("mode",), test.reference_reduced_chi2),
            "reference_reduced_chi2_frequency": (("mode",), test.reference_reduced_chi2_frequency),
            "reference_reduced_chi2_damping": (("mode",), test.reference_reduced_chi2_damping),
            "sigma_confirmed": (("mode",), ~miscalibrated[0],
                                {"long_name": "the reference reduced chi2 of f and xi is within its 99.9 % "
                                              "quantile (false: sigma too small here or a covariate missing; "
                                              "alarms too frequent)"}),
            "frequency_coefficients": (("mode", "term"), test.coefficients_frequency,
                                       {"units": "Hz (constant), Hz per covariate unit (the others)"}),
            "damping_coefficients": (("mode", "term"), test.coefficients_damping,
                                     {"units": "1 (constant), 1 per covariate unit (the others)"}),
        })
    else:
        data["alarm"] = (rm, np.zeros((n, k_modes), bool))
    if ref is not None:
        data.update({
            "reference_frequency_hz": (("mode",), ref.frequency_hz, {"units": "Hz"}),
            "reference_damping_ratio": (("mode",), ref.damping_ratio, {"units": "1"}),
            "reference_mode_shape": (("channel", "mode"), ref.mode_shape,
                                     {"long_name": COMPLEX_SHAPES["reference_mode_shape"]}),
            "reference_mode_shape_real": (("channel", "mode"), ref.mode_shape.real),
            "reference_mode_shape_imag": (("channel", "mode"), ref.mode_shape.imag),
            "reference_presence": (("mode",), ref.presence),
            "frequency_scatter": (("mode",), ref.frequency_scatter, {"units": "Hz"}),
            "damping_scatter": (("mode",), ref.damping_scatter, {"units": "1"}),
        })
    # nanoseconds: what a NetCDF or Zarr store gives back, so the dataset equals the store read again
    coords = {"record": [t.name for t in tasks], "time": (rec_dims, times.astype("datetime64[ns]")),
              "mode": np.arange(1, k_modes + 1), "channel": list(channels)}
    if test is not None:
        coords["term"] = ["constant"] + covariate_names
    attrs = {"title": "modaluq monitoring: tracked modes", "modaluq_version": __version__,
             "false_alarm_rate": tracking.false_alarm_rate,
             "smoothing": tracking.smoothing, "tracking": dumps(tracking.to_dict()),
             "covariate_names": dumps(covariate_names), "tracking_error": error}
    attrs["notes"] = dumps(notes)
    ds = xr.Dataset(data, coords=coords, attrs=attrs)
    ds["status"] = ds["status"].astype(str)
    ds["failed_stage"] = ds["failed_stage"].astype(str)
    ds["error"] = ds["error"].astype(str)
    ds["warnings"] = ds["warnings"].astype(str)
    return ds


def pole_table(tasks: list, parts: list, done: np.ndarray, times: np.ndarray, tracks):
    """One row per pole of every selected mode of the records identified, with its tracked mode
    (1-based; <NA>: its selected mode was assigned to none) (a :class:`pandas.DataFrame`)."""
    import pandas as pd

    rows = []
    for k, p in enumerate(parts):
        if not done[k]:
            continue
        pl = p["poles"]
        idx = tracks.index[k]
        for r in range(len(pl["order"])):
            sm = int(pl["selected_mode"][r])
            tm = int(idx[sm - 1]) + 1 if sm - 1 < len(idx) else 0
            rows.append({"record": tasks[k].name, "time": times[k], "selected_mode": sm,
                         "tracked_mode": tm if tm > 0 else np.nan, "representative": bool(pl["representative"][r]),
                         "order": int(pl["order"][r]), "frequency_hz": pl["frequency_hz"][r],
                         "damping_ratio": pl["damping_ratio"][r], "frequency_std": pl["frequency_std"][r],
                         "damping_std": pl["damping_std"][r]})
    poles = pd.DataFrame(rows, columns=["record", "time", "selected_mode", "tracked_mode", "representative", "order",
                                        "frequency_hz", "damping_ratio", "frequency_std", "damping_std"])
    poles["tracked_mode"] = poles["tracked_mode"].astype("Int64")
    return poles


def failure_table(tasks: list, parts: list, done: np.ndarray):
    """One row per record not identified: record, source, stage, error (a :class:`pandas.DataFrame`)."""
    import pandas as pd

    return pd.DataFrame([{"record": tasks[k].name, "source": p.get("source", tasks[k].name),
                          "stage": p.get("stage", ""), "error": p.get("error", "")}
                         for k, p in enumerate(parts) if not done[k]],
                        columns=["record", "source", "stage", "error"])


def recover(paths: dict) -> list:
    """Clean up after writers of these outputs (:func:`output_paths`) that died: a store left as
    ``<store>.old-<pid>`` between the two renames of its swap is put back; the temporaries of dead
    writers are removed (:func:`modaluq.atomic.recover`). Returns what was done, one line each."""
    return [line for key in ("store", "poles", "failures") for line in atomic.recover(paths[key])]


def write(result, paths: dict) -> tuple:
    """Write a :class:`~modaluq.monitoring.Monitoring` to the files of :func:`output_paths`: the
    store, the pole table and the failures table. Returns their names.

    Each is written to a temporary beside it (``<name>.tmp-<pid>``) and the three are renamed
    into place only once all are complete (a Zarr store, a directory, with two renames:
    :func:`modaluq.atomic.commit`), so the previous outputs survive any failure. If one cannot be
    written (full disk ...) the error names it, nothing is replaced, except the failures table,
    which is still written if it can be (the failures are what a user reads first)."""
    recover(paths)
    ds = result.dataset.drop_vars(list(COMPLEX_SHAPES), errors="ignore")  # stored as real and imaginary parts
    store = paths["store"]
    if paths["kind"] == "netcdf":
        def write_store(tmp):
            ds.to_netcdf(tmp)
    else:
        import zarr

        # Zarr format 2 (the only one of zarr < 3): its string arrays (record names, status) are
        # specified and readable by every Zarr library; zarr 3 warns that its own v3 strings are not
        fmt = {"zarr_format": 2} if int(zarr.__version__.split(".")[0]) >= 3 else {}

        def write_store(tmp):
            ds.to_zarr(tmp, mode="w", consolidated=True, **fmt)
    if paths["poles"].suffix.lower() == ".parquet":
        def write_poles(tmp):
            result.poles.to_parquet(tmp, index=False)
    else:
        def write_poles(tmp):
            atomic.csv_safe(result.poles).to_csv(tmp, index=False)

    def write_failures(tmp):
        atomic.csv_safe(result.failures).to_csv(tmp, index=False)

    # The failures table first: small, and wanted even when the store cannot be written (a full
    # disk); then the pole table, then the store. Nothing is put in place before all three are complete.
    written = []  # (temporary, output), complete and not yet in place
    failed = None  # the output that could not be written
    try:
        for path, writer in ((paths["failures"], write_failures), (paths["poles"], write_poles),
                             (store, write_store)):
            failed = path
            written.append((atomic.write_temporary(path, writer), path))
        failed = None
        while written:
            atomic.commit(*written[0])
            written.pop(0)
    except BaseException as exc:
        failures_done = [(tmp, path) for tmp, path in written if path == paths["failures"]]
        for tmp, path in written:
            if not (isinstance(exc, Exception) and failed in (store, paths["poles"]) and path == paths["failures"]):
                atomic.discard(tmp)
        if isinstance(exc, Exception) and failed in (store, paths["poles"]):
            with contextlib.suppress(OSError):  # the first error is the one to report
                if failures_done:
                    atomic.commit(*failures_done[0])
                else:
                    atomic.write_atomically(paths["failures"], write_failures)
        raise
    return (str(store), str(paths["poles"]), str(paths["failures"]))


def load_tracks(path):
    """A monitoring store (.nc or .zarr) as an :class:`xarray.Dataset`, with the complex
    ``mode_shape`` and ``reference_mode_shape`` rebuilt from their real and imaginary parts."""
    require("xarray", "load_tracks")
    import xarray as xr

    path = Path(path)
    ds = xr.open_zarr(path) if path.suffix.lower() == ".zarr" else xr.open_dataset(path)
    ds = ds.load()
    ds.close()
    for name, long_name in COMPLEX_SHAPES.items():
        if f"{name}_real" in ds:
            ds[name] = ds[f"{name}_real"] + 1j * ds[f"{name}_imag"]
            ds[name].attrs["long_name"] = long_name
    for flag in ("alarm", "shape_alarm"):
        if flag in ds:
            ds[flag] = ds[flag].astype(bool)
    return ds
