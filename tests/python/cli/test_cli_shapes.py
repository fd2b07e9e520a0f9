"""``modaluq identify FILE --geometry geo.toml --report r.html --out modes.uff`` end to end
(docs/shapes.md), and its refusals before any computation, each one line naming the option."""

import numpy as np
import pytest

import modaluq
from modaluq.cli import main

GEOMETRY = """
name = "three-mass chain"
nodes = [[1, 0, 0, 0], [2, 1, 0, 0], [3, 2, 0, 0], [4, 3, 0, 0]]
lines = [[1, 2], [2, 3], [3, 4]]
[[channels]]
name = "m1"
node = 2
direction = "+x"
[[channels]]
name = "m2"
node = 3
direction = "+x"
[[channels]]
name = "m5"
node = 4
direction = "+x"
"""
ARGS = ["--block-rows", "15", "--orders", "2:30:2", "--no-progress"]


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    sim = modaluq.simulate(20_000, seed=2)
    folder = tmp_path_factory.mktemp("shapes")
    path = folder / "chain.npz"
    np.savez(path, y=sim.y, fs=np.array(sim.fs), channel_names=np.array(["m1", "m2", "m5"]))
    (folder / "geo.toml").write_text(GEOMETRY, encoding="utf-8")
    return path, folder / "geo.toml"


def test_identify_with_geometry_report_and_uff(record, tmp_path, capsys):
    pytest.importorskip("plotly")
    pytest.importorskip("pyuff")
    from modaluq import exchange

    path, geo = record
    status = main(["identify", str(path), "--geometry", str(geo), "--report", str(tmp_path / "r.html"),
                   "--out", str(tmp_path / "modes.uff"), "--out", str(tmp_path / "modes.json"), *ARGS])
    out, err = capsys.readouterr()
    assert status == 0, err
    for name in ("r.html", "modes.uff", "modes.std.uff", "modes.json"):
        assert f"wrote {tmp_path / name}" in out
    html = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert "three-mass chain" in html and "plotly.js v" in html
    assert "with the shapes' cross-covariance" in html  # --report keeps the shape factors: the exact AutoMAC σ
    back = exchange.read_uff_modes(tmp_path / "modes.uff")
    assert back.n_modes >= 2 and back.geometry.n_nodes == 4
    a = modaluq.Analysis.from_file(path, settings=modaluq.Settings(block_rows=15, orders=tuple(range(2, 31, 2))))
    a.run()
    np.testing.assert_allclose(back.frequency_hz, a.selected.frequency_hz, rtol=1e-5)
    # node 3 carries channel m2 along x: its UFF x component is the shape's m2 component
    np.testing.assert_allclose(back.mode_shape[back.output_names.index("3+X")], a.selected.mode_shape[1],
                               rtol=1e-5, atol=1e-6)
    # the JSON holds every node of the geometry too: node 3's x is channel m2, node 1 is fixed
    import json

    nodes = json.loads((tmp_path / "modes.json").read_text(encoding="utf-8"))["node_shapes"]
    assert nodes["node_ids"] == [1, 2, 3, 4] and nodes["moving"] == [False, True, True, True]
    shape = np.array([np.array(m["real"]) + 1j * np.array(m["imag"]) for m in nodes["modes"]])  # mode, node, xyz
    np.testing.assert_allclose(shape[:, 2, 0], a.selected.mode_shape[1], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(shape[:, 0], 0)
    np.testing.assert_allclose(np.array([m["std_real"] for m in nodes["modes"]])[:, 2, 0],
                               a.selected.mode_shape_std_real[1], rtol=1e-9, atol=1e-15)



def test_refusals_name_the_option(record, tmp_path, one_line_error):
    path, geo = record
    err = one_line_error(main(["identify", str(path), "--out", str(tmp_path / "m.uff"), *ARGS]))
    assert "--out" in err and "give --geometry" in err
    err = one_line_error(main(["identify", str(path), "--report", str(tmp_path / "r.pdf"), *ARGS]))
    assert "--report" in err and ".html" in err
    bad = tmp_path / "bad.toml"
    bad.write_text(GEOMETRY.replace("node = 4", "node = 9"), encoding="utf-8")
    err = one_line_error(main(["identify", str(path), "--geometry", str(bad), *ARGS]))
    assert "--geometry" in err and "channel 'm5': unknown node 9" in err
    other = tmp_path / "other.toml"
    other.write_text(GEOMETRY.replace('name = "m5"', 'name = "m9"'), encoding="utf-8")
    err = one_line_error(main(["identify", str(path), "--geometry", str(other), *ARGS]))
    assert "--geometry" in err and "'m5' is not a channel of the geometry" in err
