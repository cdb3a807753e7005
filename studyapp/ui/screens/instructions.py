"""Instructions from the design, the criteria explained, and how to rank."""
from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.study.design.texts import EN as EN_TEXTS
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
    ui.heading(t("instructions.how_title"), 1.3)
    keys = ", ".join(f"{i + 1} = {label}" for i, label in enumerate(app.slot_names))
    ui.wrapped(t("instructions.how", keys=keys))
    if getattr(app.design.playback, "allow_ties", False):
        imgui.spacing()
        ui.wrapped(t("instructions.ties"))
    if primary_row(app, t("page.continue"), "continue", hint=t("page.press_enter")):
        app.session.finish_instructions()
    page_end()
