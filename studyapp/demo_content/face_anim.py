"""ARKit facial animation for the demo clips, derived from the speech energy envelope.

The mouth follows the voice (jaw and lips open with energy, a little rounding and stretching varying
from syllable to syllable), the eyes blink every few seconds, and the brows lift and the mouth smiles
now and then on the strongest stresses. Identical for all three conditions of a clip, as in the study.

>>> import numpy as np
>>> e = np.zeros(90); e[30:60] = 1.0
>>> face = speech_face(e, fps=30.0, seed=3)
>>> face.n_frames, bool(face.weight("jawOpen")[45] > face.weight("jawOpen")[5])
(90, True)
"""
from __future__ import annotations

import numpy as np

from studyapp.demo_content.signals import smooth, stress_peaks
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_INDEX, N_ARKIT


def _blink_shape(t: np.ndarray, start: float) -> np.ndarray:
    """One blink: closes in ~80 ms, opens in ~170 ms (eyelids open slower than they close)."""
    u = t - start
    close = np.clip(u / 0.08, 0.0, 1.0)
    opening = np.clip((u - 0.1) / 0.17, 0.0, 1.0)
    return np.where(u < 0.1, np.sin(close * np.pi / 2) ** 2, np.cos(opening * np.pi / 2) ** 2) * (u >= 0)


def _pulse(t: np.ndarray, center: float, rise: float, hold: float, fall: float) -> np.ndarray:
    """Smooth on-hold-off envelope in [0, 1]: raised-cosine edges around a plateau."""
    a = np.clip((t - (center - rise)) / rise, 0.0, 1.0)
    b = np.clip((t - (center + hold)) / fall, 0.0, 1.0)
    return np.sin(a * np.pi / 2) ** 2 * np.cos(b * np.pi / 2) ** 2


def speech_face(energy: np.ndarray, fps: float, seed: int) -> FaceAnimation:
    """A :class:`FaceAnimation` with ``len(energy)`` frames driven by the frame-aligned energy envelope."""
    rng = np.random.default_rng([seed, 2])
    e = np.asarray(energy, dtype=np.float64)
    n = e.size
    t = np.arange(n) / fps
    w = np.zeros((n, N_ARKIT))

    def put(name: str, values: np.ndarray) -> None:
        w[:, ARKIT_INDEX[name.lower()]] += values

    # Mouth: the jaw opens with loudness (compressed so quiet syllables still move the lips); rounding
    # (funnel/pucker) and spreading (stretch) alternate slowly like changing vowels.
    open_ = smooth(e, fps, 0.025) ** 0.7
    vowel = smooth(rng.standard_normal(n), fps, 0.12)
    vowel = vowel / (np.abs(vowel).max() + 1e-9)
    put("jawOpen", 0.04 + 0.5 * open_)
    put("mouthClose", 0.08 * (1.0 - open_) * (e.max(initial=0) > 0))
    put("mouthLowerDownLeft", 0.25 * open_)
    put("mouthLowerDownRight", 0.25 * open_)
    put("mouthUpperUpLeft", 0.12 * open_)
    put("mouthUpperUpRight", 0.12 * open_)
    put("mouthFunnel", 0.25 * open_ * np.clip(vowel, 0, None))
    put("mouthPucker", 0.2 * open_ * np.clip(vowel - 0.3, 0, None))
    put("mouthStretchLeft", 0.15 * open_ * np.clip(-vowel, 0, None))
    put("mouthStretchRight", 0.15 * open_ * np.clip(-vowel, 0, None))

    # Blinks every 2-5 s (healthy adults blink ~15-20 times a minute while talking, a little irregularly).
    blink = np.zeros(n)
    tb = rng.uniform(0.6, 2.0)
    while tb < t[-1] if n else False:
        blink = np.maximum(blink, _blink_shape(t, tb))
        tb += rng.uniform(2.0, 5.0)
    put("eyeBlinkLeft", 0.95 * blink)
    put("eyeBlinkRight", 0.95 * blink)
    put("eyeSquintLeft", 0.06 + 0.1 * blink)
    put("eyeSquintRight", 0.06 + 0.1 * blink)

    # Brow raises on the strongest stresses; a smile on one or two of them.
    peaks = stress_peaks(e, fps, min_height=0.6, min_gap_s=1.0)
    strongest = peaks[np.argsort(-e[peaks])][: max(1, peaks.size // 2)] if peaks.size else peaks
    brow = np.zeros(n)
    for p in np.sort(strongest):
        brow = np.maximum(brow, rng.uniform(0.3, 0.55) * _pulse(t, p / fps, 0.15, 0.2, 0.35))
    put("browInnerUp", brow)
    put("browOuterUpLeft", 0.8 * brow)
    put("browOuterUpRight", 0.75 * brow)
    smile = np.zeros(n)
    for p in rng.permutation(peaks)[: int(rng.integers(1, 3))] if peaks.size else []:
        smile = np.maximum(smile, rng.uniform(0.3, 0.5) * _pulse(t, p / fps, 0.3, rng.uniform(0.8, 1.6), 0.5))
    put("mouthSmileLeft", smile)
    put("mouthSmileRight", 0.9 * smile)
    put("cheekSquintLeft", 0.4 * smile)
    put("cheekSquintRight", 0.35 * smile)
    return FaceAnimation(np.clip(w, 0.0, 1.0).astype(np.float32), fps, source=f"demo face (seed {seed})")
