"""Before the identification: a time window, the frequency band of interest, anti-aliased
decimation to a rate that suits the band, detrending and an optional high-pass filter.

Every step is applied to the outputs ``y`` and the inputs ``u`` alike, so that an input/output
relation between them is kept (the same linear filter on both sides). Decimation uses SciPy's
polyphase resampling (:func:`scipy.signal.resample_poly`, an anti-aliasing FIR filter), the
high-pass a zero-phase Butterworth filter (:func:`scipy.signal.sosfiltfilt`). What was done is
recorded in :class:`Preprocessed` and, through :func:`modaluq.identify`, in ``Result.settings``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .checks import as_samples, check_integer, check_real, check_sampling_frequency

__all__ = ["Preprocessed", "preprocess", "decimation_factor", "OVERSAMPLING", "DETREND"]

#: The decimated rate is at least this many times the band's upper edge, so that the band lies
#: in the flat part of the anti-aliasing filter (its pass band ends near 0.8 × the new Nyquist).
OVERSAMPLING = 3.0
#: Detrending choices (``None``: none).
DETREND = ("constant", "linear")


@dataclass(frozen=True, repr=False)
class Preprocessed:
    """Samples ready for :func:`modaluq.identify` and what was done to them."""

    y: np.ndarray                 #: (n_samples, n_outputs) after every step
    u: np.ndarray | None          #: (n_samples, n_inputs) after every step, or None
    fs: float                     #: sampling frequency after decimation, Hz
    fs_original: float            #: sampling frequency of the samples given, Hz
    decimation: int               #: integer factor (1: none)
    first_sample: int             #: index of the first sample used, in the samples given
    n_samples_used: int           #: samples of the window, before decimation
    frequency_range: tuple | None  #: (f_low, f_high) in Hz, the band of interest
    detrend: str | None           #: "constant", "linear" or None
    highpass_hz: float | None     #: corner of the high-pass filter, Hz
    steps: tuple = ()             #: what was done, in words, in order

    @property
    def n_samples(self) -> int:
        return int(self.y.shape[0])

    @property
    def start_s(self) -> float:
        """Start of the window in seconds from the first sample given."""
        return self.first_sample / self.fs_original

    @property
    def stop_s(self) -> float:
        """End of the window in seconds from the first sample given."""
        return (self.first_sample + self.n_samples_used) / self.fs_original

    def settings(self) -> dict:
        """The preprocessing as plain values (stored in ``Result.settings["preprocessing"]``)."""
        return {"fs_original": self.fs_original, "decimation": self.decimation, "fs": self.fs,
                "start_s": self.start_s, "stop_s": self.stop_s,
                "frequency_range": None if self.frequency_range is None else list(self.frequency_range),
                "detrend": self.detrend, "highpass_hz": self.highpass_hz, "steps": list(self.steps)}

    def __repr__(self) -> str:
        return (f"Preprocessed({self.n_samples} samples at {self.fs:g} Hz, "
                f"{'; '.join(self.steps) if self.steps else 'unchanged'})")


def decimation_factor(fs: float, f_high: float, *, oversampling: float = OVERSAMPLING) -> int:
    """The largest integer q with fs / q >= oversampling * f_high (1 if there is none).

    Examples
    --------
    >>> decimation_factor(425.0, 30.0)
    4
    >>> decimation_factor(50.0, 20.0)
    1
    """
    fs = check_sampling_frequency(fs)
    f_high = check_real("f_high", f_high, low=0, low_open=True)
    oversampling = check_real("oversampling", oversampling, low=2, low_open=True)
    return max(1, int(math.floor(fs / (oversampling * f_high) + 1e-9)))


def _frequency_range(frequency_range, fs):
    if frequency_range is None:
        return None
    try:
        lo, hi = frequency_range
    except (TypeError, ValueError):
        raise TypeError(f"frequency_range must be a pair (f_low, f_high) in Hz; got {frequency_range!r}") from None
    lo = check_real("frequency_range[0]", lo, low=0)
    hi = check_real("frequency_range[1]", hi, low=0, low_open=True)
    if not lo < hi:
        raise ValueError(f"frequency_range must have f_low < f_high; got ({lo:g}, {hi:g}) Hz")
    if hi >= fs / 2:
        raise ValueError(f"frequency_range upper edge {hi:g} Hz must be below the Nyquist frequency "
                         f"fs/2 = {fs / 2:g} Hz")
    return (lo, hi)


def preprocess(y, u=None, *, fs, frequency_range=None, start=None, stop=None, decimate=None,
               detrend=None, highpass=None) -> Preprocessed:
    """Window, detrend, high-pass and decimate a record for identification.

    Parameters
    ----------
    y : array_like, shape (n_samples, n_outputs)
        Outputs.
    u : array_like, shape (n_samples, n_inputs), optional
        Inputs; treated exactly like ``y``.
    fs : float
        Sampling frequency of the samples given, Hz.
    frequency_range : (float, float), optional
        Band of interest (f_low, f_high) in Hz, below fs/2. It sets the automatic decimation
        (``decimate=None``) and is kept for the settings and the stabilization diagram.
    start, stop : float, optional
        Window in seconds from the first sample (default: the whole record).
    decimate : int, optional
        Integer decimation factor. Default: :func:`decimation_factor` of the band's upper edge
        when ``frequency_range`` is given, else 1 (none).
    detrend : {"constant", "linear", None}
        Remove each channel's mean or least-squares line before filtering (default None; the
        identification removes the mean anyway).
    highpass : float, optional
        Corner frequency in Hz of a 4th-order zero-phase Butterworth high-pass (default none),
        e.g. against drift below the band.

    Returns
    -------
    Preprocessed

    Examples
    --------
    >>> import numpy as np
    >>> y = np.random.default_rng(0).standard_normal((42_500, 3))
    >>> p = preprocess(y, fs=425.0, frequency_range=(10.0, 30.0), start=10.0)
    >>> p.decimation, p.fs, p.n_samples
    (4, 106.25, 9563)
    """
    fs = check_sampling_frequency(fs)
    y = as_samples(y, "y")
    u = as_samples(u, "u", allow_none=True)
    if u is not None and u.shape[0] != y.shape[0]:
        raise ValueError(f"u must have as many samples as y ({y.shape[0]}); got {u.shape[0]}")
    band = _frequency_range(frequency_range, fs)
    n = y.shape[0]
    duration = n / fs
    t0 = check_real("start", start, low=0, allow_none=True)
    t1 = check_real("stop", stop, low=0, low_open=True, allow_none=True)
    first = 0 if t0 is None else int(round(t0 * fs))
    last = n if t1 is None else min(n, int(round(t1 * fs)))
    if first >= n:
        raise ValueError(f"start = {t0:g} s is at or after the end of the record ({duration:g} s)")
    if last <= first:
        raise ValueError(f"stop must be after start; got start = {first / fs:g} s, stop = {last / fs:g} s")
    steps = []
    if first > 0 or last < n:
        steps.append(f"window {first / fs:g}-{last / fs:g} s of {duration:g} s")
    y = y[first:last]
    u = None if u is None else u[first:last]

    if detrend is not None and detrend not in DETREND:
        raise ValueError(f"detrend must be one of {DETREND} or None; got {detrend!r}")
    if detrend is not None:
        from scipy.signal import detrend as sp_detrend

        y = sp_detrend(y, axis=0, type=detrend)
        u = None if u is None else sp_detrend(u, axis=0, type=detrend)
        steps.append(f"{detrend} detrend")

    hp = check_real("highpass", highpass, low=0, low_open=True, allow_none=True)
    if hp is not None:
        if hp >= fs / 2:
            raise ValueError(f"highpass must be below fs/2 = {fs / 2:g} Hz; got {hp:g}")
        if band is not None and hp >= band[0] and band[0] > 0:
            raise ValueError(f"highpass ({hp:g} Hz) must be below the band's lower edge ({band[0]:g} Hz)")
        from scipy.signal import butter, sosfiltfilt

        sos = butter(4, hp, btype="highpass", fs=fs, output="sos")
        y = sosfiltfilt(sos, y, axis=0)
        u = None if u is None else sosfiltfilt(sos, u, axis=0)
        steps.append(f"high-pass {hp:g} Hz (Butterworth, order 4, zero phase)")

    if decimate is None:
        q = 1 if band is None else decimation_factor(fs, band[1])
    else:
        q = check_integer("decimate", decimate, minimum=1)
        if band is not None and fs / q < 2.0 * band[1] * 1.25:
            raise ValueError(f"decimate = {q} leaves fs = {fs / q:g} Hz, too low for the band's upper edge "
                             f"{band[1]:g} Hz (keep fs/decimate >= 2.5 x {band[1]:g} Hz; use decimate <= "
                             f"{max(1, int(fs / (2.5 * band[1])))})")
    if q > 1:
        from scipy.signal import resample_poly

        if y.shape[0] // q < 2:
            raise ValueError(f"decimate = {q} leaves fewer than 2 samples of the {y.shape[0]} in the window")
        y = resample_poly(y, 1, q, axis=0)
        u = None if u is None else resample_poly(u, 1, q, axis=0)
        steps.append(f"decimated by {q}: {fs:g} -> {fs / q:g} Hz (polyphase anti-aliasing FIR)")
    return Preprocessed(y=np.ascontiguousarray(y, dtype=np.float64),
                        u=None if u is None else np.ascontiguousarray(u, dtype=np.float64),
                        fs=fs / q, fs_original=fs, decimation=q, first_sample=first,
                        n_samples_used=last - first, frequency_range=band, detrend=detrend, highpass_hz=hp,
                        steps=tuple(steps))
