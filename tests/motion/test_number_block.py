"""The vectorized number parser (studyapp.motion.number_block): every value it returns is Python's float() of
the token, bit for bit (signs of zero included), and it refuses (None) whatever it cannot read exactly, so
that the general parser reads it; real files load exactly as numpy's C reader reads them."""
from __future__ import annotations

import warnings
import zlib

import numpy as np
import pytest

from motion_helpers import SAMPLES
from studyapp.motion import bvh_frames, number_block
from studyapp.motion.bvh import read_bvh_channels


def parse_block(text: bytes, n_columns: int) -> np.ndarray | None:
    """The values alone, after checking the count of line ends that comes with them."""
    got = number_block.parse_block(text, n_columns)
    if got is None:
        return None
    assert got[1] == text.count(b"\n")
    return got[0]



def _reference(text: str) -> np.ndarray:
    rows = [[float(t) for t in ln.split()] for ln in text.splitlines() if ln.strip()]
    return np.array(rows, dtype=np.float64)


def _same(a: np.ndarray | None, b: np.ndarray) -> bool:
    return a is not None and a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


def _values(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Magnitudes from 1e-12 to 1e4 (5 integer digits at most), signs, exact zeros and negative zeros."""
    v = rng.normal(size=shape) * 10.0 ** rng.integers(-12, 5, size=shape)
    v.flat[:: 17] = 0.0
    v.flat[5 :: 23] = -0.0
    return v


@pytest.mark.parametrize("fmt,sep,end", [
    ("%e", "  ", " \n"),  # DiffSHEG
    ("%E", " ", "\r\n"),
    ("%.6f", " ", "\n"),  # BEAT, LAFAN1, ZEGGS
    ("%.4f", "\t", "\n"),  # Mixamo
    ("%.8f", " \t ", " \r\n"),
    ("%.0f", " ", "\n"),  # no fraction digit ("12.")
    ("%.3e", " ", "\n"),
    ("%+.6f", " ", "\n"),  # '+' signs
    ("%+.2e", " ", "\n"),
])
def test_values_are_pythons_float_bit_for_bit(fmt, sep, end):
    rng = np.random.default_rng(zlib.crc32((fmt + sep + end).encode()))
    vals = _values(rng, (300, 57))
    if fmt == "%.0f":
        vals = np.round(vals)
        text = "".join(sep.join(("%.0f." % v) for v in row) + end for row in vals.tolist())
    else:
        text = "".join(sep.join(fmt % v for v in row) + end for row in vals.tolist())
    got = parse_block(text.encode(), 57)
    assert _same(got, _reference(text))


def test_integer_digits_of_every_width_and_leading_zeros():
    toks = ["0.5", "-0.5", "12.5", "-123.25", "1234.125", "-12345.0625", "123456.5", "+12345.5", "007.25",
            "-000.000", "0.000", "99999.99", "-99999.99"]
    text = " ".join(toks) + "\n"
    # nf differs between tokens: one token per line keeps each line uniform only with itself, so build per nf
    for nf in range(0, 5):
        same = [t for t in toks if len(t.split(".")[1]) == nf]
        if same:
            line = " ".join(same) + "\n"
            assert _same(parse_block((line * 3).encode(), len(same)), _reference(line * 3))
    assert parse_block(text.encode(), len(toks)) is None  # mixed fraction widths: the general parser's


def test_diffsheg_cut_last_exponent_and_tiny_values_read_by_float():
    rng = np.random.default_rng(4)
    vals = _values(rng, (200, 30))
    vals[::7, 3] = 3.1e-17  # power of ten beyond 1e-22 for the integer mantissa: float() reads those
    lines = []
    for row in vals.tolist():
        line = "  ".join("%e" % v for v in row) + " "
        lines.append(line[:-2] + " ")  # "e+00" -> "e+0": the writer cut the last character
    text = "\n".join(lines) + "\n"
    assert _same(parse_block(text.encode(), 30), _reference(text))


def test_random_digit_strings_against_float():
    """Random tokens of every accepted shape (digits up to the limits; exponents up to 14, so that every power of
    ten is exact: a refusal here would be a bug)."""
    rng = np.random.default_rng(7)
    for nf in range(0, 9):
        for exp in (False, True):
            toks = []
            for _ in range(2000):
                ni = int(rng.integers(1, 6))
                sign = rng.choice(["", "-", "+"])
                t = sign + "".join(rng.choice(list("0123456789"), ni)) + "." + "".join(rng.choice(list("0123456789"), nf))
                if exp:
                    t += rng.choice(["e", "E"]) + rng.choice(["+", "-"]) + str(int(rng.integers(0, 15))).zfill(int(rng.integers(1, 3)))
                toks.append(t)
            text = "\n".join(" ".join(toks[k : k + 20]) for k in range(0, 2000, 20)) + "\n"
            assert _same(parse_block(text.encode(), 20), _reference(text)), (nf, exp)


@pytest.mark.parametrize("bad", [
    "1.5 2.5 3.5\n1.5 2.5\n",  # a short line
    "1.5 2.5 3.5\n1.5 2.5 3.5 4.5\n",  # a long line
    "1.5 2.5 3.5\n1.5 x.5 3.5\n",  # a letter
    "1.5 2.5 3.5\n1.5 2 3.5\n",  # an integer without a point (the general parser reads it)
    "1.5 2.5 3.5\n1.5 2.5.5 3.5\n",  # two points
    "1.5 2.5 3.5\n1.5 -+2.5 3.5\n",
    "1.5 2.5 3.5\n1.5 2-2.5 3.5\n",
    "1.5 2.5 3.5\n1.5 nan 3.5\n",
    "1.5 2.5 3.5\n1.5 2.55 3.5\n",  # another fraction width
    "1.5 2.5 3.5\n1.5\x0b2.5 3.5\n",  # a control byte
    "1.5 2.5 3.5\r1.5 2.5 3.5\n",  # a lone carriage return
    "1.5 2.5 3.5\n1.5 2.5 \xe93.5\n",
    "1234567.5 2.5 3.5\n",  # 7 integer digits
    "1.5 2.5 -.\n",
    "1.5e+01 2.5e+01 3.5e+100\n",  # a 3-digit exponent
    "1.5e+01 2.5e+01 3.5e01\n",  # no exponent sign
    "1.5e+01 2.5e+01 3.5\n",
    "1.5e+01 2.5e+01 3.5e+\n",
    "1.5e+01 2.5e+01-3.5e+01\n",  # two numbers glued (three points, two tokens)
    "1.5e+01 2.5e+0-3.5e+01\n",  # (DiffSHEG's cut exponent: 'e+0')
    "1.5 2.5-3.5\n",
    "1.5e+01 2.5e+01 3.5e+01x\n",
    "1.5e+01 2.5e+01 3.5e-99x\n",  # a power float() reads, then junk
])
def test_anything_else_is_refused(bad):
    assert parse_block(bad.encode("latin-1"), 3) is None


def test_blank_lines_and_a_missing_last_line_end():
    text = "\n  \n1.25 -2.50 3.00\n\n\t\n4.50 5.50 -0.00"
    assert _same(parse_block(text.encode(), 3), _reference(text))


BVH_SAMPLES = sorted(SAMPLES.rglob("*.bvh"))


def test_the_samples_are_there():
    assert len(BVH_SAMPLES) >= 8  # the real files of tests/data/samples (copies of the shared samples)


@pytest.mark.parametrize("sample", BVH_SAMPLES, ids=lambda p: p.name)
def test_real_files_load_exactly_as_numpys_reader_reads_them(sample, tmp_path, monkeypatch):
    """Every sample file, its MOTION block repeated over many pieces, gives the same array bit for bit with the
    vectorized parser on and off (numpy's C reader: the reader before it)."""
    raw = sample.read_bytes()
    cut = raw.index(b"\n", raw.index(b"Frame Time")) + 1
    body = raw[cut:] if raw.endswith(b"\n") else raw[cut:] + b"\n"
    p = tmp_path / sample.name
    p.write_bytes(raw[:cut] + body * 40)
    monkeypatch.setattr(bvh_frames, "CHUNK_BYTES", 8192)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the header's Frames: count is the excerpt's
        new = read_bvh_channels(p).channels
        monkeypatch.setattr(bvh_frames, "parse_block", lambda *a: None)
        old = read_bvh_channels(p).channels
    assert new.dtype == old.dtype and _same(new, old)


def _strict_reference(text: bytes, n_columns: int) -> np.ndarray | None:
    """What the general reader makes of ``text``: lines with exactly ``n_columns`` finite numbers or nothing."""
    try:
        rows = []
        for ln in text.decode("ascii").split("\n"):
            if ln.strip():
                toks = ln.split()
                if len(toks) != n_columns:
                    return None
                rows.append([float(t) for t in toks])
    except (UnicodeDecodeError, ValueError):
        return None
    values = np.array(rows, dtype=np.float64).reshape(len(rows), n_columns)
    return values if np.isfinite(values).all() else None


@pytest.mark.parametrize("fmt,sep,end", [("%e", " ", " \n"), ("%.6f", " ", "\n"), ("%.4f", "\t", "\r\n")])
def test_damaged_text_is_refused_or_read_exactly(fmt, sep, end):
    """Random damage (a byte inserted, deleted or replaced by one of the bytes that matter) to valid text: the
    parser either refuses the piece or returns exactly what float() reads from it."""
    rng = np.random.default_rng(zlib.crc32(fmt.encode()))
    vals = _values(rng, (6, 9))
    clean = "".join(sep.join(fmt % v for v in row) + end for row in vals.tolist()).encode()
    alphabet = b"0123456789.eE+- \t\r\nx\x00\x0b"
    accepted = 0
    for _ in range(3000):
        text = bytearray(clean)
        for _ in range(int(rng.integers(1, 3))):
            at = int(rng.integers(0, len(text)))
            kind = int(rng.integers(0, 3))
            byte = alphabet[int(rng.integers(0, len(alphabet)))]
            if kind == 0:
                text.insert(at, byte)
            elif kind == 1:
                del text[at]
            else:
                text[at] = byte
        got = parse_block(bytes(text), 9)
        if got is not None:
            accepted += 1
            assert _same(got, _strict_reference(bytes(text), 9)), bytes(text)
    assert accepted > 50  # harmless damage (a space more, a digit changed) is still read
