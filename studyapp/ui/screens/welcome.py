"""Welcome and consent: what the study is, what is recorded, and the participant's agreement."""
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

KEYS_TIP = ("Tip: everything works with the keyboard too (Enter continues on every page), and F11 switches "
            "full screen on and off.")


def draw(app: ScreenApp) -> None:
    ui = app.ui
    page_begin(app, "welcome")
    ui.heading("Welcome", 2.0)
    ui.heading(app.design.title, 1.25)
    ui.text("")
    minutes = app.estimated_minutes()
    ui.wrapped(CONSENT_TEXT.format(minutes=minutes))
    ui.text("")
    ui.wrapped("By pressing the button below you agree to take part and to your anonymous answers being "
               "used for research.")
    ui.text("")
    ui.muted(KEYS_TIP)
    if primary_row(app, "I agree, start", "consent", hint="or press Enter"):
        app.session.accept_consent()
    page_end()
