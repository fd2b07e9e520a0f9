"""Issue #13, Python API: every public entry point checks its arguments with the same functions,
so the same mistake raises the same exception naming the same argument — boolean switches
that are not booleans, boolean or masked samples, transposed records, integers too large for the
core, and optional dependencies that are missing."""

import re
import sys

import numpy as np
import pytest

import modaluq
from modaluq.simulate import acceleration_response, chain_system
from modaluq.spectrum import output_spectrum_singular_values
from modaluq.validation import monte_carlo

FAST = dict(block_rows=6, orders=8, n_blocks=10)


@pytest.fixture(scope="module")
def sim():
    return modaluq.simulate(6_000, seed=3)


def _accumulator(**kw):
    args = dict(n_outputs=3, n_inputs=1, block_rows=6, block_length=200)
    args.update(kw)
    return modaluq.CovarianceAccumulator(**args)


# --------------------------------------------------------------------------- boolean switches

NOT_BOOLEANS = ["False", "no", "", 0, 1, None, 1.0, [True]]


def _switches(sim):
    """(label, call(value)) for every boolean parameter of the public API."""
    acc = _accumulator()
    acc.push(sim.y, sim.u)
    mc = dict(n_records=1, processes=1, n_samples=2_000, n_blocks=10, block_rows=6, order=8)
    return {
        "demean": lambda v: modaluq.identify(sim.y, fs=sim.fs, demean=v, **FAST),
        "uncertainty": lambda v: modaluq.identify(sim.y, fs=sim.fs, uncertainty=v, **FAST),
        "accumulator demean": lambda v: _accumulator(demean=v),
        "with_blocks": lambda v: acc.covariances(with_blocks=v),
        "accumulator uncertainty": lambda v: acc.identify(fs=sim.fs, orders=8, uncertainty=v),
        "progress": lambda v: monte_carlo(progress=v, **mc),
    }


@pytest.mark.parametrize("switch", ["demean", "uncertainty", "accumulator demean", "with_blocks",
                                    "accumulator uncertainty", "progress"])
@pytest.mark.parametrize("value", NOT_BOOLEANS, ids=repr)
def test_boolean_switches_refuse_anything_but_a_boolean(sim, switch, value):
    name = switch.split()[-1]
    with pytest.raises(TypeError, match=re.escape(f"{name} must be True or False; got {value!r}")):
        _switches(sim)[switch](value)


def test_demean_string_false_no_longer_means_true(sim):
    # bool("False") is True: this used to demean silently
    with pytest.raises(TypeError, match="demean"):
        modaluq.identify(sim.y, fs=sim.fs, demean="False", **FAST)


def test_numpy_booleans_are_booleans(sim):
    a = modaluq.identify(sim.y, fs=sim.fs, demean=np.bool_(False), uncertainty=np.bool_(False), **FAST)
    b = modaluq.identify(sim.y, fs=sim.fs, demean=False, uncertainty=False, **FAST)
    np.testing.assert_array_equal(a.at_order(8).frequency_hz, b.at_order(8).frequency_hz)
    assert not a.settings["demean"] and not a.settings["uncertainty"]


# --------------------------------------------------------------------------- samples


def _sample_entry_points(sim):
    """(label, call(y, u)) for every public function that takes samples."""
    def push(y, u):
        _accumulator().push(y, u)

    return {
        "identify": lambda y, u: modaluq.identify(y, u, fs=sim.fs, **FAST),
        "push": push,
    }


@pytest.mark.parametrize("entry", ["identify", "push"])
def test_boolean_samples_are_refused_naming_the_array(sim, entry):
    call = _sample_entry_points(sim)[entry]
    with pytest.raises(TypeError, match="y must hold real numbers; got booleans"):
        call(sim.y > 0, sim.u)
    with pytest.raises(TypeError, match="u must hold real numbers; got booleans"):
        call(sim.y, sim.u > 0)


def test_boolean_samples_are_refused_by_the_spectrum_and_the_simulator(sim):
    with pytest.raises(TypeError, match="y must hold real numbers; got booleans"):
        output_spectrum_singular_values(sim.y > 0, sim.fs)
    M, K, C = chain_system(2)
    with pytest.raises(TypeError, match="force must hold real numbers; got booleans"):
        acceleration_response(np.ones((10, 2), bool), M, K, C, fs=50.0, output_dofs=(0,))


@pytest.mark.parametrize("entry", ["identify", "push"])
def test_masked_samples_are_missing_data_named_by_sample_and_channel(sim, entry):
    call = _sample_entry_points(sim)[entry]
    y = np.ma.masked_array(sim.y.copy())
    y[4321, 2] = np.ma.masked
    y[5000, 0] = np.ma.masked
    with pytest.raises(ValueError, match=r"y: sample 4321, channel 2 is masked \(missing data\)"):
        call(y, sim.u)
    u = np.ma.masked_invalid(np.where(np.arange(sim.n_samples)[:, None] == 17, np.nan, sim.u))
    with pytest.raises(ValueError, match=r"u: sample 17, channel 0 is masked"):
        call(sim.y, u)


def test_masked_one_dimensional_record_names_its_sample(sim):
    y = np.ma.masked_array(sim.y[:, 0], mask=np.arange(sim.n_samples) == 99)
    with pytest.raises(ValueError, match="y: sample 99, channel 0 is masked"):
        modaluq.identify(y, fs=sim.fs, **FAST)


def test_unmasked_masked_array_gives_the_plain_result(sim):
    plain = modaluq.identify(sim.y, sim.u, fs=sim.fs, **FAST).at_order(8)
    masked = modaluq.identify(np.ma.masked_array(sim.y), np.ma.masked_array(sim.u, mask=False),
                              fs=sim.fs, **FAST).at_order(8)
    np.testing.assert_array_equal(plain.frequency_hz, masked.frequency_hz)
    np.testing.assert_array_equal(plain.frequency_std, masked.frequency_std)


def test_transposed_record_says_did_you_mean_transpose():
    y = np.random.default_rng(0).standard_normal((3, 100_000))
    with pytest.raises(ValueError, match=r"y has shape \(3, 100000\): more channels.*did you mean y\.T\?"):
        modaluq.identify(y, fs=50.0, **FAST)
    with pytest.raises(ValueError, match=r"u has shape \(1, 100000\).*did you mean u\.T\?"):
        modaluq.identify(y.T, y[:1], fs=50.0, **FAST)
    with pytest.raises(ValueError, match=r"did you mean y\.T\?"):
        output_spectrum_singular_values(y, 50.0)


def test_streamed_chunk_transposed_says_so_but_a_short_chunk_is_fine(sim):
    acc = _accumulator()
    acc.push(sim.y[:1], sim.u[:1])            # one sample of three channels is a valid chunk
    acc.push(sim.y[1:3], sim.u[1:3])
    with pytest.raises(ValueError, match=r"y must have 3 channels \(columns\); got shape \(4, 2\)$"):
        acc.push(sim.y[3:7, :2], sim.u[3:7])
    with pytest.raises(ValueError, match=r"got shape \(3, 100\); did you mean y\.T\?"):
        acc.push(sim.y[3:103].T, sim.u[3:103])
    with pytest.raises(ValueError, match=r"u must have 1 channels \(columns\); got shape \(1, 100\); did you mean u\.T\?"):
        acc.push(sim.y[3:103], sim.u[3:103].T)
    assert acc.n_samples == 3


# --------------------------------------------------------------------------- same mistake, same exception


@pytest.mark.parametrize("call,exc,name", [
    (lambda s: modaluq.identify(s.y, fs=s.fs, block_rows=6.0, orders=8, n_blocks=10), TypeError, "block_rows"),
    (lambda s: _accumulator(block_rows=6.0), TypeError, "block_rows"),
    (lambda s: monte_carlo(1, processes=1, progress=False, block_rows=6.0), TypeError, "block_rows"),
    (lambda s: modaluq.simulate(100.5), TypeError, "n_samples"),
    (lambda s: modaluq.simulate(100, discard=2.0), TypeError, "discard"),
    (lambda s: modaluq.simulate(100, output_dofs=(0, 1.0)), TypeError, "output_dofs"),
    (lambda s: modaluq.simulate(100, output_dofs=3), TypeError, "output_dofs"),
    (lambda s: modaluq.identify(s.y, fs="50", **FAST), TypeError, "fs"),
    (lambda s: modaluq.simulate(100, fs="50"), TypeError, "fs"),
    (lambda s: modaluq.simulate(100, noise_std="0.1"), TypeError, "noise_std"),
    (lambda s: modaluq.simulate(100, damping_ratio="0.02"), TypeError, "damping_ratio"),
    (lambda s: modaluq.identify(s.y, fs=s.fs, input_rcond="1e-10", **FAST), TypeError, "input_rcond"),
    (lambda s: modaluq.identify(s.y, fs=0.0, **FAST), ValueError, "fs"),
    (lambda s: modaluq.simulate(100, fs=0.0), ValueError, "fs"),
])
def test_the_same_mistake_raises_the_same_exception_everywhere(sim, call, exc, name):
    with pytest.raises(exc, match=name):
        call(sim)


HUGE = [2**62, 2**63, 2**64, 10**18]


@pytest.mark.parametrize("value", HUGE, ids=str)
@pytest.mark.parametrize("param", ["block_rows", "past_block_rows", "n_blocks", "orders", "references", "threads"])
def test_integers_too_large_for_the_core_are_refused_by_name(sim, param, value):
    kw = dict(fs=sim.fs, **FAST)
    kw[param] = [value] if param == "references" else value
    with pytest.raises(ValueError, match=rf"^{param} must be <= \d+; got {value}$"):
        modaluq.identify(sim.y, **kw)


@pytest.mark.filterwarnings("ignore::modaluq.ModalUQWarning")
def test_threads_are_capped_at_a_sane_number(sim):
    with pytest.raises(ValueError, match=r"threads must be <= 256; got 1000000"):
        modaluq.identify(sim.y, fs=sim.fs, threads=10**6, **FAST)
    modaluq.identify(sim.y, fs=sim.fs, threads=256, **FAST)     # allowed, however many cores


@pytest.mark.parametrize("param", ["n_outputs", "n_inputs", "block_rows", "past_block_rows", "block_length",
                                   "first_sample"])
def test_accumulator_integers_too_large_are_refused_by_name(param):
    with pytest.raises(ValueError, match=rf"^{param} must be <= \d+; got {2**63}$"):
        _accumulator(**{param: 2**63})
    acc = _accumulator()
    with pytest.raises(ValueError, match="threads must be <= 256"):
        acc.identify(fs=50.0, orders=8, threads=10**6)


@pytest.mark.parametrize("kwargs,name", [
    (dict(n_samples=2**63), "n_samples"), (dict(n_dof=2**63), "n_dof"), (dict(discard=10**18), "discard"),
])
def test_simulate_integers_too_large_are_refused_by_name(kwargs, name):
    n = kwargs.pop("n_samples", 100)
    with pytest.raises(ValueError, match=rf"^{name} must be <= \d+"):
        modaluq.simulate(n, **kwargs)


def test_monte_carlo_processes_are_capped():
    with pytest.raises(ValueError, match="processes must be <= 256"):
        monte_carlo(2, processes=10**6, progress=False)


# --------------------------------------------------------------------------- optional dependencies


@pytest.fixture
def chain_diagram(sim):
    result = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=8, orders=range(2, 15, 2), n_blocks=10)
    return result.stabilization_diagram()


def test_missing_xarray_names_the_export_extra(chain_diagram, monkeypatch):
    monkeypatch.setitem(sys.modules, "xarray", None)         # import xarray -> ImportError
    with pytest.raises(ImportError, match=r'needs xarray, which is not installed: run pip install "\.\[export\]"'):
        chain_diagram.to_xarray()


def test_missing_netcdf4_names_the_export_extra(chain_diagram, monkeypatch, tmp_path):
    from modaluq import export

    monkeypatch.setitem(sys.modules, "netCDF4", None)
    with pytest.raises(ImportError, match=r'writing NetCDF needs netCDF4.*pip install "\.\[export\]"'):
        export.write_netcdf(tmp_path / "d.nc", chain_diagram, chain_diagram.select_modes())
    assert not (tmp_path / "d.nc").exists()


def test_tutorial_installs_from_a_clone_not_the_package_index():
    import pathlib
    import re as _re

    text = (pathlib.Path(__file__).parents[2] / "docs" / "tutorial.md").read_text(encoding="utf-8")
    installs = _re.findall(r"pip install ([^`\n]+)", text)
    assert installs, "the tutorial says how to install"
    # modaluq is not on the package index: every install of it is of the clone ('.' or '.[extra]')
    assert all(arg.split()[0].strip('"\'').startswith(".") for arg in installs), installs
