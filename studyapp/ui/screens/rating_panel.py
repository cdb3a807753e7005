"""The rating panel (``rating`` trials): a 0-100 slider per figure, for each of the block's questions.

Each question is a row: its label and question across the top, then one slider under each figure, in that
figure's column of the 3D view (so which slider rates which figure needs no reading), with the figure's name
before it. Under each slider the block's anchors (e.g. Bad .. Excellent) label equal parts of the scale, at
their centres (:func:`studyapp.ui.rating.anchor_centres`), with a tick between neighbours; without anchors
the ends read 0 and 100.

A slider starts *unset*: no handle, and "not rated yet" written in it, so an untouched slider cannot be
mistaken for an answer at its starting point. A set slider's value is written beside its handle, on the side
with more room (:func:`studyapp.ui.rating.value_text_x`): ImGui's own text, centred in the track, lay under
the handle at 50. Every slider must be moved before "Next clip" is enabled; until
then the hint beside that button names the ones left ("Still to rate: Realism: A, C").

Mouse: click or drag on a slider (a click puts it where clicked). Keyboard, the ranking panel's scheme: the
highlighted slider (outlined) takes the keys: Left / Right move it by 1, Page Down / Page Up by 10, the number
keys put it on an anchor's centre (1 = the first; without anchors 1..9 = 10..90), Backspace unsets it, Up / Down change slider, Enter goes to the next
clip when all are set. Hovering over a slider lightens its track a little and nothing else.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.render.renderer import slot_viewports
from studyapp.ui.input import digit_key
from studyapp.ui.rating import RatingState, anchor_centres, digit_points, value_text_x
from studyapp.ui.screens.ranking_panel import GAP_PX, ROW_PAD_PX, next_row, row_keys

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp
    from studyapp.ui.trial import TrialView

SLIDER_PX = 30.0
ANCHOR_PX = 20.0
#: Margin between a slider and its figure column's edges, and the room for the figure's name before it.
MARGIN_PX = 18.0
NAME_PX = 26.0
#: Room between a set slider's handle and its value's text.
VALUE_GAP_PX = 6.0
ROW_BG = (0.16, 0.17, 0.20, 1.0)
FOCUS_COLOR = (0.55, 0.78, 1.0, 1.0)
UNSET_GRAB = (0.0, 0.0, 0.0, 0.0)
GRAB_COLOR = (0.35, 0.80, 0.55, 1.0)


def _criterion_text_height(app: ScreenApp, view: TrialView, ci: int, text_w: float) -> float:
    crit = view.criteria[ci]
    base = imgui.get_style().font_size_base
    imgui.push_font(app.layer.font_bold if app.layer else None, base * 1.05)
    label = imgui.calc_text_size(crit.label)
    imgui.pop_font()
    question = imgui.calc_text_size(crit.question, False, max(1.0, text_w - label.x - 10 * app.scale))
    return max(label.y, question.y)


def row_heights(app: ScreenApp, view: TrialView) -> list[float]:
    s = app.scale
    text_w = app.fb_size[0] - 2 * 20 * s - 2 * ROW_PAD_PX[0] * s
    spacing = imgui.get_style().item_spacing.y
    return [float(math.ceil(_criterion_text_height(app, view, ci, text_w) + spacing + (SLIDER_PX + ANCHOR_PX) * s
                            + 2 * ROW_PAD_PX[1] * s + 4 * s)) for ci in range(len(view.criteria))]


def height(app: ScreenApp, view: TrialView) -> float:
    rows = row_heights(app, view)
    return sum(rows) + GAP_PX * len(rows) * app.scale + 8 * app.scale


def slider_spans(app: ScreenApp, n: int, inner: tuple[float, float]) -> list[tuple[float, float]]:
    """Screen x range of each figure's slider track: inside its column of the 3D view (which spans the
    window), after room for the figure's name, and inside the row's ``inner`` x range (its padding)."""
    s = app.scale
    cols = slot_viewports((0, 0, app.fb_size[0], 100), n)
    lo, hi = inner
    out = []
    for x, _, w, _ in cols:
        a = max(x + MARGIN_PX * s, lo) + NAME_PX * s
        b = min(x + w - MARGIN_PX * s, hi)
        out.append((a, max(a + 40 * s, b)))
    return out


def missing_text(app: ScreenApp, view: TrialView, r: RatingState) -> str:
    """"Realism: A, C; Naturalness: B": the sliders still unset, by question."""
    parts = []
    for crit in view.criteria:
        left = [view.names[s] for c, s in r.missing() if c == crit.id]
        if left:
            parts.append(f"{crit.label}: {', '.join(left)}")
    return "; ".join(parts)


def _anchors(app: ScreenApp, view: TrialView, x0: float, x1: float, y: float) -> None:
    """The anchors under a slider spanning screen x ``x0..x1`` (its track), at the top ``y``."""
    ui = app.ui
    dl = imgui.get_window_draw_list()
    anchors = list(view.block.anchors) or ["0", "100"]
    base = imgui.get_style().font_size_base * app.scale
    grey = imgui.get_color_u32(imgui.ImVec4(0.74, 0.76, 0.80, 1.0))
    tick = imgui.get_color_u32(imgui.ImVec4(0.45, 0.47, 0.52, 1.0))
    pad = imgui.get_style().frame_padding.x
    t0, t1 = x0 + pad, x1 - pad   # the grab's travel, about
    if view.block.anchors:
        n = len(anchors)
        room = (t1 - t0) / n
        widths = []
        for a in anchors:
            imgui.push_font(app.layer.font, base * 0.8 / app.scale)
            widths.append(imgui.calc_text_size(a).x)
            imgui.pop_font()
        size = base * 0.8 * min(1.0, max(0.6, (room - 4) / max(1.0, max(widths))))
        for k, (a, c) in enumerate(zip(anchors, anchor_centres(n))):
            ui.record(a)
            imgui.push_font(app.layer.font, size / app.scale)
            w = imgui.calc_text_size(a).x
            imgui.pop_font()
            ui.check_box_fits(a, (w, size), (room, ANCHOR_PX * app.scale))
            cx = t0 + (t1 - t0) * c / 100.0
            dl.add_text(app.layer.font, size, imgui.ImVec2(cx - w / 2, y + 2), grey, a)
            if k:
                bx = t0 + (t1 - t0) * k / n
                dl.add_line(imgui.ImVec2(bx, y - 4 * app.scale), imgui.ImVec2(bx, y + 2), tick, 1.0)
    else:
        size = base * 0.8
        for a, x, align in ((anchors[0], t0, 0.0), (anchors[1], t1, 1.0)):
            ui.record(a)
            imgui.push_font(app.layer.font, size / app.scale)
            w = imgui.calc_text_size(a).x
            imgui.pop_font()
            dl.add_text(app.layer.font, size, imgui.ImVec2(x - w * align, y + 2), grey, a)


def _slider(app: ScreenApp, view: TrialView, r: RatingState, ci: int, slot: int, span: tuple[float, float],
            y: float) -> None:
    ui = app.ui
    s = app.scale
    crit = view.criteria[ci]
    value = r.values[crit.id][slot]
    x0, x1 = span
    win_x = imgui.get_window_pos().x
    # the figure's name before its slider
    imgui.set_cursor_pos(imgui.ImVec2(x0 - NAME_PX * s - win_x, y + 4 * s))
    ui.heading(view.names[slot], 1.0, key=("slot_name", crit.id, slot))
    imgui.set_cursor_pos(imgui.ImVec2(x0 - win_x, y))
    unset_text = app.design.text("rating.unset").replace("%", "%%")
    imgui.push_style_color(imgui.Col_.slider_grab, imgui.ImVec4(*(UNSET_GRAB if value is None else GRAB_COLOR)))
    imgui.push_style_color(imgui.Col_.slider_grab_active,
                           imgui.ImVec4(*(UNSET_GRAB if value is None else GRAB_COLOR)))
    imgui.set_next_item_width(x1 - x0)
    ui.record(unset_text if value is None else str(value))
    # a set slider's value is drawn below, beside the handle: ImGui would centre it under the handle at 50
    changed, new = imgui.slider_int(f"##rate_{ci}_{slot}", 50 if value is None else value, 0, 100,
                                    unset_text if value is None else "",
                                    imgui.SliderFlags_.no_input | imgui.SliderFlags_.always_clamp)
    imgui.pop_style_color(2)
    a, b = imgui.get_item_rect_min(), imgui.get_item_rect_max()
    ui.rects[("slider", crit.id, slot)] = (a.x, a.y, b.x, b.y)
    rows = r.rows()
    if imgui.is_item_activated():
        r.active = rows.index((crit.id, slot))
    if changed or (imgui.is_item_activated() and value is None):
        # a click on an unset slider counts as setting it where clicked, even at its hidden start value
        r.set(crit.id, slot, new)
    current = r.values[crit.id][slot]  # as this frame's click or drag left it
    if current is not None and value is not None:  # (a slider set this frame shows its value from the next)
        shown = str(current)
        size = imgui.calc_text_size(shown)
        x = value_text_x(a.x, b.x, current, size.x, imgui.get_style().grab_min_size, VALUE_GAP_PX * s)
        imgui.get_window_draw_list().add_text(imgui.ImVec2(x, (a.y + b.y - size.y) / 2),
                                              imgui.get_color_u32(imgui.Col_.text), shown)
    if rows[r.active] == (crit.id, slot):
        imgui.get_window_draw_list().add_rect(imgui.ImVec2(a.x - 3 * s, a.y - 3 * s), imgui.ImVec2(b.x + 3 * s, b.y + 3 * s),
                                              imgui.get_color_u32(imgui.ImVec4(*FOCUS_COLOR)), 6 * s, 2 * s)
    _anchors(app, view, a.x, b.x, b.y + 2 * s)


def draw(app: ScreenApp, view: TrialView) -> None:
    ui = app.ui
    s = app.scale
    r = view.answer
    assert isinstance(r, RatingState)
    heights = row_heights(app, view)
    for ci, crit in enumerate(view.criteria):
        imgui.push_style_color(imgui.Col_.child_bg, imgui.ImVec4(*ROW_BG))
        imgui.push_style_var(imgui.StyleVar_.window_padding, imgui.ImVec2(ROW_PAD_PX[0] * s, ROW_PAD_PX[1] * s))
        imgui.begin_child(f"##rate{ci}", imgui.ImVec2(0, heights[ci]),
                          imgui.ChildFlags_.borders | imgui.ChildFlags_.always_use_window_padding,
                          imgui.WindowFlags_.no_scrollbar)
        imgui.pop_style_var()
        imgui.pop_style_color()
        left = imgui.get_cursor_screen_pos().x
        spans = slider_spans(app, view.n_slots, (left, left + imgui.get_content_region_avail().x))
        ui.heading(crit.label, 1.05, key=("crit", crit.id))
        imgui.same_line(0, 10 * s)
        ui.wrapped(crit.question)
        y = imgui.get_cursor_pos_y()
        for slot in range(view.n_slots):
            _slider(app, view, r, ci, slot, spans[slot], y)
        imgui.end_child()
    _keys(app, view, r)


def _keys(app: ScreenApp, view: TrialView, r: RatingState) -> None:
    points = digit_points(len(view.block.anchors))
    for i in range(min(9, len(points))):
        if app.key_pressed(digit_key(i + 1)) or app.key_pressed(getattr(imgui.Key, f"keypad{i + 1}")):
            r.key_point(points[i])
    if app.key_pressed(imgui.Key.left_arrow):
        r.key_step(-1)
    if app.key_pressed(imgui.Key.right_arrow):
        r.key_step(1)
    if app.key_pressed(imgui.Key.page_up):
        r.key_step(10)
    if app.key_pressed(imgui.Key.page_down):
        r.key_step(-10)
    row_keys(app, view, r.move_active, r.key_clear)


def next_button(app: ScreenApp, view: TrialView) -> None:
    """The "Next clip" button and, while it is disabled, how to rate or which sliders are left."""
    r = view.answer
    assert isinstance(r, RatingState)
    t = app.design.text
    if not r.ratings():
        why = t("rating.start_hint", n=min(9, len(digit_points(len(view.block.anchors)))))
    else:
        why = t("rating.still", sliders=missing_text(app, view, r))
    next_row(app, view, why)
