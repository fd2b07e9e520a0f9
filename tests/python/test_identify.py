"""modaluq.identify: the C++ core against the NumPy oracle, the Python API, and bad input."""

import threading
import time

import numpy as np
import pytest

import modaluq
import oracle
from modaluq import _core

# (block_rows, past_block_rows, references, orders): p != q, with and without references.
SETTINGS = [
    (6, 7, None, [4, 8, 12]),
    (7, 5, [0, 2], [6, 10]),
    (7, 7, None, [8, 12, 16, 18]),  # up to 1.5x the true order: noise columns frozen (§5.5)
]


def _pairs(ours, theirs):
    assert ours.n_modes == len(theirs["frequency_hz"]), (ours.frequency_hz, theirs["frequency_hz"])


@pytest.mark.parametrize("freeze", [True, False], ids=["frozen noise", "plain"])
@pytest.mark.parametrize("io", [False, True], ids=["output-only", "input/output"])
@pytest.mark.parametrize("p,q,refs,orders", SETTINGS)
def test_core_equals_oracle(chain, io, p, q, refs, orders, freeze):
    u = chain.u if io else None
    kw = dict(fs=chain.fs, block_rows=p, past_block_rows=q, orders=orders, n_blocks=20, references=refs,
              freeze_noise=freeze, noise_coupling_limit=5.0)  # low: both kinds of poles occur here
    ours = modaluq.identify(chain.y, u, **kw)
    ref = oracle.identify(chain.y, u, **kw)
    assert ours.orders == tuple(orders)
    k_star = ref[orders[0]]["significant_singular_values"]
    assert ours.significant_singular_values == k_star
    if max(orders) > 12:
        assert k_star < max(orders)  # the case exercises the freeze
    for n in orders:
        m, r = ours.at_order(n), ref[n]
        _pairs(m, r)
        np.testing.assert_allclose(m.noise_coupling, r["noise_coupling"], rtol=1e-7)
        np.testing.assert_array_equal(m.noise_coupled, r["noise_coupled"])
        if not freeze or n <= k_star:
            assert np.all(m.noise_coupling == 1.0) and not m.noise_coupled.any()
        np.testing.assert_allclose(m.frequency_hz, r["frequency_hz"], rtol=1e-9, atol=0)
        np.testing.assert_allclose(m.damping_ratio, r["damping_ratio"], rtol=1e-9, atol=0)
        np.testing.assert_allclose(m.mode_shape, r["mode_shape"], rtol=1e-8, atol=1e-8)
        np.testing.assert_allclose(m.frequency_std, r["frequency_std"], rtol=1e-8, atol=0)
        np.testing.assert_allclose(m.damping_std, r["damping_std"], rtol=1e-8, atol=0)
        # The reference component has std exactly 0 in both; others to 1e-8 relative.
        for ours_s, ref_s in ((m.mode_shape_std_real, r["mode_shape_std_real"]),
                              (m.mode_shape_std_imag, r["mode_shape_std_imag"])):
            np.testing.assert_allclose(ours_s, ref_s, rtol=1e-8, atol=1e-8 * np.max(ref_s))
        np.testing.assert_allclose(m.covariance, r["covariance"], rtol=1e-7,
                                   atol=1e-8 * np.max(np.abs(r["covariance"])))


def test_without_uncertainty_equals_oracle_and_has_no_std(chain):
    kw = dict(fs=chain.fs, block_rows=6, orders=[12], uncertainty=False)
    ours = modaluq.identify(chain.y, chain.u, **kw)
    ref = oracle.identify(chain.y, chain.u, **kw)
    m = ours.at_order(12)
    np.testing.assert_allclose(m.frequency_hz, ref[12]["frequency_hz"], rtol=1e-9)
    assert m.frequency_std is None and m.covariance is None and not m.has_uncertainty
    assert ours.n_blocks == 0


def test_identified_frequencies_within_one_percent_at_10k(chain_10k):
    sim = chain_10k
    for u, modes_checked in ((None, range(1, 6)), (sim.u, range(6))):
        m = modaluq.identify(sim.y, u, fs=sim.fs, block_rows=15, orders=12).at_order(12)
        for k in modes_checked:
            err = np.min(np.abs(m.frequency_hz - sim.frequency_hz[k])) / sim.frequency_hz[k]
            assert err < 0.01, (u is None, k, m.frequency_hz)


def test_result_api(chain):
    res = modaluq.identify(chain.y, chain.u, fs=chain.fs, block_rows=6, orders=range(2, 13, 2), n_blocks=20)
    assert res.orders == (2, 4, 6, 8, 10, 12)
    m = res.at_order(12)
    l = chain.y.shape[1]
    assert m.mode_shape.shape == (l, m.n_modes) and m.mode_shape.dtype == complex
    assert m.covariance.shape == (m.n_modes, 2 + 2 * l, 2 + 2 * l)
    np.testing.assert_allclose(np.sqrt(m.covariance[:, 0, 0]), m.frequency_std, rtol=1e-12)
    np.testing.assert_allclose(np.sqrt(m.covariance[:, 1, 1]), m.damping_std, rtol=1e-12)
    np.testing.assert_allclose(np.sqrt(m.covariance[:, 2:2 + l, 2:2 + l].diagonal(axis1=1, axis2=2)).T,
                               m.mode_shape_std_real, rtol=1e-12, atol=1e-15)
    # Mode shapes: largest-modulus component exactly 1.
    k = np.argmax(np.abs(m.mode_shape), axis=0)
    assert np.all(m.mode_shape[k, np.arange(m.n_modes)] == 1)
    assert np.all(np.diff(m.frequency_hz) > 0)
    with pytest.raises(ValueError, match="order 5 was not identified"):
        res.at_order(5)
    text = str(res)
    assert "input/output" in text and "f [Hz]" in text and f"{m.frequency_hz[0]:.4f}" in text
    assert res.settings["past_block_rows"] == 6 and res.settings["references"] == [0, 1, 2]
    df = res.to_dataframe()
    assert len(df) == sum(x.n_modes for x in res)
    np.testing.assert_array_equal(df[df.order == 12].frequency_hz.to_numpy(), m.frequency_hz)
    assert "frequency_std" in m.to_dataframe()


def test_one_dimensional_y_and_integer_data(chain):
    y1 = chain.y[:, 0]
    a = modaluq.identify(y1, fs=chain.fs, block_rows=20, orders=8, uncertainty=False).at_order(8)
    b = modaluq.identify(y1[:, None], fs=chain.fs, block_rows=20, orders=8, uncertainty=False).at_order(8)
    np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
    yi = np.round(chain.y * 1000).astype(np.int32)
    c = modaluq.identify(yi, fs=chain.fs, block_rows=6, orders=6, uncertainty=False)
    d = modaluq.identify(yi.astype(float), fs=chain.fs, block_rows=6, orders=6, uncertainty=False)
    np.testing.assert_array_equal(c.at_order(6).frequency_hz, d.at_order(6).frequency_hz)


def test_binding_does_not_copy_samples(chain):
    y = np.ascontiguousarray(chain.y)
    assert _core._data_pointer(y.T) == y.__array_interface__["data"][0]
    prepared = modaluq.checks.as_samples(y, "y")
    assert prepared is y or prepared.__array_interface__["data"][0] == y.__array_interface__["data"][0]
    # A copy is never made silently: a non-contiguous view is refused by the binding itself.
    with pytest.raises(TypeError):
        _core._data_pointer(y[::2].T)


def test_gil_is_released_during_identify():
    sim = modaluq.simulate(200_000, seed=5)
    ticks = []
    stop = threading.Event()

    def ticker():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=ticker)
    t.start()
    try:
        t0 = time.perf_counter()
        modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=40, orders=range(2, 81, 2), n_blocks=50)
        t1 = time.perf_counter()
    finally:
        stop.set()
        t.join()
    during = [x for x in ticks if t0 < x < t1]
    # With the GIL held for the whole call the ticker could not run at all in between.
    assert len(during) >= 5, (len(during), t1 - t0)


def test_rank_deficient_input_is_reported(chain):
    u = np.column_stack([chain.u[:, 0], 2.0 * chain.u[:, 0]])  # duplicated input
    with pytest.warns(modaluq.ModalUQWarning, match="rank deficient"):
        res = modaluq.identify(chain.y, u, fs=chain.fs, block_rows=6, orders=8, n_blocks=20)
    assert res.input_rank_deficient and res.input_rank == 6
    assert any("rank deficient" in w for w in res.warnings)


def test_too_few_blocks_is_reported(chain):
    with pytest.warns(modaluq.ModalUQWarning, match="too few"):
        res = modaluq.identify(chain.y, fs=chain.fs, block_rows=6, orders=8, n_blocks=4)
    assert res.too_few_blocks


# --------------------------------------------------------------------------- bad input

def _call(chain, **overrides):
    kw = dict(y=chain.y, u=chain.u, fs=chain.fs, block_rows=6, orders=8, n_blocks=10)
    kw.update(overrides)
    y, u = kw.pop("y"), kw.pop("u")
    return modaluq.identify(y, u, **kw)


@pytest.mark.parametrize("overrides,exc,pattern", [
    (dict(fs=0.0), ValueError, "fs must be finite and > 0"),
    (dict(fs=float("nan")), ValueError, "fs must be finite"),
    (dict(fs="50"), TypeError, "fs must be a real number"),
    (dict(block_rows=1), ValueError, "block_rows must be >= 2"),
    (dict(block_rows=6.0), TypeError, "block_rows must be an integer"),
    (dict(past_block_rows=0), ValueError, "past_block_rows must be >= 1"),
    (dict(orders=16), ValueError, r"order 16 is above what the horizons support.*= 15"),
    (dict(orders=0), ValueError, "orders must be >= 1"),
    (dict(orders=[]), ValueError, "orders must not be empty"),
    (dict(orders=[8.5]), TypeError, "orders must be an integer"),
    (dict(n_blocks=1), ValueError, "n_blocks must be >= 2"),
    (dict(references=[3]), ValueError, "references: index 3 is out of range for 3 outputs"),
    (dict(references=[0, 0]), ValueError, "references: index 0 is repeated"),
    (dict(n_blocks=500), ValueError, r"record too short: 6000 samples.*at least 6011 samples"),
    (dict(input_rcond=2.0), ValueError, "input_rcond"),
])
def test_bad_settings_raise_naming_the_parameter(chain, overrides, exc, pattern):
    with pytest.raises(exc, match=pattern):
        _call(chain, **overrides)


def test_bad_samples_raise_naming_the_array_and_the_place(chain):
    y = chain.y.copy()
    y[1234, 2] = np.nan
    with pytest.raises(ValueError, match=r"y.*sample 1234, channel 2.*NaN"):
        _call(chain, y=y)
    u = chain.u.copy()
    u[17, 0] = np.inf
    with pytest.raises(ValueError, match=r"u.*sample 17, channel 0"):
        _call(chain, u=u)
    with pytest.raises(TypeError, match="y must be real"):
        _call(chain, y=chain.y.astype(complex))
    with pytest.raises(TypeError, match="u must be real"):
        _call(chain, u=chain.u.astype(complex))
    with pytest.raises(TypeError, match="y must hold real numbers"):
        _call(chain, y=np.array([["a", "b"]] * 100))
    with pytest.raises(ValueError, match="u must have as many samples as y"):
        _call(chain, u=chain.u[:-1])
    with pytest.raises(ValueError, match=r"y must have shape \(n_samples, n_channels\)"):
        _call(chain, y=chain.y[None])
    with pytest.raises(ValueError, match="at least one channel"):
        _call(chain, y=np.empty((100, 0)))
    with pytest.raises(ValueError, match="record too short"):
        _call(chain, y=chain.y[:50], u=chain.u[:50])
    with pytest.raises(TypeError, match="y must be an array"):
        _call(chain, y=None)


def test_version_agrees():
    from importlib.metadata import version

    assert modaluq.__version__ == _core.__version__ == version("modaluq")


def test_build_says_whether_products_go_to_a_blas():
    # True when CMake found OpenBLAS at build time (tests/run.sh installs it); the oracle
    # tests then check the BLAS path, ctest checks both paths of gemm().
    assert isinstance(_core.uses_blas, bool)


def test_threads_give_the_same_result(chain):
    kw = dict(fs=chain.fs, block_rows=6, orders=range(2, 13, 2), n_blocks=20)
    one = modaluq.identify(chain.y, chain.u, **kw)
    two = modaluq.identify(chain.y, chain.u, threads=2, **kw)
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
        np.testing.assert_array_equal(a.covariance, b.covariance)
    with pytest.raises(ValueError, match="threads must be >= 1"):
        modaluq.identify(chain.y, chain.u, threads=0, **kw)


def test_compute_calls_run_the_blas_on_one_thread(monkeypatch):
    # modaluq's parallelism is `threads`; its OpenBLAS products run on one thread during a call
    # (oversubscribed OpenBLAS threads slow runs down several times), and the setting is restored.
    from threadpoolctl import threadpool_info

    from modaluq import _blas

    if not _core.uses_blas:
        pytest.skip("this build uses Eigen's products")
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)

    def ours():
        return [i for i in threadpool_info() if i["user_api"] == "blas" and "libopenblas" in i["filepath"]
                and "scipy" not in i["filepath"] and "numpy" not in i["filepath"]]

    before = [i["num_threads"] for i in ours()]
    assert before, "the OpenBLAS the extension links is loaded"
    with _blas.single_threaded():
        assert all(i["num_threads"] == 1 for i in ours())
    assert [i["num_threads"] for i in ours()] == before
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")  # the user's own setting is left alone
    with _blas.single_threaded():
        assert [i["num_threads"] for i in ours()] == before
