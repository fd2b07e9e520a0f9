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

from dataclasses import dataclass

import numpy as np

from ..analysis import Analysis
from ..checks import check_boolean, check_integers, check_real
from ..indicators import mac_test, shape_covariance
from ..stabilization import modal_assurance_criterion

__all__ = ["PooledSplitHalves", "SplitHalves", "split_halves", "split_halves_windows"]

#: z within this of 0 counts as covered (the two-sided 95 % point of the normal).
Z_95 = 1.959963984540054


@dataclass(frozen=True)
class SplitHalves:
    """The modes found in both halves, their estimates, σ and z (one row per mode pair).

    ``halves_s`` are the two windows in seconds of the record; ``settings`` the horizons, orders and
    blocks both halves were identified with; ``unmatched_hz`` the frequencies (Hz) of the modes
    of each half without a partner; ``pairing`` the rule that paired them
    (``max_frequency_difference``, ``pair_within_std``, ``min_mac`` of :func:`split_halves`).
    """

    frequency_hz: np.ndarray        #: (n_pairs, 2), Hz
    frequency_std: np.ndarray       #: (n_pairs, 2), Hz
    damping_ratio: np.ndarray       #: (n_pairs, 2), fraction
    damping_std: np.ndarray         #: (n_pairs, 2), fraction
    mac: np.ndarray                 #: (n_pairs,), MAC of the two shapes
    halves_s: tuple
    settings: dict
    unmatched_hz: tuple
    #: (n_pairs,) z_MAC = (1 − MAC − E[1 − MAC]) / σ(1 − MAC) under "same mode", from both shapes'
    #: covariances (:func:`modaluq.indicators.mac_test`); NaN where a covariance is missing
    z_mac: np.ndarray = None
    #: (n_pairs,) p-value of the "same mode" test of the two shapes (NaN where not defined)
    mac_p_value: np.ndarray = None
    pairing: dict = None
    #: (n_pairs,) True where the two frequencies are farther apart than the relative window and the
    #: pair was made by the σ window alone (``pair_within_std``)
    by_std: np.ndarray = None

    def __post_init__(self):
        nan = np.full(len(self.mac), np.nan)
        for name in ("z_mac", "mac_p_value"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, nan.copy())
        if self.by_std is None:
            object.__setattr__(self, "by_std", np.zeros(len(self.mac), bool))

    @property
    def z_frequency(self) -> np.ndarray:
        return _z(self.frequency_hz, self.frequency_std)

    @property
    def z_damping(self) -> np.ndarray:
        return _z(self.damping_ratio, self.damping_std)

    def summary(self) -> dict:
        """``n_pairs``; ``rms_z_frequency``, ``rms_z_damping``, ``rms_z_mac`` (≈ 1 if σ is right); the
        share of |z| ≤ 1.96, ``within_frequency`` and ``within_damping`` (≈ 0.95); the share of
        pairs whose "same mode" test rejects at 5 %, ``same_mode_rejected`` (≈ 0.05); NaN without
        pairs; ``n_pairs_by_std``, the pairs made by the σ window alone."""
        out = {"n_pairs": int(len(self.mac)), "n_pairs_by_std": int(np.sum(self.by_std))}
        for name, z in (("frequency", self.z_frequency), ("damping", self.z_damping)):
            z = z[np.isfinite(z)]
            out[f"rms_z_{name}"] = float(np.sqrt(np.mean(z ** 2))) if z.size else float("nan")
            out[f"within_{name}"] = float(np.mean(np.abs(z) <= Z_95)) if z.size else float("nan")
        z = self.z_mac[np.isfinite(self.z_mac)]
        out["rms_z_mac"] = float(np.sqrt(np.mean(z ** 2))) if z.size else float("nan")
        p = self.mac_p_value[np.isfinite(self.mac_p_value)]
        out["same_mode_rejected"] = float(np.mean(p < 0.05)) if p.size else float("nan")
        return out

    def to_dataframe(self):
        """One row per mode pair: f, σ_f, ξ, σ_ξ of each half (suffix _1, _2), z of f and ξ, MAC."""
        import pandas as pd

        cols = {}
        for name, v in (("frequency_hz", self.frequency_hz), ("frequency_std", self.frequency_std),
                        ("damping_ratio", self.damping_ratio), ("damping_std", self.damping_std)):
            cols[f"{name}_1"], cols[f"{name}_2"] = v[:, 0], v[:, 1]
        cols.update(z_frequency=self.z_frequency, z_damping=self.z_damping, mac=self.mac, z_mac=self.z_mac,
                    mac_p_value=self.mac_p_value, paired_by_std=self.by_std)
        return pd.DataFrame(cols)

    def report(self) -> str:
        """A Markdown report: the windows, the settings, the table and the summary."""
        s = self.summary()
        (a0, a1), (b0, b1) = self.halves_s
        lines = [f"## Split halves: {a0:g}-{a1:g} s against {b0:g}-{b1:g} s", "",
                 "Settings of both halves: " + ", ".join(f"{k} {v}" for k, v in self.settings.items()), "",
                 *([self._pairing_line(), ""] if self.pairing else []),
                 "| f₁ (Hz) | f₂ (Hz) | σ_f₁, σ_f₂ (Hz) | z_f | ξ₁ (%) | ξ₂ (%) | σ_ξ₁, σ_ξ₂ (%) | z_ξ | MAC | z_MAC "
                 "| p (same mode) |",
                 "|---|---|---|---|---|---|---|---|---|---|---|"]
        zf, zx = self.z_frequency, self.z_damping
        for k in range(s["n_pairs"]):
            f, sf, x, sx = self.frequency_hz[k], self.frequency_std[k], self.damping_ratio[k], self.damping_std[k]
            mark = " (σ)" if self.by_std[k] else ""
            lines.append(f"| {f[0]:.4f} | {f[1]:.4f}{mark} | {sf[0]:.2g}, {sf[1]:.2g} | {zf[k]:+.2f} | "
                         f"{100 * x[0]:.2f} | {100 * x[1]:.2f} | {100 * sx[0]:.2g}, {100 * sx[1]:.2g} | "
                         f"{zx[k]:+.2f} | {self.mac[k]:.5f} | {self.z_mac[k]:+.2f} | {self.mac_p_value[k]:.2g} |")
        if s["n_pairs"]:
            modes = "mode" if s["n_pairs"] == 1 else "modes"
            lines += ["", f"{s['n_pairs']} {modes} in both halves: RMS z {s['rms_z_frequency']:.2f} (f), "
                          f"{s['rms_z_damping']:.2f} (ξ); within ±1.96: {100 * s['within_frequency']:.0f} % (f), "
                          f"{100 * s['within_damping']:.0f} % (ξ). Shapes: RMS z_MAC {s['rms_z_mac']:.2f}, \"same "
                          f"mode\" rejected at 5 % for {100 * s['same_mode_rejected']:.0f} % of the pairs. If σ is "
                          "right: RMS ≈ 1, about 95 % within, about 5 % rejected. With "
                          f"{s['n_pairs']} pair{'s' if s['n_pairs'] > 1 else ''}, an RMS z is known to about "
                          f"±{1 / np.sqrt(2 * s['n_pairs']):.2f} (a handful of modes only says whether σ is grossly "
                          "off)."]
            if s["n_pairs_by_std"]:
                lines.append(f"(σ): {s['n_pairs_by_std']} pair(s) farther apart than the relative window, paired by "
                             "their combined σ_f alone (the only candidate of each other).")
        else:
            lines += ["", "No mode was found in both halves (within the frequency difference and MAC asked): "
                          "nothing to compare."]
        for k, hz in enumerate(self.unmatched_hz):
            if len(hz):
                lines.append(f"Half {k + 1} only: " + ", ".join(f"{v:.4g}" for v in hz) + " Hz.")
        if any(len(hz) for hz in self.unmatched_hz):
            lines.append("(Unpaired: no mode of the other half near enough in frequency with MAC ≥ the pairing's, "
                         "or, beyond the relative window, more than one candidate.)")
        return "\n".join(lines) + "\n"

    def _pairing_line(self) -> str:
        p = self.pairing
        within = (f" or, where unambiguous, by at most {p['pair_within_std']:g} combined σ_f"
                  if p["pair_within_std"] > 0 else "")
        return (f"Pairs: frequencies apart by at most {100 * p['max_frequency_difference']:g} %{within}, "
                f"MAC ≥ {p['min_mac']:g}, nearest first, one to one.")


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
            return SplitHalves(empty2, empty2, empty2, empty2, empty, halves_s=(), settings={}, unmatched_hz=((), ()))

        def cat(name):
            return np.concatenate([getattr(c, name) for c in chosen])

        return SplitHalves(
            frequency_hz=cat("frequency_hz"), frequency_std=cat("frequency_std"), damping_ratio=cat("damping_ratio"),
            damping_std=cat("damping_std"), mac=cat("mac"), halves_s=tuple(c.halves_s for c in chosen),
            settings={}, unmatched_hz=tuple(np.concatenate([c.unmatched_hz[k] for c in chosen]) for k in (0, 1)),
            z_mac=cat("z_mac"), mac_p_value=cat("mac_p_value"), pairing=chosen[0].pairing, by_std=cat("by_std"))

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
                 "| windows | pairs | RMS z f, ξ (± about) | within ±1.96 f, ξ | RMS z_MAC, \"same mode\" rejected |",
                 "|---|---|---|---|---|"]
        for label, n in [*((f"{n}", n) for n in self.levels), ("**all**", None)]:
            s = self.pooled(n).summary()
            if not s["n_pairs"]:
                lines.append(f"| {label} | 0 | — | — | — |")
                continue
            lines.append(f"| {label} | {s['n_pairs']} | {s['rms_z_frequency']:.2f}, {s['rms_z_damping']:.2f} "
                         f"(±{1 / np.sqrt(2 * s['n_pairs']):.2f}) | "
                         f"{100 * s['within_frequency']:.0f} %, {100 * s['within_damping']:.0f} % | "
                         f"{s['rms_z_mac']:.2f}, {100 * s['same_mode_rejected']:.0f} % |")
        for level in self.levels:  # a few failures each; beyond three, the first and a count
            mine = [f for f in self.failed if f[0] == level]
            for n, k, (a, b), message in mine[:1] if len(mine) > 3 else mine:
                lines.append(f"\nWindow {k + 1} of {n} ({a:g}-{b:g} s) failed: {message}")
            if len(mine) > 3:
                lines.append(f"... and {len(mine) - 1} more of the {level} windows failed (`failed` lists them).")
        text = "\n".join(lines) + "\n"
        return text + "".join("\n" + c.report() for _, _, c in self.checks)


def split_halves_windows(analysis: Analysis, windows=(1, 2, 4, 8), *, progress: bool = False,
                         **pairing) -> PooledSplitHalves:
    """:func:`split_halves` on each of n consecutive, non-overlapping windows of ``analysis``'s
    record (its ``start``/``stop`` window), for every n of ``windows``, so that one record gives
    many mode pairs (docs/validation.md "Pooled over windows of several lengths"): with the
    default (1, 2, 4, 8) a record is split at four lengths, its halves from T/2 down to T/16.
    Every window chooses its automatic settings on its own first half, as :func:`split_halves`
    does. A window too short for them is recorded in ``failed`` and the others go on.
    ``pairing`` are :func:`split_halves`' keywords (``max_frequency_difference``, ``min_mac``,
    ``pair_within_std``); ``progress`` shows a progress bar of the windows (on stderr).

    Raises
    ------
    ValueError
        Bad ``windows`` (integers ≥ 1) or pairing keywords, or settings without the uncertainty.
    """
    if not isinstance(analysis, Analysis):
        raise TypeError(f"analysis must be a modaluq.analysis.Analysis; got {type(analysis).__name__}")
    levels = sorted(set(check_integers("windows", windows, minimum=1)))
    progress = check_boolean("progress", progress)
    limits = {"max_frequency_difference": dict(low=0.0, low_open=True), "min_mac": dict(low=0.0, high=1.0),
              "pair_within_std": dict(low=0.0)}  # as split_halves checks them, before any window runs
    unknown = set(pairing) - set(limits)
    if unknown:
        raise TypeError(f"split_halves_windows got unexpected keyword(s) {sorted(unknown)}")
    for name, value in pairing.items():
        check_real(name, value, **limits[name])
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


def _z(values: np.ndarray, stds: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return (values[:, 0] - values[:, 1]) / np.sqrt(stds[:, 0] ** 2 + stds[:, 1] ** 2)


def split_halves(analysis: Analysis, *, max_frequency_difference: float = 0.02, min_mac: float = 0.8,
                 pair_within_std: float = 4.0) -> SplitHalves:
    """Identify the two halves of ``analysis``'s record (within its ``start``/``stop`` window) with
    the same settings, select the modes of each, pair them and compare (module docstring).

    The first half is identified as ``analysis`` says (automatic ``block_rows``, ``orders`` and
    ``n_blocks`` where not set, chosen for the half's length); the second with exactly the
    settings the first used. A mode of one half pairs with the mode of the other nearest in
    frequency, one to one, when their shapes have MAC ≥ ``min_mac`` and the two frequencies differ
    by at most ``max_frequency_difference`` (a fraction); then, among the modes left, a mode pairs
    with one whose frequency differs by at most ``pair_within_std`` combined standard deviations
    √(σ_f₁² + σ_f₂²) when each is the other's only candidate (``SplitHalves.by_std``).

    Why the second bound: a fixed relative window alone truncates z_f. Two estimates of a broad
    mode from short halves, whose combined σ_f is above 1 % of f, could never give |z_f| > 2 and
    would make σ look too large. With the default 4, such a pair is cut off only beyond |z| = 4
    (probability 6·10⁻⁵ if σ is right). Only where unambiguous, because a broad mode's σ window
    can hold several modes of the other half alike in shape. 0 pairs by
    ``max_frequency_difference`` alone (the rule before 2026-11-28).

    Raises
    ------
    ValueError
        Settings without the uncertainty, a bad ``max_frequency_difference``, ``min_mac`` or
        ``pair_within_std``, or
        halves too short for the settings (the error names the half).
    """
    if not isinstance(analysis, Analysis):
        raise TypeError(f"analysis must be a modaluq.analysis.Analysis; got {type(analysis).__name__}")
    tol = check_real("max_frequency_difference", max_frequency_difference, low=0.0, low_open=True)
    min_mac = check_real("min_mac", min_mac, low=0.0, high=1.0)
    within_std = check_real("pair_within_std", pair_within_std, low=0.0)
    t0, t1 = _window(analysis)
    mid = 0.5 * (t0 + t1)
    runs = []
    for k, (a, b) in enumerate(((t0, mid), (mid, t1))):
        half = analysis.with_settings(start=a, stop=b)
        if runs:  # the second half exactly as the first was identified
            used = runs[0].result.settings
            half = half.with_settings(block_rows=used["block_rows"], past_block_rows=used["past_block_rows"],
                                      orders=used["orders"], n_blocks=used["n_blocks"])
        try:
            runs.append(half.run(check_harmonics=False, issue_warnings=False))
        except ValueError as exc:
            raise ValueError(f"half {k + 1} ({a:g}-{b:g} s): {exc}") from None
    s1, s2 = runs[0].selected, runs[1].selected
    paired = _pair(s1, s2, tol, min_mac, within_std)
    pairs = [(a, b) for a, b, _ in paired]
    i1 = np.array([p[0] for p in pairs], int)
    i2 = np.array([p[1] for p in pairs], int)

    def both(name):
        return np.column_stack([np.asarray(getattr(s1, name), float)[i1], np.asarray(getattr(s2, name), float)[i2]])

    tests = [_shape_test(s1, a, s2, b) for a, b in pairs]
    used = runs[0].result.settings
    return SplitHalves(
        frequency_hz=both("frequency_hz"), frequency_std=both("frequency_std"),
        damping_ratio=both("damping_ratio"), damping_std=both("damping_std"),
        mac=np.array([float(modal_assurance_criterion(s1.mode_shape[:, a], s2.mode_shape[:, b])[0, 0])
                      for a, b in pairs]),
        halves_s=((t0, mid), (mid, t1)),
        settings={k: used[k] for k in ("block_rows", "past_block_rows", "n_blocks")} | {
            "orders": f"{min(used['orders'])}-{max(used['orders'])}"},
        unmatched_hz=(np.delete(np.asarray(s1.frequency_hz, float), i1),
                      np.delete(np.asarray(s2.frequency_hz, float), i2)),
        z_mac=np.array([t[0] for t in tests], float), mac_p_value=np.array([t[1] for t in tests], float),
        pairing={"max_frequency_difference": tol, "pair_within_std": within_std, "min_mac": min_mac},
        by_std=np.array([p[2] for p in paired], bool))


def _shape_test(s1, a: int, s2, b: int) -> tuple:
    """(z_MAC, p-value) of the "same mode" test of mode ``a`` of ``s1`` against mode ``b`` of ``s2``."""
    c1, c2 = getattr(s1, "mode_covariance", None), getattr(s2, "mode_covariance", None)
    if c1 is None or c2 is None:
        return float("nan"), float("nan")
    t = mac_test(s1.mode_shape[:, a], s2.mode_shape[:, b], shape_covariance(c1[a]), shape_covariance(c2[b]))
    with np.errstate(invalid="ignore", divide="ignore"):
        z = (1.0 - t.mac - t.loss_mean) / t.loss_std if t.loss_std > 0 else float("nan")
    return float(z), t.p_value


def _pair(s1, s2, tol: float, min_mac: float, within_std: float) -> list:
    """One-to-one pairs (i, j, by_std) of modes of s1 and s2 (:func:`split_halves`).

    First the pairs within the relative window, nearest relative frequency first. Then a pair
    within ``within_std`` combined σ_f only (``by_std`` True), and only where it is unambiguous:
    neither mode has another candidate in the other half. A broad mode's σ window can hold several
    modes of the other half, all alike in shape on a tower or a beam; choosing among them would
    pair wrongly as often as not.
    """
    f1, f2 = np.asarray(s1.frequency_hz, float), np.asarray(s2.frequency_hz, float)
    sf1, sf2 = np.asarray(s1.frequency_std, float), np.asarray(s2.frequency_std, float)
    if not (f1.size and f2.size):
        return []
    mac = modal_assurance_criterion(s1.mode_shape, s2.mode_shape)
    d = np.abs(f1[:, None] - f2[None, :]) / np.maximum(f1[:, None], f2[None, :])
    combined = np.hypot(sf1[:, None], sf2[None, :])
    with np.errstate(invalid="ignore"):  # a NaN or infinite σ pairs by the window only
        by_std = np.isfinite(combined) & (np.abs(f1[:, None] - f2[None, :]) <= within_std * combined)
    shape_ok = mac >= min_mac
    in_window = (d <= tol) & shape_ok
    candidate = in_window | (by_std & shape_ok)
    used1, used2, out = set(), set(), []
    for _, i, j in sorted((d[i, j], i, j) for i, j in zip(*np.nonzero(in_window))):
        if i not in used1 and j not in used2:
            used1.add(i)
            used2.add(j)
            out.append((int(i), int(j), False))
    for i, j in zip(*np.nonzero(candidate & ~in_window)):
        if i not in used1 and j not in used2 and candidate[i].sum() == 1 and candidate[:, j].sum() == 1:
            used1.add(i)
            used2.add(j)
            out.append((int(i), int(j), True))
    return sorted(out)
