"""Texture PNGs decode without matplotlib (Pillow, a participant dependency): PNGs written here byte by byte
(zlib, filter 0, so the expected pixels are known independently of any PNG library) in every colour type
glTF/VRM avatars use, plus 16-bit grey and Adam7 interlacing, decode to the pixels written; the samples'
avatar textures decode as matplotlib (analysis extra) decodes them; a damaged PNG is one InputError line."""
from __future__ import annotations

import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from studyapp.errors import InputError
from studyapp.render.gltf import decode_image

SAMPLES = Path("/work/shared/samples")


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def _png(rows: np.ndarray, color_type: int, depth: int = 8, extra: bytes = b"") -> bytes:
    """A non-interlaced PNG of ``rows`` (H, W*channels, big-endian samples), every scanline filter 0."""
    h = rows.shape[0]
    w = rows.shape[1] // ({0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[color_type] * depth // 8)
    raw = b"".join(b"\x00" + r.tobytes() for r in rows)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, color_type, 0, 0, 0))
            + extra + _chunk(b"IDAT", zlib.compress(raw)) + _chunk(b"IEND", b""))


#: Adam7's passes: (first column, first row, column step, row step).
ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))


def _png_adam7(rgba: np.ndarray) -> bytes:
    """An interlaced (Adam7) RGBA PNG: each pass's pixels as scanlines of their own, filter 0."""
    h, w = rgba.shape[:2]
    raw = b""
    for x0, y0, dx, dy in ADAM7:
        sub = rgba[y0::dy, x0::dx]
        if sub.size:
            raw += b"".join(b"\x00" + r.tobytes() for r in sub)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 1))
            + _chunk(b"IDAT", zlib.compress(raw)) + _chunk(b"IEND", b""))


RNG = np.random.default_rng(7)
GREY = RNG.integers(0, 256, (5, 7), dtype=np.uint8)
RGB = RNG.integers(0, 256, (5, 7, 3), dtype=np.uint8)
RGBA = RNG.integers(0, 256, (5, 7, 4), dtype=np.uint8)
GREY_A = RNG.integers(0, 256, (5, 7, 2), dtype=np.uint8)
PALETTE = RNG.integers(0, 256, (4, 3), dtype=np.uint8)
INDEX = RNG.integers(0, 4, (5, 7), dtype=np.uint8)
ALPHA = np.array([255, 0, 128, 7], np.uint8)
GREY16 = RNG.integers(0, 65536, (5, 7), dtype=np.uint16)


def _rgba(rgb: np.ndarray, a: np.ndarray | None = None) -> np.ndarray:
    return np.concatenate([rgb, (np.full(rgb.shape[:2], 255, np.uint8) if a is None else a)[..., None]], -1)


CASES = {
    "grey": (_png(GREY, 0), _rgba(np.stack([GREY] * 3, -1))),
    "rgb": (_png(RGB.reshape(5, -1), 2), _rgba(RGB)),
    "rgba": (_png(RGBA.reshape(5, -1), 6), RGBA),
    "grey_alpha": (_png(GREY_A.reshape(5, -1), 4), _rgba(np.stack([GREY_A[..., 0]] * 3, -1), GREY_A[..., 1])),
    "palette": (_png(INDEX, 3, extra=_chunk(b"PLTE", PALETTE.tobytes()) + _chunk(b"tRNS", ALPHA.tobytes())),
                _rgba(PALETTE[INDEX], ALPHA[INDEX])),
    "grey16": (_png(GREY16.astype(">u2").view(np.uint8).reshape(5, -1), 0, depth=16),
               _rgba(np.stack([(GREY16 >> 8).astype(np.uint8)] * 3, -1))),
}


@pytest.mark.parametrize("kind", sorted(CASES))
def test_handmade_pngs_decode_to_the_pixels_written(kind: str) -> None:
    data, want = CASES[kind]
    got = decode_image(data)
    assert got.dtype == np.uint8 and got.shape == want.shape
    np.testing.assert_array_equal(got, want)


def test_an_interlaced_png_decodes_like_the_plain_one() -> None:
    big = RNG.integers(0, 256, (13, 11, 4), dtype=np.uint8)   # every pass has pixels
    np.testing.assert_array_equal(decode_image(_png_adam7(big)), big)


def test_the_samples_avatar_textures_decode_as_matplotlib_decodes_them() -> None:
    import io
    import json

    import matplotlib.image as mpimg

    seen = 0
    for path in sorted(SAMPLES.rglob("*.png")):
        want = mpimg.imread(io.BytesIO(path.read_bytes()), format="png")
        if want.dtype != np.uint8:
            want = np.clip(want * 255.0 + 0.5, 0, 255).astype(np.uint8)
        if want.ndim == 2:
            want = np.stack([want] * 3, -1)
        if want.shape[2] == 3:
            want = _rgba(want)
        np.testing.assert_array_equal(decode_image(path.read_bytes(), path), want)
        seen += 1
    for path in sorted([*SAMPLES.rglob("*.glb"), *SAMPLES.rglob("*.vrm")]):
        data = path.read_bytes()
        n = struct.unpack_from("<I", data, 12)[0]
        doc = json.loads(data[20:20 + n])
        bin_start = 20 + n + 8
        for image in doc.get("images", []):
            if image.get("mimeType") != "image/png" or "bufferView" not in image:
                continue
            view = doc["bufferViews"][image["bufferView"]]
            png = data[bin_start + view.get("byteOffset", 0):bin_start + view.get("byteOffset", 0) + view["byteLength"]]
            want = mpimg.imread(io.BytesIO(png), format="png")
            if want.dtype != np.uint8:
                want = np.clip(want * 255.0 + 0.5, 0, 255).astype(np.uint8)
            if want.ndim == 2:
                want = np.stack([want] * 3, -1)
            if want.shape[2] == 3:
                want = _rgba(want)
            np.testing.assert_array_equal(decode_image(png, path), want)
            seen += 1
    assert seen >= 1, "no PNG texture found in the samples"


def test_a_damaged_png_is_one_line() -> None:
    data = CASES["rgb"][0]
    broken = data[:40] + b"\x00" * 20 + data[60:]
    for bad in (broken, data[:30]):
        with pytest.raises(InputError, match="cannot decode texture image") as err:
            decode_image(bad, Path("avatar.glb"), "images[0]")
        assert "\n" not in str(err.value)


def test_decoding_textures_imports_no_matplotlib() -> None:
    code = ("import sys; from studyapp.render.gltf import decode_image; import base64\n"
            f"decode_image({CASES['palette'][0]!r}); print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
