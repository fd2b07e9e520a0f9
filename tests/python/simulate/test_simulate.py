"""Tests of modaluq.simulate: the paper's 6-DOF chain (docs/uq-math.md §11.1, paper §5.1)."""

import time

import numpy as np
import pytest
import scipy.linalg

from modaluq.simulate import (
    Simulation,
    acceleration_response,
    chain_system,
    default_output_dofs,
    modal_parameters,
    simulate,
    state_space,
)

# Printed in docs/uq-math.md §11.1 (4 decimals) and in the paper's Table 1 (4 significant digits).
DESIGN_FREQUENCIES_HZ = [1.9297, 5.6180, 8.6824, 14.4938, 15.8462, 17.0114]
PAPER_FREQUENCIES_HZ = [1.930, 5.618, 8.682, 14.49, 15.85, 17.01]


def _paper_chain_by_hand():
    """M and K of the paper's chain, written out element by element (independent of the code)."""
    m = 1 / 20
    k = [100.0, 200.0, 100.0, 200.0, 100.0, 200.0]  # k1 (to ground) ... k6
    M = m * np.eye(6)
    K = np.zeros((6, 6))
    for i in range(6):  # spring k[i] joins mass i-1 (or the ground) and mass i
        K[i, i] += k[i]
        if i > 0:
            K[i - 1, i - 1] += k[i]
            K[i - 1, i] -= k[i]
            K[i, i - 1] -= k[i]
    return M, K


def _state_space_loop(A, B, C, D, force):
    """Plain recursion x_{k+1} = A x_k + B w_k, y_k = C x_k + D w_k from x_0 = 0."""
    x = np.zeros(A.shape[0])
    y = np.empty((force.shape[0], C.shape[0]))
    for k, w in enumerate(force):
        y[k] = C @ x + D @ w
        x = A @ x + B @ w
    return y


def _sig4(values):
    return np.array([float(f"{v:.4g}") for v in values])


# ----------------------------------------------------------------------- true values


def test_chain_matrices_match_hand_built_chain():
    M_ref, K_ref = _paper_chain_by_hand()
    M, K, Cdamp = chain_system()
    np.testing.assert_array_equal(M, M_ref)
    np.testing.assert_array_equal(K, K_ref)
    np.testing.assert_allclose(Cdamp, Cdamp.T, atol=1e-14)


def test_true_frequencies_of_default_chain():
    # Independent computation from the hand-built matrices.
    M_ref, K_ref = _paper_chain_by_hand()
    f_ref = np.sqrt(scipy.linalg.eigh(K_ref, M_ref, eigvals_only=True)) / (2 * np.pi)
    np.testing.assert_array_equal(_sig4(f_ref), _sig4(DESIGN_FREQUENCIES_HZ))
    np.testing.assert_allclose(f_ref, DESIGN_FREQUENCIES_HZ, atol=5e-5)
    # Second check against the paper's printed values (4 significant digits).
    np.testing.assert_array_equal(_sig4(f_ref), _sig4(PAPER_FREQUENCIES_HZ))

    sim = simulate(200, seed=0, discard=0)
    np.testing.assert_allclose(sim.frequency_hz, f_ref, rtol=1e-12)
    np.testing.assert_array_equal(_sig4(sim.frequency_hz), _sig4(PAPER_FREQUENCIES_HZ))
    np.testing.assert_allclose(sim.damping_ratio, 0.02, rtol=1e-10)
    assert np.all(np.diff(sim.frequency_hz) > 0)


def test_other_stiffness_arrangements_do_not_match_paper():
    # docs/uq-math.md §11.1: only k = (100, 200, 100, 200, 100, 200) from the ground matches.
    for k in ([200, 100, 200, 100, 200, 100], [100, 100, 100, 200, 200, 200]):
        M, K, _ = chain_system(stiffness=k)
        f = np.sqrt(scipy.linalg.eigvalsh(K, M)) / (2 * np.pi)
        assert not np.allclose(f, PAPER_FREQUENCIES_HZ, rtol=1e-3)


def test_modal_damping_and_continuous_eigenvalues():
    xi = [0.01, 0.02, 0.03, 0.04, 0.05, 0.06]
    M, K, Cdamp = chain_system(damping_ratio=xi)
    # Eigenvalues of the damped continuous system, computed directly.
    Ac = np.block([[-np.linalg.solve(M, Cdamp), -np.linalg.solve(M, K)],
                   [np.eye(6), np.zeros((6, 6))]])
    mu = np.linalg.eigvals(Ac)
    mu = mu[mu.imag > 0]
    mu = mu[np.argsort(np.abs(mu))]
    omega = np.sqrt(scipy.linalg.eigvalsh(K, M))
    np.testing.assert_allclose(np.abs(mu), omega, rtol=1e-10)
    np.testing.assert_allclose(-mu.real / np.abs(mu), xi, rtol=1e-9)
    f, d, shape = modal_parameters(M, K, Cdamp, output_dofs=(0, 1, 4))
    np.testing.assert_allclose(f, omega / (2 * np.pi), rtol=1e-10)
    np.testing.assert_allclose(d, xi, rtol=1e-9)
    assert shape.shape == (3, 6) and np.iscomplexobj(shape)


def test_mode_shapes_normalised_and_equal_to_undamped_shapes():
    sim = simulate(100, seed=0, discard=0)
    shape = sim.mode_shape
    assert shape.shape == (3, 6) and shape.dtype == np.complex128
    ref = np.argmax(np.abs(shape), axis=0)
    assert np.all(shape[ref, np.arange(6)] == 1.0)  # exactly 1 + 0j
    assert np.all(np.abs(shape) <= 1.0 + 1e-12)
    # docs/uq-math.md §11.3 reports the reference components k = [2, 1, 0, 2, 0, 1].
    np.testing.assert_array_equal(ref, [2, 1, 0, 2, 0, 1])
    # Modal damping: the shapes are the real undamped shapes at the outputs.
    M_ref, K_ref = _paper_chain_by_hand()
    _, Phi = scipy.linalg.eigh(K_ref, M_ref)
    expected = Phi[[0, 1, 4]] / Phi[[0, 1, 4]][ref, np.arange(6)]
    np.testing.assert_allclose(shape, expected, atol=1e-10)


def test_mode_shapes_match_discrete_system_eigenvectors():
    # Paper Eq. (5): phi = C v with v an eigenvector of the discrete A.
    M, K, Cdamp = chain_system()
    A, _, C, _ = state_space(M, K, Cdamp, fs=50.0, output_dofs=(0, 1, 4))
    lam, V = np.linalg.eig(A)
    keep = lam.imag > 0
    mu = np.log(lam[keep]) * 50.0
    order = np.argsort(np.abs(mu))
    phi = (C @ V[:, keep])[:, order]
    phi = phi / phi[np.argmax(np.abs(phi), axis=0), np.arange(6)]
    f, xi, shape = modal_parameters(M, K, Cdamp, output_dofs=(0, 1, 4))
    np.testing.assert_allclose(np.abs(mu[order]) / (2 * np.pi), f, rtol=1e-10)
    np.testing.assert_allclose(-mu[order].real / np.abs(mu[order]), xi, rtol=1e-8)
    np.testing.assert_allclose(phi, shape, atol=1e-9)


# ----------------------------------------------------------------- exact simulation


def test_state_space_is_zero_order_hold_discretisation():
    M, K, Cdamp = chain_system()
    fs = 50.0
    A, B, C, D = state_space(M, K, Cdamp, fs=fs, output_dofs=(0, 1, 4))
    Ac = np.block([[-np.linalg.solve(M, Cdamp), -np.linalg.solve(M, K)],
                   [np.eye(6), np.zeros((6, 6))]])
    Bc = np.vstack([np.linalg.inv(M), np.zeros((6, 6))])
    A_ref = scipy.linalg.expm(Ac / fs)
    np.testing.assert_allclose(A, A_ref, rtol=1e-12, atol=1e-13 * np.abs(A_ref).max())
    # Paper Eq. (3): B = (A - I) A_c^-1 B_c.
    np.testing.assert_allclose(B, (A - np.eye(12)) @ np.linalg.solve(Ac, Bc), atol=1e-12)
    np.testing.assert_allclose(C, Ac[[0, 1, 4]], rtol=1e-14)
    np.testing.assert_allclose(D, Bc[[0, 1, 4]], rtol=1e-14)


@pytest.mark.parametrize("damping", ["modal", "non-proportional"])
def test_fast_response_equals_state_space_loop(damping):
    M, K, Cdamp = chain_system()
    if damping == "non-proportional":  # exercises the complex-mode path
        Cdamp = Cdamp.copy()
        Cdamp[0, 0] += 0.5
        Cdamp[4, 4] += 0.2
    out = (0, 1, 4)
    A, B, C, D = state_space(M, K, Cdamp, fs=50.0, output_dofs=out)
    force = np.random.default_rng(7).standard_normal((2000, 6)) * [1.0, 0.1, 0.1, 0.1, 0.1, 0.1]
    y_loop = _state_space_loop(A, B, C, D, force)
    y_fast = acceleration_response(force, M, K, Cdamp, fs=50.0, output_dofs=out)
    assert y_fast.shape == (2000, 3) and y_fast.flags.c_contiguous
    assert np.max(np.abs(y_fast - y_loop)) <= 1e-10 * np.max(np.abs(y_loop))


def test_fast_response_is_continuous_across_chunks():
    # Longer than one internal block: the filter state must carry over exactly.
    M, K, Cdamp = chain_system(3, damping_ratio=0.05)
    A, B, C, D = state_space(M, K, Cdamp, fs=20.0, output_dofs=(0, 2))
    force = np.random.default_rng(3).standard_normal((70_000, 3))
    y_fast = acceleration_response(force, M, K, Cdamp, fs=20.0, output_dofs=(0, 2))
    y_loop = _state_space_loop(A, B, C, D, force)
    assert np.max(np.abs(y_fast - y_loop)) <= 1e-10 * np.max(np.abs(y_loop))


def test_simulate_equals_response_to_its_known_input():
    # Without unknown forces and noise, y is exactly the response to u at DOF 0.
    sim = simulate(1500, seed=11, unknown_input_std=0.0, noise_std=0.0, discard=0)
    M, K, Cdamp = chain_system()
    A, B, C, D = state_space(M, K, Cdamp, fs=50.0, output_dofs=(0, 1, 4))
    y_loop = _state_space_loop(A, B[:, [0]], C, D[:, [0]], sim.u)
    assert np.max(np.abs(sim.y - y_loop)) <= 1e-10 * np.max(np.abs(y_loop))


def test_simulate_uses_documented_random_streams():
    # Known inputs (n_total, n_inputs), unknown forces (n_total, n_dof), then the noise.
    n, discard = 800, 200
    sim = simulate(n, seed=5, discard=discard)
    rng = np.random.default_rng(5)
    u = rng.standard_normal((n + discard, 1))
    force = 0.1 * rng.standard_normal((n + discard, 6))
    noise = rng.standard_normal((n, 3))
    force[:, 0] += u[:, 0]
    M, K, Cdamp = chain_system()
    A, B, C, D = state_space(M, K, Cdamp, fs=50.0, output_dofs=(0, 1, 4))
    clean = _state_space_loop(A, B, C, D, force)[discard:]
    np.testing.assert_array_equal(sim.u, u[discard:])
    expected = clean + 0.05 * clean.std(axis=0) * noise
    assert np.max(np.abs(sim.y - expected)) <= 1e-10 * np.max(np.abs(expected))


def test_discard_drops_leading_samples():
    a = simulate(1000, seed=3, discard=400, noise_std=0.0)
    b = simulate(1400, seed=3, discard=0, noise_std=0.0)
    np.testing.assert_array_equal(a.u, b.u[400:])
    np.testing.assert_allclose(a.y, b.y[400:], rtol=0, atol=1e-12 * np.abs(b.y).max())


# ------------------------------------------------------------ data and statistics


def test_seed_reproducibility_and_different_seeds():
    a = simulate(3000, seed=123)
    b = simulate(3000, seed=123)
    c = simulate(3000, seed=124)
    np.testing.assert_array_equal(a.y, b.y)
    np.testing.assert_array_equal(a.u, b.u)
    assert not np.allclose(a.y, c.y)
    assert not np.allclose(a.u, c.u)
    # A Generator is accepted too.
    d = simulate(3000, seed=np.random.default_rng(123))
    np.testing.assert_array_equal(a.y, d.y)


def test_shapes_dtypes_and_contiguity():
    sim = simulate(2500, seed=1)
    assert isinstance(sim, Simulation)
    assert sim.y.shape == (2500, 3) and sim.u.shape == (2500, 1)
    for arr in (sim.y, sim.u):
        assert arr.dtype == np.float64 and arr.flags.c_contiguous
    assert sim.frequency_hz.shape == (6,) and sim.damping_ratio.shape == (6,)
    assert sim.mode_shape.shape == (3, 6) and sim.mode_shape.dtype == np.complex128
    assert sim.output_dofs == (0, 1, 4) and sim.input_dofs == (0,)
    assert sim.fs == 50.0
    assert (sim.n_samples, sim.n_outputs, sim.n_inputs) == (2500, 3, 1)
    assert np.all(np.isfinite(sim.y))
    text = repr(sim)
    assert "n_samples=2500" in text and "1.93" in text and len(text) < 300
    with pytest.raises(AttributeError):
        sim.fs = 10.0  # frozen


def test_noise_and_input_levels():
    n = 200_000
    clean = simulate(n, seed=42, noise_std=0.0)
    noisy = simulate(n, seed=42, noise_std=0.05)
    noise = noisy.y - clean.y
    ratio = noise.std(axis=0) / clean.y.std(axis=0)
    # Sample std of n normals has relative sd 1/sqrt(2n) ~ 0.16 %; allow 1 %.
    np.testing.assert_allclose(ratio, 0.05, rtol=0.01)
    # Noise is white and independent of the clean signal.
    assert abs(np.corrcoef(noise[:-1, 0], noise[1:, 0])[0, 1]) < 0.02
    assert abs(np.corrcoef(noise[:, 0], clean.y[:, 0])[0, 1]) < 0.02
    np.testing.assert_array_equal(noisy.u, clean.u)
    assert noisy.u.std() == pytest.approx(1.0, rel=0.01)
    assert abs(noisy.u.mean()) < 0.01
    scaled = simulate(n, seed=42, input_std=3.0, noise_std=0.0)
    assert scaled.u.std() == pytest.approx(3.0, rel=0.01)
    # Everything is linear in input_std.
    np.testing.assert_allclose(scaled.y, 3.0 * clean.y, rtol=1e-12, atol=1e-12)


def test_outputs_driven_mostly_by_known_input():
    # Unknown forces have 10 % of the known std at each DOF: removing them changes y little.
    a = simulate(20_000, seed=9, noise_std=0.0)
    b = simulate(20_000, seed=9, noise_std=0.0, unknown_input_std=0.0)
    rel = (a.y - b.y).std(axis=0) / a.y.std(axis=0)
    assert np.all(rel > 0.02) and np.all(rel < 0.5)


def test_other_chain_sizes_and_options():
    assert default_output_dofs(6) == (0, 1, 4)
    dofs30 = default_output_dofs(30)
    assert len(dofs30) == 20 and dofs30[0] == 0 and dofs30[-1] == 29
    assert len(set(dofs30)) == 20 and list(dofs30) == sorted(dofs30)
    for n in (1, 2, 3, 4, 5, 7, 10, 31):
        d = default_output_dofs(n)
        assert d[0] == 0 and d[-1] == n - 1 and len(set(d)) == len(d)
    sim = simulate(2000, seed=0, n_dof=30)
    assert sim.y.shape == (2000, 20) and sim.mode_shape.shape == (20, 30)
    assert sim.output_dofs == dofs30
    M, K, _ = chain_system(30)
    f = np.sqrt(scipy.linalg.eigvalsh(K, M)) / (2 * np.pi)
    np.testing.assert_allclose(sim.frequency_hz, f, rtol=1e-10)
    oo = simulate(500, seed=0, input_dofs=())
    assert oo.u.shape == (500, 0) and np.all(np.isfinite(oo.y)) and oo.y.std() > 0
    two = simulate(500, seed=0, input_dofs=(0, 5), output_dofs=(5, 2))
    assert two.u.shape == (500, 2) and two.y.shape == (500, 2)


def test_large_record_runs():
    simulate(10_000, seed=0)  # warm-up
    t0 = time.perf_counter()
    sim = simulate(1_000_000, seed=0)
    elapsed = time.perf_counter() - t0
    print(f"\nsimulate(1_000_000): {elapsed:.3f} s")
    assert sim.y.shape == (1_000_000, 3) and sim.u.shape == (1_000_000, 1)
    assert np.all(np.isfinite(sim.y[-10:]))


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"n_samples": 0}, "n_samples"),
        ({"n_samples": -5}, "n_samples"),
        ({"fs": 0.0}, "fs"),
        ({"fs": -50.0}, "fs"),
        ({"fs": float("nan")}, "fs"),
        ({"output_dofs": (0, 6)}, "output_dofs"),
        ({"output_dofs": (-1,)}, "output_dofs"),
        ({"output_dofs": ()}, "output_dofs"),
        ({"output_dofs": (1, 1)}, "output_dofs"),
        ({"input_dofs": (6,)}, "input_dofs"),
        ({"n_dof": 0}, "n_dof"),
        ({"damping_ratio": 1.0}, "damping_ratio"),
        ({"damping_ratio": -0.01}, "damping_ratio"),
        ({"input_std": 0.0}, "input_std"),
        ({"unknown_input_std": -0.1}, "unknown_input_std"),
        ({"noise_std": -1.0}, "noise_std"),
        ({"discard": -1}, "discard"),
    ],
)
def test_bad_arguments_raise_value_error(kwargs, name):
    args = {"n_samples": 100, "seed": 0, **kwargs}
    n_samples = args.pop("n_samples")
    with pytest.raises(ValueError, match=name):
        simulate(n_samples, **args)


def test_a_non_integer_count_is_a_type_error_as_in_identify():
    # The same mistake raises the same exception in every entry point (identify: TypeError).
    with pytest.raises(TypeError, match="n_samples"):
        simulate(10.5, seed=0)
    with pytest.raises(TypeError, match="seed must be None, a non-negative integer"):
        simulate(100, seed=1.5)
    with pytest.raises(TypeError, match="seed must be"):
        simulate(100, seed=-1)


def test_nyquist_warning():
    with pytest.warns(RuntimeWarning, match="Nyquist"):
        simulate(200, seed=0, fs=30.0, discard=0)
