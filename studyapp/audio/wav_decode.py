"""The samples of a WAV file's bytes as a numpy array, without scipy (``scipy.io`` costs 0.3-0.8 s to import,
most of it on a participant's first trial).

Reads what :func:`scipy.io.wavfile.read` reads and returns the same arrays: RIFF (little-endian), RIFX
(big-endian) and RF64 (sizes in the ``ds64`` chunk); PCM (format 1) at 8 bits (unsigned), 16, 24, 32 and 64
bits (24-bit left-justified in int32, as scipy gives it), IEEE float (format 3) at 32 and 64 bits, and
WAVE_FORMAT_EXTENSIBLE (0xFFFE) with either of those sub-formats. Chunks other than ``fmt `` and ``data``
(``LIST``, ``bext``, ``fact``, ...) are skipped. Chunk sizes were checked by the caller
(:func:`studyapp.audio.wav._check_chunks`); what is wrong inside ``fmt `` or with the data's length is one
:class:`~studyapp.errors.InputError` here.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from studyapp.errors import InputError

__all__ = ["decode_wav"]

_PCM, _FLOAT, _EXTENSIBLE = 1, 3, 0xFFFE
#: numpy type of each (format, bits per sample); 24-bit PCM is widened to int32 by hand.
_TYPES = {(_PCM, 8): "u1", (_PCM, 16): "i2", (_PCM, 32): "i4", (_PCM, 64): "i8", (_FLOAT, 32): "f4", (_FLOAT, 64): "f8"}


def _chunks(raw: bytes | bytearray, endian: str) -> tuple[bytes | None, tuple[int, int] | None, int | None]:
    """(fmt chunk's body, (offset, length) of the data chunk's body, ds64's data size) of a WAV's bytes."""
    fmt: bytes | None = None
    data: tuple[int, int] | None = None
    ds64: int | None = None
    pos = 12
    while pos + 8 <= len(raw):
        cid = raw[pos : pos + 4]
        (n,) = struct.unpack_from(endian + "I", raw, pos + 4)
        body = pos + 8
        if cid == b"ds64" and n >= 16 and body + 16 <= len(raw):
            ds64 = struct.unpack_from("<Q", raw, body + 8)[0]
        elif cid == b"fmt ":
            fmt = bytes(raw[body : body + n])
        elif cid == b"data":
            if n == 0xFFFFFFFF and ds64 is not None:
                n = ds64
            data = (body, min(n, len(raw) - body))
            break
        pos = body + n + (n & 1)
    return fmt, data, ds64


def decode_wav(raw: bytes | bytearray, path: str | Path) -> tuple[int, np.ndarray]:
    """(sample rate, ``(N, C)`` samples in the file's own encoding) of the bytes of a whole WAV file."""
    endian = ">" if raw[:4] == b"RIFX" else "<"
    fmt, data, _ = _chunks(raw, endian)
    if fmt is None or len(fmt) < 16:
        raise InputError(path, "fmt chunk", "missing or shorter than 16 bytes: the file is damaged")
    tag, channels, rate, _, _, bits = struct.unpack_from(endian + "HHIIHH", fmt)
    if tag == _EXTENSIBLE:
        if len(fmt) < 26:
            raise InputError(path, "fmt chunk", "WAVE_FORMAT_EXTENSIBLE without its sub-format: the file is damaged")
        (tag,) = struct.unpack_from(endian + "H", fmt, 24)  # the first two bytes of the sub-format GUID
    if tag not in (_PCM, _FLOAT):
        raise InputError(path, "fmt chunk", f"unsupported encoding (format tag {tag:#06x}); expected PCM or IEEE float")
    if (tag, bits) not in _TYPES and (tag, bits) != (_PCM, 24):
        kind = "PCM" if tag == _PCM else "float"
        raise InputError(path, "fmt chunk", f"unsupported {bits}-bit {kind} samples; expected 8, 16, 24, 32 or 64-bit "
                                            "PCM or 32/64-bit float")
    if channels == 0:
        raise InputError(path, "fmt chunk", "declares 0 channels")
    if data is None:
        raise InputError(path, "data chunk", "missing: the file is truncated or not a complete WAV")
    start, length = data
    width = bits // 8
    frame = width * channels
    if length % frame:
        raise InputError(path, "data chunk", f"holds {length} bytes, not a whole number of {frame}-byte frames "
                                             f"({channels} channels x {bits} bits): the file is damaged")
    blob = np.frombuffer(raw, dtype=np.uint8, count=length, offset=start)
    if bits == 24:
        # left-justified in int32 (the low byte zero), as scipy returns it
        wide = np.zeros((length // 3, 4), dtype=np.uint8)
        if endian == "<":
            wide[:, 1:] = blob.reshape(-1, 3)
        else:
            wide[:, :3] = blob.reshape(-1, 3)
        samples = wide.view(endian + "i4")[:, 0].astype(np.int32)
    else:
        samples = blob.view(endian + _TYPES[tag, bits]).astype(_TYPES[tag, bits])
    return int(rate), samples.reshape(-1, channels)
