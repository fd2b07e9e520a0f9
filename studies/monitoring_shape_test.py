"""Issue 24: the monitoring's shape test (docs/monitoring.md §3) — the "same mode" test of each
record's tracked shape against its reference mode's mean shape — measured on the simulator.

1. **Gate or alarm?** A campaign of hourly records with a temperature cycle, spring 3 losing 10 %
   of its stiffness from ``damage_record`` on: per mode the share of the assigned pairs that the
   test rejects at 1 % before and after the damage, the smallest MAC to the reference after it,
   and, for every record mode against every *other* reference mode, how many such wrong pairs pass
   the fixed gate (MAC ≥ 0.8) and how many the test accepts.
2. **Its rate without change**: a campaign without damage, the share of the tests below
   0.01, 0.05, 0.1, 0.2 and 0.5, and per mode the observed mean of 1 − MAC over the mean the test
   expects (above 1: the shapes' σ too small here; below: too large).
3. **Diagonal or full covariances**: records of the paper's chain identified with
   ``modaluq.identify`` (full shape covariances), each mode tested against one record's shape with
   the full covariances and with their diagonals only (the monitoring's parts keep the diagonal).

    OPENBLAS_NUM_THREADS=1 python studies/monitoring_shape_test.py            # ~2 min
    OPENBLAS_NUM_THREADS=1 python studies/monitoring_shape_test.py 40 60 30   # smaller: records of 1, 2, 3
"""

import sys
import warnings

import numpy as np

import modaluq
from modaluq.indicators import mac_test, shape_covariance
from modaluq.monitoring import monitor, simulate_monitoring
from modaluq.monitoring.tracking import RecordModes, shape_test

ALPHAS = (0.01, 0.05, 0.1, 0.2, 0.5)


def _tracked_mode(ds, k: int, j: int):
    """Record ``k``'s tracked mode ``j`` of a monitoring dataset as a one-mode :class:`RecordModes`
    (what :func:`shape_test` reads), or None where the record lacks it."""
    shape = ds["mode_shape"].transpose("record", "channel", "mode").values[k, :, j]
    if not np.all(np.isfinite(shape)):
        return None
    std = {part: ds[f"mode_shape_std_{part}"].transpose("record", "channel", "mode").values[k, :, j:j + 1]
           for part in ("real", "imag")}
    one = np.ones(1)
    return RecordModes(frequency_hz=one, damping_ratio=one, frequency_std=one, damping_std=one,
                       frequency_damping_correlation=one, mode_shape=shape[:, None],
                       mode_shape_std_real=std["real"], mode_shape_std_imag=std["imag"])


def gate_or_alarm(n_records=120, damage_record=84, seed=3, n_samples=20_000):
    camp = simulate_monitoring(n_records, n_samples=n_samples, seed=seed, damage_element=2,
                               damage_record=damage_record, damage_fraction=0.1)
    m = monitor(camp.records, progress=False, threads=1)
    ds = m.dataset
    after = ~ds["in_reference"].values
    before = after & (np.arange(n_records) < damage_record)
    p = ds["shape_p_value"].values
    print(f"\n1. {n_records} hourly records of {n_samples / camp.fs:g} s, spring 3 loses 10 % from record "
          f"{damage_record}; the test at 1 %")
    print("| mode | f [Hz] | rejected before | rejected after | smallest MAC to the reference after |")
    print("|---|---|---|---|---|")
    for j in range(ds.sizes["mode"]):
        b, a = p[before, j], p[damage_record:, j]
        print(f"| {j + 1} | {ds['reference_frequency_hz'].values[j]:.2f} | {100 * np.nanmean(b < 0.01):.1f} % | "
              f"{100 * np.nanmean(a < 0.01):.0f} % | {np.nanmin(ds['mac_to_reference'].values[damage_record:, j]):.4f} |")
    # every record's tracked mode against every other reference mode: the wrong pairs
    ref = m.reference
    n_wrong = n_gate = n_test = 0
    for k in range(n_records):
        for i in range(ref.n_modes):
            rec = _tracked_mode(ds, k, i)
            for j in range(ref.n_modes) if rec is not None else ():
                if j == i:
                    continue
                t = shape_test(rec, 0, ref, j)
                n_wrong += 1
                n_gate += t.mac >= 0.8
                n_test += t.same_mode(0.01)
    print(f"wrong pairs (a record's mode against another reference mode): {n_wrong}; pass MAC >= 0.8: "
          f"{n_gate} ({100 * n_gate / n_wrong:.1f} %); accepted by the test at 1 %: {n_test}")


def rate_without_change(n_records=200, seed=0, n_samples=10_000):
    camp = simulate_monitoring(n_records, n_samples=n_samples, seed=seed)
    m = monitor(camp.records, settings=modaluq.Settings(orders=tuple(range(2, 25, 2))), progress=False, threads=1)
    ds = m.dataset
    after = ~ds["in_reference"].values
    p = ds["shape_p_value"].values[after]
    print(f"\n2. {n_records} records of {n_samples / camp.fs:g} s without damage (orders 2-24), {np.isfinite(p).sum()} "
          "tests after the reference period: share below")
    print("| " + " | ".join(f"{a:g}" for a in ALPHAS) + " |\n|" + "---|" * len(ALPHAS))
    print("| " + " | ".join(f"{100 * np.nanmean(p < a):.2f} %" for a in ALPHAS) + " |")
    # observed 1 - MAC against the mean the test expects, per mode
    ref, ratios = m.reference, []
    for j in range(ref.n_modes):
        tests = [shape_test(rec, 0, ref, j) for rec in (_tracked_mode(ds, k, j) for k in np.flatnonzero(after))
                 if rec is not None]
        ratios.append(np.mean([1 - t.mac for t in tests]) / np.mean([t.loss_mean for t in tests]))
    print("observed mean 1 - MAC over the test's expected mean, modes 1..: " + ", ".join(f"{r:.2f}" for r in ratios))
    return p, ratios


def full_or_diagonal(n_records=120, n_samples=10_000):
    sel = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ModalUQWarning)
        for k in range(n_records):
            sim = modaluq.simulate(n_samples, seed=100 + k)
            sel.append(modaluq.identify(sim.y, fs=sim.fs, orders=range(2, 25, 2)).select_modes())
    ref = sel[0]
    full, diagonal = [], []
    for s in sel[1:]:
        for i in range(len(s.frequency_hz)):
            j = int(np.argmin(np.abs(ref.frequency_hz - s.frequency_hz[i])))
            if abs(ref.frequency_hz[j] / s.frequency_hz[i] - 1) > 0.02:
                continue
            ca, cb = shape_covariance(s.mode_covariance[i]), shape_covariance(ref.mode_covariance[j])
            full.append(mac_test(s.mode_shape[:, i], ref.mode_shape[:, j], ca, cb).p_value)
            diagonal.append(mac_test(s.mode_shape[:, i], ref.mode_shape[:, j], np.diag(np.diag(ca)),
                                     np.diag(np.diag(cb))).p_value)
    print(f"\n3. {n_records} records of the paper's chain ({n_samples / 50:g} s, orders 2-24, output-only), each mode "
          f"against record 0's: {len(full)} tests, share below")
    print("| covariances | " + " | ".join(f"{a:g}" for a in ALPHAS) + " |\n|---|" + "---|" * len(ALPHAS))
    for label, p in (("full", full), ("diagonal", diagonal)):
        print(f"| {label} | " + " | ".join(f"{100 * np.nanmean(np.array(p) < a):.1f} %" for a in ALPHAS) + " |")
    return np.array(full), np.array(diagonal)


def main(n_gate=120, n_rate=200, n_full=120):
    gate_or_alarm(n_gate, damage_record=int(0.7 * n_gate))
    rate_without_change(n_rate)
    full_or_diagonal(n_full)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:4]))
