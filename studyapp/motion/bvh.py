"""BVH (Biovision Hierarchy) reading and writing.

Real files bend the format (see ``shared/samples/README.md``): tabs or spaces, trailing spaces,
``Frames: 3.0``, a header frame count that disagrees with the data, the last digit of a number cut
off, position channels on any joint, ``End Site`` blocks, per-joint rotation orders. The reader accepts
all of these; everything it cannot make sense of raises :class:`~studyapp.errors.InputError` naming the
file, the line and the problem.

Semantics used here (and by the writer, so round trips are exact):

* Rotation channels are intrinsic Euler angles in degrees, in the order listed:
  ``Zrotation Xrotation Yrotation`` means ``R = R_Z @ R_X @ R_Y``.
* Position channels *replace* the joint's OFFSET on the axes they name (axes without a position
  channel keep the OFFSET value); that is how the root's ``Xposition..Zposition`` is read too.

The frame data is parsed piece by piece into one preallocated array (:mod:`studyapp.motion.bvh_frames`:
values exactly as ``float()`` reads them, bounded memory, no pandas) by a vectorized numpy parser over the
raw bytes (:mod:`studyapp.motion.number_block`) in the layouts writers use (``%e``, ``%.6f``); other
layouts go to numpy's C text reader, as one stream up to 64 MB; only a piece in which that pass finds
something wrong is read again line by line, to name the offending line.

Limits, checked before the parsers see the text, so that no file can make reading hang or exhaust
memory (each is an :class:`~studyapp.errors.InputError` naming the line):

* a HIERARCHY line is at most :data:`MAX_HEADER_LINE` characters;
* a frame line is at most ``64`` characters per declared channel (plus 1,024): a file whose line breaks
  were lost (10 MB on one line) is refused rather than handed to the tokenizer as millions of columns;
* joints nest at most :data:`MAX_JOINT_DEPTH` deep (real skeletons: 7 to 14) and a file declares at most
  :data:`MAX_JOINTS` joints;
* a channel count is a whole number from 0 to 6 (``CHANNELS Infinity`` included);
* the header's ``Frames:`` sizes the first allocation only when the file's size could hold that many
  lines; the data lines decide the count.

>>> import tempfile, os
>>> from studyapp.motion.beat import beat_skeleton
>>> from studyapp.motion.skeleton import Motion
>>> path = os.path.join(tempfile.mkdtemp(), "rest.bvh")
>>> write_bvh(Motion.rest(beat_skeleton(), n_frames=2, fps=15), path)
>>> m = read_bvh(path)
>>> m.n_frames, m.fps, m.skeleton.n_joints, m.skeleton.unit_scale
(2, 15.0, 75, 0.01)
"""
from __future__ import annotations

import math
import os
import re
import warnings
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from studyapp.errors import InputError
from studyapp.motion._threads import map_rows
from studyapp.motion.bvh_frames import first_long_line, parse_frames
from studyapp.motion.fk import figure_height, guess_unit_scale
from studyapp.motion.rotations import euler_to_quat, quat_to_euler
from studyapp.motion.skeleton import Motion, Skeleton

__all__ = [
    "BvhData",
    "BvhWarning",
    "CHANNEL_NAMES",
    "read_bvh",
    "read_bvh_channels",
    "parse_bvh_text",
    "parse_bvh_bytes",
    "write_bvh",
    "format_bvh",
    "motion_from_channels",
    "channels_from_motion",
    "with_rotation_order",
]

#: Canonical spelling of the six BVH channel names (matched case-insensitively on reading).
CHANNEL_NAMES: tuple[str, ...] = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_CANON = {c.lower(): c for c in CHANNEL_NAMES}

#: Longest HIERARCHY line read (names and offsets take well under 200 characters in real files).
MAX_HEADER_LINE = 65_536
#: Deepest joint nesting read (real skeletons from BEAT, CMU, Mixamo, ZEGGS, Truebones: 7 to 14).
MAX_JOINT_DEPTH = 128
#: Most joints read (real skeletons: 22 to 75; hand-and-face rigs a few hundred).
MAX_JOINTS = 4096
_MIN_FRAME_TIME = 1e-5
#: Longest frame time read (s): motion at under one frame a minute is not motion, and its duration
#: (frames x frame time) would turn into billions of frames at any playback rate.
_MAX_FRAME_TIME = 60.0


class BvhWarning(UserWarning):
    """A BVH file was readable but odd (e.g. its header frame count disagrees with its data)."""


@dataclass(eq=False)
class BvhData:
    """The raw content of a BVH file.

    Attributes
    ----------
    skeleton:
        Hierarchy with per-joint channel layout, end sites and guessed ``unit_scale``.
    frame_time:
        Seconds per frame as written in the header (may be wrong; see :func:`read_bvh`'s ``fps``).
    channels:
        ``(F, C)`` float64 raw channel values in file order.
    warnings:
        Messages about tolerated oddities (also issued with :func:`warnings.warn`).
    header_frames:
        The ``Frames:`` value from the header (the data lines are what counts).
    path:
        Source file, for messages.
    """

    skeleton: Skeleton
    frame_time: float
    channels: np.ndarray
    warnings: list[str] = field(default_factory=list)
    header_frames: int | None = None
    path: str = ""

    @property
    def n_frames(self) -> int:
        return int(self.channels.shape[0])

    def to_motion(self, fps: float | None = None) -> Motion:
        """The motion these channels describe (``fps`` overrides the header's frame time)."""
        return _motion_with_raw(self, fps)


# Raw channels of motions made by read_bvh, so that write_bvh can write the file's own numbers
# (exact round trip, no Euler re-decomposition) while the motion is unchanged. Whether it changed is
# checked when writing (rebuilding the motion from the raw channels), which keeps reading cheap.
_RAW: "weakref.WeakKeyDictionary[Motion, tuple[Skeleton, np.ndarray, float]]" = weakref.WeakKeyDictionary()


def _raw_channels_if_unchanged(motion: Motion) -> np.ndarray | None:
    cached = _RAW.get(motion)
    if cached is None or cached[0] is not motion.skeleton:
        return None
    skeleton, channels, _ = cached
    rebuilt = motion_from_channels(skeleton, channels, motion.fps)
    if np.array_equal(rebuilt.rotations, motion.rotations) and np.array_equal(rebuilt.translations, motion.translations):
        return channels
    return None


def _fps_from_frame_time(frame_time: float) -> float:
    """``1 / frame_time``, snapped to a whole number within 0.01 % (headers print 0.008333 for 120 fps).

    >>> _fps_from_frame_time(0.008333), round(_fps_from_frame_time(1 / 29.97), 6)
    (120.0, 29.97)
    """
    fps = 1.0 / frame_time
    nearest = round(fps)
    if nearest > 0 and abs(fps - nearest) <= 1e-4 * fps:
        return float(nearest)
    return fps


def _motion_with_raw(data: BvhData, fps: float | None) -> Motion:
    if fps is None:
        if not (data.frame_time > 0 and math.isfinite(data.frame_time)):
            raise InputError(data.path, "Frame Time", f"frame time {data.frame_time} is not positive; pass the true fps")
        fps = _fps_from_frame_time(data.frame_time)
    elif not (fps > 0 and math.isfinite(fps)):
        raise InputError(data.path, "fps", f"fps must be a positive number, got {fps}")
    motion = motion_from_channels(data.skeleton, data.channels, fps, source=data.path)
    _RAW[motion] = (motion.skeleton, data.channels, data.frame_time)
    return motion


# ---------------------------------------------------------------------------------------------
# reading


def read_bvh(path: str | Path, fps: float | None = None) -> Motion:
    """Read a BVH file into a :class:`Motion`.

    ``fps`` overrides the header's ``Frame Time`` (model outputs often keep the training data's
    120 fps header for 15 fps data). Frame-count disagreements are warned about (:class:`BvhWarning`)
    and the data lines win.
    """
    return read_bvh_channels(path).to_motion(fps)


def read_bvh_channels(path: str | Path, dtype: type = np.float64) -> BvhData:
    """Read a BVH file's hierarchy and raw channel values without converting rotations.

    The file is read in pieces (:mod:`studyapp.motion.bvh_frames`): memory is the channel array plus a few
    MB, whatever the file's length. ``dtype=np.float32`` halves that array (values rounded to float32).
    """
    path = str(path)
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise InputError(path, None, f"cannot read file: {exc.strerror or exc}") from None
    with fh:
        try:
            size = os.fstat(fh.fileno()).st_size
            head = fh.read(_HEAD_BYTES)
            if b"\x00" in head[:4096]:
                raise InputError(path, "line 1", "not a BVH file (binary data); expected text starting with HIERARCHY")
            # the header grows until its Frame Time line is complete (or the file ends): the frame lines
            # after it are read piece by piece by the frame parser
            while True:
                ft = _frame_time_line(head)
                if ft is not None and ft.end() < len(head):
                    break
                more = fh.read(max(len(head), _HEAD_BYTES))
                if not more:
                    break
                head += more

            def data_from(offset: int) -> Callable[[int], bytes]:
                fh.seek(offset)
                return fh.read

            return _parse(head, data_from, size, path, dtype)
        except OSError as exc:
            raise InputError(path, None, f"cannot read file: {exc.strerror or exc}") from None


def parse_bvh_text(text: str, path: str = "<string>") -> BvhData:
    """Parse the text of a BVH file (``path`` is only used in messages)."""
    return parse_bvh_bytes(text.encode("utf-8"), path)


_MOTION_RE = re.compile(rb"(?m)^[ \t]*MOTION[ \t]*\r?$")
_FRAME_TIME_LINE_RE = re.compile(rb"(?im)^[ \t]*Frame[ \t]*Time\b[^\n]*$")
#: Bytes of a file read first: a real header (75 joints) takes about 10 KB.
_HEAD_BYTES = 1 << 16


def _frame_time_line(raw: bytes) -> re.Match | None:
    m = _MOTION_RE.search(raw)
    return _FRAME_TIME_LINE_RE.search(raw, m.end()) if m else None


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def parse_bvh_bytes(raw: bytes, path: str = "<bytes>", dtype: type = np.float64) -> BvhData:
    """Parse the bytes of a BVH file.

    Only the header (up to the ``Frame Time`` line) is decoded and split into lines; the frame data
    goes to the frame parser in pieces, which is what keeps large files fast and small in memory.
    """
    return _parse(raw, lambda offset: _reader(memoryview(raw)[offset:]), len(raw), path, dtype)


def _reader(blob: memoryview) -> Callable[[int], bytes]:
    """A ``read(n)`` over ``blob``: copies of at most ``n`` bytes, then ``b""``."""
    pos = 0

    def read(n: int) -> bytes:
        nonlocal pos
        pos += n
        return bytes(blob[pos - n : pos])

    return read


def _parse(raw: bytes, data_from: Callable[[int], Callable[[int], bytes]], size: int, path: str,
           dtype: type) -> BvhData:
    """Parse a file of ``size`` bytes whose first bytes are ``raw`` (the whole header, or the whole file);
    ``data_from(offset)`` reads the file from that byte on."""
    ft = _frame_time_line(raw)
    too_long = first_long_line(raw[: ft.end()] if ft is not None else raw, MAX_HEADER_LINE)
    if too_long is not None:
        line, length = too_long
        raise InputError(path, f"line {line + 1}", f"line is {length:,} characters long; a BVH header line has at "
                                                   f"most {MAX_HEADER_LINE:,} (are the line breaks missing?)")
    if ft is not None:
        start = ft.end()
        start += 2 if raw.startswith(b"\r\n", start) else 1 if raw.startswith((b"\n", b"\r"), start) else 0
        head = raw[: ft.end()]
        lines = _decode(head).splitlines()
        open_data, data_size = (lambda: data_from(start)), size - start
    else:
        # no well-formed header: the line-based parser below reports what is missing where
        rest = data_from(len(raw))(size - len(raw)) if size > len(raw) else b""
        lines = _decode(raw + rest).splitlines()
    motion_line, skeleton = _parse_hierarchy(lines, path)
    frames, frame_time, data_start = _parse_motion_header(lines, motion_line, path)
    n_channels = sum(len(c) for c in skeleton.channels)
    if ft is None:
        data = memoryview("\n".join(lines[data_start:]).encode("utf-8"))
        open_data, data_size = (lambda: _reader(data)), len(data)
    channels = parse_frames(open_data, data_size, data_start, n_channels, path, frames, dtype)
    notes: list[str] = []
    if frames is not None and frames != channels.shape[0]:
        notes.append(
            f"header says Frames: {frames} but the file has {channels.shape[0]} data lines; using the data lines"
        )
    if channels.shape[0] == 0:
        raise InputError(path, f"line {data_start + 1}", "no motion data: the MOTION section has no frame lines")
    skeleton = _with_unit_guess(skeleton)
    for note in notes:
        warnings.warn(f"{path}: {note}", BvhWarning, stacklevel=3)
    return BvhData(skeleton, frame_time, channels, notes, frames, path)


def _with_unit_guess(skeleton: Skeleton) -> Skeleton:
    return Skeleton(
        skeleton.names, skeleton.parents, skeleton.offsets, skeleton.channels, skeleton.end_sites,
        guess_unit_scale(figure_height(skeleton)), skeleton.rest_rotations,
    )


def _tokens(lines: list[str], start: int, stop: int):
    for i in range(start, stop):
        for tok in lines[i].split():
            # a brace glued to a name ("Hips{") is split off so the grammar below stays simple
            if len(tok) > 1 and (tok.endswith("{") or tok.endswith("}")):
                yield tok[:-1], i + 1
                yield tok[-1], i + 1
            else:
                yield tok, i + 1


def _parse_hierarchy(lines: list[str], path: str) -> tuple[int, Skeleton]:
    """Parse HIERARCHY up to MOTION; return (index of the MOTION line, skeleton)."""
    first = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise InputError(path, "line 1", "empty file; expected a BVH file starting with HIERARCHY")
    head = lines[first].split()[0]
    if head.upper() != "HIERARCHY":
        raise InputError(path, f"line {first + 1}", f"not a BVH file: expected 'HIERARCHY', found {head[:40]!r}")
    motion_line = next((i for i in range(first + 1, len(lines)) if lines[i].strip().upper().startswith("MOTION")), None)
    if motion_line is None:
        raise InputError(path, f"line {len(lines)}", "file ends before the MOTION section (truncated file?)")

    toks = list(_tokens(lines, first + 1, motion_line))
    pos = 0
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    chans: list[tuple[str, ...]] = []
    end_sites: dict[int, np.ndarray] = {}
    end_line = motion_line + 1

    def peek() -> tuple[str | None, int]:
        return toks[pos] if pos < len(toks) else (None, end_line)

    def take(expect: str | None = None, what: str = "") -> tuple[str, int]:
        nonlocal pos
        tok, ln = peek()
        if tok is None:
            raise InputError(path, f"line {ln}", f"HIERARCHY ends early: expected {what or expect!r} before MOTION (missing '}}'?)")
        if expect is not None and tok.upper() != expect.upper():
            raise InputError(path, f"line {ln}", f"expected {what or repr(expect)}, found {tok!r}")
        pos += 1
        return tok, ln

    def number(what: str) -> float:
        tok, ln = take(None, what)
        try:
            v = float(tok)
        except ValueError:
            raise InputError(path, f"line {ln}", f"expected a number for {what}, found {tok!r}") from None
        if not math.isfinite(v):
            raise InputError(path, f"line {ln}", f"{what} is {tok}; it must be a finite number")
        return v

    def offset(owner: str) -> list[float]:
        take("OFFSET", f"'OFFSET' in {owner}")
        return [number(f"OFFSET of {owner}") for _ in range(3)]

    def joint(parent: int, keyword_line: int, depth: int) -> None:
        if depth > MAX_JOINT_DEPTH:
            raise InputError(path, f"line {keyword_line}", f"joints nest more than {MAX_JOINT_DEPTH} deep; real "
                                                           f"skeletons nest 7 to 14 (a '}}' missing?)")
        if len(names) >= MAX_JOINTS:
            raise InputError(path, f"line {keyword_line}", f"more than {MAX_JOINTS} joints; no real skeleton has that many")
        # the name may contain spaces: everything up to the opening brace
        parts = []
        while True:
            tok, ln = peek()
            if tok is None or tok == "{":
                break
            if tok.upper() in ("OFFSET", "CHANNELS", "JOINT", "}"):
                raise InputError(path, f"line {ln}", f"expected '{{' after the joint name, found {tok!r}")
            parts.append(take()[0])
        if not parts:
            raise InputError(path, f"line {keyword_line}", "joint has no name")
        name = " ".join(parts)
        take("{", f"'{{' after joint {name!r}")
        idx = len(names)
        if name in names:
            raise InputError(path, f"line {keyword_line}", f"duplicate joint name {name!r}")
        names.append(name)
        parents.append(parent)
        offsets.append(offset(f"joint {name!r}"))
        layout: tuple[str, ...] = ()
        tok, ln = peek()
        if tok is not None and tok.upper() == "CHANNELS":
            take()
            count_tok, cln = take(None, "channel count")
            try:
                fcount = float(count_tok)
            except ValueError:
                raise InputError(path, f"line {cln}", f"expected a channel count, found {count_tok!r}") from None
            # Infinity and NaN parse as floats; int() of them would raise, so the range is checked first
            if not 0 <= fcount <= 6 or fcount != int(fcount):
                raise InputError(path, f"line {cln}",
                                 f"joint {name!r} declares {count_tok[:40]} channels; BVH allows a whole number 0 to 6")
            count = int(fcount)
            got = []
            for _ in range(count):
                ctok, cl = take(None, f"channel name of joint {name!r}")
                if ctok.upper() in ("JOINT", "END", "}", "{", "OFFSET", "CHANNELS"):
                    raise InputError(
                        path, f"line {cln}",
                        f"joint {name!r} declares {count} channels but lists {len(got)}: {' '.join(got) or 'none'}",
                    )
                canon = _CANON.get(ctok.lower())
                if canon is None:
                    raise InputError(
                        path, f"line {cl}",
                        f"unknown channel {ctok!r} in joint {name!r}; expected one of {', '.join(CHANNEL_NAMES)}",
                    )
                got.append(canon)
            if len(set(got)) != len(got):
                raise InputError(path, f"line {cln}", f"joint {name!r} lists a channel twice: {' '.join(got)}")
            layout = tuple(got)
        chans.append(layout)
        while True:
            tok, ln = peek()
            if tok is None:
                raise InputError(path, f"line {keyword_line}", f"joint {name!r} opened here is never closed: missing '}}'")
            up = tok.upper()
            if up == "}":
                take()
                return
            if up == "JOINT":
                take()
                joint(idx, ln, depth + 1)
            elif up == "END":
                take()
                take("SITE", "'Site' after 'End'")
                take("{", "'{' after End Site")
                if idx in end_sites:
                    raise InputError(path, f"line {ln}", f"joint {name!r} has two End Site blocks")
                end_sites[idx] = np.array(offset(f"End Site of {name!r}"))
                take("}", "'}' closing End Site")
            else:
                raise InputError(path, f"line {ln}", f"expected JOINT, End Site or '}}' in joint {name!r}, found {tok!r}")

    while pos < len(toks):
        tok, ln = take()
        if tok.upper() != "ROOT":
            raise InputError(path, f"line {ln}", f"expected ROOT, found {tok!r}")
        joint(-1, ln, 0)
    if not names:
        raise InputError(path, f"line {motion_line + 1}", "HIERARCHY has no ROOT joint")
    skeleton = Skeleton(tuple(names), np.array(parents), np.array(offsets, dtype=np.float64), tuple(chans), end_sites)
    return motion_line, skeleton


_FRAMES_RE = re.compile(r"^\s*Frames\s*:?\s*(\S+)\s*$", re.IGNORECASE)
_FTIME_RE = re.compile(r"^\s*Frame\s*Time\s*:?\s*(\S+)\s*$", re.IGNORECASE)


def _parse_motion_header(lines: list[str], motion_line: int, path: str) -> tuple[int | None, float, int]:
    """Return (header frame count, frame time, index of the first data line)."""
    rest = lines[motion_line].strip()[len("MOTION"):].strip()
    if rest:
        raise InputError(path, f"line {motion_line + 1}", f"unexpected text after MOTION: {rest[:40]!r}")
    i = motion_line + 1
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines):
        raise InputError(path, f"line {i}", "file ends after MOTION: expected 'Frames:' (truncated file?)")
    m = _FRAMES_RE.match(lines[i])
    if not m:
        raise InputError(path, f"line {i + 1}", f"expected 'Frames: N', found {lines[i].strip()[:40]!r}")
    try:
        fval = float(m.group(1))
    except ValueError:
        raise InputError(path, f"line {i + 1}", f"frame count {m.group(1)!r} is not a number") from None
    # "Frames: 3.0" is tolerated; the data lines decide the real count anyway
    frames = int(fval) if math.isfinite(fval) and fval >= 0 and fval == int(fval) else None
    if frames is None:
        raise InputError(path, f"line {i + 1}", f"frame count {m.group(1)!r} is not a whole number")
    i += 1
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines):
        raise InputError(path, f"line {i}", "file ends after 'Frames:': expected 'Frame Time:' (truncated file?)")
    m = _FTIME_RE.match(lines[i])
    if not m:
        raise InputError(path, f"line {i + 1}", f"expected 'Frame Time: seconds', found {lines[i].strip()[:40]!r}")
    try:
        frame_time = float(m.group(1))
    except ValueError:
        raise InputError(path, f"line {i + 1}", f"frame time {m.group(1)!r} is not a number") from None
    if not math.isfinite(frame_time) or frame_time < 0:
        raise InputError(path, f"line {i + 1}", f"frame time {m.group(1)} must be a positive number of seconds")
    if 0 < frame_time < _MIN_FRAME_TIME:  # 1 / frame_time must stay a frame rate (1e-300 gives infinity)
        raise InputError(path, f"line {i + 1}", f"frame time {m.group(1)} s is more than {1 / _MIN_FRAME_TIME:,.0f} "
                                                "frames per second; is it in seconds?")
    if frame_time > _MAX_FRAME_TIME:
        raise InputError(path, f"line {i + 1}", f"frame time {m.group(1)} s is longer than {_MAX_FRAME_TIME:g} s per "
                                                "frame; is it in seconds?")
    return frames, frame_time, i + 1


# ---------------------------------------------------------------------------------------------
# channels <-> motion


def _layout(skeleton: Skeleton) -> list[tuple[int, list[int], list[int], str | None, list[int]]]:
    """Per joint: (joint, position columns, position axes, rotation order, rotation columns)."""
    out = []
    col = 0
    for j, chans in enumerate(skeleton.channels):
        pcols, paxes, rcols, order = [], [], [], ""
        for c in chans:
            axis = "XYZ".index(c[0].upper())
            if c.lower().endswith("position"):
                pcols.append(col)
                paxes.append(axis)
            else:
                rcols.append(col)
                order += "XYZ"[axis]
            col += 1
        out.append((j, pcols, paxes, order or None, rcols))
    return out


def motion_from_channels(skeleton: Skeleton, data: np.ndarray, fps: float, source: str = "") -> Motion:
    """Build a :class:`Motion` from raw BVH channel values ``(F, C)`` laid out as ``skeleton.channels``.

    Joints that share a rotation order are converted in one batched call.
    """
    data = np.asarray(data, dtype=np.float64)
    layout = _layout(skeleton)
    n_ch = sum(len(c) for c in skeleton.channels)
    if data.ndim != 2 or data.shape[1] != n_ch:
        raise ValueError(f"channel data must be (frames, {n_ch}), got {data.shape}")
    f, j = data.shape[0], skeleton.n_joints
    trans = np.broadcast_to(skeleton.offsets, (f, j, 3)).copy()
    full = [x for x in layout if x[3] is not None and len(x[3]) == 3]
    if len(full) == j and len({x[3] for x in full}) == 1:
        # the common case (BEAT, Mixamo): one order on every joint, one conversion, no scatter
        cols = np.array([x[4] for x in full])
        order = full[0][3]
        rot = map_rows(lambda rows: euler_to_quat(rows, order), data[:, cols])
        layout = [(jj, pcols, paxes, None, rcols) for jj, pcols, paxes, _, rcols in layout]
    else:
        rot = np.empty((f, j, 4))
        rot[:] = skeleton.rest_rotations
    by_order: dict[str, list[tuple[int, list[int]]]] = {}
    for jj, pcols, paxes, order, rcols in layout:
        if pcols:
            trans[:, jj, paxes] = data[:, pcols]
        if order is not None:
            if len(order) == 3:
                by_order.setdefault(order, []).append((jj, rcols))
            else:
                # fewer than three rotation channels ("Zrotation" only): the missing axes are zero
                angles = np.zeros((f, 3))
                angles[:, : len(rcols)] = data[:, rcols]
                rot[:, jj] = euler_to_quat(angles, _complete_order(order))
    for order, items in by_order.items():
        idx = [jj for jj, _ in items]
        cols = np.array([c for _, c in items])  # (n, 3)
        rot[:, idx] = euler_to_quat(data[:, cols], order)
    return Motion(skeleton, fps, rot, trans, source=source)


def channels_from_motion(motion: Motion) -> np.ndarray:
    """Raw BVH channel values ``(F, C)`` of ``motion`` in its skeleton's channel layout.

    Rotations are decomposed afresh (angles in the principal ranges), so the numbers may differ from
    a source file's while describing the same poses. Joints with fewer than three rotation channels
    can only carry rotations about those axes.
    """
    skeleton = motion.skeleton
    layout = _layout(skeleton)
    f = motion.n_frames
    n_ch = sum(len(c) for c in skeleton.channels)
    out = np.zeros((f, n_ch))
    by_order: dict[str, list[tuple[int, list[int]]]] = {}
    for jj, pcols, paxes, order, rcols in layout:
        if pcols:
            out[:, pcols] = motion.translations[:, jj][:, paxes]
        if order is not None:
            if len(order) == 3:
                by_order.setdefault(order, []).append((jj, rcols))
            else:
                full = _complete_order(order)
                ang = quat_to_euler(motion.rotations[:, jj], full)
                for k, c in enumerate(rcols):
                    out[:, c] = ang[:, k]
    for order, items in by_order.items():
        idx = [jj for jj, _ in items]
        cols = np.array([c for _, c in items])
        out[:, cols] = quat_to_euler(motion.rotations[:, idx], order)
    return out


def _complete_order(order: str) -> str:
    rest = [a for a in "XYZ" if a not in order]
    return order + "".join(rest)[: 3 - len(order)]


def with_rotation_order(skeleton: Skeleton, order: str) -> Skeleton:
    """The same skeleton with every joint's rotation channels in ``order`` (position channels kept first).

    Joints without channels stay without; joints with only position channels get rotation channels,
    since a motion may rotate them.
    """
    o = order.upper()
    if len(o) != 3 or set(o) != set("XYZ"):
        raise ValueError(f"BVH rotation order must be a permutation of XYZ, got {order!r}")
    rot = tuple(f"{a}rotation" for a in o)
    chans = []
    for c in skeleton.channels:
        if not c:
            chans.append(())
            continue
        pos = tuple(x for x in c if x.lower().endswith("position"))
        chans.append(pos + rot)
    return Skeleton(
        skeleton.names, skeleton.parents, skeleton.offsets, tuple(chans), skeleton.end_sites,
        skeleton.unit_scale, skeleton.rest_rotations,
    )


# ---------------------------------------------------------------------------------------------
# writing


def _fmt(v: float, precision: int) -> str:
    return f"{v:.{precision}f}"


def format_bvh(skeleton: Skeleton, channels: np.ndarray, frame_time: float, precision: int = 6) -> str:
    """BVH text of a hierarchy and its raw channel values ``(F, C)``."""
    channels = np.asarray(channels, dtype=np.float64)
    n_ch = sum(len(c) for c in skeleton.channels)
    if channels.ndim != 2 or channels.shape[1] != n_ch:
        raise ValueError(f"channel data must be (frames, {n_ch}), got {channels.shape}")
    if not np.isfinite(channels).all():
        raise ValueError("channel data contains NaN or infinite values")
    out = ["HIERARCHY"]
    emitted: list[int] = []  # joints in the order the hierarchy lists them, which the MOTION columns follow
    children = [[] for _ in skeleton.names]
    for j, p in enumerate(skeleton.parents):
        if p >= 0:
            children[p].append(j)

    def off(v: np.ndarray) -> str:
        return " ".join(_fmt(float(x), precision) for x in v)

    def emit(j: int, depth: int) -> None:
        ind = "\t" * depth
        kw = "ROOT" if skeleton.parents[j] < 0 else "JOINT"
        emitted.append(j)
        out.append(f"{ind}{kw} {skeleton.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET {off(skeleton.offsets[j])}")
        if skeleton.channels[j]:
            out.append(f"{ind}\tCHANNELS {len(skeleton.channels[j])} {' '.join(skeleton.channels[j])}")
        for c in children[j]:
            emit(c, depth + 1)
        if j in skeleton.end_sites:
            out.append(f"{ind}\tEnd Site")
            out.append(f"{ind}\t{{")
            out.append(f"{ind}\t\tOFFSET {off(skeleton.end_sites[j])}")
            out.append(f"{ind}\t}}")
        out.append(f"{ind}}}")

    for j, p in enumerate(skeleton.parents):
        if p < 0:
            emit(j, 0)
    # Joints may be stored in any parent-first order (SMPL's puts both hips before either knee), but a BVH
    # lists them depth-first and its channel values follow that listing: reorder the columns to match.
    start = np.concatenate([[0], np.cumsum([len(c) for c in skeleton.channels])])
    columns = np.concatenate([np.arange(start[j], start[j + 1]) for j in emitted]).astype(np.int64)
    channels = channels[:, columns]
    out.append("MOTION")
    out.append(f"Frames: {channels.shape[0]}")
    out.append(f"Frame Time: {frame_time:.{max(precision, 10)}g}")
    if n_ch:
        line = " ".join([f"%.{precision}f"] * n_ch)
        out.extend(line % tuple(row) for row in channels.tolist())
    return "\n".join(out) + "\n"


def write_bvh(motion: Motion | BvhData, path: str | Path, order: str | None = None, precision: int = 6) -> None:
    """Write a motion (or raw :class:`BvhData`) as BVH.

    ``order`` (``"ZXY"`` etc.) rewrites every joint's rotation channels in that order; by default
    each joint keeps its skeleton's channel layout. A motion read with :func:`read_bvh` and not
    changed since is written from the file's own channel values, so read -> write -> read is exact to
    the printed precision.
    """
    if isinstance(motion, BvhData):
        if order is None:
            text = format_bvh(motion.skeleton, motion.channels, motion.frame_time, precision)
            Path(path).write_text(text)
            return
        motion = motion.to_motion()
    skeleton = motion.skeleton
    channels = None
    frame_time = 1.0 / float(motion.fps)
    if order is not None:
        skeleton = with_rotation_order(skeleton, order)
        if skeleton.channels == motion.skeleton.channels:
            skeleton = motion.skeleton
    if skeleton is motion.skeleton:
        channels = _raw_channels_if_unchanged(motion)
    cached = _RAW.get(motion)
    if cached is not None and cached[2] > 0 and _fps_from_frame_time(cached[2]) == float(motion.fps):
        frame_time = cached[2]  # keep the header's own spelling (0.008333 stays 0.008333)
    if channels is None:
        target = motion if skeleton is motion.skeleton else Motion(
            skeleton, motion.fps, motion.rotations, motion.translations, motion.source
        )
        channels = channels_from_motion(target)
    text = format_bvh(skeleton, channels, frame_time, precision)
    Path(path).write_text(text)
