"""The ranking panel: per criterion, three places (1st best .. 3rd worst) and the three figures' chips.

Three ways to rank, all through :class:`studyapp.ui.ranking.RankingState`:

* drag a chip onto a place (ImGui drag and drop; dropping on a filled place swaps);
* click chips in order from best to worst (clicking a filled place empties it);
* keyboard: 1 / 2 / 3 put figure A / B / C (left / middle / right) into the next free place of the
  highlighted question, Up / Down move the highlight, Backspace clears it, Enter goes to the next clip
  when everything is ranked. The digits choose a *figure*, never a rank, and the screen says so: each
  chip shows its key above its letter, and the hint beside "Next clip" spells the scheme out.

Hovering a place box only lightens it a little (ImGui's default hover colour is the blue of a selected
control, which made an empty box look chosen); a filled box is green whatever the mouse does.

When the design allows ties, a small button between neighbouring places shows ``>`` ("better than");
clicking it turns it into an amber ``=`` and the two places become equal: their captions then read, e.g.,
"1st (tied)" twice and "3rd (worst)", and the tied boxes get an amber outline. On the keyboard ``=`` ties
the next figure placed with the one above it (``1 = 2 3``). Without ties the panel is drawn as before.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable, Sequence

from imgui_bundle import imgui

from studyapp.study.design.texts import EN as EN_TEXTS
from studyapp.study.design.texts import fill
from studyapp.ui.input import digit_key
from studyapp.ui.ranking import RankingState

if TYPE_CHECKING:
    from studyapp.study.design import Criterion
    from studyapp.ui.seams import ScreenApp
    from studyapp.ui.trial import TrialView

#: Smallest height of a question's row (at scale 1); a row grows when its text needs more lines.
ROW_PX = 74.0
GAP_PX = 6.0
#: Inner padding of a row (at scale 1) and the height of the place boxes and chips.
ROW_PAD_PX = (12.0, 8.0)
BOX_PX = 54.0
PLACE_KEYS = ("rank.first", "rank.second", "rank.third")
#: Width of the ``>`` / ``=`` button between two places (designs with ties only).
LINK_PX = 28.0
#: Width of a place with ties: three of them and the two links take the room of three places without.
TIE_PLACE_PX = 112.0
TIE_COLOR = (0.93, 0.68, 0.22, 1.0)
TIE_HINT = EN_TEXTS["rank.tie_hint"]  # English; participants read design.text(...)
PLACE_PX = 132.0
CHIP_PX = 60.0
#: Empty and filled place boxes; hovering lightens them by HOVER_LIFT, never to another hue.
EMPTY_COLOR = (0.24, 0.25, 0.29, 1.0)
FILLED_COLOR = (0.18, 0.46, 0.36, 1.0)
HOVER_LIFT = 0.04


def keys_line(names: tuple[str, ...] | list[str], template: str = EN_TEXTS["rank.start_hint"]) -> str:
    """How to start ranking, mouse and keyboard: the digits pick a figure, not a rank.

    >>> keys_line(("A", "B", "C"))
    'Drag or click the letters into the boxes, best first; or press 1 = A, 2 = B, 3 = C.'
    """
    return fill(template, keys=", ".join(f"{i + 1} = {n}" for i, n in enumerate(names)))


def _lift(rgba: tuple[float, float, float, float], d: float) -> tuple[float, float, float, float]:
    return (min(1.0, rgba[0] + d), min(1.0, rgba[1] + d), min(1.0, rgba[2] + d), rgba[3])


def _text_width(app: ScreenApp, avail_w: float) -> float:
    """Width of the question column in a row ``avail_w`` pixels wide (inside the panel's padding)."""
    s = app.scale
    inner = avail_w - 2 * ROW_PAD_PX[0] * s
    return max(240 * s, inner - 3 * PLACE_PX * s - 3 * CHIP_PX * s - 126 * s)


def _text_height(app: ScreenApp, crit: Criterion, text_w: float) -> float:
    """Pixels the label, question and explanation of ``crit`` take, wrapped at ``text_w``."""
    base = imgui.get_style().font_size_base
    spacing = imgui.get_style().item_spacing
    imgui.push_font(app.layer.font_bold if app.layer else None, base * 1.05)
    label = imgui.calc_text_size(crit.label)
    imgui.pop_font()
    q_w = max(1.0, text_w - label.x - 10 * app.scale)
    question = imgui.calc_text_size(crit.question, False, q_w)
    h = max(label.y, question.y)
    if crit.explanation:
        imgui.push_font(None, base * 0.9)
        h += spacing.y + imgui.calc_text_size(crit.explanation, False, text_w).y
        imgui.pop_font()
    return h


def row_heights(app: ScreenApp, avail_w: float | None = None,
                criteria: Sequence[Criterion] | None = None) -> list[float]:
    """Pixel height of each question's row: at least ``ROW_PX``, more when its text wraps to more lines.

    ``criteria``: the trial's questions (its block's); default: all of the design's."""
    s = app.scale
    if criteria is None:
        criteria = app.design.criteria
    if avail_w is None:
        avail_w = app.fb_size[0] - 2 * 20 * s  # the panel's width inside its padding (trial.draw)
    text_w = _text_width(app, avail_w)
    # whole pixels, so boxes and their outlines sit on pixel rows (no half-covered edges)
    return [float(math.ceil(max(ROW_PX * s, _text_height(app, c, text_w) + 2 * ROW_PAD_PX[1] * s + 2 * s)))
            for c in criteria]


def height(app: ScreenApp, view: TrialView | None = None) -> float:
    """Pixels the ranking rows (of ``view``'s questions; default: the design's) need below the transport row."""
    criteria = view.criteria if view is not None else app.design.criteria
    return sum(row_heights(app, criteria=criteria)) + GAP_PX * len(criteria) * app.scale + 8 * app.scale


def _box_text(app: ScreenApp, caption: str, value: str, filled: bool) -> None:
    """Two centred lines in the last item: a small caption and the figure placed there (bold)."""
    ui = app.ui
    ui.record(caption)
    ui.record(value)
    a, b = imgui.get_item_rect_min(), imgui.get_item_rect_max()
    dl = imgui.get_window_draw_list()
    base = imgui.get_style().font_size_base * app.scale
    cap_size, val_size = base * 0.85, base * (1.25 if filled else 0.9)
    bold = app.layer.font_bold if filled else app.layer.font
    imgui.push_font(app.layer.font, cap_size / app.scale)
    cw = imgui.calc_text_size(caption).x
    imgui.pop_font()
    imgui.push_font(bold, val_size / app.scale)
    vw = imgui.calc_text_size(value).x
    imgui.pop_font()
    cx = (a.x + b.x) / 2
    top = a.y + (b.y - a.y - cap_size - val_size - 2) / 2
    grey = imgui.get_color_u32(imgui.ImVec4(0.80, 0.82, 0.86, 1.0))
    white = imgui.get_color_u32(imgui.ImVec4(1.0, 1.0, 1.0, 1.0 if filled else 0.45))
    ui.check_box_fits(caption, (cw, cap_size + val_size + 2), (b.x - a.x, b.y - a.y))
    ui.check_box_fits(value, (vw, cap_size + val_size + 2), (b.x - a.x, b.y - a.y))
    dl.add_text(app.layer.font, cap_size, imgui.ImVec2(cx - cw / 2, top), grey, caption)
    dl.add_text(bold, val_size, imgui.ImVec2(cx - vw / 2, top + cap_size + 2), white, value)


def _caption(app: ScreenApp, r: RankingState, crit_id: str, place: int) -> str:
    t = app.design.text
    if not r.is_tied(crit_id, place):
        return t(PLACE_KEYS[place])
    return t("rank.tied", ordinal=t(f"rank.ordinal{r.place_rank(crit_id, place)}"))


def _tie_link(app: ScreenApp, r: RankingState, ci: int, crit_id: str, link: int,
              size: tuple[float, float]) -> None:
    """The ``>`` / ``=`` button between places ``link`` and ``link + 1``."""
    ui = app.ui
    tied = r.ties[crit_id][link]
    bg, fg = (TIE_COLOR, (0.10, 0.10, 0.12, 1.0)) if tied else ((0.24, 0.25, 0.29, 1.0), (0.80, 0.82, 0.86, 1.0))
    imgui.push_style_color(imgui.Col_.button, imgui.ImVec4(*bg))
    imgui.push_style_color(imgui.Col_.text, imgui.ImVec4(*fg))
    imgui.push_font(app.layer.font_bold, imgui.get_style().font_size_base * 1.4)
    # "###": the id must not change with the sign, or ImGui would lose a click held across the toggle.
    if ui.button(f"{'=' if tied else '>'}###tie{ci}{link}", key=("tie", crit_id, link), size=size):
        r.toggle_tie(crit_id, link)
        r.active = ci
    imgui.pop_font()
    imgui.pop_style_color(2)
    ui.tooltip(app.design.text("rank.tie_on" if tied else "rank.tie_off"))


def row_keys(app: ScreenApp, view: TrialView, move: Callable[[int], None], clear: Callable[[], None]) -> None:
    """The keys every answer panel shares: Up/Down move between the questions, Backspace/Delete clear the
    highlighted one, Enter goes on once the answer is complete."""
    if app.key_pressed("down"):
        move(1)
    if app.key_pressed("up"):
        move(-1)
    if app.key_pressed("backspace") or app.key_pressed("delete"):
        clear()
    if app.key_pressed("enter") and view.can_submit():
        view.submit()


def question_text(app: ScreenApp, crit: Criterion, wrap_x: float) -> None:
    """A question's label, its question and its explanation, wrapped inside the text column."""
    s = app.scale
    ui = app.ui
    ui.heading(crit.label, 1.05, key=("crit", crit.id), wrap_x=wrap_x)
    imgui.same_line(0, 10 * s)
    ui.wrapped(crit.question, wrap_x=wrap_x)
    if crit.explanation:
        ui.muted(crit.explanation, wrap_x=wrap_x, size=0.9)


def _keys(app: ScreenApp, view: TrialView) -> None:
    r = view.ranking
    typed = app.typed_text()
    if r.allow_ties and "=" in typed and any(c in "123" for c in typed):
        # A fast "1=2" with key rollover puts "=" and a digit into one frame; only the typed text keeps
        # their order, and the order decides which two figures are tied.
        for c in typed:
            if c == "=":
                r.key_tie()
            elif c in "123":
                r.key_slot(int(c) - 1)
    else:
        # Digits by key code, not text: layouts such as AZERTY type "&" on the "1" key without Shift.
        for i in range(3):
            if app.key_pressed(digit_key(i + 1)) or app.key_pressed(getattr(imgui.Key, f"keypad{i + 1}")):
                r.key_slot(i)
        if r.allow_ties and "=" in typed:
            r.key_tie()
    row_keys(app, view, r.move_active, lambda: r.clear(r.criteria[r.active]))


def draw(app: ScreenApp, view: TrialView) -> None:
    ui = app.ui
    s = app.scale
    r = view.ranking
    names = view.names
    place_w, box_h, chip_w = PLACE_PX * s, BOX_PX * s, CHIP_PX * s
    link_w, link_gap = LINK_PX * s, 4 * s
    avail_w = imgui.get_content_region_avail().x
    text_w = _text_width(app, avail_w)
    heights = row_heights(app, avail_w, view.criteria)
    if r.allow_ties:
        # Narrower places and the two links fit in the room of the three places without ties, so the
        # questions keep their width and still fit their row.
        place_w = TIE_PLACE_PX * s
    for ci, crit in enumerate(view.criteria):
        active = ci == r.active
        bg = (0.21, 0.25, 0.32, 1.0) if active else (0.16, 0.17, 0.20, 1.0)
        imgui.push_style_color(imgui.Col_.child_bg, imgui.ImVec4(*bg))
        row_h = heights[ci]
        imgui.push_style_var(imgui.StyleVar_.window_padding, imgui.ImVec2(ROW_PAD_PX[0] * s, ROW_PAD_PX[1] * s))
        imgui.begin_child(f"##crit{ci}", imgui.ImVec2(0, row_h),
                          imgui.ChildFlags_.borders | imgui.ChildFlags_.always_use_window_padding,
                          imgui.WindowFlags_.no_scrollbar)
        imgui.pop_style_var()
        imgui.pop_style_color()
        if imgui.is_window_hovered() and imgui.is_mouse_clicked(0):
            r.active = ci
        # the question: label, question, explanation, wrapped inside the text column
        x0 = imgui.get_cursor_pos_x()
        top = imgui.get_cursor_pos_y()
        wrap = x0 + text_w
        question_text(app, crit, wrap)
        # the three places, best to worst
        mid = row_h / 2 - ROW_PAD_PX[1] * s  # the row's middle, in the child's content coordinates
        imgui.set_cursor_pos(imgui.ImVec2(x0 + text_w + 20 * s, round(top + mid - box_h / 2)))
        for p in range(3):
            if p and r.allow_ties:
                imgui.same_line(0, link_gap)
                _tie_link(app, r, ci, crit.id, p - 1, (link_w, box_h))
                imgui.same_line(0, link_gap)
            elif p:
                imgui.same_line()
            slot = r.order[crit.id][p]
            color = FILLED_COLOR if slot is not None else EMPTY_COLOR
            imgui.push_style_color(imgui.Col_.button, imgui.ImVec4(*color))
            imgui.push_style_color(imgui.Col_.button_hovered, imgui.ImVec4(*_lift(color, HOVER_LIFT)))
            imgui.push_style_color(imgui.Col_.button_active, imgui.ImVec4(*_lift(color, 2 * HOVER_LIFT)))
            if ui.button(f"##place{ci}{p}", key=("place", crit.id, p), size=(place_w, box_h)) and slot is not None:
                r.click(crit.id, slot)  # take it out again
            imgui.pop_style_color(3)
            _box_text(app, _caption(app, r, crit.id, p), names[slot] if slot is not None else app.design.text("rank.drop_here"),
                      slot is not None)
            if r.is_tied(crit.id, p):
                imgui.get_window_draw_list().add_rect(imgui.get_item_rect_min(), imgui.get_item_rect_max(),
                                                      imgui.get_color_u32(imgui.ImVec4(*TIE_COLOR)), 4 * s, 3 * s)
            if slot is not None and imgui.begin_drag_drop_source():
                imgui.set_drag_drop_payload_py_id(f"slot{ci}", slot)
                ui.text(names[slot])
                imgui.end_drag_drop_source()
            if imgui.begin_drag_drop_target():
                payload = imgui.accept_drag_drop_payload_py_id(f"slot{ci}")
                if payload is not None:
                    r.drop(crit.id, int(payload.data_id), p)
                    r.active = ci
                imgui.end_drag_drop_target()
        # chips of the figures not placed yet
        imgui.same_line(0, 24 * s)
        chips_x = imgui.get_cursor_pos_x()
        for slot in range(3):
            if slot:
                imgui.same_line()
            if r.place_of(crit.id, slot) is not None:
                imgui.dummy(imgui.ImVec2(chip_w, box_h))
                continue
            if ui.button(f"##chip{ci}{slot}", key=("chip", crit.id, slot), size=(chip_w, box_h)):
                r.click(crit.id, slot)
                r.active = ci
            _box_text(app, app.design.text("rank.key", n=slot + 1), names[slot], True)
            if imgui.begin_drag_drop_source():
                imgui.set_drag_drop_payload_py_id(f"slot{ci}", slot)
                ui.text(names[slot])
                imgui.end_drag_drop_source()
        if r.is_complete(crit.id):
            imgui.set_cursor_pos(imgui.ImVec2(chips_x, top + mid - imgui.get_font_size() / 2))
            ui.muted(app.design.text("rank.done"), size=0.9)
        imgui.end_child()
    _keys(app, view)


def next_button(app: ScreenApp, view: TrialView) -> None:
    """The "Next clip" button (right end of the transport row) and why it is disabled, if it is."""
    t = app.design.text
    r = view.ranking
    if view.can_submit() or view.in_play:
        why = None
    elif not any(slot is not None for places in r.order.values() for slot in places):
        why = keys_line(view.names, t("rank.start_hint"))
        if r.allow_ties:
            why += " " + t("rank.tie_hint")
    else:
        why = t("rank.still", criteria=", ".join(c.label for c in view.criteria if not r.is_complete(c.id)))
    next_row(app, view, why)


def next_row(app: ScreenApp, view: TrialView, why_not: str | None) -> None:
    """The "Next clip" button at the right end of the transport row, with one line of hint before it.

    ``why_not``: what is still to do while the answers are incomplete (every answer panel says it its way);
    the waiting and "you cannot come back" hints are the same for all.
    """
    ui = app.ui
    s = app.scale
    t = app.design.text
    last = app.session.trial_number() >= app.session.phase_total()
    if view.plan.is_practice:
        label = t("rank.start_study" if last else "rank.next_practice")
    else:
        label = t("rank.finish" if last else "rank.next")
    enabled = view.can_submit()
    if enabled:
        why = t("rank.next_ok")
    elif view.in_play:
        why = t("rank.wait")
    else:
        why = why_not or ""
    bw = 210 * s
    imgui.same_line(0, 20 * s)
    row_y = imgui.get_cursor_pos_y()
    x_text = imgui.get_cursor_pos_x()
    x_button = imgui.get_window_width() - imgui.get_style().window_padding.x - bw
    imgui.set_cursor_pos_y(row_y + 10 * s)
    # One line only: a second line would run into the first question's row below. Long hints (a design's
    # long criterion labels, a wide progress label) are drawn smaller until they fit, with 4 % to spare:
    # glyphs are rasterised at the size drawn, so text does not shrink exactly in proportion.
    room = 0.96 * max(1.0, x_button - 16 * s - x_text)
    size = max(0.7, min(1.0, room / max(1.0, imgui.calc_text_size(why).x)))
    ui.muted(why, wrap_x=x_button - 16 * s, size=round(size - 0.005, 3) if size < 1.0 else 1.0)
    imgui.set_cursor_pos(imgui.ImVec2(max(x_button, x_text), row_y))
    if ui.button(label, key="next", enabled=enabled, size=(bw, 44 * s), primary=True):
        view.submit()
