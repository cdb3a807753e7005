"""The participant pages a design edits (issue 18, item 5), through the real UI offscreen: the design's
consent text and the "I do not agree" path, every questionnaire kind answered with mouse and keyboard,
the completion text, and "welcome back" on resume."""
from __future__ import annotations

import json

import pytest

from studyapp.bots.ui_driver import UIBot
from fixtures.questionnaire_kinds import CHOICE_AND_NUMBER_ITEMS

pytestmark = pytest.mark.gl

TOP = '''consent = """
We study gestures.
It takes about {minutes} minutes."""
completion = "Thanks! This study compared gesture models."
'''
ITEMS = CHOICE_AND_NUMBER_ITEMS


def _study(tmp_path):
    from fixtures.synthetic import write_synthetic_study
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB

    path = write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0, practice=False, questionnaire=True)
    path.write_text(TOP + path.read_text() + ITEMS)
    design = load_design(path)
    return design, ResultsDB(tmp_path / "r.sqlite", design)


def test_consent_text_every_item_kind_and_completion_through_the_ui(tmp_path, secrets_of):
    design, db = _study(tmp_path)
    bot = UIBot(design, db, "P1", "random", 5, size=(1280, 720), out_dir=tmp_path / "shots")
    seen = set()
    orig = bot.frame

    def frame():
        orig()
        seen.update(bot.app.ui.frame_strings)

    bot.frame = frame
    try:
        assert bot.run() == 0
        assert bot.app.ui.leaks(secrets_of(design)) == []
        assert bot.app.ui.cut_off == []
    finally:
        bot.close()
    rows = {r["item"]: (r["kind"], r["value"]) for r in db.questionnaire("P1")}
    db.close()
    minutes = next(s for s in seen if s.startswith("We study gestures."))
    assert minutes.startswith("We study gestures. It takes about ") and "{minutes}" not in minutes
    assert "I do not agree" in seen and "Thanks! This study compared gesture models." in seen
    assert rows["device"][0] == "choice" and rows["device"][1] in ("Headphones", "Speakers", "Laptop")
    assert json.loads(rows["hobbies"][1]) and set(json.loads(rows["hobbies"][1])) <= {"Dance", "Theatre",
                                                                                     "Sign language"}
    assert rows["age"][0] == "number" and 18 <= int(rows["age"][1]) <= 99
    assert rows["q1"][0] == "likert"


def test_choice_items_answer_to_the_number_keys(tmp_path):
    from studyapp.ui.input import digit_key

    design, db = _study(tmp_path)
    bot = UIBot(design, db, "P1", "random", 5, size=(1280, 720))
    try:
        for _ in range(400):
            if bot.app.screen_key() == "questionnaire":
                break
            bot.step()
        assert bot.app.screen_key() == "questionnaire"
        bot.frame()
        ids = [q.id for q in design.questionnaire]
        bot.app.question_active = ids.index("hobbies")
        for d in (3, 1, 3):   # tick Sign language, tick Dance, untick Sign language
            bot.app.input.tap(digit_key(d))
            bot.frame()
            bot.frame()
        assert bot.app.answers["hobbies"] == ["Dance"]
        bot.app.question_active = ids.index("device")
        bot.app.input.tap(digit_key(2))
        bot.frame()
        bot.frame()
        assert bot.app.answers["device"] == "Speakers"
    finally:
        bot.close()
        db.close()


def test_i_do_not_agree_ends_the_session_in_the_ui(tmp_path):
    design, db = _study(tmp_path)
    bot = UIBot(design, db, "P1", "random", 5, size=(1280, 720), consent=False)
    try:
        assert bot.run() == 0
        assert bot.app.screen_key() == "declined"
        assert "Thank you" in bot.app.ui.frame_strings
        assert any("not to take part" in s for s in bot.app.ui.frame_strings)
    finally:
        bot.close()
    assert db.participant("P1").status == "ended_early" and db.trials("P1") == []
    db.close()


def test_resumed_participant_is_welcomed_back_with_where_they_continue(tmp_path):
    from studyapp.study.session import Session

    from fixtures.synthetic import write_synthetic_study
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB

    path = write_synthetic_study(tmp_path / "s", n_stimuli=3, seconds=1.0, practice=False)
    design = load_design(path)
    db = ResultsDB(tmp_path / "r.sqlite", design)
    s = Session(design, db, "P1")
    s.accept_consent(); s.finish_instructions(); s.record_env_check({})
    s.record_play_started(); s.record_play_finished(True)
    s.submit_ranking({c.id: {0: 1, 1: 2, 2: 3} for c in design.criteria})
    s.record_play_started(); s.record_play_finished(True)   # clip 2 watched, window closed before answering
    s.close()
    bot = UIBot(design, db, "P1", "random", 5, size=(1280, 720))
    try:
        for _ in range(3):
            bot.frame()
        strings = bot.app.ui.frame_strings
        assert "Welcome back" in strings
        assert "You are continuing at clip 2 of 3. Your earlier answers are saved." in strings
        assert any("unfinished answer was not saved" in t for t in strings)
        assert "I do not agree" not in strings
        assert bot.run() == 0
    finally:
        bot.close()
    assert len(db.trials("P1")) == 3
    db.close()
