"""The measured-record check of σ (issue 27, docs/validation.md "Split halves"): the two halves
of one record identified alike, and each mode's two estimates compared against their σ.

If the σ are right, z = (x₁ − x₂) / √(σ₁² + σ₂²) is standard normal for every mode found in both
halves (the halves are independent records of the same structure): over many modes its RMS is
about 1 and 95 % of the z lie within ±1.96. The shapes are checked alike: under "same mode" the
loss 1 − MAC of the two halves' shapes has a mean and σ from both shapes' covariances
(:func:`modaluq.indicators.mac_test`), so z_MAC = (1 − MAC − mean) / σ has RMS about 1 and the
"same mode" test rejects about 5 % of the pairs at 5 % if the shapes' σ are right. No
simulation is needed, so it checks σ on the user's own record. A structure that changes between
the halves (temperature, traffic mass, an operating machine's state, a strong-motion half and a
coda) gives |z| > 1 that is not σ's fault: choose a stationary record.

Each half is also read with its own σ, z = (x₁ − x₂) / (√2 σ_h) (``z_frequency_own_sigma``,
``z_damping_own_sigma``): the halves have the same length and settings, so this has the law of
one record's error over its own σ, the coverage of an engineer's interval x ± 1.96 σ, which the
combined z overstates where σ scatters from record to record.

    >>> import modaluq
    >>> from modaluq.analysis import Analysis
    >>> from modaluq.simulate import simulate
    >>> sim = simulate(n_samples=40_000, seed=3)
    >>> a = Analysis.from_arrays(sim.y, fs=sim.fs, settings=modaluq.Settings(block_rows=15, orders=range(2, 31, 2)))
    >>> check = split_halves(a)
    >>> check.summary()["n_pairs"] >= 4
    True
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..analysis import Analysis
from ..checks import check_boolean, check_integers
from ..comparison import Z_95, ModeComparison, check_pairing, compare_modes, rms_and_within

__all__ = ["PooledSplitHalves", "SplitHalves", "split_halves", "split_halves_windows"]

@dataclass(frozen=True)
class SplitHalves(ModeComparison):
    """The modes found in both halves, their estimates, σ and z (one row per mode pair): a
    :class:`~modaluq.comparison.ModeComparison` of the two halves.

    ``halves_s`` are the two windows in seconds of the record; ``settings`` the horizons, orders and
    blocks both halves were identified with.
    """

    halves_s: tuple = ()
    settings: dict = None
    #: (n_pairs, 2) the factor t of each half's 95 % intervals x ± t σ (``SelectedModes.interval_factor``:
    #: the Student-t quantile of that half's n_blocks − 1, the core's count); None: unknown, the normal 1.96
    interval_factor_95: np.ndarray | None = None

    @property
    def z_frequency_own_sigma(self) -> np.ndarray:
        """(n_pairs, 2): (f₁ − f₂) / (√2 σ_f,h) with each half h's own σ, the per-record reading."""
        return _z_own_sigma(self.frequency_hz, self.frequency_std)

    @property
    def z_damping_own_sigma(self) -> np.ndarray:
        """(n_pairs, 2): (ξ₁ − ξ₂) / (√2 σ_ξ,h) with each half h's own σ, the per-record reading."""
        return _z_own_sigma(self.damping_ratio, self.damping_std)

    def summary(self) -> dict:
        """:meth:`ModeComparison.summary`, and the same of the per-record reading (each half's own σ,
        both halves' z counted): ``rms_z_frequency_own_sigma``, ``within_frequency_own_sigma``,
        ``rms_z_damping_own_sigma``, ``within_damping_own_sigma``; and the share of the halves'
        95 % intervals x ± t σ (``SelectedModes.intervals``) that the per-record reading holds,
        ``within_frequency_own_interval``, ``within_damping_own_interval`` (|z| ≤ t)."""
        out = super().summary()
        factor = self._factor()
        for name, z in (("frequency", self.z_frequency_own_sigma), ("damping", self.z_damping_own_sigma)):
            out[f"rms_z_{name}_own_sigma"], out[f"within_{name}_own_sigma"] = rms_and_within(z)
            # the product's 95 % interval x ± t σ read alike: |z| ≤ t of the pair's blocks
            out[f"within_{name}_own_interval"] = rms_and_within(z * (Z_95 / factor))[1]
        return out

    def _factor(self) -> np.ndarray:
        """(n_pairs, 2) each half's interval factor (the normal quantile where unknown)."""
        if self.interval_factor_95 is None:
            return np.full((self.frequency_hz.shape[0], 2), Z_95)
        return np.asarray(self.interval_factor_95, float).reshape(-1, 2)

    def to_dataframe(self):
        """:meth:`ModeComparison.to_dataframe` with the per-record reading's z of each half
        (``z_frequency_own_sigma_1``, ``_2``, ``z_damping_own_sigma_1``, ``_2``)."""
        df = super().to_dataframe()
        for name, z in (("frequency", self.z_frequency_own_sigma), ("damping", self.z_damping_own_sigma)):
            df[f"z_{name}_own_sigma_1"], df[f"z_{name}_own_sigma_2"] = z[:, 0], z[:, 1]
        return df

    def report(self) -> str:
        """A Markdown report: the windows, the settings, the table and the summary."""
        (a0, a1), (b0, b1) = self.halves_s
        body = self._body("half", "both halves", "σ is right",
                          " (a handful of modes only says whether σ is grossly off)")
        s = self.summary()
        if s["n_pairs"]:
            body += ["", f"Each half's own σ (z = Δ / (√2 σ of that half), the per-record reading): RMS z "
                         f"{s['rms_z_frequency_own_sigma']:.2f} (f), {s['rms_z_damping_own_sigma']:.2f} (ξ); within "
                         f"±1.96: {100 * s['within_frequency_own_sigma']:.0f} % (f), "
                         f"{100 * s['within_damping_own_sigma']:.0f} % (ξ); within the 95 % interval ± t σ "
                         f"(t = {', '.join(sorted({f'{t:.3f}' for t in self._factor()[0]}))}): "
                         f"{100 * s['within_frequency_own_interval']:.0f} % (f), "
                         f"{100 * s['within_damping_own_interval']:.0f} % (ξ). " + OWN_SIGMA_NOTE]
        return "\n".join([f"## Split halves: {a0:g}-{a1:g} s against {b0:g}-{b1:g} s", "",
                          "Settings of both halves: " + ", ".join(f"{k} {v}" for k, v in (self.settings or {}).items()),
                          "", *body]) + "\n"


#: Why the report gives the per-record reading beside z = Δ / √(σ₁² + σ₂²) (docs/validation.md issue 27 (p)).
OWN_SIGMA_NOTE = ("z = Δ / √(σ₁² + σ₂²) divides by both halves' σ together, which averages out how much one "
                  "record's σ scatters; an engineer's interval f ± 1.96 σ uses one record's σ. Where σ scatters from "
                  "record to record, the combined z can read calibrated while single intervals cover less; the "
                  "per-record reading reads their coverage 1-2 points low. The coverage of your intervals lies "
                  "between the two (docs/validation.md, issue 27 (p)).")


def _z_own_sigma(values: np.ndarray, stds: np.ndarray) -> np.ndarray:
    """(x₁ − x₂) / (√2 σ_h) for h = 1, 2: the halves have the same length and settings, so under "σ
    is right" Δ has the variance 2σ² and each column is a standard normal read with one record's σ."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return (values[:, :1] - values[:, 1:]) / (np.sqrt(2.0) * stds)


@dataclass(frozen=True)
class PooledSplitHalves:
    """:func:`split_halves` on consecutive windows of one record (:func:`split_halves_windows`).

    ``checks`` holds one ``(n_windows, window, SplitHalves)`` per window that ran (window 0 is
    the first of the n); ``failed`` one ``(n_windows, window, (t0, t1) s, message)`` per window too
    short for the settings. Pairs of one ``n_windows`` use disjoint data and are independent; pairs
    of different ``n_windows`` share data, so the pooled count overstates the information.
    """

    checks: tuple
    failed: tuple

    @property
    def levels(self) -> list:
        return sorted({n for n, _, _ in self.checks} | {n for n, _, _, _ in self.failed})

    def pooled(self, n_windows=None) -> SplitHalves:
        """The pairs of every window (or of the windows of one ``n_windows``) as one :class:`SplitHalves`."""
        chosen = [c for n, _, c in self.checks if n_windows is None or n == n_windows]
        if not chosen:
            empty2, empty = np.empty((0, 2)), np.empty(0)
            return SplitHalves(empty2, empty2, empty2, empty2, empty, halves_s=(), settings={},
                               interval_factor_95=np.empty((0, 2)))

        def cat(name):
            return np.concatenate([getattr(c, name) for c in chosen])

        # every per-pair array of ModeComparison joined; the unpaired modes side by side; one pairing
        joined = {f.name: cat(f.name) for f in fields(ModeComparison) if f.name not in ("unmatched_hz", "pairing")}
        return SplitHalves(**joined, halves_s=tuple(c.halves_s for c in chosen), settings={},
                           interval_factor_95=np.concatenate([c._factor() for c in chosen]),
                           unmatched_hz=tuple(np.concatenate([c.unmatched_hz[k] for c in chosen]) for k in (0, 1)),
                           pairing=chosen[0].pairing)

    def summary(self) -> dict:
        """:meth:`SplitHalves.summary` of every pair, with ``n_windows_run`` and ``n_windows_failed``."""
        return self.pooled().summary() | {"n_windows_run": len(self.checks), "n_windows_failed": len(self.failed)}

    def to_dataframe(self):
        """:meth:`SplitHalves.to_dataframe` of every window, with ``n_windows``, ``window``,
        ``t0_s`` and ``t1_s`` (the window that was split, seconds) in front."""
        import pandas as pd

        frames = []
        for n, k, c in self.checks:
            df = c.to_dataframe()
            (a, _), (_, b) = c.halves_s
            df.insert(0, "t1_s", b)
            df.insert(0, "t0_s", a)
            df.insert(0, "window", k)
            df.insert(0, "n_windows", n)
            frames.append(df)
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(
            columns=["n_windows", "window", "t0_s", "t1_s"])

    def report(self) -> str:
        """A Markdown report: RMS z and the share within ±1.96 per number of windows and pooled,
        the failed windows, then each window's own report."""
        lines = ["## Split halves over consecutive windows", "",
                 "Each window of the record is split into its two halves. Pairs of one row (one number of windows) "
                 "use disjoint data; rows share data, so the **all** row overstates the information. If σ is right: "
                 "RMS z ≈ 1 and about 95 % within ±1.96, over many pairs; with n pairs an RMS z is known to about "
                 "±1/√(2n). A structure that changes between halves (temperature, an operating machine, people on a "
                 "floor) raises z without σ being wrong.", "",
                 "The last three columns read each half with its own σ, z = Δ / (√2 σ of that half), both halves' z "
                 "counted; the last, the share within each half's 95 % interval ± t σ (t the Student-t quantile of "
                 "its n_blocks − 1, SelectedModes.intervals). " + OWN_SIGMA_NOTE, "",
                 "| windows | pairs | RMS z f, ξ (± about) | within ±1.96 f, ξ | RMS z_MAC, \"same mode\" rejected "
                 "| own σ: RMS z f, ξ | own σ: within ±1.96 f, ξ | own σ: within ± t σ f, ξ |",
                 "|---|---|---|---|---|---|---|---|"]
        for label, n in [*((f"{n}", n) for n in self.levels), ("**all**", None)]:
            s = self.pooled(n).summary()
            if not s["n_pairs"]:
                lines.append(f"| {label} | 0 | — | — | — | — | — | — |")
                continue
            lines.append(f"| {label} | {s['n_pairs']} | {s['rms_z_frequency']:.2f}, {s['rms_z_damping']:.2f} "
                         f"(±{1 / np.sqrt(2 * s['n_pairs']):.2f}) | "
                         f"{100 * s['within_frequency']:.0f} %, {100 * s['within_damping']:.0f} % | "
                         f"{s['rms_z_mac']:.2f}, {100 * s['same_mode_rejected']:.0f} % | "
                         f"{s['rms_z_frequency_own_sigma']:.2f}, {s['rms_z_damping_own_sigma']:.2f} | "
                         f"{100 * s['within_frequency_own_sigma']:.0f} %, "
                         f"{100 * s['within_damping_own_sigma']:.0f} % | "
                         f"{100 * s['within_frequency_own_interval']:.0f} %, "
                         f"{100 * s['within_damping_own_interval']:.0f} % |")
        for level in self.levels:  # a few failures each; beyond three, the first and a count
            mine = [f for f in self.failed if f[0] == level]
            for n, k, (a, b), message in mine[:1] if len(mine) > 3 else mine:
                lines.append(f"\nWindow {k + 1} of {n} ({a:g}-{b:g} s) failed: {message}")
            if len(mine) > 3:
                lines.append(f"... and {len(mine) - 1} more of the {level} windows failed (`failed` lists them).")
        text = "\n".join(lines) + "\n"
        return text + "".join("\n" + c.report() for _, _, c in self.checks)


def split_halves_windows(analysis: Analysis, windows=(1, 2, 4, 8), *, progress: bool = False,
                         max_frequency_difference: float = 0.02, min_mac: float = 0.8,
                         pair_within_std: float = 4.0) -> PooledSplitHalves:
    """:func:`split_halves` on each of n consecutive, non-overlapping windows of ``analysis``'s
    record (its ``start``/``stop`` window), for every n of ``windows``, so that one record gives
    many mode pairs (docs/validation.md "Pooled over windows of several lengths"): with the
    default (1, 2, 4, 8) a record is split at four lengths, its halves from T/2 down to T/16.
    Every window chooses its automatic settings on its own first half, as :func:`split_halves`
    does. A window too short for them is recorded in ``failed`` and the others go on.
    ``max_frequency_difference``, ``min_mac`` and ``pair_within_std`` are :func:`split_halves`';
    ``progress`` shows a progress bar of the windows (on stderr).

    Raises
    ------
    ValueError
        Bad ``windows`` (integers ≥ 1) or pairing keywords, or settings without the uncertainty.
    """
    if not isinstance(analysis, Analysis):
        raise TypeError(f"analysis must be a modaluq.analysis.Analysis; got {type(analysis).__name__}")
    levels = sorted(set(check_integers("windows", windows, minimum=1)))
    progress = check_boolean("progress", progress)
    pairing = check_pairing(max_frequency_difference, min_mac, pair_within_std)  # before any window runs
    t0, t1 = _window(analysis)
    from tqdm.auto import tqdm

    # fewer samples than channels cannot be identified at all (and would read as a transposed array)
    channels = analysis.y.shape[1] + (analysis.u.shape[1] if analysis.u is not None else 0)
    checks, failed = [], []
    with tqdm(total=sum(levels), desc="modaluq split halves", unit="window", disable=not progress) as bar:
        for n in levels:
            half_samples = int((t1 - t0) / n / 2 * analysis.fs)
            for k in range(n):
                a, b = t0 + k * (t1 - t0) / n, t0 + (k + 1) * (t1 - t0) / n
                try:
                    if half_samples <= 2 * channels:
                        raise ValueError(f"halves of about {half_samples} samples, too short for {channels} channels")
                    checks.append((n, k, split_halves(analysis.with_settings(start=a, stop=b), **pairing)))
                except ValueError as exc:  # the window's halves are too short for its settings
                    failed.append((n, k, (a, b), str(exc).splitlines()[0] + " (fewer windows give longer halves)"))
                bar.update()
    return PooledSplitHalves(checks=tuple(checks), failed=tuple(failed))


def _window(analysis: Analysis) -> tuple:
    """(start, stop) in seconds of the part of ``analysis``'s record that is split, checked."""
    if not analysis.settings.uncertainty:
        raise ValueError("split_halves compares the estimates against their σ: the settings must keep the uncertainty")
    t0 = analysis.settings.start or 0.0
    t1 = analysis.settings.stop if analysis.settings.stop is not None else analysis.y.shape[0] / analysis.fs
    if not t1 > t0:
        raise ValueError(f"stop must be after start; got start = {t0:g} s, stop = {t1:g} s")
    return t0, t1


def _run_halves(analysis: Analysis) -> tuple:
    """The two halves of ``analysis``'s record (within its ``start``/``stop`` window) run as
    :func:`split_halves` runs them: the first at ``analysis``'s settings, the second exactly as the
    first was identified. Returns the two run :class:`~modaluq.analysis.Analysis` (their diagrams
    and selections, for a closer look than the pairs) and the halves' (start, stop) in seconds.

    Raises
    ------
    ValueError
        A half too short for the settings (the error names the half).
    """
    t0, t1 = _window(analysis)
    mid = 0.5 * (t0 + t1)
    runs = []
    for k, (a, b) in enumerate(((t0, mid), (mid, t1))):
        half = analysis.with_settings(start=a, stop=b)
        if runs:  # the second half exactly as the first was identified
            half = half.identified_like(runs[0])
        try:
            runs.append(half.run(check_harmonics=False, issue_warnings=False))
        except ValueError as exc:
            raise ValueError(f"half {k + 1} ({a:g}-{b:g} s): {exc}") from None
    return runs, ((t0, mid), (mid, t1))


def split_halves(analysis: Analysis, *, max_frequency_difference: float = 0.02, min_mac: float = 0.8,
                 pair_within_std: float = 4.0) -> SplitHalves:
    """Identify the two halves of ``analysis``'s record (within its ``start``/``stop`` window) with
    the same settings, select the modes of each, pair them and compare (module docstring).

    The first half is identified as ``analysis`` says (automatic ``block_rows``, ``orders`` and
    ``n_blocks`` where not set, chosen for the half's length); the second with exactly the
    settings the first used. The two halves' modes are paired and compared by
    :func:`modaluq.comparison.compare_modes` with ``max_frequency_difference``, ``min_mac`` and
    ``pair_within_std`` (its docstring gives the rule; ``pair_within_std=0`` is the rule before
    2026-11-28, the relative window alone).

    Raises
    ------
    ValueError
        Settings without the uncertainty, a bad ``max_frequency_difference``, ``min_mac`` or
        ``pair_within_std``, or
        halves too short for the settings (the error names the half).
    """
    if not isinstance(analysis, Analysis):
        raise TypeError(f"analysis must be a modaluq.analysis.Analysis; got {type(analysis).__name__}")
    pairing = check_pairing(max_frequency_difference, min_mac, pair_within_std)  # before the halves run
    runs, halves_s = _run_halves(analysis)
    c = compare_modes(runs[0].selected, runs[1].selected, **pairing)
    used = runs[0].result.settings
    # each half's own factor: its core's count of blocks can differ from the other's by the remainder
    factor = [run.selected.interval_factor(0.95) for run in runs]
    return SplitHalves(**{f.name: getattr(c, f.name) for f in fields(ModeComparison)},
                       halves_s=halves_s, interval_factor_95=np.tile(factor, (c.frequency_hz.shape[0], 1)),
                       settings={k: used[k] for k in ("block_rows", "past_block_rows", "n_blocks")} | {
                           "orders": f"{min(used['orders'])}-{max(used['orders'])}"})
