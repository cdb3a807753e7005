"""The only way screens put text and controls on screen.

Every participant-visible string goes through :class:`Painter`, which records it, so tests can assert
that no condition id or model name is ever drawn (:meth:`Painter.leaks`); every interactive item records
its rectangle under a stable key, so the offscreen bot and the window tests know where to click
(through :mod:`studyapp.ui.input`, like a participant). Every text item is also checked against what its
window shows (:attr:`Painter.cut_off`), so tests can assert that no text is cut off at any window size.
"""
from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Any

from studyapp.ui.line_break import break_lines

Rect = tuple[float, float, float, float]  # x0, y0, x1, y1 in framebuffer pixels

#: A line that starts a list item keeps its own line inside a paragraph.
_LIST_ITEM = re.compile(r"^\s*(?:[-*\u2022\u00b7]|\d+[.)]|\(\w\))\s")
#: Scripts written without spaces between words: lines are joined with no space between two of these.
_NO_SPACE = re.compile(r"[\u2e80-\u9fff\uac00-\ud7af\uf900-\ufaff\uff00-\uffef\u3000-\u303f]")


def reflow(text: str) -> list[str]:
    r"""Paragraphs of a design's text, each one flowing line (wrapped to the window when drawn).

    Blank lines separate paragraphs. Single line breaks inside a paragraph are where the author's editor
    wrapped the TOML, so they join into one line (no space between Chinese or Japanese characters);
    lines that start a list item (``-``, ``*``, ``1.``, ``(a)``) keep their own line.

    >>> reflow("Watch each clip\nto the end.\n\nThen:\n- rank\n- go on")
    ['Watch each clip to the end.', 'Then:\n- rank\n- go on']
    >>> reflow("\u8bf7\u89c2\u770b\n\u6bcf\u4e2a\u7247\u6bb5")
    ['请观看每个片段']
    """
    out = []
    for para in re.split(r"\n\s*\n", text.strip()):
        lines = [ln.strip() for ln in para.strip().splitlines() if ln.strip()]
        if not lines:
            continue
        joined = lines[0]
        for ln in lines[1:]:
            if _LIST_ITEM.match(ln):
                joined += "\n" + ln
            elif _NO_SPACE.match(joined[-1]) and _NO_SPACE.match(ln[0]):
                joined += ln
            else:
                joined += " " + ln
        out.append(joined)
    return out


def visible_label(label: str) -> str:
    """The part of an ImGui label that is drawn (``"Next##trial"`` -> ``"Next"``; ``"###x"`` -> ``""``)."""
    return label.split("##", 1)[0]


class Painter:
    """Thin wrapper over the imgui calls the screens use; records strings and item rectangles."""

    def __init__(self) -> None:
        from imgui_bundle import imgui

        self.imgui = imgui
        self.drawn: set[str] = set()
        self.frame_strings: list[str] = []
        self.rects: dict[Any, Rect] = {}
        self.layer = None  # set by the app: fonts live there
        #: ``(text, why)`` for every string drawn so far that did not fit where it was drawn.
        self.cut_off: list[tuple[str, str]] = []
        self._frame = 0
        self._windows: dict[int, tuple[int, int]] = {}  # window id -> (first, last) frame drawn in a row
        self._breaks: dict[tuple[str, int, float], str] = {}  # (text, width, font size) -> with CJK breaks

    def begin_frame(self) -> None:
        self._frame += 1
        self.frame_strings = []
        self.rects = {}

    def record(self, s: str) -> None:
        if s:
            self.drawn.add(s)
            self.frame_strings.append(s)

    def _item_rect(self, key: Any) -> None:
        if key is not None:
            imgui = self.imgui
            a, b = imgui.get_item_rect_min(), imgui.get_item_rect_max()
            self.rects[key] = (a.x, a.y, b.x, b.y)

    def _broken(self, s: str, wrap_x: float) -> str:
        """``s`` with the line breaks ImGui's wrapping cannot find in Chinese or Japanese text (between any two
        characters, :mod:`studyapp.ui.line_break`), for the wrap position ``wrap_x`` at the cursor; other text
        is unchanged. Cached: a page draws the same texts every frame."""
        if not _NO_SPACE.search(s):
            return s
        imgui = self.imgui
        avail = imgui.get_content_region_avail().x if wrap_x <= 0 else wrap_x - imgui.get_cursor_pos_x()
        key = (s, int(avail), imgui.get_font_size())
        if key not in self._breaks:
            if len(self._breaks) > 512:
                self._breaks.clear()
            # 1 px short of the edge: ImGui must not wrap a line that our measure says fits
            self._breaks[key] = break_lines(s, avail - 1.0, lambda t: imgui.calc_text_size(t).x)
        return self._breaks[key]

    def _check_fits(self, s: str, rect: Rect | None = None) -> None:
        """Note ``s`` (the last item, or text drawn at ``rect``) as cut off when it reaches past the left or
        right edge of what its window shows, or below the bottom of a window with no scrollbar to reach it."""
        imgui = self.imgui
        if rect is None:
            a, b = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        else:
            a, b = imgui.ImVec2(rect[0], rect[1]), imgui.ImVec2(rect[2], rect[3])
        win = imgui.internal.get_current_window()
        if int(win.flags) & int(imgui.WindowFlags_.tooltip) or win.hidden or win.skip_items:
            # tooltips (and drag previews) size themselves to their text a frame later; a window scrolled
            # wholly out of view draws nothing
            return
        dl = imgui.get_window_draw_list()
        lo, hi = dl.get_clip_rect_min(), dl.get_clip_rect_max()
        if a.x < lo.x - 0.5 or b.x > hi.x + 0.5:
            self.cut_off.append((s, f"x {a.x:.0f}..{b.x:.0f} outside {lo.x:.0f}..{hi.x:.0f}"))
            return
        # Below the bottom: cut off by the first window, from the item's own outwards, whose inside it
        # passes, unless a window on the way can scroll (a scrollbar shows) and so bring it into view.
        w = win
        while w is not None and b.y > hi.y + 0.5:
            if w.scrollbar_y or not self._settled(w):
                return
            if b.y > w.inner_rect.max.y + 0.5:
                self.cut_off.append((s, f"bottom {b.y:.0f} below {w.inner_rect.max.y:.0f}, no scrollbar"))
                return
            w = w.parent_window

    def _settled(self, win: Any) -> bool:
        """True once ImGui knows whether ``win`` needs a scrollbar: it measures a new window's content in its
        first frame and shows the scrollbar from the third (windows that never scroll are settled at once)."""
        first, last = self._windows.get(win.id_, (self._frame, self._frame))
        if last < self._frame - 1:
            first = self._frame
        self._windows[win.id_] = (first, self._frame)
        return self._frame - first >= 2 or bool(int(win.flags) & int(self.imgui.WindowFlags_.no_scrollbar))

    def check_box_fits(self, s: str, size: tuple[float, float], box: tuple[float, float]) -> None:
        """Note ``s`` as cut off when text of ``size`` (w, h) is drawn into a ``box`` (w, h) too small."""
        if self.imgui.internal.get_current_window().skip_items:
            return
        if size[0] > box[0] + 0.5 or size[1] > box[1] + 0.5:
            self.cut_off.append((s, f"{size[0]:.0f}x{size[1]:.0f} text in a {box[0]:.0f}x{box[1]:.0f} box"))

    # -- text ----------------------------------------------------------------------------------
    def text(self, s: str, *, color: tuple[float, float, float, float] | None = None, key: Any = None) -> None:
        self.record(s)
        if color is None:
            self.imgui.text_unformatted(s)
        else:  # text_unformatted: design text may contain "%", which printf-style calls would eat
            self.imgui.push_style_color(self.imgui.Col_.text, self.imgui.ImVec4(*color))
            self.imgui.text_unformatted(s)
            self.imgui.pop_style_color()
        self._check_fits(s)
        self._item_rect(key)

    def wrapped(self, s: str, *, key: Any = None, wrap_x: float = 0.0) -> None:
        """Text wrapped at ``wrap_x`` (window-local x; 0: the window's right edge)."""
        self.record(s)
        self.imgui.push_text_wrap_pos(wrap_x)
        self.imgui.text_unformatted(self._broken(s, wrap_x))
        self.imgui.pop_text_wrap_pos()
        self._check_fits(s)
        self._item_rect(key)

    def muted(self, s: str, *, wrap_x: float = 0.0, size: float = 1.0) -> None:
        """Secondary text (grey), wrapped at ``wrap_x``, ``size`` times the body size."""
        self.record(s)
        imgui = self.imgui
        imgui.push_style_color(imgui.Col_.text, imgui.ImVec4(0.70, 0.72, 0.77, 1.0))
        if size != 1.0:
            imgui.push_font(None, imgui.get_style().font_size_base * size)
        imgui.push_text_wrap_pos(wrap_x)
        imgui.text_unformatted(self._broken(s, wrap_x))
        imgui.pop_text_wrap_pos()
        self._check_fits(s)
        if size != 1.0:
            imgui.pop_font()
        imgui.pop_style_color()

    def heading(self, s: str, size: float = 1.6, *, key: Any = None, wrap_x: float = 0.0) -> None:
        """Bold text ``size`` times the body size."""
        self.record(s)
        imgui = self.imgui
        font = self.layer.font_bold if self.layer else None
        imgui.push_font(font, imgui.get_style().font_size_base * size)
        imgui.push_text_wrap_pos(wrap_x)
        imgui.text_unformatted(self._broken(s, wrap_x))
        imgui.pop_text_wrap_pos()
        self._check_fits(s)
        imgui.pop_font()
        self._item_rect(key)

    def paragraphs(self, s: str) -> None:
        """Text from a design, as :func:`reflow` reads it: paragraphs that wrap to the window's width."""
        for para in reflow(s):
            self.wrapped(para)
            self.imgui.spacing()

    def tooltip(self, s: str) -> None:
        """``s`` in a tooltip while the mouse rests on the last item."""
        self.record(s)
        self.imgui.set_item_tooltip(s)

    # -- controls -----------------------------------------------------------------------------
    def button(self, label: str, *, key: Any = None, enabled: bool = True, size: tuple[float, float] = (0, 0),
               primary: bool = False) -> bool:
        imgui = self.imgui
        self.record(visible_label(label))
        if primary and enabled:
            imgui.push_style_color(imgui.Col_.button, imgui.ImVec4(0.16, 0.55, 0.36, 1.0))
            imgui.push_style_color(imgui.Col_.button_hovered, imgui.ImVec4(0.20, 0.64, 0.42, 1.0))
            imgui.push_style_color(imgui.Col_.button_active, imgui.ImVec4(0.13, 0.46, 0.30, 1.0))
        imgui.begin_disabled(not enabled)
        pressed = imgui.button(label, imgui.ImVec2(*size))
        imgui.end_disabled()
        if primary and enabled:
            imgui.pop_style_color(3)
        text = visible_label(label)
        if text:  # the label, centred in the button: inside the button and inside what the window shows
            a, b = imgui.get_item_rect_min(), imgui.get_item_rect_max()
            tw = imgui.calc_text_size(text)
            self.check_box_fits(text, (tw.x, tw.y), (b.x - a.x, b.y - a.y))
            cx, cy = (a.x + b.x) / 2, (a.y + b.y) / 2
            self._check_fits(text, (cx - tw.x / 2, cy - tw.y / 2, cx + tw.x / 2, cy + tw.y / 2))
        self._item_rect(key if key is not None else visible_label(label))
        return bool(pressed) and enabled

    def radio(self, label: str, active: bool, *, key: Any = None) -> bool:
        self.record(visible_label(label))
        pressed = self.imgui.radio_button(label, active)
        self._check_fits(visible_label(label))
        self._item_rect(key)
        return bool(pressed)

    def checkbox(self, label: str, value: bool, *, key: Any = None) -> bool:
        self.record(visible_label(label))
        _, value = self.imgui.checkbox(label, value)
        self._check_fits(visible_label(label))
        self._item_rect(key)
        return bool(value)

    def input_multiline(self, label: str, value: str, size: tuple[float, float], *, key: Any = None) -> str:
        """A free-text box; Enter leaves it (Ctrl+Enter starts a new line), so Enter can then submit."""
        self.record(value)
        flags = self.imgui.InputTextFlags_.ctrl_enter_for_new_line
        _, value = self.imgui.input_text_multiline(label, value, self.imgui.ImVec2(*size), flags)
        self._item_rect(key)
        return value

    def input_line(self, label: str, value: str, width: float, *, key: Any = None) -> str:
        """A one-line text box ``width`` pixels wide (a number's answer); Enter leaves it."""
        self.record(value)
        self.imgui.set_next_item_width(width)
        _, value = self.imgui.input_text(label, value)
        self._item_rect(key)
        return value

    # -- checks --------------------------------------------------------------------------------
    def leaks(self, secrets: Iterable[str]) -> list[tuple[str, str]]:
        """``(secret, drawn string)`` pairs where a secret (condition id, model name, file name) was drawn.

        Matching is case-insensitive and on word boundaries (so the id ``"a"`` does not match every
        "a" in the instructions, but ``"camn"`` matches "CaMN result").
        """
        out = []
        for secret in secrets:
            if not secret:
                continue
            pat = re.compile(r"(?<![A-Za-z0-9])" + re.escape(secret) + r"(?![A-Za-z0-9])", re.IGNORECASE)
            out += [(secret, s) for s in sorted(self.drawn) if pat.search(s)]
        return out
