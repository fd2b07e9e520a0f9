"""Monte Carlo check of the σ of the mode indicators (issue 24): MPC, the MAC between an estimated
shape and the true one, and the MAC between the estimates of two independent records, over N
records of the paper's chain, output-only and input/output, at the true order (12) and in the
engineer's call (`identify(y, u, fs, frequency_range=(1, 20)).select_modes()`). For each true mode:
the std of the indicator across records against the median reported σ (± its standard error
from resampling the records), and for the two-record MAC how often the "same mode" test
(`modaluq.indicators.mac_test`) rejects at 5 % (should be ~5 %); for the MAC with the true shape,
how often the test "this shape is the true one, given its covariance" (mac_test against the true
shape, whose covariance is zero) rejects at 5 %. The rejection rates are per-record calibration:
a few records whose shape is far off inflate the pooled std (and lower the median ratio) without
saying whether each record's σ was right; the rate says how often a record's σ failed to cover.
In the engineer's call the third argument picks the pole a mode is read at: "median", the
median representative for f, ξ and the shape (the package's default before 2026-11-27); "lowest",
the lowest order at or above the noise floor for all of them (`ClusteringSettings.representative`);
"shape-lowest", the median representative's f and ξ and the shape there
(`ClusteringSettings.shape_representative`, the package's default since 2026-11-27). The table also
gives the coverage of f ± 1.96 σ_f and ξ ± 1.96 σ_ξ of the mode around the records' mean.
A fourth argument picks the structure: "chain" (the paper's, default) or "frame" (a 4-storey
chain driven at its first and last floors by two measured inputs, modaluq.simulate(n_dof=4,
input_dofs=(0, 3)), true order 8).
Usage: python studies/indicators_mc.py [N] [seconds] [representative] [structure]
       (default 200 records of 400 s, "median", "chain": ~6 min)
"""
import pathlib
import sys
import warnings

import numpy as np

import modaluq
from modaluq.indicators import mac_test, modal_phase_collinearity, shape_covariance

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from above_order_diagnosis import _stats  # noqa: E402  (median σ/σ_MC, coverage of ±1.96 σ, RMS z)

FS = 50.0
#: structure: (modaluq.simulate keywords, true order)
STRUCTURES = {"chain": ({}, 12), "frame": (dict(n_dof=4, input_dofs=(0, 3)), 8)}


def _estimates(sim, with_input, call, representative, true_order):
    """(frequency, shape, shape covariance, [f, σ_f, ξ, σ_ξ] rows) of each identified mode of one record."""
    u = sim.u if with_input else None
    if call == "true order":
        m = modaluq.identify(sim.y, u, fs=FS, block_rows=20, orders=[true_order]).modes[0]
        fx = np.column_stack([m.frequency_hz, m.frequency_std, m.damping_ratio, m.damping_std])
        return m.frequency_hz, m.mode_shape, [shape_covariance(c) for c in m.covariance], fx
    result = modaluq.identify(sim.y, u, fs=FS, frequency_range=(1, 20))
    # "shape-lowest": f and ξ from the default representative, the shape from the lowest sufficient pole
    sel = result.stabilization_diagram().select_modes(
        representative="median" if representative == "shape-lowest" else representative,
        shape_representative="lowest" if representative in ("lowest", "shape-lowest") else "median")
    fx = np.column_stack([sel.frequency_hz, sel.frequency_std, sel.damping_ratio, sel.damping_std])
    return sel.frequency_hz, sel.mode_shape, [shape_covariance(c) for c in sel.mode_covariance], fx


def main(n_records=200, duration=400.0, representative="median", structure="chain"):
    """Print one table per configuration; return {config: (records, modes, 13) array} of MPC, σ,
    MAC with the truth, σ, MAC with the paired record, σ, p-value, found, f, σ_f, ξ, σ_ξ, and the
    p-value of the MAC with the truth."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _run(n_records, duration, representative, structure)


def _run(n_records, duration, representative, structure):
    keywords, true_order = STRUCTURES[structure]
    out = {}
    for with_input in (False, True):
        for call in ("true order", "engineer's call"):
            rows, shapes = [], []
            for seed in range(n_records):
                sim = modaluq.simulate(int(duration * FS), seed=5000 + seed, **keywords)
                order = np.argsort(sim.frequency_hz)
                truth_f, truth_shape = sim.frequency_hz[order], sim.mode_shape[:, order]
                f, phi, cov, fx = _estimates(sim, with_input, call, representative, true_order)
                row = np.full((len(truth_f), 13), np.nan)
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
                    row[k, 8:12] = fx[j]
                    row[k, 12] = mac.p_value
                    found[k] = (phi[:, j], cov[j])
                if seed % 2 == 1:  # pair with the previous record
                    for k in range(len(truth_f)):
                        if found[k] is not None and shapes[-1][k] is not None:
                            t = mac_test(shapes[-1][k][0], found[k][0], shapes[-1][k][1], found[k][1])
                            row[k, 4:7] = t.mac, t.std, t.p_value
                rows.append(row)
                shapes.append(found)
            a = np.array(rows)
            name = f"{structure}, {'input/output' if with_input else 'output-only'}, {call}"
            if call != "true order":
                name += f" (representative {representative!r})"
            out[name] = a
            _table(name, a, truth_f, n_records, duration)
    return out


def _ratio(values, sigmas, n_boot=1000):
    """σ_MC, the median σ, their ratio, and the ratio's standard error from resampling the
    records (the std of a near-χ² indicator over 200 records is itself uncertain by ~10 %)."""
    ok = np.isfinite(values) & np.isfinite(sigmas)
    if ok.sum() < 3:
        return np.nan, np.nan, np.nan, np.nan
    v, s = values[ok], sigmas[ok]
    mc = np.std(v, ddof=1)
    idx = np.random.default_rng(0).integers(0, v.size, (n_boot, v.size))
    boot = np.median(s[idx], axis=1) / np.std(v[idx], axis=1, ddof=1)
    return mc, np.median(s), np.median(s) / mc, np.std(boot, ddof=1)


def _table(name, a, truth_f, n_records, duration):
    print(f"\n{name}: {n_records} records of {duration:g} s (paired: {n_records // 2})")
    print("| mode | f (Hz) | found | std MPC (MC) | median σ | ratio ± SE | std MAC vs truth (MC) | median σ | ratio ± SE "
          "| std MAC pair (MC) | median σ | ratio ± SE | same-mode rejected at 5 % | truth rejected at 5 % "
          "| f: ratio, coverage | ξ: ratio, coverage |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for k, f0 in enumerate(truth_f):
        cells = []
        for v, s in ((0, 1), (2, 3), (4, 5)):
            mc, med, r, se = _ratio(a[:, k, v], a[:, k, s])
            cells += [f"{mc:.2e}", f"{med:.2e}", f"{r:.2f} ± {se:.2f}"]
        rej = [_rejected(a[:, k, c]) for c in (6, 12)]
        fx = []
        for v in (8, 10):  # f, ξ
            ratio, coverage = _stats(a[:, k, v], a[:, k, v + 1])[:2]
            fx.append(f"{ratio:.2f}, {coverage * 100:.0f} %")
        print(f"| {k + 1} | {f0:.3f} | {int(np.nansum(a[:, k, 7]))}/{n_records} | " + " | ".join(cells)
              + f" | {rej[0]} | {rej[1]} | " + " | ".join(fx) + " |")


def _rejected(p):
    """The share of finite p-values below 5 %, and of how many."""
    p = p[np.isfinite(p)]
    return f"{np.mean(p < 0.05) * 100:.1f} % of {p.size}" if p.size else "-"


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200, float(sys.argv[2]) if len(sys.argv) > 2 else 400.0,
         sys.argv[3] if len(sys.argv) > 3 else "median", sys.argv[4] if len(sys.argv) > 4 else "chain")
