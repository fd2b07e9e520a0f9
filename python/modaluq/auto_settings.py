"""Identification settings chosen from the data when the user gives none (docs/settings.md).

The rules, in order (fs is the rate after any decimation, T the record length in seconds, l the
outputs, f_low the band's lower edge):

1. **Horizon.** The lags of H must span at least ``LAG_PERIODS`` periods of the slowest mode of
   interest and ``CENTRE_PERIODS`` periods of the band's geometric centre f_c = sqrt(f_low f_high):
   block_rows p = ceil(fs · max(LAG_PERIODS / f_low, CENTRE_PERIODS / f_c)). The second term
   matters for narrow bands far from 0 Hz: modes a few per cent apart beat apart only over
   many periods (the smartphone slab's 17.2 and 17.8 Hz modes, 3 % apart, merge into one pole
   with 3 % damping with lags of 2 periods of its band's 10 Hz edge, and separate from 10
   periods of 17 Hz on; docs/settings.md). Without a band, f_low = fs / 20 and only the first
   term counts (p = 40). p is at least 1 + ceil(MIN_ORDER / l) (so that order MIN_ORDER fits) and at most
   MAX_ROWS / l (H at most MAX_ROWS × MAX_ROWS: the cost grows with its size cubed) and what
   lets the record hold the minimum number of blocks of BLOCK_SPAN (p + q) columns. Longer lags
   resolve closer modes but add estimation noise: lags far beyond the decay times only add
   noise, and the noise floor k* of the result drops.
2. **Orders.** 2, 4, ..., n_max with n_max = min((p − 1) l, q r, MAX_ORDER): one SVD serves them
   all; the noise floor k* of the result says where the noise starts.
3. **Blocks.** Each block should last at least half the decay time 1/(2π f ξ) of a mode at
   f_low with the damping XI_REF, so that the blocks are nearly independent: n_b =
   floor(T / (0.5 / (2π f_low XI_REF))), clipped to [max(MIN_BLOCKS, 2 l + 3), MAX_BLOCKS]
   (2 l + 3 blocks give every mode's joint covariance full rank), and at most as many as hold
   BLOCK_SPAN (p + q) columns each. A record too short for that gets the minimum and the core's
   ``block_too_short`` warning says so.
4. **Memory.** The settings chosen pass :func:`modaluq.checks.check_cost`: if their estimated
   memory exceeds what the machine has (never with H of MAX_ROWS rows on an ordinary machine),
   the chosen n_blocks and then block_rows are lowered until it fits.

A record shorter than :func:`minimum_samples` is refused (``ValueError`` naming the minimum):
it cannot hold the smallest automatic identification, block_rows p = max(2, 1 + ceil(MIN_ORDER / l))
and two blocks, each of at least BLOCK_SPAN (p + q) columns and as many columns as H has rows
(p l): with fewer, a block's covariance is rank-deficient and no σ can be estimated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .checks import available_memory, check_integer, check_real, check_sampling_frequency, estimate_cost

__all__ = ["ChosenSettings", "choose_settings", "LAG_PERIODS", "CENTRE_PERIODS", "MAX_ROWS", "MAX_ORDER", "MIN_ORDER",
           "XI_REF", "MIN_BLOCKS", "MAX_BLOCKS", "minimum_samples", "fewest_blocks"]

LAG_PERIODS = 2.0   #: periods of the lowest frequency of interest spanned by the lags
CENTRE_PERIODS = 10.0  #: periods of the band's geometric centre spanned by the lags
BLOCK_SPAN = 2      #: a block holds at least this many times p + q Hankel columns
MAX_ROWS = 300      #: largest number of rows p l of H (larger: the noise floor k* falls, docs/settings.md)
MIN_ORDER = 20      #: the horizon must allow at least this order
MAX_ORDER = 100     #: largest automatic order
XI_REF = 0.01       #: damping ratio (fraction) assumed for the block-length rule
MIN_BLOCKS = 10     #: fewest automatic blocks (before the 2 l + 3 rule)
MAX_BLOCKS = 50     #: most automatic blocks (the paper's number)


def fewest_blocks(n_outputs: int) -> int:
    """The rules' fewest blocks, max(MIN_BLOCKS, 2 l + 3): 2 l + 3 give every mode's joint
    covariance full rank. Advice never asks for fewer."""
    return max(MIN_BLOCKS, 2 * check_integer("n_outputs", n_outputs, minimum=1) + 3)


@dataclass(frozen=True)
class ChosenSettings:
    """What :func:`choose_settings` chose, and why."""

    block_rows: int
    orders: tuple
    n_blocks: int
    reasons: tuple      #: one sentence per setting, with the numbers

    def as_dict(self) -> dict:
        return {"block_rows": self.block_rows, "orders": list(self.orders), "n_blocks": self.n_blocks,
                "reasons": list(self.reasons)}


def lowest_frequency(fs: float, frequency_range=None) -> float:
    """The f_low of the rules: the band's lower edge, or fs / 20 without a band (or a band from 0 Hz,
    then the smaller of fs / 20 and a tenth of its upper edge)."""
    if frequency_range is None:
        return fs / 20.0
    lo, hi = frequency_range
    return lo if lo > 0 else min(fs / 20.0, hi / 10.0)


def centre_frequency(fs: float, frequency_range=None) -> float:
    """The f_c of the horizon rule: sqrt(f_low f_high) of the band (f_high at most fs / 2)."""
    f_low = lowest_frequency(fs, frequency_range)
    f_high = fs / 2.0 if frequency_range is None else min(frequency_range[1], fs / 2.0)
    return math.sqrt(f_low * max(f_high, f_low))


def minimum_samples(n_outputs: int) -> int:
    """Fewest samples of a record the automatic settings identify (module docstring): block_rows
    p = max(2, 1 + ceil(MIN_ORDER / l)) = q, and 2 blocks of max(BLOCK_SPAN (p + q), p l) columns.

    >>> minimum_samples(1), minimum_samples(3), minimum_samples(6)
    (209, 79, 69)
    """
    l = check_integer("n_outputs", n_outputs, minimum=1)
    p = max(2, 1 + math.ceil(MIN_ORDER / l))
    return 2 * p - 1 + 2 * max(BLOCK_SPAN * 2 * p, p * l)


def choose_settings(n_samples: int, fs: float, n_outputs: int, *, frequency_range=None,
                    n_references: int | None = None, block_rows: int | None = None,
                    orders=None, n_blocks: int | None = None, n_inputs: int = 0, uncertainty: bool = True,
                    threads: int = 1, bootstrap_draws: int = 0, keep_shape_factor: bool = False) -> ChosenSettings:
    """Fill in ``block_rows``, ``orders`` and ``n_blocks`` by the rules of this module.

    Settings given are kept (and the others are chosen around them). Returns
    :class:`ChosenSettings` whose ``reasons`` say what was chosen from what. The settings chosen
    fit the memory available (:func:`modaluq.checks.check_cost`; ``n_inputs``, ``uncertainty``,
    ``threads``, ``bootstrap_draws`` and ``keep_shape_factor`` enter that estimate): when they
    would not, the chosen ``n_blocks`` and then ``block_rows`` are lowered until they do, and the
    reasons say so.

    Examples
    --------
    >>> s = choose_settings(16_384, 106.25, 3, frequency_range=(10.0, 30.0))
    >>> s.block_rows, s.orders[-1], s.n_blocks
    (62, 100, 50)
    """
    n_samples = check_integer("n_samples", n_samples, minimum=1)
    fs = check_sampling_frequency(fs)
    l = check_integer("n_outputs", n_outputs, minimum=1)
    r = l if n_references is None else check_integer("n_references", n_references, minimum=1)
    f_low = lowest_frequency(fs, frequency_range)
    reasons = []
    nb_min = fewest_blocks(l)
    if block_rows is None:
        n_min = minimum_samples(l)
        if n_samples < n_min:
            raise ValueError(f"the record has {n_samples} samples, too short for any identification with {l} "
                             f"output{'s' if l > 1 else ''}: at least {n_min} are needed (docs/settings.md, automatic "
                             "settings); record longer, or give block_rows explicitly")
        f_centre = centre_frequency(fs, frequency_range)
        centre_lags = CENTRE_PERIODS / f_centre if frequency_range is not None else 0.0
        p_want = math.ceil(max(LAG_PERIODS / f_low, centre_lags) * fs - 1e-9)
        span = (f"{LAG_PERIODS:g} periods of f_low = {f_low:.3g} Hz" if LAG_PERIODS / f_low >= centre_lags
                else f"{CENTRE_PERIODS:g} periods of the band's centre {f_centre:.3g} Hz")
        p_min = 1 + math.ceil(MIN_ORDER / l)
        p_rows = MAX_ROWS // l
        p_length = (n_samples + 1) // (2 * BLOCK_SPAN * nb_min + 2)  # nb_min blocks of BLOCK_SPAN (p + q) columns
        p = max(min(p_want, p_rows, p_length), min(p_min, p_length), 2)
        why = f"block_rows = {p}: lags of {p / fs:.3g} s"
        if p == p_want:
            why += f", {span}"
        elif p < p_want:
            cap = (f"H is capped at {MAX_ROWS} rows ({l} outputs)" if p == p_rows else
                   f"the record ({n_samples} samples) holds {nb_min} blocks of {BLOCK_SPAN} (p + q) columns only")
            why += (f", fewer than the {p_want} for {span}: {cap}; "
                    "decimate, narrow the band or record longer to reach it")
        else:
            why += f", the fewest for order {MIN_ORDER} with {l} outputs"
        reasons.append(why)
    else:
        p = check_integer("block_rows", block_rows, minimum=2)
    limit = min((p - 1) * l, p * r)
    orders_chosen = orders is None
    if orders is None:
        n_max = max(2, min(limit, MAX_ORDER) // 2 * 2)
        orders = tuple(range(2, n_max + 1, 2))
        reasons.append(f"orders 2..{n_max} step 2 (the horizon allows up to {limit})")
    if n_blocks is None:
        duration = n_samples / fs
        decay = 1.0 / (2.0 * math.pi * f_low * XI_REF)
        nb = int(duration // (0.5 * decay))
        nb_fit = max(2, (n_samples - 2 * p + 1) // (2 * BLOCK_SPAN * p))  # blocks of BLOCK_SPAN (p + q) columns
        n_b = min(max(nb, nb_min), MAX_BLOCKS, nb_fit)
        why = (f"n_blocks = {n_b}: blocks of {duration / n_b:.3g} s against a decay time 1/(2π f ξ) = "
               f"{decay:.3g} s at f_low = {f_low:.3g} Hz, ξ = {100 * XI_REF:g} %")
        if nb < nb_min:
            why += (f"; the record ({duration:.3g} s) is too short for {nb_min} blocks of half that decay time, "
                    f"so the standard deviations of the slowest modes are less reliable")
        reasons.append(why)
    else:
        n_b = check_integer("n_blocks", n_blocks, minimum=2)
    p, orders, n_b = _fit_memory(reasons, n_samples, l, r, p, orders, n_b, n_inputs=n_inputs,
                                 uncertainty=uncertainty, threads=threads, bootstrap_draws=bootstrap_draws,
                                 keep_shape_factor=keep_shape_factor, chosen=(block_rows is None,
                                                                                   orders_chosen, n_blocks is None))
    return ChosenSettings(block_rows=p, orders=tuple(orders) if not isinstance(orders, int) else (orders,),
                          n_blocks=n_b, reasons=tuple(reasons))


def capped_lag_warning(chosen, fs: float, n_outputs: int, frequency_range) -> str | None:
    """A sentence when the automatic horizon (``chosen``: the block_rows, or the
    :class:`ChosenSettings`), capped by the size of H or the record, cannot span one period of the
    band's lowest frequency: what to change, with the numbers."""
    block_rows = chosen.block_rows if isinstance(chosen, ChosenSettings) else int(chosen)
    f_low = lowest_frequency(fs, frequency_range)
    if frequency_range is None or block_rows / fs * f_low >= 1.0:
        return None
    need = math.ceil(fs / f_low)
    fewer = max(1, MAX_ROWS // need)
    return (f"the automatic block_rows = {block_rows} (lags of {block_rows / fs:.3g} s) is less than one "
            f"period of the band's lowest frequency {f_low:g} Hz: H is capped at {MAX_ROWS} rows and there are "
            f"{n_outputs} outputs. Use at most {fewer} output{'' if fewer == 1 else 's'} "
            "(the others can still be identified in separate runs), "
            f"raise the band's lower edge, or give block_rows >= {need} explicitly")


def lag_warning(block_rows: int, fs: float, frequency_range) -> str | None:
    """A sentence when user-chosen lags cannot span one period of the band's lowest frequency."""
    if frequency_range is None or frequency_range[0] <= 0:
        return None
    f_low = check_real("frequency_range[0]", frequency_range[0], low=0, low_open=True)
    if block_rows / fs * f_low >= 1.0:
        return None
    need = math.ceil(LAG_PERIODS * fs / f_low)
    return (f"block_rows = {block_rows} gives lags of {block_rows / fs:.3g} s, less than one period of the band's "
            f"lowest frequency {f_low:g} Hz ({1 / f_low:.3g} s): its modes are poorly identified; use block_rows "
            f">= {math.ceil(fs / f_low)} (the automatic choice is {need})")


def _fit_memory(reasons: list, n_samples: int, l: int, r: int, p: int, orders, n_b: int, *, n_inputs: int,
                uncertainty: bool, threads: int, chosen: tuple, bootstrap_draws: int = 0,
                keep_shape_factor: bool = False):
    """``(p, orders, n_b)`` lowered, where they were chosen, until the estimate of
    :func:`modaluq.checks.estimate_cost` fits the memory available: first the blocks (to the
    fewest that still give every mode's covariance full rank, then 2), then the horizon (halved,
    the automatic orders following it). Unchanged when they fit (every ordinary case: H is at
    most MAX_ROWS rows)."""
    p_chosen, orders_chosen, blocks_chosen = chosen
    have = available_memory()[0]

    def need(p_, orders_, n_b_):
        return estimate_cost(n_samples, l, n_inputs, block_rows=p_, n_references=r, orders=orders_, n_blocks=n_b_,
                             uncertainty=uncertainty, threads=threads, bootstrap_draws=bootstrap_draws,
                             keep_shape_factor=keep_shape_factor).bytes

    if need(p, orders, n_b) <= have:
        return p, orders, n_b
    p0, n_b0 = p, n_b
    if blocks_chosen and uncertainty:
        for fewer in (fewest_blocks(l), 2):
            if fewer < n_b:
                n_b = fewer
                if need(p, orders, n_b) <= have:
                    break
    while p_chosen and p > 2 and need(p, orders, n_b) > have:
        p = max(2, p // 2)
        if orders_chosen:
            n_max = max(2, min(min((p - 1) * l, p * r), MAX_ORDER) // 2 * 2)
            orders = tuple(range(2, n_max + 1, 2))
    if (p, n_b) != (p0, n_b0):
        reasons.append(f"lowered to block_rows = {p}, n_blocks = {n_b} (from {p0}, {n_b0}) to fit the "
                       f"{have / 1e9:.3g} GB of memory available (docs/settings.md, \"Memory\")")
    return p, orders, n_b
