"""Audio features against analytic signals and independently written formulas."""
from __future__ import annotations

import math

import numpy as np
import pytest

from studyapp.audio import features as F

SR = 16000
FPS = 15


def tone(freq: float, seconds: float = 2.0, amp: float = 0.5, sr: int = SR) -> np.ndarray:
    return amp * np.sin(2 * np.pi * freq * np.arange(int(seconds * sr)) / sr)


@pytest.mark.parametrize("freq", [200.0, 110.0, 317.5, 440.0])
def test_f0_of_pure_tone(freq: float) -> None:
    f0 = F.fundamental_frequency(tone(freq), SR, FPS)
    inner = f0[1:-1]  # the first and last windows are half silence
    assert np.all(np.abs(inner - freq) <= 2.0), inner


def test_f0_of_harmonic_voice_like_signal_is_the_fundamental() -> None:
    # Strong 2nd and 3rd harmonics make autocorrelation peaks at half the period; YIN must not halve it.
    t = np.arange(2 * SR) / SR
    x = 0.2 * np.sin(2 * np.pi * 150 * t) + 0.4 * np.sin(2 * np.pi * 300 * t) + 0.3 * np.sin(2 * np.pi * 450 * t)
    f0 = F.fundamental_frequency(x, SR, FPS)[1:-1]
    assert np.all(np.abs(f0 - 150.0) <= 2.0), f0


def test_f0_is_zero_for_silence_and_noise() -> None:
    assert np.all(F.fundamental_frequency(np.zeros(SR), SR, FPS) == 0.0)
    noise = np.random.default_rng(1).normal(0, 0.3, 3 * SR)
    f0 = F.fundamental_frequency(noise, SR, FPS)
    assert np.mean(f0 == 0.0) > 0.9, f0


def test_f0_follows_a_pitch_change_at_the_right_frame() -> None:
    x = np.concatenate([tone(120.0, 1.0), tone(240.0, 1.0)])
    f0 = F.fundamental_frequency(x, SR, FPS)
    # Frame i is centred on i / fps: frames 0..14 lie before 1 s, 16.. after; 15 straddles the switch.
    assert np.all(np.abs(f0[1:14] - 120.0) <= 2.0) and np.all(np.abs(f0[17:-1] - 240.0) <= 2.0), f0


def test_htk_mel_scale_published_anchor() -> None:
    # The HTK scale is defined so that 1000 Hz is (almost exactly) 1000 mel.
    assert F.hz_to_mel(1000.0) == pytest.approx(999.99, abs=0.01)
    f = np.array([0.0, 55.0, 440.0, 7999.0])
    assert np.allclose(F.mel_to_hz(F.hz_to_mel(f)), f)


def test_mel_filterbank_matches_direct_triangle_formula() -> None:
    sr, n_fft, n_mels, fmin, fmax = 16000, 512, 20, 80.0, 7600.0
    fb = F.mel_filterbank(sr, n_fft, n_mels, fmin, fmax)
    mel = lambda f: 2595.0 * math.log10(1.0 + f / 700.0)  # noqa: E731
    inv = lambda m: 700.0 * (10.0 ** (m / 2595.0) - 1.0)  # noqa: E731
    step = (mel(fmax) - mel(fmin)) / (n_mels + 1)
    for m in range(n_mels):
        lo, mid, hi = (inv(mel(fmin) + step * (m + k)) for k in range(3))
        for k in range(n_fft // 2 + 1):
            f = k * sr / n_fft
            if lo < f <= mid:
                want = (f - lo) / (mid - lo)
            elif mid < f < hi:
                want = (hi - f) / (hi - mid)
            else:
                want = 0.0
            assert fb[m, k] == pytest.approx(want, abs=1e-9), (m, k)


def test_log_mel_of_tone_peaks_in_the_band_holding_the_tone() -> None:
    n_mels = 40
    lm = F.log_mel_spectrogram(tone(1000.0), SR, FPS, n_mels)
    centres = F.mel_to_hz(np.linspace(0, F.hz_to_mel(SR / 2), n_mels + 2))[1:-1]
    want = int(np.argmin(np.abs(centres - 1000.0)))
    assert lm.shape == (math.ceil(2.0 * FPS), n_mels)
    assert np.all(np.argmax(lm[1:-1], axis=1) == want)
    # Silence is the log floor, and louder is larger by the power ratio (x2 amplitude = +log 4).
    assert np.all(F.log_mel_spectrogram(np.zeros(SR), SR, FPS, 8) == pytest.approx(math.log(1e-10)))
    louder = F.log_mel_spectrogram(tone(1000.0, amp=1.0), SR, FPS, n_mels)
    assert louder[5, want] - lm[5, want] == pytest.approx(math.log(4.0), abs=1e-6)


def test_short_time_energy_of_known_signals() -> None:
    e = F.short_time_energy(tone(200.0, amp=0.6), SR, FPS)
    # Mean square of a sine is amp^2 / 2; a window of ~13.3 periods (not a whole number) is within 2 %,
    # and the partial-period error averages out over frames.
    assert np.allclose(e[1:-1], 0.18, rtol=0.02) and np.mean(e[1:-1]) == pytest.approx(0.18, rel=0.005)
    assert np.allclose(F.short_time_energy(np.full(SR, -0.5), SR, FPS)[1:-1], 0.25)
    # The first window is centred on t = 0, so half of it is silence before the clip.
    win = round(SR / FPS)
    assert F.short_time_energy(np.full(SR, -0.5), SR, FPS)[0] == pytest.approx(0.25 * (win - win // 2) / win)


def test_frames_are_centred_on_frame_times() -> None:
    x = np.zeros(3 * SR)
    x[SR] = 1.0  # a click at exactly t = 1 s = frame 15 at 15 fps
    e = F.short_time_energy(x, SR, FPS)
    assert np.flatnonzero(e).tolist() == [15]
    lm = F.log_mel_spectrogram(x, SR, FPS, 16)
    loud = lm.max(axis=1)
    # The Hann window is two frames long and centred: the click is loudest in frame 15, its neighbours
    # see only the window's tails and no other frame hears it at all.
    assert int(np.argmax(loud)) == 15 and loud[15] > max(loud[14], loud[16]) + 5
    assert np.all(np.delete(loud, [14, 15, 16]) == pytest.approx(math.log(1e-10)))


def test_compute_features_shapes_channels_and_frame_count() -> None:
    mono = tone(200.0, seconds=1.01)
    stereo = np.stack([mono, mono], axis=1)
    feats = F.compute_features(["log_mel:32", "energy", "f0"], stereo, SR, FPS)
    assert list(feats) == ["log_mel:32", "energy", "f0"]
    n = math.ceil(1.01 * FPS)  # 16: frame 15 is at 1.0 s, inside the clip
    assert {k: v.shape for k, v in feats.items()} == {"log_mel:32": (n, 32), "energy": (n, 1), "f0": (n, 1)}
    assert all(v.dtype == np.float32 for v in feats.values())
    assert np.array_equal(feats["energy"], F.compute_features(["energy"], mono, SR, FPS)["energy"])
    assert F.feature_dim(["log_mel:32", "energy", "f0"]) == 34
    assert F.compute_features(["f0"], mono, SR, FPS, n_frames=40)["f0"].shape == (40, 1)


@pytest.mark.parametrize("bad", ["log_mel", "log_mel:x", "energy:3", "pitch", "mfcc:13"])
def test_unknown_or_malformed_feature_names_are_refused(bad: str) -> None:
    with pytest.raises(ValueError, match="feature"):
        F.parse_feature(bad)
