"""The last screen: thanks, where the results are, what to do next (also for an early end)."""
from __future__ import annotations

from typing import TYPE_CHECKING

from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp


def draw(app: ScreenApp) -> None:
    ui = app.ui
    session = app.session
    page_begin(app, "final")
    early = session.state.value == "ended_early"
    ui.heading("The study has ended" if early else "Study complete", 2.0)
    ui.text("")
    ui.wrapped(session.end_message)
    ui.text("")
    if app.results_file:
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
