"""Full-page screens read completely at 1280x720, and a failed attention check ends the study politely.

Both run the real session and UI code offscreen through :class:`studyapp.bots.ui_driver.UIBot`.
"""
from __future__ import annotations

import pytest

from studyapp.bots.ui_driver import UIBot

pytestmark = pytest.mark.gl


def _frames(bot, n=3):
    for _ in range(n):
        bot.frame()


def _press(bot, key, n=3):
    bot.app.input.tap(key)
    _frames(bot, n)


def test_long_instructions_say_more_is_below_and_scroll_with_the_keyboard(tmp_path):
    """The demo's instructions are taller than a 720p window: the footer says so (a scrollbar alone is easy
    to miss), and Page Down / Down bring "How to rank" into view without a mouse."""
    from imgui_bundle import imgui

    from studyapp.resources import demo_design
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB
    from studyapp.ui.screens.common import MORE_BELOW_HINT

    design = load_design(demo_design())
    db = ResultsDB(tmp_path / "r.sqlite", design)
    bot = UIBot(design, db, "S1", "ordered", 1, size=(1280, 720))
    try:
        _frames(bot, 2)
        assert bot.app.screen_key() == "welcome"
        _press(bot, imgui.Key.enter)
        assert bot.app.screen_key() == "instructions"
        _frames(bot, 2)
        ui = bot.app.ui
        assert MORE_BELOW_HINT in ui.frame_strings
        y_before = ui.rects["more_below"][1]
        assert y_before > 600  # the hint sits in the footer, next to Continue
        for _ in range(10):
            _press(bot, imgui.Key.page_down, 2)
        assert MORE_BELOW_HINT not in ui.frame_strings
        assert "or press Enter" in ui.frame_strings
        # Up arrow scrolls back: the hint returns; Down arrow scrolls down again
        for _ in range(12):
            _press(bot, imgui.Key.up_arrow, 2)
        assert MORE_BELOW_HINT in ui.frame_strings
        for _ in range(30):
            _press(bot, imgui.Key.down_arrow, 2)
        assert MORE_BELOW_HINT not in ui.frame_strings
        assert bot.app.screen_key() == "instructions"  # scrolling never continues by itself
    finally:
        bot.close()
        db.close()


def test_a_short_page_has_no_scroll_hint(tiny_study):
    design, db = tiny_study
    bot = UIBot(design, db, "S2", "ordered", 1, size=(1280, 720))
    try:
        _frames(bot, 3)
        from studyapp.ui.screens.common import MORE_BELOW_HINT

        assert bot.app.screen_key() == "welcome"
        assert MORE_BELOW_HINT not in bot.app.ui.frame_strings
        assert "or press Enter" in bot.app.ui.frame_strings
    finally:
        bot.close()


def test_sound_check_with_the_t_key(tiny_study):
    from imgui_bundle import imgui

    design, db = tiny_study
    bot = UIBot(design, db, "S3", "ordered", 1)
    try:
        _frames(bot, 2)
        _press(bot, imgui.Key.enter)
        _press(bot, imgui.Key.enter)
        _frames(bot, 3)  # the environment check measures first
        assert bot.app.screen_key() == "env_check" and bot.app.env_report is not None
        assert not bot.app.test_sound_played
        _press(bot, imgui.Key.t)
        assert bot.app.test_sound_played
        assert bot.app.screen_key() == "env_check"
    finally:
        bot.close()


@pytest.fixture
def attention_study(tmp_path):
    """Practice, two clips and one attention check; one failed check ends the session."""
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB
    from fixtures.synthetic import write_synthetic_study

    path = write_synthetic_study(tmp_path / "att", n_stimuli=2, seconds=1.0, attention_check=True,
                                 questionnaire=True, max_attention_failures=0)
    design = load_design(path)
    db = ResultsDB(tmp_path / "att.sqlite", design)
    yield design, db
    db.close()


def test_failed_attention_check_is_recorded_and_ends_politely(attention_study, monkeypatch, secrets_of):
    """The scripted participant ranks the check's frozen figure best (the wrong answer) through the real
    panel; the check looked like any other clip, the failure is stored, the remaining clips and the
    questionnaire are skipped, and the final screen shows the polite end message."""
    import studyapp.bots.policies as bots
    from studyapp.study.session import ENDED_EARLY_MESSAGE

    design, db = attention_study
    real = bots.choose_ranking

    def wrong_on_checks(policy, plan, *a, **k):
        ranks = real(policy, plan, *a, **k)
        if plan.is_attention_check:  # best <-> worst: the frozen figure comes first on realism
            return {c: {s: 4 - r for s, r in v.items()} for c, v in ranks.items()}
        return ranks

    monkeypatch.setattr(bots, "choose_ranking", wrong_on_checks)
    bot = UIBot(design, db, "A1", "ordered", 2)
    progress_on_check = None
    try:
        # run until the check is on screen, note what the participant sees there
        for _ in range(3000):
            plan = bot.session.current_trial()
            if plan is not None and plan.is_attention_check and bot.app.screen_key().endswith(":ranking"):
                progress_on_check = bot.session.progress_label()
                assert progress_on_check in bot.app.ui.frame_strings
                break
            bot.frame()
            bot.steps.popleft()() if bot.steps else bot._plan(bot.app.screen_key())
        assert progress_on_check is not None, "the attention check never came"
        assert bot.run() == 0
        drawn = set(bot.app.ui.drawn)
        final_strings = list(bot.app.ui.frame_strings)
    finally:
        bot.close()
    assert progress_on_check.startswith("Clip ") and " of " in progress_on_check
    rec = db.participant("A1")
    assert rec.status == "ended_early"
    checks = [t for t in db.trials("A1") if t["is_attention_check"]]
    assert len(checks) == 1 and checks[0]["attention_passed"] == 0
    assert db.questionnaire("A1") == []
    assert ENDED_EARLY_MESSAGE in drawn and "The study has ended" in drawn
    assert "ended early" in ENDED_EARLY_MESSAGE and "appreciated" in ENDED_EARLY_MESSAGE
    # no word on any screen gives away the check or a condition
    # (the results path on the final screen contains this test's name, so it is left out)
    assert [s for s in drawn if "attention" in s.lower() and str(db.path) not in s] == []
    from studyapp.ui.widgets import Painter

    p = Painter()
    for s in drawn:
        p.record(s)
    assert p.leaks(secrets_of(design)) == []
    assert any("Close" in s for s in final_strings)
