"""The C++ core's CPU paths (issue 25): the choice at import, MODALUQ_CPU, equal results on every path.

A process loads one core (pybind11 registers its C++ types once per process), so each path runs
in a child interpreter with ``MODALUQ_CPU`` set; the parent compares what the children saved.
"""

import io
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import modaluq
from modaluq import _core, _dispatch
from modaluq.cli import main

PACKAGE_PARENT = str(pathlib.Path(modaluq.__file__).resolve().parents[1])
AVAILABLE = _dispatch.available_paths()
FEATURES, DETECTED_BY = _dispatch.cpu_features()
#: The paths this machine runs besides the baseline (x86-64-v3 where the CPU has it).
OTHER_PATHS = [p for p in AVAILABLE if p != "baseline" and (p != "x86-64-v3" or not _dispatch.missing_for_v3(FEATURES))]

needs_two_paths = pytest.mark.skipif("baseline" not in AVAILABLE or not OTHER_PATHS,
                                     reason=f"one core path runs here (installed: {AVAILABLE})")


def run_child(code: str, cpu: str | None, **kw) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter with MODALUQ_CPU=cpu (unset for None), this package first."""
    env = dict(os.environ)
    env.pop(_dispatch.ENV, None)
    if cpu is not None:
        env[_dispatch.ENV] = cpu
    env["PYTHONPATH"] = PACKAGE_PARENT + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600, **kw)


def child_json(code: str, cpu: str | None) -> dict:
    run = run_child(code, cpu)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout.splitlines()[-1])


# -- the suite's cases on each path (test_identify.py: the 6-DOF chain, its settings, output-only
# and input/output, frozen noise and plain), saved by a child per path ------------------------
IDENTIFY_ALL = """
import sys, numpy as np, modaluq
sim = modaluq.simulate(6_000, seed=3)  # conftest.chain
if PERTURB:  # each sample changed by about one unit in the last place: what rounding alone moves
    sim.y[:] *= 1 + 2.0**-52 * np.random.default_rng(0).standard_normal(sim.y.shape)
SETTINGS = [(6, 7, None, [4, 8, 12]), (7, 5, [0, 2], [6, 10]), (7, 7, None, [8, 12, 16, 18])]
out = {"path": np.array(modaluq._core.cpu_path)}
for k, (p, q, refs, orders) in enumerate(SETTINGS):
    for io in (False, True):
        for freeze in (True, False):
            r = modaluq.identify(sim.y, sim.u if io else None, fs=sim.fs, block_rows=p, past_block_rows=q,
                                 orders=orders, n_blocks=20, references=refs, freeze_noise=freeze,
                                 noise_coupling_limit=5.0)
            for n in orders:
                m = r.at_order(n)
                for name in ("frequency_hz", "damping_ratio", "frequency_std", "damping_std", "mode_shape",
                             "mode_shape_std_real", "mode_shape_std_imag"):
                    out[f"{k}/{io}/{freeze}/{n}/{name}"] = getattr(m, name)
np.savez(FILE, **out)
"""


@pytest.fixture(scope="module")
def results_per_path(tmp_path_factory):
    folder = tmp_path_factory.mktemp("paths")
    out = {}
    for name, path, perturb in [("baseline", "baseline", False), ("rounding", "baseline", True),
                                *[(p, p, False) for p in OTHER_PATHS]]:
        file = folder / f"{name}.npz"
        run = run_child(IDENTIFY_ALL.replace("PERTURB", str(perturb)).replace("FILE", repr(str(file))), path)
        assert run.returncode == 0, run.stderr
        with np.load(file) as saved:
            out[name] = dict(saved)
            assert str(out[name].pop("path")) == path  # each child ran its path
    return out


def relative(a, b):
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300), initial=0.0))


@needs_two_paths
@pytest.mark.parametrize("path", OTHER_PATHS)
def test_each_path_equals_the_baseline(results_per_path, path):
    # Every f, xi, their std, shape and shape std of every case and order equal to 1e-10 relative,
    # or, where rounding alone moves a quantity more, to ten times that: the baseline's own change
    # when each sample changes in its last bit (the noise-coupled poles of order 18 of the plain
    # input/output case move by 2e-10 so; the paths differ there by 1.6e-10).
    base, other, rounding = (results_per_path[k] for k in ("baseline", path, "rounding"))
    assert base.keys() == other.keys() == rounding.keys() and len(base) == 12 * 3 * 7  # runs x orders x quantities
    loosened, differ = [], 0
    for key, b in base.items():
        assert other[key].shape == b.shape, key  # as many modes at each order
        bound = max(1e-10, 10 * relative(rounding[key], b))
        assert relative(other[key], b) <= bound, (key, relative(other[key], b), bound)
        loosened += [key] if bound > 1e-10 else []
        differ += relative(other[key], b) > 0
    assert len(loosened) < len(base) / 10, loosened  # the strict bound is the rule
    assert differ, "the paths gave identical bits: is the other path really running?"


# -- which path runs, and MODALUQ_CPU ------------------------------------------------------
def test_the_core_is_one_extension_that_calls_itself_modaluq_core():
    assert sys.modules["modaluq._core"] is _core is modaluq._core
    assert _core.__name__ == "modaluq._core" and _core.cpu_path in AVAILABLE
    assert os.path.basename(_core.__file__).startswith(_dispatch.MODULES[_core.cpu_path] + ".")
    # pickles and the stubs name the module the user imports, whichever path made the objects
    for obj in (_core.CovarianceAccumulator, _core.IdentifyOptions, _core.identify, _core.NumericalError,
                _core.PoleStatus):
        assert obj.__module__ == "modaluq._core", obj
    assert _dispatch.choice is not None and _dispatch.choice.path == _core.cpu_path
    assert set(_core.builds) == set(AVAILABLE)  # every core knows the flags of every path built with it


def test_without_the_variable_the_most_capable_path_this_cpu_runs_is_chosen():
    seen = child_json("import json, sys, modaluq; from modaluq import _dispatch as d; "
                      "print(json.dumps([modaluq._core.cpu_path, d.choice.forced, "
                      "sorted(m for m in sys.modules if m.startswith('modaluq._core_'))]))", None)
    expected = OTHER_PATHS[0] if OTHER_PATHS else "baseline"
    assert seen[0] == expected and seen[1] is False
    # one core in the process (a core cannot be loaded beside another), and the feature probe
    # when there is a choice to make
    probed = "x86-64-v3" in AVAILABLE and DETECTED_BY == "__builtin_cpu_supports"
    assert seen[2] == sorted({f"modaluq.{_dispatch.MODULES[expected]}"} | ({"modaluq._core_cpuinfo"} if probed else set()))


@pytest.mark.skipif("baseline" not in AVAILABLE, reason="no baseline core in this install (MODALUQ_NATIVE=ON)")
def test_the_environment_variable_forces_the_baseline():
    seen = child_json("import io, json, modaluq; c = modaluq.show_config(file=io.StringIO()); "
                      "print(json.dumps([modaluq._core.cpu_path, modaluq._core.__file__, c['core']]))", "baseline")
    path, file, core = seen
    assert path == "baseline" and os.path.basename(file).startswith("_core_baseline.")
    assert core["forced"] is True and core["reason"] == "forced by MODALUQ_CPU=baseline"
    assert core["MODALUQ_CPU"] == "baseline"


@pytest.mark.parametrize("value", ["avx512", "x86_64_v3", "Baseline"])
def test_an_unknown_value_is_an_error_naming_the_variable(value):
    run = run_child("import modaluq", value)
    assert run.returncode != 0
    assert f"ValueError: MODALUQ_CPU must be one of 'x86-64-v3', 'baseline' (or unset: chosen from the CPU), " \
           f"got {value!r}" in run.stderr


# choose() decides from what it is told (the CPU's features, the paths installed) without loading a
# core: every rule, with no need for a machine of each kind
def fake(monkeypatch, available, features, how="__builtin_cpu_supports"):
    monkeypatch.setattr(_dispatch, "available_paths", lambda: tuple(available))
    monkeypatch.setattr(_dispatch, "cpu_features", lambda: (dict(features), how))


V3_CPU = {f: True for f in _dispatch.X86_64_V3}
SSE_CPU = {**V3_CPU, **{f: False for f in ("avx", "avx2", "fma", "bmi", "bmi2", "f16c", "movbe", "lzcnt",
                                           "x86-64-v3")}}


def test_choose_picks_v3_on_a_v3_cpu_and_the_baseline_on_an_older_one(monkeypatch):
    fake(monkeypatch, ["x86-64-v3", "baseline"], V3_CPU)
    c = _dispatch.choose({})
    assert (c.path, c.module, c.forced) == ("x86-64-v3", "modaluq._core_x86_64_v3", False)
    assert c.reason == "this CPU supports x86-64-v3 (__builtin_cpu_supports)"
    # AVX without the OS saving its registers reads as no AVX (libgcc checks XGETBV): the same rule
    fake(monkeypatch, ["x86-64-v3", "baseline"], {**V3_CPU, "avx2": False, "fma": False})
    c = _dispatch.choose({})
    assert c.path == "baseline" and c.reason == "this CPU lacks x86-64-v3: no avx2, fma (__builtin_cpu_supports)"
    # features unknown: the baseline, which every CPU of the architecture runs
    fake(monkeypatch, ["x86-64-v3", "baseline"], {}, "")
    c = _dispatch.choose({})
    assert c.path == "baseline" and c.reason.startswith("this CPU's features could not be read")


def test_choose_follows_the_variable_and_refuses_what_cannot_run(monkeypatch):
    fake(monkeypatch, ["x86-64-v3", "baseline"], V3_CPU)
    assert _dispatch.choose({"MODALUQ_CPU": "baseline"}).path == "baseline"
    assert _dispatch.choose({"MODALUQ_CPU": " x86-64-v3 "}).forced
    assert _dispatch.choose({"MODALUQ_CPU": ""}).path == "x86-64-v3"  # empty: as unset
    with pytest.raises(ValueError, match="MODALUQ_CPU must be one of .* got 'sse2'"):
        _dispatch.choose({"MODALUQ_CPU": "sse2"})
    fake(monkeypatch, ["x86-64-v3", "baseline"], SSE_CPU)
    with pytest.raises(ValueError, match=r"MODALUQ_CPU=x86-64-v3, but this CPU \(or its OS\) lacks avx, avx2, fma, "
                                         r"bmi, bmi2, f16c, movbe, lzcnt, x86-64-v3 .*illegal instruction"):
        _dispatch.choose({"MODALUQ_CPU": "x86-64-v3"})
    # aarch64, or a compiler without -march=x86-64-v3: the baseline only
    fake(monkeypatch, ["baseline"], {}, "")
    c = _dispatch.choose({})
    assert c.path == "baseline" and c.reason.startswith("the only core of this install (no x86-64-v3 build on ")
    with pytest.raises(ValueError, match="MODALUQ_CPU=x86-64-v3: this install has no x86-64-v3 core; it has baseline"):
        _dispatch.choose({"MODALUQ_CPU": "x86-64-v3"})
    # MODALUQ_NATIVE=ON: one core, built for this CPU
    fake(monkeypatch, ["native"], {}, "")
    assert _dispatch.choose({}).path == "native"
    with pytest.raises(ValueError, match=r"no baseline core \(built with MODALUQ_NATIVE=ON: only the native core\)"):
        _dispatch.choose({"MODALUQ_CPU": "baseline"})
    fake(monkeypatch, [], {}, "")
    with pytest.raises(ImportError, match=r"modaluq's C\+\+ core is not built"):
        _dispatch.choose({})


def test_proc_cpuinfo_is_read_in_libgcc_names():
    if not os.path.exists("/proc/cpuinfo") or DETECTED_BY != "__builtin_cpu_supports":
        pytest.skip("needs Linux and the __builtin_cpu_supports probe to compare with")
    text = pathlib.Path("/proc/cpuinfo").read_text()
    if "flags" not in text:
        pytest.skip("this /proc/cpuinfo has no flags line (not x86)")
    flags = set(next(line for line in text.splitlines() if line.startswith("flags")).partition(":")[2].split())
    from_linux = {name: flag in flags for flag, name in _dispatch._CPUINFO_FLAGS.items()}
    assert from_linux == {k: v for k, v in FEATURES.items() if k in from_linux}  # both ways agree here
    assert set(from_linux) | {"x86-64-v3"} == set(_dispatch.X86_64_V3)


# -- a checkpoint made on one path resumes on the other --------------------------------------
PUSH = """
import pickle, sys, numpy as np, modaluq
sim = modaluq.simulate(12_000, seed=8)
half = 5_000
if sys.argv[1] == "start":
    acc = modaluq.CovarianceAccumulator(3, 1, block_rows=8, block_length=400)
    acc.push(sim.y[:half], sim.u[:half])
    pathlib = __import__("pathlib"); pathlib.Path(sys.argv[2]).write_bytes(pickle.dumps(acc))
else:
    acc = pickle.loads(__import__("pathlib").Path(sys.argv[2]).read_bytes())
    acc.push(sim.y[half:], sim.u[half:])
    m = acc.identify(fs=sim.fs, orders=12).at_order(12)
    np.savez(sys.argv[3], path=modaluq._core.cpu_path, f=m.frequency_hz, xi=m.damping_ratio,
             sf=m.frequency_std, sxi=m.damping_std)
"""


@needs_two_paths
def test_a_pickled_accumulator_resumes_on_the_other_path(tmp_path):
    other = OTHER_PATHS[0]
    out = {}
    for first, second in (("baseline", "baseline"), ("baseline", other), (other, "baseline")):
        ckpt, res = tmp_path / f"{first}.pkl", tmp_path / f"{first}-{second}.npz"
        for step, cpu in (("start", first), ("finish", second)):
            code = PUSH.replace("sys.argv[1]", repr(step)).replace("sys.argv[2]", repr(str(ckpt)))
            run = run_child(code.replace("sys.argv[3]", repr(str(res))), cpu)
            assert run.returncode == 0, run.stderr
        with np.load(res) as r:
            assert str(r["path"]) == second
            out[first, second] = {k: r[k] for k in ("f", "xi", "sf", "sxi")}
    ref = out["baseline", "baseline"]
    for key in (("baseline", other), (other, "baseline")):
        for name, value in out[key].items():
            assert value.shape == ref[name].shape and relative(value, ref[name]) < 1e-10, (key, name)


# -- show_config and --version ---------------------------------------------------------------
def test_show_config_prints_and_returns_what_runs():
    buffer = io.StringIO()
    c = modaluq.show_config(file=buffer)
    text = buffer.getvalue()
    assert c["core"]["path"] == _core.cpu_path and c["core"]["module"] == f"modaluq.{_dispatch.MODULES[_core.cpu_path]}"
    assert f"CPU path:  {_core.cpu_path} ({c['core']['module']})" in text
    assert f"  why:     {_dispatch.choice.reason}" in text
    assert c["modaluq"]["version"] == modaluq.__version__ and c["numpy"]["version"] == np.__version__
    assert set(c["builds"]) == set(AVAILABLE) and all(": " in flags for flags in c["builds"].values())
    assert f"{_core.cpu_path}:" in text and "<- running" in text
    if "x86-64-v3" in c["builds"]:
        assert "-march=x86-64-v3" in c["builds"]["x86-64-v3"] and "-march" not in c["builds"]["baseline"]
    assert c["eigen"]["version"].startswith("3.") and c["eigen"]["simd"]
    blas = c["blas"]
    assert blas["core_uses_blas"] == _core.uses_blas
    if _core.uses_blas:  # the library doing the core's products is among those loaded, with its threads
        mine = [lib for lib in blas["libraries"] if lib["used_by_core"]]
        assert len(mine) == 1 and mine[0]["threads"] >= 1 and mine[0]["version"], blas
        assert "  <- the core's" in text
    json.dumps(c)  # plain data


def test_version_names_the_core_path(capsys):
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[:2] == [f"modaluq {modaluq.__version__}",
                                    f"C++ core: {_core.cpu_path} ({_dispatch.choice.reason})"]
