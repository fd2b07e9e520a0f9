"""Write identification reports: JSON (with a provenance stamp), CSV and NetCDF.

- **JSON** (:func:`write_json`): a provenance stamp (modaluq version, every setting, the input
  file's SHA-256, a UTC timestamp) and the selected modes with their analytic σ and the spread
  across their cluster, mode shapes per channel.
- **CSV** (:func:`write_csv`): one row per selected mode (``SelectedModes.to_dataframe()``);
  plain table, no comment lines (the stamp lives in the JSON and NetCDF files).
- **NetCDF-4** (:func:`write_netcdf`, needs xarray and netCDF4, extra ``export``): the full
  stabilization diagram, every pole with status, reason and σ, plus the selected modes, with
  the stamp as global attributes.

Each file is written to a temporary beside it and renamed into place once complete
(:mod:`modaluq.atomic`): an earlier file of that name is replaced whole or left as it was, and a
failed write (full disk) raises :class:`OSError` naming the file. CSV text cells that a
spreadsheet would run as a formula are escaped (:func:`modaluq.atomic.csv_cell`).

Every conversion of a result to a file format lives here (``Diagram.to_xarray`` and
``SelectedModes.to_dict`` call it).

>>> from modaluq import export                                          # doctest: +SKIP
>>> stamp = export.provenance("run1.csv", settings={"identification": result.settings})  # doctest: +SKIP
>>> export.write("modes.json", diagram, selected, stamp=stamp)          # doctest: +SKIP
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .atomic import csv_safe, write_atomically
from .checks import require
from .geometry import node_shapes
from .jsonvalues import dumps, finite_or_none, jsonable
from .provenance import file_sha256, provenance
from .settings import PoleStatus

__all__ = ["EXTENSIONS", "diagram_to_xarray", "file_sha256", "provenance", "report", "selected_modes_to_dict",
           "write", "write_csv", "write_json", "write_netcdf"]

#: file extension -> what :func:`write` writes
EXTENSIONS = {".json": "json", ".csv": "csv", ".nc": "netcdf", ".nc4": "netcdf"}


def selected_modes_to_dict(selected) -> dict:
    """:class:`~modaluq.SelectedModes` as plain Python (JSON-ready): one dict per mode, shapes per channel."""
    num = finite_or_none
    noise_coupled = selected.noise_coupled
    bounds = selected.intervals(0.95).to_numpy()  # the 95 % intervals x ± t σ, one row per mode
    modes = []
    for i in range(selected.n_modes):
        shape = {}
        for k, name in enumerate(selected.output_names):
            shape[name] = {
                "real": num(selected.mode_shape[k, i].real), "imag": num(selected.mode_shape[k, i].imag),
                "std_real": num(selected.mode_shape_std_real[k, i]),
                "std_imag": num(selected.mode_shape_std_imag[k, i]),
                "spread_real": num(selected.mode_shape_spread_real[k, i]),
                "spread_imag": num(selected.mode_shape_spread_imag[k, i]),
            }
        modes.append({
            "mode": i + 1,
            "frequency_hz": num(selected.frequency_hz[i]), "frequency_std": num(selected.frequency_std[i]),
            "frequency_spread": num(selected.frequency_spread[i]),
            "damping_ratio": num(selected.damping_ratio[i]), "damping_std": num(selected.damping_std[i]),
            "damping_spread": num(selected.damping_spread[i]),
            "frequency_interval_95_hz": [num(bounds[i, 0]), num(bounds[i, 1])],
            "damping_interval_95": [num(bounds[i, 2]), num(bounds[i, 3])],
            "representative_order": int(selected.representative_order[i]),
            "shape_order": int(selected.shape_order[i]),
            "n_poles": int(selected.n_poles[i]), "order_min": int(selected.order_min[i]),
            "order_max": int(selected.order_max[i]), "min_mac": num(selected.min_mac[i]),
            # every pole noise-coupled: may be noise, not a mode (SelectedModes.noise_coupled)
            "noise_coupled": bool(noise_coupled[i]),
            # σ widened by the model order's effect (SelectedModes.order_discrepancy)
            "order_discrepancy": bool(selected.order_discrepancy[i]),
            # σ raised to the poles' unfrozen bound ρσ (SelectedModes.unanchored)
            "unanchored": bool(selected.unanchored[i]),
            "mpc": num(selected.mpc[i]), "mpc_std": num(selected.mpc_std[i]),
            "mpd_deg": num(selected.mpd_deg[i]), "mpd_std_deg": num(selected.mpd_std_deg[i]),
            "mode_shape": shape,
        })
    return {
        "modes": modes,
        "dropped_clusters": [{"frequency_hz": num(f), "n_poles": int(n), "reason": str(r)}
                             for f, n, r in zip(selected.dropped_frequency_hz, selected.dropped_n_poles,
                                                selected.dropped_reason)],
        "min_cluster_size": int(selected.min_cluster_size),
        # how the intervals were formed: x ± factor σ, the Student-t quantile of n_blocks - 1 (0: unknown)
        "interval_95": {"level": 0.95,
                        "factor": num(selected.interval_factor(0.95)) if selected.has_uncertainty else None,
                        "n_blocks": int(selected.n_blocks)},
        # H within 3 std of its estimation noise: every mode may be noise (SelectedModes.low_signal_to_noise)
        "low_signal_to_noise": bool(selected.low_signal_to_noise),
        "clustering": selected.settings.to_dict(),
    }


def diagram_to_xarray(diagram, selected=None, attrs: dict | None = None, geometry=None):
    """A :class:`~modaluq.Diagram` (and optionally the selected modes) as an :class:`xarray.Dataset`.

    Dimensions ``pole`` and ``channel`` (and ``mode`` with ``selected``, whose variables are
    prefixed ``selected_``); mode shapes are split into ``*_real`` / ``*_imag`` variables so
    that the dataset writes to NetCDF-4.
    ``attrs`` (e.g. a provenance stamp) become global attributes; nested values are stored
    as JSON strings. With ``geometry`` (and ``selected``), every node's displacement of each mode
    and its σ (:func:`modaluq.geometry.node_shapes`) in ``selected_node_shape_*`` (mode, node, axis)
    and the nodes' coordinates in ``node_coordinates`` (node, axis).
    """
    xr = require("xarray", "Diagram.to_xarray")

    pole_vars = {
        "order": (("pole",), diagram.order, {"long_name": "model order"}),
        "frequency_hz": (("pole",), diagram.frequency_hz, {"units": "Hz"}),
        "damping_ratio": (("pole",), diagram.damping_ratio, {"units": "1", "long_name": "damping ratio (fraction)"}),
        "frequency_std": (("pole",), diagram.frequency_std, {"units": "Hz"}),
        "damping_std": (("pole",), diagram.damping_std, {"units": "1"}),
        "status": (("pole",), np.array([s.value for s in diagram.status], dtype=object), {}),
        "reason": (("pole",), np.asarray(diagram.reason, dtype=object), {}),
        "matched_pole": (("pole",), diagram.matched_pole,
                         {"long_name": "index of the matched pole at the previous order (-1: none)"}),
        "frequency_change": (("pole",), diagram.frequency_change, {"units": "1"}),
        "damping_change": (("pole",), diagram.damping_change, {"units": "1"}),
        "mac": (("pole",), diagram.mac, {"units": "1"}),
        "frequency_change_std": (("pole",), diagram.frequency_change_std, {"units": "1"}),
        "close_singular_values": (("pole",), diagram.close_singular_values.astype(np.int8), {}),
        "noise_coupled": (("pole",), diagram.noise_coupled.astype(np.int8),
                          {"long_name": "sigma not first-order meaningful: pole coupled to noise directions"}),
        "mode_shape_real": (("channel", "pole"), diagram.mode_shape.real, {}),
        "mode_shape_imag": (("channel", "pole"), diagram.mode_shape.imag, {}),
        "mode_shape_std_real": (("channel", "pole"), diagram.mode_shape_std_real, {}),
        "mode_shape_std_imag": (("channel", "pole"), diagram.mode_shape_std_imag, {}),
    }
    if np.size(diagram.mpc) == diagram.n_poles:
        pole_vars["mpc"] = (("pole",), diagram.mpc, {"units": "1", "long_name": "modal phase collinearity"})
        pole_vars["mpd"] = (("pole",), diagram.mpd_deg, {"units": "degree", "long_name": "mean phase deviation"})
    coords = {"pole": np.arange(diagram.n_poles), "channel": list(diagram.output_names)}
    if selected is not None:
        sel = selected
        pole_vars["mode_of_pole"] = (("pole",), sel.mode_of_pole + 1,
                                     {"long_name": "selected mode number of each pole (as the mode "
                                                   "coordinate, from 1; 0: none)"})
        for name in ("frequency_hz", "damping_ratio", "frequency_std", "damping_std",
                     "frequency_spread", "damping_spread", "representative_order",
                     "representative_pole", "shape_order", "shape_pole", "n_poles", "order_min", "order_max",
                     "min_mac"):
            pole_vars[f"selected_{name}"] = (("mode",), getattr(sel, name), {})
        law = (f"Student t, n_blocks - 1 = {sel.n_blocks - 1} degrees of freedom" if sel.n_blocks >= 2
               else "normal quantile: the number of blocks is unknown")
        for name, column in zip(sel.INTERVAL_95_COLUMNS, sel.intervals(0.95).to_numpy().T):
            pole_vars[f"selected_{name}"] = (
                ("mode",), column, {"units": "Hz" if name.endswith("_hz") else "1",
                                    "long_name": f"95 % interval bound: value +- {sel.interval_factor(0.95):.4f} "
                                                 f"std ({law})"})
        pole_vars["selected_mpc"] = (("mode",), sel.mpc, {"units": "1", "long_name": "modal phase collinearity"})
        pole_vars["selected_mpc_std"] = (("mode",), sel.mpc_std, {"units": "1"})
        pole_vars["selected_mpd"] = (("mode",), sel.mpd_deg, {"units": "degree", "long_name": "mean phase deviation"})
        pole_vars["selected_mpd_std"] = (("mode",), sel.mpd_std_deg, {"units": "degree"})
        if sel.mode_covariance is not None:
            pole_vars["selected_covariance"] = (
                ("mode", "parameter", "parameter_"), sel.mode_covariance,
                {"long_name": "covariance of [f (Hz), xi, Re shape, Im shape] of each mode "
                                  "(SelectedModes.mode_covariance: the shape pole's)"})
            params = ["frequency_hz", "damping_ratio"] + [f"re_{c}" for c in diagram.output_names] + \
                     [f"im_{c}" for c in diagram.output_names]
            coords["parameter"] = params
            coords["parameter_"] = params
        pole_vars["selected_noise_coupled"] = (("mode",), np.asarray(sel.noise_coupled, np.int8),
                                               {"long_name": "every pole of the mode is noise-coupled: it may be "
                                                             "noise, not a mode"})
        pole_vars["selected_order_discrepancy"] = (
            ("mode",), np.asarray(sel.order_discrepancy, np.int8),
            {"long_name": "the std of f or xi includes the difference between the representative and the lowest "
                          "sufficient order, which exceeded 1.96 of the two poles' combined std"})
        pole_vars["selected_unanchored"] = (
            ("mode",), np.asarray(sel.unanchored, np.int8),
            {"long_name": "every pole of the mode depends on the frozen noise directions (noise coupling above "
                          "unanchored_noise_coupling at every order): the std are the poles' unfrozen bound rho*std"})
        for name, values in (("mode_shape_real", sel.mode_shape.real), ("mode_shape_imag", sel.mode_shape.imag),
                             ("mode_shape_std_real", sel.mode_shape_std_real),
                             ("mode_shape_std_imag", sel.mode_shape_std_imag),
                             ("mode_shape_spread_real", sel.mode_shape_spread_real),
                             ("mode_shape_spread_imag", sel.mode_shape_spread_imag)):
            pole_vars[f"selected_{name}"] = (("channel", "mode"), values, {})
        coords["mode"] = np.arange(1, sel.n_modes + 1)  # numbered from 1, as in every table and plot
        if geometry is not None:
            ns = node_shapes(sel, geometry)
            dims = ("mode", "node", "axis")
            how = "exact" if ns.exact else "per-channel"
            unit = {"long_name": f"displacement of the node, global axes ({how} sigma through the geometry's map)"}
            for name, values in (("real", ns.value.real), ("imag", ns.value.imag), ("std_real", ns.std_real),
                                 ("std_imag", ns.std_imag)):
                pole_vars[f"selected_node_shape_{name}"] = (dims, values, unit)
            pole_vars["node_coordinates"] = (("node", "axis"), geometry.coordinates, {"units": geometry.units})
            pole_vars["node_moving"] = (("node",), ns.moving.astype(np.int8),
                                        {"long_name": "1: the node's displacement comes from channels; 0: it is fixed"})
            coords["node"] = geometry.node_ids
            coords["axis"] = ["x", "y", "z"]
    ds = xr.Dataset({k: xr.Variable(d, v, a) for k, (d, v, a) in pole_vars.items()}, coords=coords)
    gattrs = {"fs_hz": diagram.fs, "criteria": dumps(diagram.criteria.to_dict()),
              "identification_settings": dumps(diagram.result_settings)}
    if selected is not None:
        gattrs["clustering"] = dumps(selected.settings.to_dict())
        # H within 3 std of its estimation noise: the modes cannot be told from noise
        gattrs["low_signal_to_noise"] = int(bool(selected.low_signal_to_noise))
    for k, v in (attrs or {}).items():
        gattrs[k] = v if isinstance(v, (str, int, float)) else dumps(v)
    ds.attrs.update(gattrs)
    return ds


def report(diagram, selected, *, stamp: dict | None = None, extra: dict | None = None, geometry=None) -> dict:
    """The JSON report as a dict: stamp, diagram summary, selected modes (see :func:`write_json`);
    with ``geometry``, every node's displacement of each mode with its σ (``node_shapes``)."""
    out = {"stamp": stamp if stamp is not None else provenance()}
    if extra:
        out.update(jsonable(extra))
    if diagram is not None:
        out["diagram"] = {
            "orders": list(diagram.orders),
            "n_poles": diagram.n_poles,
            "status_counts": {s.value: diagram.count(s) for s in PoleStatus},
            "close_singular_value_orders": list(diagram.close_singular_value_orders),
            "noise_coupled_poles": int(np.count_nonzero(diagram.noise_coupled)),
            "criteria": diagram.criteria.to_dict(),
            "has_uncertainty": bool(diagram.has_uncertainty),
            "output_names": list(diagram.output_names),
        }
    sel = selected.to_dict()
    out["clustering"] = {k: sel[k] for k in ("clustering", "min_cluster_size", "dropped_clusters", "interval_95")}
    out["low_signal_to_noise"] = sel["low_signal_to_noise"]
    out["units"] = {"frequency_hz": "Hz", "damping_ratio": "fraction (0.02 = 2 %)",
                    "std": f"analytic (delta-method) standard deviation, {selected.std_words}"
                           + ("" if selected.settings.representative == "lowest"
                              else " (its poles that are not noise-coupled and not at a close cut, or all of them "
                                   "where most are noise-coupled; widened where order_discrepancy)"),
                    "spread": "sample standard deviation across the poles of the mode's cluster",
                    "noise_coupled": "every pole of the mode's cluster is noise-coupled (no first-order std): it "
                                     "may be noise, not a mode",
                    "order_discrepancy": "the std of f or xi includes the difference between the mode at its "
                                         "representative's order and at its lowest sufficient order, which "
                                         "exceeded 1.96 of the two poles' combined std: the estimate moves with "
                                         "the model order",
                    "unanchored": "every pole of the mode depends on the frozen noise directions (the noise floor "
                                  "k* is below the mode): its std are at least the poles' unfrozen bound rho*std",
                    "low_signal_to_noise": "H is within 3 std of its estimation noise: the modes cannot be told "
                                           "from noise",
                    "frequency_interval_95_hz": "95 % interval [low, high] of f: value +- t std, t the Student-t "
                                                "quantile with n_blocks - 1 degrees of freedom (clustering."
                                                "interval_95): it covers 95 % where +-1.96 std covers less",
                    "damping_interval_95": "95 % interval [low, high] of xi, as frequency_interval_95_hz",
                    "mpc": "modal phase collinearity (1: real shape), std to second order",
                    "mpd_deg": "mean phase deviation, degrees (0: real shape), first-order std",
                    "mode_shape": "normalised: largest-modulus component = 1"}
    out["modes"] = sel["modes"]
    if geometry is not None:
        ns = node_shapes(selected, geometry)
        out["units"]["node_shapes"] = ("displacement of each node in the global axes x, y, z (the geometry's map of "
                                       "the channels: measured nodes, constrained nodes through their constraint, "
                                       "fixed nodes 0), with sigma(Re) and sigma(Im) through the same map")
        out["node_shapes"] = {
            "geometry": geometry.name, "units": geometry.units, "node_ids": ns.node_ids.tolist(),
            "coordinates": geometry.coordinates.tolist(), "moving": ns.moving.tolist(), "exact_sigma": ns.exact,
            "modes": [{"mode": k + 1, "real": ns.value[k].real.tolist(), "imag": ns.value[k].imag.tolist(),
                       "std_real": ns.std_real[k].tolist(), "std_imag": ns.std_imag[k].tolist()}
                      for k in range(ns.value.shape[0])]}
    return jsonable(out)


def write_json(path, diagram, selected, *, stamp: dict | None = None, extra: dict | None = None,
               geometry=None) -> Path:
    """Write :func:`report` to ``path`` as indented UTF-8 JSON; return the path."""
    path = Path(path)
    text = dumps(report(diagram, selected, stamp=stamp, extra=extra, geometry=geometry), indent=2)
    return write_atomically(path, lambda tmp: tmp.write_text(text + "\n", encoding="utf-8"))


def write_csv(path, selected) -> Path:
    """Write the selected modes (one row each, with σ and spread) as CSV; return the path."""
    table = csv_safe(selected.to_dataframe())
    return write_atomically(path, lambda tmp: table.to_csv(tmp, index=True))  # the index: the mode number, from 1


def write_netcdf(path, diagram, selected=None, *, stamp: dict | None = None, geometry=None) -> Path:
    """Write the full diagram (every pole, status, reason, σ) and the selected modes to NetCDF-4
    (with ``geometry``: their node shapes too, :func:`diagram_to_xarray`)."""
    require("netCDF4", "writing NetCDF")  # xarray's own message would name an "engine", not the package
    ds = diagram_to_xarray(diagram, selected, attrs={"stamp": dumps(stamp or provenance())}, geometry=geometry)
    return write_atomically(path, lambda tmp: ds.to_netcdf(tmp, engine="netcdf4"))


def write(path, diagram, selected, *, stamp: dict | None = None, extra: dict | None = None, geometry=None) -> Path:
    """Write by extension: ``.json`` (:func:`write_json`), ``.csv`` (:func:`write_csv`), ``.nc``
    (:func:`write_netcdf`). Raises ``ValueError`` naming ``path`` for another extension. With
    ``geometry``, the JSON and NetCDF hold every node's displacement of each mode with its σ
    (the CSV stays one row per mode, per channel)."""
    kind = EXTENSIONS.get(Path(path).suffix.lower())
    if kind is None:
        raise ValueError(f"path {os.fspath(path)!r}: unsupported extension; use one of "
                         f"{', '.join(EXTENSIONS)}")
    if kind == "json":
        return write_json(path, diagram, selected, stamp=stamp, extra=extra, geometry=geometry)
    if kind == "csv":
        return write_csv(path, selected)
    return write_netcdf(path, diagram, selected, stamp=stamp, geometry=geometry)
