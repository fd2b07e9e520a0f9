"""Monte Carlo check of the σ of the mode indicators (issue 24): MPC, the MAC between an estimated
shape and the true one, and the MAC between the estimates of two independent records, over N
records of the paper's chain, output-only and input/output, at the true order (12) and in the
engineer's call (`identify(y, u, fs, frequency_range=(1, 20)).select_modes()`). For each true mode:
the std of the indicator across records against the median reported σ, and for the two-record
MAC how often the "same mode" test (`modaluq.indicators.mac_test`) rejects at 5 % (should be ~5 %).
Usage: python studies/indicators_mc.py [N] [seconds]   (default 200 records of 400 s: ~6 min)
"""
import sys
import warnings

import numpy as np

import modaluq
from modaluq.indicators import mac_test, modal_phase_collinearity, shape_covariance

FS = 50.0
TRUE_ORDER = 12


def _estimates(sim, with_input, call):
    """(frequency, shape, shape covariance) of each identified mode of one record."""
    u = sim.u if with_input else None
    if call == "true order":
        m = modaluq.identify(sim.y, u, fs=FS, block_rows=20, orders=[TRUE_ORDER]).modes[0]
        return m.frequency_hz, m.mode_shape, [shape_covariance(c) for c in m.covariance]
    sel = modaluq.identify(sim.y, u, fs=FS, frequency_range=(1, 20)).select_modes()
    return sel.frequency_hz, sel.mode_shape, [shape_covariance(c) for c in sel.mode_covariance]


def main(n_records=200, duration=400.0):
    """Print one table per configuration; return {config: (records, modes, 8) array} of MPC, σ,
    MAC with the truth, σ, MAC with the paired record, σ, p-value, found."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _run(n_records, duration)


def _run(n_records, duration):
    out = {}
    for with_input in (False, True):
        for call in ("true order", "engineer's call"):
            rows, shapes = [], []
            for seed in range(n_records):
                sim = modaluq.simulate(int(duration * FS), seed=5000 + seed)
                order = np.argsort(sim.frequency_hz)
                truth_f, truth_shape = sim.frequency_hz[order], sim.mode_shape[:, order]
                f, phi, cov = _estimates(sim, with_input, call)
                row = np.full((len(truth_f), 8), np.nan)
                found = [None] * len(truth_f)
                for k, f0 in enumerate(truth_f):
                    j = np.flatnonzero(np.abs(f / f0 - 1) < 0.02)
                    if not j.size:
                        continue
                    j = j[np.argmin(np.abs(f[j] - f0))]
                    mpc = modal_phase_collinearity(phi[:, j], cov[j])
                    mac = mac_test(phi[:, j], truth_shape[:, k], cov[j], None)
                    row[k, :4] = mpc.value, mpc.std, mac.mac, mac.std
                    row[k, 7] = 1
                    found[k] = (phi[:, j], cov[j])
                if seed % 2 == 1:  # pair with the previous record
                    for k in range(len(truth_f)):
                        if found[k] is not None and shapes[-1][k] is not None:
                            t = mac_test(shapes[-1][k][0], found[k][0], shapes[-1][k][1], found[k][1])
                            row[k, 4:7] = t.mac, t.std, t.p_value
                rows.append(row)
                shapes.append(found)
            a = np.array(rows)
            name = f"{'input/output' if with_input else 'output-only'}, {call}"
            out[name] = a
            _table(name, a, truth_f, n_records, duration)
    return out


def _ratio(values, sigmas):
    ok = np.isfinite(values) & np.isfinite(sigmas)
    if ok.sum() < 3:
        return np.nan, np.nan, np.nan
    mc = np.std(values[ok], ddof=1)
    return mc, np.median(sigmas[ok]), np.median(sigmas[ok]) / mc


def _table(name, a, truth_f, n_records, duration):
    print(f"\n{name}: {n_records} records of {duration:g} s (paired: {n_records // 2})")
    print("| mode | f (Hz) | found | std MPC (MC) | median σ | ratio | std MAC vs truth (MC) | median σ | ratio "
          "| std MAC pair (MC) | median σ | ratio | same-mode rejected at 5 % |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for k, f0 in enumerate(truth_f):
        cells = []
        for v, s in ((0, 1), (2, 3), (4, 5)):
            mc, med, r = _ratio(a[:, k, v], a[:, k, s])
            cells += [f"{mc:.2e}", f"{med:.2e}", f"{r:.2f}"]
        p = a[:, k, 6][np.isfinite(a[:, k, 6])]
        rej = f"{np.mean(p < 0.05) * 100:.1f} % of {p.size}" if p.size else "-"
        print(f"| {k + 1} | {f0:.3f} | {int(np.nansum(a[:, k, 7]))}/{n_records} | " + " | ".join(cells) + f" | {rej} |")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200, float(sys.argv[2]) if len(sys.argv) > 2 else 400.0)
