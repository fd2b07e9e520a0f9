"""Issue 26, item 9 (resources): settings whose H and uncertainty propagation need more memory
than the machine has are refused in a moment, naming the setting to lower, instead of running
for minutes or ending in a bare ``std::bad_alloc``; the estimate is conservative against the
measured peak; the automatic settings always fit (docs/settings.md, "Memory")."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import modaluq
from memory_probe import PROBE
from modaluq import auto_settings, checks
from modaluq.checks import MEMORY_LIMIT_ENV, available_memory, check_cost, estimate_cost

PYTHON_DIR = str(Path(modaluq.__file__).resolve().parents[1])


@pytest.fixture(scope="module")
def sim():
    return modaluq.simulate(20_000, seed=1)


def run_python(code: str, *, env: dict | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    full_env = {**os.environ, "PYTHONPATH": PYTHON_DIR + os.pathsep + os.environ.get("PYTHONPATH", ""), **(env or {})}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env=full_env)


# ---------------------------------------------------------------- refused before starting
def test_block_rows_2000_on_20000_samples_refused_fast(sim, monkeypatch):
    """The issue's case: > 300 s and 3.7 GB (or a bare bad_alloc); on a machine with less
    memory than it needs it is now refused at once, naming block_rows and the numbers."""
    monkeypatch.setattr(checks, "available_memory", lambda: (4 * 1024**3, "test machine"))
    start = time.perf_counter()
    with pytest.raises(ValueError, match=r"would need about [\d.]+ GB.*but 4.29 GB is available \(test machine\); "
                                         r"lower block_rows") as info:
        modaluq.identify(sim.y, fs=sim.fs, block_rows=2000)
    assert time.perf_counter() - start < 5
    assert "H is 6000 x 6000" in str(info.value) and "min on one core" in str(info.value)


def test_memory_limit_override_refuses(sim, monkeypatch):
    """The documented override (MODALUQ_MEMORY_LIMIT) is the limit when set."""
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "200M")
    assert available_memory() == (200 * 1024**2, MEMORY_LIMIT_ENV)
    with pytest.raises(ValueError, match=f"available \\({MEMORY_LIMIT_ENV}\\); lower block_rows"):
        modaluq.identify(sim.y, fs=sim.fs, block_rows=400, orders=20, n_blocks=4)
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "lots")
    with pytest.raises(ValueError, match=MEMORY_LIMIT_ENV):
        available_memory()


def test_many_blocks_name_n_blocks_and_uncertainty(monkeypatch):
    """When the blocks carry the estimate, the message says n_blocks / uncertainty=False."""
    cost = estimate_cost(200_000, 2, 0, block_rows=150, orders=range(2, 101, 2), n_blocks=2000)
    monkeypatch.setattr(checks, "available_memory", lambda: (cost.bytes // 2, "test machine"))
    s = modaluq.Settings(block_rows=150, orders=range(2, 101, 2), n_blocks=2000)
    with pytest.raises(ValueError, match="lower n_blocks, or set uncertainty=False"):
        check_cost(200_000, 2, 0, s)
    assert check_cost(200_000, 2, 0, s.replace(uncertainty=False)).bytes < cost.bytes // 2


def test_refused_under_a_real_address_space_limit():
    """Without patching anything: under ``ulimit -v`` 3 GB the check reads the limit and refuses
    (the unchanged code ended in a bare MemoryError from std::bad_alloc)."""
    out = run_python("""
        import resource, time
        resource.setrlimit(resource.RLIMIT_AS, (3 * 1024**3, resource.RLIM_INFINITY))
        import modaluq
        sim = modaluq.simulate(20_000, seed=1)
        start = time.perf_counter()
        try:
            modaluq.identify(sim.y, fs=sim.fs, block_rows=2000)
        except Exception as exc:
            print(type(exc).__name__, round(time.perf_counter() - start, 1), exc)
    """, env={"OPENBLAS_NUM_THREADS": "1", MEMORY_LIMIT_ENV: ""})
    kind, seconds, message = out.stdout.split(" ", 2)
    assert kind == "ValueError", out.stdout + out.stderr
    assert float(seconds) < 5
    assert "address-space limit" in message and "lower block_rows" in message


# ---------------------------------------------------------------- std::bad_alloc named
def test_bad_alloc_names_the_settings(sim, monkeypatch):
    def out_of_memory(*args):
        raise MemoryError("std::bad_alloc")

    monkeypatch.setattr(modaluq.identification._core, "identify", out_of_memory)
    with pytest.raises(MemoryError, match=r"block_rows=30, past_block_rows=30, n_blocks=8.*orders up to 20: "
                                          r"lower block_rows"):
        modaluq.identify(sim.y, fs=sim.fs, block_rows=30, orders=20, n_blocks=8)


def test_real_bad_alloc_names_the_settings():
    """An allocation the estimate let through (the override raised the limit) that the process
    cannot make: a MemoryError naming the settings, not a bare std::bad_alloc."""
    out = run_python("""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (2 * 1024**3, resource.RLIM_INFINITY))
        import numpy as np, modaluq
        y = np.random.default_rng(0).standard_normal((40_000, 3))
        try:
            modaluq.identify(y, fs=100.0, block_rows=6000, orders=10, n_blocks=2)
        except MemoryError as exc:
            print("MemoryError", exc)
    """, env={"OPENBLAS_NUM_THREADS": "1", MEMORY_LIMIT_ENV: "1T"})
    assert out.stdout.startswith("MemoryError out of memory in the identification with block_rows=6000"), \
        out.stdout + out.stderr


def test_streaming_identify_is_checked(sim, monkeypatch):
    acc = modaluq.CovarianceAccumulator(3, block_rows=2000, block_length=8000)
    acc.push(sim.y)
    monkeypatch.setattr(checks, "available_memory", lambda: (2 * 1024**3, "test machine"))
    start = time.perf_counter()
    with pytest.raises(ValueError, match="lower block_rows"):
        acc.identify(fs=sim.fs, orders=20)
    assert time.perf_counter() - start < 5


# ---------------------------------------------------------------- the estimate against measurements
MEASURE = """
    import json, sys
    import numpy as np
    import modaluq
    from modaluq.checks import estimate_cost
    y = np.ascontiguousarray(modaluq.simulate(20_000, seed=1).y)
    reset_peak()
    before = memory("VmRSS")
    kw = json.loads(sys.argv[1] if len(sys.argv) > 1 else '{cfg}')
    r = modaluq.identify(y, fs=50.0, **kw)
    peak = memory("VmHWM")
    s = r.settings
    est = estimate_cost(y.shape[0], 3, 0, block_rows=s["block_rows"], orders=s["orders"], n_blocks=s["n_blocks"] or 2,
                        uncertainty=s["uncertainty"], threads=s["threads"], bootstrap_draws=s["bootstrap_draws"],
                        keep_shape_factor=s["keep_shape_factor"])
    print(json.dumps([peak - before, est.bytes]))
"""


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads VmRSS from /proc")
@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("cfg", [
    {"block_rows": 100, "orders": 100, "n_blocks": 50},               # the blocks
    {"block_rows": 200, "orders": [20, 100, 200], "n_blocks": 10},    # high orders
    {"block_rows": 450, "orders": 60, "uncertainty": False},          # the SVD of H alone
    {"block_rows": 100, "orders": [20, 40, 60], "n_blocks": 50, "bootstrap_draws": 10},  # T_H kept, H per draw
    {"block_rows": 100, "orders": list(range(2, 201, 2)), "n_blocks": 50, "keep_shape_factor": True},  # V per pole
])
def test_estimate_is_conservative_against_measured_peak(cfg):
    """Peak RSS of the identification in a fresh process (its VmHWM less the RSS before it):
    the estimate is at least that and at most 4 times it."""
    out = run_python(PROBE + textwrap.dedent(MEASURE.replace("{cfg}", json.dumps(cfg))), env={"OPENBLAS_NUM_THREADS": "1"})
    measured, estimate = json.loads(out.stdout.strip().splitlines()[-1])
    assert measured > 20e6, out.stderr  # large enough to be measured
    assert measured <= estimate <= 4 * measured, (cfg, measured, estimate)


# ---------------------------------------------------------------- the automatic settings fit
@pytest.mark.parametrize("n_samples,fs,n_outputs,band,n_inputs", [
    (16_384, 106.25, 3, (10.0, 30.0), 0), (200_000, 100.0, 1, None, 0), (1_000_000, 200.0, 12, (0.5, 20.0), 0),
    (50_000, 50.0, 40, None, 2), (3_000, 50.0, 3, None, 1), (500_000, 1000.0, 150, (1.0, 100.0), 0)])
def test_automatic_settings_pass_the_check(n_samples, fs, n_outputs, band, n_inputs):
    chosen = auto_settings.choose_settings(n_samples, fs, n_outputs, frequency_range=band, n_inputs=n_inputs)
    s = modaluq.Settings(block_rows=chosen.block_rows, orders=chosen.orders, n_blocks=chosen.n_blocks)
    check_cost(n_samples, n_outputs, n_inputs, s)  # does not raise
    assert not any("lowered" in r for r in chosen.reasons)  # and nothing changed on this machine


def test_automatic_settings_fit_a_small_machine(monkeypatch):
    """With little memory the chooser lowers its own choices until they pass the check."""
    args = (400_000, 400.0, 8)
    kw = {"frequency_range": (1.0, 100.0), "n_inputs": 20}
    usual = auto_settings.choose_settings(*args, **kw)
    need = estimate_cost(args[0], args[2], 20, block_rows=usual.block_rows, orders=usual.orders,
                         n_blocks=usual.n_blocks).bytes
    monkeypatch.setenv(MEMORY_LIMIT_ENV, str(need // 3))
    chosen = auto_settings.choose_settings(*args, **kw)
    assert (chosen.block_rows, chosen.n_blocks) < (usual.block_rows, usual.n_blocks)
    assert any(r.startswith("lowered to block_rows") for r in chosen.reasons)
    s = modaluq.Settings(block_rows=chosen.block_rows, orders=chosen.orders, n_blocks=chosen.n_blocks)
    assert check_cost(args[0], args[2], 20, s).bytes <= need // 3


def test_identify_with_automatic_settings_on_a_small_machine(sim, monkeypatch):
    """identify() with automatic settings on a machine that cannot hold the usual ones: it runs,
    with the lowered settings it says it chose."""
    usual = modaluq.identification.identify_quietly(sim.y, sim.u, fs=sim.fs)
    need = estimate_cost(sim.y.shape[0], 3, 1, block_rows=usual.settings["block_rows"],
                         orders=usual.settings["orders"], n_blocks=usual.settings["n_blocks"]).bytes
    monkeypatch.setenv(MEMORY_LIMIT_ENV, str(need // 4))
    result = modaluq.identification.identify_quietly(sim.y, sim.u, fs=sim.fs)
    assert any(r.startswith("lowered to block_rows") for r in result.settings["chosen"])
    lowered = (result.settings["block_rows"], result.settings["n_blocks"])
    assert lowered != (usual.settings["block_rows"], usual.settings["n_blocks"])
    assert lowered <= (usual.settings["block_rows"], usual.settings["n_blocks"])
    assert result.n_blocks >= 2 and np.isfinite(result.modes[-1].frequency_hz).all()
