"""Installed font files and the characters each has, read from the files themselves (no font library).

:mod:`.fonts` needs two facts about a TrueType/OpenType file: its family name and the code points its
character map covers. Both are in the file's tables (the OpenType specification, "The OpenType Font File"):

- the table directory: a 12-byte header (``numTables`` at byte 4) and 16 bytes per table (tag, checksum,
  offset, length); a collection (``.ttc``/``.otc``, tag ``ttcf``) lists its fonts' header offsets after 12
  bytes, and only its first font is read (the UI merges face 0 of a file);
- ``name``: records of 12 bytes (platform, encoding, language, name id, length, offset into the string
  storage); the family is name id 16 (typographic family), else 1, in UTF-16BE for platforms 0 and 3, Mac
  Roman for platform 1 (English preferred), as FreeType names it;
- ``OS/2``: ``usWeightClass`` at byte 4 (400 regular, 700 bold);
- ``cmap``: encoding records of 8 bytes (platform, encoding, offset of the subtable); subtable format 12
  (groups of start, end, first glyph; the full Unicode range) is preferred over format 4 (segments of
  end, start, delta, range offset; the Basic Multilingual Plane). A code point counts when it maps to a
  glyph other than 0 (``.notdef``, the empty box).

Only the header, the table directory and those three tables are read. Every offset and count a file claims
is checked against its length before it is used, and code points stop at U+10FFFF, so a damaged or hostile
file costs at most its own size: it is then no candidate (:func:`read_face` returns None), never an error.

:func:`system_fonts` lists the font files in the usual folders of Linux, macOS and Windows.
"""
from __future__ import annotations

import os
import struct
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

#: File suffixes of TrueType/OpenType fonts and collections.
SUFFIXES = (".ttf", ".otf", ".ttc", ".otc")
_MAX_CODE = 0x10FFFF


class _Bad(ValueError):
    """The file is not a font this reader understands (caught: such a file is no candidate)."""


@dataclass(frozen=True)
class FontFace:
    """The first face of a font file: its family name, weight class and covered code points."""

    path: Path
    family: str
    weight: int
    codes: frozenset[int]


def _u16(b: bytes, at: int) -> int:
    return struct.unpack_from(">H", b, at)[0]


def _u32(b: bytes, at: int) -> int:
    return struct.unpack_from(">I", b, at)[0]


def _tables(f: BinaryIO, size: int, wanted: tuple[bytes, ...]) -> dict[bytes, bytes]:
    """The ``wanted`` tables of the file's first font, by tag (only they are read)."""
    def read(at: int, n: int) -> bytes:
        if at + n > size:
            raise _Bad("a table or header outside the file")
        f.seek(at)
        return f.read(n)

    head = read(0, 16) if size >= 16 else read(0, 12)
    base = _u32(head, 12) if head[:4] == b"ttcf" else 0  # a collection: its first font
    n = _u16(read(base, 12), 4)
    directory = read(base + 12, 16 * n)
    out = {}
    for k in range(n):
        tag, _, offset, length = struct.unpack_from(">4sIII", directory, 16 * k)
        if tag in wanted:
            out[tag] = read(offset, length)
    return out


def _family(name: bytes) -> str:
    """The family of a ``name`` table: the typographic family (name id 16, which groups the weights of a
    family, e.g. "Noto Sans CJK SC" for its Bold) else name id 1; English Windows/Unicode records first, then
    Mac Roman."""
    if len(name) < 6:
        raise _Bad("name table too short")
    count, storage = _u16(name, 2), _u16(name, 4)
    if 6 + 12 * count > len(name):
        raise _Bad("name records outside the table")
    found: dict[tuple[int, int], str] = {}
    for k in range(count):
        platform, encoding, language, name_id, length, offset = struct.unpack_from(">6H", name, 6 + 12 * k)
        if name_id not in (1, 16) or storage + offset + length > len(name):
            continue
        raw = name[storage + offset:storage + offset + length]
        if platform in (0, 3):
            rank = 0 if language in (0x409, 0) else 2
            text = raw.decode("utf-16-be", "replace")
        elif platform == 1 and encoding == 0:
            rank = 1 if language == 0 else 3
            text = raw.decode("mac_roman", "replace")
        else:
            continue
        found.setdefault((name_id != 16, rank), text)
    if not found:
        raise _Bad("no family name")
    return found[min(found)].strip()


def _format12(sub: bytes) -> set[int]:
    if len(sub) < 16:
        raise _Bad("cmap format 12 header too short")
    n = _u32(sub, 12)
    if 16 + 12 * n > len(sub):
        raise _Bad("cmap format 12 groups outside the table")
    groups = np.frombuffer(sub, ">u4", count=3 * n, offset=16).reshape(n, 3).astype(np.int64)
    out: set[int] = set()
    for start, end, glyph in groups:
        end = min(int(end), _MAX_CODE)
        if start > end:
            continue
        codes = range(int(start), end + 1)
        out.update(codes if glyph else codes[1:])   # glyph 0 at the group's start is .notdef
    return out


def _format4(sub: bytes) -> set[int]:
    if len(sub) < 14:
        raise _Bad("cmap format 4 header too short")
    seg = _u16(sub, 6) // 2
    if 16 + 8 * seg > len(sub):
        raise _Bad("cmap format 4 segments outside the table")
    ends = np.frombuffer(sub, ">u2", count=seg, offset=14).astype(np.int64)
    starts = np.frombuffer(sub, ">u2", count=seg, offset=16 + 2 * seg).astype(np.int64)
    deltas = np.frombuffer(sub, ">u2", count=seg, offset=16 + 4 * seg).astype(np.int64)
    range_at = 16 + 6 * seg
    ranges = np.frombuffer(sub, ">u2", count=seg, offset=range_at).astype(np.int64)
    raw = np.frombuffer(sub, np.uint8)
    out: set[int] = set()
    for i in range(seg):
        if starts[i] > ends[i] or starts[i] == 0xFFFF:
            continue
        codes = np.arange(starts[i], ends[i] + 1)
        if ranges[i] == 0:
            glyphs = (codes + deltas[i]) & 0xFFFF
        else:
            at = range_at + 2 * i + ranges[i] + 2 * (codes - starts[i])
            inside = at + 2 <= len(sub)
            glyphs = np.zeros(codes.size, np.int64)
            idx = at[inside]
            glyphs[inside] = (raw[idx].astype(np.int64) << 8) | raw[idx + 1]
            glyphs = np.where(glyphs != 0, (glyphs + deltas[i]) & 0xFFFF, 0)
        out.update(codes[glyphs != 0].tolist())
    return out


def _codes(cmap: bytes) -> frozenset[int]:
    """The code points a ``cmap`` table maps to a real glyph (its best Unicode subtable)."""
    if len(cmap) < 4:
        raise _Bad("cmap table too short")
    n = _u16(cmap, 2)
    if 4 + 8 * n > len(cmap):
        raise _Bad("cmap records outside the table")
    best: tuple[int, int] | None = None   # (preference, offset)
    for k in range(n):
        platform, encoding, offset = struct.unpack_from(">HHI", cmap, 4 + 8 * k)
        if offset + 2 > len(cmap) or (platform, encoding) not in ((3, 10), (0, 4), (0, 6), (3, 1), (0, 3)):
            continue
        fmt = _u16(cmap, offset)
        rank = {12: 0, 4: 1}.get(fmt)
        if rank is not None and (best is None or rank < best[0]):
            best = (rank, offset)
    if best is None:
        raise _Bad("no Unicode character map")
    sub = cmap[best[1]:]
    return frozenset(_format12(sub) if best[0] == 0 else _format4(sub))


def read_face(path: str | Path) -> FontFace | None:
    """The first face of the font file ``path``, or None when it cannot be read as one."""
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            tables = _tables(f, size, (b"cmap", b"name", b"OS/2"))
        if b"cmap" not in tables or b"name" not in tables:
            return None
        os2 = tables.get(b"OS/2", b"")
        weight = _u16(os2, 4) if len(os2) >= 6 else 400
        return FontFace(Path(path), _family(tables[b"name"]), weight, _codes(tables[b"cmap"]))
    except (OSError, _Bad, struct.error, ValueError):
        return None


def font_folders() -> list[Path]:
    """Where fonts are installed on this system (the folders that exist)."""
    home = Path.home()
    if sys.platform == "win32":
        windir = Path(os.environ.get("WINDIR", r"C:\Windows"))
        local = Path(os.environ.get("LOCALAPPDATA", home / "AppData" / "Local"))
        folders = [windir / "Fonts", local / "Microsoft" / "Windows" / "Fonts"]
    elif sys.platform == "darwin":
        folders = [Path("/System/Library/Fonts"), Path("/Library/Fonts"), home / "Library" / "Fonts"]
    else:
        data = os.environ.get("XDG_DATA_DIRS") or "/usr/local/share:/usr/share"
        folders = [Path(d) / "fonts" for d in data.split(":") if d]
        folders += [Path(os.environ.get("XDG_DATA_HOME") or home / ".local" / "share") / "fonts", home / ".fonts"]
    seen: list[Path] = []
    for f in folders:
        if f.is_dir() and f not in seen:
            seen.append(f)
    return seen


def system_fonts() -> list[Path]:
    """Every TrueType/OpenType file in :func:`font_folders` (and below), sorted."""
    out: set[Path] = set()
    for folder in font_folders():
        for root, _, files in os.walk(folder):
            out.update(Path(root) / f for f in files if f.lower().endswith(SUFFIXES))
    return sorted(out)
