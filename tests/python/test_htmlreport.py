"""The interactive HTML report (modaluq.htmlreport, docs/shapes.md §3): one self-contained file
(plotly.js embedded once, no network), the diagram with ±σ and hover, the modes' table, MAC, the
modes on the geometry; a 30-channel, 100-order report stays under 10 MB; in headless Chromium it
opens without a script error, draws (the screenshot is not blank: the stable poles' green and the
3-D shapes' blue are on it) and has drawn its figures within 5 s of navigation."""

import re
import shutil
import subprocess

import numpy as np
import pytest

import modaluq

pytest.importorskip("plotly")

from modaluq.htmlreport import write_html_report  # noqa: E402

#: the report of a 30-channel, 100-order diagram stays under this (docs/shapes.md §3)
MAX_REPORT_BYTES = 10_000_000
#: drawn within this many seconds of navigation (performance.now() in the page)
MAX_RENDER_SECONDS = 5.0


def beam(l=30):
    x = np.linspace(0.0, 30.0, l)
    names = [f"z{i + 1:02d}" for i in range(l)]
    geo = modaluq.Geometry.from_dict({
        "name": f"{l}-sensor beam", "nodes": [[i + 1, float(v), 0.0, 0.0] for i, v in enumerate(x)],
        "lines": [[i + 1, i + 2] for i in range(l - 1)],
        "channels": [{"name": n, "node": i + 1, "direction": "z"} for i, n in enumerate(names)]})
    return x, names, geo


def beam_record(l=30, n=20_000, fs=50.0, seed=0):
    """Six lightly damped bending modes of a beam seen by ``l`` vertical sensors, with noise."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(seed)
    x, names, geo = beam(l)
    y = np.zeros((n, l))
    for k, (f, xi) in enumerate([(1.1, .01), (3.3, .01), (6.2, .012), (9.7, .01), (13.9, .015), (18.5, .01)], 1):
        w = 2 * np.pi * f
        r, th = np.exp(-xi * w / fs), w * np.sqrt(1 - xi * xi) / fs
        q = lfilter([1.0], [1, -2 * r * np.cos(th), r * r], rng.standard_normal(n))
        y += np.outer(q / q.std() / k, np.sin(k * np.pi * (x + 0.5) / 31))
    y += 0.05 * rng.standard_normal(y.shape)
    return y, fs, names, geo


@pytest.fixture(scope="module")
def big_report(tmp_path_factory):
    import warnings

    from modaluq.spectrum import output_spectrum_singular_values

    y, fs, names, geo = beam_record()
    a = modaluq.Analysis.from_arrays(y, fs=fs, output_names=names,
                                     settings=modaluq.Settings(block_rows=8, orders=tuple(range(2, 201, 2)),
                                                               keep_shape_factor=True))  # as --report
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", modaluq.ModalUQWarning)
        a.run()
    path = tmp_path_factory.mktemp("report") / "big.html"
    write_html_report(path, a.diagram, a.selected, geometry=geo, title="30-channel beam",
                      spectrum=output_spectrum_singular_values(a.preprocessed.y, fs),
                      run_description=a.describe_run(), warnings=a.warnings)
    return path, a


def test_report_is_self_contained_and_holds_what_it_says(big_report):
    path, a = big_report
    text = path.read_text(encoding="utf-8")
    assert len(a.diagram.orders) == 100 and a.diagram.n_outputs == 30 and a.selected.n_modes == 6
    # plotly.js embedded; no script, style or image loaded from elsewhere (the browser test opens it
    # with every host name unresolvable)
    assert "plotly.js v" in text and not re.search(r"<(script|link|img)[^>]+(src|href)=", text)
    # hover of every pole: f, ξ with σ, order and status; the table; the MAC; one figure per mode
    num = r"[^ ]+"  # a number, or a dash where σ is not known
    hover = re.compile(rf'"f {num} \\u00b1 {num} Hz\\u003cbr\\u003e\\u03be {num} \\u00b1 {num} %'
                       r'\\u003cbr\\u003eorder \d+, (stable|unstable|rejected|stable_frequency)')
    assert len(hover.findall(text)) == a.diagram.n_poles
    for k in range(a.selected.n_modes):
        assert f"<td>{a.selected.frequency_hz[k]:.5g}</td>" in text
        assert f"id='mode-{k + 1}-figure'" in text
    assert "MAC of the selected modes" in text and "±2σ ellipsoid axes" in text
    assert '"nticks":8' in text  # the longest axis of a 3-D shape (the short ones fewer, at least 3)
    mm = a.selected.mac_matrix()  # the MAC's hover: each entry ± its σ, exact (the shapes' factors kept)
    assert f'"{mm.mac[0, 1]:.4f} \\u00b1 {mm.std[0, 1]:.2g}"' in text
    assert not mm.independent_approximation and "with the shapes' cross-covariance" in text


def test_a_30_channel_100_order_report_stays_under_10_mb(big_report):
    path, _ = big_report
    size = path.stat().st_size
    print(f"report of 30 channels, 100 orders, 6 modes on the geometry: {size / 1e6:.2f} MB")
    assert size < MAX_REPORT_BYTES


def test_without_geometry_the_shapes_are_drawn_per_channel(tmp_path, chain):
    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2))
    d = result.stabilization_diagram()
    path = write_html_report(tmp_path / "r.html", d, d.select_modes())
    assert "no geometry given" in path.read_text(encoding="utf-8")


def test_the_table_shows_mpc_and_mpd_with_their_sigma(tmp_path, chain):
    import dataclasses

    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2))
    d = result.stabilization_diagram()
    sel = d.select_modes()
    text = write_html_report(tmp_path / "a.html", d, sel).read_text(encoding="utf-8")
    assert "<th>MPC ± σ</th>" in text and "<th>MPD [°] ± σ</th>" in text
    assert f"<td>{sel.mpc[0]:.3g} ± {sel.mpc_std[0]:.2g}</td>" in text
    # unknown indicators (NaN): no column
    blank = dataclasses.replace(sel, mpc=np.full(sel.n_modes, np.nan), mpd_deg=np.full(sel.n_modes, np.nan))
    text = write_html_report(tmp_path / "b.html", d, blank).read_text(encoding="utf-8")
    assert "MPC ± σ" not in text and "MPD [°] ± σ" not in text


def test_the_table_gives_the_shape_order_where_it_is_not_the_representatives(tmp_path, chain):
    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2))
    d = result.stabilization_diagram()
    sel = d.select_modes()  # the default: shapes at the lowest sufficient order
    k = int(np.flatnonzero(sel.shape_order != sel.representative_order)[0])
    text = write_html_report(tmp_path / "a.html", d, sel).read_text(encoding="utf-8")
    assert "<th>shape order</th>" in text
    row = (f"<td>{int(sel.representative_order[k])}</td><td>{int(sel.n_poles[k])}</td>"
           f"<td>{int(sel.shape_order[k])}</td>")
    assert row in text
    at_rep = d.select_modes(shape_representative="median")
    assert "shape order" not in write_html_report(tmp_path / "b.html", d, at_rep).read_text(encoding="utf-8")


def test_the_table_marks_a_mode_whose_sigma_the_model_order_widened(tmp_path):
    # the chain record of test_stabilization_core.py whose 14.5 Hz mode moves with the order
    sim = modaluq.simulate(20_000, seed=7170)
    d = modaluq.identify(sim.y, fs=sim.fs, frequency_range=(1, 20)).stabilization_diagram()
    sel = d.select_modes()
    assert sel.order_discrepancy.any()
    text = write_html_report(tmp_path / "a.html", d, sel).read_text(encoding="utf-8")
    assert text.count("<td>widened</td>") + text.count("<td>noise? widened</td>") == sel.order_discrepancy.sum()
    assert "widened: f or ξ at the representative" in text
    off = d.select_modes(order_discrepancy=False)
    assert "<td>widened</td>" not in write_html_report(tmp_path / "b.html", d, off).read_text(encoding="utf-8")


def test_refusals(tmp_path, chain):
    result = modaluq.identify(chain.y, fs=chain.fs, block_rows=15, orders=range(2, 31, 2))
    d = result.stabilization_diagram()
    sel = d.select_modes()
    with pytest.raises(ValueError, match="r.txt.*an .html file"):
        write_html_report(tmp_path / "r.txt", d, sel)
    _, _, geo = beam(3)
    with pytest.raises(ValueError, match="'y0' is not a channel of the geometry"):
        write_html_report(tmp_path / "r.html", d, sel, geometry=geo)
    assert not (tmp_path / "r.html").exists()


# --------------------------------------------------------------------------- in a real browser
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium; scripts/setup.sh --test does)")
#: headless, no GPU: WebGL (the 3-D shapes) by SwiftShader, which Chromium asks to be allowed
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--hide-scrollbars",
         "--no-first-run", "--disable-extensions"]


def chromium(*args, timeout=120):
    return subprocess.run([CHROMIUM, *FLAGS, *args], capture_output=True, text=True, timeout=timeout)


@needs_chromium
def test_the_report_opens_without_script_errors_and_draws_in_time(big_report):
    path, a = big_report
    # offline: every host name unresolvable
    out = chromium("--enable-logging=stderr", "--v=0", "--window-size=1200,2000", "--virtual-time-budget=30000",
                   "--host-resolver-rules=MAP * ~NOTFOUND", "--dump-dom", path.as_uri())
    errors = [ln for ln in out.stderr.splitlines() if "Uncaught" in ln or ("CONSOLE" in ln and "Error" in ln)]
    assert not errors, errors
    m = re.search(r'data-rendered="(\d+)" data-rendered-ms="(\d+)"', out.stdout)
    assert m, "the report's figures did not report being drawn"
    drawn, ms = int(m.group(1)), int(m.group(2))
    print(f"{drawn} figures drawn {ms / 1000:.2f} s after navigation")
    assert drawn >= 3  # the diagram, the MAC and at least the first mode in view
    assert ms / 1000 < MAX_RENDER_SECONDS


@needs_chromium
def test_the_screenshot_shows_the_diagram_and_the_3d_shape(big_report, tmp_path):
    from PIL import Image

    path, _ = big_report
    shot = tmp_path / "shot.png"
    chromium(f"--screenshot={shot}", "--window-size=1200,2600", "--virtual-time-budget=30000", path.as_uri())
    img = np.asarray(Image.open(shot).convert("RGB")).astype(float)
    assert img.shape[:2] == (2600, 1200)
    assert img.std() > 20  # not blank: a blank page has std 0

    def near(colour, region, tol=40):
        rgb = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)], float)
        return int(np.sum(np.all(np.abs(region - rgb) < tol, axis=-1)))

    top, bottom = img[:1300], img[1300:]
    assert near("#2ca02c", top) > 500, "no stable poles (green) drawn in the diagram"
    assert near("#1f77b4", bottom) > 200, "no deformed shape (blue) drawn by the 3-D scene (WebGL)"

