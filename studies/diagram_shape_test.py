"""Issue 24: could the "same mode" test of two shapes (:func:`modaluq.indicators.mac_test`, the
MAC against its second-order σ) replace the stabilization diagram's fixed ``min_mac`` = 0.98
between a pole and its match at the previous order?

Each record is identified the engineer's way (``identify(y, u, fs, frequency_range=(1, 20),
keep_shape_factor=True)``: automatic block rows and orders, every pole's shape factor kept) and
its diagram made with the default criteria. For every pole with a match at the previous order,
the test of its shape against the match's shape is computed twice:

- **independent**: each shape's own covariance, the cross-covariance taken as 0 (what a test
  between two records does, and all a diagram could do without the factors);
- **joint**: with the cross-covariance ``V_i V_jᵀ`` of the two poles' shape factors (consecutive
  orders share the data, so this is the exact second-order test).

A pole is *physical* when it lies within 1 % of a true frequency and is not noise-coupled, else
*other* (spurious, or a physical pole mixed with noise). Per class and band of orders relative to
the record's noise floor k* (≤ k*, up to 2k*, up to 4k*, above), the share rejected by
MAC < 0.98 and by each test at 1 %: a test that replaced the fixed MAC would have to reject the
others at least as often and the physical poles no more often (about 1 %).

    OPENBLAS_NUM_THREADS=1 python studies/diagram_shape_test.py 20 chain    # records; ~40 s
    OPENBLAS_NUM_THREADS=1 python studies/diagram_shape_test.py 20 frame    # 4 storeys, two inputs

docs/shapes.md §6 ("Where the test decides, and where it does not").
"""

import sys
import warnings

import numpy as np

import modaluq
from modaluq.indicators import mac_test

STRUCTURES = {"chain": {}, "frame": dict(n_dof=4, input_dofs=(0, 3))}
ALPHA = 0.01
BANDS = (("<= k*", -np.inf, 1.0), ("k*..2k*", 1.0, 2.0), ("2k*..4k*", 2.0, 4.0), ("> 4k*", 4.0, np.inf))


def _rejected(p) -> float:
    """The share of the finite p-values below ALPHA (a NaN p-value is no test, not an acceptance)."""
    p = p[np.isfinite(p)]
    return float(np.mean(p < ALPHA)) if p.size else float("nan")


def record_rows(sim, with_input: bool) -> list:
    """(order / k*, physical, MAC < min_mac, p independent, p joint) per matched pole of one record."""
    u = sim.u if with_input else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ModalUQWarning)
        r = modaluq.identify(sim.y, u, fs=sim.fs, frequency_range=(1, 20), keep_shape_factor=True)
    d = r.stabilization_diagram()
    k_star = max(int(r.significant_singular_values), 1)
    truth = np.asarray(sim.frequency_hz)
    rows = []
    for i in np.flatnonzero(d.matched_pole >= 0):
        p = int(d.matched_pole[i])
        a, b = d.mode_shape[:, i], d.mode_shape[:, p]
        va, vb = d.pole_shape_factor(i), d.pole_shape_factor(p)
        independent = mac_test(a, b, va @ va.T, vb @ vb.T)
        joint = mac_test(a, b, va @ va.T, vb @ vb.T, cross_covariance=va @ vb.T)
        physical = np.min(np.abs(truth / d.frequency_hz[i] - 1.0)) < 0.01 and not d.noise_coupled[i]
        rows.append((d.order[i] / k_star, physical, d.mac[i] < d.criteria.min_mac, independent.p_value,
                     joint.p_value))
    return rows


def main(n_records: int, structure: str, n_samples: int = 20_000) -> dict:
    """Prints the tables; returns the rows (order / k*, physical, MAC < 0.98, p independent, p
    joint) per method."""
    kw = STRUCTURES[structure]
    out = {}
    for label, with_input in (("output-only", False), ("input/output", True)):
        rows = []
        for k in range(n_records):
            rows += record_rows(modaluq.simulate(n_samples, seed=9000 + k, **kw), with_input)
        x = out[label] = np.array(rows, dtype=float)
        print(f"\n{structure}, {label}, {n_records} records ({len(x)} matched poles): share rejected "
              f"(MAC < 0.98 | independent test | joint test, at {ALPHA:.0%})")
        print("| poles | orders | n | MAC < 0.98 | independent | joint |")
        print("|---|---|---|---|---|---|")
        for cls, phys in (("physical", 1.0), ("other", 0.0)):
            for band, lo, hi in BANDS:
                sel = x[(x[:, 1] == phys) & (x[:, 0] > lo) & (x[:, 0] <= hi)]
                if not len(sel):
                    continue
                rej = [np.mean(sel[:, 2]), _rejected(sel[:, 3]), _rejected(sel[:, 4])]
                print(f"| {cls} | {band} | {len(sel)} | " + " | ".join(f"{100 * v:.0f} %" for v in rej) + " |")
        sel = x[(x[:, 1] == 0.0) & (x[:, 2] == 0.0)]
        print(f"other poles that pass MAC >= 0.98: {len(sel)}; the independent test rejects "
              f"{100 * _rejected(sel[:, 3]):.0f} %, the joint {100 * _rejected(sel[:, 4]):.0f} %; "
              f"no p-value (the shapes too different for the test's quadratic model): "
              f"{100 * np.mean(np.isnan(x[:, 3])):.1f} % and {100 * np.mean(np.isnan(x[:, 4])):.1f} % of all poles")
    return out


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20, sys.argv[2] if len(sys.argv) > 2 else "chain")
