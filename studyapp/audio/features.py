"""Speech features sampled at the motion frame rate (numpy/scipy only, no librosa).

Alignment: feature frame ``i`` describes the audio *centred* on time ``i / fps`` (sample
``round(i * sr / fps)``), the same instant motion frame ``i`` is shown. Windows reach half their length
into the future (the log-mel window is two motion frames long by default, so 1/fps seconds of look-ahead);
samples before the start and after the end of the clip count as silence. The frame count defaults to
``ceil(duration * fps)``: every frame whose time lies inside the clip.

Feature names, as used in model metadata (``studyapp.audio_features``) and by :func:`compute_features`:

* ``log_mel:N`` -- N log mel-band energies (natural log of power, HTK mel scale, Hann window);
* ``energy``    -- short-time energy, the mean square of the samples in a window one frame long;
* ``f0``        -- fundamental frequency in Hz by YIN (0 where unvoiced or silent).

>>> import numpy as np
>>> sr, fps = 16000, 15
>>> tone = np.sin(2 * np.pi * 200 * np.arange(sr) / sr)
>>> feats = compute_features(["log_mel:40", "energy", "f0"], tone, sr, fps)
>>> {k: v.shape for k, v in feats.items()}
{'log_mel:40': (15, 40), 'energy': (15, 1), 'f0': (15, 1)}
>>> round(float(np.median(feats["f0"])))
200
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

FEATURE_KINDS = ("log_mel", "energy", "f0")
_LOG_FLOOR = 1e-10


def _mono(audio: np.ndarray) -> np.ndarray:
    x = np.asarray(audio, dtype=np.float64)
    if x.ndim == 2:
        x = x.mean(axis=1)
    if x.ndim != 1:
        raise ValueError(f"audio must be (samples,) or (samples, channels), got shape {np.shape(audio)}")
    return x


def n_feature_frames(n_samples: int, sr: float, fps: float) -> int:
    """Frames whose time ``i / fps`` lies inside a clip of ``n_samples`` (``ceil(duration * fps)``)."""
    return int(math.ceil(n_samples * fps / sr - 1e-9))


def frame_centres(n_frames: int, sr: float, fps: float) -> np.ndarray:
    """Sample index at the centre of each frame: ``round(i * sr / fps)``."""
    return np.rint(np.arange(n_frames) * (sr / fps)).astype(np.int64)


def _frames(x: np.ndarray, centres: np.ndarray, length: int, lead: int) -> np.ndarray:
    """``(F, length)`` windows starting ``lead`` samples before each centre, zero outside the clip."""
    pad_l = lead
    pad_r = max(0, int(centres.max(initial=0)) - lead + length - x.size) if centres.size else 0
    padded = np.pad(x, (pad_l, pad_r + 1))
    view = np.lib.stride_tricks.sliding_window_view(padded, length)
    return view[centres]  # padded index c - lead + pad_l == c


def _resolve_frames(x: np.ndarray, sr: float, fps: float, n_frames: int | None) -> np.ndarray:
    if n_frames is None:
        n_frames = n_feature_frames(x.size, sr, fps)
    return frame_centres(n_frames, sr, fps)


def hz_to_mel(f: np.ndarray | float) -> np.ndarray:
    """HTK mel scale: ``2595 log10(1 + f / 700)``."""
    return 2595.0 * np.log10(1.0 + np.asarray(f, dtype=np.float64) / 700.0)


def mel_to_hz(m: np.ndarray | float) -> np.ndarray:
    """Inverse of :func:`hz_to_mel`."""
    return 700.0 * (10.0 ** (np.asarray(m, dtype=np.float64) / 2595.0) - 1.0)


def mel_filterbank(sr: float, n_fft: int, n_mels: int, fmin: float = 0.0, fmax: float | None = None) -> np.ndarray:
    """``(n_mels, n_fft // 2 + 1)`` triangular filters, peak 1, centres equally spaced in HTK mels.

    Filter ``m`` rises linearly from centre ``m - 1`` to centre ``m`` and falls to centre ``m + 1``
    (centres include the ``fmin`` and ``fmax`` edges), evaluated at the FFT bin frequencies.

    >>> fb = mel_filterbank(16000, 512, 40)
    >>> fb.shape, float(fb.max()) <= 1.0
    ((40, 257), True)
    """
    fmax = sr / 2.0 if fmax is None else float(fmax)
    if not 0 <= fmin < fmax <= sr / 2.0 + 1e-9:
        raise ValueError(f"need 0 <= fmin < fmax <= sr/2, got fmin={fmin}, fmax={fmax}, sr={sr}")
    edges = mel_to_hz(np.linspace(hz_to_mel(fmin), hz_to_mel(fmax), n_mels + 2))
    bins = np.arange(n_fft // 2 + 1) * (sr / n_fft)
    lo, mid, hi = edges[:-2, None], edges[1:-1, None], edges[2:, None]
    rising = (bins[None, :] - lo) / (mid - lo)
    falling = (hi - bins[None, :]) / (hi - mid)
    return np.clip(np.minimum(rising, falling), 0.0, None)


def log_mel_spectrogram(
    audio: np.ndarray,
    sr: float,
    fps: float,
    n_mels: int = 64,
    *,
    win_length: int | None = None,
    n_fft: int | None = None,
    fmin: float = 0.0,
    fmax: float | None = None,
    n_frames: int | None = None,
) -> np.ndarray:
    """``(F, n_mels)`` natural-log mel power, one row per motion frame.

    The Hann window is ``win_length`` samples (default two frame hops, so consecutive windows overlap
    by half and every sample is seen) centred on ``i / fps``; ``n_fft`` defaults to the next power of two.
    Power is ``|rfft|^2 / sum(window^2)`` so a full-scale sine gives similar values at any window length.
    """
    x = _mono(audio)
    centres = _resolve_frames(x, sr, fps, n_frames)
    win = int(win_length or 2 * round(sr / fps))
    n_fft = int(n_fft or 1 << (win - 1).bit_length())
    if n_fft < win:
        raise ValueError(f"n_fft ({n_fft}) must be at least win_length ({win})")
    window = np.hanning(win + 2)[1:-1]  # periodic-free Hann without zero end points
    frames = _frames(x, centres, win, win // 2) * window
    power = np.abs(np.fft.rfft(frames, n=n_fft, axis=1)) ** 2 / np.sum(window**2)
    mel = power @ mel_filterbank(sr, n_fft, n_mels, fmin, fmax).T
    return np.log(np.maximum(mel, _LOG_FLOOR))


def short_time_energy(audio: np.ndarray, sr: float, fps: float, *, n_frames: int | None = None) -> np.ndarray:
    """``(F,)`` mean square of the ``round(sr / fps)`` samples centred on each frame time.

    >>> import numpy as np
    >>> float(short_time_energy(np.full(3200, 0.5), 16000, 10)[1])
    0.25
    """
    x = _mono(audio)
    centres = _resolve_frames(x, sr, fps, n_frames)
    win = max(1, int(round(sr / fps)))
    # Cumulative sums give every window's sum at once, independent of window length.
    csum = np.concatenate([[0.0], np.cumsum(x * x)])
    start = np.clip(centres - win // 2, 0, x.size)
    stop = np.clip(centres - win // 2 + win, 0, x.size)
    return (csum[stop] - csum[start]) / win


def fundamental_frequency(
    audio: np.ndarray,
    sr: float,
    fps: float,
    fmin: float = 60.0,
    fmax: float = 500.0,
    *,
    threshold: float = 0.15,
    n_frames: int | None = None,
) -> np.ndarray:
    """``(F,)`` fundamental frequency in Hz by YIN (de Cheveigne & Kawahara 2002), 0 where unvoiced.

    Each frame integrates over ``ceil(sr / fmin)`` samples centred on ``i / fps``; the difference
    function comes from FFT cross-correlation and cumulative energies, so all frames are computed at
    once. The period is the first dip of the cumulative-mean-normalised difference below ``threshold``
    within ``[sr/fmax, sr/fmin]``, refined by parabolic interpolation.
    """
    x = _mono(audio)
    centres = _resolve_frames(x, sr, fps, n_frames)
    tau_min = max(2, int(math.floor(sr / fmax)))
    tau_max = int(math.ceil(sr / fmin))
    w = tau_max
    frames = _frames(x, centres, w + tau_max + 1, w // 2)  # (F, w + tau_max + 1)
    n = 1 << (frames.shape[1] + w).bit_length()
    head = frames[:, :w]
    # r[tau] = sum_j x_j x_{j+tau}, j < w
    r = np.fft.irfft(np.conj(np.fft.rfft(head, n, axis=1)) * np.fft.rfft(frames, n, axis=1), n, axis=1)[:, : tau_max + 2]
    csum = np.concatenate([np.zeros((frames.shape[0], 1)), np.cumsum(frames**2, axis=1)], axis=1)
    taus = np.arange(tau_max + 2)
    energy_tau = csum[:, taus + w] - csum[:, taus]  # sum_{j=tau}^{tau+w-1} x_j^2
    d = np.maximum(energy_tau[:, :1] + energy_tau - 2.0 * r, 0.0)
    cum = np.cumsum(d[:, 1:], axis=1)
    dn = np.ones_like(d)
    dn[:, 1:] = d[:, 1:] * taus[1:] / np.maximum(cum, 1e-300)

    inner = np.arange(tau_min, tau_max + 1)
    below = dn[:, inner] < threshold
    local_min = dn[:, inner] <= dn[:, inner + 1]
    candidate = below & local_min
    voiced = candidate.any(axis=1) & (energy_tau[:, 0] > 1e-8 * w)
    tau = inner[np.argmax(candidate, axis=1)]
    rows = np.arange(dn.shape[0])
    a, b, c = dn[rows, tau - 1], dn[rows, tau], dn[rows, tau + 1]
    denom = a - 2.0 * b + c
    shift = np.where(np.abs(denom) > 1e-12, 0.5 * (a - c) / np.where(denom == 0, 1.0, denom), 0.0)
    period = tau + np.clip(shift, -1.0, 1.0)
    return np.where(voiced, sr / period, 0.0)


def parse_feature(name: str) -> tuple[str, int]:
    """``"log_mel:64"`` -> ``("log_mel", 64)``; ``"energy"`` -> ``("energy", 1)``.

    Raises ``ValueError`` naming the known features for anything else.
    """
    kind, _, arg = name.strip().partition(":")
    kind = kind.strip().lower()
    if kind == "log_mel":
        if not arg.strip().isdigit() or int(arg) < 1:
            raise ValueError(f"feature {name!r}: log_mel needs a band count, e.g. 'log_mel:64'")
        return kind, int(arg)
    if kind in ("energy", "f0"):
        if arg:
            raise ValueError(f"feature {name!r}: {kind} takes no argument")
        return kind, 1
    raise ValueError(f"unknown audio feature {name!r}; known: log_mel:N, energy, f0")


def feature_dim(names: Sequence[str]) -> int:
    """Total width of the concatenated features ``names``."""
    return sum(parse_feature(n)[1] for n in names)


def compute_features(
    names: Sequence[str], audio: np.ndarray, sr: float, fps: float, *, n_frames: int | None = None
) -> dict[str, np.ndarray]:
    """Each named feature as a ``(F, D)`` float32 array, keyed by the name as given.

    ``audio`` is ``(samples,)`` or ``(samples, channels)`` (channels are averaged).
    """
    x = _mono(audio)
    if n_frames is None:
        n_frames = n_feature_frames(x.size, sr, fps)
    out: dict[str, np.ndarray] = {}
    for name in names:
        kind, dim = parse_feature(name)
        if kind == "log_mel":
            value = log_mel_spectrogram(x, sr, fps, dim, n_frames=n_frames)
        elif kind == "energy":
            value = short_time_energy(x, sr, fps, n_frames=n_frames)[:, None]
        else:
            value = fundamental_frequency(x, sr, fps, n_frames=n_frames)[:, None]
        out[name] = value.astype(np.float32)
    return out
