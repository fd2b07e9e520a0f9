"""UFF exchange (modaluq.exchange): geometry → UFF 15 + 82, modes → UFF 55 with the standard
deviations in a second UFF 55 file; read back by pyuff with the same numbers (UFF's 6 significant
digits); UFF 55 files written by other programs read by modaluq."""

import math
import pathlib
import types

import numpy as np
import pytest

from modaluq.geometry import Geometry

pyuff = pytest.importorskip("pyuff")

from modaluq import exchange  # noqa: E402

DATA = pathlib.Path(__file__).parent / "data" / "uff"
RTOL = 1e-5  # E13.5: 6 significant digits


@pytest.fixture
def floor():
    geo = Geometry.from_dict({
        "name": "rigid floor on columns",
        "nodes": [[1, 0, 0, 0], [2, 4, 0, 0], [3, 4, 3, 0], [4, 0, 3, 0],
                  [11, 0, 0, 3], [12, 4, 0, 3], [13, 4, 3, 3], [14, 0, 3, 3]],
        "lines": [[1, 11], [2, 12], [3, 13], [4, 14], [11, 12], [12, 13], [13, 14], [14, 11]],
        "channels": [{"name": "ax", "node": 11, "direction": "x"}, {"name": "ay", "node": 11, "direction": "y"},
                     {"name": "cx", "node": 13, "direction": [1, 0, 0]}],
        "constraints": [{"kind": "rigid", "nodes": [11, 12, 13, 14], "channels": ["ax", "ay", "cx"], "normal": "z"}]})
    rng = np.random.default_rng(2)
    shape = np.array([[1.0, 0.3 + 0.1j], [0.2 - 0.05j, 1.0], [0.8 + 0.02j, -0.4]])
    a = rng.standard_normal((2, 6, 6))
    cov = 1e-4 * np.einsum("kij,klj->kil", a, a)
    modes = types.SimpleNamespace(frequency_hz=np.array([1.25, 3.5]), damping_ratio=np.array([0.02, 0.011]),
                                  frequency_std=np.array([0.01, 0.02]), damping_std=np.array([0.003, 0.002]),
                                  mode_shape=shape, output_names=("ax", "ay", "cx"), mode_shape_covariance=cov)
    return geo, modes


def test_geometry_and_modes_round_trip_through_pyuff(tmp_path, floor):
    geo, modes = floor
    paths = exchange.write_uff(tmp_path / "modes.uff", modes, geo)
    assert [p.name for p in paths] == ["modes.uff", "modes.std.uff"]
    sets = pyuff.UFF(str(paths[0])).read_sets()
    assert [s["type"] for s in sets] == [15, 82, 55, 55]
    np.testing.assert_array_equal(sets[0]["node_nums"], geo.node_ids)
    np.testing.assert_allclose(np.column_stack([sets[0][k] for k in "xyz"]), geo.coordinates, rtol=RTOL)
    seq = [int(v) for v in sets[1]["nodes"]]
    assert [[a, b] for a, b in zip(seq[:-1], seq[1:]) if a and b] == geo.lines.tolist()
    for k in range(2):
        s = sets[2 + k]
        assert (s["analysis_type"], s["data_ch"], s["data_type"], s["mode_n"]) == (3, 2, 5, k + 1)
        lam = complex(s["eig"])
        np.testing.assert_allclose(abs(lam) / (2 * math.pi), modes.frequency_hz[k], rtol=RTOL)
        np.testing.assert_allclose(-lam.real / abs(lam), modes.damping_ratio[k], rtol=RTOL)
        u = geo.displacements(modes.mode_shape[:, k], modes.output_names).value
        np.testing.assert_array_equal(s["node_nums"], geo.node_ids)
        got = np.column_stack([s["r1"], s["r2"], s["r3"]])
        np.testing.assert_allclose(got, u, rtol=RTOL, atol=1e-12)
    # the standard deviations: σ(Re u) + i σ(Im u) of each node component, from the exact covariance
    std = pyuff.UFF(str(paths[1])).read_sets()
    assert [s["type"] for s in std] == [15, 82, 55, 55] and std[2]["id1"] == exchange.STD_ID
    for k in range(2):
        d = geo.displacements(modes.mode_shape[:, k], modes.output_names, covariance=modes.mode_shape_covariance[k])
        var = np.diagonal(d.covariance, axis1=1, axis2=2)
        got = np.column_stack([std[2 + k][r] for r in ("r1", "r2", "r3")])
        np.testing.assert_allclose(got.real, np.sqrt(var[:, :3]), rtol=RTOL, atol=1e-14)
        np.testing.assert_allclose(got.imag, np.sqrt(var[:, 3:]), rtol=RTOL, atol=1e-14)


def _floor_with_mid_column(geo):
    """The floor plus a mid-column node whose x is half the top's (a linear constraint), and the
    map from [ax, ay, cx] to every node's x, y, z written by hand from the rigid-body kinematics
    (not Geometry's solver): (n_nodes, 3, 3), and the (6 n_nodes, 6) map of [Re φ; Im φ]."""
    spec = {"nodes": [*[[int(i), *xyz] for i, xyz in zip(geo.node_ids, geo.coordinates.tolist())], [5, 4, 0, 1.5]],
            "lines": [*geo.lines.tolist(), [2, 5], [5, 12]],
            "channels": [{"name": "ax", "node": 11, "direction": "x"}, {"name": "ay", "node": 11, "direction": "y"},
                         {"name": "cx", "node": 13, "direction": "x"}],
            "constraints": [{"kind": "rigid", "nodes": [11, 12, 13, 14], "channels": ["ax", "ay", "cx"],
                             "normal": "z"},
                            {"kind": "linear", "node": 5, "direction": "x", "weights": {"ax": 0.5}}]}
    geo = Geometry.from_dict(spec)
    # u = t + θ e_z × (p - c), c = (2, 1.5): ax = tx + 1.5θ, ay = ty - 2θ, cx = tx - 1.5θ
    rigid = np.array([[0.5, 0, 0.5], [2 / 3, 1, -2 / 3], [1 / 3, 0, -1 / 3]])  # [tx, ty, θ] from [ax, ay, cx]
    t = np.zeros((geo.n_nodes, 3, 3))  # node, xyz, channel
    for i, (n, (x, y, _)) in enumerate(zip(geo.node_ids, geo.coordinates)):
        if n in (11, 12, 13, 14):
            t[i, 0] = rigid[0] - (y - 1.5) * rigid[2]
            t[i, 1] = rigid[1] + (x - 2.0) * rigid[2]
        elif n == 5:
            t[i, 0] = [0.5, 0, 0]
    big = np.zeros((6 * geo.n_nodes, 6))  # [Re u; Im u] per node from [Re φ; Im φ]
    for i in range(geo.n_nodes):
        big[6 * i:6 * i + 3, :3] = big[6 * i + 3:6 * i + 6, 3:] = t[i]
    return geo, t, big


def test_constrained_nodes_are_exported_in_xyz_with_sigma_through_the_same_map(tmp_path, floor):
    # The floor's 4 corners from 3 sensors (rigid in its plane) and a mid-column node: every
    # node's x, y, z in UFF 55, and the σ file from T C T' with T written by hand.
    geo, t, big = _floor_with_mid_column(floor[0])
    modes = floor[1]
    paths = exchange.write_uff(tmp_path / "c.uff", modes, geo)
    sets, std = (pyuff.UFF(str(p)).read_sets() for p in paths)
    assert [s["type"] for s in sets] == [15, 82, 55, 55]
    for k in range(2):
        got = np.column_stack([sets[2 + k][r] for r in ("r1", "r2", "r3")])
        np.testing.assert_array_equal(sets[2 + k]["node_nums"], geo.node_ids)
        np.testing.assert_allclose(got, t @ modes.mode_shape[:, k], rtol=RTOL, atol=1e-12)
        assert np.all(got[[0, 1, 2, 3]] == 0) and got[geo.node_ids.tolist().index(5), 1] == 0  # base; 5 along x only
        var = np.diag(big @ modes.mode_shape_covariance[k] @ big.T).reshape(-1, 2, 3)
        got = np.column_stack([std[2 + k][r] for r in ("r1", "r2", "r3")])
        np.testing.assert_allclose(got.real, np.sqrt(var[:, 0]), rtol=RTOL, atol=1e-14)
        np.testing.assert_allclose(got.imag, np.sqrt(var[:, 1]), rtol=RTOL, atol=1e-14)


def test_json_and_netcdf_hold_every_node_with_its_sigma(tmp_path, floor, chain):
    import json

    import modaluq
    from modaluq import export

    pytest.importorskip("netCDF4")
    xr = pytest.importorskip("xarray")
    geo, t, big = _floor_with_mid_column(floor[0])
    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2),
                              output_names=["ax", "ay", "cx"])
    diagram = result.stabilization_diagram()
    sel = diagram.select_modes()
    export.write(tmp_path / "m.json", diagram, sel, geometry=geo)
    export.write(tmp_path / "m.nc", diagram, sel, geometry=geo)
    nodes = json.loads((tmp_path / "m.json").read_text(encoding="utf-8"))["node_shapes"]
    assert nodes["node_ids"] == geo.node_ids.tolist() and nodes["exact_sigma"] is True
    with xr.open_dataset(tmp_path / "m.nc") as ds:
        assert ds["selected_node_shape_real"].dims == ("mode", "node", "axis")
        np.testing.assert_array_equal(ds["node"], geo.node_ids)
        np.testing.assert_allclose(ds["node_coordinates"], geo.coordinates)
        for k in range(sel.n_modes):
            want = t @ sel.mode_shape[:, k]
            sd = np.sqrt(np.clip(np.diag(big @ sel.mode_covariance[k][2:, 2:] @ big.T), 0, None)).reshape(-1, 2, 3)
            m = nodes["modes"][k]
            assert m["mode"] == k + 1
            np.testing.assert_allclose(np.array(m["real"]) + 1j * np.array(m["imag"]), want, atol=1e-12)
            np.testing.assert_allclose(m["std_real"], sd[:, 0], rtol=1e-9, atol=1e-15)
            np.testing.assert_allclose(m["std_imag"], sd[:, 1], rtol=1e-9, atol=1e-15)
            got = ds["selected_node_shape_real"][k] + 1j * ds["selected_node_shape_imag"][k]
            np.testing.assert_allclose(got, want, atol=1e-12)
            np.testing.assert_allclose(ds["selected_node_shape_std_real"][k], sd[:, 0], rtol=1e-9, atol=1e-15)
            np.testing.assert_allclose(ds["selected_node_shape_std_imag"][k], sd[:, 1], rtol=1e-9, atol=1e-15)
    # without a geometry the exports are as before
    export.write(tmp_path / "n.json", diagram, sel)
    assert "node_shapes" not in json.loads((tmp_path / "n.json").read_text(encoding="utf-8"))


def test_modaluq_reads_its_own_file_back_with_the_geometry(tmp_path, floor):
    geo, modes = floor
    exchange.write_uff(tmp_path / "m.uff", modes, geo)
    back = exchange.read_uff_modes(tmp_path / "m.uff")
    assert back.n_modes == 2 and not back.is_std
    np.testing.assert_allclose(back.frequency_hz, modes.frequency_hz, rtol=RTOL)
    np.testing.assert_allclose(back.damping_ratio, modes.damping_ratio, rtol=RTOL)
    np.testing.assert_array_equal(back.geometry.node_ids, geo.node_ids)
    np.testing.assert_array_equal(back.geometry.lines, geo.lines)
    # the nodal shape on the read geometry is the node displacement of the original
    for k in range(2):
        u = geo.displacements(modes.mode_shape[:, k], modes.output_names).value
        v = back.geometry.displacements(back.mode_shape[:, k], back.output_names).value
        np.testing.assert_allclose(v, u, rtol=RTOL, atol=1e-12)
    assert exchange.read_uff_modes(tmp_path / "m.std.uff").is_std


def test_geometry_uff_reads_back_as_a_geometry(tmp_path, floor):
    geo, _ = floor
    exchange.write_geometry_uff(tmp_path / "g.uff", geo)
    back = Geometry.from_uff(tmp_path / "g.uff", {"ax": {"node": 11, "direction": "x"}})
    np.testing.assert_array_equal(back.node_ids, geo.node_ids)
    np.testing.assert_allclose(back.coordinates, geo.coordinates)
    np.testing.assert_array_equal(back.lines, geo.lines)


def test_a_uff55_written_by_another_program_is_read():
    # an OMA program's complex mode (pyuff's sample file: ID lines "POMA ...", 7-digit E format)
    m = exchange.read_uff_modes(DATA / "pyuff_uff55_sample_test_record10.uff")
    lam = -0.1111111 + 41.11111j
    np.testing.assert_allclose(m.frequency_hz, [abs(lam) / (2 * np.pi)], rtol=1e-7)
    np.testing.assert_allclose(m.damping_ratio, [0.1111111 / abs(lam)], rtol=1e-7)
    assert m.node_ids.tolist() == [60101, 111111] and m.geometry is None  # no nodes in the file
    # each node's line: Re x, Im x, Re y, Im y, Re z, Im z
    np.testing.assert_allclose(m.mode_shape[3:, 0], [0, 0.1111111 + 0.09111111j, 0.007111111 + 0.004111111j],
                               rtol=1e-7)
    np.testing.assert_allclose(m.mode_shape[:3, 0], [0, 0, -0.04111111 - 0.01111111j], rtol=1e-7)
    assert m.ids[0][2].startswith("POMA:")
    # normal modes (analysis type 2)
    n = exchange.read_uff_modes(DATA / "pyuff_uff55_translation.uff")
    assert n.n_modes == 3 and n.frequency_hz[0] == 10.0 and n.mode_shape.shape == (12, 3)
    np.testing.assert_allclose(n.mode_shape[:3, 0], [-1.46518] * 3)


def test_a_uff55_written_by_pyuff_directly_is_read(tmp_path):
    # "another program": pyuff's own writer, a normal mode with its geometry
    path = str(tmp_path / "other.uff")
    uff = pyuff.UFF(path)
    uff.write_sets([pyuff.prepare_15(node_nums=[5, 6], def_cs=[0, 0], disp_cs=[0, 0], color=[1, 1], x=[0.0, 1.0],
                                     y=[0.0, 0.0], z=[0.0, 0.0]),
                    pyuff.prepare_55(model_type=1, analysis_type=2, data_ch=2, spec_data_type=8, data_type=2,
                                     n_data_per_node=3, load_case=1, mode_n=1, freq=7.5, modal_m=1.0,
                                     modal_damp_vis=0.015, modal_damp_his=0.0, node_nums=np.array([5, 6]),
                                     r1=np.array([0.0, 0.0]), r2=np.array([0.0, 0.0]), r3=np.array([0.5, 1.0]))],
                   mode="add")
    m = exchange.read_uff_modes(path)
    assert (m.frequency_hz[0], m.damping_ratio[0]) == (7.5, 0.015)
    np.testing.assert_allclose(m.mode_shape[:, 0], [0, 0, 0.5, 0, 0, 1.0])
    assert m.geometry.n_nodes == 2 and m.output_names[2] == "5+Z"


def test_refusals(tmp_path, floor):
    geo, modes = floor
    with pytest.raises(ValueError, match="ends in .uff or .unv"):
        exchange.write_uff(tmp_path / "m.txt", modes, geo)
    (tmp_path / "empty.uff").write_text("    -1\n    15\n    -1\n")
    with pytest.raises(ValueError, match="empty.uff"):
        exchange.read_uff_modes(tmp_path / "empty.uff")
    bad = types.SimpleNamespace(**{**vars(modes), "output_names": ("ax", "ay", "dx")})
    with pytest.raises(ValueError, match="'dx' is not a channel of the geometry"):
        exchange.write_uff(tmp_path / "m.uff", bad, geo)
    assert not (tmp_path / "m.uff").exists()


def test_modes_without_uncertainty_write_no_std_file(tmp_path, floor, chain):
    import modaluq

    geo, _ = floor
    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2),
                              output_names=["ax", "ay", "cx"], uncertainty=False)
    sel = result.select_modes()
    assert np.isnan(sel.mode_shape_std_real).all()  # NaN std: no σ to write
    assert exchange.write_uff(tmp_path / "m.uff", sel, geo) == [tmp_path / "m.uff"]
    assert not (tmp_path / "m.std.uff").exists()
    assert len(pyuff.UFF(str(tmp_path / "m.uff")).read_sets()) == 2 + sel.n_modes
