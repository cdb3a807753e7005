"""Instructions from the design, the criteria explained, and how to rank."""
from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp

HOW_TO_RANK = (
    "After a clip has played to the end, a panel opens below the figures. For each question, put the three "
    "figures in order from best (1st) to worst (3rd): drag a figure's letter into a box, or click the letters "
    "in order from best to worst. Keyboard: the number keys choose a figure, not a rank: {keys} puts that "
    "figure in the next free box, so pressing them in your order from best to worst ranks the question. "
    "Up/Down change question, Backspace clears a question, Enter goes to the next clip. Space pauses and "
    "resumes the clip."
)
HOW_TO_TIE = (
    "If two or three figures seem equally good, you may rank them as equal: click the > sign between their "
    "boxes so that it shows = (keyboard: press = before placing the next figure, e.g. 1 = 2 3). Equal figures "
    "share the better place: two equal best figures are both 1st, and the other one is 3rd."
)


def draw(app: ScreenApp) -> None:
    ui = app.ui
    page_begin(app, "instructions")
    ui.heading("Instructions", 2.0)
    ui.text("")
    ui.paragraphs(app.design.instructions or "")
    ui.heading("The questions", 1.3)
    for crit in app.design.criteria:
        ui.heading(crit.label, 1.1)
        imgui.indent()
        ui.wrapped(crit.question)
        if crit.explanation:
            ui.muted(crit.explanation)
        imgui.unindent()
    imgui.spacing()
    ui.heading("How to rank", 1.3)
    keys = ", ".join(f"{i + 1} = {label}" for i, label in enumerate(app.slot_names))
    ui.wrapped(HOW_TO_RANK.format(keys=keys))
    if getattr(app.design.playback, "allow_ties", False):
        imgui.spacing()
        ui.wrapped(HOW_TO_TIE)
    if primary_row(app, "Continue", "continue", hint="or press Enter"):
        app.session.finish_instructions()
    page_end()
