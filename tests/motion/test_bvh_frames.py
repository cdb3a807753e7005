"""The MOTION block parser (studyapp.motion.bvh_frames): exact values, one InputError naming the line, bounded
memory, no pandas.

Pieces are made small (``CHUNK_BYTES`` patched down) so that a few hundred frames cross many piece boundaries,
which is where line numbers, frame numbers and the allocation could go wrong.
"""
from __future__ import annotations

import json
import re
import os
import subprocess
import sys
import tracemalloc

import numpy as np
import pytest

from motion_helpers import BEAT_SAMPLE
from studyapp.errors import InputError
from studyapp.motion import bvh_frames
from studyapp.motion.bvh import format_bvh, parse_bvh_bytes, read_bvh_channels
from studyapp.motion.beat import beat_skeleton

SK = beat_skeleton()
N_CH = sum(len(c) for c in SK.channels)
HEADER = format_bvh(SK, np.zeros((1, N_CH)), 1 / 120).split("Frames:")[0]


def _text(rows: list[str], frames: int | None = None) -> str:
    return f"{HEADER}Frames: {len(rows) if frames is None else frames}\nFrame Time: 0.008333\n" + "".join(rows)


def _rows(n: int, seed: int = 0) -> tuple[list[str], np.ndarray]:
    """Frame lines in the layouts real writers use (``%e`` with double spaces and a trailing space, ``%.6f``,
    17-digit ``repr``, tabs, CRLF) and, independently, the values Python's float() reads from them."""
    rng = np.random.default_rng(seed)
    vals = rng.normal(scale=30.0, size=(n, N_CH)) * 10.0 ** rng.integers(-8, 8, size=(n, N_CH))
    styles = [("  ", "%e", " \n"), (" ", "%.6f", "\n"), ("\t", "%r", "\r\n"), (" \t ", "%.9g", "\n")]
    rows = []
    for k, r in enumerate(vals.tolist()):
        sep, fmt, end = styles[k % len(styles)]
        rows.append(sep.join((repr(v) if fmt == "%r" else fmt % v) for v in r) + end)
    expected = np.array([[float(t) for t in row.split()] for row in rows])
    return rows, expected


@pytest.fixture(params=["stream", "pieces"])
def small_pieces(monkeypatch, request):
    """Both paths: the C reader's one stream (fed ~10 frame lines a read) and the piece-by-piece reading
    into one allocated array (which the stream hands over to on any problem, and which long files take)."""
    monkeypatch.setattr(bvh_frames, "CHUNK_BYTES", 40_000)
    if request.param == "pieces":
        monkeypatch.setattr(bvh_frames, "STREAM_MAX_BYTES", -1)
    return request.param


def test_values_equal_pythons_float_across_pieces(tmp_path, small_pieces):
    rows, expected = _rows(300)
    rows.insert(37, "\n")  # blank lines are skipped, wherever they fall
    rows.insert(150, "   \t \n")
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows, frames=300), newline="")
    got = read_bvh_channels(p).channels
    assert got.dtype == np.float64 and got.shape == (300, N_CH)
    assert np.array_equal(got, expected)  # bit for bit, not close
    assert np.array_equal(parse_bvh_bytes(p.read_bytes()).channels, expected)


def test_float32_is_the_float64_values_rounded(tmp_path, small_pieces):
    rows, expected = _rows(60, seed=1)
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows), newline="")
    got = read_bvh_channels(p, dtype=np.float32).channels
    assert got.dtype == np.float32 and np.array_equal(got, expected.astype(np.float32))


@pytest.mark.parametrize("bad_frame", [0, 9, 10, 11, 123, 299])
def test_a_bad_line_in_any_piece_is_named_by_file_line_and_frame(tmp_path, small_pieces, bad_frame):
    rows, _ = _rows(300)
    rows[bad_frame] = rows[bad_frame].rstrip().rsplit(None, 1)[0] + "\n"  # one value short
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows), newline="")
    first_data_line = HEADER.count("\n") + 3
    with pytest.raises(InputError) as err:
        read_bvh_channels(p)
    assert err.value.where == f"line {first_data_line + bad_frame}"
    hint = " (the file looks truncated)" if bad_frame == 299 else ""
    assert err.value.problem == (f"frame {bad_frame + 1} has {N_CH - 1} values but the hierarchy declares "
                                 f"{N_CH} channels{hint}")


def test_a_non_number_deep_in_the_file_is_named(tmp_path, small_pieces):
    rows, _ = _rows(200)
    toks = rows[150].split()
    toks[7] = "0x1F"
    rows[150] = " ".join(toks) + "\n"
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows), newline="")
    with pytest.raises(InputError, match=rf"line {HEADER.count(chr(10)) + 3 + 150}: value 8 is not a number: '0x1F'"):
        read_bvh_channels(p)


@pytest.mark.parametrize("claim", [0, 5, 10**12])
def test_the_header_claim_only_sizes_the_first_allocation(tmp_path, small_pieces, claim):
    rows, expected = _rows(120)
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows, frames=claim), newline="")
    with pytest.warns(UserWarning, match=f"header says Frames: {claim} but the file has 120 data lines"):
        d = read_bvh_channels(p)
    assert np.array_equal(d.channels, expected)
    assert d.channels.base is None or d.channels.base.shape[0] < 2 * 120  # no 10^12-row (or grown, unused) buffer


@pytest.mark.parametrize("path", ["vector", "stream", "pieces"])
def test_memory_is_the_array_plus_pieces_not_the_text(tmp_path, monkeypatch, path):
    """4,000 frames (~12 MB of text, ~7 MB of float64) read in 256 KB pieces on two parsing threads: the peak
    stays near the array. ``%e`` lines go to the vectorized parser; lines alternating ``%e`` and ``%.6f`` to
    numpy's C reader."""
    monkeypatch.setattr(bvh_frames, "CHUNK_BYTES", 256 << 10)
    monkeypatch.setattr(bvh_frames, "THREADS", 2)
    if path == "pieces":
        monkeypatch.setattr(bvh_frames, "STREAM_MAX_BYTES", -1)
    rng = np.random.default_rng(2)
    vals = rng.normal(scale=50.0, size=(4000, N_CH))
    lines = ["  ".join(["%e"] * N_CH) + " \n", " ".join(["%.6f"] * N_CH) + "\n"]
    p = tmp_path / "long.bvh"
    with open(p, "w") as fh:
        fh.write(f"{HEADER}Frames: 4000\nFrame Time: 0.008333\n")
        fh.writelines(lines[k % 2 if path != "vector" else 0] % tuple(r) for k, r in enumerate(vals.tolist()))
    text_bytes = p.stat().st_size
    tracemalloc.start()
    try:
        d = read_bvh_channels(p)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert d.channels.shape == (4000, N_CH)
    assert np.array_equal(d.channels, np.array([[float(t) for t in ln.split()] for ln in
                                                 p.read_text().splitlines()[-4000:]]))
    # the stream's array grows as it reads (numpy's reader over-allocates by up to a quarter, then trims); the
    # vectorized parser's work arrays take about 8 bytes per byte of a piece, on each thread
    slack = d.channels.nbytes // 4 if path == "stream" else 0
    work = 2 * 8 * (256 << 10) if path == "vector" else 3 * (256 << 10)
    assert peak < d.channels.nbytes + slack + work + (1 << 20), (peak, d.channels.nbytes, text_bytes)
    assert peak < text_bytes  # holding the text alone would pass this bound


def test_reading_a_bvh_imports_no_pandas():
    code = ("import sys, json\nfrom studyapp.motion.bvh import read_bvh\n"
            f"read_bvh({str(BEAT_SAMPLE)!r})\nprint(json.dumps('pandas' in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) is False


def test_a_line_without_its_break_is_measured_whole(tmp_path, small_pieces):
    rows, _ = _rows(20)
    rows[5] = rows[5].rstrip("\r\n") + " " + "1.0 " * 30_000 + "\n"  # 120 KB: three pieces long
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows), newline="")
    limit = bvh_frames.line_limit(N_CH)
    length = len(rows[5].rstrip("\r\n").encode())
    with pytest.raises(InputError) as err:
        read_bvh_channels(p)
    assert err.value.where == f"line {HEADER.count(chr(10)) + 3 + 5}"
    assert re.fullmatch(rf"frame line is {length:,} characters long; {N_CH} channels take at most {limit:,} "
                        r"\(are the line breaks missing\?\)", err.value.problem)


def test_values_whose_sum_overflows_are_still_read_exactly(tmp_path):
    """The fast pass checks finiteness by one sum; a piece of huge finite values overflows it and is read by the
    careful pass, with the same numbers."""
    rows, expected = _rows(4)
    toks = rows[2].split()
    toks[:3] = ["1.7e308", "1.7e308", "-1.7976931348623157e308"]
    rows[2] = " ".join(toks) + "\n"
    expected[2, :3] = [1.7e308, 1.7e308, -1.7976931348623157e308]
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows), newline="")
    assert np.array_equal(read_bvh_channels(p).channels, expected)


def test_the_stream_takes_a_clean_block_and_hands_a_bad_one_over(tmp_path, small_pieces, monkeypatch):
    """A clean 60-frame block is read by the C reader's stream when that path is on; a block with one short
    line is refused by it and read piece by piece, which names the line."""
    taken = []
    real = bvh_frames._in_pieces

    def counted(*a, **k):  # numpy's reader piece by piece (the vectorized parser refuses these mixed layouts)
        if not k.get("vector"):
            taken.append(1)
        return real(*a, **k)

    monkeypatch.setattr(bvh_frames, "_in_pieces", counted)
    rows, expected = _rows(60)
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows), newline="")
    assert np.array_equal(read_bvh_channels(p).channels, expected)
    assert len(taken) == (0 if small_pieces == "stream" else 1)
    rows[30] = rows[30].rstrip().rsplit(None, 1)[0] + "\n"
    p.write_text(_text(rows), newline="")
    with pytest.raises(InputError, match=f"frame 31 has {N_CH - 1} values"):
        read_bvh_channels(p)
    assert len(taken) == (1 if small_pieces == "stream" else 2)


def _uniform_rows(n: int) -> tuple[list[str], np.ndarray]:
    """DiffSHEG's layout (``%e``, double spaces, a trailing space) in every line: the vectorized parser's."""
    vals = np.random.default_rng(5).normal(scale=30.0, size=(n, N_CH))
    rows = ["  ".join("%e" % v for v in r) + " \n" for r in vals.tolist()]
    return rows, np.array([[float(t) for t in row.split()] for row in rows])


@pytest.fixture
def vector_pieces(monkeypatch):
    """~12 frame lines a piece; records, for each piece the vectorized parser reads, whether it read it (in
    the order the parsing threads finish them: :func:`first_piece` finds the block's first piece by its text)."""
    monkeypatch.setattr(bvh_frames, "CHUNK_BYTES", 40_000)
    read = {}
    real = bvh_frames.parse_block

    def counted(text, n):
        got = real(text, n)
        read[bytes(text)] = got is not None
        return got

    monkeypatch.setattr(bvh_frames, "parse_block", counted)
    return read


def first_piece(read: dict[bytes, bool], first_row: str) -> bool:
    return next(ok for text, ok in read.items() if text.startswith(first_row.encode()))


@pytest.mark.parametrize("bad_frame", [0, 11, 12, 150, 299])
@pytest.mark.parametrize("damage", ["short", "not a number", "glued"])
def test_a_bad_line_in_a_vectorized_file_is_named_as_before(tmp_path, vector_pieces, bad_frame, damage):
    """The vectorized parser refuses the piece with the bad line; numpy's reader and the line-by-line pass
    then name it exactly as they do for any file (and the pieces before it were read vectorized)."""
    rows, _ = _uniform_rows(300)
    toks = rows[bad_frame].split()
    if damage == "short":
        toks = toks[:-1]
    elif damage == "not a number":
        toks[7] = "1.5e+0x"
    else:
        toks[7:9] = [toks[7] + toks[8]]
    rows[bad_frame] = "  ".join(toks) + " \n"
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows), newline="")
    line = HEADER.count("\n") + 3 + bad_frame
    with pytest.raises(InputError) as err:
        read_bvh_channels(p)
    assert err.value.where == f"line {line}"
    if damage == "not a number":
        assert err.value.problem == "value 8 is not a number: '1.5e+0x'"
    else:
        hint = " (the file looks truncated)" if bad_frame == 299 else ""
        assert err.value.problem == (f"frame {bad_frame + 1} has {N_CH - 1} values but the hierarchy declares "
                                     f"{N_CH} channels{hint}")
    # the first piece holds frames 1-12 (bad: all goes to numpy's; the pieces queued after it on the parsing
    # threads are dropped)
    assert first_piece(vector_pieces, rows[0]) == (bad_frame >= 12)


def test_a_vectorized_file_loads_exactly_whatever_the_header_claims(tmp_path, vector_pieces):
    rows, expected = _uniform_rows(300)
    rows.insert(40, "\n")
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows, frames=299), newline="")
    with pytest.warns(UserWarning, match="header says Frames: 299 but the file has 300 data lines"):
        got = read_bvh_channels(p).channels
    assert np.array_equal(got, expected) and all(vector_pieces.values()) and len(vector_pieces) > 20
    with pytest.warns(UserWarning, match="header says Frames: 299"):
        got32 = read_bvh_channels(p, dtype=np.float32).channels
    assert np.array_equal(got32, expected.astype(np.float32))


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_pieces_parsed_side_by_side_join_in_file_order(tmp_path, vector_pieces, monkeypatch, threads):
    """Pieces finish on the parsing threads in any order, some refused (``%.9g`` lines: numpy's reader reads
    those), some blank: the array is the file's frames in file order, and an error after them names its line."""
    monkeypatch.setattr(bvh_frames, "THREADS", threads)
    rows, expected = _uniform_rows(300)
    for k in range(100, 130):  # pieces 9-11: another layout
        rows[k] = " ".join("%.9g" % float(t) for t in rows[k].split()) + "\n"
    expected[100:130] = [[float(t) for t in rows[k].split()] for k in range(100, 130)]
    rows[200:200] = ["\n"] * 300  # a piece of blank lines
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows, frames=300), newline="")
    assert np.array_equal(read_bvh_channels(p).channels, expected)
    assert sum(not ok for ok in vector_pieces.values()) >= 2 and len(vector_pieces) > 20
    rows[-5] = rows[-5].replace("e", "x", 1)
    p.write_text(_text(rows, frames=300), newline="")
    with pytest.raises(InputError) as err:
        read_bvh_channels(p)
    assert err.value.where == f"line {HEADER.count(chr(10)) + 3 + len(rows) - 5}"


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork() is POSIX only")
def test_a_forked_child_reads_with_its_own_parsing_threads(tmp_path):
    """Pieces are parsed on threads; a child forked after a read (``prerender --jobs``) has the parent's
    executor but not its threads, so a read there must not wait on work that never starts."""
    rows, expected = _uniform_rows(300)
    p = tmp_path / "m.bvh"
    p.write_text(_text(rows), newline="")
    small = 40_000  # ~12 frames a piece: many pieces, each parsed on a thread
    code = (f"import os, sys, numpy as np\nfrom studyapp.motion import bvh_frames\n"
            f"from studyapp.motion.bvh import read_bvh_channels\nbvh_frames.CHUNK_BYTES = {small}\nbvh_frames.THREADS = 2\n"
            f"first = read_bvh_channels({str(p)!r}).channels\npid = os.fork()\n"
            f"if pid == 0:\n    again = read_bvh_channels({str(p)!r}).channels\n"
            f"    os._exit(0 if np.array_equal(again, first) else 3)\n"
            f"_, status = os.waitpid(pid, 0)\nprint(os.waitstatus_to_exitcode(status))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip().splitlines()[-1] == "0", out.stderr[-2000:]
