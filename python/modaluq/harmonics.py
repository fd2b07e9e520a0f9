"""Is a selected mode a structural mode or a harmonic of the excitation (a rotating machine)?

SSI identifies a sinusoid in the response as an undamped pole, and an operating turbine or pump
puts several in the band. The test here is the kurtosis of the response band-pass filtered
around the mode (Jacobsen, Andersen & Brincker, "Eliminating the influence of harmonic
components in operational modal analysis", IMAC 2007): a structural mode driven by broadband
forces is a narrow-band Gaussian process, kurtosis 3; a sinusoid has kurtosis 1.5. A mode whose
filtered response has kurtosis below ``HARMONIC_KURTOSIS`` in the channel where it is strongest
is flagged as a possible harmonic.

The kurtosis of a filtered record is itself uncertain: its standard error is about
sqrt(24 / (T B)) for a record of T seconds through a filter B Hz wide (0.38 for a 0.5 %-damped
mode at 1.17 Hz in an hour, 0.56 for 3.2 Hz in ten minutes), so a value of 2.5 alone does not
tell a sinusoid from a mode. A nearly undamped pole with a kurtosis below
``LIGHT_DAMPING_KURTOSIS`` is therefore flagged only as a member of a **family**: at an integer
multiple (2 to 10, within ``FAMILY_TOLERANCE``) of a frequency flagged on its kurtosis alone, as
the orders of a rotor's speed are. On the wind turbine, 1.606 and 3.217 Hz are 2 and 4 times the
0.803 Hz line; the 1.17 Hz mode of the simulated bridge (ξ 0.4 %, kurtosis 2.54) has no such
line and is not flagged.
"""

from __future__ import annotations

import numpy as np

from .checks import as_samples, check_real, check_sampling_frequency

__all__ = ["FAMILY_TOLERANCE", "HARMONIC_KURTOSIS", "LIGHT_DAMPING", "LIGHT_DAMPING_KURTOSIS", "harmonic_kurtosis",
           "possible_harmonics"]

#: Kurtosis below which the filtered response looks like a sinusoid (1.5) rather than a random
#: narrow-band process (3); halfway, with room for the noise of a kurtosis estimate.
HARMONIC_KURTOSIS = 2.2
#: A nearly undamped pole (damping ratio below LIGHT_DAMPING) is flagged already below this kurtosis:
#: a harmonic next to a structural mode shares its band and lifts the kurtosis towards 3.
LIGHT_DAMPING_KURTOSIS = 2.6
LIGHT_DAMPING = 0.005
#: Relative tolerance for a frequency to be an integer multiple of a flagged one.
FAMILY_TOLERANCE = 0.005


def harmonic_kurtosis(y, fs: float, frequencies_hz, *, relative_bandwidth: float = 0.02) -> np.ndarray:
    """Kurtosis of the response filtered around each frequency, in its strongest channel.

    Parameters
    ----------
    y : array_like, shape (n_samples, n_outputs)
        The outputs the modes were identified from (after any decimation: ``fs`` is their rate).
    fs : float
        Sampling frequency of ``y``, Hz.
    frequencies_hz : array_like
        Mode frequencies, Hz.
    relative_bandwidth : float
        Half-width of the band-pass filter relative to the frequency (default 0.02: ±2 %).

    Returns
    -------
    ndarray
        One kurtosis per frequency (Pearson's: 3 for a Gaussian, 1.5 for a sinusoid); NaN where
        the band does not fit below fs/2.
    """
    from scipy.signal import butter, sosfiltfilt
    from scipy.stats import kurtosis

    fs = check_sampling_frequency(fs)
    y = as_samples(y, "y")
    bw = check_real("relative_bandwidth", relative_bandwidth, low=0, low_open=True, high=0.5)
    out = []
    for f in np.atleast_1d(np.asarray(frequencies_hz, dtype=float)):
        lo, hi = f * (1 - bw), f * (1 + bw)
        if not (0 < lo and hi < fs / 2):
            out.append(np.nan)
            continue
        sos = butter(4, [lo, hi], btype="bandpass", fs=fs, output="sos")
        z = sosfiltfilt(sos, y - y.mean(axis=0), axis=0)
        edge = min(z.shape[0] // 10, int(5 * fs / (hi - lo)))  # leave out the filter's start and end
        z = z[edge:z.shape[0] - edge] if z.shape[0] > 2 * edge + 10 else z
        strongest = int(np.argmax(np.var(z, axis=0)))
        out.append(float(kurtosis(z[:, strongest], fisher=False)))
    return np.asarray(out)


def possible_harmonics(y, fs: float, frequencies_hz, damping_ratio=None, *, threshold: float = HARMONIC_KURTOSIS,
                       relative_bandwidth: float = 0.02, kurtosis=None) -> np.ndarray:
    """Which frequencies look like harmonics: kurtosis of the filtered response below ``threshold``;
    or (when ``damping_ratio`` is given) below LIGHT_DAMPING_KURTOSIS for a pole with a damping
    ratio below LIGHT_DAMPING that lies at 2 to 10 times a frequency flagged by the first rule
    (within FAMILY_TOLERANCE). A flag to look at the spectrum and the machine's speed, not a
    verdict: the kurtosis of a short record is itself uncertain. ``kurtosis``: the values of
    :func:`harmonic_kurtosis` for these frequencies when already computed (they are not again).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> t = np.arange(60_000) / 50.0
    >>> y = rng.standard_normal((60_000, 1)) + 3 * np.sin(2 * np.pi * 7.0 * t)[:, None]
    >>> possible_harmonics(y, 50.0, [7.0, 12.0]).tolist()
    [True, False]
    """
    threshold = check_real("threshold", threshold, low=1, high=3)
    if kurtosis is None:
        kurtosis = harmonic_kurtosis(y, fs, frequencies_hz, relative_bandwidth=relative_bandwidth)
    k = np.asarray(kurtosis, dtype=float)
    flag = np.isfinite(k) & (k < threshold)
    if damping_ratio is not None:
        f = np.atleast_1d(np.asarray(frequencies_hz, dtype=float))
        xi = np.abs(np.atleast_1d(np.asarray(damping_ratio, dtype=float)))
        fundamentals = f[flag]
        ratio = f[:, None] / fundamentals[None, :] if fundamentals.size else np.zeros((f.size, 0))
        multiple = np.round(ratio)
        family = np.any((multiple >= 2) & (multiple <= 10) & (np.abs(ratio / np.maximum(multiple, 1) - 1)
                                                               <= FAMILY_TOLERANCE), axis=1)
        flag |= np.isfinite(k) & (k < LIGHT_DAMPING_KURTOSIS) & (xi < LIGHT_DAMPING) & family
    return flag
