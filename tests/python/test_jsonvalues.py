"""modaluq.jsonvalues: one JSON rule for the package (a non-finite number is null), and
checks.check_instance (the settings objects an analysis takes)."""

import enum
import json
import math
import pathlib

import numpy as np
import pytest

import modaluq
from modaluq import provenance as provenance_module
from modaluq.checks import check_instance
from modaluq.jsonvalues import dumps, finite_or_none, jsonable, number


def test_non_finite_numbers_are_null():
    for x in (np.nan, math.inf, -math.inf, np.float32("nan"), np.float64("-inf")):
        assert finite_or_none(x) is None and jsonable(x) is None
    assert jsonable([1.0, np.nan, np.array([np.inf, 2.0])]) == [1.0, None, [None, 2.0]]
    assert dumps({"a": np.nan}) == '{"a": null}'
    assert json.loads(dumps(np.array([[np.nan, 1.0]]))) == [[None, 1.0]]


def test_read_back_null_is_nan():
    values = json.loads(dumps(np.array([1.0, np.nan, 3.0])))
    assert math.isnan(number(values[1])) and number(values[0]) == 1.0
    np.testing.assert_array_equal(np.asarray(values, float), [1.0, np.nan, 3.0])


def test_values():
    class Color(enum.Enum):
        RED = "red"

    class WithDict:
        def to_dict(self):
            return {"x": np.int32(2)}

    got = jsonable({1: np.int64(3), "b": np.bool_(True), "p": pathlib.Path("a/b"), "e": Color.RED,
                    "c": np.array([1 + 2j, np.nan]), "z": complex(0, -1), "t": (np.float32(0.5),),
                    "s": WithDict(), "o": object.__new__(WithDict).__class__, "none": None})
    assert got["1"] == 3 and type(got["1"]) is int and got["b"] is True
    assert got["p"] == str(pathlib.Path("a/b")) and got["e"] == "red"
    assert got["c"] == {"real": [1.0, None], "imag": [2.0, 0.0]} and got["z"] == {"real": 0.0, "imag": -1.0}
    assert got["t"] == [0.5] and got["s"] == {"x": 2} and isinstance(got["o"], str) and got["none"] is None
    assert json.loads(dumps(got)) == got


def test_dumps_refuses_what_jsonable_cannot_fix():
    # allow_nan=False: the strict JSON writer, whatever jsonable returned
    with pytest.raises(ValueError):
        json.dumps(float("nan"), allow_nan=False)
    assert "NaN" not in dumps({"x": [np.nan] * 3}, indent=2)


def test_provenance_uses_the_one_helper():
    assert provenance_module.jsonable is jsonable
    stamp = provenance_module.provenance(settings={"limit": np.inf, "n": np.int64(4)})
    assert stamp["settings"] == {"limit": None, "n": 4}


def test_report_json_has_no_nan(tmp_path):
    from modaluq.export import write_json

    sim = modaluq.simulate(4000, seed=2)
    diagram = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=15, orders=range(2, 21, 2)).stabilization_diagram()
    path = write_json(tmp_path / "r.json", diagram, diagram.select_modes(), extra={"x": np.nan})
    text = path.read_text()
    assert "NaN" not in text and "Infinity" not in text and json.loads(text)["x"] is None


def test_check_instance():
    s = modaluq.Settings()
    assert check_instance("settings", s, modaluq.Settings) is s
    assert check_instance("settings", None, modaluq.Settings) == modaluq.Settings()
    with pytest.raises(TypeError, match=r"^criteria must be a modaluq\.StabilityCriteria; got dict$"):
        check_instance("criteria", {}, modaluq.StabilityCriteria)
    with pytest.raises(TypeError, match=r"settings must be a modaluq\.Settings; got dict"):
        modaluq.Analysis.from_arrays(np.zeros((100, 2)), fs=10.0, settings={})
