"""The last screen: thanks (the design's ``completion`` text after a finished study), where the results are,
what to do next; also for an early end and for a participant who did not consent."""
from __future__ import annotations

from typing import TYPE_CHECKING

from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp

HEADINGS = {"done": "Study complete", "ended_early": "The study has ended", "declined": "Thank you"}


def draw(app: ScreenApp) -> None:
    ui = app.ui
    session = app.session
    page_begin(app, "final")
    state = session.state.value
    ui.heading(HEADINGS.get(state, HEADINGS["done"]), 2.0)
    ui.text("")
    ui.paragraphs(session.end_message)
    ui.text("")
    if state == "declined":
        pass  # nothing to send, nothing saved but the choice
    elif app.results_file:
        ui.heading("Your results file", 1.3)
        ui.wrapped(str(app.results_file))
        ui.wrapped("Please send this file to the experimenter (for example as an e-mail attachment). "
                   "It contains only your answers and your participant code.")
    else:
        ui.heading("Your answers are saved", 1.3)
        ui.wrapped(f"Results database: {app.db_path}")
        ui.wrapped("Nothing more is needed from you. Please let the experimenter know that you have finished.")
    ui.text("")
    ui.wrapped("You can now close this window.")
    if primary_row(app, "Close", "close", hint="or press Enter"):
        app.quit = True
    page_end()
