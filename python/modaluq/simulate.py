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
from typing import Iterable

import numpy as np
import scipy.linalg
import scipy.signal

from .checks import as_samples, check_integer, check_real, check_sampling_frequency

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

# Samples per block of the modal recursion (keeps temporaries in cache-sized pieces).
_CHUNK_SAMPLES = 1 << 16


# --------------------------------------------------------------------------- validation


def _per_dof(name, value, n, *, lower, upper=math.inf, closed_lower=False):
    """Broadcast a scalar or length-n sequence to an (n,) float array and check its range."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":  # strings would convert; booleans are no masses
        raise TypeError(f"{name} must be a real number or {n} real numbers, got {value!r}")
    arr = arr.astype(np.float64)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have length {n}, got shape {arr.shape}")
    low_ok = arr >= lower if closed_lower else arr > lower
    if not (np.all(np.isfinite(arr)) and np.all(low_ok) and np.all(arr < upper)):
        lo = "[" if closed_lower else "("
        raise ValueError(f"{name} must lie in {lo}{lower}, {upper}), got {value!r}")
    return arr


def _dof_tuple(name, dofs, n_dof, *, allow_empty):
    if isinstance(dofs, (str, bytes)) or not isinstance(dofs, Iterable):
        raise TypeError(f"{name} must be a sequence of DOF indices, got {dofs!r}")
    out = []
    for d in dofs:
        d = check_integer(name, d)
        if not 0 <= d < n_dof:
            raise ValueError(f"{name} entry {d} is out of range for n_dof={n_dof} "
                             f"(valid: 0 .. {n_dof - 1})")
        out.append(d)
    if not out and not allow_empty:
        raise ValueError(f"{name} must not be empty")
    if len(set(out)) != len(out):
        raise ValueError(f"{name} must not contain duplicates, got {tuple(out)}")
    return tuple(out)


def _system_matrices(M, K, Cdamp):
    M = np.asarray(M, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)
    Cdamp = np.asarray(Cdamp, dtype=np.float64)
    n = M.shape[0] if M.ndim == 2 else -1
    for name, mat in (("M", M), ("K", K), ("Cdamp", Cdamp)):
        if mat.ndim != 2 or mat.shape != (n, n):
            raise ValueError(f"{name} must be a square (n_dof, n_dof) matrix matching M, "
                             f"got shape {mat.shape}")
        if not np.all(np.isfinite(mat)):
            raise ValueError(f"{name} contains NaN or Inf")
    return M, K, Cdamp


# ------------------------------------------------------------------------------ system


def chain_system(n_dof=6, *, mass=1 / 20, stiffness=None, damping_ratio=0.02):
    """Mass, stiffness and damping matrices of a grounded mass-spring chain.

    ``ground --k_1-- m_1 --k_2-- m_2 -- ... --k_n-- m_n`` with the last mass free.

    Parameters
    ----------
    n_dof : int, default 6
        Number of masses (degrees of freedom).
    mass : float or array_like of shape (n_dof,), default 1/20
        Masses m_i in kg (> 0).
    stiffness : float or array_like of shape (n_dof,), optional
        Spring stiffnesses k_i in N/m (> 0); ``k_1`` ties mass 1 to the ground and ``k_i``
        ties mass i-1 to mass i.  The default alternates 100, 200, 100, ... starting with
        100, which for ``n_dof=6`` is the paper's chain.
    damping_ratio : float or array_like of shape (n_dof,), default 0.02
        Modal damping ratio of each mode (fraction, 0 <= xi < 1), in order of ascending
        undamped frequency.

    Returns
    -------
    M, K, Cdamp : ndarray, each (n_dof, n_dof)
        Mass (diagonal), stiffness (tridiagonal) and damping matrices.  The damping is
        modal: ``Cdamp = M Phi diag(2 xi_i omega_i) Phi^T M`` with ``Phi`` the
        mass-normalised undamped mode shapes (``Phi^T M Phi = I``) and ``omega_i`` the
        undamped circular frequencies, so each mode of the damped system has exactly the
        requested damping ratio and undamped frequency ``|mu_i| = omega_i``.

    Examples
    --------
    >>> import numpy as np, scipy.linalg
    >>> M, K, Cdamp = chain_system()
    >>> np.round(np.sqrt(scipy.linalg.eigvalsh(K, M)) / (2 * np.pi), 4)
    array([ 1.9297,  5.618 ,  8.6824, 14.4938, 15.8462, 17.0114])
    """
    n_dof = check_integer("n_dof", n_dof, minimum=1)
    m = _per_dof("mass", mass, n_dof, lower=0.0)
    if stiffness is None:
        k = np.where(np.arange(n_dof) % 2 == 0, 100.0, 200.0)
    else:
        k = _per_dof("stiffness", stiffness, n_dof, lower=0.0)
    xi = _per_dof("damping_ratio", damping_ratio, n_dof, lower=0.0, upper=1.0,
                  closed_lower=True)

    M = np.diag(m)
    k_right = np.append(k[1:], 0.0)  # spring to the next mass (none after the last)
    K = np.diag(k + k_right) - np.diag(k[1:], 1) - np.diag(k[1:], -1)
    omega2, Phi = scipy.linalg.eigh(K, M)  # ascending, Phi^T M Phi = I
    omega = np.sqrt(omega2)
    MPhi = M @ Phi
    Cdamp = (MPhi * (2.0 * xi * omega)) @ MPhi.T
    Cdamp = 0.5 * (Cdamp + Cdamp.T)
    return M, K, Cdamp


def _continuous(M, K, Cdamp):
    """Continuous state matrix A_c and force input matrix B_c (state x = [q'; q])."""
    n_dof = M.shape[0]
    Minv_K = np.linalg.solve(M, K)
    Minv_C = np.linalg.solve(M, Cdamp)
    Ac = np.zeros((2 * n_dof, 2 * n_dof))
    Ac[:n_dof, :n_dof] = -Minv_C
    Ac[:n_dof, n_dof:] = -Minv_K
    Ac[n_dof:, :n_dof] = np.eye(n_dof)
    Bc = np.zeros((2 * n_dof, n_dof))
    Bc[:n_dof] = np.linalg.inv(M)
    return Ac, Bc


def state_space(M, K, Cdamp, *, fs, output_dofs):
    """Discrete state-space model of ``M q'' + C q' + K q = w`` with acceleration outputs.

    Paper Eq. (3)-(4): zero-order hold of all ``n_dof`` nodal forces, computed exactly with
    the augmented matrix exponential ``expm([[A_c, B_c], [0, 0]] / fs)``.

    Parameters
    ----------
    M, K, Cdamp : array_like, each (n_dof, n_dof)
        Mass, stiffness and damping matrices (e.g. from :func:`chain_system`).
    fs : float
        Sampling frequency in Hz (``tau = 1/fs``).
    output_dofs : sequence of int
        0-based DOFs whose accelerations are the outputs.

    Returns
    -------
    A : ndarray, (2 n_dof, 2 n_dof)
        State transition matrix ``exp(A_c tau)``; the state is ``[q'; q]``.
    B : ndarray, (2 n_dof, n_dof)
        Input matrix of the nodal forces (column j: force on DOF j).
    C : ndarray, (n_outputs, 2 n_dof)
        Output matrix ``L_a [-M^-1 C, -M^-1 K]``.
    D : ndarray, (n_outputs, n_dof)
        Feedthrough ``L_a M^-1``.
    """
    M, K, Cdamp = _system_matrices(M, K, Cdamp)
    n_dof = M.shape[0]
    fs = check_sampling_frequency(fs)
    output_dofs = _dof_tuple("output_dofs", output_dofs, n_dof, allow_empty=False)
    Ac, Bc = _continuous(M, K, Cdamp)
    n = 2 * n_dof
    aug = np.zeros((n + n_dof, n + n_dof))
    aug[:n, :n] = Ac
    aug[:n, n:] = Bc
    E = scipy.linalg.expm(aug / fs)
    A = np.ascontiguousarray(E[:n, :n])
    B = np.ascontiguousarray(E[:n, n:])
    C = np.ascontiguousarray(Ac[:n_dof][list(output_dofs)])
    D = np.ascontiguousarray(Bc[:n_dof][list(output_dofs)])
    return A, B, C, D


def _complex_modes(M, K, Cdamp):
    """Oscillating eigenpairs of A_c (Im mu > 0, ascending |mu|).

    Returns ``mu`` (n_dof,), ``V`` (2 n_dof, n_dof), the rows ``W`` (n_dof, 2 n_dof) of
    ``V_all^-1`` belonging to them (so ``z = W x`` are the modal coordinates), ``A_c``.
    """
    Ac, _ = _continuous(M, K, Cdamp)
    mu_all, V_all = np.linalg.eig(Ac)
    n_dof = M.shape[0]
    keep = np.flatnonzero(mu_all.imag > 0)
    if keep.size != n_dof:
        raise ValueError("the system must be underdamped in every mode (found "
                         f"{keep.size} oscillating modes for n_dof={n_dof})")
    keep = keep[np.argsort(np.abs(mu_all[keep]), kind="stable")]
    W_all = np.linalg.solve(V_all, np.eye(V_all.shape[0]))
    return mu_all[keep], V_all[:, keep], W_all[keep], Ac


def modal_parameters(M, K, Cdamp, *, output_dofs):
    """True modal parameters of the continuous damped system at the output DOFs.

    Parameters
    ----------
    M, K, Cdamp : array_like, each (n_dof, n_dof)
        Mass, stiffness and damping matrices.
    output_dofs : sequence of int
        0-based DOFs of the (acceleration) outputs.

    Returns
    -------
    frequency_hz : ndarray, (n_dof,)
        ``|mu_i| / (2 pi)`` for the continuous eigenvalues ``mu_i`` (Im > 0) of the damped
        system, ascending.  With modal damping this is the undamped natural frequency.
    damping_ratio : ndarray, (n_dof,)
        ``-Re(mu_i) / |mu_i|`` (fraction).
    mode_shape : ndarray, (n_outputs, n_dof), complex
        ``C phi_i`` (paper Eq. 5; ``phi_i`` the eigenvector of A_c, equivalently of A), each
        column divided by its largest-modulus component, which is then exactly ``1 + 0j``.
        Up to that scale it is the DOF-space mode shape at the output DOFs (real for
        modal damping, apart from rounding).
    """
    M, K, Cdamp = _system_matrices(M, K, Cdamp)
    output_dofs = _dof_tuple("output_dofs", output_dofs, M.shape[0], allow_empty=False)
    mu, V, _, Ac = _complex_modes(M, K, Cdamp)
    C = Ac[: M.shape[0]][list(output_dofs)]
    frequency_hz = np.abs(mu) / (2.0 * np.pi)
    damping_ratio = -mu.real / np.abs(mu)
    shape = C @ V
    ref = np.argmax(np.abs(shape), axis=0)
    cols = np.arange(shape.shape[1])
    shape = shape / shape[ref, cols]
    shape[ref, cols] = 1.0
    return frequency_hz, damping_ratio, shape


def _zoh_sdof_filter(c, k, fs):
    """lfilter coefficients (b, a) of the ZOH-sampled ``eta'' + c eta' + k eta = p -> eta''."""
    Ac = np.array([[-c, -k], [1.0, 0.0]])
    aug = np.zeros((3, 3))
    aug[:2, :2] = Ac
    aug[0, 2] = 1.0
    E = scipy.linalg.expm(aug / fs)
    A, B = E[:2, :2], E[:2, 2]
    # H(z) = C (zI - A)^-1 B + D with C = [-c, -k], D = 1.  For 2 x 2 matrices
    # adj(zI - A) = z I + (A - tr(A) I) and det(zI - A) = z^2 - tr(A) z + det(A), so
    # H = (z^2 + (C B - tr A) z + C (A - tr(A) I) B + det A) / det(zI - A).
    Cv = np.array([-c, -k])
    a = np.array([1.0, -np.trace(A), np.linalg.det(A)])
    b = np.array([1.0, Cv @ B + a[1], Cv @ (A - np.trace(A) * np.eye(2)) @ B + a[2]])
    return b, a


class _ModalPlan:
    """Precomputed modal form of the sampled system (see :func:`acceleration_response`).

    ``kind == "real"`` (classical damping): ``p = Pin @ w`` are the real modal forces,
    each mode is a real second-order filter to its modal acceleration and
    ``y = Pout @ a``.  ``kind == "complex"``: ``g = G @ w`` complex modal inputs,
    ``z_{k+1} = lam z_k + g_k`` and ``y = 2 Re(CV2/2 @ z) + D @ w``.
    """

    def __init__(self, M, K, Cdamp, fs, output_dofs):
        out = list(output_dofs)
        omega2, Phi = scipy.linalg.eigh(K, M)  # Phi^T M Phi = I
        modal_c = Phi.T @ Cdamp @ Phi
        off = modal_c - np.diag(np.diag(modal_c))
        scale = max(np.max(np.abs(np.diag(modal_c))), 1e-300)
        if np.max(np.abs(off), initial=0.0) <= 1e-10 * scale:
            self.kind = "real"
            self.Pin = np.ascontiguousarray(Phi.T)
            self.Pout = np.ascontiguousarray(Phi[out])
            self.filters = [_zoh_sdof_filter(modal_c[i, i], omega2[i], fs)
                            for i in range(len(omega2))]
            return
        self.kind = "complex"
        A, B, C, D = state_space(M, K, Cdamp, fs=fs, output_dofs=output_dofs)
        mu, V, W, _ = _complex_modes(M, K, Cdamp)
        G = W @ B  # z_{k+1} = lambda z_k + G w_k
        self.G_re = np.ascontiguousarray(G.real)
        self.G_im = np.ascontiguousarray(G.imag)
        self.lam = np.exp(mu / fs)
        self.CV2 = 2.0 * (C @ V)
        self.D = D

    def run(self, force_chunks, out, on_chunk=None):
        """Fill ``out`` (n_samples, n_outputs) with the response, starting from rest.

        ``force_chunks`` yields consecutive (n_dof, L) blocks of the nodal force (any
        strides) whose lengths add up to ``n_samples``; ``on_chunk(start, y_chunk)`` is
        called with each (n_outputs, L) output block.
        """
        start = 0
        if self.kind == "real":
            state = np.zeros((len(self.filters), 2))
            for w in force_chunks:
                p = self.Pin @ w
                for i, (b, a) in enumerate(self.filters):
                    p[i], state[i] = scipy.signal.lfilter(b, a, p[i], zi=state[i])
                seg = self.Pout @ p
                start = self._store(out, start, seg, on_chunk)
        else:
            state = np.zeros((len(self.lam), 1), dtype=np.complex128)  # z_0 = 0
            for w in force_chunks:
                g = np.empty((len(self.lam), w.shape[1]), dtype=np.complex128)
                g.real = self.G_re @ w
                g.imag = self.G_im @ w
                for i, lam in enumerate(self.lam):
                    # b = [0, 1], a = [1, -lambda]: z_k = lambda z_{k-1} + g_{k-1}, zi = z_start.
                    g[i], state[i] = scipy.signal.lfilter([0.0, 1.0], [1.0, -lam], g[i],
                                                          zi=state[i])
                seg = (self.CV2 @ g).real
                seg += self.D @ w
                start = self._store(out, start, seg, on_chunk)
        if start != out.shape[0]:
            raise RuntimeError("force chunks do not cover the output")  # internal error

    @staticmethod
    def _store(out, start, seg, on_chunk):
        stop = start + seg.shape[1]
        out[start:stop] = seg.T
        if on_chunk is not None:
            on_chunk(start, seg)
        return stop


def _chunks_of(force):
    """(n_dof, L) views of consecutive row blocks of ``force`` (n_samples, n_dof)."""
    for start in range(0, force.shape[0], _CHUNK_SAMPLES):
        yield force[start:start + _CHUNK_SAMPLES].T


def acceleration_response(force, M, K, Cdamp, *, fs, output_dofs):
    """Noise-free acceleration response to zero-order-held nodal forces, from rest.

    Equal (to rounding) to the recursion ``x_{k+1} = A x_k + B w_k``,
    ``y_k = C x_k + D w_k``, ``x_0 = 0`` with ``(A, B, C, D) = state_space(...)``, but run
    in modal coordinates with :func:`scipy.signal.lfilter` (compiled loops):

    * classical damping (``Phi^T Cdamp Phi`` diagonal for the mass-normalised undamped
      modes ``Phi``, as from :func:`chain_system`): each mode is the exactly ZOH-sampled
      single-DOF oscillator ``eta'' + c_i eta' + omega_i^2 eta = phi_i^T w``, a real
      second-order filter from modal force to modal acceleration (feedthrough included),
      and ``y = Phi[output_dofs] eta''``;
    * otherwise: the complex modes of ``A`` (one per conjugate pair),
      ``z_{k+1} = lambda z_k + g_k`` with ``y = 2 Re(C V z) + D w`` (every mode must be
      underdamped).

    Parameters
    ----------
    force : array_like, (n_samples, n_dof)
        Nodal force ``w_k`` in N; row k is held over ``[k tau, (k+1) tau)``.
    M, K, Cdamp : array_like, each (n_dof, n_dof)
        Mass (symmetric positive definite), stiffness (symmetric) and damping matrices.
    fs : float
        Sampling frequency in Hz.
    output_dofs : sequence of int
        0-based DOFs whose accelerations are returned.

    Returns
    -------
    ndarray, (n_samples, n_outputs), float64, C-contiguous
        Accelerations ``y_k`` in m/s^2.
    """
    M, K, Cdamp = _system_matrices(M, K, Cdamp)
    n_dof = M.shape[0]
    fs = check_sampling_frequency(fs)
    output_dofs = _dof_tuple("output_dofs", output_dofs, n_dof, allow_empty=False)
    force = as_samples(force, "force", n_channels=n_dof)
    y = np.empty((force.shape[0], len(output_dofs)))
    _ModalPlan(M, K, Cdamp, fs, output_dofs).run(_chunks_of(force), y)
    return y


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
    output_dofs = _dof_tuple("output_dofs", output_dofs, n_dof, allow_empty=False)
    input_dofs = _dof_tuple("input_dofs", input_dofs, n_dof, allow_empty=True)

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
        for start in range(0, n_total, _CHUNK_SAMPLES):
            stop = min(start + _CHUNK_SAMPLES, n_total)
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
    _ModalPlan(M, K, Cdamp, fs, output_dofs).run(force_chunks(), y_clean, accumulate)
    clean_std = np.sqrt(stats["m2"] / stats["n"])

    y = rng.standard_normal((n_samples, len(output_dofs)))  # sensor noise
    y *= noise_std * clean_std
    y += y_clean[discard:]
    u = np.ascontiguousarray(u_all[discard:])
    return Simulation(y=y, u=u, fs=fs, frequency_hz=frequency_hz, damping_ratio=xi,
                      mode_shape=mode_shape, output_dofs=output_dofs, input_dofs=input_dofs)
