"""Geometry (docs/shapes.md): nodes, lines, channel placement, constraints, read from TOML, CSV and
UFF; checked refusals; a shape's node displacements and their covariance (a linear map: exact)."""

import textwrap

import numpy as np
import pytest

import modaluq
from modaluq.geometry import Geometry, direction_vector

FRAME = """
name = "two-storey frame"
units = "m"
nodes = [[1, 0, 0, 0], [2, 4, 0, 0], [3, 0, 3, 0], [4, 4, 3, 0],
         [11, 0, 0, 3], [12, 4, 0, 3], [13, 0, 3, 3], [14, 4, 3, 3]]
lines = [[1, 11], [2, 12], [3, 13], [4, 14], [11, 12], [12, 14], [14, 13], [13, 11]]
triangles = [[11, 12, 14]]

[[channels]]
name = "ax"
node = 11
direction = "+x"

[[channels]]
name = "ay"
node = 11
direction = [0, 2, 0]     # normalised

[[channels]]
name = "bx"
node = 14
direction = "+x"

[[constraints]]
kind = "rigid"
nodes = [11, 12, 13, 14]
channels = ["ax", "ay", "bx"]
normal = "z"
"""


def write(tmp_path, text, name="geo.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text), encoding="utf-8")
    return p


@pytest.fixture
def frame(tmp_path):
    return Geometry.from_toml(write(tmp_path, FRAME))


def test_toml_reads_nodes_lines_channels_and_normalises_directions(frame):
    assert frame.n_nodes == 8 and frame.n_channels == 3 and len(frame.lines) == 8 and len(frame.triangles) == 1
    assert frame.channels == ("ax", "ay", "bx")
    np.testing.assert_allclose(frame.channel_direction[1], [0, 1, 0])
    assert frame.units == "m" and frame.name == "two-storey frame"
    # the ground nodes take no part: not moving
    assert frame.moving.tolist() == [False] * 4 + [True] * 4
    assert frame.unobserved == ()  # three channels observe the plane's three motions


def test_rigid_floor_gives_every_floor_node_the_rigid_motion(frame):
    # a plane rigid motion: translation (tx, ty), rotation θ about z, centre = floor centroid (2, 1.5)
    tx, ty, th = 0.3, -0.2, 0.05
    c = np.array([2.0, 1.5, 3.0])

    def u(p):
        r = np.asarray(p, float) - c
        return np.array([tx - th * r[1], ty + th * r[0], 0.0])

    xyz = {int(i): p for i, p in zip(frame.node_ids, frame.coordinates)}
    phi = np.array([u(xyz[11])[0], u(xyz[11])[1], u(xyz[14])[0]])  # what the channels read
    d = frame.displacements(phi, ["ax", "ay", "bx"])
    for n in (11, 12, 13, 14):
        np.testing.assert_allclose(d.value[frame.node_index(n)].real, u(xyz[n]), atol=1e-12)
    np.testing.assert_array_equal(d.value[:4], 0)


def test_unobserved_rigid_motions_are_zero_and_said(tmp_path):
    # a shear-frame floor with one sensor along x: y and the rotation are not observed
    geo = Geometry.from_dict({
        "nodes": [[1, 0, 0, 0], [2, 1, 0, 0], [3, 1, 1, 0]],
        "channels": [{"name": "x", "node": 1, "direction": "x"}],
        "constraints": [{"kind": "rigid", "nodes": [1, 2, 3], "channels": ["x"], "normal": [0, 0, 1]}]})
    d = geo.displacements(np.array([2.0]), ["x"])
    np.testing.assert_allclose(d.value.real, [[2, 0, 0]] * 3, atol=1e-12)
    assert len(geo.unobserved) == 1 and "2 of its 3 motions" in geo.unobserved[0]


def test_linear_constraint_and_measured_node_least_squares():
    geo = Geometry.from_dict({
        "nodes": [[1, 0, 0, 0], [2, 1, 0, 0], [3, 2, 0, 0]],
        "channels": [{"name": "a", "node": 1, "direction": "z"}, {"name": "c", "node": 3, "direction": "z"},
                     {"name": "c2", "node": 3, "direction": [1, 0, 1]}],
        "constraints": [{"kind": "linear", "node": 2, "direction": "z", "weights": {"a": 0.5, "c": 0.5}}]})
    phi = np.array([1.0 + 0.5j, 3.0, 2.0 ** 0.5 * 2.5])  # node 3: uz = 3, (ux + uz)/√2 = 2.5√2 → ux = 2
    d = geo.displacements(phi, ["a", "c", "c2"])
    np.testing.assert_allclose(d.value, [[0, 0, 1 + 0.5j], [0, 0, 2 + 0.25j], [2, 0, 3]], atol=1e-12)


def test_shape_in_another_channel_order_is_reordered_by_name(frame):
    phi = np.array([0.1, 0.2, 0.3])
    a = frame.displacements(phi, ["ax", "ay", "bx"]).value
    b = frame.displacements(phi[[2, 0, 1]], ["bx", "ax", "ay"]).value
    np.testing.assert_allclose(a, b)


def test_covariance_is_propagated_exactly():
    # node displacements are T φ: cov = T C Tᵀ (for Re, Im and the cross terms), checked against
    # the sample covariance of draws and against the linear map applied column by column
    rng = np.random.default_rng(4)
    geo = Geometry.from_dict({
        "nodes": [[1, 0, 0, 0], [2, 2, 0, 0], [3, 0, 1, 0], [4, 2, 1, 0]],
        "channels": [{"name": "p", "node": 1, "direction": "z"}, {"name": "q", "node": 2, "direction": "z"},
                     {"name": "r", "node": 3, "direction": "z"}],
        "constraints": [{"kind": "rigid", "nodes": [1, 2, 3, 4], "channels": ["p", "q", "r"]}]})
    l = 3
    phi = np.array([1.0, 0.4 + 0.1j, -0.3 + 0.05j])
    a = rng.standard_normal((2 * l, 2 * l))
    cov = 0.01 * a @ a.T
    d = geo.displacements(phi, ["p", "q", "r"], covariance=cov)
    assert d.exact and d.covariance.shape == (4, 6, 6)
    # the map column by column (linear: a unit change of each parameter)
    jac = np.zeros((4, 6, 2 * l))
    for k in range(2 * l):
        e = np.zeros(2 * l)
        e[k] = 1.0
        dv = geo.displacements(e[:l] + 1j * e[l:], ["p", "q", "r"]).value
        jac[:, :, k] = np.concatenate([dv.real, dv.imag], axis=1)
    np.testing.assert_allclose(d.covariance, np.einsum("nik,kl,njl->nij", jac, cov, jac), atol=1e-14)
    # node 4 (unmeasured, rigid plate) against draws
    draws = rng.multivariate_normal(np.concatenate([phi.real, phi.imag]), cov, size=40_000)
    u4 = np.array([geo.displacements(x[:l] + 1j * x[l:], ["p", "q", "r"]).value[3] for x in draws[:4000]])
    sample = np.cov(np.concatenate([u4.real, u4.imag], axis=1).T)
    scale = np.sqrt(np.outer(np.diag(d.covariance[3]), np.diag(d.covariance[3]))) + 1e-12
    assert np.max(np.abs(sample - d.covariance[3]) / scale) < 0.1
    # over a cycle: Re(u e^{iα}) has the covariance covariance_at(α)
    alpha = 0.7
    at = np.array([np.cos(alpha) * v.real - np.sin(alpha) * v.imag for v in u4])
    np.testing.assert_allclose(d.at_phase(alpha)[3], (phi @ np.zeros(l) + d.value[3] * np.exp(1j * alpha)).real)
    sample_at = np.cov(at.T)
    ca = d.covariance_at(alpha)[3]
    assert np.max(np.abs(sample_at - ca) / (np.sqrt(np.outer(np.diag(ca), np.diag(ca))) + 1e-12)) < 0.1


def test_std_only_gives_a_diagonal_channel_covariance_marked_not_exact(frame):
    d = frame.displacements(np.array([1.0, 0.5, 0.8]), ["ax", "ay", "bx"], std_real=[0.1, 0.2, 0.0])
    assert not d.exact
    # channel ax's own node along x: the rigid fit of three channels is exact at the sensor
    i = frame.node_index(11)
    np.testing.assert_allclose(np.sqrt(d.covariance[i, 0, 0]), 0.1, rtol=1e-12)
    np.testing.assert_allclose(np.sqrt(d.covariance[i, 1, 1]), 0.2, rtol=1e-12)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('node = 14\n', 'node = 99\n'), "channel 'bx': unknown node 99"),
    (lambda t: t.replace('name = "bx"\nnode = 14\n', 'name = "bx"\n'), "channel 'bx' has no node"),
    (lambda t: t.replace("[0, 2, 0]", "[0, 0, 0]"), "direction of channel 'ay'"),
    (lambda t: t.replace("[13, 11]]", "[13, 77]]"), "unknown node 77"),
    (lambda t: t.replace('channels = ["ax", "ay", "bx"]', 'channels = ["ax", "zz"]'), "unknown channel 'zz'"),
    (lambda t: t.replace("[2, 4, 0, 0]", "[1, 4, 0, 0]"), "node 1 is defined twice"),
    (lambda t: t.replace('kind = "rigid"', 'kind = "bolted"'), "kind must be 'linear' or 'rigid'"),
    (lambda t: "colour = 3\n" + t, "geometry: unknown key 'colour'"),
    (lambda t: t + "\ncolour = 3\n", "rigid constraint: unknown key 'colour'"),
    (lambda t: t.replace('name = "bx"\n', 'name = "bx"\ndirn = "x"\n'), "channel 'bx': unknown key 'dirn'"),
    (lambda t: t.replace("nodes = [[1,", "nodes = [[1 ,,"), "not valid TOML"),
])
def test_bad_geometry_is_refused_by_name(tmp_path, edit, message):
    p = write(tmp_path, edit(FRAME))
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("(", r"\(")) as info:
        Geometry.from_toml(p)
    assert str(p) in str(info.value)


def test_shape_whose_names_do_not_match_is_refused_by_name(frame):
    with pytest.raises(ValueError, match="'cx' is not a channel of the geometry"):
        frame.displacements(np.ones(3), ["ax", "ay", "cx"])
    with pytest.raises(ValueError, match="no component for the geometry's channel 'bx'"):
        frame.displacements(np.ones(2), ["ax", "ay"])
    with pytest.raises(ValueError, match="dof_names has 2 names but shape has 3"):
        frame.displacements(np.ones(3), ["ax", "ay"])
    with pytest.raises(ValueError, match=r"covariance must be \(2l, 2l\)"):
        frame.displacements(np.ones(3), ["ax", "ay", "bx"], covariance=np.eye(3))


def test_direction_vector():
    np.testing.assert_allclose(direction_vector("-Y"), [0, -1, 0])
    np.testing.assert_allclose(direction_vector([3, 0, 4]), [0.6, 0, 0.8])
    for bad in ("w", [1, 2], [np.nan, 0, 1], [0, 0, 0]):
        with pytest.raises(ValueError, match="direction"):
            direction_vector(bad)


def test_csv_tables(tmp_path, frame):
    (tmp_path / "nodes.csv").write_text("id,x,y,z\n" + "".join(
        f"{i},{p[0]},{p[1]},{p[2]}\n" for i, p in zip(frame.node_ids, frame.coordinates)))
    (tmp_path / "channels.csv").write_text("name,node,direction,dx,dy,dz\nax,11,+x,,,\nay,11,,0,3,0\nbx,14,x,,,\n")
    (tmp_path / "lines.csv").write_text("a,b\n" + "".join(f"{a},{b}\n" for a, b in frame.lines))
    geo = Geometry.from_csv(tmp_path / "nodes.csv", tmp_path / "channels.csv", lines=tmp_path / "lines.csv")
    np.testing.assert_array_equal(geo.node_ids, frame.node_ids)
    np.testing.assert_allclose(geo.channel_direction, frame.channel_direction)
    np.testing.assert_array_equal(geo.lines, frame.lines)
    (tmp_path / "bad.csv").write_text("name,node,direction\nax,11,\n")
    with pytest.raises(ValueError, match="channel 'ax' has no direction"):
        Geometry.from_csv(tmp_path / "nodes.csv", tmp_path / "bad.csv")


def test_uff_15_and_82_with_a_channel_map(tmp_path, frame):
    pyuff = pytest.importorskip("pyuff")
    path = tmp_path / "geo.uff"
    uff = pyuff.UFF(str(path))
    n = frame.n_nodes
    uff.write_sets([pyuff.prepare_15(node_nums=frame.node_ids.tolist(), def_cs=[0] * n, disp_cs=[0] * n,
                                     color=[1] * n, x=frame.coordinates[:, 0].tolist(),
                                     y=frame.coordinates[:, 1].tolist(), z=frame.coordinates[:, 2].tolist()),
                    pyuff.prepare_82(trace_num=1, n_nodes=3, color=1, id="a", nodes=np.array([1, 11, 0])),
                    pyuff.prepare_82(trace_num=2, n_nodes=5, color=1, id="floor", nodes=np.array([11, 12, 14, 13, 11]))], "add")
    geo = Geometry.from_uff(path, {"ax": {"node": 11, "direction": "+x"}, "ay": {"node": 11, "direction": "y"},
                                   "bx": {"node": 14, "direction": [1, 0, 0]}})
    np.testing.assert_array_equal(geo.node_ids, frame.node_ids)
    np.testing.assert_allclose(geo.coordinates, frame.coordinates)
    assert geo.lines.tolist() == [[1, 11], [11, 12], [12, 14], [14, 13], [13, 11]]
    # the TOML format can name the UFF file for its nodes and lines
    toml = write(tmp_path, 'uff = "geo.uff"\n[[channels]]\nname = "ax"\nnode = 11\ndirection = "x"\n', "g2.toml")
    assert Geometry.from_toml(toml).n_nodes == n
    with pytest.raises(ValueError, match="channel 'ax': unknown node 5"):
        Geometry.from_uff(path, {"ax": {"node": 5, "direction": "+x"}})


def test_selected_modes_carry_the_covariance_of_their_representative_pole(chain):
    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2))
    sel = result.select_modes()
    assert sel.n_modes and sel.mode_covariance.shape == (sel.n_modes, 8, 8)
    c = sel.mode_covariance[:, 2:, 2:]
    np.testing.assert_allclose(np.sqrt(np.diagonal(c, axis1=1, axis2=2)[:, :3]).T, sel.mode_shape_std_real,
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.sqrt(np.diagonal(c, axis1=1, axis2=2)[:, 3:]).T, sel.mode_shape_std_imag,
                               rtol=1e-12, atol=1e-15)
    # the node covariance from it is that of the shape block: exact, the plots' envelope
    geo = Geometry.from_dict({"nodes": [[1, 0, 0, 0], [2, 1, 0, 0], [3, 2, 0, 0]],
                              "channels": [{"name": n, "node": i + 1, "direction": "z"}
                                           for i, n in enumerate(sel.output_names)]})
    from modaluq.geometry import mode_displacements

    d = mode_displacements(sel, 1, geo)
    assert d.exact
    np.testing.assert_allclose(d.covariance[:, 2, 2], np.diag(c[0])[:3], rtol=1e-12)


def test_from_file_takes_toml_only_and_without_uncertainty_there_is_no_covariance(tmp_path, chain):
    with pytest.raises(ValueError, match="expected a .toml file"):
        Geometry.from_file(tmp_path / "geo.uff")
    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2), uncertainty=False)
    sel = result.select_modes()
    assert sel.n_modes and sel.mode_covariance is None
