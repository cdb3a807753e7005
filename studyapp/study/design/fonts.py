"""Which font shows a design's participant texts: the UI's own (Roboto), plus a system font for the rest.

The UI draws with Roboto, which has Latin, Greek and Cyrillic but no CJK glyphs. :func:`needed_chars`
collects every character of the texts a design shows participants; :func:`fallback_font` finds an
installed font (the files in the system's font folders, read by :mod:`.font_files`) whose character map has
every one Roboto lacks, preferring well-known CJK families. The UI merges that font into its own
(:mod:`studyapp.ui.layer`); Dear ImGui 1.92 rasterises glyphs when they are first drawn, so only the
characters actually used are loaded. When no font covers the texts, ``validate`` says so
(:func:`font_problem`). On Debian/Ubuntu ``apt install fonts-noto-cjk`` (or ``fonts-wqy-microhei``)
provides one; Windows and macOS ship CJK fonts.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

from studyapp.study.design.font_files import FontFace, read_face, system_fonts

if TYPE_CHECKING:
    from studyapp.study.design.model import Design

#: Families tried first, in order (the ones Debian, Windows and macOS ship for Chinese and Japanese).
PREFERRED = ("Noto Sans CJK SC", "Noto Sans CJK JP", "Noto Sans SC", "Source Han Sans SC", "WenQuanYi Micro Hei",
             "WenQuanYi Zen Hei", "Microsoft YaHei", "SimHei", "PingFang SC", "Hiragino Sans GB", "Heiti SC",
             "Droid Sans Fallback", "Arial Unicode MS")


def ui_font_path(bold: bool = False) -> Path:
    """The UI's own font (Roboto, shipped with imgui-bundle)."""
    import imgui_bundle

    name = "Roboto-Bold.ttf" if bold else "Roboto-Regular.ttf"
    return Path(imgui_bundle.__file__).resolve().parent / "assets" / "fonts" / "Roboto" / name


@lru_cache(maxsize=None)
def _face(path: str) -> FontFace | None:
    return read_face(path)


def charmap(path: str) -> frozenset[int]:
    """The code points a font file has glyphs for (empty when it cannot be read)."""
    face = _face(path)
    return face.codes if face is not None else frozenset()


def participant_texts(design: Design) -> list[str]:
    """Every text of ``design`` a participant may read (built-in texts in its language included)."""
    out = [design.title, design.instructions, design.consent, design.completion, *design.texts.values()]
    for c in design.criteria:
        out += [c.label, c.question, c.explanation]
    for q in design.questionnaire:
        out += [q.text, *q.anchors, *q.options]
    out += list(design.slot_labels or ())
    for b in getattr(design, "blocks", None) or ():   # a block's own page, its reasons and slider anchors
        out += [b.instructions, *b.reasons, *b.anchors]
    return [t for t in out if t]


def needed_chars(texts: list[str]) -> set[str]:
    """The characters of ``texts`` that need a glyph (not spaces or control characters)."""
    return {ch for t in texts for ch in t if ch.isprintable() and not ch.isspace()}


#: Characters Roboto certainly has (ASCII, Latin-1, Latin Extended-A and common punctuation; a test checks
#: them against the font): texts made only of these need no font file read, which keeps ``validate`` of an
#: English design from reading fonts.
SURELY_IN_UI_FONT = frozenset(chr(c) for c in [*range(0x20, 0x7F), *range(0xA0, 0x180), 0x2013, 0x2014, 0x2018,
                                                0x2019, 0x201C, 0x201D, 0x2026, 0x2022, 0x2212, 0x2264, 0x2265])


def missing_from_ui_font(chars: set[str]) -> set[str]:
    """The characters the UI's own font has no glyph for."""
    rest = {ch for ch in chars if ch not in SURELY_IN_UI_FONT}
    if not rest:
        return set()
    have = charmap(str(ui_font_path()))
    return {ch for ch in rest if ord(ch) not in have}


def fallback_font(chars: set[str]) -> Path | None:
    """An installed font with every character of ``chars`` (None when none has them all, or none is needed).

    >>> fallback_font(set()) is None
    True
    """
    if not chars:
        return None
    want = {ord(c) for c in chars}
    return _search(want, _font_entries())


def _font_entries() -> list[FontFace]:
    """The first face of every installed font file that can be read (a file is read once per process)."""
    return [f for f in map(_face, map(str, system_fonts())) if f is not None]


def _search(want: set[int], entries: list[FontFace]) -> Path | None:
    entries = sorted(entries,
                     key=lambda e: (PREFERRED.index(e.family) if e.family in PREFERRED else len(PREFERRED),
                                    e.weight != 400, str(e.path)))
    for e in entries:
        # "Last Resort" fonts map every code point to a placeholder box: that is what must not be shown
        if "lastresort" in e.path.name.lower().replace(" ", ""):
            continue
        if want <= e.codes:
            return e.path
    return None


def design_fallback_font(design: Design) -> tuple[Path | None, set[str]]:
    """(font to merge into the UI's, characters no installed font covers) for a design's texts."""
    missing = missing_from_ui_font(needed_chars(participant_texts(design)))
    if not missing:
        return None, set()
    font = fallback_font(missing)
    if font is not None:
        return font, set()
    # name what is uncovered: the characters that no single font could add
    covered: set[int] = set()
    for e in _font_entries():
        if "lastresort" not in e.path.name.lower():
            covered |= e.codes & {ord(c) for c in missing}
    return None, {c for c in missing if ord(c) not in covered} or missing


def font_problem(design: Design) -> tuple[str, str, str] | None:
    """``(key, message, fix)`` when no installed font shows every character of the design's texts."""
    font, uncovered = design_fallback_font(design)
    if not uncovered:
        return None
    sample = "".join(sorted(uncovered)[:12])
    key = "language" if design.language != "en" else "texts"
    return (key, f"no installed font has all the characters participants would read ({len(uncovered)} missing, "
                 f"e.g. {sample!r}); they would show as boxes",
            "install a font that has them (Debian/Ubuntu: apt install fonts-noto-cjk; Windows and macOS ship "
            "CJK fonts)")
