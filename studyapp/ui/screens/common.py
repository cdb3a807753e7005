"""Layout shared by the full-page screens: a centred, readable column over a calm background."""
from __future__ import annotations

from typing import Any

from imgui_bundle import imgui

PAGE_FLAGS = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_move
              | imgui.WindowFlags_.no_saved_settings | imgui.WindowFlags_.no_bring_to_front_on_focus)
#: Widest text column (at scale 1); longer lines are hard to read.
COLUMN_PX = 860.0


def page_begin(app: Any, name: str) -> float:
    """Open a full-window page with a centred column; returns the column width in pixels."""
    w, h = app.fb_size
    s = app.scale
    col = min(w - 48 * s, COLUMN_PX * s)
    pad_x = max(24 * s, (w - col) / 2)
    imgui.set_next_window_pos((0, 0))
    imgui.set_next_window_size((float(w), float(h)))
    imgui.push_style_var(imgui.StyleVar_.window_padding, imgui.ImVec2(pad_x, 36 * s))
    imgui.begin(f"##page_{name}", None, PAGE_FLAGS)
    imgui.pop_style_var()
    return col


def page_end() -> None:
    imgui.end()


def primary_row(app: Any, label: str, key: str, *, enabled: bool = True, hint: str = "") -> bool:
    """The page's main button (bigger, green) with an optional keyboard hint next to it.

    Enter presses it too, so every page works from the keyboard alone.
    """
    s = app.scale
    imgui.spacing()
    imgui.separator()
    imgui.spacing()
    pressed = app.ui.button(label, key=key, enabled=enabled, size=(260 * s, 48 * s), primary=True)
    if hint:
        imgui.same_line()
        imgui.set_cursor_pos_y(imgui.get_cursor_pos_y() + 12 * s)
        app.ui.muted(hint)
    if enabled and app.key_pressed("enter"):
        pressed = True
    return pressed
