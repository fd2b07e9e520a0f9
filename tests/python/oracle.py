"""NumPy reference oracle for modaluq (SSI-cov, output-only and input/output, with
delta-method uncertainty of the modal parameters).

This module is deliberately *slow and obviously correct*: data matrices are built
explicitly from the samples, every Jacobian is an explicit (Kronecker) matrix, and the
covariances Sigma_R, Sigma_H, Sigma_Gamma and Sigma_{A,C} are all formed.  It is the
reference the C++ core is checked against.

Contract: docs/conventions.md.  Math: docs/uq-math.md; the section numbers (§) in the
docstrings refer to that note.

Conventions used throughout
* vec() is column-major (Fortran order): ``vec(X) = X.reshape(-1, order="F")``.
* P_{m,n} is the commutation matrix, P_{m,n} vec(X) = vec(X^T) for X of size m x n (§1).
* Float64 everywhere.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

__all__ = [
    "data_matrices",
    "covariances",
    "subspace_matrix",
    "jacobian_H_R",
    "svd_sorted",
    "gamma",
    "system_matrices",
    "jacobian_Gamma_H",
    "rademacher_signs",
    "noise_floor",
    "jacobian_AC_Gamma",
    "modes",
    "jacobian_theta_AC",
    "identify",
    "identify_factor",
    "commutation_matrix",
    "vec",
    "unvec",
    "R3_RCOND",
]

#: Relative tolerance of the pseudo-inverse of R3 (singular values below
#: R3_RCOND * largest are dropped), the same default as the C++ core (input_rcond).
R3_RCOND = 1e-10


# --------------------------------------------------------------------------------------
# small linear-algebra helpers
# --------------------------------------------------------------------------------------
def vec(X):
    """Column-major vec (§1)."""
    return np.asarray(X).reshape(-1, order="F")


def unvec(x, rows, cols):
    """Inverse of :func:`vec`."""
    return np.asarray(x).reshape((rows, cols), order="F")


def commutation_matrix(m, n):
    """P_{m,n} (mn x mn) with P vec(X) = vec(X^T) for X of size m x n (§1).

    Entrywise P[i*n + j, j*m + i] = 1.
    """
    P = np.zeros((m * n, m * n))
    for i in range(m):
        for j in range(n):
            P[i * n + j, j * m + i] = 1.0
    return P


def _pinv_drop_one(M):
    """Pseudo-inverse of a square matrix with a known one-dimensional null space:
    exactly one (the smallest) singular value is dropped, never a threshold (§5.2, §10.10)."""
    Uu, s, Vh = np.linalg.svd(M)
    k = len(s) - 1
    return (Vh[:k].conj().T / s[:k]) @ Uu[:, :k].conj().T


def _pinv_R3(R3):
    """Pseudo-inverse of R3 with the documented relative tolerance R3_RCOND (§4.4).

    A general (non-Hermitian) SVD is used so that finite differences that perturb a single
    entry of R3 (making it non-symmetric) are differentiated correctly."""
    return np.linalg.pinv(np.asarray(R3, dtype=np.float64), rtol=R3_RCOND)


def _as_2d(x, name):
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2:
        raise ValueError(f"{name} must be 1-D or 2-D (n_samples, n_channels)")
    return x


# --------------------------------------------------------------------------------------
# §1-§3: data matrices and covariances
# --------------------------------------------------------------------------------------
def _prepare(y, u, references, demean):
    y = _as_2d(y, "y")
    if u is not None:
        u = _as_2d(u, "u")
        if u.shape[0] != y.shape[0]:
            raise ValueError("y and u must have the same number of samples")
    if demean:
        # global channel mean over ALL samples (conventions "Data"; §10.2)
        y = y - y.mean(axis=0)
        if u is not None:
            u = u - u.mean(axis=0)
    if references is None:
        ref = np.arange(y.shape[1])
    else:
        ref = np.atleast_1d(np.asarray(references, dtype=int))
    return y, u, ref


def data_matrices(y, u, p, q, references=None, demean=True):
    """Data matrices (Y+, Y-, U+), NOT scaled by 1/sqrt(N) (conventions "Horizons", §1).

    * N = n_samples - p - q + 1 Hankel columns; column c uses samples c .. c+p+q-1.
    * Y+ (p*l x N): block row i (i = 0..p-1) is y[q+i+c], c = 0..N-1.
    * Y- (q*r x N): block row j (j = 0..q-1) is y_ref[j+c].
    * U+ (p*m x N, or None when u is None): block row i is u[q+i+c].

    The global channel mean over all samples is removed first when ``demean``.
    """
    y, u, ref = _prepare(y, u, references, demean)
    n_samples, l = y.shape
    r = len(ref)
    N = n_samples - p - q + 1
    if N < 1:
        raise ValueError("not enough samples for the requested block rows")
    Yp = np.empty((p * l, N))
    Ym = np.empty((q * r, N))
    for c in range(N):
        for i in range(p):
            Yp[i * l:(i + 1) * l, c] = y[q + i + c, :]
        for j in range(q):
            Ym[j * r:(j + 1) * r, c] = y[j + c, ref]
    Up = None
    if u is not None:
        m = u.shape[1]
        Up = np.empty((p * m, N))
        for c in range(N):
            for i in range(p):
                Up[i * m:(i + 1) * m, c] = u[q + i + c, :]
    return Yp, Ym, Up


def _products(Yp, Ym, Up, cols):
    """R1..R4 from the explicit products of the data matrices restricted to ``cols``,
    divided by the number of columns (conventions; §2.1 table)."""
    n = cols.stop - cols.start
    a, b = Yp[:, cols], Ym[:, cols]
    out = {"R1": a @ b.T / n, "R2": None, "R3": None, "R4": None}
    if Up is not None:
        c = Up[:, cols]
        out["R2"] = a @ c.T / n
        out["R3"] = c @ c.T / n
        out["R4"] = b @ c.T / n
    return out


def _stack_r(R):
    """r = [vec R1; vec R2; vec R3; vec R4] (OO: vec R1) (§3)."""
    parts = [vec(R["R1"])]
    if R.get("R2") is not None:
        parts += [vec(R["R2"]), vec(R["R3"]), vec(R["R4"])]
    return np.concatenate(parts)


def _unstack_r(r, a, b, pm):
    """Inverse of :func:`_stack_r` for H of size a x b and pm = p*m (0 for OO)."""
    h = a * b
    R1 = unvec(r[:h], a, b)
    if pm == 0:
        return R1, None, None, None
    o = h
    R2 = unvec(r[o:o + a * pm], a, pm)
    o += a * pm
    R3 = unvec(r[o:o + pm * pm], pm, pm)
    o += pm * pm
    R4 = unvec(r[o:o + b * pm], b, pm)
    return R1, R2, R3, R4


def covariances(y, u, p, q, n_blocks, references=None, demean=True):
    """Covariance matrices R1..R4 and their block covariance factor T_R (§2.1, §3).

    Returns a dict with
    * 'R1', 'R2', 'R3', 'R4': products of the data matrices over all N columns / N
      (R2..R4 are None when u is None);
    * 'blocks': list of dicts {R1..R4}, block k = columns [k*Nb, (k+1)*Nb), each / Nb;
    * 'T_R' (d_r x n_blocks): [r^1 - rbar, ..., r^nb - rbar] / sqrt(nb (nb-1)),
      r^k = [vec R1^k; vec R2^k; vec R3^k; vec R4^k] (column-major vec), rbar the mean of
      the r^k, so Sigma_R = T_R T_R^T;
    * 'N', 'Nb', 'n_blocks'.
    """
    Yp, Ym, Up = data_matrices(y, u, p, q, references=references, demean=demean)
    N = Yp.shape[1]
    n_blocks = int(n_blocks)
    if n_blocks < 2:
        raise ValueError("n_blocks must be >= 2")
    Nb = N // n_blocks
    if Nb < 1:
        raise ValueError(f"n_blocks={n_blocks} exceeds the number of Hankel columns N={N}")
    out = _products(Yp, Ym, Up, slice(0, N))
    blocks = [_products(Yp, Ym, Up, slice(k * Nb, (k + 1) * Nb)) for k in range(n_blocks)]
    rk = np.column_stack([_stack_r(B) for B in blocks])          # d_r x nb
    rbar = rk.mean(axis=1, keepdims=True)
    T_R = (rk - rbar) / np.sqrt(n_blocks * (n_blocks - 1))
    out.update(blocks=blocks, T_R=T_R, N=N, Nb=Nb, n_blocks=n_blocks)
    return out


# --------------------------------------------------------------------------------------
# §2.1, §4: subspace matrix and J_{H,R}
# --------------------------------------------------------------------------------------
def subspace_matrix(R1, R2=None, R3=None, R4=None):
    """H = R1 (output-only) or H = R1 - R2 R3^+ R4^T (input/output) (§2.1).

    R3^+ uses the relative tolerance R3_RCOND."""
    R1 = np.asarray(R1, dtype=np.float64)
    if R2 is None:
        return R1.copy()
    return R1 - np.asarray(R2) @ _pinv_R3(R3) @ np.asarray(R4).T


def jacobian_H_R(R1, R2=None, R3=None, R4=None):
    """Explicit J_{H,R} (h x d_r) of §4.2:

        J_{H,R} = [ I_h , -(M^T kron I_a) , (M^T kron G) , -(I_b kron G) P_{b,pm} ]

    with G = R2 R3^+ and M = R3^+ R4^T; it is the Kronecker form of the differential
    dH = dR1 - dR2 M + G dR3 M - G dR4^T (§4.1; note the *second* R3^+ in the dR3 term).
    Output-only: the identity I_h.
    """
    R1 = np.asarray(R1, dtype=np.float64)
    a, b = R1.shape
    h = a * b
    if R2 is None:
        return np.eye(h)
    R2, R3, R4 = (np.asarray(X, dtype=np.float64) for X in (R2, R3, R4))
    pm = R3.shape[0]
    R3p = _pinv_R3(R3)
    G = R2 @ R3p               # a x pm
    M = R3p @ R4.T             # pm x b
    J1 = np.eye(h)
    J2 = -np.kron(M.T, np.eye(a))
    J3 = np.kron(M.T, G)
    J4 = -np.kron(np.eye(b), G) @ commutation_matrix(b, pm)
    return np.hstack([J1, J2, J3, J4])


# --------------------------------------------------------------------------------------
# §2.2, §5: SVD, Gamma and J_{Gamma,H}
# --------------------------------------------------------------------------------------
def svd_sorted(H):
    """Thin SVD H = U diag(s) Vt with s descending and the sign convention of §5.4:
    the largest-modulus entry of each u_j is positive, (u_j, v_j) flipped together."""
    U, s, Vt = np.linalg.svd(np.asarray(H, dtype=np.float64), full_matrices=False)
    for j in range(len(s)):
        if U[np.argmax(np.abs(U[:, j])), j] < 0:
            U[:, j] = -U[:, j]
            Vt[j, :] = -Vt[j, :]
    return U, s, Vt


def _check_order(n, a, b, l):
    n = int(n)
    limit = min(a - l, b)                 # (p-1)*l and q*r
    if n < 1 or n > limit:
        raise ValueError(f"model order {n} must be in [1, min((p-1)*l, q*r)] = [1, {limit}]")
    return n


def gamma(H, n):
    """Gamma = U1 S1^{1/2} (a x n), i.e. gamma_j = sqrt(sigma_j) u_j (§2.2), with the
    sign convention of :func:`svd_sorted`."""
    U, s, _ = svd_sorted(H)
    if n > len(s):
        raise ValueError(f"order {n} exceeds the rank bound {len(s)} of H")
    return U[:, :n] * np.sqrt(s[:n])


def system_matrices(Gamma, l):
    """(A, C) from Gamma (§2.2): A = lstsq(Gamma_up, Gamma_dw), C = Gamma[:l].

    Gamma_up drops the last block row (l rows), Gamma_dw the first."""
    Gamma = np.asarray(Gamma, dtype=np.float64)
    up, dw = Gamma[:-l], Gamma[l:]
    A = np.linalg.lstsq(up, dw, rcond=None)[0]
    C = Gamma[:l].copy()
    return A, C


def jacobian_Gamma_H(H, n, frozen_from=None):
    """Explicit J_{Gamma,H} (a*n x h), rows stacked column by column of Gamma (vec Gamma)
    (§5.1-§5.2):

        J_{gamma_j,H} = u_j (v_j kron u_j)^T / (2 sqrt(sigma_j)) + sqrt(sigma_j) [I_a 0] B_j^+ C_j
        B_j = [[I_a, -H/sigma_j], [-H^T/sigma_j, I_b]]
        C_j = (1/sigma_j) [ v_j^T kron (I_a - u_j u_j^T) ; (u_j^T kron (I_b - v_j v_j^T)) P_{a,b} ]

    B_j^+ drops exactly one singular value (its null space is span [u_j; v_j]).
    J_{gamma_j,H} does not depend on n, so the rows for a lower order are leading rows.

    ``frozen_from`` = k* freezes the columns j >= k* (§5.5): their direction u_j is held, so
    only the first term (the scale, d sigma_j) remains.
    """
    H = np.asarray(H, dtype=np.float64)
    a, b = H.shape
    h = a * b
    U, s, Vt = svd_sorted(H)
    if n > len(s):
        raise ValueError(f"order {n} exceeds the rank bound {len(s)} of H")
    Ia, Ib = np.eye(a), np.eye(b)
    Pab = commutation_matrix(a, b)
    J = np.empty((a * n, h))
    for j in range(n):
        sj, uj, vj = s[j], U[:, j], Vt[j, :]
        Bj = np.block([[Ia, -H / sj], [-H.T / sj, Ib]])
        Cj = np.vstack([
            np.kron(vj[None, :], Ia - np.outer(uj, uj)),
            np.kron(uj[None, :], Ib - np.outer(vj, vj)) @ Pab,
        ]) / sj
        dsig = np.kron(vj, uj)[None, :]                # 1 x h : (v_j kron u_j)^T
        J[j * a:(j + 1) * a, :] = np.outer(uj, dsig) / (2.0 * np.sqrt(sj))
        if frozen_from is None or j < frozen_from:
            duv = _pinv_drop_one(Bj) @ Cj              # (a+b) x h : [du_j; dv_j]
            J[j * a:(j + 1) * a, :] += np.sqrt(sj) * duv[:a]
    return J


# --------------------------------------------------------------------------------------
# §5.5: noise floor
# --------------------------------------------------------------------------------------
NOISE_FLOOR_DRAWS = 20
NOISE_FLOOR_SEED = 0x6D6F64616C7571        # "modaluq"
_M64 = (1 << 64) - 1


def rademacher_signs(n_blocks, draws=NOISE_FLOOR_DRAWS, seed=NOISE_FLOOR_SEED):
    """(n_blocks x draws) signs from SplitMix64 (Steele, Lea & Flood 2014) seeded with
    ``seed`` (NOISE_FLOOR_SEED for §5.5, BOOTSTRAP_SEED for §5.6): entry (b, t) is draw
    t*n_blocks + b, +1 when its top bit is clear."""
    state = seed
    eps = np.empty((n_blocks, draws))
    for t in range(draws):
        for b in range(n_blocks):
            state = (state + 0x9E3779B97F4A7C15) & _M64
            z = state
            z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _M64
            z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _M64
            z ^= z >> 31
            eps[b, t] = -1.0 if z >> 63 else 1.0
    return eps


def noise_coupling(sd_base, sd_frozen):
    """ρ of eq. 5.14 per mode from the (n_modes × 2) std of [f, ξ] of the plain and the frozen
    propagation: max(1, plain / frozen) over f and ξ, ∞ where a frozen std is 0 and the plain is not."""
    sd_base, sd_frozen = np.asarray(sd_base), np.asarray(sd_frozen)
    if sd_base.shape[0] == 0:
        return np.ones(0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(sd_frozen > 0, sd_base / sd_frozen, np.where(sd_base > 0, np.inf, 1.0))
    return np.maximum(1.0, ratio.max(axis=1))


def noise_floor(H, T_H, k_max, factor=1.5):
    """k* of §5.5 (eq. 5.12), by the definition: the smallest k < min(k_max, r) with
    s_k < factor * delta_k, delta_k = RMS_t ||(U^T dH_t V)[k:, k:]||_2 over the Rademacher
    draws dH_t = unvec(T_H eps_t); min(k_max, r) if none.  Every delta_k is computed (no
    skipping), with exact spectral norms.  Returns (k*, delta)."""
    H = np.asarray(H, dtype=np.float64)
    a, b = H.shape
    U, s, Vt = svd_sorted(H)
    k_max = min(int(k_max), len(s))
    eps = rademacher_signs(T_H.shape[1])
    D = [U.T @ unvec(T_H @ eps[:, t], a, b) @ Vt.T for t in range(eps.shape[1])]
    delta = np.array([np.sqrt(np.mean([np.linalg.norm(d[k:, k:], 2) ** 2 for d in D]))
                      for k in range(k_max)])
    below = np.flatnonzero(s[:k_max] < factor * delta)
    return (int(below[0]) if below.size else k_max), delta


# --------------------------------------------------------------------------------------
# §5.6: the bootstrap of sigma_f, sigma_xi above the noise floor
# --------------------------------------------------------------------------------------
BOOTSTRAP_SEED = 0x626F6F7473747270        # "bootstrp"
BOOTSTRAP_TOLERANCE = 0.05
BOOTSTRAP_MIN_FOLLOWED = 0.8


def poles_at_orders(H, l, fs, orders):
    """{order: (f, xi)} of the poles (Im lambda > 0, by frequency) identified from H at each order:
    one SVD, then each order's A by least squares and its eigenvalues only."""
    U, s, _ = svd_sorted(H)
    out = {}
    for n in orders:
        A, _ = system_matrices(U[:, :n] * np.sqrt(s[:n]), l)
        w = scipy.linalg.eigvals(A)
        mu = np.log(w[w.imag > 0]) * fs
        f = np.abs(mu) / (2 * np.pi)
        o = np.argsort(f, kind="stable")
        out[n] = (f[o], -mu.real[o] / np.abs(mu[o]))
    return out


def follow_poles(f0, x0, f, xi, tolerance=BOOTSTRAP_TOLERANCE):
    """For each reference pole (f0, x0) the pole (f, xi) nearest in |df|/f0 + |dxi|, NaN where it
    is farther than ``tolerance`` in relative frequency (or there is none)."""
    f0, x0 = np.asarray(f0), np.asarray(x0)
    if len(f) == 0:
        return np.full(f0.size, np.nan), np.full(f0.size, np.nan)
    j = np.argmin(np.abs(f[None, :] / f0[:, None] - 1) + np.abs(xi[None, :] - x0[:, None]), axis=1)
    ok = np.abs(f[j] / f0 - 1) <= tolerance
    return np.where(ok, f[j], np.nan), np.where(ok, xi[j], np.nan)


def bootstrap_std(H, T_H, l, fs, targets, draws):
    """§5.6 by its definition: draw d is H + unvec(T_H eps_d) with eps = rademacher_signs(n_b,
    draws, BOOTSTRAP_SEED); each order of ``targets`` ({order: (f, xi)} of the record's poles) is
    identified from the draw's SVD (:func:`poles_at_orders`), each pole follows the draw's pole
    nearest in |df|/f + |dxi| when within BOOTSTRAP_TOLERANCE in f (:func:`follow_poles`), and its
    sigma is 1.4826 times the median absolute deviation from the median of the followed values
    (NaN when fewer than ceil(0.8 draws) followed).  Returns {order: (sd_f, sd_xi)}."""
    H = np.asarray(H, dtype=np.float64)
    a, b = H.shape
    eps = rademacher_signs(T_H.shape[1], draws, BOOTSTRAP_SEED)
    samples = {n: np.full((len(f), draws, 2), np.nan) for n, (f, _) in targets.items()}
    for d in range(draws):
        drawn = poles_at_orders(H + unvec(T_H @ eps[:, d], a, b), l, fs, targets)
        for n, (f0, x0) in targets.items():
            if len(f0):
                samples[n][:, d, 0], samples[n][:, d, 1] = follow_poles(f0, x0, *drawn[n])
    need = max(int(np.ceil(BOOTSTRAP_MIN_FOLLOWED * draws)), 2)
    out = {}
    for n, smp in samples.items():
        sd = np.full((smp.shape[0], 2), np.nan)
        for i in range(smp.shape[0]):
            v = smp[i][np.isfinite(smp[i, :, 0])]
            if len(v) >= need:
                sd[i] = 1.482602218505602 * np.median(np.abs(v - np.median(v, axis=0)), axis=0)
        out[n] = (sd[:, 0], sd[:, 1])
    return out


# --------------------------------------------------------------------------------------
# §6: J_{(A,C),Gamma}
# --------------------------------------------------------------------------------------
def jacobian_AC_Gamma(Gamma, l):
    """Explicit [J_{A,Gamma}; J_{C,Gamma}] ((n^2 + l n) x (a n)) of §6, with the
    least-squares residual term E = Gamma_dw - Gamma_up A:

        J_{A,Gamma} = (I_n kron W) [ I_n kron Gamma_up^T S2 - A^T kron Gamma_up^T S1
                                     + (E^T S1 kron I_n) P_{a,n} ],  W = (Gamma_up^T Gamma_up)^{-1}
        J_{C,Gamma} = I_n kron [I_l 0]
    """
    Gamma = np.asarray(Gamma, dtype=np.float64)
    a, n = Gamma.shape
    up, dw = Gamma[:-l], Gamma[l:]
    A, _ = system_matrices(Gamma, l)
    W = np.linalg.inv(up.T @ up)
    E = dw - up @ A
    In = np.eye(n)
    S1 = np.hstack([np.eye(a - l), np.zeros((a - l, l))])
    S2 = np.hstack([np.zeros((a - l, l)), np.eye(a - l)])
    inner = (np.kron(In, up.T @ S2) - np.kron(A.T, up.T @ S1)
             + np.kron(E.T @ S1, In) @ commutation_matrix(a, n))
    JA = np.kron(In, W) @ inner
    JC = np.kron(In, np.hstack([np.eye(l), np.zeros((l, a - l))]))
    return np.vstack([JA, JC])


# --------------------------------------------------------------------------------------
# §2.3, §7: modal parameters and J_{theta,(A,C)}
# --------------------------------------------------------------------------------------
def modes(A, C, fs, ref_index=None):
    """Modal parameters of (A, C) (§2.3, conventions "Identification").

    Eigenvalues lambda of A with Im lambda > 0 (real ones dropped), mu = ln(lambda) fs,
    f = |mu|/(2 pi), xi = -Re mu/|mu|; mode shape phi = C phi_r normalised so that
    component k (largest modulus on this estimate, or ``ref_index`` when given: an int for
    all modes or one index per mode in frequency order) is exactly 1.  Sorted by frequency.

    Returns a dict with eigenvalues, frequency_hz, damping_ratio, mode_shape (l x nm),
    ref_index (nm,), and the raw eigentriples 'right' (n x nm, phi), 'left' (n x nm, chi
    with chi^H A = lambda chi^H) and 'mode_shape_raw' (C phi, unnormalised).
    """
    A = np.asarray(A, dtype=np.float64)
    C = np.asarray(C, dtype=np.float64)
    w, vl, vr = scipy.linalg.eig(A, left=True, right=True)
    keep = np.flatnonzero(w.imag > 0)
    lam = w[keep]
    mu = np.log(lam) * fs
    freq = np.abs(mu) / (2 * np.pi)
    order = np.argsort(freq, kind="stable")
    keep, lam, mu, freq = keep[order], lam[order], mu[order], freq[order]
    damp = -mu.real / np.abs(mu)
    right = vr[:, keep]
    left = vl[:, keep]
    raw = C @ right
    nm = len(keep)
    if ref_index is None:
        k = np.argmax(np.abs(raw), axis=0) if nm else np.zeros(0, dtype=int)
    else:
        k = np.broadcast_to(np.asarray(ref_index, dtype=int), (nm,)).copy()
    shape = np.empty_like(raw)
    for i in range(nm):
        shape[:, i] = raw[:, i] / raw[k[i], i]
        shape[k[i], i] = 1.0
    return {
        "eigenvalues": lam,
        "frequency_hz": freq,
        "damping_ratio": damp,
        "mode_shape": shape,
        "ref_index": np.asarray(k, dtype=int),
        "right": right,
        "left": left,
        "mode_shape_raw": raw,
    }


def jacobian_theta_AC(A, C, fs, ref_index=None):
    """Real Jacobians of theta = [f, xi, Re phi~ (l), Im phi~ (l)] w.r.t. [vec A; vec C],
    one ((2 + 2l) x (n^2 + l n)) matrix per mode in the order of :func:`modes` (§7):

        J_lambda = (phi^T kron chi^H)/den,  den = chi^H phi
        J_mu = J_lambda / (lambda tau);  J_(f,xi),mu as in §7 on [Re J_mu; Im J_mu]
        J_phi,A = (lambda I - A)^+ (I - phi chi^H/den)(phi^T kron I_n)   [(.)^+ drops one s.v.]
        J_varphi = [C J_phi,A, phi^T kron I_l]
        J_varphi~ = (1/varphi_k)(I_l - varphi~ e_k^T) J_varphi

    k is the nominal largest-modulus component unless ``ref_index`` is given.
    """
    A = np.asarray(A, dtype=np.float64)
    C = np.asarray(C, dtype=np.float64)
    n = A.shape[0]
    l = C.shape[0]
    tau = 1.0 / fs
    md = modes(A, C, fs, ref_index=ref_index)
    In, Il = np.eye(n), np.eye(l)
    out = []
    for i in range(len(md["eigenvalues"])):
        lam = md["eigenvalues"][i]
        phi = md["right"][:, i]
        chi = md["left"][:, i]
        k = md["ref_index"][i]
        den = chi.conj() @ phi
        # eigenvalue, continuous-time eigenvalue, (f, xi)
        J_lam = np.kron(phi[None, :], chi.conj()[None, :]) / den           # 1 x n^2
        J_mu = J_lam / (lam * tau)
        mu = np.log(lam) * fs
        amu = np.abs(mu)
        J_fxi_mu = np.array([
            [mu.real / (2 * np.pi * amu), mu.imag / (2 * np.pi * amu)],
            [-(mu.imag ** 2) / amu ** 3, mu.real * mu.imag / amu ** 3],
        ])
        J_fxi_A = J_fxi_mu @ np.vstack([J_mu.real, J_mu.imag])             # 2 x n^2
        # eigenvector, mode shape, normalised mode shape
        J_phi_A = (_pinv_drop_one(lam * In - A) @ (In - np.outer(phi, chi.conj()) / den)
                   @ np.kron(phi[None, :], In))                             # n x n^2
        J_vphi = np.hstack([C @ J_phi_A, np.kron(phi[None, :], Il)])        # l x (n^2+ln)
        vphi_k = md["mode_shape_raw"][k, i]
        e_k = np.zeros(l)
        e_k[k] = 1.0
        J_tilde = (Il - np.outer(md["mode_shape"][:, i], e_k)) @ J_vphi / vphi_k
        J = np.vstack([
            np.hstack([J_fxi_A, np.zeros((2, l * n))]),
            J_tilde.real,
            J_tilde.imag,
        ])
        out.append(J)
    return out


# --------------------------------------------------------------------------------------
# §8: full explicit propagation
# --------------------------------------------------------------------------------------
def _orders_list(orders):
    if np.ndim(orders) == 0:
        return [int(orders)]
    return [int(o) for o in orders]


def _identify(y, u, fs, p, q, orders, n_blocks, references, uncertainty, demean, path,
              freeze_noise=True, noise_coupling_limit=20.0, bootstrap_draws=0):
    q = p if q is None else int(q)
    p = int(p)
    orders = _orders_list(orders)
    if not orders:
        raise ValueError("orders is empty")
    y2, u2, ref = _prepare(y, u, references, False)
    l, r = y2.shape[1], len(ref)
    a, b = p * l, q * r
    for n in orders:
        _check_order(n, a, b, l)
    n_max = max(orders)

    cov = covariances(y, u, p, q, n_blocks, references=references, demean=demean)
    R1, R2, R3, R4 = cov["R1"], cov["R2"], cov["R3"], cov["R4"]
    H = subspace_matrix(R1, R2, R3, R4)
    U, s, _ = svd_sorted(H)                    # SVD once (conventions)

    k_star = None
    if uncertainty:
        T_R = cov["T_R"]
        J_HR = jacobian_H_R(R1, R2, R3, R4)
        k_star, _ = noise_floor(H, J_HR @ T_R, n_max + 1)
        # Both propagations of §5.5: plain ("base") and with the columns j >= k* frozen.
        variants = {"base": jacobian_Gamma_H(H, n_max)}  # rows of order n = leading a*n rows (§5.2)
        if freeze_noise and k_star < n_max:
            variants["frozen"] = jacobian_Gamma_H(H, n_max, frozen_from=k_star)
        Sigma_G, T_G = {}, {}
        for key, J_GH in variants.items():
            if path == "explicit":
                Sigma_R = T_R @ T_R.T
                Sigma_H = J_HR @ Sigma_R @ J_HR.T
                Sigma_G[key] = J_GH @ Sigma_H @ J_GH.T
            else:                               # factor: U_Gamma = J_{Gamma,H} J_{H,R} T_R
                T_G[key] = J_GH @ (J_HR @ T_R)

    result = {}
    for n in orders:
        G = U[:, :n] * np.sqrt(s[:n])
        A, C = system_matrices(G, l)
        md = modes(A, C, fs)
        res = {key: md[key] for key in
               ("frequency_hz", "damping_ratio", "mode_shape", "eigenvalues", "ref_index")}
        if uncertainty:
            J_AC = jacobian_AC_Gamma(G, l)
            J_th = jacobian_theta_AC(A, C, fs, ref_index=md["ref_index"])
            nm, d = len(J_th), 2 + 2 * l
            keys = ["base"] + (["frozen"] if "frozen" in variants and n > k_star else [])
            covs, facs = {}, {}
            for key in keys:
                covs[key] = np.zeros((nm, d, d))
                if path == "explicit":
                    Sigma_AC = J_AC @ Sigma_G[key][:a * n, :a * n] @ J_AC.T
                    for i, J in enumerate(J_th):
                        covs[key][i] = J @ Sigma_AC @ J.T
                else:
                    T_AC = J_AC @ T_G[key][:a * n]
                    facs[key] = np.zeros((nm, d, T_AC.shape[1]))
                    for i, J in enumerate(J_th):
                        facs[key][i] = J @ T_AC
                        covs[key][i] = facs[key][i] @ facs[key][i].T
            # §5.5, eq. 5.14: the frozen covariance unless the noise directions inflate the std
            # of f or xi by more than noise_coupling_limit.
            covm = covs["base"].copy()
            rho = np.ones(nm)
            if "frozen" in covs:
                sd_b = np.sqrt(np.clip(np.diagonal(covs["base"], axis1=1, axis2=2)[:, :2], 0, None))
                sd_f = np.sqrt(np.clip(np.diagonal(covs["frozen"], axis1=1, axis2=2)[:, :2], 0, None))
                rho = noise_coupling(sd_b, sd_f)
                use = rho <= noise_coupling_limit
                covm[use] = covs["frozen"][use]
                if path != "explicit":
                    facs["base"][use] = facs["frozen"][use]
            if path != "explicit":
                res["factor"] = facs["base"]
            res["noise_coupling"] = rho
            res["noise_coupled"] = ~(rho <= noise_coupling_limit)
            var = np.clip(np.diagonal(covm, axis1=1, axis2=2), 0.0, None)   # nm x d
            std = np.sqrt(var)
            res["frequency_std"] = std[:, 0]
            res["damping_std"] = std[:, 1]
            res["mode_shape_std_real"] = std[:, 2:2 + l].T.copy()
            res["mode_shape_std_imag"] = std[:, 2 + l:].T.copy()
            res["covariance"] = covm
            res["significant_singular_values"] = k_star
            res["bootstrapped"] = np.zeros(nm, bool)
        result[n] = res
    if uncertainty and bootstrap_draws:
        _apply_bootstrap(result, H, J_HR @ T_R, l, fs, k_star, bootstrap_draws)
    return result


def _apply_bootstrap(result, H, T_H, l, fs, k_star, draws):
    """§5.6: sigma_f, sigma_xi of the poles above k* (not noise-coupled, followed) from
    :func:`bootstrap_std`; the covariance's f and xi rows and columns (and the factor's rows)
    scaled by sigma_boot / sigma_first_order."""
    targets = {n: (r["frequency_hz"], r["damping_ratio"]) for n, r in result.items()
               if n > k_star and len(r["frequency_hz"])}
    if not targets:
        return
    for n, (sf, sx) in bootstrap_std(H, T_H, l, fs, targets, draws).items():
        r = result[n]
        for i in range(len(sf)):
            if (r["noise_coupled"][i] or not (sf[i] > 0) or not (sx[i] > 0)
                    or not (r["frequency_std"][i] > 0) or not (r["damping_std"][i] > 0)):
                continue
            c = np.ones(2 + 2 * l)
            c[0], c[1] = sf[i] / r["frequency_std"][i], sx[i] / r["damping_std"][i]
            r["covariance"][i] = r["covariance"][i] * np.outer(c, c)
            if "factor" in r:
                r["factor"][i] = r["factor"][i] * c[:, None]
            r["frequency_std"][i], r["damping_std"][i] = sf[i], sx[i]
            r["bootstrapped"][i] = True


def identify(y, u=None, *, fs, block_rows, past_block_rows=None, orders, n_blocks=50,
             references=None, uncertainty=True, demean=True, freeze_noise=True,
             noise_coupling_limit=20.0, bootstrap_draws=0):
    """SSI-cov identification with the **full explicit** delta-method path (§8).

    Sigma_R = T_R T_R^T; Sigma_H = J_{H,R} Sigma_R J_{H,R}^T; Sigma_Gamma =
    J_{Gamma,H} Sigma_H J_{Gamma,H}^T (at the largest order; order n takes the leading
    a*n block); Sigma_{A,C} = J_{AC,Gamma} Sigma_Gamma J_{AC,Gamma}^T; per mode
    Sigma_theta = J_theta Sigma_{A,C} J_theta^T with theta = [f, xi, Re phi~, Im phi~].

    The noise floor k* and the frozen propagation of §5.5 apply as in the core
    (``freeze_noise``, ``noise_coupling_limit``); each order's "significant_singular_values" is k*.
    ``bootstrap_draws`` > 0: sigma_f, sigma_xi above k* from the bootstrap of §5.6
    (:func:`bootstrap_std`), each order's "bootstrapped" saying which.

    Returns {order: dict} with frequency_hz, damping_ratio, mode_shape (l x nm complex),
    eigenvalues, ref_index and, when ``uncertainty``, frequency_std, damping_std,
    mode_shape_std_real (l x nm), mode_shape_std_imag (l x nm), covariance (nm x d x d).
    Raises ValueError for an order outside [1, min((p-1) l, q r)].
    """
    return _identify(y, u, fs, block_rows, past_block_rows, orders, n_blocks, references,
                     uncertainty, demean, "explicit", freeze_noise, noise_coupling_limit, bootstrap_draws)


def identify_factor(y, u=None, *, fs, block_rows, past_block_rows=None, orders, n_blocks=50,
                    references=None, uncertainty=True, demean=True, freeze_noise=True,
                    noise_coupling_limit=20.0, bootstrap_draws=0):
    """Same as :func:`identify` but with the factor formulation (§8): U_theta =
    J_theta J_{AC,Gamma} J_{Gamma,H} J_{H,R} T_R, Sigma_theta = U_theta U_theta^T (std =
    row norms).  Each order's dict also has 'factor' (nm x d x n_blocks).  A second check
    of :func:`identify`; same explicit Jacobians, no Sigma_H formed."""
    return _identify(y, u, fs, block_rows, past_block_rows, orders, n_blocks, references,
                     uncertainty, demean, "factor", freeze_noise, noise_coupling_limit, bootstrap_draws)
