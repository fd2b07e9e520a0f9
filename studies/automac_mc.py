"""The σ of the AutoMAC (the MAC between two modes of ONE identification) against Monte Carlo:
the exact second-order σ with the shapes' cross-covariance V_i V_jᵀ (``identify(...,
keep_shape_factor=True)``, :func:`modaluq.indicators.mac_matrix` with ``factors``) and the
independent-shape approximation (cross term 0, what the package gives without the factors).

The paper's 6-DOF chain, output-only and input/output, at the true order 12 (block_rows 10,
n_blocks 50, records of ``n_samples``) and in the engineer's call (``identify(y, u, fs,
frequency_range=(1, 20), keep_shape_factor=True).select_modes()``, records of the same length),
with the default representative of each cluster and with ``representative="lowest"``.
The core's factors equal the NumPy reference's (``tests/python/oracle.py`` ``identify_factor``;
tests/python/test_indicators.py).

    OPENBLAS_NUM_THREADS=1 python studies/automac_mc.py 200     # records; ~10 min

Prints, per pair of modes: the median MAC, its std over records (σ_MC), and the median σ over
records divided by σ_MC, for the approximation and the exact cross term. docs/shapes.md §6.
"""

import sys
import time
import warnings

import numpy as np

import modaluq
from modaluq.indicators import mac_matrix

ORDER = 12
N_MODES = 6


def _automac(sim, with_input, call):
    """(MAC, σ approximation, σ exact) of the six modes of one record, each (6, 6), or None when
    the six modes are not found one to one."""
    u = sim.u if with_input else None
    truth = np.sort(sim.frequency_hz)
    if call == "true order":
        r = modaluq.identify(sim.y, u, fs=sim.fs, block_rows=10, orders=[ORDER], n_blocks=50, keep_shape_factor=True)
        m = r.at_order(ORDER)
        f, phi, cov, v = m.frequency_hz, m.mode_shape, m.covariance, m.mode_shape_factor
    else:  # "engineer's call" or "engineer's call, lowest" (ClusteringSettings.representative)
        r = modaluq.identify(sim.y, u, fs=sim.fs, frequency_range=(1, 20), keep_shape_factor=True)
        sel = r.stabilization_diagram().select_modes(representative="lowest" if call.endswith("lowest") else "median")
        f, phi, cov, v = sel.frequency_hz, sel.mode_shape, sel.mode_covariance, sel.mode_shape_factor
    pick = [np.flatnonzero(np.abs(f / f0 - 1) < 0.02) for f0 in truth]
    if any(p.size == 0 for p in pick):
        return None
    pick = [p[np.argmin(np.abs(f[p] - f0))] for p, f0 in zip(pick, truth)]
    if len(set(pick)) != N_MODES:
        return None
    approx = mac_matrix(phi[:, pick], cov[pick])
    exact = mac_matrix(phi[:, pick], cov[pick], v[pick])
    return approx.mac, approx.std, exact.std


def run(n_records, with_input, call, n_samples=20000):
    macs, approx, exact = [], [], []
    for r in range(n_records):
        sim = modaluq.simulate(n_samples, seed=100 + r)
        found = _automac(sim, with_input, call)
        if found is None:
            continue
        macs.append(found[0])
        approx.append(found[1])
        exact.append(found[2])
    return np.array(macs), np.array(approx), np.array(exact)


CALLS = ("true order", "engineer's call", "engineer's call, lowest")


def main(n_records=80, n_samples=20000, calls=CALLS):
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for call in calls:
            for name, with_input in (("output-only", False), ("input/output", True)):
                t = time.process_time()
                macs, approx, exact = run(n_records, with_input, call, n_samples)
                out[f"{name}, {call}"] = (macs, approx, exact)
                print(f"\n{name}, {call}: {macs.shape[0]} of {n_records} records with the six modes, "
                      f"{time.process_time() - t:.0f} CPU s")
                print("| pair | MAC | σ_MC | approx. / σ_MC | exact / σ_MC |\n|---|---|---|---|---|")
                if macs.shape[0] < 2:
                    continue
                mc = macs.std(axis=0, ddof=1)
                ra, re = [], []
                for i in range(N_MODES):
                    for j in range(i + 1, N_MODES):
                        ra.append(np.median(approx[:, i, j]) / mc[i, j])
                        re.append(np.median(exact[:, i, j]) / mc[i, j])
                        print(f"| {i + 1}-{j + 1} | {np.median(macs[:, i, j]):.3f} | {mc[i, j]:.2e} | "
                              f"{ra[-1]:.2f} | {re[-1]:.2f} |")
                print(f"| all 15 pairs | | | {min(ra):.2f}–{max(ra):.2f} | {min(re):.2f}–{max(re):.2f} |")
    return out


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200, calls=tuple(sys.argv[2:]) or CALLS)
