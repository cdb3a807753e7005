"""The preference panel (``pairwise`` and ``mismatch`` trials): per question, which of two figures, how clearly.

Each of the block's questions is a row: its label, question and explanation on the left, then the scale's
options as boxes, left to right: "Clearly A", "Slightly A", "No preference", "Slightly B", "Clearly B" (the
figures' names, :func:`studyapp.ui.paradigm.slot_names`; a 3-level block shows "A is better", "No
preference", "B is better"). A mismatch block uses the same panel with its own question (e.g. "Which one's
movement fits the speech better?"). When the block has reasons, one more row lists them as check boxes; it is
greyed out until some answer is a preference, and its ticks are only submitted then (see
:mod:`studyapp.ui.preference`).

Mouse: click an option box (clicking another one changes the answer), click the reasons' boxes.
Keyboard, the same scheme as the ranking panel's: the number keys act on the highlighted row and each box
shows its key above its text ("key 1" .. "key 5"; the reasons show theirs beside them); Left / Right move the
highlighted answer one step along the scale, Up / Down change row, Backspace clears it, Enter goes to the next
clip once every question is answered. The hint beside "Next clip" spells the keys out.

The chosen box is green; hovering over a box only lightens it a little, never to the chosen colour, so
hovering does not look like choosing (the same colours as the ranking panel's place boxes).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.ui.input import digit_key
from studyapp.ui.preference import PreferenceState, option_keys
from studyapp.ui.screens.ranking_panel import (
    EMPTY_COLOR,
    FILLED_COLOR,
    GAP_PX,
    HOVER_LIFT,
    ROW_PAD_PX,
    ROW_PX,
    _lift,
    _text_height,
    next_row,
    question_text,
    row_keys,
)

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp
    from studyapp.ui.trial import TrialView

#: Width of one option box at scale 1, by number of levels, and the boxes' height.
OPTION_PX = {5: 124.0, 3: 168.0}
BOX_PX = 54.0
#: The highlighted row's background and the others' (as the ranking panel's).
ACTIVE_BG = (0.21, 0.25, 0.32, 1.0)
ROW_BG = (0.16, 0.17, 0.20, 1.0)


def option_label(app: ScreenApp, view: TrialView, value: int) -> str:
    """The text of one option box, e.g. "Clearly A" or "No preference"."""
    key, side = option_keys(value, view.block.levels)
    figure = view.names[0] if side == "left" else view.names[-1]
    return app.design.text(key, figure=figure)


def _options_width(app: ScreenApp, levels: int) -> float:
    s = app.scale
    return levels * OPTION_PX[levels] * s + (levels - 1) * 8 * s


def _text_width(app: ScreenApp, avail_w: float, levels: int) -> float:
    s = app.scale
    inner = avail_w - 2 * ROW_PAD_PX[0] * s
    return max(220 * s, inner - _options_width(app, levels) - 24 * s)


def row_heights(app: ScreenApp, view: TrialView, avail_w: float | None = None) -> list[float]:
    """Pixel height of each question's row (and of the reasons row, last, when the block has reasons)."""
    s = app.scale
    if avail_w is None:
        avail_w = app.fb_size[0] - 2 * 20 * s
    text_w = _text_width(app, avail_w, view.block.levels)
    out = [float(math.ceil(max(ROW_PX * s, _text_height(app, c, text_w) + 2 * ROW_PAD_PX[1] * s + 2 * s)))
           for c in view.criteria]
    if view.block.reasons:
        lines = _reason_lines(app, view, avail_w - 2 * ROW_PAD_PX[0] * s)
        style = imgui.get_style()
        box_h = imgui.get_frame_height()
        out.append(float(math.ceil(2 * ROW_PAD_PX[1] * s + 4 * s + imgui.get_text_line_height() + style.item_spacing.y
                                   + len(lines) * box_h + (len(lines) - 1) * style.item_spacing.y + 2 * s)))
    return out


def reason_label(app: ScreenApp, k: int, reason: str) -> str:
    """A reason's check box text: the reason and, for the first nine, its number key."""
    return f"{reason}  ({app.design.text('rank.key', n=k + 1)})" if k < 9 else reason


def _reason_lines(app: ScreenApp, view: TrialView, width: float) -> list[list[int]]:
    """The reasons' check boxes flowed into lines ``width`` pixels wide: indices per line."""
    style = imgui.get_style()
    gap = 22 * app.scale
    lines: list[list[int]] = [[]]
    x = 0.0
    for k, reason in enumerate(view.block.reasons):
        w = imgui.get_frame_height() + style.item_inner_spacing.x + imgui.calc_text_size(reason_label(app, k, reason)).x
        if lines[-1] and x + gap + w > width:
            lines.append([])
            x = 0.0
        x += (gap if lines[-1] else 0.0) + w
        lines[-1].append(k)
    return lines


def height(app: ScreenApp, view: TrialView) -> float:
    """Pixels the panel's rows need below the transport row."""
    rows = row_heights(app, view)
    return sum(rows) + GAP_PX * len(rows) * app.scale + 8 * app.scale


def _option_box(app: ScreenApp, key_caption: str, label: str, chosen: bool, size: tuple[float, float],
                key: tuple) -> bool:
    """One option: a box with its key (small) above its text; True when clicked."""
    ui = app.ui
    color = FILLED_COLOR if chosen else EMPTY_COLOR
    imgui.push_style_color(imgui.Col_.button, imgui.ImVec4(*color))
    imgui.push_style_color(imgui.Col_.button_hovered, imgui.ImVec4(*_lift(color, HOVER_LIFT)))
    imgui.push_style_color(imgui.Col_.button_active, imgui.ImVec4(*_lift(color, 2 * HOVER_LIFT)))
    clicked = ui.button(f"##{key}", key=key, size=size)
    imgui.pop_style_color(3)
    ui.record(key_caption)
    ui.record(label)
    a, b = imgui.get_item_rect_min(), imgui.get_item_rect_max()
    dl = imgui.get_window_draw_list()
    base = imgui.get_style().font_size_base * app.scale
    cap_size, val_size = base * 0.8, base * 0.98
    font = app.layer.font_bold if chosen else app.layer.font
    imgui.push_font(app.layer.font, cap_size / app.scale)
    cw = imgui.calc_text_size(key_caption).x
    imgui.pop_font()
    imgui.push_font(font, val_size / app.scale)
    vw = imgui.calc_text_size(label).x
    imgui.pop_font()
    box = (b.x - a.x, b.y - a.y)
    ui.check_box_fits(key_caption, (cw, cap_size + val_size + 2), box)
    ui.check_box_fits(label, (vw, cap_size + val_size + 2), box)
    cx = (a.x + b.x) / 2
    top = a.y + (b.y - a.y - cap_size - val_size - 2) / 2
    grey = imgui.get_color_u32(imgui.ImVec4(0.80, 0.82, 0.86, 1.0))
    white = imgui.get_color_u32(imgui.ImVec4(1.0, 1.0, 1.0, 1.0 if chosen else 0.85))
    dl.add_text(app.layer.font, cap_size, imgui.ImVec2(cx - cw / 2, top), grey, key_caption)
    dl.add_text(font, val_size, imgui.ImVec2(cx - vw / 2, top + cap_size + 2), white, label)
    return clicked


def _row_begin(app: ScreenApp, name: str, row_h: float, active: bool) -> None:
    s = app.scale
    imgui.push_style_color(imgui.Col_.child_bg, imgui.ImVec4(*(ACTIVE_BG if active else ROW_BG)))
    imgui.push_style_var(imgui.StyleVar_.window_padding, imgui.ImVec2(ROW_PAD_PX[0] * s, ROW_PAD_PX[1] * s))
    imgui.begin_child(name, imgui.ImVec2(0, row_h),
                      imgui.ChildFlags_.borders | imgui.ChildFlags_.always_use_window_padding,
                      imgui.WindowFlags_.no_scrollbar)
    imgui.pop_style_var()
    imgui.pop_style_color()


def draw(app: ScreenApp, view: TrialView) -> None:
    s = app.scale
    p = view.answer
    assert isinstance(p, PreferenceState)
    t = app.design.text
    levels = view.block.levels
    avail_w = imgui.get_content_region_avail().x
    text_w = _text_width(app, avail_w, levels)
    heights = row_heights(app, view, avail_w)
    opt_w, box_h = OPTION_PX[levels] * s, BOX_PX * s
    for ci, crit in enumerate(view.criteria):
        row_h = heights[ci]
        _row_begin(app, f"##pref{ci}", row_h, ci == p.active)
        if imgui.is_window_hovered() and imgui.is_mouse_clicked(0):
            p.active = ci
        x0 = imgui.get_cursor_pos_x()
        top = imgui.get_cursor_pos_y()
        wrap = x0 + text_w
        question_text(app, crit, wrap)
        mid = row_h / 2 - ROW_PAD_PX[1] * s
        imgui.set_cursor_pos(imgui.ImVec2(x0 + text_w + 24 * s, round(top + mid - box_h / 2)))
        for k, value in enumerate(p.options):
            if k:
                imgui.same_line(0, 8 * s)
            if _option_box(app, t("rank.key", n=k + 1), option_label(app, view, value), p.choice[crit.id] == value,
                           (opt_w, box_h), ("option", crit.id, value)):
                p.choose(crit.id, value)
        imgui.end_child()
    if view.block.reasons:
        _reasons_row(app, view, p, heights[-1])
    _keys(app, view, p)


def _reasons_row(app: ScreenApp, view: TrialView, p: PreferenceState, row_h: float) -> None:
    """"What made the difference?" on its own line, then the reasons' check boxes, flowing onto more lines
    when they do not fit one (the row's height allows for them: :func:`row_heights`)."""
    ui = app.ui
    s = app.scale
    t = app.design.text
    asked = p.reasons_asked()
    _row_begin(app, "##reasons", row_h, asked and p.active == len(view.criteria))
    if asked and imgui.is_window_hovered() and imgui.is_mouse_clicked(0):
        p.active = len(view.criteria)
    imgui.set_cursor_pos_y(imgui.get_cursor_pos_y() + 4 * s)
    imgui.begin_disabled(not asked)
    ui.text(t("pref.reasons"), key="reasons")
    for line in _reason_lines(app, view, imgui.get_content_region_avail().x):
        for j, k in enumerate(line):
            if j:
                imgui.same_line(0, 22 * s)
            reason = view.block.reasons[k]
            ticked = reason in p.ticked
            if ui.checkbox(f"{reason_label(app, k, reason)}##reason{k}", ticked, key=("reason", k)) != ticked:
                p.toggle_reason(reason)
                p.active = len(view.criteria)
    imgui.end_disabled()
    imgui.end_child()


def _keys(app: ScreenApp, view: TrialView, p: PreferenceState) -> None:
    # Digits by key code, not text: layouts such as AZERTY type "&" on the "1" key without Shift.
    for i in range(9):
        if app.key_pressed(digit_key(i + 1)) or app.key_pressed(getattr(imgui.Key, f"keypad{i + 1}")):
            p.key_digit(i)
    if app.key_pressed(imgui.Key.left_arrow):
        p.key_step(-1)
    if app.key_pressed(imgui.Key.right_arrow):
        p.key_step(1)
    row_keys(app, view, p.move_active, p.key_clear)


def next_button(app: ScreenApp, view: TrialView) -> None:
    """The "Next clip" button and, while it is disabled, how to answer or which questions are left."""
    p = view.answer
    assert isinstance(p, PreferenceState)
    t = app.design.text
    if not p.answers():
        why = t("pref.start_hint", n=len(p.options))
    else:
        why = t("pref.still", criteria=", ".join(c.label for c in view.criteria if not p.is_complete(c.id)))
    next_row(app, view, why)
