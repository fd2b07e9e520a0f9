"""Settings: what an analysis is asked to do, as frozen dataclasses mapped onto the core's options.

- :class:`Settings`: the identification (horizons, orders, blocks, uncertainty) and the
  preprocessing of the record (band, window, decimation, filters): every keyword of
  :func:`modaluq.identify`, in one object that checks itself and can be reused, compared and
  saved (``to_dict``);
- :class:`StabilityCriteria`: how the stabilization diagram judges each pole;
- :class:`ClusteringSettings`: how the automatic selection groups stable poles into modes;
- :class:`PoleStatus`: the verdict on one pole.

Every check names the field at fault (``TypeError`` for the wrong kind of value, ``ValueError``
for a value out of range), as :mod:`modaluq.checks` does everywhere.

One source per default: a field that the core's options struct also has (same name:
``IdentifyOptions``, ``StabilityCriteria``, ``ClusteringOptions``) takes its default from the
struct as the core constructs it (:func:`core_defaults`), and ``to_core``/``to_dict`` loop over
the fields. Where the core writes "not set" or an enum differently, :data:`_CODECS` translates,
in one place. Only what the core does not know keeps a Python default (the preprocessing, and
``block_rows``/``orders``/``n_blocks``, chosen from the data when None).
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass, fields
from typing import Callable, NamedTuple, Optional, Tuple

from . import _core
from .checks import MAX_THREADS, check_boolean, check_integer, check_integers, check_real, check_sampling_frequency

__all__ = ["ClusteringSettings", "PoleStatus", "Settings", "StabilityCriteria", "CORE_OF_STATUS", "STATUS_OF_CORE",
           "core_defaults", "core_fields"]


class PoleStatus(str, enum.Enum):
    """Outcome of the stability checks for one pole (a ``str``, so it prints and exports as text).

    STABLE
        Passes its own checks and every check against its match at the previous order.
    STABLE_FREQUENCY
        Frequency stable (relative change and, with uncertainty, the σ test), but the damping
        change or the MAC fails.
    UNSTABLE
        Lowest order, no acceptable pole at the previous order, or the frequency test fails.
    REJECTED
        Physically implausible (damping out of range) or too uncertain (σ_f / f too large);
        never compared and never selected.
    """

    STABLE = "stable"
    STABLE_FREQUENCY = "stable_frequency"
    UNSTABLE = "unstable"
    REJECTED = "rejected"

    def __str__(self) -> str:  # "stable", not "PoleStatus.STABLE"
        return self.value


#: the core's status (stabilization.hpp) -> PoleStatus, and back
STATUS_OF_CORE = {
    _core.PoleStatus.stable: PoleStatus.STABLE, _core.PoleStatus.stable_frequency: PoleStatus.STABLE_FREQUENCY,
    _core.PoleStatus.unstable: PoleStatus.UNSTABLE, _core.PoleStatus.rejected: PoleStatus.REJECTED,
}
CORE_OF_STATUS = {v: k for k, v in STATUS_OF_CORE.items()}


# --------------------------------------------------------------------------- the seam with the core's structs


class _Codec(NamedTuple):
    """How one field crosses between the core's struct and the dataclass."""

    to_python: Callable
    to_core: Callable


#: Fields the core writes differently from Python ("not set" as 0 or empty, enums); every other
#: field crosses as it is (an empty ``std::optional`` is already None).
_CODECS = {
    # 0 / empty: "not set" (q = p, every output, the automatic size); None in Python
    "block_rows": _Codec(lambda v: int(v) or None, lambda v: int(v or 0)),
    "past_block_rows": _Codec(lambda v: int(v) or None, lambda v: int(v or 0)),
    "min_cluster_size": _Codec(lambda v: int(v) or None, lambda v: int(v or 0)),
    "orders": _Codec(lambda v: tuple(v) or None, lambda v: list(v or ())),
    "references": _Codec(lambda v: tuple(v) or None, lambda v: list(v or ())),
    "statuses": _Codec(lambda v: tuple(STATUS_OF_CORE[s] for s in v), lambda v: [CORE_OF_STATUS[s] for s in v]),
    "linkage": _Codec(lambda v: v.name, lambda v: getattr(_core.Linkage, v)),
    # None (Python's default: the identification's own, resolved by select_modes) crosses as the
    # core's default, one record's "median"
    "cluster_std": _Codec(lambda v: v.name, lambda v: getattr(_core.ClusterStd, v or "median")),
    "representative": _Codec(lambda v: v.name, lambda v: getattr(_core.Representative, v)),
    "shape_representative": _Codec(lambda v: v.name, lambda v: getattr(_core.Representative, v)),
}


def core_fields(core_type) -> tuple:
    """The data fields of a bound core struct (its ``def_readwrite`` properties, in binding order)."""
    names = {}
    for klass in reversed(type.mro(core_type)):  # a Python subclass of the struct keeps its fields
        names.update((k, None) for k, v in vars(klass).items() if type(v) is property)  # not static ones
    return tuple(names)


def core_defaults(core_type) -> dict:
    """Every field of the core struct ``core_type`` as it constructs it, in Python's terms (None
    for "not set", :class:`PoleStatus`, linkage names): the defaults of the dataclasses.

    >>> core_defaults(_core.StabilityCriteria)["min_mac"] == StabilityCriteria().min_mac
    True
    """
    made = core_type()
    return {name: _CODECS[name].to_python(getattr(made, name)) if name in _CODECS else getattr(made, name)
            for name in core_fields(core_type)}


def _crossing(cls, core_type) -> tuple:
    """The dataclass's fields that the core struct has too (the dataclass's order)."""
    core = set(core_fields(core_type))
    return tuple(f.name for f in fields(cls) if f.name in core)


def _to_core(obj, core_type, names):
    """A default-constructed ``core_type`` with ``names`` set from the dataclass ``obj``."""
    out = core_type()
    for name in names:
        value = getattr(obj, name)
        if name in _CODECS:
            value = _CODECS[name].to_core(value)
        elif value is not None and isinstance(getattr(out, name), (bool, int, float)):
            value = type(getattr(out, name))(value)  # the struct's kind: 1 for a double is 1.0
        setattr(out, name, value)
    return out


def _exported(value):
    """A field's value for ``to_dict``: tuples as lists, :class:`PoleStatus` as its text."""
    if isinstance(value, tuple):
        return [_exported(v) for v in value]
    return value.value if isinstance(value, enum.Enum) else value


#: The core's defaults, read once when modaluq is imported.
_IDENTIFY = core_defaults(_core.IdentifyOptions)
_CRITERIA = core_defaults(_core.StabilityCriteria)
_CLUSTERING = core_defaults(_core.ClusteringOptions)


# --------------------------------------------------------------------------- identification


#: Fields of :class:`Settings` that only change the samples before identification (preprocess.py).
PREPROCESSING_FIELDS = ("frequency_range", "start", "stop", "decimate", "detrend", "highpass")


@dataclass(frozen=True)
class Settings:
    """Every setting of one identification (see :func:`modaluq.identify` for what each does).

    ``block_rows``, ``orders`` and ``n_blocks`` left at ``None`` are chosen from the data
    (:mod:`modaluq.auto_settings`); :meth:`to_core` maps the rest one to one onto the core's
    ``IdentifyOptions``. Checked when made, so a wrong value fails where it is written.

    >>> s = Settings(block_rows=20, orders=range(2, 41, 2))
    >>> s.orders[:3], s.n_blocks
    ((2, 4, 6), None)
    >>> s.replace(n_blocks=30).n_blocks
    30
    """

    # block_rows, orders, n_blocks: None = chosen from the data (auto_settings); the core's
    # placeholders (0, empty, 50 blocks) are not defaults. The other fields the core has: its defaults.
    block_rows: Optional[int] = None                 #: future block rows p (>= 2)
    past_block_rows: Optional[int] = _IDENTIFY["past_block_rows"]  #: past block rows q (None: p)
    orders: Optional[Tuple[int, ...]] = None         #: model orders, ascending, distinct
    n_blocks: Optional[int] = None                   #: blocks for the covariance of the covariances
    references: Optional[Tuple[int, ...]] = _IDENTIFY["references"]  #: output indices of the past (None: all)
    uncertainty: bool = _IDENTIFY["uncertainty"]     #: propagate the covariance to every parameter
    demean: bool = _IDENTIFY["demean"]               #: remove each channel's mean
    input_rcond: float = _IDENTIFY["input_rcond"]    #: relative cut of the input covariance's pseudo-inverse
    threads: int = _IDENTIFY["threads"]              #: threads of the core (the result does not depend on it)
    freeze_noise: bool = _IDENTIFY["freeze_noise"]   #: hold the noise directions fixed (docs/uq-math.md §5.5)
    noise_coupling_limit: float = _IDENTIFY["noise_coupling_limit"]  #: σ shrink factor that flags a noise-coupled pole
    #: scale each mode's σ for the correlation of adjacent blocks (docs/uq-math.md §3.1)
    block_correlation_correction: bool = _IDENTIFY["block_correlation_correction"]
    #: draws of the bootstrap of σ_f, σ_ξ above the noise floor (docs/uq-math.md §5.6); 0: off
    bootstrap_draws: int = _IDENTIFY["bootstrap_draws"]
    #: a campaign's merge only: block combinations per setup its noise-coupling test uses
    #: (docs/uq-math.md §13.4); 0: every block
    coupling_sketch: int = _IDENTIFY["coupling_sketch"]
    #: keep each pole's first-order shape factor (``Modes.mode_shape_factor``): the exact σ of an
    #: AutoMAC, for 2 l n_blocks values per pole
    keep_shape_factor: bool = _IDENTIFY["keep_shape_factor"]
    # preprocessing (preprocess.py), which the core does not know
    frequency_range: Optional[Tuple[float, float]] = None  #: band of interest (f_low, f_high), Hz
    start: Optional[float] = None                    #: window start, s from the first sample
    stop: Optional[float] = None                     #: window end, s
    decimate: Optional[int] = None                   #: integer decimation factor
    detrend: Optional[str] = None                    #: "constant", "linear" or None
    highpass: Optional[float] = None                 #: high-pass corner, Hz

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)  # frozen: normalise once, here

        if self.block_rows is not None:
            put("block_rows", check_integer("block_rows", self.block_rows, minimum=2))
        if self.past_block_rows is not None:
            put("past_block_rows", check_integer("past_block_rows", self.past_block_rows, minimum=1))
        if self.orders is not None:
            put("orders", tuple(sorted(set(check_integers("orders", self.orders, minimum=1)))))
        if self.n_blocks is not None:
            put("n_blocks", check_integer("n_blocks", self.n_blocks))
        if self.references is not None:
            put("references", tuple(check_integers("references", self.references, minimum=0)))
        for name in ("uncertainty", "demean", "freeze_noise", "block_correlation_correction", "keep_shape_factor"):
            put(name, check_boolean(name, getattr(self, name)))
        put("input_rcond", check_real("input_rcond", self.input_rcond, low=0, high=1, high_open=True))
        put("threads", check_integer("threads", self.threads, minimum=1, maximum=MAX_THREADS))
        put("noise_coupling_limit", check_real("noise_coupling_limit", self.noise_coupling_limit, low=1))
        put("bootstrap_draws", check_integer("bootstrap_draws", self.bootstrap_draws, minimum=0))
        if 0 < self.bootstrap_draws < _core.IdentifyOptions.min_bootstrap_draws:
            raise ValueError(f"bootstrap_draws must be 0 (off) or >= {_core.IdentifyOptions.min_bootstrap_draws}, "
                             f"got {self.bootstrap_draws}")
        put("coupling_sketch", check_integer("coupling_sketch", self.coupling_sketch, minimum=0))
        if isinstance(self.frequency_range, list):  # checked against fs by preprocess()
            put("frequency_range", tuple(self.frequency_range))

    @property
    def preprocessing(self) -> dict:
        """The preprocessing fields that are set (keyword arguments of :func:`modaluq.preprocess.preprocess`)."""
        return {k: getattr(self, k) for k in PREPROCESSING_FIELDS if getattr(self, k) is not None}

    def replace(self, **changes) -> "Settings":
        """A copy with ``changes`` (checked like the original)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        return {f.name: _exported(getattr(self, f.name)) for f in fields(self)}

    def layout(self, n_outputs: int, n_inputs: int = 0) -> "_core.HankelLayout":
        """The core's Hankel layout of these horizons for ``n_outputs`` / ``n_inputs`` channels."""
        if self.block_rows is None:
            raise ValueError("block_rows is not set (Settings.layout needs the horizons)")
        lay = _core.HankelLayout()
        lay.n_outputs = check_integer("n_outputs", n_outputs, minimum=1)
        lay.n_inputs = check_integer("n_inputs", n_inputs, minimum=0)
        lay.block_rows = self.block_rows
        lay.past_block_rows = self.past_block_rows or 0
        lay.references = list(self.references or ())
        return lay

    def max_order(self, n_outputs: int) -> int:
        """Largest model order these horizons support, ``min((p-1) l, q r)`` (the core's rule)."""
        return int(self.layout(n_outputs).max_order)

    def to_core(self, fs: float) -> "_core.IdentifyOptions":
        """The core's ``IdentifyOptions`` (``block_rows``, ``orders`` and ``n_blocks`` must be set)."""
        missing = [k for k in ("block_rows", "orders", "n_blocks") if getattr(self, k) is None]
        if missing:
            raise ValueError(f"{', '.join(missing)} not set: choose them (auto_settings.choose_settings) first")
        o = _to_core(self, _core.IdentifyOptions, _crossing(Settings, _core.IdentifyOptions))
        o.fs = check_sampling_frequency(fs)
        o.validate()
        return o

    def record(self, fs: float, n_outputs: int) -> dict:
        """What ``Result.settings`` keeps of the identification: ``fs`` and every field the core's
        ``IdentifyOptions`` has, with what "not set" resolves to."""
        resolved = {"past_block_rows": self.past_block_rows or self.block_rows,
                    "n_blocks": self.n_blocks if self.uncertainty else None,
                    "references": list(self.references or ()) or list(range(n_outputs))}
        out = {"fs": fs}
        for name in _crossing(Settings, _core.IdentifyOptions):
            out[name] = resolved[name] if name in resolved else _exported(getattr(self, name))
        return out


# --------------------------------------------------------------------------- diagram and selection


@dataclass(frozen=True)
class StabilityCriteria:
    """Thresholds of the stabilization diagram (all dimensionless fractions unless stated).

    A pole is first checked on its own; failing any of these makes it ``REJECTED``:

    - ``damping_ratio < min_damping_ratio`` (default 0: negative damping is unstable, not a
      structural mode) or ``damping_ratio > max_damping_ratio`` (default 0.20 = 20 %: lightly
      damped structures rarely exceed a few percent; heavily damped poles are usually noise);
    - optionally (off by default), ``MPC < min_mpc`` or ``MPD > max_mpd_deg`` (the modal phase
      collinearity and mean phase deviation of the pole's shape, :mod:`modaluq.indicators`):
      peers filter spurious poles by their complexity; a physical mode of a structure with
      non-proportional damping (dampers, soil, aerodynamics) is complex too, so modaluq leaves
      the decision to the σ tests unless asked (e.g. ``min_mpc=0.8`` for a building);
    - ``frequency_std / frequency_hz > max_frequency_cov`` (default 0.05 = 5 %, a loose backstop:
      whether a column's σ is too large is judged by the selection against the bandwidth f ξ
      of its peak, :class:`ClusteringSettings`. The earlier 2 % cut the columns of well-damped
      modes into pieces; on Painter Street it hid the 10.8 Hz column). Skipped when the result
      carries no uncertainty; a pole whose σ is not finite is rejected.

    The other poles are compared with the pole of the previous identified order that minimises
    ``|Δf| / f_prev + (1 - MAC)`` among that order's non-rejected poles within ``match_window``
    in frequency (default 0.05 = 5 %); with none there, the pole is ``UNSTABLE`` ("no match").
    It is

    - frequency stable when ``|Δf| / f_prev <= max_frequency_change`` (default 0.01 = 1 %) **and**,
      with uncertainty, ``|Δf| <= frequency_std_factor * sqrt(σ_f² + σ_f,prev²)`` (default
      k = 2: a change larger than twice the combined standard deviation is statistically
      significant at about 95 % even if the two estimates were independent, and estimates at
      consecutive orders from the same data are positively correlated, so the test is
      conservative towards keeping a pole). ``frequency_std_factor=None`` switches it off;
    - damping stable, with uncertainty, when ``|Δξ| <= damping_std_factor * sqrt(σ_ξ² + σ_ξ,prev²)``
      (default k = 2) and ``|Δξ| / |ξ_prev| <= max_damping_change_with_std`` (default 0.5, a
      loose backstop): a damping ratio with σ_ξ = 50 % of ξ moves by more than 10 % between
      orders on noise alone, so a fixed relative bound breaks the columns of physical modes
      into pieces (on the shared records the σ test keeps 10–60 % more poles per mode and adds
      no spurious mode; the clusters of spurious poles it lets through are dropped by their σ,
      see :class:`ClusteringSettings`). Without uncertainty, or with ``damping_std_factor=None``,
      ``|Δξ| / |ξ_prev| <= max_damping_change`` (default 0.10 = 10 %; the 5 % often used makes
      physical poles flicker);
    - shape stable when ``MAC >= min_mac`` (default 0.98).

    ``STABLE`` needs all three; frequency alone gives ``STABLE_FREQUENCY``.

    Parameters
    ----------
    max_frequency_change : float
        Largest relative frequency change between consecutive orders (fraction).
    max_damping_change : float
        Largest relative damping-ratio change between consecutive orders (fraction).
    min_mac : float
        Smallest MAC between the shapes at consecutive orders (0..1).
    frequency_std_factor : float or None
        k of the σ test on the frequency change (dimensionless), or None to skip it.
    max_frequency_cov : float or None
        Largest coefficient of variation σ_f / f (fraction), or None to skip it.
    min_damping_ratio, max_damping_ratio : float
        Accepted range of the damping ratio (fraction, 0.02 = 2 %).
    damping_std_factor : float or None
        k of the σ test on the damping change (default 2), or None for the relative test.
    max_damping_change_with_std : float
        Backstop on the relative damping change when the σ test is used (fraction).
    match_window : float
        Largest relative frequency distance to a pole of the previous order that can be its match.
    min_mpc : float or None
        Smallest modal phase collinearity of a pole's shape (0..1), or None (default) for no test.
    max_mpd_deg : float or None
        Largest mean phase deviation of a pole's shape (degrees, 0..90), or None (default) for no test.
    """

    max_frequency_change: float = _CRITERIA["max_frequency_change"]
    max_damping_change: float = _CRITERIA["max_damping_change"]
    min_mac: float = _CRITERIA["min_mac"]
    frequency_std_factor: float | None = _CRITERIA["frequency_std_factor"]
    max_frequency_cov: float | None = _CRITERIA["max_frequency_cov"]
    min_damping_ratio: float = _CRITERIA["min_damping_ratio"]
    max_damping_ratio: float = _CRITERIA["max_damping_ratio"]
    damping_std_factor: float | None = _CRITERIA["damping_std_factor"]
    max_damping_change_with_std: float = _CRITERIA["max_damping_change_with_std"]
    match_window: float = _CRITERIA["match_window"]
    min_mpc: float | None = _CRITERIA["min_mpc"]
    max_mpd_deg: float | None = _CRITERIA["max_mpd_deg"]

    def __post_init__(self):
        check_real("max_frequency_change", self.max_frequency_change, low=0)
        check_real("max_damping_change", self.max_damping_change, low=0)
        check_real("min_mac", self.min_mac, low=0, high=1)
        check_real("frequency_std_factor", self.frequency_std_factor, low=0, low_open=True, allow_none=True)
        check_real("max_frequency_cov", self.max_frequency_cov, low=0, low_open=True, allow_none=True)
        check_real("damping_std_factor", self.damping_std_factor, low=0, low_open=True, allow_none=True)
        check_real("max_damping_change_with_std", self.max_damping_change_with_std, low=0)
        check_real("match_window", self.match_window, low=0, low_open=True)
        check_real("min_mpc", self.min_mpc, low=0, high=1, allow_none=True)
        check_real("max_mpd_deg", self.max_mpd_deg, low=0, high=90, allow_none=True)
        lo = check_real("min_damping_ratio", self.min_damping_ratio, low=-1, high=1)
        hi = check_real("max_damping_ratio", self.max_damping_ratio, low=-1, high=1)
        if hi <= lo:
            raise ValueError(f"max_damping_ratio must be > min_damping_ratio ({lo}); got {hi}")

    def to_dict(self) -> dict:
        return {f.name: _exported(getattr(self, f.name)) for f in fields(self)}

    def to_core(self) -> "_core.StabilityCriteria":
        """The core's criteria (its ``frequency_range``, the band, is set from the identification)."""
        return _to_core(self, _core.StabilityCriteria, _crossing(StabilityCriteria, _core.StabilityCriteria))


@dataclass(frozen=True)
class ClusteringSettings:
    """How :func:`select_modes` groups poles into modes.

    Parameters
    ----------
    distance_threshold : float
        Cut height of the dendrogram on the distance ``|f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)``
        (dimensionless; default 0.02, e.g. 1 % in frequency plus MAC 0.99). Poles of one cluster
        are on average closer than this to each other (average linkage).
    min_cluster_size : int or None
        Clusters with fewer members (after keeping one pole per order) are dropped. Default
        (None): ``min_cluster_fraction`` of the identified orders from the lowest order that holds
        a clustered pole upwards, rounded up, and at least 3.
    min_cluster_fraction : float
        Used when ``min_cluster_size`` is None (default 0.25): a physical mode should be stable
        over at least a quarter of the orders that can hold it. Spurious poles seldom stay
        stable over more than a few consecutive orders, while a physical mode can lose
        stability over a range of orders where a spurious pole splits it (seen with few sensors
        at orders far above the true one), so a higher fraction drops real modes.
    per_cluster_min_size : bool
        With ``min_cluster_size=None``, count the orders from each cluster's own lowest order
        (True: a mode that first appears at a high order needs fewer poles) instead of from the
        lowest order of any clustered pole (False, default).
    max_frequency_std_per_bandwidth : float or None
        Clusters whose median ``σ_f / (f ξ)`` exceeds this are dropped (default 1): the frequency
        is then less certain than the half-power half-bandwidth ``f ξ`` of the peak the pole
        claims. A structural mode identified from a record of ``T`` seconds has about
        ``1 / sqrt(2π f T ξ)`` (0.05–0.4 on the shared records), while spurious poles, whose σ
        the noise directions inflate, have 2–5. None switches it off; skipped without uncertainty.
    merge_fragments : bool
        Join clusters that are pieces of one mode (default True; skipped without uncertainty):
        median frequencies within ``fragment_std_factor`` (default 3) combined σ_f, shapes with
        MAC >= ``fragment_min_mac`` (default 0.8), and at most ``fragment_max_shared`` (default
        0.25) of the smaller piece's orders in common. A mode has one pole per order, so two
        clusters present at the same orders are two modes, however close (a fore-aft/side-side
        pair of a tower); pieces arise where a mode's shape varies with the order (close modes,
        few sensors) and the frequency-and-MAC distance splits its column into parts each too
        small to be selected (the wind turbine's 1.6 Hz column, docs/settings.md).
    fragment_std_factor, fragment_min_mac, fragment_max_shared : float
        See ``merge_fragments``.
    drop_doublets : bool
        Drop the later of two selected clusters within ``doublet_window`` (default 0.05 = 5 %)
        in frequency whose shapes have MAC >= ``doublet_min_mac`` (default 0.8). Above the true
        order one mode is often fitted by a pair of poles with the same shape, the twin a few
        per cent away and often lightly damped; the twin appears at higher orders than the mode.
        "Later": the higher first order, then fewer poles. On the paper's chain, output-only,
        this removes the twins selected in 5 of 12 records (docs/settings.md);
        two physical modes that close and that alike in shape are not told apart by the
        sensors anyway. The dropped twin is listed with its reason.
    doublet_window, doublet_min_mac : float
        See ``drop_doublets``.
    drop_noise_twins : bool
        Drop a lightly damped twin born of the noise (default True): a cluster that first appears
        above the noise floor k* (``Result.significant_singular_values``), at a higher order than
        a kept mode, inside that mode's half-power band (|f − f_mode| < f_mode ξ_mode, median
        values) and less than half as damped (a close physical pair has comparable damping).
        Above k* the added states fit the estimation error of the covariances, whose tail
        oscillates at the mode's frequency without decaying, with a lightly damped pole beside
        the mode; with few sensors its shape need not resemble the mode's, so ``drop_doublets``
        misses it. On the paper's chain, output-only, 400 s, such a twin (ξ 0.1–0.5 % beside
        modes of 2 %) is selected 47 times in 300 records and, read as the mode, puts its ξ 10–15 σ
        off (docs/validation.md, issue 27 (i)). A physical mode has signal singular values and
        is born at or below k*; where k* is far above the modes' order (the measured records'
        34–46) nothing is dropped. Needs the noise floor (uncertainty on). False: as before
        2026-11-27.
    reassign_borrowed_poles : bool
        Before ``drop_doublets`` (default True): of two alike clusters (within ``doublet_window``,
        MAC ≥ ``doublet_min_mac``), the earlier one's poles at orders below the later one's first
        order go to the later one when every one of them is nearer to its median frequency and its
        median damping ratio. A lightly damped cluster fed by the noise can take a mode's
        lowest-order poles and so be the earlier of the two; ``drop_doublets`` then kept it and
        dropped the mode as its twin (the paper's chain, input/output: a 15.99 Hz, ξ 0.3 % cluster
        holding the 15.81 Hz, ξ 2.0 % poles of orders 4–6, the 15.83 Hz mode from order 8 dropped;
        docs/validation.md, issue 27 (j)). Only orders the other cluster lacks move, so each keeps
        one pole per order; a cluster gives or takes once, and those that gave or took are judged
        again by the size and bandwidth rules (one that gave all its poles is gone). Needs
        ``drop_doublets``. False: as before 2026-11-28.
    statuses : tuple of PoleStatus
        Which poles are clustered (default only ``STABLE``).
    linkage : str
        Linkage method (the clustering is the core's, selection.hpp; it equals
        :func:`scipy.cluster.hierarchy.linkage` + ``fcluster``): default ``"average"``;
        ``"single"`` chains neighbouring poles, ``"complete"`` is stricter, ``"weighted"`` is WPGMA.
    cluster_std : {None, "median", "mean"}
        Which σ_f and σ_ξ each selected mode reports; the selected value is the representative
        pole's either way. ``"median"``: the median of the σ of the cluster's reliable poles (not at
        a close singular-value cut, not noise-coupled unless most of the cluster is), one order's σ.
        ``"mean"``: the σ of the mean of those poles' estimates, ``‖(1/K) Σ_m u_m‖`` from each
        pole's first-order factor rows (``Modes.frequency_damping_factor``; docs/uq-math.md §13.10),
        which the selected value scatters like when the poles of one run decorrelate across orders;
        the median where the poles carry no factor rows. None (default): the identification's own,
        ``"mean"`` for a multi-setup merge (:func:`modaluq.identify_setups`, whose merged poles
        decorrelate across orders: the median was 1.04–1.4× the scatter of the selected value, issue
        23) and ``"median"`` for one record (the core's default). The cluster tests
        (``max_frequency_std_per_bandwidth``, ``merge_fragments``) use the poles' own σ either way.
    representative : {"median", "lowest"}
        Which member of a cluster is the mode. ``"median"`` (default): the reliable member nearest
        to the cluster's median (f, ξ), measured in their median σ; its f, ξ and shape are
        reported with the cluster's σ of f and ξ (``cluster_std``) and its own shape covariance.
        ``"lowest"``: the reliable member at the lowest order n ≥ max(k*, 2m), with k* the noise
        floor (``Result.significant_singular_values``) and m the number of selected modes (two
        states each; below that the model cuts signal and the pole is biased), or the highest
        reliable member when none is that high; the mode is then that pole, σ and covariance
        included (``cluster_std`` is not used): one order's identification, read where its
        first-order σ is calibrated. Above it the noise directions make a shape's σ too small and
        a weakly excited mode's shape can mix with a spurious pole, which the MPC, the MAC and
        their σ read (docs/shapes.md §6: on the paper's chain, 200 records, the σ of MPC and MAC
        of modes 2–4 and 6 input/output and 2–3 output-only go from 0.01–0.83 of their scatter
        to 0.96–1.26).
    shape_representative : {"lowest", "median"}
        Which member gives each mode's shape and the shape's σ (``SelectedModes.shape_pole``);
        f, ξ and their σ stay the representative's. ``"lowest"`` (default): the cluster's
        reliable member at the lowest order n ≥ max(k*, 2m), where the shape's first-order σ is
        calibrated, unless the representative is lower and its order holds every selected mode
        (≥ 2m: a measured record whose noise floor k* is far above the modes' order, where the
        member above k* is the worse shape). The median member, far above the true order,
        has too small a shape σ: on the paper's chain the σ of MPC and MAC go from 0.01–0.83 of
        their scatter to 0.96–1.26 (docs/shapes.md §6, with the measured records' split halves).
        ``"median"``: the representative itself (the choice before 2026-11-27). With
        ``representative="lowest"`` both are that pole.
    order_discrepancy : bool
        Widen σ_f and σ_ξ where the model order moves the estimate beyond them (default True):
        where the representative's f (or ξ) differs from the cluster's lowest sufficient member's
        (the default shape pole) by more than 1.96 of their combined σ, the mode's σ becomes
        √(σ² + difference²) and ``SelectedModes.order_discrepancy`` says so. Above the true order a
        spurious pole can take part of a mode at every order from some order on and bias its
        damping by several σ, which no one pole's first-order σ sees. On the simulations it fires
        for about 5 % of the output-only modes and 2 % of the input/output ones, and brings the
        output-only coverage of ±1.96 σ to 0.92–0.96 for every mode (docs/validation.md, issue 27
        (h)). False: no widening, as before 2026-11-27 (the other rule of that change, a mostly
        noise-coupled cluster's σ over all its poles, has no switch).
    unanchored_noise_coupling : float or None
        A mode with no order below its own noise floor (default 2.0): when every reliable pole of a
        cluster (not at a close cut, not noise-coupled; the cluster not mostly noise-coupled) has
        ``noise_coupling`` ρ (``Diagram.noise_coupling``: its σ with the noise directions free over
        its σ with them frozen, 1 at orders ≤ k*) above this, the mode's own singular directions
        lie below the noise floor k* (a weak mode) and every pole's frozen σ misses them. The mode's
        σ_f and σ_ξ become at least the median of ρ σ over those poles, the unfrozen σ's bound,
        and ``SelectedModes.unanchored`` says so. On the paper's chain it fires on 7 % of the
        1.9 Hz input/output modes (k* = 11 < 12, ρ 2.5–5.5 at every order, σ_ξ 3.5× too small)
        and 5 % of the 17 Hz output-only ones, and lifts the coverage of ±1.96 σ of the engineer's
        call's worst cell, that mode's input/output ξ, from 0.90 to 0.93 (docs/validation.md, issue
        27 (n)). None: no such rule (as before 2026-12-07).
    """

    distance_threshold: float = _CLUSTERING["distance_threshold"]
    min_cluster_size: int | None = _CLUSTERING["min_cluster_size"]
    min_cluster_fraction: float = _CLUSTERING["min_cluster_fraction"]
    per_cluster_min_size: bool = _CLUSTERING["per_cluster_min_size"]
    max_frequency_std_per_bandwidth: float | None = _CLUSTERING["max_frequency_std_per_bandwidth"]
    merge_fragments: bool = _CLUSTERING["merge_fragments"]
    drop_doublets: bool = _CLUSTERING["drop_doublets"]
    doublet_window: float = _CLUSTERING["doublet_window"]
    doublet_min_mac: float = _CLUSTERING["doublet_min_mac"]
    fragment_std_factor: float = _CLUSTERING["fragment_std_factor"]
    fragment_min_mac: float = _CLUSTERING["fragment_min_mac"]
    fragment_max_shared: float = _CLUSTERING["fragment_max_shared"]
    statuses: tuple = _CLUSTERING["statuses"]
    linkage: str = _CLUSTERING["linkage"]
    #: None: the identification's own (``"mean"`` for a multi-setup merge, else the core's ``"median"``)
    cluster_std: str | None = None
    representative: str = _CLUSTERING["representative"]
    shape_representative: str = _CLUSTERING["shape_representative"]
    order_discrepancy: bool = _CLUSTERING["order_discrepancy"]
    drop_noise_twins: bool = _CLUSTERING["drop_noise_twins"]
    reassign_borrowed_poles: bool = _CLUSTERING["reassign_borrowed_poles"]
    unanchored_noise_coupling: float | None = _CLUSTERING["unanchored_noise_coupling"]

    def __post_init__(self):
        check_real("distance_threshold", self.distance_threshold, low=0, low_open=True)
        if self.min_cluster_size is not None:
            check_integer("min_cluster_size", self.min_cluster_size, minimum=1)
        check_real("min_cluster_fraction", self.min_cluster_fraction, low=0, high=1, low_open=True)
        check_real("max_frequency_std_per_bandwidth", self.max_frequency_std_per_bandwidth, low=0, low_open=True,
              allow_none=True)
        check_real("unanchored_noise_coupling", self.unanchored_noise_coupling, low=1, allow_none=True)
        for name in ("per_cluster_min_size", "merge_fragments", "drop_doublets", "order_discrepancy",
                     "drop_noise_twins", "reassign_borrowed_poles"):
            object.__setattr__(self, name, check_boolean(name, getattr(self, name)))  # a bool, as to_dict gives
        check_real("doublet_window", self.doublet_window, low=0)
        check_real("doublet_min_mac", self.doublet_min_mac, low=0, high=1)
        check_real("fragment_std_factor", self.fragment_std_factor, low=0)
        check_real("fragment_min_mac", self.fragment_min_mac, low=0, high=1)
        check_real("fragment_max_shared", self.fragment_max_shared, low=0, high=1)
        if isinstance(self.statuses, (str, PoleStatus)):
            object.__setattr__(self, "statuses", (self.statuses,))
        try:
            object.__setattr__(self, "statuses", tuple(PoleStatus(s) for s in self.statuses))
        except (TypeError, ValueError):
            raise ValueError(f"statuses must hold PoleStatus values {[s.value for s in PoleStatus]}; "
                             f"got {self.statuses!r}") from None
        if not self.statuses:
            raise ValueError("statuses must not be empty")
        if self.linkage not in ("single", "complete", "average", "weighted"):
            raise ValueError(f"linkage must be 'single', 'complete', 'average' or 'weighted'; got {self.linkage!r}")
        if self.cluster_std is not None and not isinstance(self.cluster_std, str):
            raise TypeError(f"cluster_std must be None, 'median' or 'mean'; got {type(self.cluster_std).__name__}")
        if self.cluster_std not in (None, "median", "mean"):
            raise ValueError(f"cluster_std must be None, 'median' or 'mean'; got {self.cluster_std!r}")
        for name in ("representative", "shape_representative"):
            value = getattr(self, name)
            if not isinstance(value, str):
                raise TypeError(f"{name} must be 'median' or 'lowest'; got {type(value).__name__}")
            if value not in ("median", "lowest"):
                raise ValueError(f"{name} must be 'median' or 'lowest'; got {value!r}")

    def to_dict(self) -> dict:
        return {f.name: _exported(getattr(self, f.name)) for f in fields(self)}

    def to_core(self) -> "_core.ClusteringOptions":
        return _to_core(self, _core.ClusteringOptions, _crossing(ClusteringSettings, _core.ClusteringOptions))
