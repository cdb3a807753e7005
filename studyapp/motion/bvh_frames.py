"""The MOTION block of a BVH file: lines of numbers -> one ``(frames, channels)`` array, in bounded memory.

The block is read in pieces of whole lines (:data:`CHUNK_BYTES`, a few hundred KB) into one array allocated up
front, so reading never holds the whole text, nor a Python string of it, nor a second copy of the numbers: an
hour of 120 fps motion costs its array plus a few pieces. No pandas (a second's import on a participant's
first trial). Two parsers, both giving exactly Python's ``float()`` of every number (correctly rounded):

* :func:`~studyapp.motion.number_block.parse_block`, vectorized numpy over the raw bytes, for the layouts
  writers use (``%e``, ``%.6f``: the same count of fraction digits in every number of a piece); for a 60 s
  BEAT file in DiffSHEG's ``%e`` layout it executes half the instructions of numpy's C text reader and two
  thirds of ``pandas.read_csv``'s (callgrind, imports excluded);
* numpy's C text reader (:func:`numpy.loadtxt`) for anything else, and for any piece the first refuses; it
  refuses a line whose count of values differs from the first's, and a careful line-by-line pass then names it.

A block whose first piece the vectorized parser refuses goes whole to the C reader (one stream when it is
under :data:`STREAM_MAX_BYTES`).

The vectorized parser runs on a pool of threads, one per core this process may use (:data:`THREADS`, at
most :data:`MAX_THREADS`): its numpy calls release the interpreter lock, so pieces are parsed side by side
while the calling thread reads the next one and copies each result into the array in file order -- the
cores ``pandas.read_csv`` also uses (pandas 3 splits a large file between threads). One piece per thread is
in flight. Everything a piece decides (errors, line numbers, refusals) is still taken in file order, and an
error or a refusal drops the pieces queued after it.

Checks, each an :class:`~studyapp.errors.InputError` naming the file line:

* a line is at most :func:`line_limit` characters (64 per channel plus 1,024): a file whose line breaks
  were lost is refused before any parser sees it;
* every non-blank line has exactly as many values as the hierarchy declares channels; every value is a
  finite number. A piece that fails either check is read again line by line (:func:`slow_frames`), which
  names the first bad line; that pass also accepts a number whose exponent's last digit a writer cut off
  (``1.5e+`` reads as ``1.5``).
* the header's ``Frames:`` only sizes the first allocation, and only when the bytes left in the file could
  hold that many lines; the data lines decide the count (the array grows, or is trimmed, to fit them).
"""
from __future__ import annotations

import io
import math
import os
import re
import threading
import warnings
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from studyapp.errors import InputError
from studyapp.motion.cores import usable_cores
from studyapp.motion.number_block import parse_block

__all__ = ["CHUNK_BYTES", "STREAM_MAX_BYTES", "line_limit", "first_long_line", "parse_frames", "slow_frames"]

#: Bytes of frame text parsed at a time (whole lines; a piece grows to hold at least two of the longest lines).
#: A few hundred KB keep the vectorized parser's work arrays in the CPU's cache.
CHUNK_BYTES = 256 << 10
#: Characters allowed per channel value on a frame line ("-1.2345678901234567e+308 " is 25).
CHARS_PER_CHANNEL = 64
_DANGLING_EXP = re.compile(r"^([-+]?(?:\d+\.?\d*|\.\d+))[eE][-+]?$")
_NON_SPACE = re.compile(rb"\S")

Reader = Callable[[int], bytes]

#: Blocks of frame text up to this size are parsed as one stream (faster: no Python object per line); the
#: reader's array then grows as it goes, so longer blocks (an hour of motion is ~1 GB) go piece by piece
#: into one array allocated once.
STREAM_MAX_BYTES = 64 << 20

# numpy's C text reader in file mode, which np.loadtxt uses for a path but not for an in-memory stream;
# private, so it is optional: without it every block goes piece by piece through np.loadtxt.
try:
    from numpy._core._multiarray_umath import _load_from_filelike as _C_READER
except ImportError:  # pragma: no cover - other numpy layouts
    _C_READER = None


#: Threads that parse pieces: ``None`` is one per core this process may use, at most :data:`MAX_THREADS`;
#: ``1`` parses every piece on the calling thread when it is reached (``bench_motion.py``'s one-thread row,
#: against ``pandas.read_csv`` held to one thread).
THREADS: int | None = None
MAX_THREADS = 4

_POOLS: tuple[int, dict[int, ThreadPoolExecutor]] = (os.getpid(), {})
_POOLS_LOCK = threading.Lock()


def _threads() -> int:
    return max(1, THREADS) if THREADS is not None else usable_cores(MAX_THREADS)


def _pool(workers: int) -> ThreadPoolExecutor:
    """The ``workers`` threads that parse pieces (made on first use, shared by every read of this process). A
    forked child (``prerender --jobs``, a multiprocessing pool) inherits the executor but not its threads, and
    work queued there would never run: each process makes its own."""
    global _POOLS
    with _POOLS_LOCK:
        if _POOLS[0] != os.getpid():
            _POOLS = (os.getpid(), {})
        pools = _POOLS[1]
        if workers not in pools:
            pools[workers] = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="bvh-parse")
        return pools[workers]


class _WhenAsked:
    """``parse_block(piece)`` run when its result is asked for, on the asking thread."""

    def __init__(self, piece: bytes, n_channels: int) -> None:
        self._args = (piece, n_channels)

    def result(self) -> tuple[np.ndarray, int] | None:
        return parse_block(*self._args)

    def cancel(self) -> bool:
        return True


def _drop(parses: list[Future | _WhenAsked | None]) -> None:
    """Cancels parses not started and waits for those running."""
    for later in parses:
        if later is not None and not later.cancel():
            later.exception()


def _parse_later(piece: bytes, n_channels: int, workers: int) -> Future | _WhenAsked | None:
    """``parse_block(piece)`` started on a parsing thread (None for a piece with no frames)."""
    if not piece or not _NON_SPACE.search(piece):
        return None
    return _pool(workers).submit(parse_block, piece, n_channels) if workers > 1 else _WhenAsked(piece, n_channels)


class _LineTooLong(Exception):
    """A line over the limit reached the stream: the piece-by-piece pass reports it."""


class _CheckedText:
    """A file-like ``read`` over the block that hands out whole-line pieces, each checked for overlong
    lines before the C reader sees it."""

    def __init__(self, read: Reader, limit: int) -> None:
        self._pieces = _pieces(b"", read, max(CHUNK_BYTES, 2 * limit))
        self._limit = limit

    def read(self, size: int = -1) -> bytes:
        piece = next(self._pieces, b"")
        if _has_long_line(piece, self._limit):
            raise _LineTooLong
        return piece


def line_limit(n_channels: int) -> int:
    """Longest frame line accepted for ``n_channels`` values."""
    return n_channels * CHARS_PER_CHANNEL + 1024


def first_long_line(blob: bytes | memoryview, limit: int) -> tuple[int, int] | None:
    """(0-based index, length) of the first line of ``blob`` longer than ``limit`` bytes, or ``None``.

    Scans 16 MB at a time with numpy, so a large block costs a few MB and a fraction of a second.
    """
    if len(blob) <= limit:
        return None
    arr = np.frombuffer(blob, dtype=np.uint8)
    last_newline = -1
    lines_before = 0
    step = 1 << 24
    for a in range(0, arr.size, step):
        newlines = np.flatnonzero(arr[a : a + step] == 10) + a
        if newlines.size == 0:
            continue
        lengths = np.diff(newlines, prepend=last_newline) - 1
        over = np.flatnonzero(lengths > limit)
        if over.size:
            return lines_before + int(over[0]), int(lengths[over[0]])
        lines_before += newlines.size
        last_newline = int(newlines[-1])
    tail = arr.size - last_newline - 1
    return (lines_before, tail) if tail > limit else None


def _pieces(first: bytes, read: Reader, chunk: int) -> Iterator[bytes]:
    """The text ``first`` + whatever ``read`` returns, cut after line ends into pieces of about ``chunk``
    bytes (the last piece may lack its line end; a piece over ``chunk`` bytes with no line end at all is
    one overlong line, and the last piece given)."""
    carry = first
    while True:
        more = read(chunk)
        if not more:
            if carry:
                yield carry
            return
        cut = more.rfind(b"\n") + 1
        if cut == 0:
            carry += more
            if len(carry) > chunk:
                yield carry  # the caller's length check reports it
                return
            continue
        # one copy per piece: a fresh bytes object that io.BytesIO then shares instead of copying
        yield b"".join((carry, memoryview(more)[:cut])) if carry else more[:cut] if cut < len(more) else more
        carry = more[cut:]


def _has_long_line(piece: bytes, limit: int) -> bool:
    """Whether a line of ``piece`` is longer than ``limit`` bytes: one backward search per ``limit`` bytes
    (every line inside a window of ``limit + 1`` bytes is short enough), not one pass per byte."""
    pos, end = 0, len(piece)
    while end - pos > limit:
        last = piece.rfind(b"\n", pos, pos + limit + 1)
        if last < 0:
            return True
        pos = last + 1
    return False


def _rest_of_line(read: Reader, chunk: int) -> int:
    """Bytes ``read`` gives before its next line end (or its end), read and dropped ``chunk`` at a time."""
    extra = 0
    while more := read(chunk):
        end = more.find(b"\n")
        if end >= 0:
            return extra + end
        extra += len(more)
    return extra


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _fast_piece(piece: bytes, n_channels: int) -> np.ndarray | None:
    """``(n, n_channels)`` values of a piece of whole lines, ``None`` when anything looks wrong."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data" for blank pieces: shape says it
            values = np.loadtxt(io.BytesIO(piece), dtype=np.float64, comments=None, ndmin=2, encoding="latin-1")
    except ValueError:
        return None
    # a finite sum means every value is finite (an inf or NaN makes the sum one); a sum that overflows only
    # sends the piece to the careful pass, which reads it right
    with np.errstate(over="ignore", invalid="ignore"):
        total = float(values.sum())
    if values.shape[1] != n_channels or not math.isfinite(total):
        return None
    return values


def slow_frames(body: list[str], start: int, n_channels: int, path: str, first_frame: int = 0,
                last: bool = True) -> np.ndarray:
    """Line-by-line parse of frame lines ``body`` (the first is file line ``start + 1`` and frame
    ``first_frame + 1``), raising an :class:`InputError` naming the first bad line; ``last`` says the
    lines end the file (a short last line is then called truncated)."""
    rows = []
    nonempty = [(i, ln) for i, ln in enumerate(body) if ln.strip()]
    for k, (i, ln) in enumerate(nonempty):
        lineno = start + i + 1
        toks = ln.split()
        if len(toks) != n_channels:
            hint = " (the file looks truncated)" if last and k == len(nonempty) - 1 and len(toks) < n_channels else ""
            raise InputError(
                path, f"line {lineno}",
                f"frame {first_frame + k + 1} has {len(toks)} values but the hierarchy declares {n_channels} channels{hint}",
            )
        vals = []
        for col, tok in enumerate(toks):
            try:
                v = float(tok)
            except ValueError:
                m = _DANGLING_EXP.match(tok)
                if not m:
                    raise InputError(path, f"line {lineno}", f"value {col + 1} is not a number: {tok[:40]!r}") from None
                # a writer cut the exponent's last digit ("1.5e+"): the mantissa is the best reading
                v = float(m.group(1))
            if not math.isfinite(v):
                raise InputError(path, f"line {lineno}", f"value {col + 1} is {tok}; channel values must be finite")
            vals.append(v)
        rows.append(vals)
    return np.array(rows, dtype=np.float64).reshape(len(rows), n_channels)


def _first_capacity(header_frames: int | None, first_piece: bytes, first_rows: int, bytes_left: int,
                    n_channels: int) -> int:
    """Rows to allocate: the header's claim when the file's size allows it, else an estimate from the first
    piece's bytes per line (a line of ``C`` values takes at least ``2 C`` bytes, which bounds any claim)."""
    most = first_rows + bytes_left // (2 * n_channels) + 1
    if header_frames is not None and first_rows <= header_frames <= most:
        return header_frames
    if first_rows == 0:
        return 0
    per_line = max(len(first_piece) / first_rows, 2 * n_channels)
    return min(most, first_rows + int(bytes_left / per_line * 1.05) + 1)


def parse_frames(open_data: Callable[[], Reader], size: int, start: int, n_channels: int, path: str,
                 header_frames: int | None = None, dtype: type = np.float64) -> np.ndarray:
    """Frame values ``(F, n_channels)`` of a MOTION block whose first line is file line ``start + 1``.

    ``open_data()`` gives a ``read(n)`` that returns the block's next (up to) ``n`` bytes, ``b""`` at its end,
    from its start each time it is called (a second pass names a bad line); ``size`` is the block's length in
    bytes (it bounds the rows allocated). ``dtype`` is the array's type: float64 keeps every value exactly
    as written; float32 halves the memory (each value is the float64 one rounded to float32).

    The block is read piece by piece into one array allocated up front, by the vectorized parser. When it
    refuses the first piece, blocks up to :data:`STREAM_MAX_BYTES` go to numpy's C reader as one stream (its
    array grows as it reads; no Python object per line); longer ones, float32 and any block that stream
    refuses are read piece by piece by the C reader.
    """
    if n_channels > 0:
        values = _in_pieces(b"", open_data(), size, start, n_channels, path, header_frames, dtype, vector=True)
        if values is not None:
            return values
    if np.dtype(dtype) == np.float64 and n_channels > 0 and size <= STREAM_MAX_BYTES:
        values = _stream(open_data(), n_channels)
        if values is not None:
            return values
    return _in_pieces(b"", open_data(), size, start, n_channels, path, header_frames, dtype)


def _stream(read: Reader, n_channels: int) -> np.ndarray | None:
    """The whole block through numpy's C reader in file mode, ``None`` when anything looks wrong (an
    overlong line, a count of values or a value it refuses, a non-finite value) or numpy lacks that reader."""
    if _C_READER is None:
        return None
    try:
        values = _C_READER(_CheckedText(read, line_limit(n_channels)), delimiter=None, comment=None, quote=None,
                           imaginary_unit="j", usecols=None, skiplines=0, max_rows=-1, converters=None,
                           dtype=np.dtype(np.float64), encoding="latin-1", filelike=True, byte_converters=False)
    except (ValueError, TypeError, _LineTooLong):
        return None
    if values.ndim != 2 or values.shape[0] == 0 or values.shape[1] != n_channels:
        return None
    with np.errstate(over="ignore", invalid="ignore"):
        total = float(values.sum())
    return values if math.isfinite(total) else None


def _in_pieces(first: bytes, read: Reader, bytes_left: int, start: int, n_channels: int, path: str,
               header_frames: int | None, dtype: type, vector: bool = False) -> np.ndarray | None:
    """:func:`parse_frames` piece by piece: ``first`` (text already read) then what ``read`` returns, at
    most ``bytes_left`` bytes, into one array allocated up front; a piece that numpy refuses is read line by
    line, which names the bad line. ``vector``: each piece goes first to the vectorized parser, and ``None``
    is returned when it refuses the first piece that holds frames (later pieces it refuses go to numpy's)."""
    limit = line_limit(n_channels)
    out = np.empty((0, n_channels), dtype=dtype)
    n = 0
    line = start
    pieces = _pieces(first, read, max(CHUNK_BYTES, 2 * limit))
    consumed = 0
    workers = _threads() if vector and n_channels > 0 else 1
    # pieces in file order with their parses, started as they are read: one piece per parsing thread, the next
    # read as the first is taken, so memory holds a few pieces whatever the file's length
    queued: deque[tuple[bytes, Future | _WhenAsked | None]] = deque()

    def fill() -> None:
        while len(queued) < workers and (more := next(pieces, b"")):
            queued.append((more, _parse_later(more, n_channels, workers) if vector and n_channels > 0 else None))

    parsing = None
    try:
        fill()
        while queued:
            piece, parsing = queued.popleft()
            fill()
            last = not queued
            too_long = first_long_line(piece, limit) if _has_long_line(piece, limit) else None
            if too_long is not None:
                at, length = too_long
                if last and at == piece.count(b"\n"):
                    length += _rest_of_line(read, CHUNK_BYTES)  # the message gives the whole line's length
                raise InputError(path, f"line {line + at + 1}",
                                 f"frame line is {length:,} characters long; {n_channels} channels take at most {limit:,} "
                                 "(are the line breaks missing?)")
            line_ends = None
            if _NON_SPACE.search(piece):
                if n_channels == 0:
                    raise InputError(path, f"line {start + 1}", "the hierarchy declares no channels but frame data follows")
                block = parsing.result() if parsing is not None else None
                if block is None and vector and n == 0:
                    return None
                values, line_ends = block if block is not None else (_fast_piece(piece, n_channels), None)
                if values is None:
                    values = slow_frames(_decode(piece).splitlines(), line, n_channels, path, n, last=last)
                consumed += len(piece)
                if n == 0 and out.shape[0] == 0:
                    left = max(len(first) + bytes_left - consumed, 0)
                    out = np.empty((_first_capacity(header_frames, piece, len(values), left, n_channels), n_channels), dtype)
                if n + len(values) > out.shape[0]:
                    grown = np.empty((max(n + len(values), out.shape[0] + out.shape[0] // 2), n_channels), dtype)
                    grown[:n] = out[:n]
                    out = grown
                out[n : n + len(values)] = values
                n += len(values)
            else:
                consumed += len(piece)
            line += piece.count(b"\n") if line_ends is None else line_ends
    finally:  # an error or a refusal: parses still queued stop, and their work arrays are freed here
        _drop([parsing, *(later for _, later in queued)])
    if n == out.shape[0]:
        return out
    # trimmed by a copy when a real share would be wasted (a header claiming far more frames than sent)
    return out[:n].copy() if n < out.shape[0] * 7 // 8 else out[:n]
