"""Post-study questionnaire: Likert rows (radio buttons between two anchors) and free-text answers.

Keyboard: Up/Down pick the item, digits choose a point on a Likert item, Enter submits when every
Likert item is answered (text items are optional).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from imgui_bundle import imgui

from studyapp.ui.input import digit_key
from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.study.design import QuestionItem
    from studyapp.ui.seams import ScreenApp


def complete(items: list[QuestionItem], answers: dict[str, Any]) -> bool:
    return all(answers.get(q.id) is not None for q in items if q.kind == "likert")


def draw(app: ScreenApp) -> None:
    ui = app.ui
    s = app.scale
    items = app.session.questionnaire_items
    answers = app.answers
    page_begin(app, "questionnaire", arrow_scroll=False)  # Up/Down pick the item
    ui.heading("A few last questions", 2.0)
    ui.wrapped("Please tell us about your experience. Choose one point on each scale.")
    ui.text("")
    _keys(app, items)
    for qi, q in enumerate(items):
        active = qi == app.question_active
        ui.heading(f"{qi + 1}. {q.text}", 1.05, key=("question", q.id))
        if active and app.question_moved:
            imgui.set_scroll_here_y(0.3)  # an item picked with the keyboard comes into view
            app.question_moved = False
        if q.kind == "likert":
            left, right = q.anchors
            points = int(q.points)
            # one row "left (1) ... (n) right" when it fits the column, else the anchors on a wrapped line
            # above the points, so long anchors are never cut off at the window's edge
            radio_w = imgui.get_frame_height() + imgui.get_style().item_inner_spacing.x
            row_w = (imgui.calc_text_size(left).x + imgui.calc_text_size(right).x + 14 * s
                     + sum(radio_w + imgui.calc_text_size(str(v)).x + 12 * s for v in range(1, points + 1)))
            inline = row_w <= imgui.get_content_region_avail().x
            if inline:
                imgui.align_text_to_frame_padding()
                ui.text(left, color=(0.70, 0.72, 0.77, 1.0))
                imgui.same_line(0, 14 * s)
            else:
                ui.muted(f"1 = {left};  {points} = {right}")
            for v in range(1, points + 1):
                if ui.radio(f"{v}##{q.id}", answers.get(q.id) == v, key=("likert", q.id, v)):
                    answers[q.id] = v
                    app.question_active = qi
                if inline or v < points:
                    imgui.same_line(0, 12 * s)
            if inline:
                ui.text(right, color=(0.70, 0.72, 0.77, 1.0))
        else:
            old = answers.get(q.id, "") or ""
            if active and app.focus_text:
                imgui.set_keyboard_focus_here()
                app.focus_text = False
            new = ui.input_multiline(f"##{q.id}", old, (min(700 * s, imgui.get_content_region_avail().x),
                                                         90 * s), key=("text", q.id))
            if imgui.is_item_active():
                app.question_active = qi
                app.typing = True
            answers[q.id] = new
        if active:
            ui.muted(f"Keyboard: press 1-{min(9, int(q.points))} to answer, Up/Down arrows for another question"
                     if q.kind == "likert" else "Keyboard: type your answer, then press Enter")
        imgui.spacing()
    ok = complete(items, answers)
    if primary_row(app, "Submit answers", "submit", enabled=ok,
                   hint="" if ok else "Please answer every scale (text answers are optional)."):
        app.session.submit_questionnaire({q.id: answers.get(q.id) for q in items})
    page_end()


def _keys(app: ScreenApp, items: list[QuestionItem]) -> None:
    if not items or app.typing:
        app.typing = False
        return
    if app.key_pressed("down"):
        app.question_active = min(len(items) - 1, app.question_active + 1)
        app.focus_text = app.question_moved = True
    if app.key_pressed("up"):
        app.question_active = max(0, app.question_active - 1)
        app.focus_text = app.question_moved = True
    q = items[app.question_active]
    if q.kind == "likert":
        for v in range(1, min(9, int(q.points)) + 1):
            if app.key_pressed(digit_key(v)):
                app.answers[q.id] = v
