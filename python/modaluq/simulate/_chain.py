"""The chain's mechanics behind :func:`modaluq.simulate`: mass, stiffness and damping matrices,
the exact zero-order-hold state space, the modal parameters and the time response computed in
modal coordinates (the model is written out in :mod:`modaluq.simulate`'s docstring).

The names meant for users (``chain_system``, ``state_space``, ``modal_parameters``,
``acceleration_response``) are re-exported by :mod:`modaluq.simulate`; import them from there.
"""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np

from ..checks import as_samples, check_integer, check_sampling_frequency

# Samples per block of the modal recursion (keeps temporaries in cache-sized pieces).
CHUNK_SAMPLES = 1 << 16


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


def dof_tuple(name, dofs, n_dof, *, allow_empty):
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
    import scipy.linalg  # SciPy when simulating, not when modaluq is imported
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
    output_dofs = dof_tuple("output_dofs", output_dofs, n_dof, allow_empty=False)
    Ac, Bc = _continuous(M, K, Cdamp)
    n = 2 * n_dof
    aug = np.zeros((n + n_dof, n + n_dof))
    aug[:n, :n] = Ac
    aug[:n, n:] = Bc
    import scipy.linalg  # SciPy when simulating, not when modaluq is imported
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
    output_dofs = dof_tuple("output_dofs", output_dofs, M.shape[0], allow_empty=False)
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
    import scipy.linalg  # SciPy when simulating, not when modaluq is imported
    E = scipy.linalg.expm(aug / fs)
    A, B = E[:2, :2], E[:2, 2]
    # H(z) = C (zI - A)^-1 B + D with C = [-c, -k], D = 1.  For 2 x 2 matrices
    # adj(zI - A) = z I + (A - tr(A) I) and det(zI - A) = z^2 - tr(A) z + det(A), so
    # H = (z^2 + (C B - tr A) z + C (A - tr(A) I) B + det A) / det(zI - A).
    Cv = np.array([-c, -k])
    a = np.array([1.0, -np.trace(A), np.linalg.det(A)])
    b = np.array([1.0, Cv @ B + a[1], Cv @ (A - np.trace(A) * np.eye(2)) @ B + a[2]])
    return b, a


class ModalPlan:
    """Precomputed modal form of the sampled system (see :func:`acceleration_response`).

    ``kind == "real"`` (classical damping): ``p = Pin @ w`` are the real modal forces,
    each mode is a real second-order filter to its modal acceleration and
    ``y = Pout @ a``.  ``kind == "complex"``: ``g = G @ w`` complex modal inputs,
    ``z_{k+1} = lam z_k + g_k`` and ``y = 2 Re(CV2/2 @ z) + D @ w``.
    """

    def __init__(self, M, K, Cdamp, fs, output_dofs):
        out = list(output_dofs)
        import scipy.linalg  # SciPy when simulating, not when modaluq is imported
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
        import scipy.signal  # SciPy when simulating, not when modaluq is imported

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
    for start in range(0, force.shape[0], CHUNK_SAMPLES):
        yield force[start:start + CHUNK_SAMPLES].T


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
    output_dofs = dof_tuple("output_dofs", output_dofs, n_dof, allow_empty=False)
    force = as_samples(force, "force", n_channels=n_dof)
    y = np.empty((force.shape[0], len(output_dofs)))
    ModalPlan(M, K, Cdamp, fs, output_dofs).run(_chunks_of(force), y)
    return y
