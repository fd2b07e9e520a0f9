"""Simulated vibration data: the damped mass-spring chain of the paper's §5.1.

The reference test case (docs/uq-math.md §11.1; Mellinger, Döhler & Mevel, §5.1) is a
chain of six masses fixed to the ground at one end and free at the other::

    ground --k1-- m1 --k2-- m2 --k3-- m3 --k4-- m4 --k5-- m5 --k6-- m6

with m_i = 1/20, k1 = k3 = k5 = 100, k2 = k4 = k6 = 200 and 2 % modal damping on every
mode.  It is sampled at 50 Hz with a zero-order hold on all nodal forces; the outputs are
the accelerations of masses 1, 2 and 5 (0-based DOFs 0, 1, 4), the known input is a white
Gaussian force on mass 1 and unknown white forces act on every mass.

Model (paper Eq. 1-4), with state x = [q'; q] (velocities first, then displacements):

    A_c = [[-M^-1 C, -M^-1 K], [I, 0]],   B_c = [[M^-1], [0]]   (all n_dof nodal forces)
    [A, B] = top rows of expm([[A_c, B_c], [0, 0]] tau)          (exact zero-order hold)
    C = L_a [-M^-1 C, -M^-1 K],            D = L_a M^-1          (accelerations)
    x_{k+1} = A x_k + B w_k,               y_k = C x_k + D w_k

where w_k is the total nodal force held constant over [k tau, (k+1) tau).

The time response is computed in modal coordinates with :func:`scipy.signal.lfilter`
(a compiled loop), which is exact to rounding (tested against the plain recursion) and
needs no Python loop over samples.  With classical (e.g. modal) damping each mode is a
single-DOF oscillator whose ZOH-sampled transfer function from modal force to modal
acceleration is a real second-order filter; otherwise the complex modes of A are used,
z_{k+1} = lambda z_k + g_k with y = 2 Re(C V z) + D w (one mode per conjugate pair).
:func:`simulate` of 10^6 samples takes about 0.3 s, half of it drawing the 10^7 random
numbers.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..checks import check_integer, check_real, check_sampling_frequency
from ._chain import (
    CHUNK_SAMPLES,
    ModalPlan,
    acceleration_response,
    chain_system,
    dof_tuple,
    modal_parameters,
    state_space,
)

__all__ = [
    "Simulation",
    "acceleration_response",
    "chain_system",
    "default_output_dofs",
    "modal_parameters",
    "simulate",
    "state_space",
]

#: Paper's sensor positions for the 6-DOF chain (masses 1, 2 and 5), 0-based.
PAPER_OUTPUT_DOFS = (0, 1, 4)



def default_output_dofs(n_dof):
    """Default sensor DOFs (0-based) for a chain of ``n_dof`` masses.

    * ``n_dof == 6``: ``(0, 1, 4)``, the paper's masses 1, 2 and 5.
    * otherwise: ``ceil(2 n_dof / 3)`` DOFs evenly spread from the first (the default
      input DOF) to the last (the free end), ``floor(linspace(0, n_dof-1, n) + 0.5)``;
      e.g. 20 DOFs for ``n_dof=30``, ``(0, 2)`` for ``n_dof=3``, ``(0,)`` for ``n_dof=1``.

    Examples
    --------
    >>> default_output_dofs(6)
    (0, 1, 4)
    >>> default_output_dofs(10)
    (0, 2, 3, 5, 6, 8, 9)
    """
    n_dof = check_integer("n_dof", n_dof, minimum=1)
    if n_dof == 6:
        return PAPER_OUTPUT_DOFS
    n_out = min(n_dof, math.ceil(2 * n_dof / 3))
    if n_out == 1:
        return (0,)
    pos = np.floor(np.linspace(0.0, n_dof - 1, n_out) + 0.5).astype(int)
    return tuple(int(p) for p in pos)


# ---------------------------------------------------------------------------- simulate


@dataclass(frozen=True, repr=False, eq=False)
class Simulation:
    """One simulated input/output record with the true modal parameters.

    Attributes
    ----------
    y : ndarray, (n_samples, n_outputs), float64, C-contiguous
        Acceleration outputs (m/s^2) including sensor noise.
    u : ndarray, (n_samples, n_inputs), float64, C-contiguous
        Known input force(s) in N, aligned sample by sample with ``y``.
    fs : float
        Sampling frequency in Hz.
    frequency_hz : ndarray, (n_modes,)
        True natural frequencies ``|mu|/(2 pi)`` of the continuous damped system,
        ascending (equal to the undamped frequencies for modal damping).
    damping_ratio : ndarray, (n_modes,)
        True damping ratios ``-Re(mu)/|mu|`` (fraction).
    mode_shape : ndarray, (n_outputs, n_modes), complex
        True mode shapes at the output DOFs, each column scaled so that its
        largest-modulus component is exactly 1.
    output_dofs, input_dofs : tuple of int
        0-based DOFs of the outputs and of the known inputs.
    """

    y: np.ndarray
    u: np.ndarray
    fs: float
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    mode_shape: np.ndarray
    output_dofs: tuple
    input_dofs: tuple

    @property
    def n_samples(self):
        """Number of samples (rows of ``y`` and ``u``)."""
        return self.y.shape[0]

    @property
    def n_outputs(self):
        """Number of output channels."""
        return self.y.shape[1]

    @property
    def n_inputs(self):
        """Number of known input channels."""
        return self.u.shape[1]

    def __repr__(self):
        freqs = ", ".join(f"{f:.4g}" for f in self.frequency_hz)
        xi = np.unique(np.round(100 * self.damping_ratio, 3)) + 0.0  # no "-0"
        damp = f"{xi[0]:g} %" if xi.size == 1 else f"{xi.min():g}-{xi.max():g} %"
        return (f"Simulation(n_samples={self.n_samples}, fs={self.fs:g} Hz, "
                f"outputs={self.output_dofs}, inputs={self.input_dofs}, "
                f"frequency_hz=[{freqs}], damping={damp})")


def simulate(n_samples=10_000, *, seed=None, n_dof=6, output_dofs=None, input_dofs=(0,),
             damping_ratio=0.02, fs=50.0, input_std=1.0, unknown_input_std=0.1,
             noise_std=0.05, discard=3000, mass=1 / 20, stiffness=None):
    """Simulate input/output data of the grounded mass-spring chain (paper §5.1).

    The defaults reproduce the paper's test case: 6 masses of 1/20 kg, stiffnesses
    100/200 alternating, 2 % modal damping, 50 Hz sampling, accelerations at DOFs 0, 1, 4,
    a known white force at DOF 0, unknown white forces at every DOF with 10 % of its
    std, 5 % sensor noise and 3000 start-up samples discarded.

    Parameters
    ----------
    n_samples : int, default 10_000
        Number of returned samples (after ``discard``).
    seed : None, int, or numpy.random.SeedSequence / BitGenerator / Generator
        Passed to :func:`numpy.random.default_rng`; the same seed gives identical arrays.
    n_dof : int, default 6
        Number of masses; the chain is ``chain_system(n_dof, damping_ratio=...)``.
    output_dofs : sequence of int, optional
        0-based DOFs whose accelerations are measured.  Default
        :func:`default_output_dofs`: ``(0, 1, 4)`` for 6 DOFs, otherwise ``ceil(2 n_dof/3)``
        DOFs evenly spread from the first to the last.  No duplicates.
    input_dofs : sequence of int, default (0,)
        0-based DOFs of the known input forces (may be empty: output-only data, ``u``
        then has 0 columns).  No duplicates.
    damping_ratio : float or array_like of shape (n_dof,), default 0.02
        Modal damping ratio(s) in [0, 1).
    fs : float, default 50.0
        Sampling frequency in Hz (tau = 1/fs = 0.02 s).  A warning is issued if a mode lies
        at or above the Nyquist frequency fs/2.
    input_std : float, default 1.0
        Std (N) of each known white Gaussian input force.
    unknown_input_std : float, default 0.1
        Std of the unknown white forces on every DOF, **relative to** ``input_std``.
    noise_std : float, default 0.05
        Sensor-noise std relative to the std of each noise-free output channel (computed on
        the returned samples).
    discard : int, default 3000
        Leading samples dropped so that the start from rest has decayed (for 2 % damping at
        1.93 Hz, 3000 samples at 50 Hz are about 15 time constants).
    mass, stiffness : float or array_like of shape (n_dof,)
        The chain's masses (kg) and springs (N/m), see :func:`chain_system` (default: the
        paper's 1/20 kg and 100/200 N/m alternating).

    Returns
    -------
    Simulation
        ``y`` (n_samples, n_outputs), ``u`` (n_samples, n_inputs) and the true
        ``frequency_hz``, ``damping_ratio``, ``mode_shape``.

    Notes
    -----
    The random streams are drawn from one generator, as standard normal arrays in this
    order and shape (C order): the known inputs ``(n_samples + discard, n_inputs)``, the
    unknown forces ``(n_samples + discard, n_dof)``, then the sensor noise
    ``(n_samples, n_outputs)``; each is then scaled.  The noise std uses the population
    std (``ddof=0``) of each noise-free output over the returned samples.  The
    total nodal force ``w_k`` (unknown forces plus the known ones at ``input_dofs``) is held
    constant over each sample interval (zero-order hold) and the accelerations include
    the direct feedthrough ``D w_k``, see :func:`acceleration_response`.

    Examples
    --------
    >>> sim = simulate(5000, seed=1)
    >>> sim.y.shape, sim.u.shape
    ((5000, 3), (5000, 1))
    >>> np.round(sim.frequency_hz, 3)
    array([ 1.93 ,  5.618,  8.682, 14.494, 15.846, 17.011])
    """
    n_samples = check_integer("n_samples", n_samples, minimum=1)
    n_dof = check_integer("n_dof", n_dof, minimum=1)
    fs = check_sampling_frequency(fs)
    input_std = check_real("input_std", input_std, low=0.0, low_open=True)
    unknown_input_std = check_real("unknown_input_std", unknown_input_std, low=0.0)
    noise_std = check_real("noise_std", noise_std, low=0.0)
    discard = check_integer("discard", discard, minimum=0)
    if output_dofs is None:
        output_dofs = default_output_dofs(n_dof)
    output_dofs = dof_tuple("output_dofs", output_dofs, n_dof, allow_empty=False)
    input_dofs = dof_tuple("input_dofs", input_dofs, n_dof, allow_empty=True)

    M, K, Cdamp = chain_system(n_dof, mass=mass, stiffness=stiffness, damping_ratio=damping_ratio)
    frequency_hz, xi, mode_shape = modal_parameters(M, K, Cdamp, output_dofs=output_dofs)
    if frequency_hz[-1] >= fs / 2:
        warnings.warn(f"highest mode ({frequency_hz[-1]:.4g} Hz) is at or above the Nyquist "
                      f"frequency fs/2 = {fs / 2:.4g} Hz; it will alias", RuntimeWarning,
                      stacklevel=2)

    try:
        rng = np.random.default_rng(seed)
    except (TypeError, ValueError) as exc:  # numpy's message names a SeedSequence, not the argument
        raise TypeError(f"seed must be None, a non-negative integer, a SeedSequence or a Generator; "
                        f"got {seed!r}") from exc
    n_total = n_samples + discard
    u_all = rng.standard_normal((n_total, len(input_dofs)))
    u_all *= input_std
    unknown_scale = unknown_input_std * input_std
    in_rows = list(input_dofs)

    def force_chunks():
        # The unknown forces are drawn block by block; consecutive draws give exactly the
        # numbers of one (n_total, n_dof) draw, without holding them all in memory.
        for start in range(0, n_total, CHUNK_SAMPLES):
            stop = min(start + CHUNK_SAMPLES, n_total)
            w = rng.standard_normal((stop - start, n_dof)).T  # (n_dof, L) view
            w *= unknown_scale
            if in_rows:
                w[in_rows] += u_all[start:stop].T
            yield w

    # Mean and variance of each noise-free output over the kept samples, accumulated per
    # block (Chan et al.'s pairwise update) while the response is computed.
    stats = {"n": 0, "mean": np.zeros(len(output_dofs)), "m2": np.zeros(len(output_dofs))}

    def accumulate(start, seg):
        seg = seg[:, max(discard - start, 0):]
        n_b = seg.shape[1]
        if n_b == 0:
            return
        mean_b = seg.mean(axis=1)
        m2_b = np.sum((seg - mean_b[:, None]) ** 2, axis=1)
        n_a, n = stats["n"], stats["n"] + n_b
        delta = mean_b - stats["mean"]
        stats["mean"] = stats["mean"] + delta * (n_b / n)
        stats["m2"] = stats["m2"] + m2_b + delta**2 * (n_a * n_b / n)
        stats["n"] = n

    y_clean = np.empty((n_total, len(output_dofs)))
    ModalPlan(M, K, Cdamp, fs, output_dofs).run(force_chunks(), y_clean, accumulate)
    clean_std = np.sqrt(stats["m2"] / stats["n"])

    y = rng.standard_normal((n_samples, len(output_dofs)))  # sensor noise
    y *= noise_std * clean_std
    y += y_clean[discard:]
    u = np.ascontiguousarray(u_all[discard:])
    return Simulation(y=y, u=u, fs=fs, frequency_hz=frequency_hz, damping_ratio=xi,
                      mode_shape=mode_shape, output_dofs=output_dofs, input_dofs=input_dofs)
