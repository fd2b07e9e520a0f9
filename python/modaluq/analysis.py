"""Analysis: from a record (a file or arrays) to selected modes, every step kept.

:class:`Analysis` is the pipeline behind ``modaluq identify`` and what a notebook or a batch
job uses to go the same way: the record's channels → preprocessing (window, band, decimation,
filters) → identification → stabilization diagram → selected modes (with the possible
harmonics and, on request, the horizon check) → provenance. Each step's result stays on the
object; plotting and writing files are the layers above (:mod:`modaluq.plot`,
:mod:`modaluq.export`).

>>> import modaluq
>>> sim = modaluq.simulate(50_000, seed=2)
>>> a = Analysis.from_arrays(sim.y, sim.u, fs=sim.fs, settings=modaluq.Settings(block_rows=21, orders=range(2, 61, 2)))
>>> _ = a.run()
>>> [round(float(f), 1) for f in a.selected.frequency_hz]
[1.9, 5.6, 8.7, 14.5, 15.8, 17.0]
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence

import numpy as np

from . import horizons
from .auto_settings import LAG_PERIODS, choose_settings
from .checks import as_samples, check_boolean, check_instance, check_sampling_frequency
from .harmonics import harmonic_kurtosis, possible_harmonics
from .horizons import HorizonCheck
from .identification import identify_quietly, short_lag_warning
from .io import Recording, load
from .jsonvalues import finite_or_none, jsonable
from .preprocess import Preprocessed, preprocess
from .provenance import provenance
from .results import IdentificationWarning, ModalUQWarning, Result
from .selection import SelectedModes, largest_dropped_clusters, select_modes
from .settings import ClusteringSettings, PoleStatus, Settings, StabilityCriteria
from .stabilization import Diagram, stabilization_diagram

__all__ = ["Analysis", "describe_orders", "resolve_channels"]


def resolve_channels(tokens: Sequence, names: Sequence[str], parameter: str) -> list:
    """Channel names or indices (ints or their text) → indices into ``names`` (a name wins).

    Raises ``ValueError`` naming ``parameter`` for an unknown, ambiguous, out-of-range or
    repeated channel.
    """
    n = len(names)
    out = []
    for t in tokens:
        hits = [k for k, nm in enumerate(names) if nm == str(t)]
        if len(hits) > 1:
            raise ValueError(f"{parameter}: channel name {t!r} is ambiguous (channels {hits}); give its index")
        if hits:
            out.append(hits[0])
            continue
        try:
            k = int(t)
        except (TypeError, ValueError):
            shown = ", ".join(repr(s) for s in names[:20]) + (", ..." if n > 20 else "")
            raise ValueError(f"{parameter}: channel {t!r} not found; channels are: {shown}") from None
        if not -n <= k < n:
            raise ValueError(f"{parameter}: channel index {k} is out of range for {n} channels")
        out.append(k % n)
    if len(set(out)) != len(out):
        raise ValueError(f"{parameter}: the same channel is given more than once: {' '.join(map(str, tokens))}")
    return out


def describe_orders(orders) -> str:
    """``2..60 step 2 (30 orders)`` for a regular range, else the list."""
    orders = list(orders)
    if len(orders) > 2:
        steps = set(np.diff(orders).tolist())
        if len(steps) == 1:
            return f"{orders[0]}..{orders[-1]} step {steps.pop()} ({len(orders)} orders)"
    return ", ".join(map(str, orders))


def _warnings_of_selection(result: Result, selected: SelectedModes, lag: str | None = None,
                           pole_frequency_hz=None) -> list:
    """The identification's warnings that concern the selected modes (docs/settings.md, "Warnings
    that mean something"): a warning is kept only when what it says changes a selected mode or
    its σ.

    - Slowly decaying poles (``Result.slow_decay``, the core's flag of poles whose decay time
      1/(2π f ξ) is more than twice a block): not said. Monte Carlo finds the σ of f and ξ of
      such modes not under-estimated, with blocks down to 1/170 of the decay time (the slow part
      of a block's error is the mode's amplitude, which leaves f and ξ alone); the flag stays in
      numbers, ``SelectedModes.block_too_short``, and in ``Result.warnings``.
    - ``lag``, the sentence of :func:`~modaluq.identification.short_lag_warning` that identify()
      added (Python's own words; lags shorter than one period of the band's lower edge): kept when
      a pole of the diagram not rejected by its own checks (``pole_frequency_hz``; without it, a
      selected mode or a dropped cluster) lies near that edge, below LAG_PERIODS f_low, with a
      period longer than the lags (a mode there is identified with too short lags, or missed: its
      poles do not stabilise), or when no mode is selected.
    """
    out = list(result.warnings)
    drop = set()
    if result.slow_decay is not None:
        drop.add(result.warning_codes.index(IdentificationWarning.SLOW_DECAY))
    python_words = [k for k, c in enumerate(result.warning_codes) if c is None and out[k] == lag]
    if lag is not None and python_words and not _lags_matter(result, selected, pole_frequency_hz):
        drop.update(python_words)
    return [w for k, w in enumerate(out) if k not in drop]


def _lags_matter(result: Result, selected: SelectedModes, pole_frequency_hz=None) -> bool:
    """Whether lags shorter than one period of the band's lower edge concern this run: a pole of
    the diagram (or a selected mode or dropped cluster) near that edge (below LAG_PERIODS f_low)
    whose period is longer than the lags, or no mode selected at all."""
    if not selected.n_modes:
        return True
    band = result.settings.get("frequency_range")
    if not band:
        return True
    spanned = result.fs / result.settings["block_rows"]  # the lowest frequency whose period the lags span
    near = min(spanned, LAG_PERIODS * band[0])
    if pole_frequency_hz is None:
        pole_frequency_hz = np.concatenate([np.asarray(selected.frequency_hz, float),
                                            np.asarray(selected.dropped_frequency_hz, float)])
    found = np.asarray(pole_frequency_hz, float)
    return bool(np.any((found >= band[0]) & (found < near)))


@dataclass
class Analysis:
    """One record's way from samples to selected modes; :meth:`run` fills the results.

    Made by :meth:`from_file` or :meth:`from_arrays`. The settings are frozen objects
    (:class:`~modaluq.Settings`, :class:`~modaluq.StabilityCriteria`,
    :class:`~modaluq.ClusteringSettings`); :meth:`with_settings` gives a copy with some changed.
    """

    y: np.ndarray                       #: (n_samples, n_outputs) outputs as recorded
    u: Optional[np.ndarray]             #: (n_samples, n_inputs) inputs as recorded, or None
    fs: float                           #: sampling frequency of the record, Hz
    output_names: tuple
    input_names: tuple = ()
    references: Optional[tuple] = None  #: indices into the outputs (default all)
    settings: Settings = field(default_factory=Settings)
    criteria: StabilityCriteria = field(default_factory=StabilityCriteria)
    clustering: ClusteringSettings = field(default_factory=ClusteringSettings)
    source: Optional[str] = None        #: the file read, if any
    recording: Optional[Recording] = None
    # ------------------------------------------------------------------ filled by run()
    preprocessed: Optional[Preprocessed] = None
    result: Optional[Result] = None
    diagram: Optional[Diagram] = None
    selected: Optional[SelectedModes] = None
    harmonic_kurtosis: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: per selected mode
    possible_harmonic: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  #: per selected mode
    horizons: Optional[HorizonCheck] = None
    warnings: tuple = ()                #: the identification's warnings, as text

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_arrays(cls, y, u=None, *, fs: float, output_names=None, input_names=None, references=None,
                    settings: Settings | None = None, criteria: StabilityCriteria | None = None,
                    clustering: ClusteringSettings | None = None) -> "Analysis":
        """An analysis of ``y`` (and ``u``) sampled at ``fs`` Hz; ``references`` by name or index."""
        fs = check_sampling_frequency(fs)
        y = as_samples(y, "y")
        u = as_samples(u, "u", allow_none=True)
        if u is not None and u.shape[0] != y.shape[0]:
            raise ValueError(f"u must have as many samples as y ({y.shape[0]}); got {u.shape[0]}")
        out_names = _names(output_names, y.shape[1], "y", "output_names")
        in_names = _names(input_names, 0 if u is None else u.shape[1], "u", "input_names")
        refs = None if references is None else tuple(resolve_channels(references, out_names, "references"))
        return cls(y=y, u=u, fs=fs, output_names=out_names, input_names=in_names, references=refs,
                   settings=check_instance("settings", settings, Settings),
                   criteria=check_instance("criteria", criteria, StabilityCriteria),
                   clustering=check_instance("clustering", clustering, ClusteringSettings))

    @classmethod
    def from_file(cls, path, *, fs: float | None = None, format: str | None = None, read_options: dict | None = None,
                  outputs=None, inputs=None, references=None, settings: Settings | None = None,
                  criteria: StabilityCriteria | None = None,
                  clustering: ClusteringSettings | None = None) -> "Analysis":
        """An analysis of a recording file (:func:`modaluq.io.load`).

        ``outputs`` / ``inputs`` / ``references`` select channels by name or index; by default
        the inputs are those the file declares (unless listed as outputs) and the outputs the
        rest. ``fs`` overrides the file's rate; ``read_options`` go to the file's reader.
        """
        rec = load(path, fs=fs, format=format, **(read_options or {}))
        names = list(rec.output_names) + list(rec.input_names)
        data = rec.y if rec.u is None else np.hstack([rec.y, rec.u])
        file_inputs = list(range(rec.n_outputs, rec.n_outputs + rec.n_inputs))
        out_idx = resolve_channels(outputs, names, "outputs") if outputs else None
        if inputs:
            in_idx = resolve_channels(inputs, names, "inputs")
        else:  # inputs the file declares itself (e.g. 'u' of an .npz), unless listed as outputs
            in_idx = [k for k in file_inputs if out_idx is None or k not in out_idx]
        if out_idx is None:
            out_idx = [k for k in range(len(names)) if k not in set(in_idx)]
        both = sorted(set(in_idx) & set(out_idx))
        if both:
            raise ValueError(f"outputs and inputs both select channel {names[both[0]]!r}")
        if not out_idx:
            raise ValueError("no output channel left: every channel is an input")
        y = np.ascontiguousarray(data[:, out_idx])
        u = np.ascontiguousarray(data[:, in_idx]) if in_idx else None
        a = cls.from_arrays(y, u, fs=rec.fs, output_names=[names[k] for k in out_idx],
                            input_names=[names[k] for k in in_idx], references=references, settings=settings,
                            criteria=criteria, clustering=clustering)
        return dataclasses.replace(a, source=str(path), recording=rec)

    def with_settings(self, **changes) -> "Analysis":
        """A copy (not run) whose :class:`~modaluq.Settings` has ``changes``; the preprocessed record
        is kept when no preprocessing field changes (the command line sets the orders after it)."""
        settings = self.settings.replace(**changes)
        kept = self.preprocessed if settings.preprocessing == self.settings.preprocessing else None
        return dataclasses.replace(self, settings=settings, preprocessed=kept, result=None, diagram=None,
                                   selected=None, harmonic_kurtosis=np.zeros(0),
                                   possible_harmonic=np.zeros(0, bool), horizons=None, warnings=())

    def identified_like(self, other: "Analysis") -> "Analysis":
        """A copy (not run) with the horizons, orders and blocks ``other``'s run used (its automatic
        choice or its settings), so that this record is identified as ``other`` was: two records
        compared, or the two halves of one (:func:`modaluq.compare_modes`, split halves)."""
        other._require_run()
        used = other.result.settings
        return self.with_settings(**{k: used[k] for k in ("block_rows", "past_block_rows", "orders", "n_blocks")})

    # ------------------------------------------------------------------ steps

    def preprocess(self) -> Preprocessed:
        """The record after the settings' window, band, decimation and filters (kept)."""
        if self.preprocessed is None:
            self.preprocessed = preprocess(self.y, self.u, fs=self.fs, **self.settings.preprocessing)
        return self.preprocessed

    def identification_settings(self) -> Settings:
        """The settings identify() gets: the preprocessed samples' band, no further preprocessing,
        the references, and ``block_rows`` chosen from the data when not set."""
        pre = self.preprocess()
        return self.settings.replace(
            frequency_range=pre.frequency_range, decimate=1, start=None, stop=None, detrend=None, highpass=None,
            references=self.references if self.references is not None else self.settings.references)

    def largest_order(self) -> tuple:
        """``(order, why)``: the largest model order the horizons allow on this record, and a
        sentence saying how it comes about (the core's rule, min((p-1) l, q r))."""
        pre = self.preprocess()
        s = self.identification_settings()
        l = pre.y.shape[1]
        n_refs = len(s.references) if s.references else l
        if s.block_rows is None:  # the rule identify() applies to the same samples (docs/settings.md)
            s = s.replace(block_rows=choose_settings(pre.n_samples, pre.fs, l, frequency_range=pre.frequency_range,
                                                     n_references=n_refs, orders=(2,), n_blocks=2).block_rows)
        p = s.block_rows
        q = s.past_block_rows or p
        if p + q > pre.n_samples:  # no bound from absurd horizons
            raise ValueError(f"block_rows {p} with past_block_rows {q}: p + q = {p + q} exceeds the "
                             f"{pre.n_samples} samples of the record")
        return s.max_order(l), (f" = min((p-1)·l, q·r) = min({p - 1}·{l}, {q}·{n_refs}) for block_rows {p}, "
                                f"past_block_rows {q}, {l} outputs and {n_refs} references")

    def run(self, *, check_horizons: bool = False, check_harmonics: bool = True,
            progress: Callable[[str], None] | None = None, issue_warnings: bool = True) -> "Analysis":
        """Identify, form the diagram, select the modes (and check the horizons); returns self.

        ``check_harmonics``: flag the selected modes that may be harmonics of the excitation
        (:mod:`modaluq.harmonics`; it filters the record around each mode, which costs about as
        much as the identification of a long many-channel record). ``progress`` is called with
        the name of each step before it starts. The identification's warnings are kept in
        :attr:`warnings` and, with ``issue_warnings`` (default), issued as :class:`ModalUQWarning`;
        threads running analyses at once pass False (Python's warning filters are global state).
        A warning is kept only when what it says concerns the selected modes (docs/settings.md,
        "Warnings that mean something"): lags shorter than a period of the band's lower edge, when
        a pole of the diagram not rejected lies near that edge or no mode is found; poles decaying more slowly
        than the blocks are long are not said (their σ of f and ξ hold; ``SelectedModes.block_too_short``
        keeps the flag).
        """
        issue_warnings = check_boolean("issue_warnings", issue_warnings)
        step = progress or (lambda _: None)
        pre = self.preprocess()
        s = self.identification_settings()

        step("identifying")
        result = identify_quietly(pre.y, pre.u, fs=pre.fs, settings=s, output_names=self.output_names)
        result.settings["preprocessing"] = pre.settings()  # what was done to the record's samples
        self.result = result

        step("stabilization diagram")
        self.diagram = stabilization_diagram(result, self.criteria, output_names=self.output_names)
        step("clustering")
        self.selected = select_modes(self.diagram, self.clustering)
        lag = short_lag_warning(result.settings["block_rows"], pre.fs, pre.y.shape[1], pre.frequency_range,
                                automatic=s.block_rows is None)
        plausible = ~self.diagram.is_status(PoleStatus.REJECTED)  # rejected: ξ out of range, outside the band ...
        self.warnings = tuple(_warnings_of_selection(result, self.selected, lag,
                                                     self.diagram.frequency_hz[plausible]))
        if issue_warnings:
            for w in self.warnings:
                warnings.warn(w, ModalUQWarning, stacklevel=2)
        # rotating machinery: kurtosis of the response filtered around each mode (harmonics.py)
        if check_boolean("check_harmonics", check_harmonics) and self.selected.n_modes:
            self.harmonic_kurtosis = harmonic_kurtosis(pre.y, pre.fs, self.selected.frequency_hz)
            self.possible_harmonic = possible_harmonics(pre.y, pre.fs, self.selected.frequency_hz,
                                                        self.selected.damping_ratio, kurtosis=self.harmonic_kurtosis)
        if check_boolean("check_horizons", check_horizons) and self.selected.n_modes:
            # the same record at 0.75, 1 and 1.5 times the horizon: a bias from the horizon
            # does not show in σ, but in how the estimate moves (horizons.py)
            step("settings check")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self.horizons = horizons.check_horizons(
                    pre.y, pre.u, fs=pre.fs, settings=s.replace(block_rows=result.settings["block_rows"], orders=None,
                                                                keep_shape_factor=False),
                    criteria=self.criteria, clustering=self.clustering, progress=step)
        return self

    # ------------------------------------------------------------------ provenance and reports

    def provenance(self, **extra_settings) -> dict:
        """The stamp of the run: version, every setting, the channels, the input file's checksum."""
        self._require_run()
        refs = list(self.references) if self.references is not None else None
        return provenance(self.source, settings={
            "identification": self.result.settings, "stability": self.criteria.to_dict(),
            "clustering": self.clustering.to_dict(),
            "channels": {"outputs": list(self.output_names), "inputs": list(self.input_names),
                         "references": [self.output_names[k] for k in refs] if refs else list(self.output_names)},
            **extra_settings,
        })

    def report(self) -> dict:
        """What a report adds to the diagram and the modes: the input, warnings, possible harmonics
        and the horizon check (plain values)."""
        self._require_run()
        sel = self.selected
        out = {"input": {"n_samples": int(self.y.shape[0]), "fs_hz": self.fs, "outputs": list(self.output_names),
                         "inputs": list(self.input_names),
                         "source": self.recording.source if self.recording is not None else None},
               "warnings": list(self.warnings),
               "possible_harmonics": [{"mode": k + 1, "frequency_hz": float(sel.frequency_hz[k]),
                                       "kurtosis": float(self.harmonic_kurtosis[k])}
                                      for k in np.flatnonzero(self.possible_harmonic)]}
        if self.horizons is not None:
            h = self.horizons
            out["horizon_check"] = {
                "block_rows": list(h.block_rows),
                "modes": [{"mode": i + 1, "frequency_hz": jsonable(h.frequency_hz[i]),
                           "damping_ratio": jsonable(h.damping_ratio[i]),
                           "frequency_spread": finite_or_none(h.frequency_spread[i])} for i in range(sel.n_modes)]}
        return out

    def describe_run(self) -> str:
        """The record, the preprocessing, the settings chosen and the diagram's counts, in words."""
        self._require_run()
        r, d, s = self.result, self.diagram, self.result.settings
        n = int(self.y.shape[0])
        kind = "input/output" if self.input_names else "output-only"
        lines = [f"  {n} samples at {self.fs:g} Hz ({n / self.fs:g} s), {kind}; outputs: {', '.join(self.output_names)}"
                 + (f"; inputs: {', '.join(self.input_names)}" if self.input_names else "")]
        lines += [f"  {step}" for step in s.get("preprocessing", {}).get("steps", [])]
        lines += [f"  chosen: {why}" for why in s.get("chosen", [])]
        lines.append(f"  block_rows={s['block_rows']}, past_block_rows={s['past_block_rows']}, "
                     f"orders {describe_orders(r.orders)}, "
                     + (f"{r.n_blocks} blocks of {r.block_length} columns" if r.n_blocks else "no uncertainty"))
        counts = ", ".join(f"{st.value.replace('_', ' ')} {d.count(st)}" for st in PoleStatus)
        lines.append(f"  stabilization diagram: {d.n_poles} poles ({counts})")
        if r.n_blocks:
            coupled = d.noise_coupled
            stable = d.is_status(PoleStatus.STABLE)
            lines.append(f"  noise floor: {r.significant_singular_values} significant singular values of H (an "
                         f"estimate of the model order); {int(coupled.sum())} pole(s) noise-coupled, "
                         f"{int((coupled & stable).sum())} of them stable (spurious or mixed with a spurious pole: "
                         "no first-order std)")
        close = d.close_singular_value_orders
        if close:
            lines.append(f"  orders cutting close singular values (their std less reliable): {describe_orders(close)}")
        return "\n".join(lines)

    def describe_modes(self) -> str:
        """The selected modes, possible harmonics, the horizon check and the largest dropped clusters."""
        self._require_run()
        sel = self.selected
        lines = []
        if sel.n_modes:
            lines.append(str(sel))
            for k in np.flatnonzero(self.possible_harmonic):
                lines.append(f"mode {k + 1} ({sel.frequency_hz[k]:.4g} Hz, xi {100 * sel.damping_ratio[k]:.2g} %) may "
                             f"be a harmonic of the excitation, not a structural mode: its filtered response has "
                             f"kurtosis {self.harmonic_kurtosis[k]:.2f} (a sinusoid 1.5, a random mode 3; "
                             "docs/settings.md)")
        else:
            lines.append("no mode selected: no cluster of stable poles both reached "
                         f"{sel.min_cluster_size} poles and had a frequency std within its bandwidth "
                         "(try more orders, a longer record, a narrower band or looser criteria)")
        if self.horizons is not None:
            lines += ["", str(self.horizons)]
        lines += largest_dropped_clusters(sel)
        return "\n".join(lines)

    def __str__(self) -> str:
        if self.result is None:
            return repr(self)
        return self.describe_run() + "\n\n" + self.describe_modes()

    def __repr__(self) -> str:
        state = "not run" if self.result is None else f"{self.selected.n_modes} modes selected"
        return (f"Analysis({self.source or 'arrays'}: {self.y.shape[0]} samples at {self.fs:g} Hz, "
                f"{len(self.output_names)} outputs, {len(self.input_names)} inputs; {state})")

    def _require_run(self) -> None:
        if self.result is None:
            raise ValueError("the analysis has not been run: call .run() first")


def _names(names, n: int, prefix: str, parameter: str) -> tuple:
    if names is None:
        return tuple(f"{prefix}{k}" for k in range(n))
    if isinstance(names, str):
        raise TypeError(f"{parameter} must be a sequence of names; got a single string")
    names = tuple(str(s) for s in names)
    if len(names) != n:
        raise ValueError(f"{parameter} must have {n} entries; got {len(names)}")
    return names
