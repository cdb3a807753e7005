"""The final screen of a bundle run with uploads (``bundle --upload-url``) says whether the answers reached the
study server, read from the upload worker each frame; without uploads it says nothing about a server."""
from __future__ import annotations

import pytest

from studyapp.bots.ui_driver import UIBot
from studyapp.study.upload import Outcome, final_message

pytestmark = pytest.mark.gl


def test_the_final_screen_says_whether_the_answers_reached_the_study_server(tiny_study):
    design, db = tiny_study
    outcomes = {"now": Outcome(False, sending=True)}
    bot = UIBot(design, db, "U1", "ordered", 1)
    bot.app.upload_status = lambda: final_message(outcomes["now"])
    try:
        for _ in range(20000):
            if bot.session.state.value == "done":
                break
            bot.step()
        for _ in range(3):
            bot.frame()
        sending = list(bot.app.ui.frame_strings)
        outcomes["now"] = Outcome(True)    # the worker's last upload was acknowledged
        for _ in range(3):
            bot.frame()
        sent = list(bot.app.ui.frame_strings)
    finally:
        bot.close()
    assert db.participant("U1").status == "done"
    assert "Sending your answers to the study server..." in sending
    assert "All your answers reached the study server." in sent and "Sending your answers to the study server..." not in sent
