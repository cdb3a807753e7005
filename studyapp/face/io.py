"""Read and write ARKit facial animation files; one function per format, one dispatcher.

Formats (chosen by content first, extension second):

* **Live Link Face CSV** (Epic's iPhone app): ``Timecode, BlendShapeCount``, 52 PascalCase shapes in the app's
  own column order, ``HeadYaw, HeadPitch, HeadRoll`` (kept as head rotation, values as written) and six eye angles (ignored).
  Timecodes are ``HH:MM:SS:FF.fff`` (frame plus sub-frame fraction) at the timecode rate, which is not the
  capture rate: a 30 fps take on a 60 fps timecode steps the frame field by 2. The rate is derived from the
  time stamps themselves.
* **BEAT facial JSON**: ``{"names": [...51...], "frames": [{"weights": [...], "time": t, "rotation": [...]}]}``.
* **Plain CSV**: a header row of ARKit names in any order and case, an optional ``time`` column (seconds), an
  optional ``frame`` column and optional ``HeadYaw, HeadPitch, HeadRoll`` (radians).
* **NPZ** with ``weights`` ``(F, K)`` and ``names`` ``(K,)`` [+ ``fps``]; **bare NPY** ``(F, 52)`` in Apple order
  (needs ``fps``).

Limits, checked before anything is sized from the file (each an :class:`~studyapp.errors.InputError`): a CSV
has at most :data:`MAX_CSV_COLUMNS` columns (real files: 52 to 63 and a few extra), JSON nests at most
:data:`MAX_JSON_DEPTH` deep (BEAT's is 3), and time stamps with a gap are resampled only while the regular
grid they imply stays within a few times the rows the file has (a stamp of 10^9 s would otherwise ask for
billions of frames).

Columns are always mapped by name (case-insensitive, see :func:`~studyapp.face.arkit.match_arkit_name`),
never by position. Shapes the source lacks are zero and reported with :func:`warnings.warn`; names that are
not ARKit shapes are kept in ``FaceAnimation.unknown``. Every malformed input raises
:class:`~studyapp.errors.InputError` naming the file, the line/column/key and the problem.

>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "face.csv"
>>> save_face_csv(FaceAnimation.neutral(3, 30.0), p)
>>> load_face(p).fps, load_face(p).n_frames
(30.0, 3)
"""
from __future__ import annotations

import csv
import io
import json
import math
import re
import warnings
from pathlib import Path

import numpy as np

from studyapp.errors import InputError
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_INDEX, ARKIT_NAMES, N_ARKIT, match_arkit_name
from studyapp.safe_io import load_npy, open_npz

#: Weights beyond these limits are not rounding noise but a different scale (e.g. percent): refuse them.
_WEIGHT_LIMITS = (-0.5, 1.5)
_TIME_COLUMNS = {"time", "time_s", "times", "timestamp", "seconds", "t", "sec"}
_FRAME_COLUMNS = {"frame", "frames", "frame_index", "index"}
_HEAD_COLUMNS = ("headyaw", "headpitch", "headroll")
_LIVELINK_EYES = {f"{side}eye{angle}" for side in ("left", "right") for angle in ("yaw", "pitch", "roll")}
# Timecode rates a Live Link Face (or any SMPTE) clock runs at; the file's frame field must stay below it.
_TIMECODE_RATES = (24, 25, 30, 48, 50, 60, 100, 120, 240)
#: Most columns a face CSV may have (Live Link Face writes 63; ARKit names, time and head angles are 57).
MAX_CSV_COLUMNS = 1024
#: Deepest JSON nesting read (BEAT facial JSON nests 3 deep; Python's reader fails near 1,000).
MAX_JSON_DEPTH = 64
_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')
_TIMECODE = re.compile(r"^\s*(\d+):(\d{1,2}):(\d{1,2})[:;](\d+)(?:\.(\d+))?\s*$")


# ----------------------------------------------------------------------------------------------- dispatch

def load_face(path: str | Path, fps: float | None = None) -> FaceAnimation:
    """Load facial animation from any supported file; ``fps`` overrides the rate the file implies.

    The result is in Apple's ARKit order whatever the file's column order; see the module docstring.
    """
    return _load(Path(path), fps)[0]


def _load(path: Path, fps: float | None) -> tuple[FaceAnimation, str]:
    if fps is not None and not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise InputError(path, None, f"fps must be a positive number, got {fps!r}")
    if not path.is_file():
        raise InputError(path, None, "file not found" if not path.exists() else "not a regular file")
    with path.open("rb") as f:
        head = f.read(8)
    if head.startswith(b"\x93NUMPY"):
        return _load_npy(path, fps), "npy"
    if head.startswith(b"PK"):
        return _load_npz(path, fps), "npz"
    if path.suffix.lower() in (".npy", ".npz"):
        raise InputError(path, None, f"not a NumPy {path.suffix} file (bad magic bytes {head[:6]!r})")
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(path, f"byte {exc.start}", "not a UTF-8 text file; expected CSV, JSON, NPY or NPZ") from None
    if not text.strip():
        raise InputError(path, None, "file is empty")
    if text.lstrip().startswith(("{", "[")) or path.suffix.lower() == ".json":
        return _load_beat_json(path, text, fps), "beat-json"
    header, rows = _read_csv(path, text)
    keys = [h.strip().lower() for h in header]
    if keys and keys[0] == "timecode" and "blendshapecount" in keys:
        return _load_livelink(path, header, rows, fps), "livelink-csv"
    if any(match_arkit_name(h) for h in header):
        return _load_plain_csv(path, header, rows, fps), "plain-csv"
    raise InputError(
        path, "line 1",
        "unknown face data layout: the header names no ARKit blendshape (expected a Live Link Face CSV, a CSV "
        "with ARKit names as column headers, BEAT facial JSON, or NPY/NPZ)",
    )


# ----------------------------------------------------------------------------------------------- helpers

def _read_csv(path: Path, text: str) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header and ``(line number, cells)`` of each non-blank row; ragged rows are refused here."""
    first = text.splitlines()[0] if text.splitlines() else ""
    delimiter = "\t" if "\t" in first and "," not in first else (";" if ";" in first and "," not in first else ",")
    reader = csv.reader(io.StringIO(text), delimiter=delimiter)
    header: list[str] | None = None
    rows: list[tuple[int, list[str]]] = []
    trailing = False
    try:
        for cells in reader:
            if not cells or all(not c.strip() for c in cells):
                continue
            if header is None:
                # Some writers end every line with a delimiter; the empty last cell is then not a column.
                trailing = len(cells) > 1 and not cells[-1].strip()
                header = [c.strip() for c in (cells[:-1] if trailing else cells)]
                header_line = reader.line_num
                if len(header) > MAX_CSV_COLUMNS:
                    raise InputError(path, f"line {header_line}", f"the header has {len(header):,} columns; a face "
                                     f"CSV has at most {MAX_CSV_COLUMNS:,} (52 ARKit shapes and a few more)")
                continue
            if trailing and len(cells) == len(header) + 1 and not cells[-1].strip():
                cells = cells[:-1]
            if len(cells) != len(header):
                raise InputError(path, f"line {reader.line_num}",
                                 f"row has {len(cells)} fields but the header (line {header_line}) has {len(header)}")
            rows.append((reader.line_num, cells))
    except csv.Error as exc:
        raise InputError(path, f"line {reader.line_num}", f"unreadable CSV: {exc}") from None
    if header is None:
        raise InputError(path, None, "file is empty")
    if not rows:
        raise InputError(path, "line 2", "no data rows after the header")
    empty = [i + 1 for i, h in enumerate(header) if not h]
    if empty:
        raise InputError(path, f"line 1, column {empty[0]}", "empty column name in the header")
    return header, rows


def _json_depth_error(path: Path, text: str) -> InputError | None:
    """The error for JSON nested deeper than :data:`MAX_JSON_DEPTH`, or ``None``; strings are skipped and the
    depth is counted with numpy, so a large file costs one pass at C speed."""
    raw = text.encode("utf-8")
    if raw.count(b"[") + raw.count(b"{") <= MAX_JSON_DEPTH:
        return None
    # strings replaced by as many 'x' (same offsets), so brackets inside names do not count
    bare = _JSON_STRING.sub(lambda m: b"x" * len(m.group(0)), raw)
    arr = np.frombuffer(bare, dtype=np.uint8)
    step = np.zeros(arr.size, dtype=np.int32)
    step[(arr == ord("[")) | (arr == ord("{"))] = 1
    step[(arr == ord("]")) | (arr == ord("}"))] = -1
    depth = np.cumsum(step)
    over = np.flatnonzero(depth > MAX_JSON_DEPTH)
    if not over.size:
        return None
    at = int(over[0])
    line = raw.count(b"\n", 0, at) + 1
    col = at - (raw.rfind(b"\n", 0, at) + 1) + 1
    return InputError(path, f"line {line}, column {col}", f"JSON nested more than {MAX_JSON_DEPTH} deep; BEAT facial "
                                                          "JSON nests 3 deep")


def _numeric(path: Path, header: list[str], rows: list[tuple[int, list[str]]], cols: list[int]) -> np.ndarray:
    """``(F, len(cols))`` floats from the given columns; a bad cell is reported by line and column name."""
    try:  # fast path: numpy parses the whole block; the cell-by-cell loop below only runs to name a bad cell
        out = np.array([[cells[c] for c in cols] for _, cells in rows], dtype=np.float64).reshape(len(rows), len(cols))
        if np.isfinite(out).all():
            return out
    except ValueError:
        pass
    out = np.empty((len(rows), len(cols)), dtype=np.float64)
    for r, (line, cells) in enumerate(rows):
        for c, col in enumerate(cols):
            cell = cells[col].strip()
            try:
                v = float(cell)
            except ValueError:
                raise InputError(path, f"line {line}, column {header[col]}",
                                 f"not a number: {cell!r}" if cell else "empty value") from None
            if not math.isfinite(v):
                raise InputError(path, f"line {line}, column {header[col]}", f"value is {cell!r}; weights must be finite")
            out[r, c] = v
    return out


def _snap_fps(fps: float) -> float:
    """Round an estimated rate to the standard rate it evidently is (30, 29.97, 60, ...) when within 0.05% (capture clocks jitter)."""
    whole = round(fps)
    if whole > 0 and abs(fps - whole) <= 5e-4 * whole:
        return float(whole)
    ntsc = round(fps * 1.001) / 1.001
    if ntsc > 0 and abs(fps - ntsc) <= 5e-4 * ntsc:
        return ntsc
    return float(fps)


def _fps_from_times(path: Path, times: np.ndarray, lines: list[str]) -> tuple[float, bool]:
    """Frame rate implied by time stamps, and whether the stamps are uneven (dropped frames).

    The rate comes from the whole span, not one step, so rounding of printed stamps does not bias it.
    """
    if times.size < 2:
        raise InputError(path, None, "a single frame has no frame rate; pass fps explicitly")
    steps = np.diff(times)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(path, lines[i], f"time stamps must increase ({times[i]:g} after {times[i - 1]:g})")
    step = float(np.median(steps))
    uneven = bool(np.any(np.abs(steps - step) > 0.5 * step))
    if uneven:
        fps = 1.0 / step
    else:
        fps = (times.size - 1) / float(times[-1] - times[0])
    if not math.isfinite(fps) or fps > 10_000:
        raise InputError(path, lines[1], f"time stamps {times[0]:g}, {times[1]:g}, ... imply {fps:g} frames per "
                                         "second; are they in seconds?")
    return _snap_fps(fps), uneven


def _regularize(path: Path, values: np.ndarray, times: np.ndarray, fps: float,
                lines: list[str] | None = None) -> np.ndarray:
    """Resample rows stamped at uneven times (dropped frames) onto the regular ``fps`` grid.

    The grid's size comes from the stamps, so it is checked first: more than four times the rows (plus
    1,000) is not dropped frames but a wrong stamp, reported at the largest gap.
    """
    span = float(times[-1] - times[0])
    limit = 4 * times.size + 1000
    if not span * fps < limit:
        i = int(np.argmax(np.diff(times))) + 1
        where = lines[i] if lines else None
        raise InputError(path, where, f"time stamps jump from {times[i - 1]:g} to {times[i]:g} s: at {fps:g} fps the "
                                      f"{times.size} rows would span {span * fps:.3g} frames (a wrong time stamp?)")
    n = int(round(span * fps)) + 1
    grid = times[0] + np.arange(n) / fps
    warnings.warn(f"{path}: time stamps are uneven (dropped frames?); resampled {times.size} rows "
                  f"onto {n} frames at {fps:g} fps", stacklevel=5)
    return np.stack([np.interp(grid, times, values[:, c]) for c in range(values.shape[1])], axis=1)


def _check_range(path: Path, values: np.ndarray, names: list[str], where_row) -> None:
    lo, hi = _WEIGHT_LIMITS
    bad = np.argwhere((values < lo) | (values > hi))
    if bad.size:
        r, c = (int(x) for x in bad[0])
        raise InputError(path, f"{where_row(r)}, column {names[c]}",
                         f"weight {values[r, c]:g} is far outside [0, 1] (a 0-100 scale? divide by 100)")


def _assemble(path: Path, names: list[str], values: np.ndarray, fps: float, head: np.ndarray | None,
              where_name, ignored: set[str] = frozenset()) -> FaceAnimation:
    """Place source columns into ARKit order by name; warn about missing shapes, report unknown names."""
    weights = np.zeros((values.shape[0], N_ARKIT), dtype=np.float32)
    seen: dict[str, str] = {}
    unknown: list[str] = []
    for c, name in enumerate(names):
        canon = match_arkit_name(name)
        if canon is None:
            if name.strip().lower() not in ignored:
                unknown.append(name)
            continue
        if canon in seen:
            raise InputError(path, where_name(c), f"{name!r} and {seen[canon]!r} both name the ARKit shape {canon!r}")
        seen[canon] = name
        weights[:, ARKIT_INDEX[canon.lower()]] = values[:, c]
    missing = tuple(n for n in ARKIT_NAMES if n not in seen)
    if missing:
        warnings.warn(f"{path}: {len(missing)} ARKit blendshape(s) missing, set to 0: {', '.join(missing)}",
                      stacklevel=5)
    return FaceAnimation(weights, fps, head, str(path), missing, tuple(unknown))


# ----------------------------------------------------------------------------------------------- formats

def _parse_timecode(path: Path, cell: str, where: str) -> tuple[int, int, int, int, float]:
    m = _TIMECODE.match(cell)
    if not m:
        raise InputError(path, where, f"bad timecode {cell!r}; expected HH:MM:SS:FF or HH:MM:SS:FF.fff")
    hh, mm, ss, ff = (int(m.group(i)) for i in range(1, 5))
    frac = float("0." + m.group(5)) if m.group(5) else 0.0
    if mm > 59 or ss > 59:
        raise InputError(path, where, f"bad timecode {cell!r}: minutes and seconds must be below 60")
    return hh, mm, ss, ff, frac


def _timecode_seconds(path: Path, tcs: list[tuple[int, int, int, int, float]], lines: list[str]) -> np.ndarray:
    """Seconds of each timecode, choosing the timecode rate that makes the stamps evenly spaced.

    The frame field only tells the rate once it wraps into the next second, so each standard rate above the
    largest frame number seen is tried and the first giving even steps wins (with no wrap, all do: the
    slowest such rate is then the only one consistent with the file).
    """
    arr = np.array(tcs, dtype=np.float64)
    whole = arr[:, 0] * 3600 + arr[:, 1] * 60 + arr[:, 2]
    sub = arr[:, 3] + arr[:, 4]
    max_frame = int(arr[:, 3].max())
    rates = [r for r in _TIMECODE_RATES if r > max_frame]
    if not rates:
        raise InputError(path, lines[int(arr[:, 3].argmax())],
                         f"timecode frame field {max_frame} exceeds every standard timecode rate")
    best = None
    for rate in rates:
        t = whole + sub / rate
        steps = np.diff(t)
        if steps.size == 0:
            return t
        if np.all(steps > 0):
            spread = float(np.max(np.abs(steps - np.median(steps))) / np.median(steps))
            if spread < 0.25:
                return t
            if best is None or spread < best[0]:
                best = (spread, t)
    if best is None:
        t = whole + sub / rates[0]
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise InputError(path, lines[i], "timecodes do not increase")
    return best[1]


def _load_livelink(path: Path, header: list[str], rows, fps: float | None) -> FaceAnimation:
    keys = [h.lower() for h in header]
    lines = [f"line {ln}" for ln, _ in rows]
    tcs = [_parse_timecode(path, cells[0], f"line {ln}, column {header[0]}") for ln, cells in rows]
    count_col = keys.index("blendshapecount")
    _numeric(path, header, rows, [count_col])  # validated only: the app writes 61 whatever it recorded
    shape_cols = [i for i, k in enumerate(keys) if i not in (0, count_col) and k not in _HEAD_COLUMNS]
    head_cols = [keys.index(k) for k in _HEAD_COLUMNS if k in keys]
    values = _numeric(path, header, rows, shape_cols)
    names = [header[i] for i in shape_cols]
    _check_range(path, values, names, lambda r: lines[r])
    head = _numeric(path, header, rows, head_cols) if len(head_cols) == 3 else None
    if fps is None:
        times = _timecode_seconds(path, tcs, lines)
        fps, uneven = _fps_from_times(path, times, lines)
        if uneven:
            values = _regularize(path, values, times, fps, lines)
            head = None if head is None else _regularize(path, head, times, fps, lines)
    return _assemble(path, names, values, fps, head,
                     lambda c: f"line 1, column {names[c]}", ignored=_LIVELINK_EYES)


def _load_plain_csv(path: Path, header: list[str], rows, fps: float | None) -> FaceAnimation:
    keys = [h.lower() for h in header]
    lines = [f"line {ln}" for ln, _ in rows]
    dup = sorted({h for h in keys if keys.count(h) > 1})
    if dup:
        raise InputError(path, "line 1", f"duplicate column(s) {', '.join(dup)}")
    time_col = next((i for i, k in enumerate(keys) if k in _TIME_COLUMNS), None)
    head_cols = [keys.index(k) for k in _HEAD_COLUMNS if k in keys]
    meta = {time_col, *head_cols} | {i for i, k in enumerate(keys) if k in _FRAME_COLUMNS}
    shape_cols = [i for i in range(len(header)) if i not in meta]
    names = [header[i] for i in shape_cols]
    # Unknown text columns (a "subject" label, say) are reported, not parsed; only ARKit columns must be numeric.
    arkit_cols = [i for i in shape_cols if match_arkit_name(header[i])]
    values = np.zeros((len(rows), len(shape_cols)))
    values[:, [shape_cols.index(i) for i in arkit_cols]] = _numeric(path, header, rows, arkit_cols)
    _check_range(path, values, names, lambda r: lines[r])
    head = _numeric(path, header, rows, head_cols) if len(head_cols) == 3 else None
    if fps is None:
        if time_col is None:
            raise InputError(path, "line 1", "no time column and no fps given: add a 'time' column (seconds) "
                                             "or pass the frame rate")
        times = _numeric(path, header, rows, [time_col])[:, 0]
        fps, uneven = _fps_from_times(path, times, lines)
        if uneven:
            values = _regularize(path, values, times, fps, lines)
            head = None if head is None else _regularize(path, head, times, fps, lines)
    return _assemble(path, names, values, fps, head, lambda c: f"line 1, column {names[c]}")


def _load_beat_json(path: Path, text: str, fps: float | None) -> FaceAnimation:
    too_deep = _json_depth_error(path, text)
    if too_deep is not None:
        raise too_deep
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(path, f"line {exc.lineno}, column {exc.colno}", f"invalid JSON: {exc.msg}") from None
    if not isinstance(doc, dict):
        raise InputError(path, None, "expected a JSON object with keys 'names' and 'frames' (BEAT facial JSON)")
    for key in ("names", "frames"):
        if key not in doc:
            raise InputError(path, f"key {key}", "missing; BEAT facial JSON needs 'names' and 'frames'")
    names = doc["names"]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise InputError(path, "key names", "must be a non-empty list of blendshape names")
    frames = doc["frames"]
    if not isinstance(frames, list) or not frames:
        raise InputError(path, "key frames", "must be a non-empty list of frames")
    k = len(names)
    values = np.empty((len(frames), k))
    times = np.empty(len(frames))
    rotations = []
    for i, fr in enumerate(frames):
        where = f"key frames[{i}]"
        if not isinstance(fr, dict):
            raise InputError(path, where, "each frame must be an object with 'weights' and 'time'")
        for key in ("weights", "time") if fps is None else ("weights",):
            if key not in fr:
                raise InputError(path, f"{where}.{key}", "missing")
        w = fr["weights"]
        if not isinstance(w, list) or len(w) != k:
            got = len(w) if isinstance(w, list) else type(w).__name__
            raise InputError(path, f"{where}.weights", f"expected {k} weights (one per name), got {got}")
        try:
            row = np.array(w, dtype=np.float64)
        except (TypeError, ValueError):
            bad = next(j for j, x in enumerate(w) if not isinstance(x, (int, float)) or isinstance(x, bool))
            raise InputError(path, f"{where}.weights[{bad}] ({names[bad]})", f"not a number: {w[bad]!r}") from None
        if not np.isfinite(row).all():
            bad = int(np.flatnonzero(~np.isfinite(row))[0])
            raise InputError(path, f"{where}.weights[{bad}] ({names[bad]})", f"value is {row[bad]}; must be finite")
        values[i] = row
        t = fr.get("time", i)
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
            raise InputError(path, f"{where}.time", f"not a finite number: {t!r}")
        times[i] = t
        rot = fr.get("rotation") or []
        rotations.append(rot)
    _check_range(path, values, names, lambda r: f"key frames[{r}].weights")
    head = None
    if all(isinstance(r, list) and len(r) == 3 for r in rotations):
        try:
            head = np.array(rotations, dtype=np.float64)
        except (TypeError, ValueError):
            head = None
        if head is not None and not np.isfinite(head).all():
            raise InputError(path, "key frames[].rotation", "rotation values must be finite")
    if fps is None:
        lines = [f"key frames[{i}].time" for i in range(len(frames))]
        fps, uneven = _fps_from_times(path, times, lines)
        if uneven:
            values = _regularize(path, values, times, fps, lines)
            head = None if head is None else _regularize(path, head, times, fps, lines)
    return _assemble(path, names, values, fps, head, lambda c: f"key names[{c}]")


def _load_npz(path: Path, fps: float | None) -> FaceAnimation:
    with open_npz(path) as z:
        data = z.arrays()
    for key in ("weights", "names"):
        if key not in data:
            raise InputError(path, f"key {key}", f"missing; NPZ face data needs 'weights' (F, K) and 'names' (K,); "
                                                 f"found {sorted(data)}")
    w, names = data["weights"], data["names"]
    if w.ndim != 2 or not np.issubdtype(w.dtype, np.number):
        raise InputError(path, "key weights", f"must be a numeric (frames, shapes) array, got {w.dtype} {w.shape}")
    if names.ndim != 1 or names.shape[0] != w.shape[1] or names.dtype.kind not in "US":
        raise InputError(path, "key names", f"must be {w.shape[1]} strings (one per weights column), "
                                            f"got {names.dtype} {names.shape}")
    if w.shape[0] == 0:
        raise InputError(path, "key weights", "has no frames")
    w = w.astype(np.float64)
    if not np.isfinite(w).all():
        r, c = (int(x) for x in np.argwhere(~np.isfinite(w))[0])
        raise InputError(path, f"key weights[{r}, {c}] ({names[c]})", "value is not finite")
    names = [str(n) for n in names]
    _check_range(path, w, names, lambda r: f"key weights[{r}]")
    if fps is None:
        if "fps" not in data:
            raise InputError(path, "key fps", "missing and no fps given: store 'fps' in the NPZ or pass the frame rate")
        try:
            fps = float(data["fps"]) if data["fps"].dtype.kind in "biuf" and data["fps"].size == 1 else float("nan")
        except (TypeError, ValueError):
            fps = float("nan")
        if not (math.isfinite(fps) and fps > 0):
            raise InputError(path, "key fps", f"must be a positive number, got {data['fps']!r}")
    return _assemble(path, names, w, fps, None, lambda c: f"key names[{c}]")


def _load_npy(path: Path, fps: float | None) -> FaceAnimation:
    w = load_npy(path)
    if w.ndim != 2 or w.shape[1] != N_ARKIT or not np.issubdtype(w.dtype, np.number):
        raise InputError(path, "array shape", f"a bare NPY must be (frames, {N_ARKIT}) numbers in Apple's ARKit order, "
                                              f"got {w.dtype} {w.shape}; use an NPZ with 'names' for other layouts")
    if w.shape[0] == 0:
        raise InputError(path, "array shape", "has no frames")
    if fps is None:
        raise InputError(path, None, "a bare NPY carries no frame rate: pass fps")
    w = w.astype(np.float64)
    if not np.isfinite(w).all():
        r, c = (int(x) for x in np.argwhere(~np.isfinite(w))[0])
        raise InputError(path, f"row {r}, column {c} ({ARKIT_NAMES[c]})", "value is not finite")
    _check_range(path, w, list(ARKIT_NAMES), lambda r: f"row {r}")
    return FaceAnimation(w, fps, None, str(path))


# ----------------------------------------------------------------------------------------------- writing

def _fmt(v: float, decimals: int) -> str:
    s = f"{v:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if s in ("", "-0") else s


def save_face_csv(face: FaceAnimation, path: str | Path, decimals: int = 6) -> None:
    """Write a plain CSV: ``time`` (seconds) and the 52 ARKit names in Apple order (+ head angles if any).

    Values are printed with ``decimals`` places (time stamps with at least 9) and trailing zeros trimmed,
    so the file is small and exactly reproducible; :func:`load_face` reads it back to within ``0.5 * 10**-decimals``.
    """
    path = Path(path)
    header = ["time", *ARKIT_NAMES]
    cols = [np.arange(face.n_frames) / face.fps, *face.weights.astype(np.float64).T]
    if face.head_rotation is not None:
        header += ["HeadYaw", "HeadPitch", "HeadRoll"]
        cols += list(face.head_rotation.astype(np.float64).T)
    table = np.stack(cols, axis=1) if face.n_frames else np.zeros((0, len(header)))
    lines = [",".join(header)]
    # Time stamps get 9 places whatever ``decimals`` is: the reader derives the frame rate from them.
    lines += [",".join([_fmt(row[0], max(decimals, 9))] + [_fmt(v, decimals) for v in row[1:]]) for row in table.tolist()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8", newline="\n")


def summarize(path: str | Path, fps: float | None = None) -> dict:
    """What a face file holds, for ``inspect``-style listings and design validation.

    Returns ``format``, ``frames``, ``fps``, ``duration``, ``shapes_found`` (count), ``found`` / ``missing``
    / ``unknown`` name lists and ``has_head_rotation``. Raises :class:`InputError` like :func:`load_face`.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # missing shapes are part of the summary, not a warning here
        face, fmt = _load(Path(path), fps)
    missing = set(face.missing)
    return {
        "path": str(path),
        "format": fmt,
        "frames": face.n_frames,
        "fps": face.fps,
        "duration": face.duration,
        "shapes_found": N_ARKIT - len(missing),
        "found": [n for n in ARKIT_NAMES if n not in missing],
        "missing": list(face.missing),
        "unknown": list(face.unknown),
        "has_head_rotation": face.head_rotation is not None,
    }


__all__ = ["load_face", "save_face_csv", "summarize"]
