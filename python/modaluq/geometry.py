"""Test geometry: nodes, lines, and where each channel measures (docs/shapes.md).

A :class:`Geometry` holds

- **nodes**: integer ids and their coordinates x, y, z (one length unit, ``units``);
- **lines** (pairs of node ids) and optionally **triangles** (triples), what is drawn;
- **channels**: each channel (a shape's ``dof_names`` entry) at a node, measuring along a
  direction (a unit vector in the global axes; a non-unit vector is normalised, a zero one refused);
- optional **constraints** for nodes without sensors: ``linear`` (one component of a node as a
  weighted sum of channels) and ``rigid`` (nodes that move with a rigid body, e.g. a floor, whose
  motion is fitted to the channels listed).

Everything a node does is one **linear** map of the channel values: ``u = T φ`` with ``T``
(3 n_nodes × n_channels, real, :attr:`Geometry.transform`). :meth:`Geometry.displacements` applies
it to a complex shape and, given the shape's covariance, propagates it exactly (a linear map has no
first-order error): ``cov(u) = T cov(φ) Tᵀ`` for the real and imaginary parts and their cross terms.

How a node gets its displacement:

1. a node of a ``rigid`` constraint: the rigid body's motion at the node (translation t and
   rotation θ, ``u = t + θ × (p - c)``) fitted by least squares to the constraint's channels
   (``d_k · u(p_k) = φ_k``); a ``plane`` rigid body (``normal`` given) moves in its plane only
   (two translations and the rotation about the normal; out of plane 0). Motions the channels do
   not observe (a shear frame's floor with one sensor along x: y and the rotation) are taken as 0
   (translations are fitted first, then rotations), said in :attr:`Geometry.unobserved`;
2. any other node with channels or ``linear`` constraints: each is a row ``d · u = w · φ``
   (a channel: its direction and weight 1 on itself), solved by least squares with the minimum norm;
   a node measured along x only moves along x;
3. a node with neither: does not move (drawn, marked as not measured).

Files: a small TOML format (:meth:`Geometry.from_toml`), CSV tables (:meth:`Geometry.from_csv`),
UFF datasets 15 (or 2411) and 82 with a channel map (:meth:`Geometry.from_uff`); see docs/shapes.md.

>>> geo = Geometry.from_toml("frame.toml")                               # doctest: +SKIP
>>> d = geo.displacements(selected.mode_shape[:, 0], selected.output_names)  # doctest: +SKIP
>>> d.value.shape                                                         # doctest: +SKIP
(n_nodes, 3)
"""

from __future__ import annotations

import csv
import math
import numbers
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .checks import check_integer

__all__ = ["Constraint", "Geometry", "NodeDisplacements", "NodeShapes", "direction_vector", "mode_displacements",
           "node_shapes"]

#: axis names accepted for a direction, as in UFF's +X ... -Z
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
#: a direction shorter than this is degenerate (after the coordinates' own rounding)
MIN_DIRECTION_NORM = 1e-12


def direction_vector(value, name: str = "direction") -> np.ndarray:
    """A unit 3-vector from ``"+x"``, ``"-Y"``, ``"z"`` or three numbers (normalised).

    Raises ``ValueError`` naming ``name`` for a zero, non-finite or malformed direction.
    """
    if isinstance(value, str):
        s = value.strip().lower()
        sign = -1.0 if s.startswith("-") else 1.0
        axis = s.lstrip("+-")
        if axis not in AXES:
            raise ValueError(f"{name} {value!r}: expected +x, -y, z ... or three numbers")
        return sign * np.asarray(AXES[axis])
    try:
        v = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} {value!r}: expected +x, -y, z ... or three numbers") from None
    if v.size != 3 or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} {value!r}: expected three finite numbers")
    n = float(np.linalg.norm(v))
    if n < MIN_DIRECTION_NORM:
        raise ValueError(f"{name} {value!r}: degenerate (zero) direction")
    return v / n


def _node_id(value, name: str) -> int:
    # UFF labels nodes by positive integers; so does the geometry (a float 3.0 is accepted as 3)
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be a positive integer node id; got {value!r}")
    if isinstance(value, numbers.Real) and float(value).is_integer() and value > 0:
        return int(value)
    if isinstance(value, str) and value.strip().isdigit() and int(value) > 0:
        return int(value)
    raise ValueError(f"{name} must be a positive integer node id; got {value!r}")


@dataclass(frozen=True)
class Constraint:
    """Displacements of nodes without (enough) sensors, as linear combinations of channels.

    ``kind="linear"``: the component of ``nodes[0]`` along ``direction`` is ``Σ weights[c] φ_c``.
    ``kind="rigid"``: ``nodes`` move with one rigid body fitted to ``channels`` (about ``center``,
    default the mean of those nodes); with ``normal`` the body moves in its plane only.
    """

    kind: str                          #: "linear" or "rigid"
    nodes: tuple                       #: node ids the constraint gives
    channels: tuple = ()               #: rigid: the channels the body's motion is fitted to
    direction: tuple | None = None     #: linear: the unit direction of the component given
    weights: tuple = ()                #: linear: one weight per entry of ``channels``
    normal: tuple | None = None        #: rigid: unit normal of a plane body (None: 3-D rigid body)

    def to_dict(self) -> dict:
        out = {"kind": self.kind}
        if self.kind == "linear":
            out.update(node=self.nodes[0], direction=list(self.direction),
                       weights=dict(zip(self.channels, self.weights)))
        else:
            out.update(nodes=list(self.nodes), channels=list(self.channels))
            if self.normal is not None:
                out["normal"] = list(self.normal)
        return out


@dataclass(frozen=True, eq=False)
class NodeDisplacements:
    """Per-node complex 3-D displacement of one shape, with its covariance when known.

    ``value[n]`` is node n's (x, y, z) displacement (complex: the shape's phase per component).
    ``covariance[n]`` is the 6×6 covariance of ``[Re u_n, Im u_n]`` (None without one); the
    displacement over a cycle, ``Re(u e^{iα})``, has the 3×3 covariance :meth:`covariance_at`.
    """

    node_ids: np.ndarray               #: (n_nodes,)
    value: np.ndarray                  #: (n_nodes, 3) complex
    covariance: np.ndarray | None      #: (n_nodes, 6, 6) of [Re u, Im u], or None
    moving: np.ndarray                 #: (n_nodes,) bool: the node's displacement comes from channels
    exact: bool = True                 #: False: covariance from per-channel σ only (correlations neglected)

    def at_phase(self, alpha: float) -> np.ndarray:
        """Real displacement at phase α of the cycle: ``Re(u e^{iα}) = Re u cos α - Im u sin α``."""
        return self.value.real * math.cos(alpha) - self.value.imag * math.sin(alpha)

    def covariance_at(self, alpha: float) -> np.ndarray | None:
        """(n_nodes, 3, 3) covariance of :meth:`at_phase` (exact: a linear map of [Re u, Im u])."""
        if self.covariance is None:
            return None
        m = np.hstack([math.cos(alpha) * np.eye(3), -math.sin(alpha) * np.eye(3)])  # 3 x 6
        return np.einsum("ij,njk,lk->nil", m, self.covariance, m)

    def largest_std(self, alpha: float) -> float:
        """The largest principal σ of any moving node's displacement at phase α (half the longest
        ±1σ ellipsoid axis drawn), in the shape's units; NaN without a covariance, 0 if nothing moves."""
        cov = self.covariance_at(alpha)
        if cov is None:
            return float("nan")
        top = max((float(np.linalg.eigvalsh(0.5 * (c + c.T))[-1]) for c in cov[self.moving]), default=0.0)
        return math.sqrt(max(top, 0.0))

    @property
    def real_covariance(self) -> np.ndarray | None:
        """(n_nodes, 3, 3) covariance of Re u (phase 0)."""
        return None if self.covariance is None else self.covariance[:, :3, :3]


@dataclass(frozen=True, eq=False)  # arrays: compared by identity (== of arrays is not a bool)
class Geometry:
    """Nodes, lines and channel placement; see the module docstring and docs/shapes.md."""

    node_ids: np.ndarray               #: (n_nodes,) int, distinct, > 0
    coordinates: np.ndarray            #: (n_nodes, 3) float, in ``units``
    channels: tuple                    #: channel names (a shape's dof_names), distinct
    channel_node: np.ndarray           #: (n_channels,) node id of each channel
    channel_direction: np.ndarray      #: (n_channels, 3) unit vectors, global axes
    lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))      #: (n_lines, 2) node ids
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))  #: (n, 3) node ids
    constraints: tuple = ()            #: :class:`Constraint`\\ s
    units: str = "m"                   #: length unit of the coordinates
    name: str = ""                     #: a title (the structure)

    def __post_init__(self):
        ids = np.asarray([_node_id(v, "node id") for v in np.asarray(self.node_ids).reshape(-1)], np.int64)
        xyz = np.asarray(self.coordinates, dtype=float)
        if xyz.shape != (ids.size, 3):
            raise ValueError(f"coordinates must be (n_nodes, 3) = ({ids.size}, 3); got {xyz.shape}")
        if not np.all(np.isfinite(xyz)):
            bad = ids[~np.all(np.isfinite(xyz), axis=1)]
            raise ValueError(f"coordinates of node {int(bad[0])} are not finite")
        if ids.size == 0:
            raise ValueError("nodes: a geometry needs at least one node")
        uniq, counts = np.unique(ids, return_counts=True)
        if np.any(counts > 1):
            raise ValueError(f"node {int(uniq[counts > 1][0])} is defined twice")
        known = set(ids.tolist())
        names = tuple(str(c) for c in self.channels)
        if len(set(names)) != len(names):
            dup = next(c for c in names if names.count(c) > 1)
            raise ValueError(f"channel {dup!r} is placed twice")
        cn = np.asarray(self.channel_node).reshape(-1)
        if cn.size != len(names):
            raise ValueError(f"channel_node must have one node per channel ({len(names)}); got {cn.size}")
        cnode = []
        for c, n in zip(names, cn):
            if n is None or (isinstance(n, float) and math.isnan(n)):
                raise ValueError(f"channel {c!r} has no node")
            n = _node_id(n, f"node of channel {c!r}")
            if n not in known:
                raise ValueError(f"channel {c!r}: unknown node {n}")
            cnode.append(n)
        cd = np.asarray(self.channel_direction, dtype=float).reshape(len(names), 3) if names else np.zeros((0, 3))
        cd = np.array([direction_vector(d, f"direction of channel {c!r}") for c, d in zip(names, cd)]).reshape(-1, 3)
        object.__setattr__(self, "node_ids", ids)
        object.__setattr__(self, "coordinates", xyz)
        object.__setattr__(self, "channels", names)
        object.__setattr__(self, "channel_node", np.asarray(cnode, np.int64))
        object.__setattr__(self, "channel_direction", cd)
        for attr, k in (("lines", 2), ("triangles", 3)):
            raw = np.asarray(getattr(self, attr), dtype=object)
            rows = raw.reshape(-1, k) if raw.size else np.zeros((0, k), object)
            if raw.size and raw.size % k:
                raise ValueError(f"{attr} must be rows of {k} node ids")
            arr = np.array([[_node_id(v, attr[:-1] + " node") for v in row] for row in rows], np.int64).reshape(-1, k)
            for row in arr:
                for v in row:
                    if int(v) not in known:
                        raise ValueError(f"{attr[:-1]} {row.tolist()}: unknown node {int(v)}")
            object.__setattr__(self, attr, arr)
        object.__setattr__(self, "constraints", tuple(self._checked_constraint(c, known) for c in self.constraints))
        object.__setattr__(self, "units", str(self.units))
        # the one linear map, built once (and checked: a rigid body needs channels)
        t, unobserved = self._build_transform()
        object.__setattr__(self, "_transform", t)
        object.__setattr__(self, "_unobserved", tuple(unobserved))

    # ------------------------------------------------------------------ construction checks
    def _checked_constraint(self, c, known) -> Constraint:
        if isinstance(c, dict):
            c = constraint_from_dict(c)
        if not isinstance(c, Constraint):
            raise TypeError(f"constraints must be Constraint objects or dicts; got {type(c).__name__}")
        for n in c.nodes:
            if n not in known:
                raise ValueError(f"{c.kind} constraint: unknown node {n}")
        for ch in c.channels:
            if ch not in self.channels:
                raise ValueError(f"{c.kind} constraint on node(s) {list(c.nodes)}: unknown channel {ch!r}")
        return c

    def _build_transform(self):
        n_nodes, n_ch = self.node_ids.size, len(self.channels)
        index = {int(n): i for i, n in enumerate(self.node_ids)}
        ch_index = {c: k for k, c in enumerate(self.channels)}
        t = np.zeros((n_nodes, 3, n_ch))
        rigid_nodes = set()
        unobserved = []
        for c in self.constraints:
            if c.kind != "rigid":
                continue
            ks = [ch_index[ch] for ch in c.channels]
            pts = np.array([self.coordinates[index[int(self.channel_node[k])]] for k in ks])
            center = np.mean([self.coordinates[index[n]] for n in c.nodes], axis=0)
            basis = _rigid_basis(c.normal)  # motions as columns: 6 (3-D) or 3 (plane)
            # channel k observes d_k · (t + θ × (p_k - c)): one row per channel
            rows = np.array([self.channel_direction[k] @ _motion_at(p - center, basis) for k, p in zip(ks, pts)])
            # The motions the channels observe, translations first (a column is kept when it adds to
            # the rank), fitted by least squares; the others are 0 (not the minimum-norm mix of a
            # translation and a rotation a single off-centre sensor would give).
            tol = 1e-10 * max(1.0, float(np.abs(rows).max(initial=0)))
            kept = []
            for j in range(basis.shape[1]):
                if np.linalg.matrix_rank(rows[:, kept + [j]], tol=tol) > len(kept):
                    kept.append(j)
            fit = np.zeros((basis.shape[1], len(ks)))
            fit[kept] = np.linalg.pinv(rows[:, kept], rcond=1e-10)  # (n_motions, n_ch_c)
            rank = len(kept)
            if rank < basis.shape[1]:
                unobserved.append(f"rigid body of nodes {list(c.nodes)}: {basis.shape[1] - rank} of its "
                                  f"{basis.shape[1]} motions not observed by its channels (taken as 0)")
            for n in c.nodes:
                if n in rigid_nodes:
                    raise ValueError(f"rigid constraint: node {n} is in two rigid bodies")
                rigid_nodes.add(n)
                m = _motion_at(self.coordinates[index[n]] - center, basis) @ fit  # 3 x n_ch_c
                t[index[n]][:, ks] = m
        # per node: rows d · u = w · φ from its channels and linear constraints
        rows = {i: ([], []) for i in range(n_nodes)}
        for k in range(n_ch):
            w = np.zeros(n_ch)
            w[k] = 1.0
            i = index[int(self.channel_node[k])]
            rows[i][0].append(self.channel_direction[k])
            rows[i][1].append(w)
        for c in self.constraints:
            if c.kind != "linear":
                continue
            n = c.nodes[0]
            if n in rigid_nodes:
                raise ValueError(f"linear constraint on node {n}: the node is in a rigid body already")
            w = np.zeros(n_ch)
            for ch, wt in zip(c.channels, c.weights):
                w[ch_index[ch]] += wt
            rows[index[n]][0].append(np.asarray(c.direction))
            rows[index[n]][1].append(w)
        for i, (d, w) in rows.items():
            if not d or int(self.node_ids[i]) in rigid_nodes:
                continue
            t[i] = np.linalg.pinv(np.array(d), rcond=1e-10) @ np.array(w)
        return t, unobserved

    # ------------------------------------------------------------------ properties
    @property
    def n_nodes(self) -> int:
        return int(self.node_ids.size)

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def transform(self) -> np.ndarray:
        """(n_nodes, 3, n_channels) real: node n's displacement is ``transform[n] @ φ``."""
        return self._transform.copy()

    @property
    def unobserved(self) -> tuple:
        """Rigid-body motions the channels do not observe (taken as 0), in words; empty if none."""
        return self._unobserved

    @property
    def moving(self) -> np.ndarray:
        """(n_nodes,) bool: the node's displacement depends on some channel."""
        return np.any(self._transform != 0, axis=(1, 2))

    @property
    def size(self) -> float:
        """Largest extent of the nodes' bounding box (1 for a single point): the plots' scale."""
        ext = float(np.max(np.ptp(self.coordinates, axis=0)))
        return ext if ext > 0 else 1.0

    def node_index(self, node_id) -> int:
        hits = np.nonzero(self.node_ids == _node_id(node_id, "node_id"))[0]
        if not hits.size:
            raise ValueError(f"node_id {node_id}: unknown node")
        return int(hits[0])

    def __repr__(self) -> str:
        return (f"Geometry({self.name + ': ' if self.name else ''}{self.n_nodes} nodes, {len(self.lines)} lines, "
                f"{len(self.triangles)} triangles, {self.n_channels} channels, {len(self.constraints)} constraints)")

    # ------------------------------------------------------------------ shapes on the geometry
    def channel_order(self, dof_names) -> np.ndarray:
        """Index into ``dof_names`` of each of this geometry's channels. ``ValueError`` naming a name
        of the shape the geometry does not place, or a channel of the geometry the shape lacks."""
        if dof_names is None:
            raise ValueError("dof_names: a shape must name its components (one name per channel)")
        names = [str(s) for s in dof_names]
        if len(set(names)) != len(names):
            dup = next(s for s in names if names.count(s) > 1)
            raise ValueError(f"dof_names: {dup!r} appears twice")
        pos = {s: i for i, s in enumerate(names)}
        extra = [s for s in names if s not in self.channels]
        if extra:
            raise ValueError(f"dof_names: {extra[0]!r} is not a channel of the geometry "
                             f"(its channels: {', '.join(self.channels)})")
        missing = [c for c in self.channels if c not in pos]
        if missing:
            raise ValueError(f"dof_names: the shape has no component for the geometry's channel {missing[0]!r}")
        return np.array([pos[c] for c in self.channels], np.int64)

    def displacements(self, shape, dof_names, *, covariance=None, std_real=None, std_imag=None) -> NodeDisplacements:
        """Per-node 3-D complex displacement of ``shape`` (one entry per name of ``dof_names``).

        ``covariance``: (2l, 2l) of ``[Re φ, Im φ]`` in the order of ``dof_names``: propagated
        exactly (``T C Tᵀ``). Without it, ``std_real`` / ``std_imag`` (per component) give a
        covariance that neglects the correlations between components (``exact=False``).
        """
        phi = np.asarray(shape)
        if phi.ndim != 1:
            raise ValueError(f"shape must be one vector (n_channels,); got shape {phi.shape}")
        if len(dof_names) != phi.size:
            raise ValueError(f"dof_names has {len(dof_names)} names but shape has {phi.size} components")
        order = self.channel_order(dof_names)
        if not np.all(np.isfinite(phi)):
            raise ValueError("shape has non-finite components")
        t = self._transform
        u = np.einsum("nik,k->ni", t, phi.astype(complex)[order])
        l = phi.size
        cov, exact = None, True
        if covariance is not None:
            c = np.asarray(covariance, dtype=float)
            if c.shape != (2 * l, 2 * l):
                raise ValueError(f"covariance must be (2l, 2l) = ({2 * l}, {2 * l}) of [Re φ, Im φ]; got {c.shape}")
            idx = np.concatenate([order, order + l])
            c = c[np.ix_(idx, idx)]
        elif std_real is not None or std_imag is not None:
            sr = np.zeros(l) if std_real is None else np.nan_to_num(np.asarray(std_real, float).reshape(-1))
            si = np.zeros(l) if std_imag is None else np.nan_to_num(np.asarray(std_imag, float).reshape(-1))
            if sr.size != l or si.size != l:
                raise ValueError(f"std_real and std_imag must have {l} entries")
            c = np.diag(np.concatenate([sr[order] ** 2, si[order] ** 2]))
            exact = False
        if covariance is not None or std_real is not None or std_imag is not None:
            zero = np.zeros_like(t)
            big = np.concatenate([np.concatenate([t, zero], axis=2), np.concatenate([zero, t], axis=2)], axis=1)
            cov = np.einsum("nik,kl,njl->nij", big, c, big)  # (n_nodes, 6, 6)
        return NodeDisplacements(node_ids=self.node_ids.copy(), value=u, covariance=cov, moving=self.moving,
                                 exact=exact)

    # ------------------------------------------------------------------ dictionaries and files
    def to_dict(self) -> dict:
        """The geometry in the TOML format's structure (plain Python)."""
        return {
            "name": self.name, "units": self.units,
            "nodes": [[int(i), *map(float, p)] for i, p in zip(self.node_ids, self.coordinates)],
            "lines": self.lines.tolist(), "triangles": self.triangles.tolist(),
            "channels": [{"name": c, "node": int(n), "direction": d.tolist()}
                         for c, n, d in zip(self.channels, self.channel_node, self.channel_direction)],
            "constraints": [c.to_dict() for c in self.constraints],
        }

    @classmethod
    def from_dict(cls, data: dict, *, base: Path | None = None) -> "Geometry":
        """From the TOML format's structure (docs/shapes.md); ``base``: folder of relative ``uff`` paths."""
        if not isinstance(data, dict):
            raise TypeError(f"geometry data must be a dict; got {type(data).__name__}")
        known = {"name", "units", "nodes", "lines", "triangles", "channels", "constraints", "uff"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"geometry: unknown key {unknown[0]!r} (known: {', '.join(sorted(known))})")
        ids, xyz, lines = [], [], list(data.get("lines", []))
        if "uff" in data:
            path = Path(data["uff"])
            if base is not None and not path.is_absolute():
                path = base / path
            ids, xyz, uff_lines = _read_uff_nodes_lines(path)
            lines += uff_lines
        for k, n in enumerate(data.get("nodes", [])):
            if isinstance(n, dict):
                if "id" not in n:
                    raise ValueError(f"nodes[{k}]: no id")
                p = n.get("xyz", [n.get("x", 0.0), n.get("y", 0.0), n.get("z", 0.0)])
                ids.append(n["id"])
                xyz.append(p)
            else:
                row = list(n)
                if len(row) != 4:
                    raise ValueError(f"nodes[{k}]: expected [id, x, y, z]; got {row!r}")
                ids.append(row[0])
                xyz.append(row[1:])
        names, nodes, dirs = [], [], []
        for k, c in enumerate(data.get("channels", [])):
            if not isinstance(c, dict) or "name" not in c:
                raise ValueError(f"channels[{k}]: expected a table with name, node and direction")
            extra = sorted(set(c) - {"name", "node", "direction"})
            if extra:
                raise ValueError(f"channel {c['name']!r}: unknown key {extra[0]!r} (known: name, node, direction)")
            if "node" not in c:
                raise ValueError(f"channel {c['name']!r} has no node")
            if "direction" not in c:
                raise ValueError(f"channel {c['name']!r} has no direction")
            names.append(str(c["name"]))
            nodes.append(c["node"])
            dirs.append(direction_vector(c["direction"], f"direction of channel {c['name']!r}"))
        try:
            xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
        except (TypeError, ValueError):
            raise ValueError("nodes: coordinates must be numbers") from None
        return cls(node_ids=np.asarray(ids, dtype=object), coordinates=xyz, channels=tuple(names),
                   channel_node=np.asarray(nodes, dtype=object), channel_direction=np.asarray(dirs).reshape(-1, 3),
                   lines=np.asarray(lines, dtype=object), triangles=np.asarray(data.get("triangles", []), dtype=object),
                   constraints=tuple(constraint_from_dict(c) for c in data.get("constraints", [])),
                   units=str(data.get("units", "m")), name=str(data.get("name", "")))

    @classmethod
    def from_toml(cls, path) -> "Geometry":
        """Read the TOML format of docs/shapes.md (``ValueError`` naming the file on a syntax error)."""
        path = Path(path)
        data = _read_toml(path)
        try:
            return cls.from_dict(data, base=path.parent)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None

    @classmethod
    def from_csv(cls, nodes, channels, *, lines=None, triangles=None, units: str = "m", name: str = "") -> "Geometry":
        """From CSV tables with a header row: ``nodes`` (id,x,y,z), ``channels`` (name,node,dx,dy,dz
        or name,node,direction with +x/-y/...), optional ``lines`` (a,b) and ``triangles`` (a,b,c)."""
        def table(p, need):
            p = Path(p)
            with open(p, newline="", encoding="utf-8") as fh:
                rows = list(csv.DictReader(fh))
            for k, r in enumerate(rows):
                missing = [c for c in need if c not in r or r[c] in (None, "")]
                if missing:
                    raise ValueError(f"{p} row {k + 2}: no {missing[0]!r}")
            return rows

        def num(p, k, r, c):
            try:
                return float(r[c])
            except ValueError:
                raise ValueError(f"{p} row {k + 2}: {c} {r[c]!r} is not a number") from None

        node_rows = table(nodes, ["id", "x", "y", "z"])
        data = {"units": units, "name": name,
                "nodes": [[r["id"], num(nodes, k, r, "x"), num(nodes, k, r, "y"), num(nodes, k, r, "z")]
                          for k, r in enumerate(node_rows)], "channels": []}
        for k, r in enumerate(table(channels, ["name", "node"])):
            if r.get("direction"):
                d = r["direction"]
            elif all(r.get(c) not in (None, "") for c in ("dx", "dy", "dz")):
                d = [num(channels, k, r, c) for c in ("dx", "dy", "dz")]
            else:
                raise ValueError(f"{channels} row {k + 2}: channel {r['name']!r} has no direction "
                                 "(direction or dx,dy,dz)")
            data["channels"].append({"name": r["name"], "node": r["node"], "direction": d})
        if lines is not None:
            data["lines"] = [[r["a"], r["b"]] for r in table(lines, ["a", "b"])]
        if triangles is not None:
            data["triangles"] = [[r["a"], r["b"], r["c"]] for r in table(triangles, ["a", "b", "c"])]
        return cls.from_dict(data)

    @classmethod
    def from_uff(cls, path, channels, *, constraints=(), units: str = "m", name: str = "") -> "Geometry":
        """Nodes from UFF dataset 15 (or 2411), lines from 82 (pyuff), channels from a map:
        a dict ``{name: {"node": id, "direction": "+x" or [dx, dy, dz]}}``, a list of such tables
        with ``name``, or a TOML file whose ``[[channels]]`` (and ``[[constraints]]``) are used."""
        path = Path(path)
        extra_constraints = list(constraints)
        if isinstance(channels, (str, os.PathLike)):
            mp = _read_toml(Path(channels))
            chans = mp.get("channels", [])
            extra_constraints += mp.get("constraints", [])
        elif isinstance(channels, dict):
            chans = [{"name": k, **v} for k, v in channels.items()]
        else:
            chans = list(channels)
        ids, xyz, lines = _read_uff_nodes_lines(path)
        data = {"units": units, "name": name, "nodes": [[i, *p] for i, p in zip(ids, xyz)], "lines": lines,
                "channels": chans, "constraints": extra_constraints}
        return cls.from_dict(data)

    @classmethod
    def from_file(cls, path) -> "Geometry":
        """By extension: ``.toml`` (which may name a UFF file for its nodes and lines)."""
        p = Path(path)
        if p.suffix.lower() != ".toml":
            raise ValueError(f"geometry {os.fspath(path)!r}: expected a .toml file (docs/shapes.md); for UFF "
                             "nodes and lines, name the .uff file in it (uff = \"geo.uff\") with the channels")
        return cls.from_toml(p)


def constraint_from_dict(c: dict) -> Constraint:
    """A :class:`Constraint` from the TOML format's table (``ValueError`` naming what is wrong)."""
    if isinstance(c, Constraint):
        return c
    if not isinstance(c, dict):
        raise ValueError(f"constraints: expected a table; got {c!r}")
    kind = c.get("kind")
    keys = {"linear": {"kind", "node", "direction", "weights"}, "rigid": {"kind", "nodes", "channels", "normal"}}
    extra = sorted(set(c) - keys.get(kind, set(c)))
    if extra:
        raise ValueError(f"{kind} constraint: unknown key {extra[0]!r} (known: {', '.join(sorted(keys[kind]))})")
    if kind == "linear":
        if "node" not in c or "direction" not in c or "weights" not in c:
            raise ValueError("linear constraint: needs node, direction and weights")
        node = _node_id(c["node"], "linear constraint node")
        w = c["weights"]
        if not isinstance(w, dict) or not w:
            raise ValueError(f"linear constraint on node {node}: weights must be a table channel = weight")
        ws = []
        for ch, v in w.items():
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
                raise ValueError(f"linear constraint on node {node}: weight of {ch!r} must be a finite number")
            ws.append(float(v))
        d = direction_vector(c["direction"], f"direction of the linear constraint on node {node}")
        return Constraint("linear", (node,), tuple(str(k) for k in w), tuple(d.tolist()), tuple(ws))
    if kind == "rigid":
        if not c.get("nodes") or not c.get("channels"):
            raise ValueError("rigid constraint: needs nodes and channels")
        nodes = tuple(_node_id(n, "rigid constraint node") for n in c["nodes"])
        normal = c.get("normal")
        if normal is not None:
            normal = tuple(direction_vector(normal, f"normal of the rigid body of nodes {list(nodes)}").tolist())
        return Constraint("rigid", nodes, tuple(str(ch) for ch in c["channels"]), normal=normal)
    raise ValueError(f"constraints: kind must be 'linear' or 'rigid'; got {kind!r}")


def _rigid_basis(normal):
    """Columns: the rigid motions (t_x, t_y, t_z, θ_x, θ_y, θ_z), or in a plane of unit normal n
    (two in-plane translations and the rotation about n)."""
    if normal is None:
        return np.eye(6)
    n = np.asarray(normal, float)
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    basis = np.zeros((6, 3))
    basis[:3, 0], basis[:3, 1], basis[3:, 2] = e1, e2, n
    return basis


def _motion_at(r, basis) -> np.ndarray:
    """3 × n_motions: displacement t + θ × r at offset r, per motion of ``basis``."""
    rx = np.array([[0.0, r[2], -r[1]], [-r[2], 0.0, r[0]], [r[1], -r[0], 0.0]])  # θ × r = rx @ θ
    return np.hstack([np.eye(3), rx]) @ basis


def _read_toml(path: Path) -> dict:
    try:
        import tomllib  # Python 3.11+
    except ImportError:  # pragma: no cover - 3.9/3.10
        import tomli as tomllib
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None


def _read_uff_nodes_lines(path: Path):
    """Node ids and coordinates (UFF 15 or 2411) and line pairs (UFF 82) of a file (pyuff)."""
    from .checks import require

    pyuff = require("pyuff", "reading a UFF geometry")  # imported here: a heavy optional reader
    if not Path(path).is_file():
        raise ValueError(f"{path}: no such file")
    try:
        sets = pyuff.UFF(os.fspath(path)).read_sets()
    except Exception as exc:  # pyuff raises bare Exceptions on malformed files
        raise ValueError(f"{path}: not a readable UFF file ({exc})") from None
    if isinstance(sets, dict):
        sets = [sets]
    ids, xyz, lines = [], [], []
    for s in sets:
        if s.get("type") in (15, 2411):
            lab = np.asarray(s["node_nums"]).reshape(-1)
            pts = np.column_stack([np.asarray(s[k], float).reshape(-1) for k in ("x", "y", "z")])
            ids += [int(v) for v in lab]
            xyz += pts.tolist()
        elif s.get("type") == 82:
            seq = [int(v) for v in np.asarray(s["nodes"]).reshape(-1)]
            # a 0 lifts the pen: consecutive non-zero pairs are the lines
            lines += [[a, b] for a, b in zip(seq[:-1], seq[1:]) if a and b]
    if not ids:
        raise ValueError(f"{path}: no node dataset (UFF 15 or 2411)")
    return ids, xyz, lines


def mode_displacements(modes, mode: int, geometry):
    """The :class:`~modaluq.geometry.NodeDisplacements` of mode ``mode`` (from 1) of ``modes``
    (a :class:`~modaluq.SelectedModes` or anything with ``mode_shape`` (l, n_modes) and
    ``output_names``), with the shape covariance when ``modes`` carries it (``mode_covariance``,
    (n_modes, 2+2l, 2+2l) of [f, ξ, Re φ, Im φ], or ``mode_shape_covariance``, its (2l, 2l) shape
    block), else the per-channel σ (``mode_shape_std_real/imag``)."""
    shape = np.asarray(modes.mode_shape)
    n_modes = shape.shape[1] if shape.ndim == 2 else 0
    k = check_integer("mode", mode, minimum=1, maximum=max(n_modes, 1)) - 1
    if not n_modes:
        raise ValueError("mode: there are no modes")
    names = tuple(getattr(modes, "output_names", ()) or ())
    if not names:
        raise ValueError("modes has no output_names: the geometry places channels by name")
    # the full covariance of [Re φ, Im φ]: SelectedModes.mode_covariance holds [f, ξ, Re φ, Im φ]
    # (its shape block); another source of shapes may give the shape block itself
    cov = getattr(modes, "mode_shape_covariance", None)
    full = getattr(modes, "mode_covariance", None)
    if cov is None and full is not None:
        cov = np.asarray(full)[:, 2:, 2:]
    if cov is not None:
        return geometry.displacements(shape[:, k], names, covariance=np.asarray(cov)[k])
    sr, si = getattr(modes, "mode_shape_std_real", None), getattr(modes, "mode_shape_std_imag", None)
    # a run without uncertainty has NaN std (SelectedModes): no σ, not a σ of NaN
    sr, si = (None if v is None or not np.isfinite(np.asarray(v)[:, k]).any() else v for v in (sr, si))
    if sr is None and si is None:
        return geometry.displacements(shape[:, k], names)
    return geometry.displacements(shape[:, k], names, std_real=None if sr is None else np.asarray(sr)[:, k],
                                  std_imag=None if si is None else np.asarray(si)[:, k])


@dataclass(frozen=True, eq=False)
class NodeShapes:
    """Every mode of a modes object at every node of a geometry (:func:`node_shapes`): what the
    exports write beside the per-channel shapes."""

    node_ids: np.ndarray      #: (n_nodes,)
    value: np.ndarray         #: (n_modes, n_nodes, 3) complex: x, y, z in the global axes
    std_real: np.ndarray      #: (n_modes, n_nodes, 3) σ(Re u), NaN without σ
    std_imag: np.ndarray      #: (n_modes, n_nodes, 3) σ(Im u)
    moving: np.ndarray        #: (n_nodes,) bool: the node's displacement comes from channels
    exact: bool               #: σ from the shapes' covariance (False: per-channel σ, or no σ)


def node_shapes(modes, geometry) -> NodeShapes:
    """:func:`mode_displacements` of every mode of ``modes``: measured nodes from their channels,
    constrained nodes through their constraint, the σ through the same linear map."""
    n_modes = np.asarray(modes.mode_shape).shape[1]
    n = geometry.n_nodes
    value = np.zeros((n_modes, n, 3), complex)
    sr, si = np.full((n_modes, n, 3), np.nan), np.full((n_modes, n, 3), np.nan)
    exact, moving = n_modes > 0, np.zeros(n, bool)
    for k in range(n_modes):
        d = mode_displacements(modes, k + 1, geometry)
        value[k], moving = d.value, d.moving
        if d.covariance is None:
            exact = False
            continue
        var = np.clip(np.diagonal(d.covariance, axis1=1, axis2=2), 0.0, None)
        sr[k], si[k] = np.sqrt(var[:, :3]), np.sqrt(var[:, 3:])
        exact = exact and d.exact
    return NodeShapes(node_ids=geometry.node_ids.copy(), value=value, std_real=sr, std_imag=si, moving=moving,
                      exact=bool(exact))
