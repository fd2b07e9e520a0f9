"""The output spectrum behind a stabilization diagram: singular values of the cross spectral density."""

from __future__ import annotations

import math

import numpy as np

from .checks import as_samples, check_integer, check_sampling_frequency

__all__ = ["output_spectrum_singular_values"]


def output_spectrum_singular_values(y, fs: float, *, nperseg: int | None = None):
    """Singular values of the cross power spectral density matrix of the outputs (Welch).

    ``G(f)`` (``n_outputs × n_outputs``) is estimated with :func:`scipy.signal.csd` (Hann
    window, 50 % overlap, one-sided, density scaling), and its singular values at each frequency
    are returned, largest first. Their peaks indicate the modes; this is the background of the
    stabilization diagram (paper Figure 3).

    Parameters
    ----------
    y : array_like, shape (n_samples, n_outputs)
        Output samples (units u).
    fs : float
        Sampling frequency, Hz.
    nperseg : int, optional
        Samples per Welch segment; default the power of two nearest to ``n_samples / 64``
        (about 120 averaged segments), clipped to [256, 8192] and to ``n_samples``. The
        frequency resolution is ``fs / nperseg``.

    Returns
    -------
    frequency_hz : ndarray, shape (n_frequencies,)
    singular_values : ndarray, shape (n_frequencies, n_outputs)
        In u²/Hz, descending along the second axis.
    """
    import scipy.signal

    y = as_samples(y, "y")
    fs = check_sampling_frequency(fs)
    if not np.all(np.isfinite(y)):
        raise ValueError("y must be finite (NaN or Inf found)")
    n = y.shape[0]
    if nperseg is None:
        nperseg = int(2 ** round(math.log2(max(n / 64, 1))))
        nperseg = min(max(nperseg, 256), 8192, n)
    else:  # at most the record: scipy would shorten it silently
        nperseg = check_integer("nperseg", nperseg, minimum=2, maximum=n)
    y = y - y.mean(axis=0)
    freq, g = scipy.signal.csd(y[:, :, None], y[:, None, :], fs=fs, nperseg=int(nperseg), axis=0)
    # g has shape (n_freq, l, l)
    sv = np.linalg.svd(g, compute_uv=False)
    return freq, sv
