"""A block's own instructions page, shown before its first trial, and how each paradigm is answered.

When the trial about to be shown is the first of a block that has ``instructions`` (the session says so:
``Session.block_instructions()`` returns the text), the trial screen shows this page instead: the block's text
(paragraphs as the design wrote them, :func:`studyapp.ui.widgets.reflow`), the block's questions, then "How
to answer" for the block's paradigm with its keys (:func:`how_to_answer`), and "Start this part" (or Enter), which calls
``Session.finish_block_instructions()``. The page never names or hints at a condition.

:func:`how_to_answer` is also what the study's instructions page says for each paradigm a design uses, so
the keys are explained in one wording everywhere.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.ui.paradigm import PREFERENCE, BlockView, block_view, figure_labels, slot_names
from studyapp.ui.rating import digit_points
from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp


def pending(app: ScreenApp) -> str | None:
    """The block's instructions to show now, or None (no block page due)."""
    return app.session.block_instructions()


def how_to_answer(app: ScreenApp, block: BlockView) -> list[str]:
    """Paragraphs saying how a trial of ``block``'s paradigm is answered, mouse and keyboard."""
    t = app.design.text
    if block.paradigm in PREFERENCE:
        first, *_, last = slot_names(figure_labels(app.design, 2), 2)  # as the answer boxes call them
        out = [t("instructions.how_pref", n=block.levels, first=first, last=last)]
        if block.reasons:
            out.append(t("instructions.how_reasons"))
        return out
    if block.paradigm == "rating":
        return [t("instructions.how_rating", n=min(9, len(digit_points(len(block.anchors)))))]
    names = slot_names(figure_labels(app.design, 3), 3)
    out = [t("instructions.how", keys=", ".join(f"{i + 1} = {label}" for i, label in enumerate(names)))]
    if getattr(app.design.playback, "allow_ties", False):
        out.append(t("instructions.ties"))
    return out


def draw(app: ScreenApp) -> None:
    ui = app.ui
    t = app.design.text
    text = pending(app) or ""
    plan = app.session.current_trial()
    page_begin(app, "block")
    ui.heading(t("block.title"), 2.0)
    ui.text("")
    ui.paragraphs(text)
    if plan is not None:
        block = block_view(app.design, plan)
        imgui.spacing()
        ui.heading(t("instructions.questions"), 1.3)
        for crit in block.criteria:
            ui.heading(crit.label, 1.1)
            imgui.indent()
            ui.wrapped(crit.question)
            if crit.explanation:
                ui.muted(crit.explanation)
            imgui.unindent()
        imgui.spacing()
        ui.heading(t("instructions.how_answer_title" if block.paradigm != "rank" else "instructions.how_title"), 1.3)
        for para in how_to_answer(app, block):
            ui.wrapped(para)
            imgui.spacing()
    if primary_row(app, t("block.continue"), "block_continue", hint=t("page.press_enter")):
        app.session.finish_block_instructions()
    page_end()
