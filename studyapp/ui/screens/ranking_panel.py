"""The ranking panel: per criterion, three places (1st best .. 3rd worst) and the three figures' chips.

Three ways to rank, all through :class:`studyapp.ui.ranking.RankingState`:

* drag a chip onto a place (ImGui drag and drop; dropping on a filled place swaps);
* click chips in order from best to worst (clicking a filled place empties it);
* keyboard: 1 / 2 / 3 place the left / middle / right figure in the highlighted question, Up / Down move
  the highlight, Backspace clears it, Enter goes to the next clip when everything is ranked.
"""
from __future__ import annotations

from typing import Any

from imgui_bundle import imgui

from studyapp.ui.input import digit_key

ROW_PX = 96.0
HEADER_PX = 34.0
FOOTER_PX = 62.0
PLACE_NAMES = ("1st (best)", "2nd", "3rd (worst)")


def height(app: Any) -> float:
    s = app.scale
    return (HEADER_PX + ROW_PX * len(app.design.criteria) + FOOTER_PX) * s


def _keys(app: Any, view: Any) -> None:
    r = view.ranking
    for i in range(3):
        if app.key_pressed(digit_key(i + 1)) or app.key_pressed(getattr(imgui.Key, f"keypad{i + 1}")):
            r.key_slot(i)
    if app.key_pressed("down"):
        r.move_active(1)
    if app.key_pressed("up"):
        r.move_active(-1)
    if app.key_pressed("backspace") or app.key_pressed("delete"):
        r.clear(r.criteria[r.active])
    if app.key_pressed("enter") and view.can_submit():
        view.submit()


def draw(app: Any, view: Any) -> None:
    ui = app.ui
    s = app.scale
    r = view.ranking
    names = app.slot_names
    keys = ", ".join(f"{i + 1} = {n}" for i, n in enumerate(names))
    imgui.separator()
    ui.muted(f"For each question, drag the letters into the boxes from best to worst, or click them in order. "
             f"Keys: {keys}; Up/Down change the question; Backspace clears it.")
    avail_w = imgui.get_content_region_avail().x
    text_w = max(220 * s, avail_w - (3 * 150 + 3 * 70 + 70) * s)
    for ci, crit in enumerate(app.design.criteria):
        active = ci == r.active
        bg = (0.22, 0.25, 0.31, 1.0) if active else (0.17, 0.18, 0.21, 1.0)
        imgui.push_style_color(imgui.Col_.child_bg, imgui.ImVec4(*bg))
        imgui.begin_child(f"##crit{ci}", imgui.ImVec2(0, (ROW_PX - 8) * s),
                          imgui.ChildFlags_.borders, imgui.WindowFlags_.no_scrollbar)
        imgui.pop_style_color()
        if imgui.is_window_hovered() and imgui.is_mouse_clicked(0):
            r.active = ci
        # question text
        imgui.begin_group()
        imgui.push_text_wrap_pos(imgui.get_cursor_pos_x() + text_w)
        done = r.is_complete(crit.id)
        ui.heading(f"{crit.label}{'  - done' if done else ''}", 1.1, key=("crit", crit.id))
        ui.text(crit.question)
        if crit.explanation:
            ui.muted(crit.explanation)
        imgui.pop_text_wrap_pos()
        imgui.end_group()
        # places
        row_top = imgui.get_item_rect_min().y
        imgui.same_line(text_w + 30 * s)
        imgui.set_cursor_screen_pos(imgui.ImVec2(imgui.get_cursor_screen_pos().x, row_top + 8 * s))
        for p in range(3):
            if p:
                imgui.same_line()
            slot = r.order[crit.id][p]
            label = f"{PLACE_NAMES[p]}\n{names[slot] if slot is not None else '-'}##place{ci}{p}"
            if slot is not None:
                imgui.push_style_color(imgui.Col_.button, imgui.ImVec4(0.20, 0.45, 0.36, 1.0))
            else:
                imgui.push_style_color(imgui.Col_.button, imgui.ImVec4(0.24, 0.25, 0.29, 1.0))
            if ui.button(label, key=("place", crit.id, p), size=(140 * s, 62 * s)) and slot is not None:
                r.click(crit.id, slot)  # take it out again
            imgui.pop_style_color()
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
        imgui.same_line(0, 30 * s)
        for slot in range(3):
            if slot:
                imgui.same_line()
            if r.place_of(crit.id, slot) is not None:
                imgui.dummy(imgui.ImVec2(62 * s, 62 * s))
                continue
            if ui.button(f"{names[slot]}##chip{ci}{slot}", key=("chip", crit.id, slot), size=(62 * s, 62 * s)):
                r.click(crit.id, slot)
                r.active = ci
            if imgui.begin_drag_drop_source():
                imgui.set_drag_drop_payload_py_id(f"slot{ci}", slot)
                ui.text(names[slot])
                imgui.end_drag_drop_source()
        imgui.end_child()
    _keys(app, view)
    # next
    imgui.spacing()
    last = app.session.trial_number() >= app.session.phase_total()
    if view.plan.is_practice:
        label = "Start the study" if last else "Next practice clip"
    else:
        label = "Finish" if last else "Next clip"
    enabled = view.can_submit()
    if ui.button(label, key="next", enabled=enabled, size=(220 * s, 44 * s), primary=True):
        view.submit()
    imgui.same_line(0, 16 * s)
    imgui.set_cursor_pos_y(imgui.get_cursor_pos_y() + 10 * s)
    if enabled:
        ui.muted("Press Enter or the button. You cannot come back to this clip.")
    elif view.playing_id:
        ui.muted("Available when the clip has finished.")
    else:
        missing = [c.label for c in app.design.criteria if not r.is_complete(c.id)]
        ui.muted("Still to rank: " + ", ".join(missing))
