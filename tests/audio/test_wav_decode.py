"""The scipy-free WAV decoder gives what scipy.io.wavfile.read gives, array for array, for every encoding it
claims (byte orders, RF64, WAVE_FORMAT_EXTENSIBLE, odd chunks), and names what it cannot read."""
from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from studyapp.audio.wav import load_wav
from studyapp.audio.wav_decode import decode_wav
from studyapp.errors import InputError

REPO = Path(__file__).resolve().parents[2]
RNG = np.random.default_rng(7)
PCM, FLOAT, EXT = 1, 3, 0xFFFE


def _samples(bits: int, tag: int, n: int, channels: int) -> np.ndarray:
    if tag == FLOAT:
        return RNG.uniform(-1, 1, size=(n, channels)).astype(f"f{bits // 8}")
    if bits == 8:
        return RNG.integers(0, 256, size=(n, channels), dtype=np.uint8)
    return RNG.integers(-(2 ** (bits - 1)), 2 ** (bits - 1), size=(n, channels), dtype=np.int64)


def _payload(x: np.ndarray, bits: int, big: bool) -> bytes:
    e = ">" if big else "<"
    if bits == 24:
        b = x.astype("<i4").reshape(-1).view(np.uint8).reshape(-1, 4)[:, :3]
        return (b[:, ::-1] if big else b).tobytes()
    kind = "u" if bits == 8 else x.dtype.kind
    return x.astype(f"{e}{kind}{bits // 8}").tobytes()


def _wav(bits: int, tag: int, channels: int = 2, n: int = 101, big: bool = False, rf64: bool = False,
         extensible: bool = False, junk: bool = False) -> tuple[bytes, np.ndarray]:
    x = _samples(bits, tag, n, channels)
    e = ">" if big else "<"
    block = channels * bits // 8
    fmt = struct.pack(e + "HHIIHH", EXT if extensible else tag, channels, 16000, 16000 * block, block, bits)
    if extensible:
        guid = struct.pack(e + "H", tag) + b"\x00\x00\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71"
        fmt += struct.pack(e + "HHI", 22, bits, 3) + guid
    payload = _payload(x, bits, big)
    chunks = b"fmt " + struct.pack(e + "I", len(fmt)) + fmt
    if junk:
        chunks += b"LIST" + struct.pack(e + "I", 5) + b"abcde\x00"  # odd size, padded
    if rf64:
        riff_size = 4 + 8 + 28 + len(chunks) + 8 + len(payload) + (len(payload) & 1)
        ds64 = struct.pack("<QQQI", riff_size, len(payload), n, 0)
        chunks = b"ds64" + struct.pack("<I", len(ds64)) + ds64 + chunks + b"data" + struct.pack("<I", 0xFFFFFFFF)
    else:
        chunks += b"data" + struct.pack(e + "I", len(payload))
    body = b"WAVE" + chunks + payload + (b"\x00" if len(payload) & 1 else b"")
    head = b"RF64" + struct.pack("<I", 0xFFFFFFFF) if rf64 else (b"RIFX" if big else b"RIFF") + struct.pack(e + "I", len(body))
    return head + body, x


ENCODINGS = [(8, PCM), (16, PCM), (24, PCM), (32, PCM), (64, PCM), (32, FLOAT), (64, FLOAT)]
LAYOUTS = [{}, {"big": True}, {"extensible": True}, {"junk": True}, {"rf64": True}, {"channels": 1, "n": 7}]


@pytest.mark.parametrize("bits,tag", ENCODINGS)
@pytest.mark.parametrize("layout", LAYOUTS, ids=lambda d: ",".join(d) or "plain")
def test_same_arrays_as_scipy(tmp_path, bits, tag, layout):
    raw, _ = _wav(bits, tag, **layout)
    p = tmp_path / "x.wav"
    p.write_bytes(raw)
    rate, got = decode_wav(raw, p)
    ref_rate, ref = wavfile.read(p)
    ref = ref.reshape(ref.shape[0], -1)
    assert rate == ref_rate == 16000
    assert got.dtype == ref.dtype.newbyteorder("=") and got.dtype.isnative
    assert np.array_equal(got, ref)


def test_24_bit_values_are_left_justified(tmp_path):
    raw, x = _wav(24, PCM, channels=1, n=50)
    _, got = decode_wav(raw, "x.wav")
    assert np.array_equal(got[:, 0], x[:, 0] * 256)


@pytest.mark.parametrize("change,where,words", [
    (lambda fmt: struct.pack("<H", 2) + fmt[2:], "fmt chunk", "unsupported encoding (format tag 0x0002)"),
    (lambda fmt: fmt[:14] + struct.pack("<H", 12), "fmt chunk", "unsupported 12-bit PCM samples"),
    (lambda fmt: fmt[:2] + struct.pack("<H", 0) + fmt[4:], "fmt chunk", "declares 0 channels"),
    (lambda fmt: fmt[:2] + struct.pack("<H", 3) + fmt[4:], "data chunk", "not a whole number of 6-byte frames"),
])
def test_what_cannot_be_read_is_one_input_error(tmp_path, change, where, words):
    raw, _ = _wav(16, PCM, channels=2, n=101)
    at = raw.index(b"fmt ") + 8
    raw = raw[:at] + change(raw[at : at + 16]) + raw[at + 16 :]
    p = tmp_path / "bad.wav"
    p.write_bytes(raw)
    with pytest.raises(InputError) as err:
        load_wav(p)
    assert err.value.where == where and words in err.value.problem, str(err.value)


def test_loading_the_demo_audio_imports_no_scipy():
    code = ("import sys, json\nfrom studyapp.audio.wav import load_wav\n"
            "load_wav(sys.argv[1])\nprint(json.dumps(sorted(m for m in sys.modules if m.startswith('scipy'))))")
    clip = REPO / "study_designs/demo/audio/clip01.wav"
    out = subprocess.run([sys.executable, "-c", code, str(clip)], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"
