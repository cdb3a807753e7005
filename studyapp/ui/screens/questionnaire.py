"""Post-study questionnaire: Likert rows, choices (one or several), numbers in a range and free text.

What each kind accepts is :meth:`~studyapp.study.design.QuestionItem.check_answer`'s rule, the one the
session enforces; the page uses it to say what is still missing. Keyboard: Up/Down pick the item, digits
choose a point on a Likert item or the option of that number on a choice item (toggling it when several
may be chosen), a number or text item takes typing, Enter submits when every item but text is answered.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from imgui_bundle import imgui

from studyapp.study.design.model import plain_number
from studyapp.ui.input import digit_key
from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.study.design import QuestionItem
    from studyapp.ui.seams import ScreenApp

MUTED = (0.70, 0.72, 0.77, 1.0)
WARN = (1.0, 0.80, 0.35, 1.0)


def complete(items: list[QuestionItem], answers: dict[str, Any]) -> bool:
    return all(q.check_answer(answers.get(q.id))[1] is None for q in items)


def _likert(app: ScreenApp, qi: int, q: QuestionItem) -> None:
    ui, s, answers = app.ui, app.scale, app.answers
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
        ui.text(left, color=MUTED)
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
        ui.text(right, color=MUTED)


def _choose(app: ScreenApp, q: QuestionItem, k: int) -> None:
    """Option ``k`` (0-based) picked: the answer, or (several allowed) toggled in or out of the answer."""
    option = q.options[k]
    if q.multiple:
        chosen = list(app.answers.get(q.id) or [])
        app.answers[q.id] = [o for o in q.options if (o in chosen) != (o == option)]
    else:
        app.answers[q.id] = option


def _choice(app: ScreenApp, qi: int, q: QuestionItem) -> None:
    ui = app.ui
    for k, option in enumerate(q.options):
        label = f"{option}##{q.id}{k}"
        if q.multiple:
            now = option in (app.answers.get(q.id) or [])
            if ui.checkbox(label, now, key=("choice", q.id, k)) != now:
                _choose(app, q, k)
                app.question_active = qi
        elif ui.radio(label, app.answers.get(q.id) == option, key=("choice", q.id, k)):
            _choose(app, q, k)
            app.question_active = qi


def _typed(app: ScreenApp, qi: int, q: QuestionItem, active: bool) -> None:
    """A number or text box; the raw text is the answer (the session parses numbers)."""
    ui, s = app.ui, app.scale
    old = app.answers.get(q.id, "") or ""
    if active and app.focus_text:
        imgui.set_keyboard_focus_here()
        app.focus_text = False
    if q.kind == "number":
        new = ui.input_line(f"##{q.id}", str(old), 200 * s, key=("number", q.id))
    else:
        new = ui.input_multiline(f"##{q.id}", old, (min(700 * s, imgui.get_content_region_avail().x), 90 * s),
                                 key=("text", q.id))
    if imgui.is_item_active():
        app.question_active = qi
        app.typing = True
    app.answers[q.id] = new
    if q.kind == "number" and str(new).strip():
        if q.check_answer(new)[1] is not None:
            ui.text(app.design.text("questionnaire.out_of_range", min=plain_number(q.min), max=plain_number(q.max)), color=WARN)


def _hint(app: ScreenApp, q: QuestionItem) -> str:
    t = app.design.text
    if q.kind == "likert":
        return t("questionnaire.keys_likert", n=min(9, int(q.points)))
    if q.kind == "choice":
        return t("questionnaire.keys_choices" if q.multiple else "questionnaire.keys_choice", n=min(9, len(q.options)))
    return t("questionnaire.keys_text")


def draw(app: ScreenApp) -> None:
    ui = app.ui
    t = app.design.text
    items = app.session.questionnaire_items
    page_begin(app, "questionnaire", arrow_scroll=False)  # Up/Down pick the item
    ui.heading(t("questionnaire.title"), 2.0)
    ui.wrapped(t("questionnaire.intro"))
    ui.text("")
    _keys(app, items)
    for qi, q in enumerate(items):
        active = qi == app.question_active
        ui.heading(f"{qi + 1}. {q.text}", 1.05, key=("question", q.id), wrap_x=0.0)
        if active and app.question_moved:
            imgui.set_scroll_here_y(0.3)  # an item picked with the keyboard comes into view
            app.question_moved = False
        if q.kind == "likert":
            _likert(app, qi, q)
        elif q.kind == "choice":
            if q.multiple:
                ui.muted(t("questionnaire.all_that_apply"))
            _choice(app, qi, q)
        else:
            if q.kind == "number":
                ui.muted(t("questionnaire.whole_number" if q.integer else "questionnaire.number", min=plain_number(q.min),
                           max=plain_number(q.max)))
            _typed(app, qi, q, active)
        if active:
            ui.muted(_hint(app, q))
        imgui.spacing()
    ok = complete(items, app.answers)
    if primary_row(app, t("questionnaire.submit"), "submit", enabled=ok,
                   hint="" if ok else t("questionnaire.missing")):
        app.session.submit_questionnaire({q.id: app.answers.get(q.id) for q in items})
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
    elif q.kind == "choice":
        for v in range(1, min(9, len(q.options)) + 1):
            if app.key_pressed(digit_key(v)):
                _choose(app, q, v - 1)
