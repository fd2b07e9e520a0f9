"""Two sets of selected modes compared against their σ: is a difference a change or noise?

:func:`compare_modes` pairs the modes of two results (two records, two days, before and after a
repair) and gives, per mode found in both, z = (x₁ − x₂) / √(σ₁² + σ₂²) for the frequency and the
damping ratio, and the "same mode" test of the two shapes (:func:`modaluq.indicators.mac_test`).
If nothing changed but the noise and σ is right, each z is standard normal: |z| > 1.96 for about
5 % of the modes, so with six modes at least one such z comes by chance a quarter of the time
(1 − 0.95⁶). A larger |z| says the difference is more than the estimation error of two records.
That is a change of the structure **or of its conditions** (temperature moves a bridge's
frequencies by several σ from day to day), or of the identification (identify both records with
the same settings), or two close modes paired crosswise, or a σ that is too small (check it on a
record with :func:`modaluq.validation.split_halves`). Compare records of alike conditions, or use
:mod:`modaluq.monitoring`, which learns the conditions' scatter from a reference period.

    >>> import modaluq
    >>> from modaluq.simulate import simulate
    >>> a, b = (modaluq.identify(simulate(20_000, seed=s).y, fs=50, frequency_range=(1, 20)).select_modes()
    ...         for s in (1, 2))
    >>> c = compare_modes(a, b)                    # two records of one structure: noise only
    >>> c.summary()["n_pairs"] >= 5 and bool(abs(c.z_frequency).max() < 4)
    True

The split-halves check of σ (:func:`modaluq.validation.split_halves`) is this comparison of the
two halves of one record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import check_real
from .indicators import mac_test, shape_covariance
from .selection import SelectedModes
from .stabilization import modal_assurance_criterion

__all__ = ["ModeComparison", "Z_95", "check_pairing", "compare_modes"]

#: z within this of 0 counts as covered (the two-sided 95 % point of the normal).
Z_95 = 1.959963984540054


@dataclass(frozen=True)
class ModeComparison:
    """The modes found in both sets, their estimates, σ and z (one row per mode pair; column 0 the
    first set, column 1 the second).

    ``unmatched_hz`` are the frequencies (Hz) of the modes of each set without a partner;
    ``pairing`` the rule that paired them (``max_frequency_difference``, ``pair_within_std``,
    ``min_mac`` of :func:`compare_modes`).
    """

    frequency_hz: np.ndarray        #: (n_pairs, 2), Hz
    frequency_std: np.ndarray       #: (n_pairs, 2), Hz
    damping_ratio: np.ndarray       #: (n_pairs, 2), fraction
    damping_std: np.ndarray         #: (n_pairs, 2), fraction
    mac: np.ndarray                 #: (n_pairs,), MAC of the two shapes
    unmatched_hz: tuple = ((), ())
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
            out[f"rms_z_{name}"], out[f"within_{name}"] = rms_and_within(z)
        out["rms_z_mac"] = rms_and_within(self.z_mac)[0]
        p = self.mac_p_value[np.isfinite(self.mac_p_value)]
        out["same_mode_rejected"] = float(np.mean(p < 0.05)) if p.size else float("nan")
        return out

    def to_dataframe(self):
        """One row per mode pair: f, σ_f, ξ, σ_ξ of each set (suffix _1, _2), z of f and ξ, MAC, z_MAC,
        the "same mode" p-value and whether the pair was made by σ alone."""
        import pandas as pd

        cols = {}
        for name, v in (("frequency_hz", self.frequency_hz), ("frequency_std", self.frequency_std),
                        ("damping_ratio", self.damping_ratio), ("damping_std", self.damping_std)):
            cols[f"{name}_1"], cols[f"{name}_2"] = v[:, 0], v[:, 1]
        cols.update(z_frequency=self.z_frequency, z_damping=self.z_damping, mac=self.mac, z_mac=self.z_mac,
                    mac_p_value=self.mac_p_value, paired_by_std=self.by_std)
        return pd.DataFrame(cols)

    def report(self) -> str:
        """A Markdown report: the pairing rule, the table, the summary and the unpaired modes."""
        return "\n".join(["## Modes compared", "", *self._body()]) + "\n"

    def _body(self, what: str = "set", both: str = "both sets", hypothesis: str = "nothing but the noise changed "
              "and σ is right", note: str = "") -> list:
        """The report's lines after its heading; ``what`` names one side ("set", "half")."""
        s = self.summary()
        lines = [*([self._pairing_line(), ""] if self.pairing else []),
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
            lines += ["", f"{s['n_pairs']} {modes} in {both}: RMS z {s['rms_z_frequency']:.2f} (f), "
                          f"{s['rms_z_damping']:.2f} (ξ); within ±1.96: {100 * s['within_frequency']:.0f} % (f), "
                          f"{100 * s['within_damping']:.0f} % (ξ). Shapes: RMS z_MAC {s['rms_z_mac']:.2f}, \"same "
                          f"mode\" rejected at 5 % for {100 * s['same_mode_rejected']:.0f} % of the pairs. If "
                          f"{hypothesis}: RMS ≈ 1, about 95 % within, about 5 % rejected. With "
                          f"{s['n_pairs']} pair{'s' if s['n_pairs'] > 1 else ''}, an RMS z is known to about "
                          f"±{1 / np.sqrt(2 * s['n_pairs']):.2f}{note}."]
            if s["n_pairs_by_std"]:
                lines.append(f"(σ): {s['n_pairs_by_std']} pair(s) farther apart than the relative window, paired by "
                             "their combined σ_f alone (the only candidate of each other).")
        else:
            lines += ["", f"No mode was found in {both} (within the frequency difference and MAC asked): "
                          "nothing to compare."]
        for k, hz in enumerate(self.unmatched_hz):
            if len(hz):
                lines.append(f"{what.capitalize()} {k + 1} only: " + ", ".join(f"{v:.4g}" for v in hz) + " Hz.")
        if any(len(hz) for hz in self.unmatched_hz):
            lines.append(f"(Unpaired: no mode of the other {what} near enough in frequency with MAC ≥ the pairing's, "
                         "or, beyond the relative window, more than one candidate.)")
        return lines

    def _pairing_line(self) -> str:
        p = self.pairing
        within = (f" or, where unambiguous, by at most {p['pair_within_std']:g} combined σ_f"
                  if p["pair_within_std"] > 0 else "")
        return (f"Pairs: frequencies apart by at most {100 * p['max_frequency_difference']:g} %{within}, "
                f"MAC ≥ {p['min_mac']:g}, nearest first, one to one.")


def compare_modes(first, second, *, max_frequency_difference: float = 0.02, min_mac: float = 0.8,
                  pair_within_std: float = 4.0) -> ModeComparison:
    """Pair the selected modes of ``first`` and ``second`` and compare each pair against its σ.

    ``first`` and ``second`` are :class:`~modaluq.selection.SelectedModes` of the same channels,
    identified with the uncertainty (or a result with ``select_modes()``, whose default selection
    is taken, or an :class:`~modaluq.analysis.Analysis` that was run). A mode of one pairs with the
    mode of the other nearest in frequency, one to one, when their shapes have MAC ≥ ``min_mac``
    and the two frequencies differ by at most ``max_frequency_difference`` (a fraction); then,
    among the modes left, a mode pairs with one whose frequency differs by at most
    ``pair_within_std`` combined standard deviations √(σ_f₁² + σ_f₂²) when each is the other's
    only candidate (``ModeComparison.by_std``). A mode that moved more than the window and its σ
    allow is listed unpaired in both sets (``unmatched_hz``), itself a sign of a change; widen
    ``max_frequency_difference`` to pair it, at the price of wrong pairs where modes are dense (on
    the wind turbine record, 5 % pairs a 4.19 Hz rotor line with a 4.01 Hz one, MAC 0.80).

    Why the second bound: a fixed relative window alone truncates z_f. Two estimates of a broad
    mode whose combined σ_f is above 1 % of f could never give |z_f| > 2. With the default 4, such
    a pair is cut off only beyond |z| = 4 (probability 6·10⁻⁵ if σ is right). Only where
    unambiguous, because a broad mode's σ window can hold several modes of the other set alike in
    shape. 0 pairs by ``max_frequency_difference`` alone.

    Raises
    ------
    ValueError
        A bad ``max_frequency_difference``, ``min_mac`` or ``pair_within_std``; shapes of other
        channels (count or names); modes without σ (identified with ``uncertainty=False``).
    TypeError
        ``first`` or ``second`` not selected modes.
    """
    pairing = check_pairing(max_frequency_difference, min_mac, pair_within_std)
    s1, s2 = (_selected(name, s) for name, s in (("first", first), ("second", second)))
    if s1.mode_shape.shape[0] != s2.mode_shape.shape[0]:
        raise ValueError(f"first and second must have shapes of one set of channels; got {s1.mode_shape.shape[0]} "
                         f"and {s2.mode_shape.shape[0]} channels")
    names = [tuple(getattr(s, "output_names", None) or ()) for s in (s1, s2)]
    if all(names) and names[0] != names[1]:
        raise ValueError(f"first and second must have shapes of one set of channels; got {list(names[0])} and "
                         f"{list(names[1])}")
    paired = _pair(s1, s2, pairing["max_frequency_difference"], pairing["min_mac"], pairing["pair_within_std"])
    i1 = np.array([p[0] for p in paired], int)
    i2 = np.array([p[1] for p in paired], int)

    def both(name):
        return np.column_stack([np.asarray(getattr(s1, name), float)[i1], np.asarray(getattr(s2, name), float)[i2]])

    tests = [_shape_test(s1, a, s2, b) for a, b, _ in paired]
    return ModeComparison(
        frequency_hz=both("frequency_hz"), frequency_std=both("frequency_std"),
        damping_ratio=both("damping_ratio"), damping_std=both("damping_std"),
        mac=np.array([float(modal_assurance_criterion(s1.mode_shape[:, a], s2.mode_shape[:, b])[0, 0])
                      for a, b, _ in paired]),
        unmatched_hz=(np.delete(np.asarray(s1.frequency_hz, float), i1),
                      np.delete(np.asarray(s2.frequency_hz, float), i2)),
        z_mac=np.array([t[0] for t in tests], float), mac_p_value=np.array([t[1] for t in tests], float),
        pairing=pairing,
        by_std=np.array([p[2] for p in paired], bool))


def check_pairing(max_frequency_difference, min_mac, pair_within_std) -> dict:
    """The pairing of :func:`compare_modes`, checked (an error names the parameter), as the dict
    ``ModeComparison.pairing`` holds; callers that identify first check it before they do."""
    return {"max_frequency_difference": check_real("max_frequency_difference", max_frequency_difference, low=0.0,
                                                   low_open=True),
            "min_mac": check_real("min_mac", min_mac, low=0.0, high=1.0),
            "pair_within_std": check_real("pair_within_std", pair_within_std, low=0.0)}


def _selected(name: str, modes) -> SelectedModes:
    """Selected modes: given, a result's default selection, or a run Analysis's."""
    if isinstance(getattr(modes, "selected", None), SelectedModes):
        modes = modes.selected
    elif not isinstance(modes, SelectedModes) and callable(getattr(modes, "select_modes", None)):
        modes = modes.select_modes()
    if not isinstance(modes, SelectedModes):
        raise TypeError(f"{name} must be selected modes (SelectedModes, a result with select_modes(), or an Analysis "
                        f"that was run); got {type(modes).__name__}")
    if modes.n_modes and not np.any(np.isfinite(modes.frequency_std)):
        raise ValueError(f"{name} has no σ (identified with uncertainty=False): nothing to compare against")
    return modes


def rms_and_within(z: np.ndarray) -> tuple:
    """(RMS of the finite z, their share with |z| ≤ 1.96); NaN, NaN without any."""
    z = np.ravel(z)
    z = z[np.isfinite(z)]
    if not z.size:
        return float("nan"), float("nan")
    return float(np.sqrt(np.mean(z ** 2))), float(np.mean(np.abs(z) <= Z_95))


def _z(values: np.ndarray, stds: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return (values[:, 0] - values[:, 1]) / np.sqrt(stds[:, 0] ** 2 + stds[:, 1] ** 2)


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
    """One-to-one pairs (i, j, by_std) of modes of s1 and s2 (:func:`compare_modes`).

    First the pairs within the relative window, nearest relative frequency first. Then a pair
    within ``within_std`` combined σ_f only (``by_std`` True), and only where it is unambiguous:
    neither mode has another candidate in the other set. A broad mode's σ window can hold several
    modes of the other set, all alike in shape on a tower or a beam; choosing among them would
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
