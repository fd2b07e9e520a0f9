"""Part 4: is the block covariance of H biased when the known input carries (nearly) all the
excitation (unknown_input_std = 0)?

Fixed directions g_m = d f_m / d H (order 12, modes 1..6) from one long reference record.
The linearised influence of Hankel column c on H is exactly the outer product
(y+_c - G u+_c)(y-_c - M^T u+_c)^T (G = R2 R3^+, M = R3^+ R4^T), so along g_m
  <g_m, H> = mean_c z_c,  z_c = (y+_c - G u+_c)^T g_m (y-_c - M^T u+_c),
and the core's block estimate of var<g_m, H> is var over blocks of the block means of z / n_b.
We compare, over records, the mean block estimate (n_b = 25, 50, 100, 200) with the Monte Carlo
variance of <g_m, H>, and average the autocovariance of z_c over records.

usage: OPENBLAS_NUM_THREADS=1 nice -n 10 python3 hcov.py N_RECORDS OUT.npz [unknown_input_std] [REFERENCE_SAMPLES]
(the reference record: 400_000 samples by default)
"""
import sys
import time
import warnings

import numpy as np
from prop import Record, covariances, grad_H, hankel

import modaluq

warnings.simplefilter("ignore")
P = 15
NBS = (25, 50, 100, 200)
MAXLAG = 1200


def main():
    n_rec = int(sys.argv[1])
    out = sys.argv[2]
    uis = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    n_ref = int(sys.argv[4]) if len(sys.argv) > 4 else 400_000
    t0 = time.process_time()
    ref = modaluq.simulate(n_ref, seed=987654, unknown_input_std=uis)
    Href, dHref = covariances(ref.y, ref.u, P, P, 50)
    rec = Record(Href, dHref, 3, ref.fs)
    md = rec.order(12)
    assert len(md["f"]) == 6, md["f"]
    g = np.stack([grad_H(rec, 12, gr["Ff"], gr["Fdf"]) for gr in md["grads"]])   # (6, a, b)
    print("reference f", md["f"], file=sys.stderr)
    proj = np.full((n_rec, 6), np.nan)           # <g_m, H> per record
    blockvar = np.full((n_rec, len(NBS), 6), np.nan)
    acov = np.zeros((6, MAXLAG + 1))
    NBIN = 400
    pgram = np.zeros((6, NBIN))            # mean periodogram |FFT(z - mean z)|^2 / N at bins 0..NBIN-1 (bin k: k/N cycles per column)
    for k in range(n_rec):
        sim = modaluq.simulate(10_000, seed=np.random.SeedSequence(0, spawn_key=(k,)), unknown_input_std=uis)
        Yp, Ym, Up = hankel(sim.y, sim.u, P, P)
        N = Yp.shape[1]
        R2 = Yp @ Up.T / N
        R3 = Up @ Up.T / N
        R4 = Ym @ Up.T / N
        R3p = np.linalg.pinv(R3, rtol=1e-10)
        Yf = Yp - (R2 @ R3p) @ Up               # y+ - G u+
        Yb = Ym - (R4 @ R3p) @ Up               # y- - M^T u+
        z = np.einsum("ac,mab,bc->mc", Yf, g, Yb)   # (6, N)
        proj[k] = z.mean(axis=1)
        for t, nb in enumerate(NBS):
            Nb = N // nb
            zb = z[:, :nb * Nb].reshape(6, nb, Nb).mean(axis=2)
            blockvar[k, t] = zb.var(axis=1, ddof=1) / nb
        zc = z - z.mean(axis=1, keepdims=True)
        F = np.fft.rfft(zc, 2 * N, axis=1)
        ac = np.fft.irfft(F * F.conj(), axis=1)[:, :MAXLAG + 1] / N
        acov += ac
        pgram += (np.abs(np.fft.rfft(zc, axis=1)[:, :NBIN]) ** 2) / N
        if (k + 1) % 25 == 0:
            print(f"{k + 1} records, cpu {time.process_time() - t0:.0f} s", file=sys.stderr, flush=True)
    acov /= n_rec
    pgram /= n_rec
    np.savez(out, pgram=pgram, proj=proj, blockvar=blockvar, acov=acov, nbs=NBS, f_ref=md["f"], N=N,
             unknown_input_std=uis)


if __name__ == "__main__":
    main()
