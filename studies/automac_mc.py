"""The σ of the AutoMAC (the MAC between two modes of ONE identification): the independent-shape
approximation modaluq draws (:func:`modaluq.indicators.mac_matrix`) against the exact second-order σ
with the shapes' cross-covariance, and both against Monte Carlo over records.

The core keeps each pole's covariance, not the factor F it is made of (Σ = F Fᵀ, one column per
block), so the cross-covariance F_i F_jᵀ of two modes is unknown to the package; the NumPy
reference ``tests/python/oracle.py`` (``identify_factor``) returns the factors. The paper's 6-DOF
chain at the true order 12 (block_rows 10, n_blocks 50), output-only and input/output.

    OPENBLAS_NUM_THREADS=1 python studies/automac_mc.py 80      # records; ~2 min per configuration

Prints, per pair of modes: the median MAC, its std over records, and the median σ over records
divided by that std, for the approximation (cross term 0) and the exact cross term. docs/shapes.md §6.
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "python"))
import modaluq  # noqa: E402
import oracle  # noqa: E402
from modaluq.indicators import mac_matrix  # noqa: E402

ORDER = 12


def mac_of(z, l):
    a, b = z[:l] + 1j * z[l:2 * l], z[2 * l:3 * l] + 1j * z[3 * l:]
    return abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real)


def exact_std(a, b, joint, h=1e-5):
    """Second-order σ of the MAC (docs/uq-math.md §12) for the joint covariance of [Re a, Im a, Re b, Im b],
    the derivatives by central differences."""
    l = a.size
    z = np.concatenate([a.real, a.imag, b.real, b.imag])
    e = np.eye(z.size) * h
    g = np.array([(mac_of(z + d, l) - mac_of(z - d, l)) / (2 * h) for d in e])
    hess = np.array([[(mac_of(z + di + dj, l) - mac_of(z + di - dj, l) - mac_of(z - di + dj, l)
                       + mac_of(z - di - dj, l)) / (4 * h * h) for dj in e] for di in e])
    hs = hess @ joint
    tr2 = np.sum(hs * hs.T)
    return np.sqrt(max(g @ joint @ g - tr2, 0.0) + 0.5 * tr2)


def run(n_records, with_input, n_samples=20000):
    macs, approx, exact = [], [], []
    for r in range(n_records):
        sim = modaluq.simulate(n_samples, seed=100 + r)
        res = oracle.identify_factor(sim.y, sim.u if with_input else None, fs=sim.fs, block_rows=10,
                                     orders=[ORDER], n_blocks=50)[ORDER]
        factor, phi = res["factor"], res["mode_shape"]
        if phi.shape[1] != 6:
            continue
        mm = mac_matrix(phi, res["covariance"])
        ex = np.zeros((6, 6))
        for i in range(6):
            for j in range(i + 1, 6):
                fa, fb = factor[i][2:], factor[j][2:]
                joint = np.block([[fa @ fa.T, fa @ fb.T], [fb @ fa.T, fb @ fb.T]])
                ex[i, j] = ex[j, i] = exact_std(phi[:, i], phi[:, j], joint)
        macs.append(mm.mac)
        approx.append(mm.std)
        exact.append(ex)
    return np.array(macs), np.array(approx), np.array(exact)


def main(n_records=80, n_samples=20000):
    out = {}
    for name, with_input in (("output-only", False), ("input/output", True)):
        t = time.process_time()
        macs, approx, exact = run(n_records, with_input, n_samples)
        out[name] = (macs, approx, exact)
        print(f"\n{name}: {macs.shape[0]} records, {time.process_time() - t:.0f} CPU s")
        print("| pair | MAC | σ_MC | approx. / σ_MC | exact / σ_MC |\n|---|---|---|---|---|")
        if macs.shape[0] < 2:
            continue
        mc = macs.std(axis=0, ddof=1)
        for i in range(6):
            for j in range(i + 1, 6):
                print(f"| {i + 1}-{j + 1} | {np.median(macs[:, i, j]):.3f} | {mc[i, j]:.2e} | "
                      f"{np.median(approx[:, i, j]) / mc[i, j]:.2f} | {np.median(exact[:, i, j]) / mc[i, j]:.2f} |")
    return out


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 80)
