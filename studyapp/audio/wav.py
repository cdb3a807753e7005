"""WAV files as float arrays: load any PCM/float WAV, save at a chosen bit depth, summarize.

Samples are held as ``(N, C)`` float32 in ``[-1, 1]`` whatever the file's encoding, using the conventional
full-scale of each encoding (8-bit unsigned centred at 128, signed integers divided by ``2**(bits-1)``), so
a file written at one depth and read back differs from the original by at most one quantization step.

:mod:`studyapp.audio.wav_decode` reads 8/16/24/32-bit integer and 32/64-bit float WAVs (24-bit arrives
left-justified in int32) without importing scipy; scipy's writer cannot write 24-bit, so that one encoding is
packed here by hand.

>>> import tempfile, pathlib
>>> clip = AudioClip(np.array([[0.0], [0.5], [-0.5]], np.float32), 16000)
>>> p = pathlib.Path(tempfile.mkdtemp()) / "a.wav"
>>> save_wav(clip, p, subtype="int24")
>>> load_wav(p).samples[:, 0].tolist()
[0.0, 0.5, -0.5]
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from math import gcd
from pathlib import Path

import numpy as np

from studyapp.audio.wav_decode import decode_wav
from studyapp.errors import InputError

#: Encodings :func:`save_wav` writes: name -> (numpy dtype of the stored samples, bits per sample).
SUBTYPES: dict[str, tuple[str, int]] = {
    "uint8": ("u1", 8),
    "int16": ("<i2", 16),
    "int24": ("<i4", 24),
    "int32": ("<i4", 32),
    "float32": ("<f4", 32),
    "float64": ("<f8", 64),
}


@dataclass(eq=False)
class AudioClip:
    """Audio samples in memory.

    Attributes
    ----------
    samples:
        ``(N, C)`` float32 in ``[-1, 1]`` (a 1-D array is taken as mono).
    sample_rate:
        Samples per second per channel.
    source:
        File path or description, for messages.
    """

    samples: np.ndarray
    sample_rate: int
    source: str = ""

    def __post_init__(self) -> None:
        s = np.asarray(self.samples, dtype=np.float32)
        if s.ndim == 1:
            s = s[:, None]
        if s.ndim != 2 or s.shape[1] < 1:
            raise ValueError(f"samples must be (N, channels), got {s.shape}")
        self.samples = s
        if int(self.sample_rate) != self.sample_rate or self.sample_rate <= 0:
            raise ValueError(f"sample_rate must be a positive integer, got {self.sample_rate}")
        self.sample_rate = int(self.sample_rate)

    @property
    def n_samples(self) -> int:
        return int(self.samples.shape[0])

    @property
    def n_channels(self) -> int:
        return int(self.samples.shape[1])

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return self.n_samples / self.sample_rate

    def mono(self) -> np.ndarray:
        """``(N,)`` float32 mean of the channels (the signal feature extractors and lip sync listen to)."""
        return self.samples.mean(axis=1, dtype=np.float32) if self.n_channels > 1 else self.samples[:, 0].copy()

    def resample(self, rate: int) -> "AudioClip":
        """The clip at another sample rate (polyphase, anti-aliased; duration kept to the nearest sample).

        >>> AudioClip(np.zeros(48000, np.float32), 48000).resample(16000).n_samples
        16000
        """
        rate = int(rate)
        if rate <= 0:
            raise ValueError(f"sample rate must be positive, got {rate}")
        if rate == self.sample_rate:
            return AudioClip(self.samples.copy(), rate, self.source)
        from studyapp.audio.dsp import resample_poly  # scipy's, in numpy: a participant's install has no scipy

        g = gcd(rate, self.sample_rate)
        out = resample_poly(self.samples.astype(np.float64), rate // g, self.sample_rate // g, axis=0)
        return AudioClip(np.clip(out, -1.0, 1.0).astype(np.float32), rate, self.source)


def _to_float(data: np.ndarray, path: Path) -> np.ndarray:
    kind, size = data.dtype.kind, data.dtype.itemsize
    if kind == "u" and size == 1:
        return (data.astype(np.float32) - 128.0) / 128.0
    if kind == "i":
        # 24-bit files arrive left-justified in int32, so one scale serves 24 and 32 bits.
        return (data.astype(np.float64) / float(2 ** (8 * size - 1))).astype(np.float32)
    if kind == "f":
        out = data.astype(np.float32)
        bad = np.flatnonzero(~np.isfinite(out).reshape(out.shape[0], -1).all(axis=1))
        if bad.size:
            raise InputError(path, f"sample {int(bad[0])}", "float WAV holds NaN or infinite samples")
        return np.clip(out, -1.0, 1.0)
    raise InputError(path, "fmt chunk", f"unsupported sample type {data.dtype}")


def _bits_per_sample(path: Path) -> int | None:
    """Bits per sample from the ``fmt `` chunk (scipy reports only the numpy dtype, which hides 24-bit)."""
    with path.open("rb") as f:
        head = f.read(12)
        if len(head) < 12 or head[:4] not in (b"RIFF", b"RIFX") or head[8:12] != b"WAVE":
            return None
        endian = "<" if head[:4] == b"RIFF" else ">"
        while True:
            chunk = f.read(8)
            if len(chunk) < 8:
                return None
            cid, size = chunk[:4], struct.unpack(endian + "I", chunk[4:])[0]
            if cid == b"fmt ":
                fmt = f.read(size)
                return struct.unpack(endian + "H", fmt[14:16])[0] if len(fmt) >= 16 else None
            f.seek(size + (size & 1), 1)


def _check_chunks(path: Path, head: bytes) -> tuple[int, int] | None:
    """Name the chunk a damaged file breaks in, before the decoder meets it.

    Only sizes are checked (a chunk that claims more bytes than follow, a missing ``fmt `` or ``data``);
    everything inside the chunks is left to :func:`~studyapp.audio.wav_decode.decode_wav`. RF64 keeps the real sizes elsewhere, so it is not judged
    here. Streaming writers put 0 or 0xFFFFFFFF in an unfinished ``data`` size: that claim is never trusted
    (a reader trusting it would allocate 4 GiB); the returned ``(offset of the size field, bytes that follow)`` lets
    the caller read the samples the file really holds.
    """
    if head[:4] == b"RF64":
        return None
    endian = "<" if head[:4] == b"RIFF" else ">"
    size = path.stat().st_size
    seen: set[bytes] = set()
    with path.open("rb") as f:
        f.seek(12)
        while True:
            pos = f.tell()
            chunk = f.read(8)
            if len(chunk) < 8:
                break
            cid, n = chunk[:4], struct.unpack(endian + "I", chunk[4:])[0]
            name = cid.decode("latin-1").strip() or "?"
            left = size - pos - 8
            if cid == b"data" and n in (0, 0xFFFFFFFF):
                return pos + 4, left
            if n > left:
                if cid == b"data":
                    raise InputError(path, "data chunk", f"declares {n} bytes of samples but only {left} follow: "
                                                         "the file is truncated")
                raise InputError(path, f"{name} chunk at byte {pos}", f"declares {n} bytes but only {left} follow: "
                                                                     "the file is truncated or damaged")
            seen.add(cid)
            if cid == b"data":
                break
            f.seek(n + (n & 1), 1)
    for cid in (b"fmt ", b"data"):
        if cid not in seen:
            raise InputError(path, f"{cid.decode().strip()} chunk", "missing: the file is truncated or not a complete WAV")


def _read(path: Path) -> tuple[int, np.ndarray]:
    if not path.is_file():
        raise InputError(path, None, "file not found" if not path.exists() else "not a regular file")
    with path.open("rb") as f:
        head = f.read(12)
    if len(head) < 12 or head[:4] not in (b"RIFF", b"RIFX", b"RF64") or head[8:12] != b"WAVE":
        raise InputError(path, "header", f"not a WAV file (starts with {head[:12]!r}, expected RIFF....WAVE)")
    unfinished = _check_chunks(path, head)
    raw = path.read_bytes()
    if unfinished is not None:  # the data chunk is the rest of the file, whatever its size field says
        at, left = unfinished
        patched = bytearray(raw)
        struct.pack_into(("<" if head[:4] == b"RIFF" else ">") + "I", patched, at, left)
        raw = patched
    rate, data = decode_wav(raw, path)
    if data.ndim == 1:
        data = data[:, None]
    if data.shape[0] == 0:
        raise InputError(path, "data chunk", "the WAV holds no samples")
    if rate <= 0:
        raise InputError(path, "fmt chunk", f"sample rate {rate} is not positive")
    return rate, data


def load_wav(path: str | Path) -> AudioClip:
    """Read a WAV file (8-bit unsigned, 16/24/32-bit integer or 32/64-bit float; any channel count).

    Raises :class:`InputError` naming the file for anything that is not a complete, non-empty WAV.
    """
    path = Path(path)
    rate, data = _read(path)
    return AudioClip(_to_float(data, path), rate, str(path))


def _pack_int24(q: np.ndarray) -> bytes:
    """Little-endian 3-byte samples from int32 values in the 24-bit range (interleaved order kept)."""
    b = q.astype("<i4").reshape(-1).view(np.uint8).reshape(-1, 4)
    return b[:, :3].tobytes()


def _write_int24(path: Path, rate: int, q: np.ndarray) -> None:
    channels = q.shape[1]
    payload = _pack_int24(q)
    block = 3 * channels
    fmt = struct.pack("<HHIIHH", 1, channels, rate, rate * block, block, 24)
    pad = b"\x00" if len(payload) & 1 else b""
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(payload)) + payload + pad
    path.write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)


def save_wav(clip: AudioClip, path: str | Path, subtype: str = "int16") -> None:
    """Write ``clip`` as a WAV file in the given encoding (one of :data:`SUBTYPES`).

    Integer encodings round to the nearest step and saturate at full scale (``+1.0`` becomes the largest code).
    """
    from scipy.io import wavfile  # here: see _read

    if subtype not in SUBTYPES:
        raise ValueError(f"unknown WAV subtype {subtype!r}; choose from {', '.join(SUBTYPES)}")
    path = Path(path)
    x = np.clip(clip.samples.astype(np.float64), -1.0, 1.0)
    dtype, bits = SUBTYPES[subtype]
    if subtype.startswith("float"):
        data = x.astype(dtype)
    elif subtype == "uint8":
        data = np.clip(np.round(x * 128.0 + 128.0), 0, 255).astype(np.uint8)
    else:
        full = 2 ** (bits - 1)
        q = np.clip(np.round(x * full), -full, full - 1).astype(np.int64)
        if subtype == "int24":
            _write_int24(path, clip.sample_rate, q)
            return
        data = q.astype(dtype)
    wavfile.write(path, clip.sample_rate, data[:, 0] if data.shape[1] == 1 else data)


def summarize(path: str | Path) -> dict:
    """Sample rate, channels, duration, encoding, peak and RMS (in dBFS too) of a WAV file.

    Raises :class:`InputError` like :func:`load_wav`.
    """
    path = Path(path)
    rate, data = _read(path)
    x = _to_float(data, path).astype(np.float64)
    peak = float(np.abs(x).max())
    rms = float(np.sqrt(np.mean(x * x)))
    bits = _bits_per_sample(path) or 8 * data.dtype.itemsize

    def db(v: float) -> float:
        return float(20 * np.log10(v)) if v > 0 else float("-inf")

    return {
        "path": str(path),
        "sample_rate": int(rate),
        "channels": int(data.shape[1]),
        "samples": int(data.shape[0]),
        "duration": data.shape[0] / rate,
        "bits": int(bits),
        "dtype": ("float" if data.dtype.kind == "f" else ("uint" if data.dtype.kind == "u" else "int")) + str(bits),
        "peak": peak,
        "rms": rms,
        "peak_dbfs": db(peak),
        "rms_dbfs": db(rms),
    }


__all__ = ["AudioClip", "load_wav", "save_wav", "summarize", "SUBTYPES"]
