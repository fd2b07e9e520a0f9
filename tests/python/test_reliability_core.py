"""Regression tests of the reliability audit (issue 13) on the C++ core, through Python.

Each test reproduces a defect of the audit: a record that used to give a silently wrong answer,
a crash or an abort must now be refused with the reason, flagged, or handled.
"""

import resource
import subprocess
import sys
import textwrap
import threading
import warnings

import numpy as np
import pytest

import modaluq

KW = dict(fs=50.0, block_rows=8, n_blocks=10)


@pytest.fixture(scope="module")
def sim():
    return modaluq.simulate(6000, seed=1)


def test_overflowing_products_are_refused_not_identified_from_a_stale_svd(sim):
    # Before: Eigen's SVD returned unfilled outputs and the previous call's modes came back.
    modaluq.identify(sim.y, orders=[4, 6], **KW)  # a valid call first, whose SVD could be reused
    y = sim.y.copy()
    y[5, 0] = 1e300
    with pytest.raises(ValueError, match="not finite.*rescale"):
        modaluq.identify(y, orders=[4, 6], **KW)


def test_a_large_finite_scale_gives_the_same_modes(sim):
    y = sim.y.copy()
    y[:, 2] *= 1e12
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ModalUQWarning)
        big = modaluq.identify(y, orders=[2], **KW)
    assert big.at_order(2).n_modes == 1
    assert np.all(np.isfinite(big.singular_values))


def test_outputs_passed_as_inputs_are_refused(sim):
    # Before: singular values ~1e-10 and confident modes at 11.10 and 15.65 Hz with sigma 0.05 Hz.
    with pytest.raises(ValueError, match="numerically zero.*outputs passed as inputs"):
        modaluq.identify(sim.y, sim.y.copy(), fs=50, block_rows=8, orders=[4, 6], n_blocks=10)


@pytest.mark.parametrize("kind", ["zeros", "constant", "impulse"])
def test_degenerate_records_are_a_value_error_saying_why(kind):
    y = np.zeros((6000, 3))
    if kind == "constant":
        y[:] = 2.5
    elif kind == "impulse":
        y[3000] = 1.0
    with pytest.raises(ValueError, match="no dynamics|numerical rank"):
        modaluq.identify(y, orders=[2, 4], **KW)


def test_a_step_is_identified_up_to_its_rank_and_flagged_above():
    # A step has H of numerical rank 2 (a near-DC pole at order 2); every higher order used to
    # fail the whole run with NumericalError, and is now a flagged order without modes.
    y = np.zeros((6000, 3))
    y[3000:] = 1.0
    with pytest.warns(modaluq.ModalUQWarning, match="use orders <= 2"):
        r = modaluq.identify(y, orders=[2, 4, 6], **KW)
    assert r.numerical_rank == 2
    assert [m.degenerate for m in r.modes] == [False, True, True]
    assert np.all(r.at_order(2).frequency_hz < 1.0 / (6000 / 50.0))  # below the record's resolution


def test_orders_above_the_numerical_rank_are_flagged_not_fatal():
    t = np.arange(6000) / 50.0
    rng = np.random.default_rng(0)
    y = np.sin(2 * np.pi * 3.0 * t)[:, None] * np.ones((1, 3)) + 1e-9 * rng.standard_normal((6000, 3))
    with pytest.warns(modaluq.ModalUQWarning, match="use orders <= 2"):
        r = modaluq.identify(y, orders=[2, 4, 6, 8], **KW)
    assert r.numerical_rank == 2
    assert not r.at_order(2).degenerate
    assert abs(r.at_order(2).frequency_hz[0] - 3.0) < 1e-6
    for n in (4, 6, 8):
        m = r.at_order(n)
        assert m.degenerate and m.n_modes == 0
        assert "numerical rank" in m.note
        assert "no modes" in str(m)


def test_one_channel_in_other_units_flags_high_orders_instead_of_failing_the_run():
    # README settings with one channel in x1e6 units: before, one order failed the whole run.
    s = modaluq.simulate(100_000, seed=1)
    y = s.y.copy()
    y[:, 1] *= 1e6
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ModalUQWarning)
        r = modaluq.identify(y, s.u, fs=s.fs, block_rows=15, orders=range(2, 41, 2), n_blocks=50)
    good = [m for m in r.modes if not m.degenerate]
    assert good and all(np.all(np.isfinite(m.frequency_hz)) for m in good)
    assert all(m.n_modes == 0 for m in r.modes if m.degenerate)
    assert r.at_order(12).n_modes >= 5


def _hammer(acc, chunk, errors, n=200):
    try:
        for _ in range(n):
            acc.push(chunk)
    except RuntimeError as exc:
        errors.append(str(exc))


def test_concurrent_use_of_one_accumulator_is_refused_and_leaves_it_intact(sim):
    # Before: "missing boundary samples (internal error)", segfaults, bad_alloc, OOM kills.
    acc = modaluq.CovarianceAccumulator(n_outputs=3, block_rows=8, block_length=200)
    chunk = np.ascontiguousarray(sim.y[:3000])
    errors: list[str] = []
    threads = [threading.Thread(target=_hammer, args=(acc, chunk, errors)) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors, "four threads pushing 200 times each never overlapped"
    assert all("in use by another thread" in e for e in errors)
    # Whatever was pushed went in whole: the accumulator equals one fed the same count serially.
    n_chunks = acc.n_samples // chunk.shape[0]
    assert acc.n_samples == n_chunks * chunk.shape[0]
    serial = modaluq.CovarianceAccumulator(n_outputs=3, block_rows=8, block_length=200)
    for _ in range(n_chunks):
        serial.push(chunk)
    np.testing.assert_array_equal(acc.covariances().R1, serial.covariances().R1)


def test_push_while_another_thread_identifies_is_refused(sim):
    acc = modaluq.CovarianceAccumulator(n_outputs=3, block_rows=15, block_length=2000)
    acc.push(modaluq.simulate(200_000, seed=3).y)
    errors: list[str] = []
    stop = threading.Event()

    def pusher():
        while not stop.is_set():
            try:
                acc.push(sim.y[:100])
            except RuntimeError as exc:
                errors.append(str(exc))

    t = threading.Thread(target=pusher)
    t.start()
    try:
        for _ in range(5):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", modaluq.ModalUQWarning)
                    acc.identify(fs=50.0, orders=range(2, 31, 2))
            except RuntimeError as exc:
                errors.append(str(exc))
    finally:
        stop.set()
        t.join()
    assert errors and all("in use by another thread" in e for e in errors)


def test_sequential_use_from_several_threads_is_fine(sim):
    acc = modaluq.CovarianceAccumulator(n_outputs=3, block_rows=8, block_length=500)
    lock = threading.Lock()
    parts = np.array_split(sim.y, 6)

    def push(part):
        with lock:
            acc.push(part)

    for part in parts:  # one thread after the other, in order
        t = threading.Thread(target=push, args=(part,))
        t.start()
        t.join()
    whole = modaluq.CovarianceAccumulator(n_outputs=3, block_rows=8, block_length=500)
    whole.push(sim.y)
    np.testing.assert_allclose(acc.covariances().R1, whole.covariances().R1, rtol=1e-12, atol=1e-12)


def test_an_accumulator_cannot_be_merged_into_itself(sim):
    acc = modaluq.CovarianceAccumulator(n_outputs=3, block_rows=8, block_length=500)
    acc.push(sim.y)
    with pytest.raises(ValueError, match="itself"):
        acc.merge(acc)


def test_threads_the_os_refuses_do_not_abort_the_process():
    # Before: std::terminate (exit 134) when a thread could not be created. Here every thread
    # stack is 2 GiB (RLIMIT_STACK sets glibc's default) and the address space has room for about
    # one more, so most of the 200 threads are refused (their stack mmap fails with ENOMEM) while
    # ordinary allocations still succeed; the result must equal the one-thread result.
    code = textwrap.dedent("""
        import resource, warnings
        import numpy as np
        import modaluq
        warnings.simplefilter("ignore")
        sim = modaluq.simulate(20000, seed=1)
        kw = dict(fs=sim.fs, block_rows=10, orders=[4, 8, 12], n_blocks=40)
        ref = modaluq.identify(sim.y, **kw)
        vm = int(open("/proc/self/statm").read().split()[0]) * resource.getpagesize()
        resource.setrlimit(resource.RLIMIT_AS, (vm + (3 << 30), resource.RLIM_INFINITY))
        same = True
        for _ in range(3):
            r = modaluq.identify(sim.y, threads=200, **kw)
            same &= np.array_equal(r.at_order(12).frequency_std, ref.at_order(12).frequency_std)
        print(same)
    """)

    def huge_thread_stacks():
        resource.setrlimit(resource.RLIMIT_STACK, (2 << 30, resource.RLIM_INFINITY))

    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       preexec_fn=huge_thread_stacks)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip() == "True"


def test_accumulator_state_grows_with_blocks_not_samples(sim):
    y = modaluq.simulate(400_000, seed=2).y
    few_long = modaluq.CovarianceAccumulator(n_outputs=3, block_rows=12, block_length=20_000)
    few_short = modaluq.CovarianceAccumulator(n_outputs=3, block_rows=12, block_length=2_000)
    few_long.push(y)
    few_short.push(y[:40_000])
    assert few_long.state_bytes == few_short.state_bytes


def test_order_one_alone_is_accepted():
    s = modaluq.simulate(20_000, seed=1)
    r = modaluq.identify(s.y, s.u, fs=s.fs, block_rows=15, orders=[1], uncertainty=False)
    assert r.at_order(1).n_modes == 0 and not r.at_order(1).degenerate


def test_a_short_record_near_its_noise_is_a_warning_not_a_refusal():
    # The signal-to-noise statistic comes from the blocks: a short record with real dynamics can
    # fall below 3 by chance; it is reported (flag + warning), and identified as without uncertainty.
    s = modaluq.simulate(600, seed=0)
    kw = dict(fs=s.fs, block_rows=6, orders=[4, 6], n_blocks=10)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = modaluq.identify(s.y, **kw)
    plain = modaluq.identify(s.y, uncertainty=False, **kw)
    np.testing.assert_allclose(r.at_order(6).frequency_hz, plain.at_order(6).frequency_hz, rtol=1e-12)
    assert r.low_signal_to_noise == (r.signal_to_noise < 3)
    if r.low_signal_to_noise:
        assert any("estimation noise" in str(w.message) for w in caught)


def test_a_degenerate_order_keeps_the_uncertainty_of_the_others_in_the_diagram():
    # A degenerate order used to look like "no uncertainty", which switched the sigma criteria
    # of the stabilization diagram off for every order.
    t = np.arange(6000) / 50.0
    rng = np.random.default_rng(0)
    y = (np.sin(2 * np.pi * 3.0 * t) + np.sin(2 * np.pi * 7.0 * t))[:, None] * np.ones((1, 3))
    y = y + 1e-9 * rng.standard_normal(y.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ModalUQWarning)
        r = modaluq.identify(y, orders=[2, 4, 6], **KW)
    m6 = r.at_order(6)
    assert m6.degenerate and m6.has_uncertainty and m6.mode_shape.shape == (3, 0)
    assert m6.covariance.shape == (0, 8, 8)
    assert all(m.has_uncertainty for m in r.modes)
    strict = r.stabilization_diagram(max_frequency_cov=1e-30)
    assert "frequency std" in " ".join(str(x) for x in strict.to_dataframe()["reason"] if x)
