"""One self-contained interactive HTML report of an identification (docs/shapes.md §3).

:func:`write_html_report` writes a single HTML file that opens offline (Plotly's JavaScript is
embedded once, no network at view time):

- the run (file, settings, warnings) and the selected modes' table with σ and spread;
- the stabilization diagram: every pole at (f, order), coloured by status, ±σ_f error bars,
  hover with f, ξ, their σ, the order, status, reason and flags (noise-coupled, close singular
  values); zoomable; the spectrum's singular values behind when the samples are given;
- the MAC matrix of the selected modes (hover: each MAC ± its σ);
- each mode animated on the geometry in 3-D (rotatable; Plotly frames over one cycle, play and a
  phase slider) with the ±2σ ellipsoid axes of every node, or, without a geometry, the shape per
  channel with ±σ bars.

Plotly (extra ``report``) is imported when a report is written.
"""

from __future__ import annotations

import html
import math
import os
from pathlib import Path

import numpy as np

from .atomic import write_atomically
from .checks import require
from .geometry import mode_displacements
from .indicators import mac_matrix
from .settings import PoleStatus
from .version import __version__

__all__ = ["write_html_report"]

#: colour of each pole status (as the matplotlib diagram's STATUS_STYLE)
STATUS_COLOUR = {"stable": "#2ca02c", "stable_frequency": "#1f77b4", "unstable": "#ff7f0e", "rejected": "#a6a6a6"}
STATUS_SYMBOL = {"stable": "circle", "stable_frequency": "triangle-down-open", "unstable": "x-thin-open",
                 "rejected": "circle"}
#: phases per cycle of the 3-D animation
ANIMATION_FRAMES = 16
#: tick marks on the longest axis of a 3-D mode figure (the others in proportion to their length)
MAX_TICKS_3D = 8
#: largest node motion drawn, fraction of the structure's size
DISPLAY_FRACTION = 0.15


def _fmt(x, digits=4):
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def _diagram_figure(go, diagram, selected, spectrum):
    fig = go.Figure()
    has_std = bool(diagram.has_uncertainty)
    if spectrum is not None:
        freq, sv = spectrum
        sv = np.asarray(sv)
        sv = sv[:, None] if sv.ndim == 1 else sv
        for k in range(min(sv.shape[1], 3)):
            fig.add_trace(go.Scatter(x=freq[1:], y=sv[1:, k], yaxis="y2", mode="lines", hoverinfo="skip",
                                     line={"color": "#404040" if k == 0 else "#999999", "width": 1 if k == 0 else 0.7},
                                     name="singular values of the PSD" if k == 0 else f"s{k + 1}",
                                     showlegend=k == 0, legendgroup="spectrum"))
    for status in PoleStatus:
        mask = np.asarray(diagram.is_status(status), bool)
        if not mask.any():
            continue
        idx = np.nonzero(mask)[0]
        f, n = diagram.frequency_hz[idx], diagram.order[idx]
        sf, xi, sx = diagram.frequency_std[idx], diagram.damping_ratio[idx], diagram.damping_std[idx]
        coupled = np.asarray(diagram.noise_coupled, bool)[idx]
        close = np.asarray(diagram.close_singular_values, bool)[idx]
        reasons = np.asarray(diagram.reason)[idx]
        text = []
        for j in range(idx.size):
            flags = [s for s, on in (("noise-coupled: no first-order σ", coupled[j]),
                                     ("order cuts close singular values", close[j])) if on]
            text.append(f"f {f[j]:.5g} ± {_fmt(sf[j], 2)} Hz<br>ξ {100 * xi[j]:.3g} ± {_fmt(100 * sx[j], 2)} %"
                        f"<br>order {int(n[j])}, {status.value}" + (f": {html.escape(str(reasons[j]))}"
                                                                    if reasons[j] else "")
                        + "".join(f"<br>{s}" for s in flags))
        err = None
        if has_std and status is not PoleStatus.REJECTED:
            err = {"type": "data", "array": np.where(coupled, 0.0, np.nan_to_num(sf, nan=0.0)), "visible": True,
                   "thickness": 0.8, "width": 1.5, "color": STATUS_COLOUR[status.value]}
        fig.add_trace(go.Scatter(
            x=f, y=n, mode="markers", error_x=err, name=f"{status.value.replace('_', ' ')} ({idx.size})",
            marker={"color": STATUS_COLOUR[status.value], "symbol": STATUS_SYMBOL[status.value],
                    "size": 4 if status is PoleStatus.REJECTED else 6},
            text=text, hovertemplate="%{text}<extra></extra>",
            visible="legendonly" if status is PoleStatus.REJECTED and idx.size > 2000 else True))
    band = (diagram.result_settings or {}).get("frequency_range")
    lo, hi = (0.0, diagram.fs / 2) if band is None else map(float, band)
    for k in range(selected.n_modes if selected is not None else 0):
        fk = float(selected.frequency_hz[k])
        s = float(selected.frequency_std[k]) if np.isfinite(selected.frequency_std[k]) else 0.0
        half = max(s, 0.002 * (hi - lo))
        fig.add_vrect(x0=fk - half, x1=fk + half, fillcolor="purple", opacity=0.18, line_width=0, layer="below")
        fig.add_vline(x=fk, line={"color": "black", "dash": "dot", "width": 1})
        fig.add_annotation(x=fk, y=1.0, yref="paper", yanchor="bottom", text=str(k + 1), showarrow=False)
    layout = {"title": f"Stabilization diagram ({'±1σ_f bars' if has_std else 'no uncertainty'}; "
                       "hover a pole for f, ξ, σ and flags; drag to zoom)",
              "xaxis": {"title": "frequency [Hz]", "range": [lo, hi]},
              "yaxis": {"title": "model order"}, "height": 560, "hovermode": "closest",
              "legend": {"orientation": "h", "y": -0.15}, "margin": {"t": 60}}
    if spectrum is not None:
        layout["yaxis2"] = {"overlaying": "y", "side": "right", "type": "log", "showgrid": False,
                            "title": "singular values of the output PSD", "exponentformat": "power",
                            "dtick": 1}
    fig.update_layout(**layout)
    return fig


def _mac_figure(go, selected):
    phi = np.asarray(selected.mode_shape, complex)
    mm = mac_matrix(phi, getattr(selected, "mode_covariance", None), getattr(selected, "mode_shape_factor", None))
    mac, std = mm.mac, mm.std
    labels = [f"{k + 1}: {selected.frequency_hz[k]:.4g} Hz" for k in range(selected.n_modes)]
    with_std = bool(np.isfinite(std).all())
    hover = [[f"{mac[i, j]:.4f}" + (f" ± {std[i, j]:.2g}" if with_std and i != j else "")
              for j in range(len(labels))] for i in range(len(labels))]
    fig = go.Figure(go.Heatmap(z=mac, x=labels, y=labels, zmin=0, zmax=1, colorscale="Blues",
                               text=[[f"{v:.3f}" for v in row] for row in mac], texttemplate="%{text}",
                               customdata=hover,
                               hovertemplate="MAC(%{y}, %{x}) = %{customdata}<extra></extra>"))
    note = ("" if not with_std else "<br><sub>hover: ±1σ, shapes taken as independent (their cross-covariance "
            "is not kept)</sub>" if mm.independent_approximation else "<br><sub>hover: ±1σ, with the shapes' "
            "cross-covariance</sub>")
    fig.update_layout(title="MAC of the selected modes" + note, height=max(320, 60 + 40 * selected.n_modes),
                      width=max(420, 160 + 60 * selected.n_modes), yaxis={"autorange": "reversed"})
    return fig


def _line_xyz(xyz, index, lines):
    pts = []
    for a, b in lines:
        pts += [xyz[index[int(a)]], xyz[index[int(b)]], [None] * 3]
    return np.array(pts, dtype=object).reshape(-1, 3) if pts else np.zeros((0, 3), object)


def _envelope_xyz(moved, cov, moving, factor):
    pts = []
    if cov is not None:
        for n in np.nonzero(moving)[0]:
            w, v = np.linalg.eigh(0.5 * (cov[n] + cov[n].T))
            w = np.clip(w, 0, None)
            top = math.sqrt(float(w.max(initial=0.0)))
            for j in range(3):
                s = math.sqrt(w[j])
                if top == 0 or s < 1e-3 * top:
                    continue
                d = factor * s * v[:, j]
                pts += [moved[n] - d, moved[n] + d, [None] * 3]
    return np.array(pts, dtype=object).reshape(-1, 3) if pts else np.zeros((0, 3), object)


def _r(a, digits=5):
    """Coordinates rounded for the file (sizes: a 3-D frame per phase per mode)."""
    out = np.asarray(a, dtype=object).copy()
    for i in np.ndindex(out.shape):
        if out[i] is not None:
            out[i] = round(float(out[i]), digits)
    return out


def _shape_3d_figure(go, selected, k, geometry, sigma=2.0):
    disp = mode_displacements(selected, k + 1, geometry)
    xyz = geometry.coordinates
    index = {int(n): i for i, n in enumerate(geometry.node_ids)}
    peak = float(np.max(np.linalg.norm(np.abs(disp.value), axis=1), initial=0.0))
    factor = DISPLAY_FRACTION * geometry.size / peak if peak > 0 else 1.0
    digits = max(3, 4 - int(math.floor(math.log10(geometry.size))))
    und = _r(_line_xyz(xyz, index, geometry.lines), digits)
    moving = disp.moving

    def traces(alpha):
        moved = xyz + factor * disp.at_phase(alpha)
        ln = _r(_line_xyz(moved, index, geometry.lines), digits)
        env = _r(_envelope_xyz(moved, disp.covariance_at(alpha), moving, factor * sigma), digits)
        nd = _r(moved[moving], digits)
        return [go.Scatter3d(x=ln[:, 0], y=ln[:, 1], z=ln[:, 2], mode="lines", line={"color": "#1f77b4", "width": 5},
                             name="deformed", hoverinfo="skip"),
                go.Scatter3d(x=env[:, 0], y=env[:, 1], z=env[:, 2], mode="lines", line={"color": "#d62728", "width": 4},
                             name=f"±{sigma:g}σ ellipsoid axes", hoverinfo="skip"),
                go.Scatter3d(x=nd[:, 0], y=nd[:, 1], z=nd[:, 2], mode="markers", name="nodes",
                             marker={"size": 3, "color": "black"},
                             text=[str(int(i)) for i in geometry.node_ids[moving]],
                             hovertemplate="node %{text}<extra></extra>")]

    phases = 2 * np.pi * np.arange(ANIMATION_FRAMES) / ANIMATION_FRAMES
    # the real part at phase 0 is the shape as normalised (reference component 1)
    first = traces(0.0)
    base = [go.Scatter3d(x=und[:, 0], y=und[:, 1], z=und[:, 2], mode="lines", name="undeformed",
                         line={"color": "#bbbbbb", "width": 2, "dash": "dash"}, hoverinfo="skip")]
    frames = [go.Frame(data=traces(a), name=f"{int(round(math.degrees(a)))}", traces=[1, 2, 3]) for a in phases]
    fig = go.Figure(data=base + first, frames=frames)
    lo = xyz.min(axis=0) - factor * peak * 1.2
    hi = xyz.max(axis=0) + factor * peak * 1.2
    span = np.maximum(hi - lo, 0.05 * float((hi - lo).max()))
    ratio = span / span.max()
    # how large the envelope is against the motion (it may be too small to see at true scale)
    rel = ""
    if disp.covariance is not None and peak > 0:  # the longest axis drawn at phase 0, as the static figure's legend
        rel = f"; largest ±{sigma:g}σ: {100 * sigma * disp.largest_std(0.0) / peak:.2g} % of the largest motion"
    f, xi = float(selected.frequency_hz[k]), float(selected.damping_ratio[k])
    sf = getattr(selected, "frequency_std", None)
    head = (f"mode {k + 1}: {f:.4g} ± {_fmt(float(sf[k]), 2)} Hz, ξ {100 * xi:.3g} ± "
            f"{_fmt(100 * float(selected.damping_std[k]), 2)} %") if sf is not None else f"mode {k + 1}: {f:.4g} Hz"
    env = ("shape covariance" if disp.exact else "per-channel σ, correlations neglected") \
        if disp.covariance is not None else "no σ"
    fig.update_layout(
        title=f"{head}<br><sub>deformation × {factor:.3g}; ±{sigma:g}σ: {env}{rel}; drag to rotate</sub>",
        height=640, margin={"t": 70, "l": 0, "r": 0, "b": 0}, legend={"x": 0, "y": 0.9},
        scene={"camera": {"eye": {"x": 1.25, "y": -1.45, "z": 0.7}},
               # ticks in proportion to each axis's drawn length: a deck's short axes stay legible
               **{f"{c}axis": {"title": f"{c} [{geometry.units}]", "range": [lo[i], lo[i] + span[i]],
                               "nticks": max(3, int(round(MAX_TICKS_3D * ratio[i])))}
                  for i, c in enumerate("xyz")},
               "aspectmode": "manual", "aspectratio": {"x": ratio[0], "y": ratio[1], "z": ratio[2]}},
        updatemenus=[{"type": "buttons", "x": 0.05, "y": 0.02, "xanchor": "left", "yanchor": "bottom",
                      "direction": "left", "buttons": [
                          {"label": "▶ play", "method": "animate",
                           "args": [None, {"frame": {"duration": 70, "redraw": True}, "fromcurrent": True,
                                           "transition": {"duration": 0}, "mode": "immediate"}]},
                          {"label": "❚❚ pause", "method": "animate",
                           "args": [[None], {"frame": {"duration": 0, "redraw": False}, "mode": "immediate"}]}]}],
        sliders=[{"x": 0.25, "len": 0.7, "y": 0.02, "currentvalue": {"prefix": "phase [°] "},
                  "steps": [{"label": fr.name, "method": "animate",
                             "args": [[fr.name], {"frame": {"duration": 0, "redraw": True}, "mode": "immediate"}]}
                            for fr in frames]}])
    return fig


def _shape_bar_figure(go, selected, k):
    names = list(selected.output_names)
    phi = np.asarray(selected.mode_shape)[:, k]
    sr = np.asarray(getattr(selected, "mode_shape_std_real", np.zeros_like(phi.real)))[:, k]
    si = np.asarray(getattr(selected, "mode_shape_std_imag", np.zeros_like(phi.real)))[:, k]
    fig = go.Figure([go.Bar(x=names, y=phi.real, error_y={"array": np.nan_to_num(sr)}, name="real"),
                     go.Bar(x=names, y=phi.imag, error_y={"array": np.nan_to_num(si)}, name="imag")])
    fig.update_layout(title=f"mode {k + 1}: {selected.frequency_hz[k]:.4g} Hz (±1σ; no geometry given)",
                      height=360, barmode="group", yaxis={"range": [-1.15, 1.15]})
    return fig


#: Per-mode indicators shown in the table when the selected modes carry them: field → (column,
#: field of its σ). A column appears when any mode has a finite value (SelectedModes: MPC and
#: MPD with their σ, modaluq.indicators).
INDICATOR_COLUMNS = {"mpc": ("MPC", "mpc_std"), "mpd_deg": ("MPD [°]", "mpd_std_deg")}


def _interval_note(selected) -> str:
    """The sentence that says how to read a 95 % interval from the table (SelectedModes.interval_words)."""
    words = getattr(selected, "interval_words", None)
    if words is None or not selected.has_uncertainty or not selected.n_modes:
        return ""
    return " " + html.escape(words().replace("+-", "±").replace(" std", " σ")) + "."


def _table(selected) -> str:
    rows = []
    flags = np.asarray(getattr(selected, "noise_coupled", np.zeros(selected.n_modes, bool)), bool)
    # σ widened by the model order (SelectedModes.order_discrepancy), as the printed table says
    widened = np.asarray(getattr(selected, "order_discrepancy", np.zeros(selected.n_modes, bool)), bool)
    # σ raised to the poles' ρσ (SelectedModes.unanchored), as the printed table says
    unanchored = np.asarray(getattr(selected, "unanchored", np.zeros(selected.n_modes, bool)), bool)
    indicators = {}
    for name, (_, std_name) in INDICATOR_COLUMNS.items():
        values = getattr(selected, name, None)
        if values is not None and np.shape(values) == (selected.n_modes,) and np.isfinite(values).any():
            std = getattr(selected, std_name, None)
            indicators[name] = (np.asarray(values, float),
                                np.full(selected.n_modes, np.nan) if std is None else np.asarray(std, float))
    # the order the shape (and MPC, MPD, MAC) is read at, when it is not the representative's
    shape_order = getattr(selected, "shape_order", None)
    with_shape_order = shape_order is not None and np.any(np.asarray(shape_order) != selected.representative_order)
    for k in range(selected.n_modes):
        cells = [str(k + 1), f"{selected.frequency_hz[k]:.5g}", _fmt(float(selected.frequency_std[k]), 3),
                 _fmt(float(selected.frequency_spread[k]), 3), f"{100 * selected.damping_ratio[k]:.4g}",
                 _fmt(100 * float(selected.damping_std[k]), 3), _fmt(100 * float(selected.damping_spread[k]), 3),
                 str(int(selected.representative_order[k])), str(int(selected.n_poles[k]))]
        cells += [str(int(shape_order[k]))] if with_shape_order else []
        cells += [f"{_fmt(v[k], 3)} ± {_fmt(sd[k], 2)}" for v, sd in indicators.values()]
        cells.append(" ".join(w for w, on in (("noise?", flags[k]), ("widened", widened[k]),
                                              ("rho*std", unanchored[k])) if on))
        rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    head = ["mode", "f [Hz]", "σ f [Hz]", "spread f", "ξ [%]", "σ ξ [%]", "spread ξ", "order", "poles"]
    head += ["shape order"] if with_shape_order else []
    head += [f"{INDICATOR_COLUMNS[n][0]} ± σ" for n in indicators] + [""]
    return ("<table><thead><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr></thead><tbody>"
            + "".join(rows) + "</tbody></table>")


CSS = """body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px auto;max-width:1150px;
color:#222}h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.8em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;font-size:.92em}td,th{padding:3px 10px;border-bottom:1px solid #eee;text-align:right}
th{background:#f4f4f4}pre{background:#f7f7f7;padding:8px;font-size:.85em;white-space:pre-wrap}
.warn{color:#a33}.note{color:#555;font-size:.9em}"""


#: Draws the first mode's figure when the page has loaded and each other one when it comes into
#: view (an IntersectionObserver's first notice waits for a rendered frame, which headless
#: browsers do not always produce: the first mode stayed blank there); records in ``body[data-rendered]`` how many
#: figures are drawn and in ``body[data-rendered-ms]`` when the last one was (performance.now(),
#: what the browser test reads).
LAZY_SCRIPT = """(function(){
var cfg={displaylogo:false,responsive:true};
function mark(){var b=document.body;b.dataset.rendered=document.querySelectorAll('.js-plotly-plot').length;
b.dataset.renderedMs=Math.round(performance.now());}
function draw(el){if(el.dataset.drawn)return;el.dataset.drawn=1;
var fig=JSON.parse(document.getElementById(el.id+'-figure').textContent);fig.config=cfg;
Plotly.newPlot(el,fig).then(mark);}
var lazy=document.querySelectorAll('.lazy-plot');
if('IntersectionObserver' in window){var io=new IntersectionObserver(function(es){es.forEach(function(e){
if(e.isIntersecting){draw(e.target);io.unobserve(e.target);}});},{rootMargin:'200px'});
lazy.forEach(function(el){io.observe(el);});}else{lazy.forEach(draw);}
window.addEventListener('load',function(){mark();if(lazy.length)draw(lazy[0]);});})();"""


def write_html_report(path, diagram, selected, *, geometry=None, spectrum=None, title: str = "",
                      run_description: str = "", warnings=(), stamp: dict | None = None) -> Path:
    """Write the interactive report (see the module docstring) to ``path`` (``.html``), atomically.

    Parameters
    ----------
    diagram : Diagram
    selected : SelectedModes
    geometry : Geometry, optional
        Each mode animated on it in 3-D; without it, the shapes per channel.
    spectrum : (frequency_hz, singular_values), optional
        Drawn behind the diagram (:func:`modaluq.spectrum.output_spectrum_singular_values`).
    title, run_description, warnings, stamp
        Shown at the top (the stamp as JSON, collapsed).
    """
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise ValueError(f"path {os.fspath(path)!r}: the report is an .html file")
    require("plotly", "the HTML report")
    import plotly.graph_objects as go
    import plotly.io as pio

    if geometry is not None and selected.n_modes:
        geometry.channel_order(selected.output_names)  # a mismatch refused before anything is drawn
    def div(fig, first=False):
        return pio.to_html(fig, full_html=False, include_plotlyjs=first, auto_play=False,
                           config={"displaylogo": False, "responsive": True})

    # plotly.js once, with the first figure: the file opens offline
    parts = ["<h2>Stabilization diagram</h2>" + div(_diagram_figure(go, diagram, selected, spectrum), first=True),
             "<h2>Selected modes</h2>" + _table(selected) +
             f"<p class='note'>σ: analytic (delta-method) standard deviation, {selected.std_words}; spread: "
             "standard deviation across the cluster's poles. noise?: every pole of the mode is noise-coupled. "
             "widened: f or ξ at the representative's order and at the lowest sufficient order differ by more "
             "than 1.96 of the two poles' combined σ, and σ includes that difference. rho*std: every pole of the "
             "mode depends on the frozen noise directions (the noise floor is below the mode), and σ is their "
             "unfrozen bound ρσ." + _interval_note(selected) + "</p>"]
    if selected.n_modes > 1:
        parts.append("<h2>MAC matrix</h2>" + div(_mac_figure(go, selected)))
    if selected.n_modes:
        parts.append("<h2>Mode shapes</h2>" + (
            f"<p class='note'>On the geometry {html.escape(geometry.name)}: drag to rotate, press play or move the "
            "phase slider; red: the ±2σ ellipsoid axes of each node's displacement at that phase.</p>"
            if geometry is not None else "<p class='note'>No geometry given: the shapes per channel, ±1σ.</p>"))
    for k in range(selected.n_modes):
        fig = _shape_3d_figure(go, selected, k, geometry) if geometry is not None else \
            _shape_bar_figure(go, selected, k)
        # drawn when scrolled into view (LAZY_SCRIPT): a 3-D scene per mode at load would make a
        # report of many modes slow to open; "</" escaped so that the JSON cannot close the script
        spec = pio.to_json(fig, validate=False).replace("</", "<\\/")
        height = int(fig.layout.height or 450)
        parts.append(f"<section><div class='lazy-plot' id='mode-{k + 1}' style='height:{height}px'></div>"
                     f"<script type='application/json' id='mode-{k + 1}-figure'>{spec}</script></section>")
    if geometry is not None and geometry.unobserved:
        parts.append("<p class='note'>" + "<br>".join(html.escape(u) for u in geometry.unobserved) + "</p>")
    warn = "".join(f"<p class='warn'>warning: {html.escape(str(w))}</p>" for w in warnings)
    stamp_html = ""
    if stamp:
        from .jsonvalues import dumps

        stamp_html = f"<details><summary>provenance</summary><pre>{html.escape(dumps(stamp, indent=2))}</pre></details>"
    run = f"<pre>{html.escape(run_description)}</pre>" if run_description else ""
    doc = (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title or 'modaluq')}"
           f"</title><style>{CSS}</style></head><body><h1>{html.escape(title or 'modaluq identification')}</h1>"
           f"<p class='note'>modaluq {__version__}; self-contained (opens offline)</p>"
           f"{run}{warn}{stamp_html}{''.join(parts)}<script>{LAZY_SCRIPT}</script></body></html>")
    return write_atomically(path, lambda tmp: tmp.write_text(doc, encoding="utf-8"))
