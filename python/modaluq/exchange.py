"""Universal File exchange (docs/shapes.md §4): geometry as UFF 15 + 82, modes as UFF 55, their
standard deviations as a second UFF 55 file, and UFF 55 modes of other programs read back.

What is written (pyuff, ASCII):

- **15** the nodes (id, x, y, z; coordinate system 0, the global one);
- **82** the lines, chained into traces (a 0 lifts the pen);
- **55** one dataset per mode: analysis type 3 (complex eigenvalue, first order), the continuous
  eigenvalue ``λ = -ζω + iω√(1-ζ²)`` (rad/s, ω = 2π f) from which any reader takes f and ζ, and
  at every node its 3 global translations (x, y, z; data characteristic 2, complex) from the
  geometry (``Geometry.displacements``: measured nodes from their channels, constrained nodes
  from their constraint, still nodes 0). ID line 4 gives f, ξ and their σ in words;
- the **standard deviations** in a second file (``<name>.std.uff`` beside ``modes.uff``): the
  same datasets, each node component holding ``σ(Re u) + i σ(Im u)`` (from the node covariance,
  exact with ``SelectedModes.mode_covariance``). They are kept apart so that ME'scope,
  ARTeMIS or pyOMA2 opening ``modes.uff`` see modes only.

UFF stores numbers as E13.5 text: 6 significant digits (what the round-trip tests check).

>>> from modaluq import exchange                                              # doctest: +SKIP
>>> exchange.write_uff("modes.uff", selected, geo)                            # doctest: +SKIP
[PosixPath('modes.uff'), PosixPath('modes.std.uff')]
>>> back = exchange.read_uff_modes("modes.uff")                               # doctest: +SKIP
>>> back.plot_shape(1, geometry=back.geometry)                                # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import write_atomically
from .checks import require
from .geometry import Geometry, mode_displacements
from .version import __version__

__all__ = ["UFFModes", "geometry_datasets", "mode_datasets", "read_uff_modes", "std_path_of", "write_geometry_uff",
           "write_uff"]

#: UFF direction codes of the three global translations
DIRECTIONS = ("+X", "+Y", "+Z")
#: ID line 1 of the datasets of standard deviations (how :func:`read_uff_modes` tells them apart)
STD_ID = "modaluq standard deviations"


def _pyuff():
    return require("pyuff", "UFF exchange")  # imported here: an optional file-format library


def std_path_of(path) -> Path:
    """``modes.uff`` → ``modes.std.uff``: where :func:`write_uff` puts the standard deviations."""
    p = Path(path)
    return p.with_name(p.stem + ".std" + p.suffix)


def _traces(lines) -> list:
    """Lines chained into pen strokes: [a, b, c, 0, d, e, ...] (a 0 lifts the pen)."""
    seq = []
    for a, b in np.asarray(lines, np.int64).reshape(-1, 2):
        if seq and seq[-1] == a:
            seq.append(int(b))
        else:
            if seq:
                seq.append(0)
            seq += [int(a), int(b)]
    return seq


def geometry_datasets(geometry: Geometry) -> list:
    """pyuff dictionaries: one dataset 15 of the nodes, one 82 of the lines (none without lines)."""
    pyuff = _pyuff()
    n = geometry.n_nodes
    xyz = geometry.coordinates
    out = [pyuff.prepare_15(node_nums=geometry.node_ids.tolist(), def_cs=[0] * n, disp_cs=[0] * n, color=[11] * n,
                            x=xyz[:, 0].tolist(), y=xyz[:, 1].tolist(), z=xyz[:, 2].tolist())]
    seq = _traces(geometry.lines)
    if seq:
        out.append(pyuff.prepare_82(trace_num=1, n_nodes=len(seq), color=8, id=(geometry.name or "lines")[:80],
                                    nodes=np.asarray(seq, np.int64)))
    return out


def _eigenvalue(f: float, xi: float) -> complex:
    w = 2.0 * math.pi * f
    return complex(-xi * w, w * math.sqrt(max(0.0, 1.0 - xi * xi)))


def mode_datasets(modes, geometry: Geometry, *, std: bool = False) -> list:
    """pyuff dictionaries of UFF 55, one per mode (``std``: of the standard deviations)."""
    pyuff = _pyuff()
    out = []
    sf = getattr(modes, "frequency_std", None)
    sx = getattr(modes, "damping_std", None)
    n_modes = np.asarray(modes.mode_shape).shape[1]
    for k in range(n_modes):
        disp = mode_displacements(modes, k + 1, geometry)
        f, xi = float(modes.frequency_hz[k]), float(modes.damping_ratio[k])
        words = f"mode {k + 1}: f {f:.6g} Hz, xi {xi:.6g}"
        if sf is not None and np.isfinite(sf[k]):
            words += f"; std f {float(sf[k]):.3g} Hz, std xi {float(sx[k]):.3g}"
        if std:
            if disp.covariance is None:
                raise ValueError("modes: no standard deviations to write (no shape covariance or std)")
            var = np.diagonal(disp.covariance, axis1=1, axis2=2)
            values = np.sqrt(np.clip(var[:, :3], 0, None)) + 1j * np.sqrt(np.clip(var[:, 3:], 0, None))
            id1 = STD_ID
            id3 = "sigma(Re u) + i sigma(Im u) per component" + ("" if disp.exact else
                                                                   " (per-channel sigma, correlations neglected)")
        else:
            values = disp.value
            id1 = f"modaluq {__version__} mode shapes"
            id3 = "complex mode shape, largest channel component 1"
        out.append(pyuff.prepare_55(
            id1=id1, id2=(geometry.name or "NONE")[:80], id3=id3[:80], id4=words[:80], id5="NONE",
            model_type=1, analysis_type=3, data_ch=2, spec_data_type=8, data_type=5, n_data_per_node=3,
            load_case=1, mode_n=k + 1, eig=_eigenvalue(f, xi), modal_a=0j, modal_b=0j,
            node_nums=geometry.node_ids.astype(int), r1=values[:, 0], r2=values[:, 1], r3=values[:, 2]))
    return out


def _write_sets(path: Path, sets: list) -> Path:
    pyuff = _pyuff()

    def writer(tmp):
        pyuff.UFF(os.fspath(tmp)).write_sets(sets, mode="overwrite")

    return write_atomically(path, writer)


def write_geometry_uff(path, geometry: Geometry) -> Path:
    """The geometry alone: UFF 15 + 82."""
    return _write_sets(Path(path), geometry_datasets(geometry))


def write_uff(path, modes, geometry: Geometry, *, std_path="auto") -> list:
    """Geometry (15, 82) and one UFF 55 per mode to ``path``; the standard deviations (UFF 55) to
    ``std_path`` (default :func:`std_path_of`; None: not written; nothing when ``modes`` has no σ,
    e.g. an identification with ``uncertainty=False``).

    ``modes``: a :class:`~modaluq.SelectedModes` (or anything :func:`modaluq.shapes.plot_shape`
    takes) whose ``output_names`` the geometry places. Returns the paths written."""
    path = Path(path)
    if path.suffix.lower() not in (".uff", ".unv"):
        raise ValueError(f"path {os.fspath(path)!r}: a Universal File ends in .uff or .unv")
    written = [_write_sets(path, geometry_datasets(geometry) + mode_datasets(modes, geometry))]
    n_modes = np.asarray(modes.mode_shape).shape[1]
    # σ known (a covariance, or finite per-channel std: a run without uncertainty has NaN std)
    has_std = n_modes > 0 and all(mode_displacements(modes, k + 1, geometry).covariance is not None
                                  for k in range(n_modes))
    if std_path is not None and has_std:
        sp = std_path_of(path) if std_path == "auto" else Path(std_path)
        written.append(_write_sets(sp, geometry_datasets(geometry) + mode_datasets(modes, geometry, std=True)))
    return written


@dataclass(frozen=True, repr=False)
class UFFModes:
    """Modes read from UFF 55 datasets (:func:`read_uff_modes`), shaped like the package's modes:
    ``mode_shape`` has one row per node component, named ``output_names`` (``"12+X"``), and
    ``geometry`` places them (from the file's 15/82 when present), so :meth:`plot_shape` works."""

    frequency_hz: np.ndarray          #: (n_modes,) Hz, from the eigenvalue (or the frequency of a normal mode)
    damping_ratio: np.ndarray         #: (n_modes,) fraction (0 for a normal mode without damping)
    mode_shape: np.ndarray            #: (3 n_nodes, n_modes) complex
    output_names: tuple               #: "node+X", "node+Y", "node+Z" per node
    node_ids: np.ndarray              #: (n_nodes,)
    geometry: Geometry | None         #: nodes of the 15 (or 2411) dataset and 82 lines, channels = output_names
    descriptions: tuple = ()          #: ID line 1 of each dataset
    is_std: bool = False              #: the file holds modaluq's standard deviations (:data:`STD_ID`)
    ids: tuple = field(default_factory=tuple)  #: the five ID lines of each dataset

    @property
    def n_modes(self) -> int:
        return int(self.frequency_hz.size)

    def plot_shape(self, mode: int, geometry=None, **kwargs):
        from .shapes import plot_shape

        return plot_shape(self, mode, geometry if geometry is not None else self.geometry, **kwargs)

    def __repr__(self) -> str:
        f = np.array2string(self.frequency_hz, precision=4, separator=", ")
        return f"UFFModes(n_modes={self.n_modes}, n_nodes={self.node_ids.size}, frequency_hz={f})"


def read_uff_modes(path) -> UFFModes:
    """The UFF 55 mode shapes of a file (any program's): normal modes (analysis type 2: f from
    the frequency, ζ from the viscous damping ratio) and complex modes (type 3: f = |λ|/2π,
    ζ = -Re λ/|λ|, λ in rad/s), 3 translations per node (data characteristic 2, or the first 3
    of 6). Nodes missing from a mode are 0. ``ValueError`` naming the file when it has none."""
    pyuff = _pyuff()
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{p}: no such file")
    try:
        sets = pyuff.UFF(os.fspath(p)).read_sets()
    except Exception as exc:  # pyuff raises bare Exceptions
        raise ValueError(f"{p}: not a readable UFF file ({exc})") from None
    sets = [sets] if isinstance(sets, dict) else list(sets)
    modes = [s for s in sets if s.get("type") == 55 and s.get("analysis_type") in (2, 3)]
    if not modes:
        raise ValueError(f"{p}: no mode shapes (UFF 55 of analysis type 2 or 3)")
    node_ids = sorted({int(n) for s in modes for n in np.asarray(s["node_nums"]).reshape(-1)})
    index = {n: i for i, n in enumerate(node_ids)}
    shape = np.zeros((3 * len(node_ids), len(modes)), complex)
    f, xi = np.zeros(len(modes)), np.zeros(len(modes))
    for k, s in enumerate(modes):
        if s.get("data_ch") not in (2, 3):
            raise ValueError(f"{p}: dataset 55 of mode {s.get('mode_n')}: data characteristic {s.get('data_ch')} "
                             "(only 3 or 6 DOF global vectors are mode shapes here)")
        if s["analysis_type"] == 3:
            lam = complex(s["eig"])
            f[k] = abs(lam) / (2 * math.pi)
            xi[k] = -lam.real / abs(lam) if lam else 0.0
        else:
            f[k] = float(s.get("freq", 0.0))
            xi[k] = float(s.get("modal_damp_vis", 0.0))
        for n, *r in zip(np.asarray(s["node_nums"]).reshape(-1), s["r1"], s["r2"], s["r3"]):
            shape[3 * index[int(n)]:3 * index[int(n)] + 3, k] = r
    names = tuple(f"{n}{d}" for n in node_ids for d in DIRECTIONS)
    nodes, lines = {}, []
    for s in sets:
        if s.get("type") in (15, 2411):
            for n, x, y, z in zip(np.asarray(s["node_nums"]).reshape(-1), s["x"], s["y"], s["z"]):
                nodes[int(n)] = (float(x), float(y), float(z))
        elif s.get("type") == 82:
            seq = [int(v) for v in np.asarray(s["nodes"]).reshape(-1)]
            lines += [[a, b] for a, b in zip(seq[:-1], seq[1:]) if a and b]
    geometry = None
    if nodes and all(n in nodes for n in node_ids):
        geometry = Geometry.from_dict({
            "nodes": [[n, *xyz] for n, xyz in nodes.items()], "lines": lines,
            "channels": [{"name": f"{n}{d}", "node": n, "direction": d.lower()} for n in node_ids for d in DIRECTIONS]})
    ids = tuple(tuple(str(s.get(f"id{i}", "")) for i in range(1, 6)) for s in modes)
    return UFFModes(frequency_hz=f, damping_ratio=xi, mode_shape=shape, output_names=names,
                    node_ids=np.asarray(node_ids, np.int64), geometry=geometry,
                    descriptions=tuple(i[0] for i in ids), is_std=all(i[0] == STD_ID for i in ids), ids=ids)
