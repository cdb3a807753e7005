"""Layout shared by the full-page screens: a centred, readable column over a calm background.

A page is a scrolling body (with a visible scrollbar when the text is longer than the window) and a
fixed footer holding the page's main button, so "Continue" is always on screen, at any window size.
While part of the body is out of sight the footer says so (at 1280x720 the instructions are taller than
the window, and a scrollbar alone is easy to miss), and the keyboard scrolls it too: Page Up / Page Down
on every page, the arrow keys on pages that do not use them for something else.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.study.design.texts import EN as EN_TEXTS

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp

PAGE_FLAGS = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_move
              | imgui.WindowFlags_.no_saved_settings | imgui.WindowFlags_.no_bring_to_front_on_focus)
#: Widest text column (at scale 1); longer lines are hard to read.
COLUMN_PX = 860.0
FOOTER_PX = 84.0

_body_open = False
_arrow_scroll = True
#: Set when the last page body closed with text still below the visible part.
_more_below = False
# Page Down, not the arrows: the questionnaire uses Up/Down to move between its questions.
MORE_BELOW_HINT = EN_TEXTS["page.more_below"]  # in English; pages show design.text("page.more_below")


def page_begin(app: ScreenApp, name: str, *, arrow_scroll: bool = True) -> float:
    """Open a full-window page and its scrolling body; returns the column width in pixels.

    ``arrow_scroll``: Up/Down scroll the body (False where the page uses the arrows itself).
    """
    global _body_open, _arrow_scroll
    w, h = app.fb_size
    s = app.scale
    col = min(w - 48 * s, COLUMN_PX * s)
    pad_x = max(24 * s, (w - col) / 2)
    imgui.set_next_window_pos((0, 0))
    imgui.set_next_window_size((float(w), float(h)))
    imgui.push_style_var(imgui.StyleVar_.window_padding, imgui.ImVec2(0, 0))
    imgui.begin(f"##page_{name}", None, PAGE_FLAGS)
    imgui.pop_style_var()
    # The body spans the full width (scrollbar at the window edge) and pads the column inside.
    imgui.push_style_var(imgui.StyleVar_.window_padding, imgui.ImVec2(pad_x, 32 * s))
    imgui.begin_child("##body", imgui.ImVec2(0, -FOOTER_PX * s), imgui.ChildFlags_.always_use_window_padding)
    imgui.pop_style_var()
    _body_open = True
    _arrow_scroll = arrow_scroll
    app.page_pad_x = pad_x
    return col


def _scroll_keys(app: ScreenApp) -> None:
    """Keyboard scrolling of the open page body (keyboard-only participants must reach all the text)."""
    line = imgui.get_text_line_height_with_spacing()
    page = max(line, imgui.get_window_height() - 3 * line)
    step = 0.0
    if app.key_pressed(imgui.Key.page_down):
        step += page
    if app.key_pressed(imgui.Key.page_up):
        step -= page
    if _arrow_scroll and app.key_pressed("down"):
        step += 3 * line
    if _arrow_scroll and app.key_pressed("up"):
        step -= 3 * line
    if step:
        imgui.set_scroll_y(min(max(0.0, imgui.get_scroll_y() + step), imgui.get_scroll_max_y()))


def _end_body(app: ScreenApp | None = None) -> None:
    global _body_open, _more_below
    if _body_open:
        if app is not None:
            _scroll_keys(app)
        _more_below = imgui.get_scroll_y() < imgui.get_scroll_max_y() - 1.0
        imgui.end_child()
        _body_open = False


def page_end() -> None:
    _end_body()
    imgui.end()


def primary_row(app: ScreenApp, label: str, key: str, *, enabled: bool = True, hint: str = "") -> bool:
    """The page's main button (green) in the fixed footer, with an optional hint next to it.

    Enter presses it too, so every page works from the keyboard alone.
    """
    s = app.scale
    _end_body(app)
    imgui.separator()
    pad_x = app.page_pad_x if app.page_pad_x is not None else 24 * s
    imgui.set_cursor_pos(imgui.ImVec2(pad_x, imgui.get_cursor_pos_y() + 14 * s))
    pressed = app.ui.button(label, key=key, enabled=enabled, size=(260 * s, 48 * s), primary=True)
    # One hint beside the button, so it fits the row: "more below" while text is hidden (the page's own hint
    # is read once the participant has scrolled there), else the page's hint.
    if _more_below:
        imgui.same_line(0, 16 * s)
        imgui.set_cursor_pos_y(imgui.get_cursor_pos_y() + 12 * s)
        app.ui.text(app.design.text("page.more_below"), color=(1.0, 0.80, 0.35, 1.0), key="more_below")
    elif hint:  # the page's own hint (e.g. what is still unanswered) stays visible beside it
        imgui.same_line(0, 16 * s)
        imgui.set_cursor_pos_y(imgui.get_cursor_pos_y() + 12 * s)
        app.ui.muted(hint)
    if enabled and app.key_pressed("enter"):
        pressed = True
    return pressed
