"""Mode shapes on the structure (modaluq.shapes): the drawn envelope is ±2σ of the node
displacement at the drawn phase, the deformed lines are the shape at the peak phase, complex
modes are coloured by phase, and the animation writes a GIF of one cycle."""

import math
import types

import numpy as np
import pytest

from modaluq.geometry import Geometry

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")

from modaluq import shapes  # noqa: E402


@pytest.fixture
def beam():
    # a cantilever of 4 nodes along x, sensors along z at nodes 2..4, node 1 clamped
    geo = Geometry.from_dict({
        "name": "beam",
        "nodes": [[i, float(i - 1), 0.0, 0.0] for i in range(1, 5)],
        "lines": [[1, 2], [2, 3], [3, 4]],
        "channels": [{"name": f"z{i}", "node": i, "direction": "z"} for i in (2, 3, 4)]})
    phi = np.array([[0.3 + 0.2j, 0.7 - 0.05j, 1.0]]).T
    cov = np.diag([0.02, 0.03, 0.0, 0.01, 0.01, 0.0]) ** 2
    modes = types.SimpleNamespace(frequency_hz=np.array([2.0]), damping_ratio=np.array([0.01]),
                                  frequency_std=np.array([0.01]), damping_std=np.array([0.002]),
                                  mode_shape=phi, output_names=("z2", "z3", "z4"),
                                  mode_shape_covariance=cov[None])
    return geo, modes


def test_peak_phase_maximises_the_motion():
    rng = np.random.default_rng(1)
    u = rng.standard_normal((5, 3)) + 1j * rng.standard_normal((5, 3))
    a = shapes.peak_phase(u)
    grid = np.linspace(0, np.pi, 2001)
    norms = [np.linalg.norm((u * np.exp(1j * g)).real) for g in grid]
    assert np.linalg.norm((u * np.exp(1j * a)).real) >= max(norms) - 1e-9
    assert shapes.peak_phase(np.array([[1.0, -2.0, 0.5]]) + 0j) == 0.0


def test_node_phases_fold_antiphase_to_zero_and_show_lag():
    u = np.array([[0, 0, 1.0], [0, 0, -0.5], [0, 0, 1j], [0, 0, 0]])
    ph = shapes.node_phases(u)
    np.testing.assert_allclose(np.abs(ph[:3]), [0, 0, 90], atol=1e-9)  # ±90°: the same motion
    assert np.isnan(ph[3])


def test_static_plot_draws_the_shape_and_its_two_sigma_envelope(beam):
    geo, modes = beam
    fig = shapes.plot_shape(modes, 1, geo)
    ax = fig.axes[0]
    disp = geo.displacements(modes.mode_shape[:, 0], modes.output_names, covariance=modes.mode_shape_covariance[0])
    alpha = shapes.peak_phase(disp.value)
    factor = shapes.DISPLAY_FRACTION * geo.size / np.max(np.linalg.norm(np.abs(disp.value), axis=1))
    cols = [c for c in ax.collections if hasattr(c, "_segments3d")]
    deformed = next(c for c in cols if matplotlib.colors.same_color(c.get_color()[0], "tab:blue"))
    envelope = next(c for c in cols if matplotlib.colors.same_color(c.get_color()[0][:3], "tab:red"))
    moved = geo.coordinates + factor * disp.at_phase(alpha)
    np.testing.assert_allclose(np.asarray(deformed._segments3d)[:, 1], moved[1:], atol=1e-12)
    # one segment per moving node with σ > 0 (node 4 is the reference, σ = 0): ±2σ along z
    segs = np.asarray(envelope._segments3d)
    cov = disp.covariance_at(alpha)
    half = 0.5 * np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    np.testing.assert_allclose(half, factor * 2 * np.sqrt(cov[[1, 2], 2, 2]), rtol=1e-10)
    assert "±2σ: shape covariance" in fig.get_suptitle() and "mode 1: 2 ± 0.01 Hz" in fig.get_suptitle()
    # the phase lag of the complex shape is in the title (node 2 lags by ~34°)
    lag = abs(math.degrees(np.angle(0.3 + 0.2j)))
    assert f"largest phase lag {lag:.0f}°" in fig.get_suptitle()


def test_without_covariance_the_channel_sigma_is_used_and_said(beam):
    geo, modes = beam
    m = types.SimpleNamespace(**{**vars(modes), "mode_shape_covariance": None,
                                 "mode_shape_std_real": np.array([[0.02], [0.03], [0.0]]),
                                 "mode_shape_std_imag": np.array([[0.01], [0.01], [0.0]])})
    fig = shapes.plot_shape(m, 1, geo)
    assert "correlations neglected" in fig.get_suptitle()


def test_bad_mode_and_names_are_refused(beam):
    geo, modes = beam
    with pytest.raises(ValueError, match="mode must be <= 1"):
        shapes.plot_shape(modes, 2, geo)
    m = types.SimpleNamespace(**{**vars(modes), "output_names": ("z2", "z3", "q")})
    with pytest.raises(ValueError, match="'q' is not a channel of the geometry"):
        shapes.plot_shape(m, 1, geo)


def test_animation_writes_a_gif_of_one_cycle(beam, tmp_path):
    pil = pytest.importorskip("PIL.Image")
    geo, modes = beam
    path = tmp_path / "m.gif"
    anim = shapes.animate_shape(modes, 1, geo, path=path, frames=8)
    with pil.open(path) as im:
        assert im.n_frames == 8
    # the envelope's true size in the title, the number of the static figure's legend (tested below)
    legend = next(t.get_text() for t in shapes.plot_shape(modes, 1, geo).legends[0].get_texts() if "ellipsoid" in t.get_text())
    assert anim._fig.get_suptitle().endswith("\n±2σ " + legend.split("\n")[1])
    assert [p.name for p in tmp_path.iterdir()] == ["m.gif"]  # no temporary left
    with pytest.raises(ValueError, match="as .gif or .mp4"):
        shapes.animate_shape(modes, 1, geo, path=tmp_path / "m.avi")


def test_mp4_without_ffmpeg_is_refused_by_name(beam, tmp_path, monkeypatch):
    from matplotlib.animation import writers

    geo, modes = beam
    monkeypatch.setattr(writers, "is_available", lambda name: False)
    with pytest.raises(ValueError, match="m.mp4.*needs ffmpeg"):
        shapes.animate_shape(modes, 1, geo, path=tmp_path / "m.mp4")


def test_selected_modes_methods(chain, tmp_path):
    import modaluq

    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2),
                              output_names=["a", "b", "c"])
    sel = result.select_modes()
    geo = Geometry.from_dict({"nodes": [[1, 0, 0, 0], [2, 1, 0, 0], [3, 2, 0, 0], [4, 3, 0, 0]],
                              "lines": [[1, 2], [2, 3], [3, 4]],
                              "channels": [{"name": n, "node": i + 2, "direction": "y"}
                                           for i, n in enumerate("abc")]})
    fig = sel.plot_shape(1, geometry=geo)
    assert "shape covariance" in fig.get_suptitle()
    sel.animate(1, geometry=geo, path=tmp_path / "a.gif", frames=4)
    assert (tmp_path / "a.gif").stat().st_size > 0


def test_result_methods_draw_the_selected_mode_or_a_pole_of_an_order(chain, tmp_path):
    import modaluq
    from modaluq.geometry import mode_displacements

    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2),
                              output_names=["a", "b", "c"])
    geo = Geometry.from_dict({"nodes": [[1, 0, 0, 0], [2, 1, 0, 0], [3, 2, 0, 0], [4, 3, 0, 0]],
                              "lines": [[1, 2], [2, 3], [3, 4]],
                              "channels": [{"name": n, "node": i + 2, "direction": "y"}
                                           for i, n in enumerate("abc")]})
    sel = result.select_modes()
    # by default the selected modes, numbered as print(result) and the tables number them
    fig = result.plot_shape(2, geo)
    title = fig.get_suptitle()
    assert title.startswith(f"mode 2: {sel.frequency_hz[1]:.4g} ± ") and "shape covariance" in title
    cols = [c for c in fig.axes[0].collections if hasattr(c, "_segments3d")]
    deformed = next(c for c in cols if matplotlib.colors.same_color(c.get_color()[0], "tab:blue"))
    disp = mode_displacements(sel, 2, geo)  # the deformed lines are the selected mode's shape
    factor = shapes._scale(geo, disp.value, None)
    want = geo.coordinates + factor * disp.at_phase(shapes.peak_phase(disp.value))
    np.testing.assert_allclose(np.asarray(deformed._segments3d)[:, 1], want[1:], atol=1e-12)
    # order=: a pole of that order, numbered as print(result.at_order(n)), with its own covariance
    m = result.at_order(12)
    fig = result.plot_shape(3, geo, order=12)
    title = fig.get_suptitle()
    assert title.startswith(f"order 12, mode 3: {m.frequency_hz[2]:.4g} ± ") and "shape covariance" in title
    src, k = result._shape_source(3, 12, None, None)
    d = mode_displacements(src, k, geo)
    np.testing.assert_allclose(d.value[1:, 1], m.mode_shape[:, 2])
    np.testing.assert_allclose(d.covariance[1:, 1, 1], m.mode_shape_std_real[:, 2] ** 2, rtol=1e-12, atol=1e-300)
    anim = result.animate(1, geo, path=tmp_path / "r.gif", frames=4, order=12)
    assert (tmp_path / "r.gif").stat().st_size > 0 and anim is not None
    with pytest.raises(ValueError, match="order 13 was not identified"):
        result.plot_shape(1, geo, order=13)
    with pytest.raises(ValueError, match="mode"):
        result.plot_shape(m.n_modes + 1, geo, order=12)
    with pytest.raises(ValueError, match="criteria and settings"):
        result.plot_shape(1, geo, order=12, criteria=modaluq.StabilityCriteria())


def test_legend_gives_the_true_size_of_the_envelope(beam):
    geo, modes = beam
    fig = shapes.plot_shape(modes, 1, geo, magnify_envelope=10)
    disp = geo.displacements(modes.mode_shape[:, 0], modes.output_names, covariance=modes.mode_shape_covariance[0])
    cov = disp.covariance_at(shapes.peak_phase(disp.value))
    top = max(np.linalg.eigvalsh(c)[-1] for c in cov[disp.moving])
    peak = np.max(np.linalg.norm(np.abs(disp.value), axis=1))
    label = next(t.get_text() for t in fig.legends[0].get_texts() if "ellipsoid" in t.get_text())
    assert label == f"±2σ ellipsoid axes (σ × 10)\n(true size up to {100 * 2 * np.sqrt(top) / peak:.2g} % of the largest motion)"


def test_without_uncertainty_there_is_no_envelope_and_the_title_says_so(chain):
    import modaluq

    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2),
                              output_names=["a", "b", "c"], uncertainty=False)
    geo = Geometry.from_dict({"nodes": [[1, 0, 0, 0], [2, 1, 0, 0], [3, 2, 0, 0], [4, 3, 0, 0]],
                              "lines": [[1, 2], [2, 3], [3, 4]],
                              "channels": [{"name": n, "node": i + 2, "direction": "y"}
                                           for i, n in enumerate("abc")]})
    for fig in (result.plot_shape(1, geo), result.plot_shape(1, geo, order=12)):
        assert "no σ" in fig.get_suptitle()  # the selected modes' std are NaN: not a σ
        assert not any("ellipsoid" in t.get_text() for t in fig.legends[0].get_texts())


def test_largest_std_is_the_longest_principal_sigma_at_the_phase(beam):
    geo, modes = beam  # σ(Re) = 0.02, 0.03, 0 and σ(Im) = 0.01, 0.01, 0 along z at nodes 2, 3, 4
    disp = geo.displacements(modes.mode_shape[:, 0], modes.output_names, covariance=modes.mode_shape_covariance[0])
    assert disp.largest_std(0.0) == pytest.approx(0.03, rel=1e-12)
    assert disp.largest_std(math.pi / 2) == pytest.approx(0.01, rel=1e-12)
    assert disp.largest_std(math.pi / 4) == pytest.approx(math.sqrt(0.5 * 0.03**2 + 0.5 * 0.01**2), rel=1e-12)
    assert math.isnan(geo.displacements(modes.mode_shape[:, 0], modes.output_names).largest_std(0.0))


def test_default_figure_follows_the_structure_and_thin_sides_carry_their_range_in_the_label(beam):
    # a deck 40 m long and 1 m wide, a tower 40 m high: wide and tall figures; the deck's width is
    # too short in the drawing for tick labels, so the axis label gives its range
    geo, modes = beam
    nodes = geo.coordinates
    deck = Geometry.from_dict({"nodes": [[i + 1, 10 * x, y, z] for i, (x, y, z) in enumerate(nodes)],
                               "lines": [[1, 2], [2, 3], [3, 4]],
                               "channels": [{"name": n, "node": i + 2, "direction": "z"}
                                            for i, n in enumerate(modes.output_names)]})
    tower = Geometry.from_dict({"nodes": [[i + 1, 0.0, 0.0, 10 * x] for i, (x, y, z) in enumerate(nodes)],
                                "lines": [[1, 2], [2, 3], [3, 4]],
                                "channels": [{"name": n, "node": i + 2, "direction": "x"}
                                             for i, n in enumerate(modes.output_names)]})
    wide, tall = shapes.plot_shape(modes, 1, deck), shapes.plot_shape(modes, 1, tower)
    assert tuple(wide.get_size_inches()) == (9.6, 5.6) and tuple(tall.get_size_inches()) == (5.6, 7.6)
    assert tuple(shapes.plot_shape(modes, 1, deck, figsize=(5, 4)).get_size_inches()) == (5, 4)
    ax = wide.axes[0]
    assert ax.get_ylabel().startswith("y [m] (") and not any(t.get_text() for t in ax.yaxis.get_ticklabels())
    assert ax.get_xlabel() == "x [m]"
