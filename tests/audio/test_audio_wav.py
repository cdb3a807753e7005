"""WAV reading/writing at every bit depth, resampling, summaries and bad files."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.io import wavfile

from studyapp.audio.wav import SUBTYPES, AudioClip, load_wav, save_wav, summarize
from studyapp.errors import InputError

#: One quantization step of each encoding in float units (the round-trip error bound is half of it).
STEP = {"uint8": 1 / 128, "int16": 1 / 32768, "int24": 1 / 2 ** 23, "int32": 1 / 2 ** 31, "float32": 0.0, "float64": 0.0}


def _pcm_wav(path: Path, rate: int, channels: int, bits: int, payload: bytes, fmt_tag: int = 1) -> None:
    """A WAV file built byte by byte, independently of the code under test."""
    block = channels * bits // 8
    fmt = struct.pack("<HHIIHH", fmt_tag, channels, rate, rate * block, block, bits)
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(payload)) + payload
    path.write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)


@pytest.mark.parametrize("subtype", list(SUBTYPES))
@pytest.mark.parametrize("channels", [1, 2])
def test_round_trip_every_encoding(tmp_path: Path, subtype: str, channels: int) -> None:
    rng = np.random.default_rng(7)
    x = rng.uniform(-1, 1, (1000, channels)).astype(np.float32)
    x[:4, 0] = [0.0, -1.0, 0.5, -0.5]
    p = tmp_path / f"{subtype}.wav"
    save_wav(AudioClip(x, 22050), p, subtype=subtype)
    back = load_wav(p)
    assert back.sample_rate == 22050 and back.samples.shape == (1000, channels) and back.samples.dtype == np.float32
    tol = STEP[subtype] / 2 + 1e-7
    # The largest code is one step below +1.0 (two's complement), so the top half-step saturates there.
    np.testing.assert_allclose(back.samples, np.minimum(x, 1 - STEP[subtype]), atol=tol)
    # Exact codes: 0, -1 and +-0.5 are representable in every encoding.
    np.testing.assert_array_equal(back.samples[:4, 0], [0.0, -1.0, 0.5, -0.5])
    s = summarize(p)
    assert s["bits"] == SUBTYPES[subtype][1] and s["dtype"].endswith(str(SUBTYPES[subtype][1]))
    assert s["channels"] == channels and s["samples"] == 1000


def test_full_scale_positive_saturates(tmp_path: Path) -> None:
    p = tmp_path / "a.wav"
    save_wav(AudioClip(np.array([1.0, -1.0, 2.0], np.float32), 8000), p, subtype="int16")
    _, raw = wavfile.read(p)
    assert raw.tolist() == [32767, -32768, 32767]


def test_reads_24_bit_written_by_hand(tmp_path: Path) -> None:
    codes = [0, 1, -1, 2 ** 22, -(2 ** 23), 2 ** 23 - 1]
    payload = b"".join(struct.pack("<i", c)[:3] for c in codes)
    p = tmp_path / "24.wav"
    _pcm_wav(p, 48000, 1, 24, payload)
    clip = load_wav(p)
    np.testing.assert_allclose(clip.samples[:, 0], np.array(codes) / 2 ** 23, rtol=0, atol=1e-12)
    # and our 24-bit writer produces exactly those bytes back
    q = tmp_path / "24b.wav"
    save_wav(clip, q, subtype="int24")
    assert q.read_bytes() == p.read_bytes()
    assert summarize(q)["bits"] == 24


def test_reads_8_bit_unsigned_written_by_hand(tmp_path: Path) -> None:
    p = tmp_path / "8.wav"
    _pcm_wav(p, 8000, 2, 8, bytes([128, 0, 255, 192]))
    clip = load_wav(p)
    np.testing.assert_allclose(clip.samples, [[0.0, -1.0], [127 / 128, 0.5]])
    assert clip.n_channels == 2 and clip.duration == pytest.approx(2 / 8000)
    np.testing.assert_allclose(clip.mono(), [-0.5, (127 / 128 + 0.5) / 2])


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(list(SUBTYPES)), st.integers(1, 3), st.integers(1, 300), st.sampled_from([8000, 16000, 44100, 48000]))
def test_round_trip_property(tmp_path: Path, subtype: str, channels: int, n: int, rate: int) -> None:
    x = np.random.default_rng(n).uniform(-1, 1, (n, channels)).astype(np.float32)
    p = tmp_path / "h.wav"
    save_wav(AudioClip(x, rate), p, subtype=subtype)
    back = load_wav(p)
    assert back.samples.shape == x.shape and back.sample_rate == rate
    np.testing.assert_allclose(back.samples, np.minimum(x, 1 - STEP[subtype]), atol=STEP[subtype] / 2 + 1e-7)


def test_resample_keeps_frequency_and_length() -> None:
    sr = 48000
    t = np.arange(sr) / sr
    clip = AudioClip((0.5 * np.sin(2 * np.pi * 440 * t)).astype(np.float32), sr)
    out = clip.resample(16000)
    assert out.sample_rate == 16000 and out.n_samples == 16000 and out.duration == pytest.approx(1.0)
    spec = np.abs(np.fft.rfft(out.mono()))
    assert np.argmax(spec) * 16000 / out.n_samples == pytest.approx(440, abs=1)
    mid = out.mono()[2000:-2000]
    np.testing.assert_allclose(mid, 0.5 * np.sin(2 * np.pi * 440 * np.arange(16000)[2000:-2000] / 16000), atol=2e-3)
    assert clip.resample(sr).samples is not clip.samples


def test_summary_levels(tmp_path: Path) -> None:
    sr = 16000
    x = 0.5 * np.sin(2 * np.pi * 250 * np.arange(sr) / sr)  # whole periods: rms = 0.5 / sqrt(2)
    p = tmp_path / "s.wav"
    save_wav(AudioClip(x.astype(np.float32), sr), p, subtype="float32")
    s = summarize(p)
    assert s["sample_rate"] == sr and s["channels"] == 1 and s["duration"] == 1.0 and s["dtype"] == "float32"
    assert s["peak"] == pytest.approx(0.5, abs=1e-6)
    assert s["rms"] == pytest.approx(0.5 / np.sqrt(2), rel=1e-5)
    assert s["peak_dbfs"] == pytest.approx(-6.0206, abs=1e-3)


def test_invalid_clip() -> None:
    with pytest.raises(ValueError):
        AudioClip(np.zeros((3, 2, 2)), 16000)
    with pytest.raises(ValueError):
        AudioClip(np.zeros(3), 0)
    with pytest.raises(ValueError):
        save_wav(AudioClip(np.zeros(3), 8000), "x.wav", subtype="int12")


def test_bad_files(tmp_path: Path) -> None:
    good = tmp_path / "good.wav"
    save_wav(AudioClip(np.zeros(1000, np.float32), 16000), good)
    data = good.read_bytes()
    save_wav(AudioClip(np.zeros((1000, 2), np.float32), 16000), tmp_path / "stereo.wav")
    stereo = (tmp_path / "stereo.wav").read_bytes()
    cases = {
        "text.wav": (b"hello, this is not audio at all", "header", "not a WAV"),
        "tiny.wav": (b"RIFF", "header", "not a WAV"),
        "cut_header.wav": (data[:30], "fmt chunk at byte 12", "truncated"),
        "cut_data.wav": (data[:1000], "data chunk", "truncated"),
        "no_samples.wav": (data[:44], "data chunk", "truncated"),
        # a RIFF/WAVE header followed by a chunk header cut short (scipy raises struct.error inside)
        "cut_chunk.wav": (b"RIFFxxxxWAVEjunk\n", "fmt chunk", "truncated"),
        # cut mid-sample in a stereo file: scipy fails with a bare reshape error there
        "cut_stereo.wav": (stereo[:1001], "data chunk", "declares 4000 bytes of samples but only 957 follow"),
    }
    for name, (content, where, words) in cases.items():
        p = tmp_path / name
        p.write_bytes(content)
        with pytest.raises(InputError) as exc:
            load_wav(p)
        assert exc.value.path == str(p) and exc.value.where == where and words in exc.value.problem, (name, exc.value)
        with pytest.raises(InputError):
            summarize(p)
    empty = tmp_path / "zero.wav"
    _pcm_wav(empty, 16000, 1, 16, b"")
    with pytest.raises(InputError, match="no samples"):
        load_wav(empty)
    with pytest.raises(InputError, match="file not found"):
        load_wav(tmp_path / "missing.wav")
    nan = tmp_path / "nan.wav"
    wavfile.write(nan, 8000, np.array([0.0, np.nan], np.float32))
    with pytest.raises(InputError, match="NaN") as exc:
        load_wav(nan)
    assert exc.value.where == "sample 1"
