"""Welcome and consent: what the study is, what is recorded, and the participant's agreement (or not).

The consent text is the design's ``consent`` (``{minutes}`` becomes the estimated length), else the
built-in one. "I agree, start" (or Enter) goes on; "I do not agree" asks once more, then ends the session
without taking part (:meth:`~studyapp.study.session.Session.decline_consent`, recorded). A resumed
participant, who consented before, is welcomed back instead: the page says at which clip they continue,
and that an answer left half-finished last time was dropped.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp

CONSENT_TEXT = (
    "In this study you will watch short clips of three animated figures talking and rank them on a few "
    "questions. It takes about {minutes} minutes. Your answers are saved as you go, under a participant "
    "code, without your name. You can stop at any time by closing the window; nothing else is recorded."
)
AGREE_NOTE = ("By pressing \"I agree, start\" you agree to take part and to your anonymous answers being used "
              "for research. If you do not want to take part, press \"I do not agree\".")

KEYS_TIP = ("Tip: everything works with the keyboard too (Enter continues on every page), and F11 switches "
            "full screen on and off.")


def _consent(app: ScreenApp) -> None:
    ui = app.ui
    s = app.scale
    page_begin(app, "welcome")
    ui.heading("Welcome", 2.0)
    ui.heading(app.design.title, 1.25)
    ui.text("")
    # replace, not str.format: a design's own text may hold other braces
    ui.paragraphs((app.design.consent or CONSENT_TEXT).replace("{minutes}", str(app.estimated_minutes())))
    ui.wrapped(AGREE_NOTE)
    ui.text("")
    if not app.declining:
        if ui.button("I do not agree", key="decline", size=(260 * s, 0)):
            app.declining = True
    else:
        ui.wrapped("End the study now, without taking part? Only that choice is recorded.")
        if ui.button("Yes, end without taking part", key="decline_confirm", size=(320 * s, 0)):
            app.session.decline_consent()
            app.declining = False
            page_end()
            return
        app.ui.imgui.same_line()
        if ui.button("No, go back", key="decline_back", size=(200 * s, 0)):
            app.declining = False
    ui.text("")
    ui.muted(KEYS_TIP)
    if primary_row(app, "I agree, start", "consent", hint="or press Enter"):
        app.declining = False
        app.session.accept_consent()
    page_end()


def _welcome_back(app: ScreenApp) -> None:
    ui = app.ui
    rp = app.session.resume_point
    page_begin(app, "welcome")
    ui.heading("Welcome back", 2.0)
    ui.heading(app.design.title, 1.25)
    ui.text("")
    if rp is not None:
        what = "practice clip" if rp.practice else "clip"
        ui.wrapped(f"You are continuing at {what} {rp.k} of {rp.n}. Your earlier answers are saved.")
        if rp.dropped:
            ui.wrapped("Last time you had started this clip but not finished your answer. That unfinished "
                       "answer was not saved; you will see the clip again from the start.")
    ui.text("")
    ui.muted(KEYS_TIP)
    if primary_row(app, "Continue", "consent", hint="or press Enter"):
        app.session.accept_consent()
    page_end()


def draw(app: ScreenApp) -> None:
    if app.session.resume_point is not None:
        _welcome_back(app)
    else:
        _consent(app)
