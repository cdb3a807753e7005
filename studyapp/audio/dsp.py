"""The three signal-processing routines a participant's session uses, in numpy: scipy is an experimenter's extra.

A participant's install (``pip install studyapp``) has no scipy (143 MB, README "Dependencies"), yet the
session resamples a clip to the audio device's rate and the scripted ``careful`` participant smooths and picks
peaks of a speech envelope. These are ports of scipy's algorithms with scipy's defaults, so results are the
same to floating-point rounding (``tests/audio/test_dsp.py`` compares them with scipy on random input):

- :func:`resample_poly`: ``scipy.signal.resample_poly`` (Kaiser window, beta 5, ``padtype="constant"``), as
  a polyphase filter so a 44.1 -> 48 kHz clip costs one pass over the output, not a 160-fold upsampling;
- :func:`gaussian_filter1d`: ``scipy.ndimage.gaussian_filter1d`` (``truncate=4``) for modes ``reflect`` and
  ``nearest``;
- :func:`find_peaks`: ``scipy.signal.find_peaks`` with ``height`` and ``distance`` (plateaus give their
  middle sample; closer peaks are removed lowest first).
"""
from __future__ import annotations

from math import ceil, gcd

import numpy as np

#: ndimage boundary mode -> the numpy.pad mode that extends a signal the same way
_PAD_MODE = {"reflect": "symmetric", "nearest": "edge"}


def gaussian_filter1d(x: np.ndarray, sigma: float, mode: str = "reflect", truncate: float = 4.0) -> np.ndarray:
    """``x`` (1-D) smoothed by a Gaussian of standard deviation ``sigma`` samples, cut at ``truncate`` sigmas.

    >>> gaussian_filter1d(np.array([0.0, 0.0, 1.0, 0.0, 0.0]), 1.0).round(3).tolist()
    [0.058, 0.242, 0.399, 0.242, 0.058]
    """
    if mode not in _PAD_MODE:
        raise ValueError(f"mode must be one of {', '.join(_PAD_MODE)}, got {mode!r}")
    x = np.asarray(x, dtype=np.float64)
    sigma = float(sigma)
    radius = int(truncate * sigma + 0.5)
    k = np.arange(-radius, radius + 1, dtype=np.float64)
    weights = np.exp(-0.5 / (sigma * sigma) * k * k)
    weights /= weights.sum()
    if x.size == 0 or radius == 0:
        return x.copy()
    padded = np.pad(x, radius, mode=_PAD_MODE[mode])
    return np.convolve(padded, weights[::-1], mode="valid")


def find_peaks(x: np.ndarray, height: float | None = None, distance: float | None = None) -> np.ndarray:
    """Indices of the local maxima of ``x`` (1-D) at least ``height`` high and ``distance`` samples apart.

    >>> find_peaks(np.array([0, 2, 0, 1, 1, 1, 0, 3, 0.0]), height=1.5).tolist()
    [1, 7]
    """
    x = np.asarray(x, dtype=np.float64)
    peaks = _local_maxima(x)
    if height is not None:
        peaks = peaks[x[peaks] >= height]
    if distance is not None and peaks.size > 1:
        if distance < 1:
            raise ValueError("distance must be at least 1")
        peaks = peaks[_keep_by_distance(peaks, x[peaks], distance)]
    return peaks


def _local_maxima(x: np.ndarray) -> np.ndarray:
    """Maxima and the middles of flat maxima (rising before, falling after); never the first or last sample."""
    out: list[int] = []
    i, last = 1, x.size - 1
    while i < last:
        if x[i - 1] < x[i]:
            ahead = i + 1
            while ahead < last and x[ahead] == x[i]:
                ahead += 1
            if x[ahead] < x[i]:
                out.append((i + ahead - 1) // 2)
                i = ahead
        i += 1
    return np.asarray(out, dtype=np.intp)


def _keep_by_distance(peaks: np.ndarray, priority: np.ndarray, distance: float) -> np.ndarray:
    """scipy's rule: from the highest peak down, each kept peak removes its neighbours closer than ``distance``."""
    d = ceil(distance)
    keep = np.ones(peaks.size, dtype=bool)
    order = np.argsort(priority)  # the same sort scipy uses, so equal heights are visited in the same order
    for i in range(peaks.size - 1, -1, -1):
        j = order[i]
        if not keep[j]:
            continue
        k = j - 1
        while k >= 0 and peaks[j] - peaks[k] < d:
            keep[k] = False
            k -= 1
        k = j + 1
        while k < peaks.size and peaks[k] - peaks[j] < d:
            keep[k] = False
            k += 1
    return keep


def _lowpass(n_taps: int, cutoff: float) -> np.ndarray:
    """scipy.signal.firwin(n_taps, cutoff) with a Kaiser window (beta 5): a windowed sinc, unit gain at 0 Hz."""
    m = np.arange(n_taps) - 0.5 * (n_taps - 1)
    h = cutoff * np.sinc(cutoff * m) * np.kaiser(n_taps, 5.0)
    return h / h.sum()


def resample_poly(x: np.ndarray, up: int, down: int, axis: int = 0) -> np.ndarray:
    """``x`` resampled by ``up / down`` along ``axis``: zero-stuffed, low-pass filtered, decimated.

    Computed in ``x``'s floating dtype (float32 stays float32, as in scipy).

    >>> resample_poly(np.ones(48, np.float32), 1, 3).shape
    (16,)
    """
    x = np.asarray(x)
    if x.dtype.kind != "f":
        x = x.astype(np.float64)
    g = gcd(int(up), int(down))
    up, down = int(up) // g, int(down) // g
    if up == down == 1:
        return x.copy()
    x = np.moveaxis(x, axis, 0)
    n_in = x.shape[0]
    n_out = (n_in * up) // down + bool((n_in * up) % down)
    max_rate = max(up, down)
    half_len = 10 * max_rate
    h = (_lowpass(2 * half_len + 1, 1.0 / max_rate).astype(x.dtype)) * x.dtype.type(up)
    # scipy pads the filter so output sample 0 sits at the filter's centre, then drops the leading samples
    pre_pad = down - half_len % down
    h = np.concatenate([np.zeros(pre_pad, x.dtype), h])
    first = (half_len + pre_pad) // down
    # output n reads the zero-stuffed input at t = (first + n) * down: y[n] = sum_i h[t - i*up] * x[i]
    t = (first + np.arange(n_out)) * down
    y = np.empty((n_out,) + x.shape[1:], dtype=x.dtype)
    n_taps = -(-h.size // up)  # taps per phase
    h = np.concatenate([h, np.zeros(n_taps * up - h.size, x.dtype)])
    # zeros around the input stand for scipy's constant (0) padding: row r of `padded` is input r - n_taps
    padded = np.concatenate([np.zeros((n_taps,) + x.shape[1:], x.dtype), x,
                             np.zeros((2 * n_taps + 2,) + x.shape[1:], x.dtype)])
    windows = np.lib.stride_tricks.sliding_window_view(padded, n_taps, axis=0)  # (rows, ..., n_taps), no copy
    for phase in range(up):
        # gcd(up, down) == 1: one output in every `up` has this phase, and its input moves on by `down`
        start = next((n for n in range(min(up, n_out)) if t[n] % up == phase), None)
        if start is None:
            continue
        count = len(range(start, n_out, up))
        # taps phase, phase+up, ... read inputs base, base-1, ...: a reversed window ending at base
        first_row = t[start] // up + 1
        rows = windows[first_row:first_row + down * (count - 1) + 1:down]
        y[start::up] = rows @ h[phase::up][::-1]
    return np.moveaxis(y, 0, axis)
