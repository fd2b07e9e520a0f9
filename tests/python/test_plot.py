"""Plots: the stabilization diagram draws ±σ_f bars at every pole over the output spectrum; the
mode-shape plot draws ±σ bars on the shape components. Checked on the drawn artists."""

import types

import numpy as np
import pytest

import modaluq
from modaluq import PoleStatus
from modaluq.indicators import mac_matrix
from modaluq.spectrum import output_spectrum_singular_values

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from modaluq.plot import STATUS_STYLE, plot_mac, plot_mode_shapes, plot_stabilization_diagram  # noqa: E402


@pytest.fixture(scope="module")
def small_chain():
    sim = modaluq.simulate(20_000, seed=2)
    result = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=15, orders=range(2, 31, 2))
    diagram = modaluq.stabilization_diagram(result, output_names=["m1", "m2", "m5"])
    return sim, diagram, diagram.select_modes()


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _container(ax, status):
    label = STATUS_STYLE[status.value][-1]
    found = [c for c in ax.containers if c.get_label().startswith(label + " (")]
    return found[0] if found else None


def test_diagram_error_bars_are_plus_minus_one_sigma(small_chain):
    sim, d, sel = small_chain
    fig = d.plot(y=sim.y, selected=sel)
    ax = fig.axes[0]
    for status in (PoleStatus.STABLE, PoleStatus.STABLE_FREQUENCY, PoleStatus.UNSTABLE):
        mask = d.is_status(status)
        c = _container(ax, status)
        if not mask.any():
            assert c is None
            continue
        assert c.get_label().endswith(f"({mask.sum()})")
        line, _, (bars,) = c.lines[0], c.lines[1], c.lines[2]
        np.testing.assert_array_equal(line.get_xdata(), d.frequency_hz[mask])
        np.testing.assert_array_equal(line.get_ydata(), d.order[mask])
        seg = np.array(bars.get_segments())          # (n, 2 points, xy)
        half = np.where(d.noise_coupled[mask], 0.0, d.frequency_std[mask])  # no first-order σ: no bar
        np.testing.assert_allclose(seg[:, 0, 0], d.frequency_hz[mask] - half, rtol=1e-12)
        np.testing.assert_allclose(seg[:, 1, 0], d.frequency_hz[mask] + half, rtol=1e-12)
        np.testing.assert_array_equal(seg[:, 0, 1], d.order[mask])
    # rejected poles are drawn, without bars
    c = _container(ax, PoleStatus.REJECTED)
    assert c is not None and c.has_xerr is False
    # one dotted vertical line per selected mode
    dotted = [ln for ln in ax.lines if ln.get_linestyle() == ":"]
    np.testing.assert_allclose(sorted(ln.get_xdata()[0] for ln in dotted), sel.frequency_hz)
    assert ax.get_xlim() == (0.0, sim.fs / 2)


def test_diagram_spectrum_axis_is_logarithmic_and_sums_to_the_auto_spectra(small_chain):
    import scipy.signal

    sim, d, _ = small_chain
    fig = d.plot(y=sim.y, nperseg=512)
    assert len(fig.axes) == 2
    spec = fig.axes[1]
    assert spec.get_yscale() == "log"
    assert len(spec.lines) == 3  # one curve per singular value (3 outputs)
    # the PSD matrix is Hermitian positive semidefinite: its singular values sum to its trace,
    # the sum of the auto spectra (independent Welch estimates of each channel)
    _, sv = output_spectrum_singular_values(sim.y, sim.fs, nperseg=512)
    f, pxx = scipy.signal.welch(sim.y - sim.y.mean(axis=0), fs=sim.fs, nperseg=512, axis=0)
    np.testing.assert_allclose(sv.sum(axis=1), pxx.sum(axis=1), rtol=1e-9)
    drawn = np.sum([ln.get_ydata() for ln in spec.lines], axis=0)
    np.testing.assert_allclose(drawn, pxx[1:].sum(axis=1), rtol=1e-9)


def test_diagram_options(small_chain):
    sim, d, _ = small_chain
    fig, ax = plt.subplots()
    assert d.plot(ax=ax, show_rejected=False, frequency_range=(1, 10)) is fig
    assert len(fig.axes) == 1                       # no spectrum without y
    assert _container(ax, PoleStatus.REJECTED) is None
    assert ax.get_xlim() == (1.0, 10.0)
    with pytest.raises(TypeError, match="diagram"):
        plot_stabilization_diagram(sim)


def test_mode_shape_bars_and_error_bars(small_chain):
    sim, _, sel = small_chain
    fig = sel.plot()
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == sel.n_modes
    for k, ax in enumerate(visible):
        from matplotlib.container import BarContainer

        real_bars, imag_bars = [c for c in ax.containers if isinstance(c, BarContainer)]
        np.testing.assert_allclose([p.get_height() for p in real_bars.patches], sel.mode_shape[:, k].real)
        np.testing.assert_allclose([p.get_height() for p in imag_bars.patches], sel.mode_shape[:, k].imag)
        seg = np.array(real_bars.errorbar.lines[2][0].get_segments())
        np.testing.assert_allclose(seg[:, 1, 1] - seg[:, 0, 1], 2 * sel.mode_shape_std_real[:, k], rtol=1e-9,
                                   atol=1e-15)
        assert [t.get_text() for t in ax.get_xticklabels()] == ["m1", "m2", "m5"]
    # also works on the Modes of one order (no output names, same σ fields)
    modes = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=15, orders=12).at_order(12)
    fig2 = plot_mode_shapes(modes)
    assert sum(ax.get_visible() for ax in fig2.axes) == modes.n_modes
    assert [t.get_text() for t in fig2.axes[0].get_xticklabels()] == ["y0", "y1", "y2"]


def test_png_written_and_readable(small_chain, tmp_path):
    sim, d, sel = small_chain
    path = tmp_path / "diagram.png"
    d.plot(y=sim.y, selected=sel).savefig(path, dpi=60)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = plt.imread(path)
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100


def test_result_plot_draws_the_diagram_with_selected_modes(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import modaluq

    sim = modaluq.simulate(20_000, seed=4)
    res = modaluq.identify(sim.y, fs=sim.fs, block_rows=20, orders=range(2, 31, 2), n_blocks=20)
    diagram = res.stabilization_diagram()
    assert diagram.n_poles == sum(m.n_modes for m in res)
    fig = res.plot(y=sim.y)
    out = tmp_path / "d.png"
    fig.savefig(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # One error bar per pole with a finite sigma, as drawn by Diagram.plot on the same diagram.
    ref = diagram.plot(y=sim.y, selected=res.select_modes())
    assert len(fig.axes[0].lines) == len(ref.axes[0].lines)
    assert len(fig.axes[0].collections) == len(ref.axes[0].collections)


# --------------------------------------------------------------------------- issue #13: no pyplot state


def test_plots_do_not_pile_up_in_pyplot(small_chain, tmp_path):
    sim, d, sel = small_chain
    plt.close("all")
    result = modaluq.identify(sim.y[:5000], fs=sim.fs, block_rows=8, orders=range(2, 13, 2), n_blocks=10)
    before = plt.get_fignums()
    for _ in range(5):
        figs = [d.plot(), sel.plot(), plot_stabilization_diagram(d), plot_mode_shapes(sel), result.plot(),
                result.select_modes().plot()]
    assert plt.get_fignums() == before == []
    # still ordinary figures: they save, and a given Axes is drawn into (pyplot's, if the caller wants a window)
    figs[0].savefig(tmp_path / "d.png", dpi=40)
    assert (tmp_path / "d.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    fig, ax = plt.subplots()
    assert d.plot(ax=ax) is fig and plt.get_fignums() == [fig.number]


def test_figures_display_in_jupyter_with_and_without_the_inline_backend(small_chain):
    pytest.importorskip("IPython")
    import base64

    from IPython.core.formatters import DisplayFormatter

    _, d, sel = small_chain
    for fig in (d.plot(), sel.plot()):
        # a kernel where pyplot was never imported: no figure formatter is registered
        data, _ = DisplayFormatter().format(fig)
        assert data["image/png"][:8] == b"\x89PNG\r\n\x1a\n"
    # with the inline backend's formatter (what `%matplotlib inline` registers)
    from IPython.core.interactiveshell import InteractiveShell
    from IPython.core.pylabtools import select_figure_formats

    shell = InteractiveShell.instance()
    select_figure_formats(shell, {"png"})
    png = shell.display_formatter.format(d.plot())[0]["image/png"]
    png = base64.b64decode(png) if isinstance(png, str) else png   # base64 text in recent IPython
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_switches_must_be_booleans(small_chain):
    _, d, sel = small_chain
    with pytest.raises(TypeError, match="show_rejected must be True or False; got 'no'"):
        d.plot(show_rejected="no")
    with pytest.raises(TypeError, match="ncols must be an integer"):
        plot_mode_shapes(sel, ncols=2.0)


def test_noise_coupled_poles_are_ringed_without_a_bar():
    """Orders far above the true one have spurious poles whose σ is not first-order (docs/uq-math.md §5.5)."""
    sim = modaluq.simulate(100_000, seed=1)  # the tutorial's record and settings
    result = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=25, orders=range(2, 61, 2))
    d = modaluq.stabilization_diagram(result)
    shown = d.noise_coupled & ~d.is_status(PoleStatus.REJECTED)
    assert shown.any()
    ax = d.plot().axes[0]
    rings = [ln for ln in ax.lines if ln.get_label().startswith("noise-coupled")]
    assert len(rings) == 1 and rings[0].get_label().endswith(f"({shown.sum()})")
    np.testing.assert_array_equal(rings[0].get_xdata(), d.frequency_hz[shown])
    np.testing.assert_array_equal(rings[0].get_ydata(), d.order[shown])
    for status in (PoleStatus.STABLE, PoleStatus.STABLE_FREQUENCY, PoleStatus.UNSTABLE):
        c = _container(ax, status)
        if c is None:
            continue
        mask = d.is_status(status)
        widths = np.ptp(np.array(c.lines[2][0].get_segments())[:, :, 0], axis=1)
        assert np.all(widths[d.noise_coupled[mask]] == 0)


def test_many_channels_get_horizontal_bars_with_one_readable_label_each():
    from types import SimpleNamespace

    n_out = 19
    names = tuple(f"sta{k:02d}|Up|Deck: Middle of North Span" for k in range(n_out))
    rng = np.random.default_rng(0)
    shape = rng.standard_normal((n_out, 2)) + 0.01j * rng.standard_normal((n_out, 2))
    modes = SimpleNamespace(mode_shape=shape / np.abs(shape).max(axis=0), frequency_hz=np.array([3.1, 4.5]),
                            damping_ratio=np.array([0.02, 0.01]), output_names=names,
                            mode_shape_std_real=np.full((n_out, 2), 0.02), mode_shape_std_imag=np.full((n_out, 2), 0.01))
    fig = plot_mode_shapes(modes)
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_yticklabels()] == list(names)   # one label per channel, on the y axis
    assert ax.get_xlim() == (-1.15, 1.15)
    width, height = fig.get_size_inches()
    assert height >= 0.19 * n_out                                          # rows do not overlap
    bars = [p for p in ax.patches]
    assert len(bars) == 2 * n_out


def test_selected_modes_get_a_visible_sigma_band_and_pole_bars_have_caps():
    """σ_f of the chain's modes is far below a pixel on a 1-20 Hz axis: each selected mode gets a
    shaded ±σ band at least MIN_BAND_FRACTION of the axis wide, centred on the mode."""
    import matplotlib.patches as mpatches

    from modaluq.plot import MIN_BAND_FRACTION

    sim = modaluq.simulate(30_000, seed=2)
    result = modaluq.identify(sim.y, sim.u, fs=sim.fs, frequency_range=(1, 20))
    diagram = result.stabilization_diagram()
    sel = diagram.select_modes()
    fig = diagram.plot(selected=sel)
    ax = fig.axes[0]
    bands = [p for p in ax.patches if isinstance(p, mpatches.Polygon) or isinstance(p, mpatches.Rectangle)]
    spans = []
    for p in bands:
        x = p.get_xy()[:, 0] if isinstance(p, mpatches.Polygon) else np.array([p.get_x(), p.get_x() + p.get_width()])
        spans.append((float(x.min()), float(x.max())))
    assert len(spans) >= sel.n_modes
    for f, s in zip(sel.frequency_hz, sel.frequency_std):
        lo, hi = min(spans, key=lambda sp: abs(0.5 * (sp[0] + sp[1]) - f))
        assert abs(0.5 * (lo + hi) - f) < 1e-9
        assert hi - lo >= max(2 * s, MIN_BAND_FRACTION * 19.0) - 1e-12


def test_automac_draws_each_mac_with_its_sigma(small_chain):
    _, _, sel = small_chain
    fig = sel.plot_mac()
    ax = fig.axes[0]
    mm = sel.mac_matrix()
    m = sel.n_modes
    np.testing.assert_allclose(ax.images[0].get_array(), mm.mac)
    texts = {(round(t.get_position()[1]), round(t.get_position()[0])): t.get_text() for t in ax.texts}
    assert len(texts) == m * m
    assert texts[(0, 0)] == "1.000"
    assert texts[(0, 1)] == f"{mm.mac[0, 1]:.3f}\n±{mm.std[0, 1]:.2g}" and texts[(1, 0)] == texts[(0, 1)]
    assert "shapes taken as independent" in ax.get_title()
    assert [t.get_text() for t in ax.get_xticklabels()][0] == f"1\n{sel.frequency_hz[0]:.3g} Hz"
    # without covariances: the MAC alone, said
    # more modes than fit a σ in a cell: values only, said
    many = np.arange(9) % sel.n_modes
    wide = types.SimpleNamespace(mode_shape=sel.mode_shape[:, many], frequency_hz=sel.frequency_hz[many],
                                 mode_covariance=sel.mode_covariance[many])
    ax = plot_mac(wide).axes[0]
    assert "values only" in ax.get_title() and not any("±" in t.get_text() for t in ax.texts)
    bare = types.SimpleNamespace(mode_shape=sel.mode_shape, frequency_hz=sel.frequency_hz)
    ax = plot_mac(bare).axes[0]
    assert "no σ" in ax.get_title() and not any("±" in t.get_text() for t in ax.texts)
    # with the shapes' factors (keep_shape_factor=True): the exact σ, said
    def factor(c):  # any V with V Vᵀ = the shape covariance
        w, q = np.linalg.eigh(c[2:, 2:])
        return q * np.sqrt(np.clip(w, 0, None))

    factors = np.stack([factor(c) for c in sel.mode_covariance])
    exact = types.SimpleNamespace(mode_shape=sel.mode_shape, frequency_hz=sel.frequency_hz,
                                  mode_covariance=sel.mode_covariance, mode_shape_factor=factors)
    ax = plot_mac(exact).axes[0]
    assert "with the shapes' cross-covariance" in ax.get_title()
    mm = mac_matrix(sel.mode_shape, factors=factors)
    assert any(t.get_text() == f"{mm.mac[0, 1]:.3f}\n±{mm.std[0, 1]:.2g}" for t in ax.texts)
