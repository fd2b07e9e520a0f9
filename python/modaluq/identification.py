"""Identification: :func:`identify` runs covariance-driven SSI with the uncertainty of every mode.

The arithmetic runs once, in the C++ core (``modaluq._core``); this module converts the
user's arrays (``(n_samples, n_channels)``, the shape CSV files, pandas and the OMA packages
use), preprocesses them when asked, completes the settings from the data, and wraps the
core's result in a :class:`~modaluq.Result`.
"""

from __future__ import annotations

import math
import os
from typing import Sequence

import numpy as np

from . import _core
from ._blas import single_threaded as single_threaded_blas
from .auto_settings import capped_lag_warning, choose_settings, fewest_blocks, lag_warning
from .checks import (
    as_samples,
    check_cost,
    check_instance,
    check_sampling_frequency,
    constant_channel_warning,
    constant_channels,
    naming_settings_on_memory_error,
)
from .io import Recording, load
from .io.campaign import Campaign, load_campaign
from .poser import check_references_after_modular, identify_poser, reference_check_orders
from .preprocess import preprocess
from .results import IdentificationWarning, Result, result_from_core, warn_all
from .settings import ClusteringSettings, Settings, StabilityCriteria

__all__ = ["identify", "identify_quietly", "identify_setups", "make_settings", "short_lag_warning",
           "slow_decay_advice"]


def make_settings(settings: Settings | None, keywords: dict, *, function: str = "identify") -> Settings:
    """``settings`` with ``keywords`` replacing its fields (a new :class:`Settings` without it)."""
    if settings is not None and not isinstance(settings, Settings):
        raise TypeError(f"settings must be a modaluq.Settings; got {type(settings).__name__}")
    unknown = sorted(set(keywords) - set(Settings.__dataclass_fields__))
    if unknown:
        raise TypeError(f"{function}() got an unexpected keyword argument {unknown[0]!r}")
    return Settings(**keywords) if settings is None else settings.replace(**keywords)


def identify(y, u=None, *, fs: float, settings: Settings | None = None,
             output_names: Sequence[str] | None = None, **keywords) -> Result:
    """Identify modes by covariance-driven SSI, with their standard deviations.

    Parameters
    ----------
    y : array_like, shape (n_samples, n_outputs) or (n_samples,)
        Measured outputs (e.g. accelerations). Real numbers; NaN/Inf are refused.
    u : array_like, shape (n_samples, n_inputs), optional
        Measured inputs (forces, ground motion). ``None`` for output-only identification.
    fs : float
        Sampling frequency in Hz.
    settings : Settings, optional
        All the settings below in one object (:class:`modaluq.Settings`); keyword arguments
        given as well replace its fields. The keywords below are the fields of ``Settings``.
    block_rows : int, optional
        Future block rows p of the Hankel covariance (>= 2). Default: chosen from the data
        (:mod:`modaluq.auto_settings`, docs/settings.md): lags of two periods of the band's
        lowest frequency. The choices and why are in ``Result.settings["chosen"]``.
    past_block_rows : int, optional
        Past block rows q (default p).
    orders : int or iterable of int, optional
        Model orders; each must be <= min((p-1) n_outputs, q n_references). All orders come
        from one SVD at the largest. Default: 2, 4, ... up to what the horizon allows (at most 100).
    n_blocks : int, optional
        Blocks for the covariance of the data covariances (>= 2). Each block should be longer
        than the slowest mode's decay time; ``Result.warnings`` says when it is not. Default:
        blocks of half the decay time of a 1 %-damped mode at the band's lowest frequency,
        10 (at least 2 n_outputs + 3) to 50 of them.
    references : iterable of int, optional
        Outputs that form the past data matrix (default all).
    uncertainty : bool
        Propagate the covariance to every modal parameter (default True); False skips it at no cost.
    demean : bool
        Remove each channel's mean over the record (default True).
    input_rcond : float
        Eigenvalues of the input covariance R3 below ``input_rcond`` times the largest are dropped
        from its pseudo-inverse; ``Result.input_rank_deficient`` reports when that happens.
    threads : int
        Threads for the covariance pass, the per-block and the per-order work (default 1). The
        result does not depend on it; 2 on a 2-core machine takes 30–40 % off the wall time of
        a large stabilization diagram.
        When the module is built with OpenBLAS (``modaluq._core.uses_blas``), its products run
        on one BLAS thread during the call (unless ``OPENBLAS_NUM_THREADS`` is set), so
        ``threads`` is the only parallelism and parallel processes do not oversubscribe.

    freeze_noise : bool
        Hold the directions of the singular vectors below the noise floor fixed in the
        propagation (default True; docs/uq-math.md §5.5). Above the true order, the rotations
        among noise singular vectors are not determined by the data and, left free, inflate
        the standard deviations of physical poles by up to tens of times. False gives the
        plain first-order propagation.
    noise_coupling_limit : float
        A pole whose sigma_f or sigma_xi shrinks by more than this factor (>= 1, default 20)
        when the noise directions are frozen is flagged ``Modes.noise_coupled``: it is
        spurious or mixed with a spurious pole, no first-order value is meaningful, and it
        keeps the unfrozen, conservative standard deviations.
    block_correlation_correction : bool
        Correct each mode's block covariance for the correlation of adjacent blocks (default
        False; docs/uq-math.md §3.1): where |ρ| > 2/√n_blocks, its standard deviations are
        multiplied by √c, c = max(1/4, 1 + 2ρ), with ρ the lag-1 autocorrelation of its f and ξ
        block terms plus 1/n_blocks (c = 1 otherwise), reported per mode as
        ``block_correlation_scale``. Where a measured input
        carries most of the excitation, the uncorrected σ grows with ``n_blocks``; corrected,
        it does not (docs/validation.md, "Issue 27"). One record only (``identify_setups``
        refuses it).
    bootstrap_draws : int
        Above the noise floor k* (``Result.significant_singular_values``) the first-order σ of a
        physical pole is too small (the noise directions in the model are chosen by the noise,
        which no linearisation follows). With ``bootstrap_draws`` = B (0 = off, the default, or
        >= 10; 100 is what was validated), σ_f and σ_ξ of every pole above k* that is not
        noise-coupled are the robust spread (1.4826 MAD) of the pole over B identifications of H
        perturbed by its own estimation error (docs/uq-math.md §5.6), flagged per mode in
        ``Modes.bootstrapped``; orders up to k* are unchanged. Each draw costs an SVD of H and
        the eigenvalues of the orders above k*; over a full diagram B = 100 costs 5–10
        identifications. It is for reading poles at given orders: the selected modes
        (``select_modes``), which average over many orders, come out conservative with it (up to
        2× too wide; docs/validation.md, "Issue 27" (g)), and are calibrated without it. One record
        only (``identify_setups`` refuses it).
    keep_shape_factor : bool
        Keep each pole's first-order factor of its shape (``Modes.mode_shape_factor``, default
        False): two modes of one record share the data, and the σ of the MAC between them
        (``SelectedModes.mac_matrix()``, the AutoMAC plot and the report) is exact only with their
        cross-covariance, which this factor gives; without it that cross-covariance is taken as 0
        (within about ±20 %, docs/shapes.md §6). Costs 2 n_outputs n_blocks values per pole (about
        60 MB for 30 channels, 50 blocks and orders 2..100).

    frequency_range : (float, float), optional
        Band of interest (f_low, f_high) in Hz. The record is decimated (anti-aliased) to a
        rate of about 3 f_high unless ``decimate`` says otherwise, the automatic settings follow
        the band, and the stabilization diagram rejects poles outside it.
    start, stop : float, optional
        Time window in seconds from the first sample.
    decimate : int, optional
        Integer decimation factor (default: from ``frequency_range``, else none).
    detrend : {"constant", "linear", None}
        Detrend each channel before filtering.
    highpass : float, optional
        Corner in Hz of a zero-phase 4th-order Butterworth high-pass applied to y and u.
    output_names : sequence of str, optional
        One name per output channel, used by tables, plots and exports. Default: the columns of
        ``y`` when it is a :class:`pandas.DataFrame`, else ``y0, y1, ...``.

    Settings whose estimated memory (H is p l x q r; the propagation holds n_blocks + 20 copies
    of it) exceeds the memory available are refused before the core starts, with a ValueError
    naming the settings to lower; docs/settings.md, "Memory".

    Returns
    -------
    Result
        ``result.at_order(n)`` gives the :class:`Modes` of order n. ``result.fs`` is the rate
        identified at (after decimation); ``result.settings["preprocessing"]`` says what was done.

    Examples
    --------
    >>> import modaluq
    >>> sim = modaluq.simulate(20_000, seed=1)
    >>> result = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=15, orders=12)
    >>> modes = result.at_order(12)
    >>> [round(float(f), 1) for f in modes.frequency_hz]
    [1.9, 5.6, 8.7, 14.5, 15.8, 17.0]
    """
    result = identify_quietly(y, u, fs=fs, settings=settings, output_names=output_names, **keywords)
    warn_all(result)
    return result


def short_lag_warning(block_rows: int, fs: float, n_outputs: int, frequency_range, *, automatic: bool) -> str | None:
    """The sentence of lags shorter than one period of the band's lowest frequency: for an
    automatic ``block_rows`` capped by the size of H or the record (what to change), or for one
    the user gave (the number to use); None when the lags span that period."""
    if automatic:
        return capped_lag_warning(block_rows, fs, n_outputs, frequency_range)
    return lag_warning(block_rows, fs, frequency_range)


def identify_quietly(y, u=None, *, fs: float, settings: Settings | None = None,
                     output_names: Sequence[str] | None = None, **keywords) -> Result:
    """:func:`identify` without issuing ``Result.warnings`` as Python warnings (they are kept in
    the result). For threads identifying at once: Python's warning filters are one global state,
    and catching each thread's warnings with ``warnings.catch_warnings`` mixes them up."""
    fs = check_sampling_frequency(fs)
    s = make_settings(settings, keywords)
    names = _output_names(output_names, y)
    y = as_samples(y, "y")
    if len(names) not in (0, y.shape[1]):
        raise ValueError(f"output_names must have {y.shape[1]} entries (one per column of y); got {len(names)}")
    u = as_samples(u, "u", allow_none=True)
    if u is not None and u.shape[0] != y.shape[0]:
        raise ValueError(f"u must have as many samples as y ({y.shape[0]}); got {u.shape[0]}")
    # dead sensors, as recorded (before any filter): the core identifies around them without a word
    dead = [w for w in (constant_channel_warning(y, names or [f"y{k}" for k in range(y.shape[1])], "output"),
                        None if u is None else constant_channel_warning(u, [f"u{k}" for k in range(u.shape[1])],
                                                                        "input")) if w]
    if len(constant_channels(y)) == y.shape[1]:
        raise ValueError(f"every output is constant: {dead[0]}; nothing to identify")
    pre = None
    if s.preprocessing:
        pre = preprocess(y, u, fs=fs, **s.preprocessing)
        y, u, fs = pre.y, pre.u, pre.fs
    band = None if pre is None else pre.frequency_range
    chosen = None
    if s.block_rows is None or s.orders is None or s.n_blocks is None:
        n_refs = None if s.references is None else len(s.references)
        chosen = choose_settings(y.shape[0], fs, y.shape[1], frequency_range=band, n_references=n_refs,
                                 block_rows=s.block_rows, orders=s.orders, n_blocks=s.n_blocks,
                                 n_inputs=0 if u is None else u.shape[1], uncertainty=s.uncertainty, threads=s.threads,
                                 bootstrap_draws=s.bootstrap_draws, keep_shape_factor=s.keep_shape_factor)
        s = s.replace(block_rows=chosen.block_rows, orders=chosen.orders, n_blocks=chosen.n_blocks)
    o = s.to_core(fs)
    # refused here, in a moment, rather than after minutes or with a bare std::bad_alloc
    check_cost(y.shape[0], y.shape[1], 0 if u is None else u.shape[1], s)
    u_t = np.empty((0, y.shape[0])) if u is None else u.T
    with single_threaded_blas(), naming_settings_on_memory_error(s):
        ident = _core.identify(y.T, u_t, o)
    record = s.record(fs, y.shape[1])
    record["frequency_range"] = None if band is None else list(band)
    if pre is not None:
        record["preprocessing"] = pre.settings()
    if chosen is not None:
        record["chosen"] = list(chosen.reasons)
    extra = list(dead)
    lag = short_lag_warning(s.block_rows, fs, y.shape[1], band,
                            automatic=chosen is not None and any(r.startswith("block_rows") for r in chosen.reasons))
    if lag:
        extra.append(lag)
    worded = {}
    slow = slow_decay_advice(ident.slow_decay, y.shape[1])
    if slow:
        worded[IdentificationWarning.SLOW_DECAY] = slow
    return result_from_core(ident, record, y.shape[1], 0 if u is None else u.shape[1], extra_warnings=extra,
                            output_names=names, worded=worded)


def slow_decay_advice(slow, n_outputs: int) -> str | None:
    """Python's sentence for the core's slow-decay finding (``Identification.slow_decay``: numbers)
    when the core's advice, n_blocks <= K, would go below the rules' fewest blocks
    (:func:`~modaluq.auto_settings.fewest_blocks`): the record length that would hold that many
    blocks of half the decay time instead. None when the core's words stand (K at least the
    fewest, or fewer than 2 blocks fit: a longer record)."""
    if not slow.n_poles:
        return None
    fewest = fewest_blocks(n_outputs)
    fitting = int(slow.fitting_n_blocks)
    if fitting < 2 or fitting >= fewest:
        return None
    half = 0.5 * float(slow.longest_decay_s)
    return (f"{int(slow.n_poles)} pole(s) decay more slowly than the blocks are long (blocks of "
            f"{float(slow.block_seconds):.6g} s, less than half of the decay time 1/(2 pi f xi), up to "
            f"{float(slow.longest_decay_s):.6g} s); n_blocks <= {fitting} would be fewer than the {fewest} blocks the "
            f"rules need with {n_outputs} output{'s' if n_outputs > 1 else ''}: {fewest} blocks of {half:.3g} s need "
            f"a record of at least {fewest * half:.3g} s (the selected modes' sigma of f and xi were not found "
            "under-estimated by short blocks, docs/settings.md)")


def _output_names(output_names, y) -> tuple:
    """The names given, else a DataFrame's columns, else () (meaning y0, y1, ...)."""
    if output_names is not None:
        if isinstance(output_names, str):
            raise TypeError("output_names must be a sequence of names, one per output; got a single string")
        return tuple(str(n) for n in output_names)
    columns = getattr(y, "columns", None)
    return tuple(str(c) for c in columns) if columns is not None and getattr(y, "ndim", 0) == 2 else ()


def identify_setups(setups, *, fs=None, references: Sequence[str] | None = None,
                    inputs: Sequence[str] | None = None, settings: Settings | None = None,
                    method: str = "modular", criteria=None, clustering=None, **keywords):
    """Identify a campaign measured in several setups, merged into global mode shapes with their σ.

    The modular merge of Döhler & Mevel (2012) with the first-order covariance of Döhler, Lam &
    Mevel (2013), docs/uq-math.md §13: each setup's subspace is brought into the first setup's
    state basis through the reference channels, one global model is identified at every order,
    and each setup's block covariance is propagated (the setups are independent records) to f,
    ξ and the global shape. The result is a :class:`Result` like :func:`identify`'s: its
    stabilization diagram and ``select_modes()`` work unchanged, with ``output_names`` the
    global DOFs (the references once, then each setup's other channels in setup and column
    order). Each setup's noise floor is frozen as for one record (``freeze_noise``, docs/uq-math.md
    §13.4), so σ above the true order is not inflated by the setups' noise directions.

    Parameters
    ----------
    setups : sequence of records, or a campaign
        One record per setup, each a pandas DataFrame (shape (n_samples_j, n_channels_j),
        columns the channel names), a :class:`modaluq.io.Recording` (its output and input names,
        its rate; its inputs are inputs) or a file path (read by :func:`modaluq.io.load`). Records
        may have different lengths and channels; the references must be in every one. Or a
        :class:`modaluq.io.Campaign` (:func:`modaluq.io.load_campaign`) or the path of a campaign
        file (``.toml``, docs/multisetup.md): its setups, references, inputs, fs and
        ``[settings]``, the arguments given here replacing them.
    fs : float or sequence of float, optional
        Sampling frequency in Hz, the same for every setup (a sequence is checked to be constant).
        Optional when every setup carries its rate (recordings, files); a setup whose own rate
        differs from ``fs`` is a ValueError naming it.
    references : sequence of str
        Names of the reference channels, measured in every setup (the past channels of each).
    inputs : sequence of str, optional
        Names of measured-input columns (input/output); in each setup the columns with these
        names are its inputs (a setup may have none: it is then output-only).
    method : {"modular", "poser"}
        ``"modular"`` (default): the merge above, returning a :class:`Result`. ``"poser"``: each
        setup identified and its modes selected alone, then merged (f and ξ by inverse-variance
        weights, shapes rescaled on the references, σ propagated; docs/uq-math.md §13.5, §13.9),
        returning a :class:`~modaluq.poser.PoserResult` whose ``select_modes()`` gives the merged
        modes over the same global DOFs. With either, each setup's reference components are
        tested against the others' (a mislabelled or moved reference issues a
        :class:`~modaluq.poser.ReferenceMismatchWarning` naming the setup, the channel and the
        mode); for the modular merge this identifies each setup alone once more.
    criteria, clustering : StabilityCriteria, ClusteringSettings, optional
        ``method="poser"`` only: how each setup's modes are selected before the merge, as
        ``Result.select_modes(criteria, clustering)`` would (defaults when None); for example
        ``ClusteringSettings(shape_representative="median")`` for the shapes of the clusters'
        representatives. The modular merge returns a :class:`Result`: give them to its
        ``select_modes`` instead (a ValueError here).
    settings, **keywords
        As for :func:`identify`: ``block_rows``, ``past_block_rows``, ``orders``, ``n_blocks``
        (per setup), ``uncertainty``, ``input_rcond``, ``threads`` and the preprocessing
        keywords (``frequency_range``, ``decimate``, ...), applied to every setup alike.
        Orders are bounded by min(p r, q r, (p-1) l_g) with r references and l_g global DOFs.
        ``coupling_sketch`` (default 4; the merge only): the noise-coupling test (ρ, the flag
        ``noise_coupled`` above a setup's noise floor) runs on that many signed combinations of
        each setup's blocks instead of every block, which makes the merge about 1.5× faster; a
        flagged pole's σ is then its frozen σ times ρ (docs/uq-math.md §13.4). 0 runs the exact
        test on every block.
        ``keep_shape_factor`` (default False): each merged pole keeps its global shape's factor
        over every setup's blocks (``Modes.mode_shape_factor``), for the AutoMAC's σ with the
        shapes' cross-covariance (see :func:`identify`).

    Raises
    ------
    ValueError
        A reference missing from a setup, different sampling frequencies, a channel (not a
        reference) measured in two setups, a setup without outputs, or settings the merge
        cannot use. Each names the setup.
    TypeError
        A setup that is none of the records above (named), or a single string of references.
    """
    if method not in ("modular", "poser"):
        raise ValueError(f"method must be 'modular' or 'poser'; got {method!r}")
    if method == "modular" and (criteria is not None or clustering is not None):
        given = " and ".join(n for n, v in (("criteria", criteria), ("clustering", clustering)) if v is not None)
        raise ValueError(f"{given}: only with method='poser' (each setup's modes are selected before the merge); "
                         "the modular merge returns a Result: give them to its select_modes(criteria, settings)")
    if criteria is not None:
        check_instance("criteria", criteria, StabilityCriteria)
    if clustering is not None:
        check_instance("clustering", clustering, ClusteringSettings)
    if isinstance(setups, (str, os.PathLike)) and str(setups).lower().endswith(".toml"):
        setups = load_campaign(setups)
    base = campaign_settings(setups, settings) if isinstance(setups, Campaign) else settings
    s = make_settings(base, keywords, function="identify_setups")
    if s.references is not None:
        raise TypeError("identify_setups takes the references by name (references=[...]), not as Settings.references")
    records, rate, refs, dof_names = _campaign_records(setups, fs, references, inputs)
    fs = rate

    rate, band = fs, None
    if s.preprocessing:
        pre = [preprocess(y, u, fs=fs, **s.preprocessing) for y, u, _ in records]
        records = [(p.y, p.u, w) for p, (_, _, w) in zip(pre, records)]
        rate, band = pre[0].fs, pre[0].frequency_range
    r = len(refs)
    l_g = len(dof_names)
    if s.block_rows is None or s.orders is None or s.n_blocks is None:
        shortest = min(y.shape[0] for y, _, _ in records)
        widest = max(y.shape[1] for y, _, _ in records)
        chosen = choose_settings(shortest, rate, widest, frequency_range=band, n_references=r,
                                 block_rows=s.block_rows, orders=s.orders, n_blocks=s.n_blocks,
                                 n_inputs=max((0 if u is None else u.shape[1]) for _, u, _ in records),
                                 uncertainty=s.uncertainty, threads=s.threads,
                                 keep_shape_factor=s.keep_shape_factor)
        s = s.replace(block_rows=chosen.block_rows, orders=chosen.orders, n_blocks=chosen.n_blocks)
    o = s.to_core(rate)
    core_setups = []
    for y, u, _ in records:
        lay = s.layout(y.shape[1], 0 if u is None else u.shape[1])
        lay.references = list(range(r))
        u_t = np.empty((0, y.shape[0])) if u is None else np.ascontiguousarray(u.T)
        with single_threaded_blas():
            cov = _core.compute_covariances(y.T, u_t, lay, s.n_blocks if s.uncertainty else 1, s.demean,
                                            s.uncertainty, s.threads)
        core_setups.append(_core.SetupData(cov, list(range(r)), rate))
    names_per_setup = [refs + dof_names[r + sum(w for _, _, w in records[:j]):][:w]
                       for j, (_, _, w) in enumerate(records)]
    n_inputs_per_setup = [0 if u is None else u.shape[1] for _, u, _ in records]
    if method == "poser":
        record = s.record(rate, l_g)
        record.update(references=list(range(r)), reference_names=refs,
                      frequency_range=None if band is None else list(band))
        with naming_settings_on_memory_error(s):
            return identify_poser(core_setups, o, record, names_per_setup, n_inputs_per_setup, dof_names, refs,
                                  criteria=criteria, clustering=clustering)
    with single_threaded_blas(), naming_settings_on_memory_error(s):
        ident = _core.identify_setups(core_setups, o)
    record = s.record(rate, l_g)
    record["references"] = list(range(r))
    record["reference_names"] = refs
    record["setups"] = [{"n_samples": int(y.shape[0]), "n_outputs": int(y.shape[1]),
                         "n_inputs": 0 if u is None else int(u.shape[1])} for y, u, _ in records]
    record["frequency_range"] = None if band is None else list(band)
    n_in = max((0 if u is None else u.shape[1]) for _, u, _ in records)
    result = result_from_core(ident, record, l_g, n_in, output_names=dof_names)
    warn_all(result)
    single = dict(record, setups=None)
    # the reference check reads f and the shapes only: no shape factors kept for it
    o_check = s.replace(orders=reference_check_orders(s.orders), keep_shape_factor=False).to_core(rate)
    check_references_after_modular(core_setups, o_check, single, names_per_setup, n_inputs_per_setup, refs)
    return result


def campaign_settings(campaign: Campaign, settings: Settings | None = None) -> Settings:
    """``settings`` (default ones when None) with the campaign file's ``[settings]`` applied,
    checked here so that a bad entry is a ValueError naming the file and the table."""
    try:
        return make_settings(settings, dict(campaign.settings), function="identify_setups")
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{campaign.source or 'campaign'}: [settings]: {exc}") from None


def _campaign_records(setups, fs, references, inputs) -> tuple:
    """The setups of :func:`identify_setups` as ``(records, fs, references, dof_names)``:
    ``records`` one ``(y, u, n_moving)`` per setup, y's columns the references then the setup's
    other outputs. Every error names the setup (its index, and its name or file when known)."""
    labels = None
    if isinstance(setups, (str, os.PathLike)):
        raise TypeError(f"setups must be a list of records (one per setup) or a campaign file (.toml); got the "
                            f"single path {str(setups)!r}")
    if isinstance(setups, Campaign):
        labels = [f"setup {j} ({name!r})" for j, name in enumerate(setups.names)]
        fs = setups.fs if fs is None else fs
        references = setups.references if references is None else references
        inputs = (setups.inputs or None) if inputs is None else inputs
        setups = setups.setups
    if isinstance(setups, (Recording,)) or getattr(setups, "columns", None) is not None:
        raise TypeError("setups must be a list of records, one per setup; got a single "
                        f"{type(setups).__name__} (wrap it in a list)")
    try:
        setups = list(setups)
    except TypeError:
        raise TypeError(f"setups must be a list of records (DataFrames, modaluq.io Recordings or file paths); "
                        f"got {type(setups).__name__}") from None
    if not setups:
        raise ValueError("setups must hold at least one record")
    named = labels is not None
    if labels is None:
        labels = [f"setup {j}" for j in range(len(setups))]
    if references is None:
        raise TypeError("identify_setups() needs references=[...]: the names of the reference channels")
    if isinstance(references, str):
        raise TypeError("references must be a sequence of channel names, not a single string")
    refs = [str(r) for r in references]
    if not refs:
        raise ValueError("references must name at least one reference channel")
    if len(set(refs)) != len(refs):
        raise ValueError(f"references has a repeated name: {refs}")
    if isinstance(inputs, str):
        raise TypeError("inputs must be a sequence of channel names, not a single string")
    input_names = set() if inputs is None else {str(n) for n in inputs}
    if input_names & set(refs):
        raise ValueError(f"references and inputs share {sorted(input_names & set(refs))}")

    given = None
    if fs is not None:
        given = np.atleast_1d(np.asarray(fs, dtype=float))
        if given.ndim != 1 or given.size not in (1, len(setups)):
            raise ValueError(f"fs must be one rate or one per setup ({len(setups)}); got {given.size}")
    # each setup as (names, columns, its declared inputs, its own rate or None)
    tables = []
    for j, rec in enumerate(setups):
        fs_j = None if given is None else float(given[0 if given.size == 1 else j])
        if isinstance(rec, (str, os.PathLike)):
            try:
                rec = load(rec)
            except ValueError:
                if fs_j is None:
                    raise
                rec = load(rec, fs=fs_j)  # a file that states no rate: fs is its rate
        if isinstance(rec, Recording):
            if rec.source and not named:
                labels[j] += f" ({rec.source})"
            names = list(rec.output_names) + list(rec.input_names)
            data = rec.y if rec.u is None else np.hstack([rec.y, rec.u])
            tables.append((names, data, set(rec.input_names), float(rec.fs)))
        elif getattr(rec, "columns", None) is not None and hasattr(rec, "to_numpy"):
            tables.append(([str(c) for c in rec.columns], rec, set(), None))
        else:
            raise TypeError(f"{labels[j]} must be a pandas.DataFrame whose columns are channel names, a "
                            f"modaluq.io.Recording or a file path; got {type(rec).__name__}")
    rates = []
    for j, (_, _, _, own) in enumerate(tables):
        fs_j = None if given is None else float(given[0 if given.size == 1 else j])
        if own is not None and fs_j is not None and not math.isclose(own, fs_j, rel_tol=1e-9):
            raise ValueError(f"{labels[j]} is sampled at {own:g} Hz but fs = {fs_j:g} Hz: every setup must have "
                             "the same rate (resample it, or correct fs)")
        rate = fs_j if fs_j is not None else own
        if rate is None:
            raise ValueError(f"{labels[j]} is a DataFrame, which carries no rate: give fs")
        rates.append(rate)
    for j, rate in enumerate(rates):
        if not math.isclose(rate, rates[0], rel_tol=1e-9):
            raise ValueError(f"{labels[j]} has fs = {rate} Hz but {labels[0]} has {rates[0]} Hz: "
                             "every setup must be sampled at the same rate (resample first)")
    rate = check_sampling_frequency(rates[0])

    records, dof_names, seen = [], list(refs), {}
    for j, (names, data, declared, _) in enumerate(tables):
        twice = sorted({c for c in names if names.count(c) > 1})
        if twice:
            raise ValueError(f"{labels[j]} has more than one channel named {twice[0]!r}")
        missing = [r for r in refs if r not in names]
        if missing:
            raise ValueError(f"{labels[j]} lacks the reference channel(s) {missing} (its channels: {names})")
        is_input = declared | input_names
        as_input = [r for r in refs if r in declared]
        if as_input:
            raise ValueError(f"{labels[j]}: the reference {as_input[0]!r} is an input of the record")
        outs = [c for c in names if c not in is_input]
        ins = [c for c in names if c in is_input]
        moving = [c for c in outs if c not in refs]
        for c in moving:
            if c in seen:
                raise ValueError(f"channel {c!r} is measured in setups {labels[seen[c]].removeprefix('setup ')} "
                                 f"and {labels[j].removeprefix('setup ')} but is not a reference: declare it in "
                                 "references or rename one")
            seen[c] = j
        dof_names += moving
        # references first (the past channels, in the global order), then the moving channels
        if isinstance(data, np.ndarray):
            col = {c: k for k, c in enumerate(names)}
            y_raw, u_raw = data[:, [col[c] for c in refs + moving]], data[:, [col[c] for c in ins]] if ins else None
        else:
            y_raw = data[refs + moving].to_numpy(dtype=float)
            u_raw = data[ins].to_numpy(dtype=float) if ins else None
        y = as_samples(y_raw, f"setups[{j}]")
        u = as_samples(u_raw, f"setups[{j}] inputs") if ins else None
        records.append((y, u, len(moving)))
    return records, rate, refs, dof_names
