"""Tracking (modaluq.monitoring.tracking) on synthetic modes whose truth is set here: reference
modes, the assignment, a batch's tracks.

Every expected value comes from the construction: the frequencies and shapes drawn.
"""

import numpy as np
import pytest
import scipy.stats

from modaluq.indicators import mac_test
from modaluq.monitoring.tracking import (
    RecordModes,
    TrackingSettings,
    after_reference,
    assign,
    reference_modes,
    reference_period,
    shape_test,
    track,
)

TRUE_F = np.array([2.0, 5.0, 5.1, 9.0])      # 5.0 and 5.1 are 2 % apart
TRUE_XI = np.array([0.02, 0.015, 0.03, 0.01])
SHAPES = np.array([[1, 0.5, 0.2, 1], [0.6, 1, -0.9, -0.5], [0.2, -0.7, 1, 0.8]], complex)


def record(rng, *, sf=0.003, sx=0.002, drift=0.0, drop=(), extra=None, order=None):
    """One record's modes: the truth (frequencies times 1 + drift) plus Gaussian errors of the σ stated."""
    f = TRUE_F * (1 + drift) + rng.standard_normal(4) * sf * TRUE_F
    xi = TRUE_XI + rng.standard_normal(4) * sx
    phi = SHAPES * np.exp(1j * rng.uniform(0, 2 * np.pi, 4)) + 0.01 * rng.standard_normal(SHAPES.shape)
    keep = [i for i in range(4) if i not in drop]
    cols = dict(frequency_hz=f[keep], damping_ratio=xi[keep], frequency_std=sf * TRUE_F[keep],
                damping_std=np.full(len(keep), sx), frequency_damping_correlation=np.zeros(len(keep)),
                mode_shape=phi[:, keep], mode_shape_std_real=np.full((3, len(keep)), 0.01),
                mode_shape_std_imag=np.full((3, len(keep)), 0.01))
    if extra is not None:  # a spurious mode: frequency and shape
        for k, v in (("frequency_hz", extra[0]), ("damping_ratio", 0.05), ("frequency_std", 0.01),
                     ("damping_std", 0.01), ("frequency_damping_correlation", 0.0)):
            cols[k] = np.append(cols[k], v)
        cols["mode_shape"] = np.column_stack([cols["mode_shape"], extra[1]])
        cols["mode_shape_std_real"] = np.column_stack([cols["mode_shape_std_real"], np.full(3, 0.01)])
        cols["mode_shape_std_imag"] = np.column_stack([cols["mode_shape_std_imag"], np.full(3, 0.01)])
    if order is not None:
        cols = {k: (v[..., order] if k.startswith("mode_shape") else v[order]) for k, v in cols.items()}
    return RecordModes(**cols)


def test_reference_modes_recover_the_truth_and_the_environmental_scatter():
    rng = np.random.default_rng(1)
    drifts = 0.004 * rng.standard_normal(40)  # 0.4 % of environmental scatter, > σ_f = 0.3 %
    ref = reference_modes([record(rng, drift=d) for d in drifts])
    assert ref.n_modes == 4
    np.testing.assert_allclose(ref.frequency_hz, TRUE_F, rtol=0.003)
    np.testing.assert_allclose(ref.damping_ratio, TRUE_XI, atol=0.002)
    # the scatter beyond σ is the drift's std (0.4 % of f), within its sampling error (40 records)
    np.testing.assert_allclose(ref.frequency_scatter / TRUE_F, 0.004, rtol=0.35)
    assert np.all(ref.presence == 1)


def test_reference_keeps_modes_present_in_enough_records():
    rng = np.random.default_rng(2)
    recs = [record(rng, drop=(3,) if k % 3 else ()) for k in range(30)]  # mode 4 in a third of them
    assert reference_modes(recs).n_modes == 3
    assert reference_modes(recs, TrackingSettings(min_presence=0.3)).n_modes == 4
    with pytest.raises(ValueError, match="no mode was selected"):
        reference_modes([None, None])


def test_assignment_undoes_a_permutation_and_leaves_spurious_and_gated_modes_out():
    rng = np.random.default_rng(3)
    ref = reference_modes([record(rng) for _ in range(20)])
    order = np.array([2, 0, 3, 1])
    idx, mac, cost = assign(record(rng, order=order), ref)
    np.testing.assert_array_equal(idx, order)  # the 2 %-apart pair (5.0, 5.1 Hz) is not swapped
    assert np.all(mac > 0.95) and np.all(np.isfinite(cost))
    # a spurious mode between two modes, with a shape unlike any: not assigned
    idx, _, _ = assign(record(rng, extra=(7.0, np.array([1, 1j, -1]))), ref)
    np.testing.assert_array_equal(idx, [0, 1, 2, 3, -1])
    # a missing mode leaves its reference mode free, and nothing else takes it
    idx, _, _ = assign(record(rng, drop=(1,)), ref)
    np.testing.assert_array_equal(idx, [0, 2, 3])
    # the frequency gate: a mode 20 % away is not the same mode even with its shape
    far = record(rng)
    far = RecordModes(**{**far.__dict__, "frequency_hz": far.frequency_hz * np.array([1, 1, 1, 1.2])})
    idx, _, _ = assign(far, ref)
    assert idx[3] == -1


def test_swapped_frequencies_of_close_modes_follow_the_shapes_not_the_order():
    # two modes 2 % apart whose frequencies come out in the other order: the shapes decide
    rng = np.random.default_rng(4)
    ref = reference_modes([record(rng) for _ in range(20)])
    r = record(rng, sf=1e-4)
    f = r.frequency_hz.copy()
    f[1], f[2] = 5.1, 5.0
    shapes = r.mode_shape.copy()
    shapes[:, [1, 2]] = shapes[:, [2, 1]]
    idx, _, _ = assign(RecordModes(**{**r.__dict__, "frequency_hz": f, "mode_shape": shapes}), ref,
                       TrackingSettings(max_frequency_deviation=0.1))
    np.testing.assert_array_equal(idx, [0, 2, 1, 3])


def test_track_puts_every_records_modes_on_the_reference_modes():
    rng = np.random.default_rng(4)
    records = [record(rng) for _ in range(10)] + [record(rng, order=[2, 0, 3, 1]), None, record(rng, drop=(1,))]
    tracks = track(records, np.arange(13) < 10, 3)
    assert tracks.n_modes == 4 and tracks.error == "" and tracks.frequency_hz.shape == (13, 4)
    # a permuted record: column j holds the record's mode assigned to reference mode j
    np.testing.assert_array_equal(tracks.index[10], [2, 0, 3, 1])
    np.testing.assert_array_equal(tracks.frequency_hz[10], records[10].frequency_hz[[1, 3, 0, 2]])
    np.testing.assert_array_equal(tracks.mode_shape[10], records[10].mode_shape[:, [1, 3, 0, 2]])
    np.testing.assert_array_equal(tracks.covariance()[10, 0], records[10].covariance()[1])
    # a record not identified has no modes; a record without mode 2 has NaN there
    assert tracks.index[11] is None and np.isnan(tracks.frequency_hz[11]).all()
    assert np.isnan(tracks.frequency_hz[12, 1]) and np.isfinite(tracks.frequency_hz[12, [0, 2, 3]]).all()
    assert tracks.n_unassigned.tolist() == [0] * 13
    # other per-mode values follow the same assignment
    placed = tracks.place([np.arange(r.n_modes) if r is not None else None for r in records], -1, int)
    np.testing.assert_array_equal(placed[10], [1, 3, 0, 2])
    assert placed[11].tolist() == [-1] * 4 and placed[12].tolist() == [0, -1, 1, 2]
    # fewer than 3 reference records: no reference modes, and why
    untracked = track(records, np.arange(13) < 2, 3)
    assert untracked.reference is None and "at least 3 are needed" in untracked.error
    assert untracked.frequency_hz.shape == (13, 0) and untracked.n_unassigned[0] == 4


SHAPE_STD = 0.01  # σ of the real and of the imaginary part of every shape component


def gaussian_record(rng, changed=None):
    """The four modes with shape errors exactly as their σ state (complex Gaussian, SHAPE_STD each
    part); ``changed``: (mode, channel, size) added to one component of the true shape."""
    shapes = SHAPES.copy()
    if changed is not None:
        shapes[changed[1], changed[0]] += changed[2]
    phi = shapes + SHAPE_STD * (rng.standard_normal(shapes.shape) + 1j * rng.standard_normal(shapes.shape))
    std = np.full(shapes.shape, SHAPE_STD)
    return RecordModes(frequency_hz=TRUE_F.copy(), damping_ratio=TRUE_XI.copy(), frequency_std=0.003 * TRUE_F,
                       damping_std=np.full(4, 0.002), frequency_damping_correlation=np.zeros(4), mode_shape=phi,
                       mode_shape_std_real=std, mode_shape_std_imag=std.copy())


def test_the_shape_test_is_the_same_mode_test_against_the_reference_mean():
    # reference records whose shapes are exact (a random phase each) with a stated σ: their mean,
    # brought onto one phase, is the true shape; its σ is σ/√K; the scatter beyond σ is 0
    rng = np.random.default_rng(5)
    exact = [RecordModes(**{**gaussian_record(rng).__dict__,
                            "mode_shape": SHAPES * np.exp(1j * rng.uniform(0, 2 * np.pi, 4))}) for _ in range(20)]
    ref = reference_modes(exact)
    mac_to_truth = np.abs(np.sum(ref.mode_shape_mean.conj() * SHAPES, axis=0)) ** 2 / (
        np.sum(np.abs(ref.mode_shape_mean) ** 2, axis=0) * np.sum(np.abs(SHAPES) ** 2, axis=0))
    np.testing.assert_allclose(mac_to_truth, 1.0, atol=1e-12)
    np.testing.assert_allclose(ref.mode_shape_mean_std, np.hypot(SHAPE_STD, SHAPE_STD) / np.sqrt(20), rtol=1e-12)
    assert np.all(ref.mode_shape_scatter == 0)
    rec = gaussian_record(rng)
    half = SHAPE_STD**2 / 20  # the mean's σ², half to each part
    expected = mac_test(rec.mode_shape[:, 2], SHAPES[:, 2], np.eye(6) * SHAPE_STD**2, np.eye(6) * half)
    got = shape_test(rec, 2, ref, 2)
    assert got.mac == pytest.approx(expected.mac, abs=1e-12) and got.p_value == pytest.approx(expected.p_value, rel=1e-9)
    assert 0 < got.p_value < 1 and got.std > 0
    # a σ unknown: the MAC alone, no p-value (no alarm can follow)
    blind = RecordModes(**{**rec.__dict__, "mode_shape_std_real": np.full((3, 4), np.nan)})
    t = shape_test(blind, 2, ref, 2)
    assert t.mac == got.mac and np.isnan(t.p_value) and np.isnan(t.std)


def test_shape_alarms_keep_the_rate_in_each_campaign_and_fire_when_a_shape_moves():
    # 12 independent campaigns of 20 reference and 50 later records, shape errors exactly as σ
    # states: the mean rate of shape alarms is the rate stated, and its spread over the campaigns is
    # the binomial one (the reference's error, shared by a campaign's records, is that of a mean)
    rate, n_ref, n_after = 0.05, 20, 50
    rates = []
    for seed in range(12):
        rng = np.random.default_rng(100 + seed)
        records = [gaussian_record(rng) for _ in range(n_ref + n_after)]
        tracks = track(records, np.arange(n_ref + n_after) < n_ref, 3, TrackingSettings(false_alarm_rate=rate))
        assert not tracks.shape_alarm[:n_ref].any()  # never in the reference period
        assert np.array_equal(tracks.shape_alarm[n_ref:], tracks.shape_p_value[n_ref:] < rate)
        rates.append(tracks.shape_alarm[n_ref:].mean())
    rates, dof = np.array(rates), len(rates) - 1
    # the mean of the campaigns' rates: Student's t with their own spread, 99.9 % two-sided
    assert abs(rates.mean() - rate) < scipy.stats.t.isf(0.0005, dof) * rates.std(ddof=1) / np.sqrt(len(rates)), \
        rates.mean()
    # their spread is a binomial's (200 tests each): the sample variance below its χ² 99.9 % quantile
    binomial_var = rate * (1 - rate) / (n_after * 4)
    assert rates.var(ddof=1) < binomial_var * scipy.stats.chi2.isf(0.001, dof) / dof, (rates.var(ddof=1), binomial_var)
    # mode 4's second component moved by 10 σ (9.7 σ of the difference with the reference mean): its
    # MAC stays far above the gate (0.8), the test sees it
    rng = np.random.default_rng(6)
    reference = [gaussian_record(rng) for _ in range(n_ref)]
    moved = [gaussian_record(rng, changed=(3, 1, 10 * SHAPE_STD)) for _ in range(50)]
    tracks = track(reference + moved, np.arange(n_ref + 50) < n_ref, 3, TrackingSettings(false_alarm_rate=rate))
    assert np.all(tracks.mac_to_reference[n_ref:, 3] > 0.95)
    assert tracks.shape_alarm[n_ref:, 3].mean() >= 0.9, tracks.shape_alarm[n_ref:, 3].mean()
    assert tracks.shape_alarm[n_ref:, :3].mean() <= 0.15


def test_no_shape_alarm_before_a_reference_span():
    rng = np.random.default_rng(7)
    before = [gaussian_record(rng, changed=(3, 1, 10 * SHAPE_STD)) for _ in range(5)]  # moved, but before it
    records = before + [gaussian_record(rng) for _ in range(25)]
    in_reference = np.zeros(30, bool)
    in_reference[5:25] = True
    tracks = track(records, in_reference, 3)
    assert np.all(tracks.shape_p_value[:5, 3] < 1e-3)  # the test sees the moved shape ...
    assert not tracks.shape_alarm[:25].any()  # ... but a record before the reference period is not charted
    np.testing.assert_array_equal(after_reference(in_reference), np.arange(30) >= 25)


def test_the_reference_period_takes_identified_records_only():
    done = np.array([True, False, True, True, True, True])
    times = np.arange(6).astype("datetime64[h]").astype("datetime64[s]")
    first = reference_period(done, times, TrackingSettings(reference_records=3))
    assert first.tolist() == [True, False, True, True, False, False]
    span = reference_period(done, times, TrackingSettings(reference_span=(str(times[1]), str(times[4]))))
    assert span.tolist() == [False, False, True, True, True, False]


def test_settings_are_checked_by_name():
    with pytest.raises(ValueError, match="false_alarm_rate"):
        TrackingSettings(false_alarm_rate=0)
    with pytest.raises(ValueError, match="reference_records"):
        TrackingSettings(reference_records=2)
    with pytest.raises(ValueError, match="reference_span"):
        TrackingSettings(reference_span=("2026-02-01", "2026-01-01"))
    with pytest.raises(ValueError, match="smoothing"):
        TrackingSettings(smoothing=1.5)
