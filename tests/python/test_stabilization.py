"""Stabilization diagram and automatic mode selection.

Unit tests use small hand-made pole sets whose expected status follows from the documented
rule; the end-to-end test identifies the paper's 6-DOF chain and checks that the automatic
selection finds exactly its six modes, each within 3 analytic standard deviations.
"""

import math

import numpy as np
import pytest

import modaluq
from modaluq import (
    ClusteringSettings,
    Diagram,
    PoleStatus,
    StabilityCriteria,
    modal_assurance_criterion,
    select_modes,
    stabilization_diagram,
)
from modaluq.results import Modes, Result

SHAPE_A = (1.0, 0.5, -0.3)
SHAPE_B = (0.2, -0.7, 1.0)
SHAPE_C = (0.6, 1.0, 0.4)


def pole(f, xi=0.02, shape=SHAPE_A, sf=None, sxi=None):
    """One hand-made pole; default σ_f = 0.1 % of f (passes every σ test below)."""
    return {"f": f, "xi": xi, "shape": shape, "sf": 1e-3 * f if sf is None else sf,
            "sxi": 0.05 * abs(xi) if sxi is None else sxi}


def make_result(poles_by_order, *, with_std=True, close_orders=()):
    """A modaluq.Result holding the given poles: {order: [pole(...), ...]}."""
    n_out = 3
    modes = []
    for n in sorted(poles_by_order):
        rows = sorted(poles_by_order[n], key=lambda p: p["f"])
        k = len(rows)
        shape = np.array([p["shape"] for p in rows], dtype=complex).T.reshape(n_out, k)
        std = dict(
            frequency_std=np.array([p["sf"] for p in rows], float),
            damping_std=np.array([p["sxi"] for p in rows], float),
            mode_shape_std_real=np.full((n_out, k), 1e-3),
            mode_shape_std_imag=np.full((n_out, k), 1e-3),
        ) if with_std else {}
        modes.append(Modes(order=n, frequency_hz=np.array([p["f"] for p in rows], float),
                           damping_ratio=np.array([p["xi"] for p in rows], float), mode_shape=shape,
                           eigenvalue=np.zeros(k, complex), reference_component=np.zeros(k, np.int64),
                           close_singular_values=n in close_orders,
                           noise_coupled=(np.array([bool(p.get("coupled", False)) for p in rows])
                                          if with_std else None), **std))
    return Result(modes=tuple(modes), fs=100.0, settings={"fs": 100.0}, singular_values=np.ones(1),
                  n_samples=10_000, n_outputs=n_out, n_inputs=0, n_columns=9_000,
                  n_blocks=50 if with_std else 0, block_length=180, channel_mean=np.zeros(n_out))


def status_of(diagram, order, f):
    i = int(np.flatnonzero((diagram.order == order) & np.isclose(diagram.frequency_hz, f))[0])
    return diagram.status[i], diagram.reason[i], i


# --------------------------------------------------------------------------- MAC


def test_mac_is_one_for_scaled_shapes_and_zero_for_orthogonal_ones():
    a = np.array([1.0, 0.5 - 0.2j, -0.3])
    assert modal_assurance_criterion(a, (2 - 3j) * a)[0, 0] == pytest.approx(1.0, abs=1e-14)
    assert modal_assurance_criterion([1, 0, 0], [0, 1j, 0])[0, 0] == 0.0
    b = np.array([0.2, 1.0, 0.1j])
    expected = abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real)
    mac = modal_assurance_criterion(np.column_stack([a, b]), b)
    assert mac.shape == (2, 1)
    assert mac[0, 0] == pytest.approx(expected, rel=1e-13) and mac[1, 0] == pytest.approx(1.0)


def test_mac_refuses_mismatched_shapes():
    with pytest.raises(ValueError, match="shape_a and shape_b"):
        modal_assurance_criterion(np.ones(3), np.ones(4))
    with pytest.raises(ValueError, match="shape_a and shape_b"):
        modal_assurance_criterion(np.ones((3, 2, 1)), np.ones(3))


def test_mac_is_the_cores_and_equals_numpy_for_every_kind_of_input():
    # the core computes it (stabilization.hpp); NumPy's products sum in another order: 1e-15 apart
    from stabilization_oracle import modal_assurance_criterion as numpy_mac

    rng = np.random.default_rng(3)
    a = rng.standard_normal((5, 4)) + 1j * rng.standard_normal((5, 4))
    b = rng.standard_normal((5, 3))
    a[:, 2] = 0.0  # a zero shape has MAC 0 with everything
    for x, y in [(a, b), (a, a), (b, a), (a[:, 0], b), (a, b[:, 1]), (b[:, 0], b[:, 1]), (a[:, :0], b),
                 (list(a[:, 0]), a[:, 1].tolist()), (np.asfortranarray(a), b[::-1])]:
        mac = modal_assurance_criterion(x, y)
        assert mac.dtype == np.float64 and mac.shape == numpy_mac(x, y).shape
        np.testing.assert_allclose(mac, numpy_mac(x, y), rtol=0, atol=1e-14)
    assert not modal_assurance_criterion(a, b)[2].any()
    # single precision is computed in double (NumPy's products stayed in single precision)
    b32 = b.astype(np.float32)
    assert np.array_equal(modal_assurance_criterion(a, b32), modal_assurance_criterion(a, b32.astype(float)))


@pytest.mark.filterwarnings("ignore::modaluq.ModalUQWarning")
def test_diagram_is_the_cores_and_a_result_without_it_gives_the_same_numbers():
    # identify() keeps the core's identification and the diagram comes from _core.poles_of; a
    # Result made otherwise (here a copy) flattens its modes: the same diagram and modes, bit for bit
    import dataclasses
    import pickle

    sim = modaluq.simulate(20_000, seed=1)
    for u, extra in ((None, {}), (sim.u, {}), (None, {"uncertainty": False}), (sim.u, {"frequency_range": (1, 16)})):
        result = modaluq.identify(sim.y, u, fs=sim.fs, block_rows=15, orders=range(2, 31, 2), **extra)
        assert result.core_identification is not None
        copies = [dataclasses.replace(result), pickle.loads(pickle.dumps(result))]
        assert all(c.core_identification is None for c in copies)
        diagram = result.stabilization_diagram()
        assert diagram.noise_floor_order == result.significant_singular_values
        for copy in copies:
            other = copy.stabilization_diagram()
            for name in [f.name for f in dataclasses.fields(Diagram) if f.init]:
                x, y = getattr(diagram, name), getattr(other, name)
                if isinstance(x, np.ndarray):
                    assert x.dtype == y.dtype and x.shape == y.shape, name
                    assert np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"), name
                else:
                    assert x == y, name
            assert str(copy.select_modes()) == str(result.select_modes())


def test_select_modes_needs_the_diagram_stabilization_diagram_made():
    import dataclasses
    import pickle

    diagram = stabilization_diagram(make_result({4: [pole(5.0)], 6: [pole(5.0)], 8: [pole(5.0)]}))
    assert diagram.select_modes(min_cluster_size=2).n_modes == 1
    for copy in (pickle.loads(pickle.dumps(diagram)), dataclasses.replace(diagram)):
        np.testing.assert_array_equal(copy.frequency_hz, diagram.frequency_hz)
        with pytest.raises(TypeError, match="make it again with stabilization_diagram"):
            copy.select_modes()


def test_a_diagram_without_poles_keeps_its_channels():
    d = stabilization_diagram(make_result({2: [], 4: []}))
    assert d.n_poles == 0 and d.mode_shape.shape == (3, 0) and d.n_outputs == 3
    assert d.select_modes().n_modes == 0


# --------------------------------------------------------------------------- per-pole criteria


def test_lowest_order_poles_are_unstable_and_say_why():
    d = stabilization_diagram(make_result({4: [pole(5.0)], 6: [pole(5.0)]}))
    s, reason, _ = status_of(d, 4, 5.0)
    assert s is PoleStatus.UNSTABLE and "lowest order" in reason
    assert status_of(d, 6, 5.0)[0] is PoleStatus.STABLE and status_of(d, 6, 5.0)[1] == ""


def test_damping_out_of_range_is_rejected_with_the_value():
    c = StabilityCriteria()
    d = stabilization_diagram(make_result({4: [pole(5.0, xi=-0.01), pole(9.0, xi=0.35), pole(12.0, xi=0.19)]}), c)
    s, reason, _ = status_of(d, 4, 5.0)
    assert s is PoleStatus.REJECTED and "damping ratio -1 % < 0 %" in reason
    s, reason, _ = status_of(d, 4, 9.0)
    assert s is PoleStatus.REJECTED and "damping ratio 35 % > 20 %" in reason
    assert status_of(d, 4, 12.0)[0] is not PoleStatus.REJECTED   # 19 % <= max_damping_ratio 20 %


def test_coefficient_of_variation_above_threshold_is_rejected():
    c = StabilityCriteria(max_frequency_cov=0.02)
    poles = {4: [pole(10.0, sf=0.3), pole(20.0, sf=0.3), pole(30.0, sf=float("nan"))]}  # 3 %, 1.5 %, NaN
    d = stabilization_diagram(make_result(poles), c)
    s, reason, _ = status_of(d, 4, 10.0)
    assert s is PoleStatus.REJECTED and "frequency std/f 3 % > 2 %" in reason
    assert status_of(d, 4, 20.0)[0] is PoleStatus.UNSTABLE   # kept (lowest order), 1.5 % <= 2 %
    s, reason, _ = status_of(d, 4, 30.0)
    assert s is PoleStatus.REJECTED and "not finite" in reason
    # the same poles without the criterion: none rejected for uncertainty
    d = stabilization_diagram(make_result(poles), max_frequency_cov=None)
    assert d.count(PoleStatus.REJECTED) == 0


def test_all_failing_checks_are_listed_in_the_reason():
    d = stabilization_diagram(make_result({4: [pole(10.0, xi=-0.02, sf=1.0)]}))
    reason = status_of(d, 4, 10.0)[1]
    assert "damping ratio" in reason and "frequency std/f" in reason and "; " in reason


# --------------------------------------------------------------------------- between orders


def test_relative_frequency_change_threshold():
    # 10 -> 10.05 Hz is a 0.5 % change (<= 1 %); 20 -> 20.4 Hz is 2 % (> 1 %). Large σ so the σ test passes.
    d = stabilization_diagram(make_result({
        4: [pole(10.0, sf=0.1), pole(20.0, shape=SHAPE_B, sf=0.15)],
        6: [pole(10.05, sf=0.1), pole(20.4, shape=SHAPE_B, sf=0.15)]}))
    s, _, i = status_of(d, 6, 10.05)
    assert s is PoleStatus.STABLE and d.frequency_change[i] == pytest.approx(0.005)
    s, reason, i = status_of(d, 6, 20.4)
    assert s is PoleStatus.UNSTABLE and d.frequency_change[i] == pytest.approx(0.02)
    assert "frequency change 2 % > 1 %" in reason and "(vs order 4)" in reason


@pytest.mark.parametrize("sigma,k,expected", [
    (0.01, 2.0, PoleStatus.UNSTABLE),    # |Δf| = 0.05 Hz > 2 * sqrt(2) * 0.01 = 0.028 Hz
    (0.03, 2.0, PoleStatus.STABLE),      # 0.05 Hz <= 2 * sqrt(2) * 0.03 = 0.085 Hz
    (0.01, 4.0, PoleStatus.STABLE),      # 0.05 Hz <= 4 * sqrt(2) * 0.01 = 0.057 Hz
    (0.01, None, PoleStatus.STABLE),     # σ test switched off; 0.5 % <= 1 %
])
def test_frequency_change_judged_against_its_standard_deviation(sigma, k, expected):
    d = stabilization_diagram(make_result({4: [pole(10.0, sf=sigma)], 6: [pole(10.05, sf=sigma)]}),
                              frequency_std_factor=k)
    s, reason, i = status_of(d, 6, 10.05)
    assert s is expected
    if k is not None:
        assert d.frequency_change_std[i] == pytest.approx(0.05 / math.hypot(sigma, sigma))
    if expected is PoleStatus.UNSTABLE:
        assert "combined std" in reason


def test_damping_change_threshold_gives_stable_frequency():
    # Without the σ test: ξ 0.02 -> 0.025 is a 25 % change (> 10 %); 0.02 -> 0.021 is 5 % (<= 10 %).
    d = stabilization_diagram(make_result({
        4: [pole(10.0), pole(20.0, shape=SHAPE_B)],
        6: [pole(10.0, xi=0.025), pole(20.0, xi=0.021, shape=SHAPE_B)]}), damping_std_factor=None)
    s, reason, i = status_of(d, 6, 10.0)
    assert s is PoleStatus.STABLE_FREQUENCY and "damping change 25 % > 10 %" in reason
    assert d.damping_change[i] == pytest.approx(0.25)
    assert status_of(d, 6, 20.0)[0] is PoleStatus.STABLE


def test_mac_threshold_gives_stable_frequency():
    changed = (1.0, 0.5, 0.3)
    expected_mac = abs(np.vdot(SHAPE_A, changed)) ** 2 / (np.vdot(SHAPE_A, SHAPE_A) * np.vdot(changed, changed))
    assert 0.7 < expected_mac < 0.98   # 1.16^2 / 1.34^2 = 0.749
    d = stabilization_diagram(make_result({4: [pole(10.0)], 6: [pole(10.0, shape=changed)]}))
    s, reason, i = status_of(d, 6, 10.0)
    assert s is PoleStatus.STABLE_FREQUENCY and f"MAC {expected_mac:.4f} < 0.98" in reason
    assert d.mac[i] == pytest.approx(expected_mac)
    assert stabilization_diagram(make_result({4: [pole(10.0)], 6: [pole(10.0, shape=changed)]}),
                                 min_mac=0.7).status[1] is PoleStatus.STABLE


def test_match_is_the_nearest_accepted_pole_of_the_previous_order():
    # order 4: an accepted pole at 10.0 Hz and a rejected one (negative damping) at 10.02 Hz
    d = stabilization_diagram(make_result({
        4: [pole(5.0, shape=SHAPE_B), pole(10.0), pole(10.02, xi=-0.01)],
        6: [pole(10.02)]}))
    _, _, i_prev = status_of(d, 4, 10.0)
    s, _, i = status_of(d, 6, 10.02)
    assert d.matched_pole[i] == i_prev and s is PoleStatus.STABLE


def test_no_accepted_pole_at_previous_order():
    d = stabilization_diagram(make_result({4: [pole(10.0, xi=-0.01)], 6: [pole(10.0)]}))
    s, reason, i = status_of(d, 6, 10.0)
    assert s is PoleStatus.UNSTABLE and "no accepted pole at the previous order 4" in reason
    assert d.matched_pole[i] == -1 and np.isnan(d.frequency_change[i])


def test_without_uncertainty_the_sigma_criteria_are_skipped():
    # σ would reject (CoV 5 %) and fail the σ test; without uncertainty neither applies
    poles = {4: [pole(10.0, sf=0.5)], 6: [pole(10.05, sf=0.5)]}
    d = stabilization_diagram(make_result(poles, with_std=False))
    assert not d.has_uncertainty and np.all(np.isnan(d.frequency_std))
    assert status_of(d, 6, 10.05)[0] is PoleStatus.STABLE
    assert np.all(np.isnan(d.frequency_change_std))


def test_orders_cutting_close_singular_values_are_noted():
    d = stabilization_diagram(make_result({4: [pole(10.0)], 6: [pole(10.0)], 8: [pole(10.0)]},
                                          close_orders=(6, 8)))
    assert d.close_singular_value_orders == (6, 8)
    np.testing.assert_array_equal(d.close_singular_values, [False, True, True])


def test_every_non_stable_pole_has_a_reason_and_dataframe_shows_it():
    pytest.importorskip("pandas")
    d = stabilization_diagram(make_result({4: [pole(10.0), pole(15.0, xi=-0.1)], 6: [pole(10.5)]}))
    df = d.to_dataframe()
    assert list(df["status"]) == ["unstable", "rejected", "unstable"]
    assert all(df["reason"].str.len() > 0)
    assert {"order", "frequency_hz", "frequency_std", "damping_ratio", "damping_std", "mac",
            "mode_shape_y0"} <= set(df.columns)


@pytest.mark.parametrize("kwargs,name", [
    ({"min_mac": 1.5}, "min_mac"), ({"max_frequency_change": -0.1}, "max_frequency_change"),
    ({"frequency_std_factor": 0.0}, "frequency_std_factor"), ({"max_frequency_cov": -1}, "max_frequency_cov"),
    ({"min_damping_ratio": 0.3}, "max_damping_ratio"),
])
def test_bad_criteria_name_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        StabilityCriteria(**kwargs)


def test_bad_arguments_raise_type_errors():
    with pytest.raises(TypeError, match="result"):
        stabilization_diagram({"orders": [2]})
    with pytest.raises(TypeError, match="min_mac"):
        StabilityCriteria(min_mac="0.9")
    with pytest.raises(TypeError, match="diagram"):
        select_modes([1, 2])
    with pytest.raises(ValueError, match="distance_threshold"):
        ClusteringSettings(distance_threshold=0)
    with pytest.raises(ValueError, match="min_cluster_size"):
        ClusteringSettings(min_cluster_size=0)


# --------------------------------------------------------------------------- mode selection

ORDERS = list(range(2, 21, 2))  # 10 orders


def two_modes_and_a_spurious_pole(**pole_kwargs):
    """Mode A (5 Hz) and mode B (12 Hz) at every order, drifting 0.01 %/order; a spurious pole at
    8 Hz at orders 10 and 12 only (so stable at order 12 alone)."""
    poles = {}
    for j, n in enumerate(ORDERS):
        poles[n] = [pole(5.0 * (1 + 1e-4 * j), shape=SHAPE_A), pole(12.0 * (1 + 1e-4 * j), shape=SHAPE_B)]
        if n in (10, 12):
            poles[n].append(pole(8.0, shape=SHAPE_C))
    return poles


def test_two_modes_selected_and_the_spurious_cluster_dropped():
    d = stabilization_diagram(make_result(two_modes_and_a_spurious_pole()))
    sel = d.select_modes()
    # rule: 9 orders from the first stable one (4) -> ceil(0.25 * 9) = 3 poles needed
    assert sel.min_cluster_size == 3
    assert sel.n_modes == 2
    # the lowest order is unstable by rule, so each mode has one stable pole at orders 4..20
    np.testing.assert_array_equal(sel.n_poles, [9, 9])
    np.testing.assert_array_equal(sel.order_min, [4, 4])
    np.testing.assert_array_equal(sel.order_max, [20, 20])
    np.testing.assert_array_equal(sel.dropped_n_poles, [1])
    assert sel.dropped_frequency_hz[0] == pytest.approx(8.0)
    # representative: member nearest the median frequency (f grows with order -> middle order 12)
    np.testing.assert_array_equal(sel.representative_order, [12, 12])
    j12 = ORDERS.index(12)
    np.testing.assert_allclose(sel.frequency_hz, [5.0 * (1 + 1e-4 * j12), 12.0 * (1 + 1e-4 * j12)], rtol=1e-14)
    np.testing.assert_allclose(sel.frequency_std, 1e-3 * sel.frequency_hz, rtol=1e-14)
    # spread: sample std across the members
    f_members = 5.0 * (1 + 1e-4 * np.arange(1, 10))
    assert sel.frequency_spread[0] == pytest.approx(np.std(f_members, ddof=1), rel=1e-12)
    assert sel.damping_spread[0] == 0.0
    np.testing.assert_allclose(sel.min_mac, 1.0)
    # every selected pole knows its mode
    assert np.sum(sel.mode_of_pole == 0) == 9 and np.sum(sel.mode_of_pole == 1) == 9


def test_representative_prefers_orders_without_close_singular_values():
    # orders 4..14 flagged: candidates are orders 16, 18, 20; nearest to the median (order 12) is 16
    d = stabilization_diagram(make_result(two_modes_and_a_spurious_pole(), close_orders=(4, 6, 8, 10, 12, 14)))
    sel = d.select_modes()
    np.testing.assert_array_equal(sel.representative_order, [16, 16])


def test_one_pole_per_order_in_a_mode():
    poles = two_modes_and_a_spurious_pole()
    poles[10].append(pole(5.0 * (1 + 1e-4 * ORDERS.index(10)) + 2e-4, shape=SHAPE_A))  # a twin at order 10
    d = stabilization_diagram(make_result(poles))
    sel = d.select_modes()
    assert sel.n_modes == 2
    for members in sel.members:
        orders = d.order[members]
        assert orders.size == np.unique(orders).size


def test_explicit_min_cluster_size_drops_short_modes():
    d = stabilization_diagram(make_result(two_modes_and_a_spurious_pole()))
    sel = d.select_modes(min_cluster_size=10)
    assert sel.n_modes == 0
    np.testing.assert_array_equal(np.sort(sel.dropped_n_poles), [1, 9, 9])
    assert "0 modes" in str(sel)


def test_no_poles_give_an_empty_selection():
    pytest.importorskip("pandas")
    d = stabilization_diagram(make_result({2: [], 4: [pole(5.0, xi=-0.1)]}))
    assert d.n_poles == 1 and d.count("rejected") == 1
    sel = d.select_modes()
    assert sel.n_modes == 0 and sel.mode_shape.shape == (3, 0)
    assert sel.to_dict()["modes"] == [] and len(sel.to_dataframe()) == 0


def test_selection_without_uncertainty_has_nan_std_and_a_spread():
    d = stabilization_diagram(make_result(two_modes_and_a_spurious_pole(), with_std=False))
    sel = d.select_modes()
    assert sel.n_modes == 2 and not sel.has_uncertainty
    assert np.all(np.isnan(sel.frequency_std)) and np.all(sel.frequency_spread > 0)
    assert all(m["frequency_std"] is None for m in sel.to_dict()["modes"])   # JSON null
    assert " -" in sel.table()


def test_selection_is_deterministic():
    d = stabilization_diagram(make_result(two_modes_and_a_spurious_pole()))
    a, b = d.select_modes(), d.select_modes()
    np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
    np.testing.assert_array_equal(a.representative_pole, b.representative_pole)


# --------------------------------------------------------------------------- the paper's chain


@pytest.fixture(scope="module")
def chain_100k():
    return modaluq.simulate(100_000, seed=1)


@pytest.fixture(scope="module", params=[False, True], ids=["output-only", "input/output"])
def chain_selection(request, chain_100k):
    sim = chain_100k
    result = modaluq.identify(sim.y, sim.u if request.param else None, fs=sim.fs, block_rows=25,
                              orders=range(2, 61, 2))
    diagram = modaluq.stabilization_diagram(result)
    return sim, diagram, diagram.select_modes()


def test_chain_selection_finds_exactly_the_six_true_modes_within_3_sigma(chain_selection):
    sim, diagram, sel = chain_selection
    assert sel.n_modes == 6, sel
    # each true mode pairs with the selected mode nearest in frequency, one to one
    nearest = [int(np.argmin(np.abs(sel.frequency_hz - f))) for f in sim.frequency_hz]
    assert nearest == list(range(6))
    z = np.abs(sel.frequency_hz - sim.frequency_hz) / sel.frequency_std
    assert np.all(z <= 3.0), z
    assert np.all(sel.frequency_std > 0) and np.all(np.isfinite(sel.damping_std))


def test_chain_selection_reports_consistent_members_and_spread(chain_selection):
    _, diagram, sel = chain_selection
    for k, members in enumerate(sel.members):
        assert all(diagram.status[i] is PoleStatus.STABLE for i in members)
        assert sel.representative_pole[k] in members
        assert sel.frequency_spread[k] == pytest.approx(np.std(diagram.frequency_hz[members], ddof=1), rel=1e-12)
        assert sel.n_poles[k] == members.size >= sel.min_cluster_size
        # σ: the median over the cluster's reliable poles (robust to the order it is read at)
        reliable = members[~(diagram.close_singular_values[members] | diagram.noise_coupled[members])]
        assert sel.frequency_std[k] == np.median(diagram.frequency_std[reliable])
        assert sel.damping_std[k] == np.median(diagram.damping_std[reliable])
        # the shape: the shape pole's, a reliable member (by default the lowest sufficient one)
        assert sel.shape_pole[k] in reliable
        np.testing.assert_array_equal(sel.mode_shape[:, k], diagram.mode_shape[:, sel.shape_pole[k]])


def test_chain_lowest_representative_is_one_pole_read_at_the_lowest_sufficient_order(chain_selection):
    """representative="lowest": the same clusters; each mode is its reliable member at the lowest
    order >= max(k*, 2 m), with that pole's own σ and covariance; the noise floor is the result's."""
    sim, diagram, sel = chain_selection
    low = diagram.select_modes(representative="lowest")
    assert [list(m) for m in low.members] == [list(m) for m in sel.members]
    assert diagram.noise_floor_order > 0  # the identification's k* (Result.significant_singular_values)
    floor = max(diagram.noise_floor_order, 2 * low.n_modes)
    for k, members in enumerate(low.members):
        reliable = members[~(diagram.close_singular_values[members] | diagram.noise_coupled[members])]
        above = reliable[diagram.order[reliable] >= floor]
        i = above[np.argmin(diagram.order[above])] if above.size else reliable[np.argmax(diagram.order[reliable])]
        assert low.representative_pole[k] == i
        assert (low.frequency_hz[k], low.frequency_std[k], low.damping_std[k]) == (
            diagram.frequency_hz[i], diagram.frequency_std[i], diagram.damping_std[i])
        np.testing.assert_array_equal(low.mode_covariance[k], diagram.pole_covariance(int(i)))
    # read near the floor, not at the median member's order
    assert np.median(low.representative_order) < np.median(sel.representative_order)
    z = np.abs(low.frequency_hz - sim.frequency_hz) / low.frequency_std
    assert np.all(z <= 3.0), z


def test_chain_shape_pole_gives_the_shape_and_the_representative_f_and_xi(chain_selection):
    """The default shape_representative="lowest": f, ξ and their σ are those of
    shape_representative="median" (the representative's); the shape, its σ and its covariance block
    are those of the pole representative="lowest" reads; the covariance's [f, ξ] block is the
    mode's, its f-shape rows the shape pole's correlations at the mode's σ."""
    _, diagram, hyb = chain_selection
    assert hyb.settings.shape_representative == "lowest"
    low = diagram.select_modes(representative="lowest")
    med = diagram.select_modes(shape_representative="median")
    assert [list(m) for m in hyb.members] == [list(m) for m in med.members]
    for name in ("frequency_hz", "damping_ratio", "frequency_std", "damping_std", "representative_pole"):
        np.testing.assert_array_equal(getattr(hyb, name), getattr(med, name), err_msg=name)
    np.testing.assert_array_equal(hyb.shape_pole, low.representative_pole)
    np.testing.assert_array_equal(hyb.shape_order, diagram.order[hyb.shape_pole])
    np.testing.assert_array_equal(hyb.mode_shape, low.mode_shape)
    np.testing.assert_array_equal(hyb.mode_shape_std_real, low.mode_shape_std_real)
    np.testing.assert_array_equal(hyb.mpc_std, low.mpc_std)
    np.testing.assert_array_equal(med.shape_pole, med.representative_pole)  # "median": one pole
    assert "shapes: each cluster's pole at the lowest sufficient order" in str(hyb)
    np.testing.assert_array_equal(hyb.to_dataframe()["shape_order"].to_numpy(), hyb.shape_order)
    assert "shapes:" not in str(med) and "shapes:" not in str(low)
    assert np.any(hyb.shape_pole != hyb.representative_pole)
    for k, p in enumerate(hyb.shape_pole):
        own = diagram.pole_covariance(int(p))
        c = hyb.mode_covariance[k]
        np.testing.assert_array_equal(c[2:, 2:], own[2:, 2:])
        assert c[0, 0] == hyb.frequency_std[k] ** 2 and c[1, 1] == hyb.damping_std[k] ** 2
        corr = c[0, 2:] / np.sqrt(c[0, 0] * np.diag(c)[2:].clip(1e-300))
        own_corr = own[0, 2:] / np.sqrt(own[0, 0] * np.diag(own)[2:].clip(1e-300))
        np.testing.assert_allclose(corr, own_corr, rtol=1e-9, atol=1e-12)


def test_representative_must_be_median_or_lowest(chain_selection):
    _, diagram, _ = chain_selection
    with pytest.raises(ValueError, match="representative"):
        diagram.select_modes(representative="highest")
    with pytest.raises(TypeError, match="representative"):
        diagram.select_modes(representative=1)
    with pytest.raises(ValueError, match="shape_representative"):
        diagram.select_modes(shape_representative="highest")


def test_chain_rejected_and_unstable_poles_keep_their_reason(chain_selection):
    _, diagram, _ = chain_selection
    stable = diagram.is_status(PoleStatus.STABLE)
    assert np.all(diagram.reason[stable] == "")
    assert all(len(r) > 0 for r in diagram.reason[~stable])
    assert diagram.count(PoleStatus.REJECTED) > 0
    assert isinstance(diagram, Diagram) and len(diagram) == diagram.n_poles


def test_diagram_to_netcdf_round_trip(chain_selection, tmp_path):
    xr = pytest.importorskip("xarray")
    pytest.importorskip("netCDF4")
    _, diagram, sel = chain_selection
    path = tmp_path / "diagram.nc"
    diagram.to_xarray(sel).to_netcdf(path, engine="netcdf4")
    with xr.open_dataset(path) as ds:
        assert ds.sizes["pole"] == diagram.n_poles and ds.sizes["mode"] == 6
        np.testing.assert_array_equal(ds["status"].values.astype(str), [s.value for s in diagram.status])
        np.testing.assert_array_equal(ds["reason"].values.astype(str), diagram.reason)
        np.testing.assert_allclose(ds["frequency_std"].values, diagram.frequency_std)
        np.testing.assert_allclose(ds["selected_frequency_hz"].values, sel.frequency_hz)
        np.testing.assert_allclose(ds["mode_shape_real"].values + 1j * ds["mode_shape_imag"].values,
                                   diagram.mode_shape)


def test_noise_coupled_poles_are_a_column_and_never_the_representative():
    """A pole whose σ is not first-order (docs/uq-math.md §5.5) is kept in its cluster but never read from."""
    poles = two_modes_and_a_spurious_pole()
    for n in (12, 14, 16):  # the members nearest the cluster's median frequency
        for p in poles[n]:
            p["coupled"] = True
    d = stabilization_diagram(make_result(poles))
    flagged = d.noise_coupled
    assert flagged.dtype == bool and flagged.sum() == sum(len(poles[n]) for n in (12, 14, 16))
    assert list(d.to_dataframe()["noise_coupled"]) == list(flagged)
    sel = d.select_modes()
    assert sel.n_modes == 2
    for k in range(2):
        assert not flagged[sel.representative_pole[k]]
        assert d.order[sel.representative_pole[k]] not in (12, 14, 16)


def test_damping_change_is_judged_against_its_combined_std():
    """σ_ξ = 50 % of ξ: a 25 % change is noise (stable); a change beyond 2 combined σ, or beyond
    the loose backstop of 50 %, is not."""
    d = stabilization_diagram(make_result({
        4: [pole(10.0, sxi=0.01), pole(20.0, shape=SHAPE_B, sxi=0.01), pole(30.0, shape=SHAPE_C, sxi=0.001)],
        6: [pole(10.0, xi=0.025, sxi=0.0125), pole(20.0, xi=0.035, shape=SHAPE_B, sxi=0.02),
            pole(30.0, xi=0.025, shape=SHAPE_C, sxi=0.001)]}), damping_std_factor=2.0)
    assert status_of(d, 6, 10.0)[0] is PoleStatus.STABLE                     # 0.005 < 2 x 0.016
    s, reason, _ = status_of(d, 6, 20.0)                                      # 75 % > 50 % backstop
    assert s is PoleStatus.STABLE_FREQUENCY and "damping change 75 % > 50 %" in reason
    s, reason, _ = status_of(d, 6, 30.0)                                      # 0.005 > 2 x 0.0014
    assert s is PoleStatus.STABLE_FREQUENCY and "x combined std" in reason


def test_a_pole_matches_only_a_pole_within_the_window():
    """No pairing of a 3.3 Hz pole with a 27 Hz one: beyond match_window it is 'no match'."""
    d = stabilization_diagram(make_result({4: [pole(27.0)], 6: [pole(3.3), pole(27.0)]}))
    s, reason, i = status_of(d, 6, 3.3)
    assert s is PoleStatus.UNSTABLE and reason.startswith("no match: no pole within 5 %")
    assert d.matched_pole[i] == -1
    assert status_of(d, 6, 27.0)[0] is PoleStatus.STABLE


def test_channel_names_and_mode_numbers_are_the_same_in_every_output(tmp_path):
    """A DataFrame's columns name the shape columns everywhere; modes are numbered from 1 in the
    DataFrame index, the CSV, the JSON-ready dict and the xarray coordinate alike."""
    import pandas as pd

    from modaluq.export import write_csv

    sim = modaluq.simulate(20_000, seed=1)
    names = ["acc1", "acc2", "acc5"]
    y = pd.DataFrame(sim.y, columns=names)
    result = modaluq.identify(y, sim.u, fs=sim.fs, block_rows=15, orders=range(2, 31, 2))
    assert result.output_names == tuple(names)
    per_order = result.to_dataframe()
    assert {f"mode_shape_{n}" for n in names} <= set(per_order.columns)
    assert per_order["mode"].min() == 1
    diagram = result.stabilization_diagram()
    assert diagram.output_names == tuple(names)
    sel = diagram.select_modes()
    df = sel.to_dataframe()
    assert list(df.index) == list(range(1, sel.n_modes + 1)) and df.index.name == "mode"
    assert "mode_shape_acc2_real" in df.columns
    assert [m["mode"] for m in sel.to_dict()["modes"]] == list(range(1, sel.n_modes + 1))
    csv = pd.read_csv(write_csv(tmp_path / "modes.csv", sel))
    assert list(csv["mode"]) == list(range(1, sel.n_modes + 1))
    ds = diagram.to_xarray(selected=sel)
    assert list(ds["mode"].values) == list(range(1, sel.n_modes + 1))
    # mode_of_pole in the dataset uses the same numbers (0: no mode)
    k = int(sel.representative_pole[2])
    assert int(ds["mode_of_pole"].values[k]) == 3
    with pytest.raises(ValueError, match="output_names"):
        modaluq.identify(sim.y, fs=sim.fs, block_rows=15, orders=4, output_names=["a", "b"])


def test_spurious_clusters_are_dropped_by_their_uncertainty_with_the_reason():
    """The paper chain at 50 Hz, output-only, band 1-20 Hz with automatic settings: without the
    bandwidth test two spurious clusters (all poles noise-coupled, σ_f 1-2 % of f) are selected
    beside the six modes; with it (default) exactly the six remain, and the two are listed with
    their reason."""
    sim = modaluq.simulate(100_000, seed=1)
    with pytest.warns(modaluq.ModalUQWarning, match="decay more slowly"):  # the spurious poles' own
        result = modaluq.identify(sim.y, fs=sim.fs, frequency_range=(1, 20))
    diagram = result.stabilization_diagram()
    truth = np.sort(sim.frequency_hz)
    loose = diagram.select_modes(max_frequency_std_per_bandwidth=None)
    sel = diagram.select_modes()
    assert sel.n_modes == 6
    np.testing.assert_allclose(sel.frequency_hz, truth, rtol=0.005)
    assert loose.n_modes > 6  # the test removes something real
    extra = [f for f in loose.frequency_hz if np.min(np.abs(truth - f) / truth) > 0.01]
    reasons = dict(zip(np.round(sel.dropped_frequency_hz, 6), sel.dropped_reason))
    for f in extra:
        near = min(reasons, key=lambda g: abs(g - f))
        assert "half-power bandwidth" in reasons[near]
    assert np.all(sel.frequency_std_per_bandwidth < 1)


def test_horizon_check_finds_every_mode_at_each_horizon_and_reports_the_spread():
    """The chain at 0.75, 1 and 1.5 times the automatic horizon: each of the six modes is found
    at every horizon, within 0.5 % of the truth, and its spread across horizons is finite and
    of the order of its σ (no horizon bias on this well-separated system)."""
    sim = modaluq.simulate(40_000, seed=4)
    check = modaluq.check_horizons(sim.y, sim.u, fs=sim.fs, frequency_range=(1, 20))
    assert check.block_rows == (75, 100, 150) and check.reference_block_rows == 100
    assert check.found.all()
    np.testing.assert_allclose(check.frequency_hz, np.sort(sim.frequency_hz)[:, None] * np.ones((1, 3)), rtol=0.005)
    spread = check.frequency_spread
    assert np.all(np.isfinite(spread)) and np.all(spread < 5 * check.selected.frequency_std)
    df = check.to_dataframe()
    assert list(df.index) == list(range(1, 7)) and "frequency_hz_p150" in df.columns
    assert "settings check: block_rows 75, 100, 150" in str(check)
    with pytest.raises(ValueError, match="factors"):
        modaluq.check_horizons(sim.y, fs=sim.fs, frequency_range=(1, 20), factors=(0.0,))


def test_lowest_representative_says_whose_std_it_reports(chain_selection):
    _, diagram, sel = chain_selection
    low = diagram.select_modes(representative="lowest")
    assert "std: analytic, the pole's own, at the lowest sufficient order" in str(low)
    assert "median over the cluster" in str(sel)
    assert low.settings.to_dict()["representative"] == "lowest"
    from modaluq.export import report

    assert report(diagram, low)["units"]["std"] == ("analytic (delta-method) standard deviation, the pole's own, at "
                                                    "the lowest sufficient order")
    assert report(diagram, sel)["units"]["std"].endswith("(its poles that are not noise-coupled and not at a close cut, "
                                                         "or all of them where most are noise-coupled; widened "
                                                         "where order_discrepancy)")
