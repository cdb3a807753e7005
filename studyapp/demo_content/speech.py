"""Speech-like audio for the demo study, synthesized from a seed (no recordings to license).

Each clip is a sequence of phrases separated by pauses; each phrase a run of syllables at 3-5 per second.
A syllable is an optional consonant-like noise burst followed by a voiced vowel: harmonics of a pitch
contour (declining over the phrase, with accents on stressed syllables) shaped by three formant resonances
that glide from vowel to vowel. It is not intelligible, but it has the rhythm, intonation and timbre that
viewers use to judge whether gestures are in time with speech, and that the energy envelope picks up.

>>> clip, script = synthesize_speech(SPEAKERS["spk1"], seed=1, duration_s=2.0)
>>> clip.sample_rate, clip.duration, 100 <= min(s.f0 for s in script.syllables) <= 220
(16000, 2.0, True)
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from studyapp.audio.wav import AudioClip

SAMPLE_RATE = 16000

#: (F1, F2, F3) in Hz of a few vowels of an adult male voice (Peterson & Barney averages, rounded).
VOWELS: dict[str, tuple[float, float, float]] = {
    "a": (730.0, 1090.0, 2440.0),
    "e": (530.0, 1840.0, 2480.0),
    "i": (270.0, 2290.0, 3010.0),
    "o": (570.0, 840.0, 2410.0),
    "u": (300.0, 870.0, 2240.0),
    "@": (500.0, 1500.0, 2500.0),
}
_BANDWIDTHS = np.array([90.0, 110.0, 170.0])


@dataclass(frozen=True)
class Voice:
    """A synthetic speaker: pitch register and vocal-tract size.

    Attributes
    ----------
    name:
        Speaker id used in file names and designs.
    f0_hz:
        Typical pitch; phrases decline around it and accents rise above it.
    f0_limits:
        Hard limits of the pitch contour in Hz.
    formant_scale:
        Multiplies every formant (shorter vocal tract -> higher formants).
    """

    name: str
    f0_hz: float
    f0_limits: tuple[float, float]
    formant_scale: float


SPEAKERS: dict[str, Voice] = {
    "spk1": Voice("spk1", 118.0, (100.0, 160.0), 1.0),
    "spk2": Voice("spk2", 182.0, (150.0, 220.0), 1.14),
}


@dataclass(frozen=True)
class Syllable:
    start: float
    end: float
    stressed: bool
    f0: float
    vowel: str


@dataclass(frozen=True)
class Script:
    """The timing of a synthesized clip: phrases as (start, end) and their syllables."""

    phrases: list[tuple[float, float]] = field(default_factory=list)
    syllables: list[Syllable] = field(default_factory=list)


def _plan(rng: np.random.Generator, voice: Voice, duration_s: float) -> Script:
    """Lay out phrases and syllables: 0.3-0.5 s lead-in, phrases of 5-12 syllables, 0.35-0.8 s pauses."""
    phrases, syllables = [], []
    t = rng.uniform(0.3, 0.5)
    while True:
        n = int(rng.integers(5, 13))
        durs = rng.uniform(0.2, 0.31, size=n)
        if t + durs.sum() > duration_s - 0.35:
            # The last phrase is shortened to fit, so every clip ends in silence.
            keep = np.flatnonzero(np.cumsum(durs) <= duration_s - 0.35 - t)
            if keep.size < 3:
                break
            durs = durs[: keep[-1] + 1]
            n = durs.size
        # Phrase-initial stress, then roughly every third syllable: the rhythm of stress-timed speech.
        stressed = np.zeros(n, bool)
        stressed[0] = rng.random() < 0.7
        k = int(rng.integers(1, 3))
        while k < n:
            stressed[k] = True
            k += int(rng.integers(2, 5))
        start = t
        decline = np.linspace(1.08, 0.9, n)
        for i in range(n):
            f0 = voice.f0_hz * decline[i] * (1.22 if stressed[i] else 1.0) * rng.uniform(0.97, 1.03)
            f0 = float(np.clip(f0, *voice.f0_limits))
            vowel = str(rng.choice(list(VOWELS)))
            syllables.append(Syllable(t, t + float(durs[i]), bool(stressed[i]), f0, vowel))
            t += float(durs[i])
        phrases.append((start, t))
        t += rng.uniform(0.35, 0.8)
        if t > duration_s - 1.2:
            break
    return Script(phrases, syllables)


def _smooth(x: np.ndarray, width: int) -> np.ndarray:
    """Moving average along axis 0 (edge-padded), for gliding pitch and formant tracks."""
    if width <= 1:
        return x
    pad = width // 2
    xp = np.pad(x, [(pad, width - 1 - pad)] + [(0, 0)] * (x.ndim - 1), mode="edge")
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), xp]), axis=0)
    return (c[width:] - c[:-width]) / width


def synthesize_speech(voice: Voice, seed: int, duration_s: float = 10.0,
                      sample_rate: int = SAMPLE_RATE) -> tuple[AudioClip, Script]:
    """A speech-like clip of exactly ``duration_s`` seconds and the script it follows.

    Deterministic for a given seed. Peak level is -2 dBFS; pauses are silent apart from a -70 dB noise floor.
    """
    rng = np.random.default_rng(seed)
    script = _plan(rng, voice, duration_s)
    n = int(round(duration_s * sample_rate))
    t = np.arange(n) / sample_rate

    # Per-sample tracks: pitch, formants and voiced amplitude, piecewise per syllable, then smoothed.
    f0 = np.full(n, voice.f0_hz * 0.9)
    formants = np.tile(np.array(VOWELS["@"]) * voice.formant_scale, (n, 1))
    amp = np.zeros(n)
    noise_env = np.zeros(n)
    for syl in script.syllables:
        a, b = int(syl.start * sample_rate), int(syl.end * sample_rate)
        f0[a:b] = syl.f0
        formants[a:b] = np.array(VOWELS[syl.vowel]) * voice.formant_scale
        length = b - a
        # Consonant-like onset: 20-50 ms of noise, then the vowel rises, holds and decays.
        burst = int(rng.uniform(0.02, 0.05) * sample_rate) if rng.random() < 0.75 else 0
        u = np.linspace(0.0, 1.0, length - burst, endpoint=False)
        shape = np.sin(np.pi * np.clip(u / 0.35, 0, 1) / 2) ** 2 * np.cos(np.pi * np.clip((u - 0.55) / 0.45, 0, 1) / 2) ** 2
        level = 1.0 if syl.stressed else rng.uniform(0.4, 0.65)
        amp[a + burst:b] = level * shape
        if burst:
            noise_env[a:a + burst] = 0.25 * level * np.hanning(burst)
    f0 = _smooth(f0, int(0.04 * sample_rate))
    formants = _smooth(formants, int(0.03 * sample_rate))
    # A slow 5 Hz, 1 % vibrato keeps sustained vowels from sounding like a pure buzzer.
    f0 = f0 * (1.0 + 0.01 * np.sin(2 * np.pi * 5.0 * t + rng.uniform(0, 2 * np.pi)))
    phase = 2 * np.pi * np.cumsum(f0) / sample_rate

    voiced = np.zeros(n)
    nyquist_guard = 0.45 * sample_rate
    for k in range(1, int(nyquist_guard / voice.f0_limits[0]) + 1):
        fk = k * f0
        live = fk < nyquist_guard
        if not live.any():
            break
        # Cascade of three second-order resonators (unit gain at 0 Hz, peaks of F/B at each formant), as in a
        # Klatt-style formant synthesizer, on a source falling 6 dB per octave.
        gain = np.ones(n)
        for j in range(3):
            fj = formants[:, j]
            gain *= fj ** 2 / np.sqrt((fj ** 2 - fk ** 2) ** 2 + (_BANDWIDTHS[j] * fk) ** 2)
        voiced += np.where(live, gain / k, 0.0) * np.sin(k * phase)
    voiced /= np.abs(voiced).max() + 1e-12

    noise = rng.standard_normal(n)
    noise = np.diff(noise, prepend=0.0) * 0.5  # first difference: a hiss-like, high-tilted spectrum
    x = voiced * amp + noise * noise_env + 10 ** (-70 / 20) * rng.standard_normal(n)
    x *= 10 ** (-2 / 20) / np.abs(x).max()
    return AudioClip(x.astype(np.float32), sample_rate, f"synthetic speech {voice.name} seed {seed}"), script
