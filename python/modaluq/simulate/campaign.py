"""A simulated multi-setup campaign on a bridge deck (issue 23; docs/uq-math.md §13).

The structure is a simply supported deck of span L with two instrumented edges (left,
right), 12 stations per edge at x = s L/13 (s = 1 … 12): **24 vertical DOFs**, named
``"L1" … "L12", "R1" … "R12"``.  Its first six modes are bending (B) and torsion (T) modes of
a deck strip, with exact shapes

    B_k(x, side) = sin(kπx/L),     T_k(x, side) = ±sin(kπx/L)  (+ left, − right),

frequencies B1 1.20, T1 2.55, B2 4.30, T2 5.10, T3 7.65, B3 9.40 Hz and damping ratios
1.5, 1.2, 1.8, 1.4, 2.0, 1.6 %.  The response is the modal superposition of these six modes
(unit modal masses; higher modes are not part of the model), so the true model order is 12.

Each mode is the exactly ZOH-sampled single-DOF oscillator of :func:`acceleration_response`
driven by the modal force φ_kᵀ w, with w the nodal forces: unmeasured white forces at every
DOF, plus, optionally, known (measured) white forces at ``input_dofs``.  The outputs are
accelerations (feedthrough included) with white sensor noise of ``noise_std`` times each
noise-free channel's std.

The campaign (default): references L3 and R8 in every setup; the other 22 DOFs roved in six
setups of 4, 4, 4, 4, 3, 3 DOFs (6 or 5 sensors per setup), with different durations and a
different ambient level in each setup (the unmeasured forces are scaled by a factor drawn
uniformly in [1/(1+s), 1+s], s = ``excitation_spread``), as on a real bridge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..checks import check_real, check_sampling_frequency
from ._chain import acceleration_response

__all__ = ["CampaignSetup", "SimulatedCampaign", "deck_modes", "simulate_campaign",
           "DECK_DOFS", "DEFAULT_REFERENCES", "DEFAULT_ROVING"]

#: The 24 DOF names: left edge stations 1..12, then right edge stations 1..12.
DECK_DOFS = tuple([f"L{s}" for s in range(1, 13)] + [f"R{s}" for s in range(1, 13)])
#: Reference DOFs, measured in every setup.
DEFAULT_REFERENCES = ("L3", "R8")
#: Roving DOFs per setup (the 22 non-reference DOFs in six groups).
DEFAULT_ROVING = (("L1", "L2", "L4", "L5"), ("L6", "L7", "L8", "L9"), ("L10", "L11", "L12", "R1"),
                  ("R2", "R3", "R4", "R5"), ("R6", "R7", "R9"), ("R10", "R11", "R12"))
#: Durations (s) of the default setups.
DEFAULT_DURATIONS = (600.0, 720.0, 540.0, 660.0, 480.0, 600.0)

_FREQ = np.array([1.20, 2.55, 4.30, 5.10, 7.65, 9.40])
_DAMP = np.array([0.015, 0.012, 0.018, 0.014, 0.020, 0.016])
_KIND = (("B", 1), ("T", 1), ("B", 2), ("T", 2), ("T", 3), ("B", 3))


def deck_modes():
    """True modes of the deck: (frequency_hz (6,), damping_ratio (6,), shapes (24, 6) real,
    unit-norm columns over the 24 DOFs of :data:`DECK_DOFS`, mode names)."""
    x = np.arange(1, 13) / 13.0
    cols = []
    for kind, k in _KIND:
        s = np.sin(k * np.pi * x)
        cols.append(np.concatenate([s, s if kind == "B" else -s]))
    Phi = np.column_stack(cols)
    Phi /= np.linalg.norm(Phi, axis=0)
    return _FREQ.copy(), _DAMP.copy(), Phi, tuple(f"{kind}{k}" for kind, k in _KIND)


@dataclass(frozen=True, eq=False)
class CampaignSetup:
    """One setup: ``y`` (n_samples, n_channels) accelerations, ``u`` (n_samples, n_inputs)
    measured forces or None, ``channels`` (the DOF name of each column of y) and
    ``references`` (the column of each reference, in :data:`DEFAULT_REFERENCES` order)."""

    y: np.ndarray
    u: np.ndarray | None
    channels: tuple
    references: tuple


@dataclass(frozen=True, eq=False)
class SimulatedCampaign:
    """Setups plus the truth: ``frequency_hz``, ``damping_ratio`` (n_modes,), ``mode_shape``
    (24, n_modes) real (unit norm, over :data:`DECK_DOFS`), ``mode_names``, ``fs`` (Hz)."""

    setups: tuple
    fs: float
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    mode_shape: np.ndarray
    mode_names: tuple
    dofs: tuple = DECK_DOFS

    def frames(self, input_names=()) -> list:
        """Each setup as a pandas DataFrame, what :func:`modaluq.identify_setups` takes: one column
        per channel named by its DOF, then the measured forces named ``input_names`` (one name
        per input; none by default, so a setup is output-only)."""
        import pandas as pd

        out = []
        for s in self.setups:
            df = pd.DataFrame(s.y, columns=list(s.channels))
            for k, name in enumerate(input_names):
                df[name] = s.u[:, k]
            out.append(df)
        return out


def simulate_campaign(seed=None, *, durations=DEFAULT_DURATIONS, roving=DEFAULT_ROVING,
                      references=DEFAULT_REFERENCES, fs=25.0, input_dofs=(), input_std=1.0,
                      unknown_input_std=1.0, noise_std=0.05, excitation_spread=0.5,
                      discard=1000):
    """Simulate one campaign (module docstring).

    ``durations`` (s) and ``roving`` (DOF names) are per setup; ``input_dofs`` (DOF names)
    carry known white forces of std ``input_std`` N, measured in every setup (input/output);
    the unmeasured forces at every DOF have std ``unknown_input_std`` N times the setup's
    ambient factor.  Returns a :class:`SimulatedCampaign`.
    """
    fs = check_sampling_frequency(fs)
    noise_std = check_real("noise_std", noise_std, low=0.0)
    excitation_spread = check_real("excitation_spread", excitation_spread, low=0.0)
    if len(durations) != len(roving):
        raise ValueError(f"durations has {len(durations)} entries but roving has {len(roving)} setups")
    names = {n: i for i, n in enumerate(DECK_DOFS)}
    for n in list(references) + [d for grp in roving for d in grp] + list(input_dofs):
        if n not in names:
            raise ValueError(f"unknown DOF name {n!r} (valid: {', '.join(DECK_DOFS)})")
    freq, damp, Phi, mode_names = deck_modes()
    omega = 2 * np.pi * freq
    nm = len(freq)
    Mm, Km, Cm = np.eye(nm), np.diag(omega ** 2), np.diag(2 * damp * omega)
    rng = np.random.default_rng(seed)
    in_idx = [names[n] for n in input_dofs]
    setups = []
    for dur, grp in zip(durations, roving):
        n = int(round(dur * fs))
        total = n + int(discard)
        level = np.exp(rng.uniform(-1, 1) * np.log1p(excitation_spread))
        w = rng.standard_normal((total, len(DECK_DOFS))) * (unknown_input_std * level)
        u = None
        if in_idx:
            u = rng.standard_normal((total, len(in_idx))) * input_std
            w[:, in_idx] += u
        eta_dd = acceleration_response(w @ Phi, Mm, Km, Cm, fs=fs, output_dofs=range(nm))
        chans = tuple(references) + tuple(grp)
        rows = [names[c] for c in chans]
        y = eta_dd[discard:] @ Phi[rows].T
        y = y + noise_std * y.std(axis=0) * rng.standard_normal(y.shape)
        setups.append(CampaignSetup(y=np.ascontiguousarray(y),
                                    u=None if u is None else np.ascontiguousarray(u[discard:]),
                                    channels=chans, references=tuple(range(len(references)))))
    return SimulatedCampaign(setups=tuple(setups), fs=fs, frequency_hz=freq, damping_ratio=damp,
                             mode_shape=Phi, mode_names=mode_names)
