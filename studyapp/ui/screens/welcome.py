"""Welcome and consent: what the study is, what is recorded, and the participant's agreement (or not).

The consent text is the design's ``consent`` (``{minutes}`` becomes the estimated length), else the
built-in one. "I agree, start" (or Enter) goes on; "I do not agree" asks once more, then ends the session
without taking part (:meth:`~studyapp.study.session.Session.decline_consent`, recorded). A resumed
participant, who consented before, is welcomed back instead: the page says at which clip they continue,
and that an answer left half-finished last time was dropped.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from studyapp.study.design.texts import EN as EN_TEXTS
from studyapp.study.design.texts import fill
from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp

# The English texts (tests read them); participants read design.text(...) in the design's language.
CONSENT_TEXT = EN_TEXTS["welcome.consent"]
KEYS_TIP = EN_TEXTS["welcome.keys_tip"]


def _consent(app: ScreenApp) -> None:
    ui = app.ui
    s = app.scale
    t = app.design.text
    page_begin(app, "welcome")
    ui.heading(t("welcome.title"), 2.0)
    ui.heading(app.design.title, 1.25)
    ui.text("")
    # replace, not str.format: a design's own text may hold other braces
    ui.paragraphs(fill(app.design.consent or t("welcome.consent"), minutes=app.estimated_minutes()))
    ui.wrapped(t("welcome.agree_note"))
    ui.text("")
    if not app.declining:
        if ui.button(t("welcome.decline"), key="decline", size=(260 * s, 0)):
            app.declining = True
    else:
        ui.wrapped(t("welcome.decline_ask"))
        if ui.button(t("welcome.decline_confirm"), key="decline_confirm", size=(320 * s, 0)):
            app.session.decline_consent()
            app.declining = False
            page_end()
            return
        app.ui.imgui.same_line()
        if ui.button(t("welcome.decline_back"), key="decline_back", size=(200 * s, 0)):
            app.declining = False
    ui.text("")
    ui.muted(t("welcome.keys_tip"))
    if primary_row(app, t("welcome.agree"), "consent", hint=t("page.press_enter")):
        app.declining = False
        app.session.accept_consent()
    page_end()


def _welcome_back(app: ScreenApp) -> None:
    ui = app.ui
    t = app.design.text
    rp = app.session.resume_point
    page_begin(app, "welcome")
    ui.heading(t("welcome.back_title"), 2.0)
    ui.heading(app.design.title, 1.25)
    ui.text("")
    if rp is not None:
        ui.wrapped(t("welcome.back_practice" if rp.practice else "welcome.back_clip", k=rp.k, n=rp.n))
        if rp.dropped:
            ui.wrapped(t("welcome.back_dropped"))
    ui.text("")
    ui.muted(t("welcome.keys_tip"))
    if primary_row(app, t("page.continue"), "consent", hint=t("page.press_enter")):
        app.session.accept_consent()
    page_end()


def draw(app: ScreenApp) -> None:
    if app.session.resume_point is not None:
        _welcome_back(app)
    else:
        _consent(app)
