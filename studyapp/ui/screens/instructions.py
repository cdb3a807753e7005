"""Instructions from the design, the criteria explained, and how to answer.

"How to rank" for a ranking study (a design without blocks: as always); a design with other paradigms gets
"How to answer" with each of its paradigms' keys (:func:`studyapp.ui.screens.block_intro.how_to_answer`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.study.design.texts import EN as EN_TEXTS
from studyapp.ui.paradigm import paradigm_views
from studyapp.ui.screens.block_intro import how_to_answer
from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp

# English (tests read them); participants read design.text(...) in the design's language
HOW_TO_RANK = EN_TEXTS["instructions.how"]
HOW_TO_TIE = EN_TEXTS["instructions.ties"]


def draw(app: ScreenApp) -> None:
    ui = app.ui
    t = app.design.text
    page_begin(app, "instructions")
    ui.heading(t("instructions.title"), 2.0)
    ui.text("")
    ui.paragraphs(app.design.instructions or "")
    ui.heading(t("instructions.questions"), 1.3)
    for crit in app.design.criteria:
        ui.heading(crit.label, 1.1)
        imgui.indent()
        ui.wrapped(crit.question)
        if crit.explanation:
            ui.muted(crit.explanation)
        imgui.unindent()
    imgui.spacing()
    blocks = paradigm_views(app.design)
    only_rank = [b.paradigm for b in blocks] == ["rank"]
    ui.heading(t("instructions.how_title" if only_rank else "instructions.how_answer_title"), 1.3)
    paras: list[str] = []   # pairwise and mismatch blocks are answered alike: their paragraphs once
    for block in blocks:
        paras += [p for p in how_to_answer(app, block) if p not in paras]
    for k, para in enumerate(paras):
        if k:
            imgui.spacing()
        ui.wrapped(para)
    if primary_row(app, t("page.continue"), "continue", hint=t("page.press_enter")):
        app.session.finish_instructions()
    page_end()
