"""The last screen: thanks (the design's ``completion`` text after a finished study), where the results are,
what to do next; also for an early end and for a participant who did not consent."""
from __future__ import annotations

from typing import TYPE_CHECKING

from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp



def draw(app: ScreenApp) -> None:
    ui = app.ui
    session = app.session
    page_begin(app, "final")
    t = app.design.text
    state = session.state.value
    ui.heading(t(f"final.{state}" if state in ("ended_early", "declined") else "final.done"), 2.0)
    ui.text("")
    ui.paragraphs(session.end_message)
    ui.text("")
    if state == "declined":
        pass  # nothing to send, nothing saved but the choice
    elif app.results_file:
        ui.heading(t("final.file_title"), 1.3)
        ui.wrapped(str(app.results_file))
        ui.wrapped(t("final.file_text"))
    else:
        ui.heading(t("final.saved_title"), 1.3)
        ui.wrapped(t("final.saved_db", path=app.db_path))
        ui.wrapped(t("final.saved_text"))
    if app.upload_status is not None and state != "declined":
        ui.text("")
        ui.wrapped(app.upload_status())   # cheap: the upload worker's last known state, read under a lock
    ui.text("")
    ui.wrapped(t("final.close_window"))
    if primary_row(app, t("final.close"), "close", hint=t("page.press_enter")):
        app.quit = True
    page_end()
