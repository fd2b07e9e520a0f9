"""Markdown report and histograms of a Monte Carlo run (:class:`MonteCarloResult`).

The report mirrors the layout of the paper's Tables 1 and 2 and prints the paper's values
(:mod:`modaluq.validation.paper`) beside ours, in the paper's units, which every header names:
frequencies in Hz, their std in 10⁻² Hz, damping ratios and their std in per mille (‰,
10⁻³; the paper prints ξ = 2 % as "20.0").  The result object itself holds SI values
(Hz, damping ratio as a fraction).
"""

from __future__ import annotations

import numpy as np

from .paper import METHOD_LABELS, METHODS, PAPER_N_RECORDS, PAPER_N_SAMPLES, PAPER_ORDER, PAPER_TABLE_1, PAPER_TABLE_2

__all__ = ["markdown_report", "plot_estimates", "plot_histograms"]

#: Band of σ̄_est / σ_MC called a match in the report's check (±10 %).
RATIO_BAND = 0.10

# Display scale and unit of each parameter, as in the paper's tables.
_SCALE = {"frequency": 1e2, "damping": 1e3}          # std: Hz -> 10^-2 Hz; fraction -> per mille
_STD_UNIT = {"frequency": "10⁻² Hz", "damping": "‰"}
_SYMBOL = {"frequency": "f", "damping": "ξ"}


def _fmt(x, digits: int) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _pm(x, e, digits: int, e_digits: int | None = None) -> str:
    if x is None or not np.isfinite(x):
        return "–"
    if e is None or not np.isfinite(e):
        return _fmt(x, digits)
    return f"{x:.{digits}f} ± {e:.{digits if e_digits is None else e_digits}f}"


def _row(label, cells) -> str:
    return "| " + " | ".join([label, *cells]) + " |"


def _header(first, n_modes, extra_first=()) -> list:
    cols = [*extra_first, first, *[f"mode {i + 1}" for i in range(n_modes)]]
    return ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]


def _paper_comparable(res) -> bool:
    s = res.settings
    return (s.get("n_samples") == PAPER_N_SAMPLES and s.get("order") == PAPER_ORDER and res.n_modes == 6
            and s.get("paper_case", True))


def _paper_structure(res) -> bool:
    """The paper's chain was simulated (its values are comparable in kind)."""
    return res.n_modes == 6 and res.settings.get("paper_case", True)


def _table_1(res) -> list:
    n = res.n_modes
    paper_ok = _paper_structure(res)
    lines = ["### Table 1: mean frequencies and damping ratios",
             "",
             f"Ours: mean over the records where the mode was matched ± its standard error "
             f"(sample std / √n); the paper's: mean over {PAPER_N_RECORDS:,} records.",
             "",
             "**Frequency (Hz)**", ""]
    lines += _header("", n)
    if paper_ok:
        lines.append(_row("actual model, paper", [f"{v:.4g}" for v in PAPER_TABLE_1["actual"]["frequency_hz"]]))
    lines.append(_row("actual model, ours (exact)", [_fmt(v, 4) for v in res.true_frequency_hz]))
    for m, method in enumerate(METHODS):
        if paper_ok:
            lines.append(_row(f"{METHOD_LABELS[method]}, paper",
                              [f"{v:.4g}" for v in PAPER_TABLE_1[method]["frequency_hz"]]))
        lines.append(_row(f"**{METHOD_LABELS[method]}, ours**",
                          [_pm(res.frequency_mean[m, i], res.frequency_mean_se[m, i], 4) for i in range(n)]))
    lines += ["", "**Damping ratio (‰ = 10⁻³; the paper's header says % but it prints 20.0 for ξ = 2 %)**", ""]
    lines += _header("", n)
    if paper_ok:
        lines.append(_row("actual model, paper", [_fmt(v, 1) for v in PAPER_TABLE_1["actual"]["damping_permille"]]))
    lines.append(_row("actual model, ours (exact)", [_fmt(1e3 * v, 2) for v in res.true_damping_ratio]))
    for m, method in enumerate(METHODS):
        if paper_ok:
            lines.append(_row(f"{METHOD_LABELS[method]}, paper",
                              [_fmt(v, 1) for v in PAPER_TABLE_1[method]["damping_permille"]]))
        lines.append(_row(f"**{METHOD_LABELS[method]}, ours**",
                          [_pm(1e3 * res.damping_mean[m, i], 1e3 * res.damping_mean_se[m, i], 2)
                           for i in range(n)]))
    return lines


def _paper_std(method, name):
    t = PAPER_TABLE_2[method]
    if name == "frequency":
        return (t["frequency_std_est_centihz"], t["frequency_std_est_spread_centihz"], t["frequency_std_mc_centihz"])
    return (t["damping_std_est_permille"], t["damping_std_est_spread_permille"], t["damping_std_mc_permille"])


def _table_2(res, name) -> list:
    n = res.n_modes
    paper_ok = _paper_structure(res)
    k = _SCALE[name]
    sym = _SYMBOL[name]
    title = "frequency" if name == "frequency" else "damping ratio"
    digits = 3
    lines = [f"**Standard deviation of the {title} ({_STD_UNIT[name]})**", ""]
    lines += _header("", n, extra_first=("",))
    est, spread, mc = (getattr(res, f"{name}_std_est"), getattr(res, f"{name}_std_est_spread"),
                       getattr(res, f"{name}_std_mc"))
    ratio, ratio_se = getattr(res, f"{name}_std_ratio"), getattr(res, f"{name}_std_ratio_se")
    for m, method in enumerate(METHODS):
        lab = METHOD_LABELS[method]
        rows = []
        if paper_ok:
            p_est, p_spread, p_mc = _paper_std(method, name)
            rows.append(("σ̄_est ± spread, paper", [f"{a:.2f} ± {b:.2f}" for a, b in zip(p_est, p_spread)]))
        rows.append(("**σ̄_est ± spread, ours**",
                     [_pm(k * est[m, i], k * spread[m, i], digits) for i in range(n)]))
        if paper_ok:
            rows.append(("σ_MC, paper", [f"{v:.2f}" for v in p_mc]))
        rows.append(("**σ_MC, ours**", [_fmt(k * mc[m, i], digits) for i in range(n)]))
        if paper_ok:
            rows.append(("σ̄_est / σ_MC, paper", [f"{a / b:.2f}" for a, b in zip(p_est, p_mc)]))
        rows.append(("**σ̄_est / σ_MC ± SE, ours**", [_pm(ratio[m, i], ratio_se[m, i], 2) for i in range(n)]))
        for label, cells in rows:
            lines.append(_row(lab, [f"{label} ({sym})", *cells]))
    return lines


def _check(res) -> list:
    """Which ratios lie within ±10 % of 1, and the others with their distance in standard errors."""
    lines = [f"### Check: σ̄_est / σ_MC within ±{100 * RATIO_BAND:.0f} %", ""]
    lines += ["| method | parameter | modes within ±10 % | outside (ratio ± SE, distance from 1 in SE) |",
              "|---|---|---|---|"]
    for m, method in enumerate(METHODS):
        for name in ("frequency", "damping"):
            ratio = getattr(res, f"{name}_std_ratio")[m]
            se = getattr(res, f"{name}_std_ratio_se")[m]
            inside = [i + 1 for i in range(res.n_modes) if np.isfinite(ratio[i]) and abs(ratio[i] - 1) <= RATIO_BAND]
            outside = []
            for i in range(res.n_modes):
                if i + 1 in inside:
                    continue
                if not np.isfinite(ratio[i]):
                    outside.append(f"mode {i + 1}: no estimate")
                    continue
                z = abs(ratio[i] - 1) / se[i] if np.isfinite(se[i]) and se[i] > 0 else np.nan
                outside.append(f"mode {i + 1}: {ratio[i]:.2f} ± {_fmt(se[i], 2)} ({_fmt(z, 1)} SE)")
            lines.append(f"| {METHOD_LABELS[method]} | {_SYMBOL[name]} | "
                         f"{', '.join(map(str, inside)) or 'none'} | {'; '.join(outside) or '–'} |")
    lines += ["", "The standard error of the ratio is the std of the ratio over "
              f"{res.n_bootstrap} bootstrap resamples of the records (estimate and its std resampled "
              "together).  With n records, σ_MC alone is uncertain by about 1/√(2(n−1)) "
              f"({100 / np.sqrt(2 * max(res.n_records - 1, 1)):.1f} % here for Gaussian estimates; more "
              "for heavy-tailed ones)."]
    return lines


def _flag_table(res) -> list:
    """Ratios with and without the poles flagged noise_coupled, and the mode-shape check."""
    n = res.n_modes
    lines = ["### Flagged poles, medians and mode shapes", "",
             "Flagged: share of the matched poles with `noise_coupled` set (their σ is the unfrozen, "
             "conservative one; docs/uq-math.md §5.5).  \"all\": every matched pole; \"unflagged\": the "
             "flagged ones left out of both σ_MC and the analytic σ (what a user who sets them aside gets).  "
             "Shape: median over the non-reference components (real and imaginary parts) of "
             "median σ / σ_MC, unflagged records normalised at the same component.  RMS((est − mean)/σ): "
             "each record's error in units of its own σ; 1 when every record's σ is right, also when σ "
             "differs between records (above the true order it does, and the pooled σ_MC then exceeds "
             "the median σ of a correct estimator).  Coverage: share of the records within ±1.96 of their "
             "own σ of the Monte Carlo mean (0.95 when σ is right and known; with σ estimated from n_b "
             "blocks, P(|t_{n_b−1}| ≤ 1.96), 0.944 at 50 blocks).  The 95 % interval ± t σ takes the "
             "Student-t quantile with n_b − 1 degrees of freedom (SelectedModes.intervals, "
             "docs/uq-math.md §14): it covers 0.95 when σ is right.", ""]
    lines += _header("", n, extra_first=("method",))
    rows = [("flagged (%)", lambda m: [_fmt(100 * v, 1) for v in res.noise_coupled_share[m]])]
    for name in ("frequency", "damping"):
        sym = _SYMBOL[name]
        for key, label in (("std_ratio", f"mean σ / σ_MC ({sym}), all"),
                           ("std_ratio_median", f"median σ / σ_MC ({sym}), all"),
                           ("std_ratio_unflagged", f"mean σ / σ_MC ({sym}), unflagged"),
                           ("std_ratio_median_unflagged", f"median σ / σ_MC ({sym}), unflagged"),
                           ("rms_z_unflagged", f"RMS((est − mean)/σ) ({sym}), unflagged"),
                           ("coverage_unflagged", f"coverage of ±1.96 σ ({sym}), unflagged"),
                           ("coverage_interval_unflagged", f"coverage of the 95 % interval ± t σ ({sym}), "
                                                           f"unflagged (t = {res.interval_factor_95:.3f})")):
            rows.append((label, lambda m, a=getattr(res, f"{name}_{key}"): [_fmt(v, 2) for v in a[m]]))  # noqa: B008
    rows.append(("median σ / σ_MC (shape), unflagged",
                 lambda m: [_fmt(v, 2) for v in res.mode_shape_std_ratio_median[m]]))
    for m, method in enumerate(METHODS):
        for label, cells in rows:
            lines.append(_row(METHOD_LABELS[method], [label, *cells(m)]))
    return lines


def _matching(res) -> list:
    tol = res.settings.get("match_tolerance", float("nan"))
    lines = ["### Matching and flags", "",
             f"An identified mode is matched to the true mode whose window it falls in (nearest frequency, "
             f"window ±{100 * tol:.0f} % of the true frequency, narrowed to half the distance to the "
             f"neighbouring true mode).  A miss leaves that mode out of that record's statistics.", ""]
    lines += _header("", res.n_modes, extra_first=("method",))
    for m, method in enumerate(METHODS):
        lines.append(_row(METHOD_LABELS[method], ["misses", *[str(int(v)) for v in res.n_missed[m]]]))
    lines.append("")
    for m, method in enumerate(METHODS):
        lines.append(
            f"- {METHOD_LABELS[method]}: {int(res.failed[m].sum())} identification(s) failed, "
            f"{int((res.n_identified[m] < res.n_modes).sum())} record(s) with fewer than {res.n_modes} modes at the "
            f"order, {int(res.close_singular_values[m].sum())} record(s) where the order cuts close singular "
            f"values (the core's flag), {int((res.n_warnings[m] > 0).sum())} record(s) with a warning.")
    return lines


def markdown_report(res) -> str:
    """The Monte Carlo run as Markdown: settings, Tables 1 and 2 beside the paper, checks.

    Parameters
    ----------
    res : MonteCarloResult
        The run.

    Returns
    -------
    str
        Markdown text.  Frequencies in Hz (std in 10⁻² Hz), damping ratios and their std in
        per mille (‰), as in the paper's tables; every header names its unit.
    """
    s = res.settings
    q = s.get("past_block_rows", s.get("block_rows"))
    lines = [
        "# modaluq Monte Carlo validation of the analytic standard deviations",
        "",
        f"- Records: {res.n_records:,} independent records of N = {s.get('n_samples'):,} samples at "
        f"{s.get('fs', float('nan')):g} Hz ({s.get('simulation', '')}), "
        f"seed {s.get('seed')} (record k: `SeedSequence({s.get('seed')}, spawn_key=(k,))`).",
        f"- Identification: SSI-cov, output-only (OO) and input/output (IO) on the same record, model order "
        f"{s.get('order')}, p = {s.get('block_rows')} future and q = {q} past block rows, "
        f"{s.get('n_blocks')} blocks for the covariance; "
        + ("noise singular vectors frozen, poles flagged noise-coupled above "
           f"ρ = {s.get('noise_coupling_limit', 20):g} "
           "(docs/uq-math.md §5.5)." if s.get("freeze_noise", True) else
           "plain first-order propagation (noise singular vectors free, `--no-freeze-noise`).")
        + (" σ corrected for the correlation of adjacent blocks (`--block-correlation-correction`, "
           "docs/uq-math.md §3.1)." if s.get("block_correlation_correction", False) else "")
        + (f" σ_f, σ_ξ above the noise floor from {s['bootstrap_draws']} bootstrap draws (`--bootstrap-draws`, "
           "docs/uq-math.md §5.6)." if s.get("bootstrap_draws", 0) else ""),
        f"- Run: {res.elapsed_s:.1f} s wall time, {res.processes} process(es); {res.machine}.",
        f"- Paper: Mellinger, Döhler & Mevel (ISMA 2016), Tables 1 and 2: {PAPER_N_RECORDS:,} records of "
        f"N = {PAPER_N_SAMPLES:,}, order {PAPER_ORDER}; its block rows and number of blocks are not stated.",
        "- σ̄_est: mean over the records of the analytic (delta-method) std computed from each record alone; "
        "\"± spread\": their sample std over the records.  σ_MC: sample std of the estimates over the records.",
        "",
    ]
    if not _paper_comparable(res):
        lines += ["**Note:** these settings differ from the paper's (N = 10,000, order 12, six modes); "
                  "its values are shown for orientation only.", ""]
    lines += ["## Results", ""]
    lines += _table_1(res)
    lines += ["", "### Table 2: mean estimated standard deviation and sample standard deviation", ""]
    lines += _table_2(res, "frequency")
    lines += [""]
    lines += _table_2(res, "damping")
    lines += ["", "The paper's ratio row is computed from its rounded Table 2 values.", ""]
    lines += _check(res)
    lines += [""]
    lines += _flag_table(res)
    lines += [""]
    lines += _matching(res)
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- plots


def _figure(n_modes):
    """A bare Agg figure (no pyplot: the caller's backend and open figures are left alone)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2.5 * n_modes, 9))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2 * len(METHODS), n_modes, squeeze=False)
    return fig, axes


def _finite(x):
    x = np.asarray(x)
    return x[np.isfinite(x)]


def _axis_range(v, center=None):
    """x range of a histogram: the data within 4 interquartile ranges of the quartiles."""
    q1, q3 = np.percentile(v, [25, 75])
    iqr = q3 - q1 if q3 > q1 else max(abs(q3), 1e-300) * 1e-3
    lo, hi = max(v.min(), q1 - 4 * iqr), min(v.max(), q3 + 4 * iqr)
    if center is not None and np.isfinite(center):
        lo, hi = min(lo, center), max(hi, center)
    return lo, hi


_TEX = {"frequency": r"\sigma_f", "damping": r"\sigma_\xi"}
_SYMBOL_TEX = {"frequency": "f", "damping": r"\xi"}


def plot_histograms(res, path, *, dpi: int = 72) -> str:
    """Histograms of the estimated standard deviations, one panel per mode, method and parameter.

    Like the paper's Figure 2 (std panels), for every mode: the analytic σ_f and σ_ξ of each
    record, with a solid vertical line at the sample std σ_MC of the estimates over the records
    and a dashed one at their mean σ̄_est.  Rows: OO σ_f, OO σ_ξ, IO σ_f, IO σ_ξ.  σ_f in
    10⁻² Hz, σ_ξ in ‰.  The x axis covers the values within 4 interquartile ranges of the
    quartiles (and σ_MC, σ̄_est); the panel title counts the records beyond it.

    Parameters
    ----------
    res : MonteCarloResult
        The run.
    path : str or path-like
        PNG file to write.
    dpi : int, default 72
        Resolution (the figure is 15 × 9 inches).

    Returns
    -------
    str
        ``path``.
    """
    fig, axes = _figure(res.n_modes)
    n = res.n_modes
    for m, method in enumerate(METHODS):
        for r, name in enumerate(("frequency", "damping")):
            row = 2 * m + r
            k = _SCALE[name]
            stds = getattr(res, f"{name}_std")[m]
            for i in range(n):
                ax = axes[row, i]
                s = k * _finite(stds[:, i][np.isfinite(res.frequency_hz[m, :, i])])
                mc = k * getattr(res, f"{name}_std_mc")[m, i]
                est = k * getattr(res, f"{name}_std_est")[m, i]
                title = f"{METHOD_LABELS[method]} mode {i + 1}"
                if s.size:
                    lo, hi = _axis_range(s)
                    lo, hi = np.nanmin([lo, mc, est]), np.nanmax([hi, mc, est])
                    beyond = int(np.sum((s < lo) | (s > hi)))
                    ax.hist(s[(s >= lo) & (s <= hi)], bins=30, range=(lo, hi), color="0.7", edgecolor="0.45",
                            linewidth=0.4)
                    if beyond:
                        title += f" ({beyond} off axis)"
                if np.isfinite(mc):
                    ax.axvline(mc, color="C3", lw=1.6, label=r"$\sigma_{MC}$ (sample std of the estimates)")
                if np.isfinite(est):
                    ax.axvline(est, color="C0", lw=1.2, ls="--", label=r"$\bar\sigma_{est}$ (mean analytic std)")
                ax.set_title(title, fontsize=9)
                ax.tick_params(labelsize=7)
                ax.set_yticks([])
                if i == 0:
                    ax.set_ylabel(f"{METHOD_LABELS[method]} ${_TEX[name]}$", fontsize=9)
                ax.set_xlabel(f"${_TEX[name]}$ [{_STD_UNIT[name]}]", fontsize=8)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="upper right", fontsize=8, ncol=2)
    fig.suptitle(f"Analytic std per record ({res.n_records} records, N = {res.settings.get('n_samples')}, "
                 f"order {res.settings.get('order')}): histogram, sample std of the estimates (solid)",
                 fontsize=10, x=0.02, ha="left")
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    fig.savefig(path, dpi=dpi, format="png", pil_kwargs={"optimize": True})
    return str(path)


def plot_estimates(res, path, *, dpi: int = 72) -> str:
    """Histograms of the estimated frequencies and damping ratios with the analytic density.

    Like the paper's Figure 2 (estimate panels), for every mode and method: the estimates over
    the records, and the normal density with their mean and the mean analytic std σ̄_est; if
    the analytic std is right the curve follows the histogram.  f in Hz, ξ in ‰.

    Parameters
    ----------
    res : MonteCarloResult
        The run.
    path : str or path-like
        PNG file to write.
    dpi : int, default 72
        Resolution (the figure is 15 × 9 inches).

    Returns
    -------
    str
        ``path``.
    """
    fig, axes = _figure(res.n_modes)
    n = res.n_modes
    units = {"frequency": ("Hz", 1.0), "damping": ("‰", 1e3)}
    for m, method in enumerate(METHODS):
        for r, (name, attr) in enumerate((("frequency", "frequency_hz"), ("damping", "damping_ratio"))):
            unit, k = units[name]
            for i in range(n):
                ax = axes[2 * m + r, i]
                v = k * _finite(getattr(res, attr)[m][:, i])
                title = f"{METHOD_LABELS[method]} mode {i + 1}"
                if v.size >= 2:
                    mean = float(np.mean(v))
                    est = k * getattr(res, f"{name}_std_est")[m, i]
                    lo, hi = _axis_range(v)
                    outside = int(np.sum((v < lo) | (v > hi)))
                    ax.hist(v[(v >= lo) & (v <= hi)], bins=30, range=(lo, hi), density=True, color="0.7",
                            edgecolor="0.45", linewidth=0.4)
                    if np.isfinite(est) and est > 0:
                        x = np.linspace(lo, hi, 200)
                        ax.plot(x, np.exp(-0.5 * ((x - mean) / est) ** 2) / (est * np.sqrt(2 * np.pi)),
                                color="C0", lw=1.2, label=r"normal density, mean and $\bar\sigma_{est}$")
                    if outside:
                        title += f" ({outside} off axis)"
                ax.set_title(title, fontsize=9)
                ax.tick_params(labelsize=7)
                ax.set_yticks([])
                ax.set_xlabel(f"${_SYMBOL_TEX[name]}$ [{unit}]", fontsize=8)
                if i == 0:
                    ax.set_ylabel(f"{METHOD_LABELS[method]} ${_SYMBOL_TEX[name]}$", fontsize=9)
    handles, labels = axes[-1, -1].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="upper right", fontsize=8)
    fig.suptitle(f"Estimates over {res.n_records} records (histogram) and the normal density with the mean "
                 f"analytic std (curve)", fontsize=10, x=0.02, ha="left")
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    fig.savefig(path, dpi=dpi, format="png", pil_kwargs={"optimize": True})
    return str(path)
