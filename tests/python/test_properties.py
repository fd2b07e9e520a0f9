"""Property tests (hypothesis): chunking, scaling, bad shapes."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import modaluq

_SIM = modaluq.simulate(3_000, seed=21)
_FS = _SIM.fs


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cuts=st.lists(st.integers(min_value=0, max_value=3_000), max_size=8), io=st.booleans(),
       q=st.integers(min_value=4, max_value=6))
def test_any_chunking_gives_the_batch_result(cuts, io, q):
    y, u = _SIM.y, (_SIM.u if io else None)
    n_columns = len(y) - 5 - q + 1
    block_length = n_columns // 10  # the batch call's N_b for n_blocks = 10
    acc = modaluq.CovarianceAccumulator(3, 1 if io else 0, block_rows=5, past_block_rows=q, block_length=block_length)
    edges = [0, *sorted(cuts), len(y)]
    for a, b in zip(edges[:-1], edges[1:]):
        acc.push(y[a:b], None if u is None else u[a:b])
    assert acc.n_samples == len(y)
    streamed = acc.identify(fs=_FS, orders=[6, 10])
    n_blocks = 10
    batch = modaluq.identify(y, u, fs=_FS, block_rows=5, past_block_rows=q, orders=[6, 10], n_blocks=n_blocks)
    assert streamed.n_blocks == batch.n_blocks == n_blocks
    for n in (6, 10):
        a, b = streamed.at_order(n), batch.at_order(n)
        np.testing.assert_allclose(a.frequency_hz, b.frequency_hz, rtol=1e-10)
        np.testing.assert_allclose(a.damping_ratio, b.damping_ratio, rtol=1e-8)
        np.testing.assert_allclose(a.frequency_std, b.frequency_std, rtol=1e-7)


@settings(max_examples=20, deadline=None)
@given(scale=st.floats(min_value=1e-6, max_value=1e6), io=st.booleans())
def test_scaling_y_leaves_frequency_and_damping_unchanged(scale, io):
    u = _SIM.u if io else None
    kw = dict(fs=_FS, block_rows=6, orders=8, n_blocks=10)
    a = modaluq.identify(_SIM.y, u, **kw).at_order(8)
    b = modaluq.identify(scale * _SIM.y, u, **kw).at_order(8)
    np.testing.assert_allclose(b.frequency_hz, a.frequency_hz, rtol=1e-9)
    np.testing.assert_allclose(b.damping_ratio, a.damping_ratio, rtol=1e-7)
    np.testing.assert_allclose(b.frequency_std, a.frequency_std, rtol=1e-6)
    np.testing.assert_allclose(b.damping_std, a.damping_std, rtol=1e-6)


@settings(max_examples=30, deadline=None)
@given(shape=st.one_of(
    st.tuples(st.integers(0, 3)),
    st.tuples(st.integers(0, 22), st.integers(0, 4)),  # 23 samples is the minimum here
    st.tuples(st.integers(1, 5), st.integers(1, 5), st.integers(1, 5)),
))
def test_bad_shapes_raise_value_error_not_crash(shape):
    y = np.random.default_rng(0).standard_normal(shape)
    with pytest.raises(ValueError):
        modaluq.identify(y, fs=10.0, block_rows=4, orders=2, n_blocks=2)


@settings(max_examples=30, deadline=None)
@given(n_u=st.integers(0, 60), width=st.integers(0, 3))
def test_mismatched_inputs_raise_value_error(n_u, width):
    assume(n_u != 60 or width == 0)  # a (60, k) input is valid (a constant one is reported, not refused)
    y = _SIM.y[:60]
    u = np.ones((n_u, width))
    with pytest.raises(ValueError):
        modaluq.identify(y, u, fs=_FS, block_rows=4, orders=2, n_blocks=2)
