"""Audio onsets: where new sounds start (syllables, stressed words), the audio side of beat alignment.

Spectral flux on a log-mel spectrogram with librosa's default peak picking (``librosa.onset.onset_detect``),
in numpy, so the Beat Align Score of gesture papers (BEAT, EMAGE), computed there with librosa, can be
computed here without it:

1. log-mel power (:func:`studyapp.audio.features.log_mel_spectrogram`, 64 bands, frames every
   :data:`HOP_S` = 10 ms, each window 20 ms), in dB, floored 80 dB below the clip's loudest value;
2. onset strength: the mean over bands of the half-wave rectified increase from the previous frame,
   scaled to 0..1 over the clip;
3. a frame is an onset when it is the largest value in the 30 ms before it, at least 0.07 above the
   mean of the 100 ms either side, and at least 30 ms after the previous onset;
4. and (unlike librosa) the frame is no more than :data:`GATE_DB` = 40 dB quieter than the clip's loudest
   frame: background noise rising and falling between words is not a sound starting.

Onset times are frame times (``i * HOP_S``). A silent clip has no onsets.

>>> sr = 16000
>>> x = np.zeros(sr * 2, np.float32)
>>> n = np.arange(int(0.2 * sr))
>>> pluck = 0.5 * np.sin(2 * np.pi * 220 * n / sr) * np.exp(-n / (0.03 * sr))   # sharp attack, smooth decay
>>> for t0 in (0.5, 1.2):
...     x[int(t0 * sr):int(t0 * sr) + n.size] = pluck
>>> [round(float(t), 2) for t in onset_times(x, sr)]
[0.5, 1.2]
"""
from __future__ import annotations

import numpy as np

from studyapp.audio.features import log_mel_spectrogram

#: Onset-strength frame spacing in seconds.
HOP_S = 0.01
#: An onset frame is at most this many dB quieter (summed mel power) than the clip's loudest frame.
GATE_DB = 40.0
_TOP_DB = 80.0
_N_MELS = 64
_PRE_MAX_S, _PRE_AVG_S, _POST_AVG_S, _WAIT_S, _DELTA = 0.03, 0.10, 0.10, 0.03, 0.07


def _mel_db(audio: np.ndarray, sr: float) -> np.ndarray:
    x = np.asarray(audio, dtype=np.float64)
    if x.ndim == 2:
        x = x.mean(axis=1)
    if x.size == 0:
        return np.zeros((0, _N_MELS))
    return log_mel_spectrogram(x, sr, 1.0 / HOP_S, _N_MELS) * (10.0 / np.log(10.0))


def onset_strength(audio: np.ndarray, sr: float) -> np.ndarray:
    """``(F,)`` spectral-flux onset strength, 0..1, one value per :data:`HOP_S` frame (see the module notes)."""
    return _strength(_mel_db(audio, sr))


def _strength(db: np.ndarray) -> np.ndarray:
    if len(db) == 0:
        return np.zeros(0)
    db = np.maximum(db, db.max() - _TOP_DB)
    flux = np.zeros(len(db))
    if len(db) > 1:
        flux[1:] = np.maximum(db[1:] - db[:-1], 0.0).mean(axis=1)
    span = flux.max() - flux.min() if flux.size else 0.0
    return (flux - flux.min()) / span if span > 0 else np.zeros_like(flux)


def pick_peaks(strength: np.ndarray, hop_s: float = HOP_S) -> np.ndarray:
    """Indices of the onset peaks of ``strength`` by librosa's default rule (see the module notes)."""
    s = np.asarray(strength, dtype=np.float64)
    n = s.size
    if n == 0:
        return np.zeros(0, np.int64)
    pre_max = max(1, int(round(_PRE_MAX_S / hop_s)))
    pre_avg = int(round(_PRE_AVG_S / hop_s))
    post_avg = int(round(_POST_AVG_S / hop_s)) + 1
    wait = int(round(_WAIT_S / hop_s))
    padded = np.pad(s, (pre_max, 0), constant_values=-np.inf)
    local_max = s >= np.lib.stride_tricks.sliding_window_view(padded, pre_max + 1).max(axis=1)
    csum = np.concatenate([[0.0], np.cumsum(s)])
    lo = np.clip(np.arange(n) - pre_avg, 0, n)
    hi = np.clip(np.arange(n) + post_avg, 0, n)
    mean = (csum[hi] - csum[lo]) / (hi - lo)
    candidates = np.flatnonzero(local_max & (s >= mean + _DELTA) & (s > 0))
    out, last = [], -np.inf
    for i in candidates:  # the wait rule depends on the previous accepted onset: a short sequential pass
        if i - last > wait:
            out.append(i)
            last = i
    return np.asarray(out, np.int64)


def onset_times(audio: np.ndarray, sr: float) -> np.ndarray:
    """Onset times in seconds of ``audio`` (``(samples,)`` or ``(samples, channels)``) at ``sr`` Hz."""
    db = _mel_db(audio, sr)
    if len(db) == 0:
        return np.zeros(0)
    peaks = pick_peaks(_strength(db))
    loud = 10.0 * np.log10(np.maximum(np.power(10.0, db / 10.0).sum(axis=1), 1e-30))
    return peaks[loud[peaks] >= loud.max() - GATE_DB] * HOP_S


__all__ = ["GATE_DB", "HOP_S", "onset_strength", "onset_times", "pick_peaks"]
