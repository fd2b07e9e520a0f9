"""NumPy re-implementation of modaluq's first-order chain in the SVD basis, with full
control of the singular-vector couplings Omega_ij (diagnosis of issue #11).

Formulas: uq-math §2-§9 and cpp/include/modaluq/uncertainty.hpp (svd_perturbation):
  Omega_ij = (s_j Ua_ij + s_i Ua_ji) / (s_j^2 - s_i^2),  Ua = U^T dH V,  i != j
  du_j = U Omega_j  (H is square here: a = b = r, so dH v_j / s_j lies in span U)
  dgamma_j = u_j ds_j / (2 sqrt s_j) + sqrt(s_j) du_j,  ds_j = Ua_jj
  dA = W [Gamma_up^T (dGamma_dw - dGamma_up A) + dGamma_up^T E]
  dlambda = chi^H dA phi / chi^H phi
All quantities are linear in (Omega, ds); for each mode we build the real gradient
F (r x n) of f (and of xi) w.r.t. Omega[:, :n] and Fd (n) w.r.t. ds, so that the block-k
perturbation is df_k = sum_ij F_ij Omega^k_ij + sum_j Fd_j ds^k_j, sigma_f^2 = sum_k df_k^2.
"""
import numpy as np
import scipy.linalg


def hankel(y, u, p, q):
    y = y - y.mean(axis=0)
    N = y.shape[0] - p - q + 1
    Yp = np.vstack([y[q + i:q + i + N].T for i in range(p)])
    Ym = np.vstack([y[j:j + N].T for j in range(q)])
    Up = None
    if u is not None:
        u = u - u.mean(axis=0)
        Up = np.vstack([u[q + i:q + i + N].T for i in range(p)])
    return Yp, Ym, Up


def covariances(y, u, p, q, nb):
    """H and the block perturbations dH^k (nb, a, b) scaled so that Sigma_H = sum_k vec dH^k vec dH^k^T
    (T_H = J_{H,R} T_R, T_R centred on the block mean and divided by sqrt(nb (nb-1)))."""
    Yp, Ym, Up = hankel(y, u, p, q)
    a, N = Yp.shape
    b = Ym.shape[0]
    Nb = N // nb
    sl = slice(0, nb * Nb)
    Ypb = Yp[:, sl].reshape(a, nb, Nb)
    Ymb = Ym[:, sl].reshape(b, nb, Nb)
    R1 = Yp @ Ym.T / N
    R1k = np.einsum("akt,bkt->kab", Ypb, Ymb) / Nb
    scale = 1.0 / np.sqrt(nb * (nb - 1))
    d1 = (R1k - R1k.mean(axis=0)) * scale
    if Up is None:
        return R1, d1
    pm = Up.shape[0]
    Upb = Up[:, sl].reshape(pm, nb, Nb)
    R2 = Yp @ Up.T / N
    R3 = Up @ Up.T / N
    R4 = Ym @ Up.T / N
    R3p = np.linalg.pinv(R3, rtol=1e-10)
    G = R2 @ R3p
    M = R3p @ R4.T
    H = R1 - G @ R4.T
    R2k = np.einsum("akt,bkt->kab", Ypb, Upb) / Nb
    R3k = np.einsum("akt,bkt->kab", Upb, Upb) / Nb
    R4k = np.einsum("akt,bkt->kab", Ymb, Upb) / Nb
    d2 = (R2k - R2k.mean(axis=0)) * scale
    d3 = (R3k - R3k.mean(axis=0)) * scale
    d4 = (R4k - R4k.mean(axis=0)) * scale
    dH = d1 - d2 @ M + G @ d3 @ M - G @ np.transpose(d4, (0, 2, 1))
    return H, dH


def svd_sorted(H):
    U, s, Vt = np.linalg.svd(H)
    for j in range(len(s)):
        if U[np.argmax(np.abs(U[:, j])), j] < 0:
            U[:, j] *= -1
            Vt[j] *= -1
    return U, s, Vt.T


class Record:
    """SVD of H and the SVD-basis perturbation of every block."""

    def __init__(self, H, dH, l, fs):
        self.H, self.l, self.fs = H, l, fs
        a, b = H.shape
        assert a == b, "square H assumed (a = b)"
        self.U, self.s, self.V = svd_sorted(H)
        U, s, V = self.U, self.s, self.V
        self.Ua = np.einsum("ai,kab,bj->kij", U, dH, V)          # (nb, r, r): u_i^T dH v_j
        self.ds = np.einsum("kii->ki", self.Ua)                  # (nb, r)
        sj2 = s[None, :] ** 2
        si2 = s[:, None] ** 2
        den = sj2 - si2
        np.fill_diagonal(den, np.inf)
        # Omega_ij = (s_j Ua_ij + s_i Ua_ji) / (s_j^2 - s_i^2)
        self.Om = (s[None, None, :] * self.Ua + s[None, :, None] * np.transpose(self.Ua, (0, 2, 1))) / den[None]
        # std of s_i - s_j from the blocks (as the core's singular_value_gap)
        D = self.ds[:, :, None] - self.ds[:, None, :]
        self.gap_std = np.sqrt(np.sum(D ** 2, axis=0))           # (r, r)
        self.s_std = np.sqrt(np.sum(self.ds ** 2, axis=0))
        self.gap_z = np.abs(s[:, None] - s[None, :]) / np.where(self.gap_std > 0, self.gap_std, np.inf)

    def cut_gap(self, n):
        s = self.s
        return (s[n - 1] - s[n]) / self.gap_std[n - 1, n]

    def order(self, n):
        """Modes at order n and, per mode, the gradients of f and xi w.r.t. Omega[:, :n] and ds[:n]."""
        U, s, l, fs = self.U, self.s, self.l, self.fs
        a = U.shape[0]
        sq = np.sqrt(s[:n])
        G = U[:, :n] * sq
        up, dw = G[:-l], G[l:]
        A = np.linalg.lstsq(up, dw, rcond=None)[0]
        W = np.linalg.inv(up.T @ up)
        E = dw - up @ A
        w, vl, vr = scipy.linalg.eig(A, left=True, right=True)
        keep = np.flatnonzero(w.imag > 0)
        lam = w[keep]
        mu = np.log(lam) * fs
        f = np.abs(mu) / (2 * np.pi)
        o = np.argsort(f)
        keep, lam, mu, f = keep[o], lam[o], mu[o], f[o]
        xi = -mu.real / np.abs(mu)
        mu_all = np.log(w.astype(complex)) * fs
        cond = np.array([np.linalg.norm(vl[:, kk]) * np.linalg.norm(vr[:, kk]) / abs(vl[:, kk].conj() @ vr[:, kk])
                         for kk in keep])
        dist = np.array([np.min(np.abs(np.delete(mu_all, kk) - mu_all[kk])) / (2 * np.pi) for kk in keep])
        out = []
        for i in range(len(keep)):
            phi = vr[:, keep[i]]
            chi = vl[:, keep[i]]
            den = chi.conj() @ phi
            psi = W @ chi                        # chi^H W = psi^H (W symmetric)
            gu = up @ psi.conj()                 # Gamma_up conj(psi)
            GG = np.zeros((a, n), dtype=complex)  # d lambda = sum(GG * dGamma)
            GG[l:] += np.outer(gu, phi)
            GG[:-l] += -lam[i] * np.outer(gu, phi) + np.outer(E @ phi, psi.conj())
            GG /= den
            GX = U.T @ GG                        # dGamma = U X
            c_f = np.conj(mu[i]) / (2 * np.pi * np.abs(mu[i])) * fs / lam[i]
            c_x = fs / lam[i]
            amu = np.abs(mu[i])
            GXf = np.real(c_f * GX)
            # xi: d xi = Im(mu) Im(conj(mu) d mu) / |mu|^3
            GXx = mu[i].imag * np.imag(np.conj(mu[i]) * c_x * GX) / amu ** 3
            # X = Omega[:, :n] S^1/2 + diag(ds / (2 sqrt s)) on the leading n rows
            Ff = GXf * sq[None, :]
            Fx = GXx * sq[None, :]
            Fdf = np.diagonal(GXf)[:n] / (2 * sq)
            Fdx = np.diagonal(GXx)[:n] / (2 * sq)
            shape = (self.U[:l, :n] * sq) @ phi
            out.append(dict(Ff=Ff, Fx=Fx, Fdf=Fdf, Fdx=Fdx, shape=shape, phi=phi, chi=chi))
        return dict(f=f, xi=xi, lam=lam, grads=out, cond=cond, dist=dist)

    def perturb(self, n, F, Fd, mask=None):
        """Per-block perturbation (nb,) of a scalar with gradients F (r x n), Fd (n)."""
        Om = self.Om[:, :, :n]
        if mask is not None:
            Om = Om * mask[None, :, :n]
        return np.einsum("kij,ij->k", Om, F) + self.ds[:, :n] @ Fd

    def mask(self, kappa, n=None, across_only=False):
        """1 where the coupling Omega_ij is kept; 0 where |s_i - s_j| < kappa std(s_i - s_j)
        (optionally only for pairs across the cut of order n: j < n <= i)."""
        M = (self.gap_z >= kappa).astype(float)
        if across_only:
            r = len(self.s)
            cross = np.zeros((r, r), bool)
            cross[n:, :n] = True
            cross[:n, n:] = True
            M = np.where(cross, M, 1.0)
        return M


def factors(rec, spec):
    """Elementwise factor (r x r) applied to Omega_ij for a fix variant:
    'base'       : none
    'dK'         : drop pairs with |s_i - s_j| < K std(s_i - s_j)
    'gK'         : floor the gap: |s_i - s_j| -> max(|s_i - s_j|, K std(s_i - s_j)) in Omega's denominator
    'rT'         : cap the first-order std of each rotation Omega_ij (over blocks) at T rad
    """
    if spec == "base":
        return None
    kind, val = spec[0], float(spec[1:])
    gap = np.abs(rec.s[:, None] - rec.s[None, :])
    if kind == "d":
        return (rec.gap_z >= val).astype(float)
    if kind == "g":
        floor = np.maximum(gap, val * rec.gap_std)
        with np.errstate(invalid="ignore", divide="ignore"):
            f = np.where(floor > 0, gap / floor, 1.0)
        np.fill_diagonal(f, 1.0)
        return f
    if kind == "r":
        sd = np.sqrt(np.sum(rec.Om ** 2, axis=0))
        with np.errstate(invalid="ignore", divide="ignore"):
            f = np.minimum(1.0, val / sd)
        f[~np.isfinite(f)] = 1.0
        return f
    raise ValueError(spec)


def grad_H(rec, n, g_f, g_fd):
    """Gradient (a x b) of a scalar with Omega/ds gradients (g_f: r x n, g_fd: n) w.r.t. H:
    d = sum_ij g_f[i,j] Omega_ij + g_fd . ds, Omega from Ua = U^T dH V."""
    s = rec.s
    r = len(s)
    GA = np.zeros((r, r))
    den = s[None, :n] ** 2 - s[:, None] ** 2            # (r, n): s_j^2 - s_i^2
    idx = np.arange(n)
    den[idx, idx] = np.inf
    GA[:, :n] += g_f * s[None, :n] / den                 # d/dUa_ij
    GA[:n, :] += (g_f * s[:, None] / den).T              # d/dUa_ji
    GA[idx, idx] += g_fd
    return rec.U @ GA @ rec.V.T


def dh_norm(rec_dH, draws=20, seed=0):
    """RMS spectral norm of a draw of the estimation error Delta H = sum_k xi_k dH^k, xi ~ N(0, I)
    (Davis-Kahan scale of the perturbation)."""
    rng = np.random.default_rng(seed)
    xs = rng.standard_normal((draws, rec_dH.shape[0]))
    return np.sqrt(np.mean([np.linalg.norm(np.tensordot(x, rec_dH, 1), 2) ** 2 for x in xs]))


def factors2(rec, spec, dnorm=None):
    """More fix variants (factor on Omega_ij, rows i, columns j):
    'cK'  : clusters by chaining adjacent singular values with |s_j - s_j+1| < K std(s_j - s_j+1);
            drop Omega_ij for i, j in the same cluster
    'sC'  : freeze the direction of noise-like kept columns: Omega[:, j] = 0 where s_j < C std(s_j)
    'nK'  : Davis-Kahan scale: drop pairs with |s_i - s_j| < K ||Delta H||_2 (dnorm)
    else  : factors() of prop (base, dK, gK, rT)
    """
    kind, r = spec[0], len(rec.s)
    if kind == "c":
        K = float(spec[1:])
        adj = np.array([rec.gap_z[j, j + 1] for j in range(r - 1)])
        lab = np.concatenate([[0], np.cumsum(adj >= K)])
        return (lab[:, None] != lab[None, :]).astype(float) + np.eye(r)
    if kind == "s":
        C = float(spec[1:])
        f = np.ones((r, r))
        f[:, rec.s < C * rec.s_std] = 0.0
        return f
    if kind == "n":
        K = float(spec[1:])
        gap = np.abs(rec.s[:, None] - rec.s[None, :])
        return (gap >= K * dnorm).astype(float) + np.eye(r)
    return factors(rec, spec)


def trailing_norms(rec, draws=20, seed=0, kmax=None):
    """delta_k = RMS over draws of ||(U^T Delta H V)[k:, k:]||_2, Delta H = sum_b xi_b dH^b, xi ~ N(0, I):
    the size of the estimation error inside the trailing singular subspace from index k (Weyl scale)."""
    rng = np.random.default_rng(seed)
    r = len(rec.s)
    kmax = r if kmax is None else kmax
    xs = rng.standard_normal((draws, rec.Ua.shape[0]))
    D = np.tensordot(xs, rec.Ua, 1)                           # (draws, r, r)
    out = np.full(r, np.nan)
    for k in range(kmax):
        out[k] = np.sqrt(np.mean([np.linalg.norm(D[t, k:, k:], 2) ** 2 for t in range(draws)]))
    return out


def noise_floor(rec, c, delta):
    """k* = first index with s_k < c delta_k (Weyl: s_k not above the estimation error of the trailing block)."""
    below = np.flatnonzero(rec.s < c * delta)
    return int(below[0]) if below.size else len(rec.s)


def factor_noise_columns(rec, kstar):
    """Freeze the direction of noise columns j >= k*: Omega[:, j] = 0 (their couplings to physical
    i < k* are within the kept set at every order n > j and do not change f, xi, shapes)."""
    f = np.ones((len(rec.s), len(rec.s)))
    f[:, kstar:] = 0.0
    return f
