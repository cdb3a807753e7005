"""The font files studyapp reads itself (studyapp.study.design.font_files): every installed font's family and
character map agree with FreeType's (matplotlib's ft2font, in the test environment only), and a damaged or
hostile file is no candidate, quickly, never an error."""
from __future__ import annotations

import struct
import time
from pathlib import Path

from studyapp.study.design.font_files import read_face, system_fonts


def test_every_installed_font_reads_as_freetype_reads_it() -> None:
    from matplotlib import ft2font  # FreeType, the independent reader (matplotlib: the analysis extra)

    fonts = system_fonts()
    assert fonts, "no font installed (the CI installs fonts-dejavu and fonts-wqy-microhei)"
    for path in fonts:
        face, ft = read_face(path), ft2font.FT2Font(str(path))
        assert face is not None, path
        assert face.family == ft.family_name, path
        assert face.codes == frozenset(ft.get_charmap()), path
    assert any(ord("你") in read_face(p).codes for p in fonts)  # the CJK font the language tests use


def _font(cmap: bytes, name: bytes = b"") -> bytes:
    """A minimal sfnt with a cmap (and name) table."""
    tables = [(b"cmap", cmap)] + ([(b"name", name)] if name else [])
    offset = 12 + 16 * len(tables)
    head = struct.pack(">IHHHH", 0x00010000, len(tables), 0, 0, 0)
    directory, body = b"", b""
    for tag, data in tables:
        directory += struct.pack(">4sIII", tag, 0, offset + len(body), len(data))
        body += data
    return head + directory + body


def _name(family: str) -> bytes:
    text = family.encode("utf-16-be")
    return struct.pack(">HHH", 0, 1, 18) + struct.pack(">6H", 3, 1, 0x409, 1, len(text), 0) + text


def test_a_handmade_cmap_and_damaged_files(tmp_path: Path) -> None:
    # format 12: U+4F60..U+4F62 -> glyphs 5.., U+1F600 -> glyph 9
    groups = [(0x4F60, 0x4F62, 5), (0x1F600, 0x1F600, 9)]
    sub = struct.pack(">HHIII", 12, 0, 16 + 12 * len(groups), 0, len(groups)) + b"".join(
        struct.pack(">III", *g) for g in groups)
    cmap = struct.pack(">HH", 0, 1) + struct.pack(">HHI", 3, 10, 12) + sub
    good = tmp_path / "good.ttf"
    good.write_bytes(_font(cmap, _name("Hand Made")))
    face = read_face(good)
    assert face is not None and face.family == "Hand Made" and face.codes == {0x4F60, 0x4F61, 0x4F62, 0x1F600}

    huge = struct.pack(">HHIII", 12, 0, 16, 0, 0xFFFFFFF0)   # claims 4 billion groups
    cases = {
        "not_a_font.ttf": b"hello, this is text",
        "truncated.ttf": good.read_bytes()[:40],
        "huge_count.ttf": _font(struct.pack(">HH", 0, 1) + struct.pack(">HHI", 3, 10, 12) + huge, _name("X")),
        "tables_outside.ttf": struct.pack(">IHHHH", 0x00010000, 60000, 0, 0, 0),
        "empty.ttf": b"",
    }
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        t = time.perf_counter()
        assert read_face(tmp_path / name) is None, name
        assert time.perf_counter() - t < 0.5, name
