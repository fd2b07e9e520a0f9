"""NumPy reference for multi-setup SSI-cov (issue 23): the modular merge of Döhler & Mevel
(2012) with the first-order covariance of Döhler, Lam & Mevel (2013), output-only and
input/output, and the PoSER comparison path.  Math: docs/uq-math.md §13 (equation numbers
(12.x) below).

Written to be checked, not to be fast, but vectorised over the blocks so that a Monte Carlo
of campaigns runs in minutes:

* each setup's R1..R4 and T_R come from explicit data matrices (same definitions as
  ``oracle.covariances``, vectorised; the tests check they are equal);
* each setup's T_H = J_{H,R} T_R is applied matrix-free (4.1) and checked against
  ``oracle.jacobian_H_R``;
* each setup's dΓ per block uses the SVD-basis form (5.5)-(5.7), checked against
  ``oracle.jacobian_Gamma_H``;
* the merge (13.2)-(13.6), (A, C) (6.1) and the modes (7.1)-(7.6) are differentiated by hand,
  per block, and every stage is checked against central finite differences
  (tests/python/test_multisetup_oracle.py).

The setups are independent, so the factor of the merged result is the horizontal
concatenation of the per-setup factors (13.7): U_θ = [U_θ^(1), …, U_θ^(Ns)], Σ_θ = U_θ U_θᵀ.

Layout (13.1): global DOFs are the r references (in the order of ``references``), then each
setup's other channels in setup order and, within a setup, column order.  ``dofs`` (a list of
(setup, channel) pairs, references attributed to setup 0) names them.
"""

from __future__ import annotations

import os
import sys

import numpy as np
import scipy.linalg

sys.path.insert(0, os.path.dirname(__file__))
import oracle  # noqa: E402

__all__ = [
    "setup_covariances",
    "setup_subspace",
    "gamma_factor",
    "Campaign",
    "merge_gamma",
    "merge_gamma_perturbation",
    "system_perturbation",
    "modal_perturbation",
    "identify_modular",
    "identify_poser",
    "poser_combine",
    "rescale_shapes",
]


# --------------------------------------------------------------------------------------
# one setup: covariances, H, T_H, Γ and dΓ per block
# --------------------------------------------------------------------------------------
def setup_covariances(y, u, p, q, n_blocks, references):
    """R1..R4 and T_R of one setup (uq-math §2.1, §3; conventions), vectorised.

    Same definitions as ``oracle.covariances`` (global means removed, lag 0 excluded, blocks
    of N_b = ⌊N/n_b⌋ columns, T_R centred on the block mean and scaled by 1/√(n_b(n_b−1))).
    """
    y = np.asarray(y, dtype=np.float64)
    y = y - y.mean(axis=0)
    ref = np.asarray(references, dtype=int)
    n_samples, l = y.shape
    N = n_samples - p - q + 1
    Yp = np.vstack([y[q + i:q + i + N].T for i in range(p)])
    Ym = np.vstack([y[j:j + N, ref].T for j in range(q)])
    Up = None
    if u is not None:
        u = np.asarray(u, dtype=np.float64)
        u = u.reshape(n_samples, -1) - u.reshape(n_samples, -1).mean(axis=0)
        Up = np.vstack([u[q + i:q + i + N].T for i in range(p)])
    Nb = N // n_blocks
    if Nb < 1:
        raise ValueError(f"n_blocks={n_blocks} exceeds the number of Hankel columns N={N}")

    def prods(cols):
        n = cols.stop - cols.start
        a, b = Yp[:, cols], Ym[:, cols]
        R = [a @ b.T / n]
        if Up is not None:
            c = Up[:, cols]
            R += [a @ c.T / n, c @ c.T / n, b @ c.T / n]
        return R

    full = prods(slice(0, N))
    rk = np.column_stack([np.concatenate([oracle.vec(X) for X in prods(slice(k * Nb, (k + 1) * Nb))])
                          for k in range(n_blocks)])
    T_R = (rk - rk.mean(axis=1, keepdims=True)) / np.sqrt(n_blocks * (n_blocks - 1))
    out = {"R1": full[0], "R2": None, "R3": None, "R4": None, "T_R": T_R, "N": N, "Nb": Nb}
    if Up is not None:
        out.update(R2=full[1], R3=full[2], R4=full[3])
    return out


def setup_subspace(cov):
    """H (2.2)/(2.3) and T_H = J_{H,R} T_R applied matrix-free (4.1) for one setup."""
    R1, R2, R3, R4, T_R = cov["R1"], cov["R2"], cov["R3"], cov["R4"], cov["T_R"]
    H = oracle.subspace_matrix(R1, R2, R3, R4)
    a, b = R1.shape
    if R2 is None:
        return H, T_R.copy()
    pm = R3.shape[0]
    R3p = oracle._pinv_R3(R3)
    G, M = R2 @ R3p, R3p @ R4.T
    T_H = np.empty((a * b, T_R.shape[1]))
    for k in range(T_R.shape[1]):
        d1, d2, d3, d4 = oracle._unstack_r(T_R[:, k], a, b, pm)
        T_H[:, k] = oracle.vec(d1 - d2 @ M + G @ d3 @ M - G @ d4.T)
    return H, T_H


def gamma_factor(H, T_H, n_max, frozen_from=None):
    """Γ = U_n S_n^{1/2} at n_max (2.5) and its perturbation per block, dΓ (a × n_max × n_b),
    from the SVD-basis form (5.5)-(5.7) (unfrozen: every coupling kept).  With ``frozen_from``
    = k*, returns (Γ, dΓ, dΓ frozen): the columns j ≥ k* keep only their scale, du_j = 0 (5.13)."""
    a, b = H.shape
    U, s, Vt = oracle.svd_sorted(H)
    V = Vt.T
    if n_max > len(s):
        raise ValueError(f"order {n_max} exceeds the rank bound {len(s)} of H")
    Gam = U[:, :n_max] * np.sqrt(s[:n_max])
    if T_H is None:
        return Gam, None
    nb = T_H.shape[1]
    dH = T_H.reshape(b, a, nb).transpose(1, 0, 2)              # column-major unvec per block
    Ua = np.einsum("ai,abk,bj->ijk", U, dH, V)                 # d × d × n_b, Ua_ij = u_iᵀ dH v_j
    d = len(s)
    num = s[None, :, None] * Ua + s[:, None, None] * Ua.transpose(1, 0, 2)
    den = s[None, :] ** 2 - s[:, None] ** 2
    np.fill_diagonal(den, 1.0)
    Om = num / den[:, :, None]
    Om[np.arange(d), np.arange(d), :] = 0.0                     # (5.5), Ω_jj = 0
    Om = Om[:, :n_max, :]
    dHv = np.einsum("abk,bj->ajk", dH, V[:, :n_max])            # dH v_j
    du = (np.einsum("ai,ijk->ajk", U, Om)
          + (dHv - np.einsum("ai,ijk->ajk", U, Ua[:, :n_max, :])) / s[None, :n_max, None])   # (5.6)
    ds = np.einsum("jjk->jk", Ua[:n_max, :n_max, :])
    scale = U[:, :n_max, None] * (ds / (2 * np.sqrt(s[:n_max, None])))[None]
    dG = scale + np.sqrt(s[None, :n_max, None]) * du                                       # (5.3)
    if frozen_from is None:
        return Gam, dG
    du[:, frozen_from:, :] = 0.0                                                           # (5.13)
    return Gam, dG, scale + np.sqrt(s[None, :n_max, None]) * du


# --------------------------------------------------------------------------------------
# the campaign: layout of the global DOFs, one entry per setup
# --------------------------------------------------------------------------------------
class Campaign:
    """Per-setup Γ and dΓ (at n_max) and the global layout (13.1).

    ``setups``: list of dicts with keys "H" (a_j × b), "T_H" (h_j × n_b,j or None),
    "n_channels" l_j, "references" (the r channel indices of the references in this setup,
    in the global reference order).  Setup 0 is the basis setup (13.2).
    """

    def __init__(self, setups, p, n_max, uncertainty=True, pool_references=False, freeze_noise=False,
                 noise_floor_factor=1.5):
        self.p = int(p)
        self.pool = bool(pool_references)
        self.n_max = int(n_max)
        self.r = len(setups[0]["references"])
        self.setups = []
        self.dofs = [(0, int(c)) for c in setups[0]["references"]]
        for j, st in enumerate(setups):
            refs = np.asarray(st["references"], dtype=int)
            if len(refs) != self.r:
                raise ValueError(f"setup {j}: {len(refs)} references, expected {self.r}")
            l = int(st["n_channels"])
            mov = np.array([c for c in range(l) if c not in set(refs.tolist())], dtype=int)
            T_H = st.get("T_H") if uncertainty else None
            # §13.4: each setup's own noise floor k*_j (5.10)-(5.12), its columns j >= k*_j frozen
            k_star = self.n_max + 1
            if freeze_noise and T_H is not None:
                k_star = oracle.noise_floor(st["H"], T_H, self.n_max + 1, factor=noise_floor_factor)[0]
            if k_star < self.n_max:
                Gam, dG, dGf = gamma_factor(st["H"], T_H, self.n_max, frozen_from=k_star)
            else:
                Gam, dG = gamma_factor(st["H"], T_H, self.n_max)
                dGf = dG
            rows_ref = (np.arange(self.p)[:, None] * l + refs[None, :]).ravel()
            rows_mov = (np.arange(self.p)[:, None] * l + mov[None, :]).ravel()
            self.setups.append({"Gamma": Gam, "dGamma": dG, "dGamma_frozen": dGf, "k_star": k_star,
                                "l": l, "rows_ref": rows_ref,
                                "rows_mov": rows_mov, "n_mov": len(mov)})
            self.dofs += [(j, int(c)) for c in mov]
        self.l_g = len(self.dofs)
        # (13.11) with pool_references, the reference rows of setups j >= 1 (normalised) are
        # extra rows of each block row, after the l_g DOFs: they enter A, not C.
        self.l_A = self.l_g + (len(self.setups) - 1) * self.r * self.pool
        # global rows: block row i, column g -> i*l_A + g
        off = self.r
        for st in self.setups:
            g = off + np.arange(st["n_mov"])
            st["grows_mov"] = (np.arange(self.p)[:, None] * self.l_A + g[None, :]).ravel()
            off += st["n_mov"]
        for st in self.setups[1:]:
            g = off + np.arange(self.r)
            st["grows_refx"] = (np.arange(self.p)[:, None] * self.l_A + g[None, :]).ravel() if self.pool else None
            off += self.r * self.pool
        self.grows_ref = (np.arange(self.p)[:, None] * self.l_A + np.arange(self.r)[None, :]).ravel()
        limit = min(self.p * self.r, (self.p - 1) * self.l_g,
                    *[st["Gamma"].shape[1] for st in self.setups])
        if self.n_max > limit:
            raise ValueError(f"order {self.n_max} exceeds min(p·r, (p−1)·l_g, setup ranks) = {limit}")

    @property
    def n_columns(self):
        """Columns of the concatenated factor, Σ_j n_b,j (13.7)."""
        return sum(st["dGamma"].shape[2] for st in self.setups)


def merge_gamma(camp, n):
    """Global Γ_g at order n (13.2)-(13.4): basis B = Γ^(0)_ref, T_j = (Γ^(j)_ref)^† B,
    moving rows Γ^(j)_mov T_j, references once (from the basis setup)."""
    B = camp.setups[0]["Gamma"][camp.setups[0]["rows_ref"], :n]
    G = np.zeros((camp.p * camp.l_A, n))
    G[camp.grows_ref] = B
    for j, st in enumerate(camp.setups):
        X = st["Gamma"][st["rows_ref"], :n]
        T = np.linalg.lstsq(X, B, rcond=None)[0]
        G[st["grows_mov"]] = st["Gamma"][st["rows_mov"], :n] @ T
        if camp.pool and j > 0:
            G[st["grows_refx"]] = X @ T
    return G


def merge_gamma_perturbation(camp, n, frozen=False, sketch=None):
    """dΓ_g per block column of the concatenated factor (13.5)-(13.7): a list with, per
    setup j, the (a_g × n × n_b,j) perturbation of Γ_g caused by setup j's blocks; ``frozen``:
    from each setup's frozen dΓ (§13.4); ``sketch``: per setup j an (n_b,j × s_j) matrix whose
    columns combine its blocks (the noise-coupling test's sketch), the result then per column."""
    s0 = camp.setups[0]
    B = s0["Gamma"][s0["rows_ref"], :n]
    pre = []
    for st in camp.setups:
        X = st["Gamma"][st["rows_ref"], :n]
        W = np.linalg.inv(X.T @ X)
        T = W @ (X.T @ B)
        pre.append({"X": X, "W": W, "T": T, "E": B - X @ T, "Gm": st["Gamma"][st["rows_mov"], :n]})
    out = []
    for j, st in enumerate(camp.setups):
        dG = st["dGamma_frozen" if frozen else "dGamma"][:, :n, :]
        if sketch is not None:
            dG = np.einsum("ank,kt->ant", dG, sketch[j])
        nb = dG.shape[2]
        D = np.zeros((camp.p * camp.l_A, n, nb))
        dX = dG[st["rows_ref"]]
        if j == 0:
            # basis setup: dB enters the reference rows and every T_i (13.6); T_0 ≡ I.
            D[camp.grows_ref] = dX
            D[st["grows_mov"]] = dG[st["rows_mov"]]
            for i in range(1, len(camp.setups)):
                P = pre[i]
                XpGm = P["Gm"] @ P["W"] @ P["X"].T                  # Γ^(i)_mov X_i^†
                D[camp.setups[i]["grows_mov"]] += np.einsum("ar,rnk->ank", XpGm, dX)
                if camp.pool:                                       # d(X_i T_i) = X_i X_i^† dB
                    XXp = P["X"] @ P["W"] @ P["X"].T
                    D[camp.setups[i]["grows_refx"]] += np.einsum("ar,rnk->ank", XXp, dX)
        else:
            P = pre[j]
            # dT_j = −X^† dX T + W dXᵀ E (13.5), the second term the least-squares residual's
            dT = (-np.einsum("nr,rmk,ml->nlk", P["W"] @ P["X"].T, dX, P["T"])
                  + np.einsum("nm,rmk,rl->nlk", P["W"], dX, P["E"]))
            D[st["grows_mov"]] = (np.einsum("amk,mn->ank", dG[st["rows_mov"]], P["T"])
                                  + np.einsum("am,mnk->ank", P["Gm"], dT))
            if camp.pool:                                           # d(X_j T_j)
                D[st["grows_refx"]] = (np.einsum("amk,mn->ank", dX, P["T"])
                                       + np.einsum("am,mnk->ank", P["X"], dT))
        out.append(D)
    return out


# --------------------------------------------------------------------------------------
# (A, C) and the modes, per block (uq-math §6-§7), for any Γ (here the global one)
# --------------------------------------------------------------------------------------
def system_perturbation(Gam, dGam, l, l_out=None):
    """A, C (2.6)-(2.7) and dA, dC per block from (6.1)-(6.2), residual term included.
    Block rows have l rows; C is the first ``l_out`` (default l) rows of the first one."""
    l_out = l if l_out is None else l_out
    up, dw = Gam[:-l], Gam[l:]
    A = np.linalg.lstsq(up, dw, rcond=None)[0]
    C = Gam[:l_out].copy()
    W = np.linalg.inv(up.T @ up)
    E = dw - up @ A
    dup, ddw = dGam[:-l], dGam[l:]
    rhs = (np.einsum("an,amk->nmk", up, ddw) - np.einsum("an,amk,ml->nlk", up, dup, A)
           + np.einsum("amk,al->mlk", dup, E))
    dA = np.einsum("nm,mlk->nlk", W, rhs)
    return A, C, dA, dGam[:l_out]


def modal_perturbation(A, C, dA, dC, fs, ref_index=None):
    """Modes of (A, C) (``oracle.modes``) and the factor rows [df; dξ; Re dϕ̃; Im dϕ̃] per
    mode and block, (7.1)-(7.6) with dφ = (λI − A)^+(I − φχᴴ/den) dA φ (§8's form)."""
    md = oracle.modes(A, C, fs, ref_index=ref_index)
    n, l = A.shape[0], C.shape[0]
    nm = len(md["eigenvalues"])
    fac = np.zeros((nm, 2 + 2 * l, dA.shape[2]))
    for i in range(nm):
        lam, phi, chi = md["eigenvalues"][i], md["right"][:, i], md["left"][:, i]
        k = md["ref_index"][i]
        den = chi.conj() @ phi
        dAphi = np.einsum("nmk,m->nk", dA, phi)
        dlam = chi.conj() @ dAphi / den
        dmu = fs * dlam / lam
        mu = np.log(lam) * fs
        amu = abs(mu)
        df = (mu.real * dmu.real + mu.imag * dmu.imag) / (2 * np.pi * amu)
        dxi = (-(mu.imag ** 2) * dmu.real + mu.real * mu.imag * dmu.imag) / amu ** 3
        Pinv = oracle._pinv_drop_one(lam * np.eye(n) - A)
        dphi = Pinv @ (dAphi - np.outer(phi, chi.conj() @ dAphi) / den)
        dvphi = C @ dphi + np.einsum("lnk,n->lk", dC, phi)
        vk = md["mode_shape_raw"][k, i]
        dt = (dvphi - np.outer(md["mode_shape"][:, i], dvphi[k])) / vk
        dt[k] = 0.0
        fac[i] = np.vstack([df[None], dxi[None], dt.real, dt.imag])
    return md, fac


def _summaries(res, fac, l):
    cov = np.einsum("mak,mbk->mab", fac, fac)
    std = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
    res.update(factor=fac, covariance=cov, frequency_std=std[:, 0], damping_std=std[:, 1],
               mode_shape_std_real=std[:, 2:2 + l].T.copy(), mode_shape_std_imag=std[:, 2 + l:].T.copy())
    return res


# --------------------------------------------------------------------------------------
# the modular merge, all orders
# --------------------------------------------------------------------------------------
def prepare_setups(records, p, q, n_blocks, references):
    """Per-setup {H, T_H, n_channels, references} from data records.

    ``records``: list of (y_j, u_j or None) with y_j (n_samples_j, l_j); ``references``: per
    setup, the r channel indices of the references in the global reference order;
    ``n_blocks``: an int or one per setup."""
    nbs = np.broadcast_to(np.asarray(n_blocks), (len(records),))
    out = []
    for (y, u), refs, nb in zip(records, references, nbs):
        cov = setup_covariances(y, u, p, q, int(nb), refs)
        H, T_H = setup_subspace(cov)
        out.append({"H": H, "T_H": T_H, "n_channels": np.asarray(y).reshape(len(y), -1).shape[1],
                    "references": list(refs)})
    return out


COUPLING_SKETCH_SEED = 0x736B65746368  # "sketch", the core's detail::kCouplingSketchSeed


def coupling_sketch_matrices(n_blocks, s):
    """Per setup j the (n_b,j × s_j) sketch of the noise-coupling test (§13.4): s_j = min(s, n_b,j)
    Rademacher columns / √s_j from seed COUPLING_SKETCH_SEED + j, the identity if s ≥ n_b,j."""
    out = []
    for j, nb in enumerate(n_blocks):
        sj = min(int(s), int(nb))
        out.append(oracle.rademacher_signs(nb, sj, COUPLING_SKETCH_SEED + j) / np.sqrt(sj) if sj < nb
                   else np.eye(nb))
    return out


def identify_modular(setups, *, fs, p, orders, ref_index=None, uncertainty=True,
                     pool_references=False, freeze_noise=False, noise_floor_factor=1.5,
                     noise_coupling_limit=20.0, coupling_sketch=0):
    """Modular multi-setup identification at every order (13.2)-(13.7).

    ``setups`` as for :class:`Campaign` (e.g. from :func:`prepare_setups`).  Returns
    ({order: result}, campaign).  Each result has frequency_hz, damping_ratio, mode_shape
    (l_g × nm, normalised to 1 at ref_index, the nominal largest component by default),
    eigenvalues, ref_index and, with ``uncertainty``, factor (nm × (2+2l_g) × Σn_b,j),
    covariance, frequency_std, damping_std, mode_shape_std_real/imag.

    ``pool_references``: the normalised reference rows X_j T_j of every setup j ≥ 1 enter the
    estimate of A as extra rows (13.11); C keeps the references once.

    ``freeze_noise`` (the core's default; off here, the unfrozen merge being the reference of
    §13.7): each setup's columns from its own noise floor k*_j on are frozen (§13.4); at an
    order n above some k*_j each mode gets the frozen factor unless its noise coupling ρ (5.14)
    exceeds ``noise_coupling_limit`` (results then carry noise_coupling, noise_coupled).
    ``coupling_sketch`` = s > 0 (the core's default 4): ρ from the unfrozen pass on s signed
    combinations of each setup's blocks, compared with the frozen rows combined alike, and a
    flagged mode's factor is its frozen one times ρ (when some setup has more than s blocks)."""
    orders = [int(o) for o in np.atleast_1d(orders)]
    camp = Campaign(setups, p, max(orders), uncertainty=uncertainty, pool_references=pool_references,
                    freeze_noise=freeze_noise, noise_floor_factor=noise_floor_factor)
    out = {}
    for n in orders:
        Gg = merge_gamma(camp, n)
        if uncertainty:
            dGg = np.concatenate(merge_gamma_perturbation(camp, n), axis=2)
            A, C, dA, dC = system_perturbation(Gg, dGg, camp.l_A, camp.l_g)
            md, fac = modal_perturbation(A, C, dA, dC, fs, ref_index=ref_index)
            rho = np.ones(len(md["frequency_hz"]))
            if any(n > st["k_star"] for st in camp.setups):
                dGf = np.concatenate(merge_gamma_perturbation(camp, n, frozen=True), axis=2)
                _, _, dAf, dCf = system_perturbation(Gg, dGf, camp.l_A, camp.l_g)
                fac_f = modal_perturbation(A, C, dAf, dCf, fs, ref_index=ref_index)[1]
                nbs = [st["dGamma"].shape[2] for st in camp.setups]
                if 0 < coupling_sketch < max(nbs):  # else no setup is sketched: the exact test
                    S = coupling_sketch_matrices(nbs, coupling_sketch)
                    dGs = np.concatenate(merge_gamma_perturbation(camp, n, sketch=S), axis=2)
                    _, _, dAs, dCs = system_perturbation(Gg, dGs, camp.l_A, camp.l_g)
                    fac_s = modal_perturbation(A, C, dAs, dCs, fs, ref_index=ref_index)[1]
                    rho = oracle.noise_coupling(np.linalg.norm(fac_s[:, :2, :], axis=2),
                                                np.linalg.norm(fac_f[:, :2, :] @ scipy.linalg.block_diag(*S), axis=2))
                    fac = fac_f * np.where(rho <= noise_coupling_limit, 1.0, np.minimum(rho, 1e150))[:, None, None]
                else:
                    rho = oracle.noise_coupling(np.linalg.norm(fac[:, :2, :], axis=2),
                                                np.linalg.norm(fac_f[:, :2, :], axis=2))
                    use = rho <= noise_coupling_limit
                    fac = fac.copy()
                    fac[use] = fac_f[use]
        else:
            A = oracle.system_matrices(Gg, camp.l_A)[0]
            C = Gg[:camp.l_g].copy()
            md = oracle.modes(A, C, fs, ref_index=ref_index)
        res = {k: md[k] for k in ("frequency_hz", "damping_ratio", "mode_shape", "eigenvalues",
                                  "ref_index")}
        if uncertainty:
            _summaries(res, fac, camp.l_g)
            res["noise_coupling"] = rho
            res["noise_coupled"] = ~(rho <= noise_coupling_limit)
        out[n] = res
    return out, camp


# --------------------------------------------------------------------------------------
# PoSER: each setup alone, then f, ξ by inverse-variance weights, shapes rescaled
# --------------------------------------------------------------------------------------
def rescale_shapes(shapes, d_shapes, refs_of, mov_of, ref_index=None):
    """Global shape from per-setup shapes (13.9)-(13.10) and its perturbation.

    ``shapes``: per setup, the complex shape (l_j,); ``d_shapes``: per setup, its complex
    perturbation per block (l_j × n_b,j) or None; ``refs_of``/``mov_of``: per setup, the
    reference / moving channel indices.  Setup 0's references are kept; setup j's moving part
    is multiplied by α_j = ϕ_jᴴ b / ϕ_jᴴ ϕ_j (ϕ_j its reference part, b setup 0's), then the
    whole shape is divided by its component ``ref_index`` (the largest by default).
    Returns (shape, list of per-setup perturbations (l_g × n_b,j) or None, ref_index)."""
    b = shapes[0][refs_of[0]]
    parts, alphas = [b], []
    for j, sh in enumerate(shapes):
        ph = sh[refs_of[j]]
        al = (ph.conj() @ b) / (ph.conj() @ ph)
        alphas.append(al)
        parts.append(al * sh[mov_of[j]])
    psi = np.concatenate(parts)
    k = int(np.argmax(np.abs(psi))) if ref_index is None else int(ref_index)
    psit = psi / psi[k]
    if d_shapes is None:
        return psit, None, k
    r = len(b)
    sizes = [len(m) for m in mov_of]
    offs = np.cumsum([r] + sizes)
    out = []
    for j in range(len(shapes)):
        ds = d_shapes[j]
        D = np.zeros((len(psi), ds.shape[1]), dtype=complex)
        if j == 0:
            D[:r] = ds[refs_of[0]]
        for i, sh in enumerate(shapes):
            ph = sh[refs_of[i]]
            nrm = ph.conj() @ ph
            dal = np.zeros(ds.shape[1], dtype=complex)
            if i == j:        # d of ϕ_i (its own references), non-holomorphic: conj enters
                dph = ds[refs_of[i]]
                dal += (dph.conj().T @ b) / nrm - alphas[i] * (dph.conj().T @ ph + ph.conj() @ dph) / nrm
                D[offs[i]:offs[i + 1]] += alphas[i] * ds[mov_of[i]]
            if j == 0:        # d of b (setup 0's references)
                dal += (ph.conj() @ ds[refs_of[0]]) / nrm
            D[offs[i]:offs[i + 1]] += np.outer(sh[mov_of[i]], dal)
        Dt = (D - np.outer(psit, D[k])) / psi[k]
        Dt[k] = 0.0
        out.append(Dt)
    return psit, out, k


def poser_combine(values, factors):
    """Inverse-variance weighted mean (13.8) of per-setup estimates of one scalar with their
    factor rows (1 × n_b,j each); returns (mean, concatenated factor)."""
    var = np.array([f @ f for f in factors])
    w = 1.0 / var
    mean = float(np.sum(w * np.asarray(values)) / w.sum())
    return mean, np.concatenate([wi / w.sum() * f for wi, f in zip(w, factors)])


def identify_poser(setups, *, fs, p, order, targets, ref_index=None, tol=0.05):
    """PoSER at one order: each setup identified alone (a one-setup modular run is exactly
    the single-setup SSI-cov), modes matched to ``targets`` (Hz) by nearest frequency within
    ``tol`` (relative), f and ξ combined by inverse-variance weights (13.8), shapes rescaled on
    the references (13.9)-(13.10).  Returns a dict like :func:`identify_modular`'s results,
    with NaN for a target missing in some setup, and the global ``dofs`` of the modular layout.
    """
    per = []
    for st in setups:
        res, _ = identify_modular([st], fs=fs, p=p, orders=[order])
        per.append(res[order])
    camp = Campaign(setups, p, order, uncertainty=False)
    # a one-setup run returns its shape in the layout (13.1): references first, then the rest
    r = camp.r
    refs_of = [np.arange(r) for _ in setups]
    mov_of = [r + np.arange(st["n_channels"] - r) for st in setups]
    l_g, nt = camp.l_g, len(targets)
    K = sum(r["factor"].shape[2] for r in per)
    out = {"frequency_hz": np.full(nt, np.nan), "damping_ratio": np.full(nt, np.nan),
           "mode_shape": np.full((l_g, nt), np.nan + 0j), "factor": np.zeros((nt, 2 + 2 * l_g, K)),
           "ref_index": np.zeros(nt, dtype=int), "dofs": camp.dofs}
    for t, f0 in enumerate(targets):
        idx = []
        for r in per:
            if len(r["frequency_hz"]) == 0:
                break
            i = int(np.argmin(np.abs(r["frequency_hz"] - f0)))
            if abs(r["frequency_hz"][i] / f0 - 1) > tol:
                break
            idx.append(i)
        if len(idx) != len(per):
            continue
        f, Uf = poser_combine([r["frequency_hz"][i] for r, i in zip(per, idx)],
                              [r["factor"][i, 0] for r, i in zip(per, idx)])
        x, Ux = poser_combine([r["damping_ratio"][i] for r, i in zip(per, idx)],
                              [r["factor"][i, 1] for r, i in zip(per, idx)])
        shapes, dshapes = [], []
        for r, i, st in zip(per, idx, setups):
            l = st["n_channels"]
            shapes.append(r["mode_shape"][:, i])
            dshapes.append(r["factor"][i, 2:2 + l] + 1j * r["factor"][i, 2 + l:])
        ki = None if ref_index is None else ref_index[t]
        psi, dpsi, k = rescale_shapes(shapes, dshapes, refs_of, mov_of, ki)
        dpsi = np.concatenate(dpsi, axis=1)
        out["frequency_hz"][t], out["damping_ratio"][t] = f, x
        out["mode_shape"][:, t], out["ref_index"][t] = psi, k
        out["factor"][t] = np.vstack([Uf[None], Ux[None], dpsi.real, dpsi.imag])
    return _summaries(out, out["factor"], l_g)


def eig_sorted_check(A):
    """Eigenvalues of A with Im > 0 sorted by |ln λ| (a helper for the tests)."""
    w = scipy.linalg.eigvals(A)
    w = w[w.imag > 0]
    return w[np.argsort(np.abs(np.log(w)))]
