"""Onset detection finds sounds placed at known times, and nothing in silence or a steady tone."""
from __future__ import annotations

import numpy as np

from studyapp.audio.onsets import HOP_S, onset_strength, onset_times, pick_peaks

SR = 16000


def _plucks(times: list[float], seconds: float, noise: float = 1e-3, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = rng.normal(0, noise, int(seconds * SR))
    n = np.arange(int(0.25 * SR))
    for i, t0 in enumerate(times):
        f = 150 + 40 * i  # a different pitch each, like syllables
        burst = 0.4 * np.sin(2 * np.pi * f * n / SR) * np.exp(-n / (0.05 * SR))
        start = int(round(t0 * SR))
        x[start:start + n.size] += burst[: x.size - start]
    return x.astype(np.float32)


def test_onsets_are_found_at_the_times_sounds_start():
    times = [0.4, 0.9, 1.55, 2.3, 2.75, 3.6]
    found = onset_times(_plucks(times, 4.2), SR)
    assert len(found) == len(times)
    assert np.abs(found - np.array(times)).max() <= 2 * HOP_S   # within 20 ms


def test_silence_and_a_steady_tone_have_no_onsets_after_the_start():
    assert onset_times(np.zeros(SR * 2, np.float32), SR).size == 0
    t = np.arange(SR * 2) / SR
    tone = 0.3 * np.sin(2 * np.pi * 200 * t)
    found = onset_times(tone, SR)
    assert np.all(found <= 0.05)  # only the tone's start


def test_peak_picking_follows_the_wait_and_threshold_rules():
    s = np.zeros(100)
    s[[10, 12, 40, 70]] = [1.0, 0.9, 0.05, 0.8]   # 12 is within 30 ms of 10; 40 is below mean + 0.07
    assert pick_peaks(s).tolist() == [10, 70]
    assert onset_strength(np.zeros(0), SR).size == 0
