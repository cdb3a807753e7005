"""The pairwise, mismatch and rating screens offscreen (EGL), driven through the input queue like a participant.

One scripted participant (fixtures.paradigm_studies.SCRIPT: keyboard, mouse and both) goes through a study
with one block of each paradigm; the test checks what the database stores, what the screen shows (the chosen
option green, a hovered one not, an unset slider without a handle) and that nothing names a condition. The
window test (test_paradigm_window_xvfb.py) plays the same script through X events and must store the same.
"""
from __future__ import annotations

import sqlite3

import numpy as np
import pytest

from fixtures.paradigm_studies import SCRIPT, SCRIPT_STORED, paradigm_study  # noqa: F401
from studyapp.bots.ui_driver import UIBot, center, slider_point

pytestmark = pytest.mark.gl


def stored(db, pid: str) -> dict[int, tuple[dict, list]]:
    import json

    out: dict[int, tuple[dict, list]] = {}
    with sqlite3.connect(db.path) as con:
        for trial, crit, slot, value, reasons in con.execute(
                "SELECT trial_index, criterion, slot, value, reasons FROM judgements WHERE participant = ?", (pid,)):
            values, _ = out.setdefault(trial, ({}, json.loads(reasons) if reasons else []))
            values.setdefault(crit, {})[int(slot)] = float(value)
    return out


def imgui_key(name: str):
    from imgui_bundle import imgui

    from studyapp.ui.input import digit_key

    if name.isdigit():
        return digit_key(int(name))
    return {"Return": imgui.Key.enter, "Right": imgui.Key.right_arrow, "Left": imgui.Key.left_arrow,
            "Down": imgui.Key.down_arrow, "Up": imgui.Key.up_arrow, "Prior": imgui.Key.page_up,
            "Next": imgui.Key.page_down}[name]


class ScriptedBot(UIBot):
    """The offscreen participant, playing :data:`SCRIPT` on the trials (the usual bot on the other pages)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.done: set[tuple[int, str]] = set()
        self.checks: list = []

    def _plan_trial(self, key: str) -> None:
        sub = key.split(":")[1] if ":" in key else ""
        plan = self.session.current_trial()
        part = "block" if sub == "block" else "answer" if sub in ("answering", "answered") else None
        if part is None or (plan.trial_index, part) in self.done:
            if sub == "ready":
                self.click("play")
            self.wait()
            return
        self.done.add((plan.trial_index, part))
        self.on_screen(plan.trial_index, part)
        for action in SCRIPT[plan.trial_index].get(part, []):
            kind = action[0]
            if kind == "key":
                self.key(imgui_key(action[1]))
            elif kind == "click":
                self.click(action[1])
            elif kind == "slider":
                q = self.app.input
                self.steps.append(lambda k=action[1], v=action[2]: q.mouse_move(*slider_point(self._rect(k), v)))
                self.steps.append(lambda: q.mouse_button(0, True))
                self.steps.append(lambda: q.mouse_button(0, False))
                self.wait(2)
            else:  # "missing": checked when the step runs
                self.steps.append(lambda want=action[1]: self.checks.append(
                    (want, self.app.trial_view().answer.missing(), self.app.trial_view().can_submit())))
        self.wait(2)

    def on_screen(self, trial: int, part: str) -> None:
        """Hook: the screen of ``trial`` / ``part`` is shown, before the script acts on it."""


def test_offscreen_script_stores_each_paradigms_answer(paradigm_study, tmp_path, secrets_of):
    design, db = paradigm_study
    bot = ScriptedBot(design, db, "S1", "ordered", 0, out_dir=tmp_path / "shots")
    try:
        assert bot.run() == 0
        drawn = set(bot.app.ui.drawn)
        assert bot.app.ui.cut_off == []          # five reasons flow onto two lines; nothing runs off
    finally:
        bot.close()
    assert [p.paradigm for p in bot.session.plans] == ["pairwise", "mismatch", "mismatch", "rating"]
    assert stored(db, "S1") == SCRIPT_STORED
    # Continue stayed disabled while one slider was unset, and the panel named it
    assert bot.checks == [([("diversity", 2)], [("diversity", 2)], False)]
    for text in ("key 1", "key 5", "Clearly A", "Slightly B", "No preference", "Hand and arm movement  (key 1)", "Facial expression  (key 5)", "Excellent",
                 "not rated yet", "In this part you compare two figures at a time.", "Still to rate: Diversity: C"):
        assert text in drawn, text
    from studyapp.ui.widgets import Painter

    p = Painter()
    for s in drawn:
        p.record(s)
    assert p.leaks(secrets_of(design)) == []


def _pixel(rgb: np.ndarray, rect, inset=(8, 6)) -> np.ndarray:
    """The colour of a box near its lower left corner (clear of its centred text and rounded corner)."""
    x0, y0, x1, y1 = rect
    return rgb[int(y1) - inset[1], int(x0) + inset[0]].astype(int)


def test_chosen_option_is_green_and_hover_only_lightens(paradigm_study):
    """Pixels: after key 4 the "Slightly B" box is the chosen green; the mouse resting on "Clearly A" lightens
    that box by a few levels, nowhere near green; an unset slider shows no handle, a set one does."""
    from studyapp.ui.screens.ranking_panel import EMPTY_COLOR, FILLED_COLOR

    design, db = paradigm_study
    seen: dict = {}

    class Looking(ScriptedBot):
        def on_screen(self, trial, part):
            if (trial, part) == (0, "answer"):
                q = self.app.input
                self.steps.append(lambda: q.mouse_move(*center(self._rect(("option", "realism", -2)))))
                self.wait(2)
                self.key(imgui_key("4"))
                self.wait(5)
                self.steps.append(lambda: seen.update(pref=(self.screenshot("pref"), dict(self.app.ui.rects))))
            if (trial, part) == (3, "answer"):
                self.wait(2)
                self.steps.append(lambda: seen.update(unset=(self.screenshot("unset"), dict(self.app.ui.rects))))

    bot = Looking(design, db, "S2", "ordered", 0)
    try:
        # the script's first key is 4 again: harmless, the answer stays "Slightly B"
        assert bot.run() == 0
    finally:
        bot.close()
    rgb, rects = seen["pref"]
    green = np.array(FILLED_COLOR[:3]) * 255
    empty = np.array(EMPTY_COLOR[:3]) * 255
    chosen = _pixel(rgb, rects[("option", "realism", 1)])
    hovered = _pixel(rgb, rects[("option", "realism", -2)])
    plain = _pixel(rgb, rects[("option", "realism", 2)])
    assert np.abs(chosen - green).max() <= 3, chosen
    assert np.abs(plain - empty).max() <= 3, plain
    assert 3 <= (hovered - empty).min() and (hovered - empty).max() <= 15, hovered   # lighter grey, same hue
    assert np.abs(hovered - green).max() > 40
    rgb, rects = seen["unset"]
    x0, y0, x1, y1 = (int(v) for v in rects[("slider", "realism", 1)])
    handle = np.abs(rgb[y0:y1, x0:x1].astype(int) - np.array([89, 204, 140])).max(axis=2) < 30
    assert handle.sum() == 0                     # not moved yet: no handle anywhere on the track
    assert stored(db, "S2")[3][0]["realism"][1] == 90.0


def test_chinese_paradigm_screens_have_every_glyph_and_nothing_cut_off(tmp_path, monkeypatch):
    """A ``language = "zh"`` study with a pairwise, mismatch and rating block whose reasons, anchors and block
    page are Chinese: every character drawn has a glyph (checked in the pixels as test_language_glyphs does)
    and no text is cut off."""
    from fixtures.paradigm_studies import BLOCKS, write_paradigm_study
    from studyapp.study.design import load_design
    from studyapp.study.design.fonts import design_fallback_font, needed_chars, participant_texts
    from studyapp.study.storage import ResultsDB
    from test_language_glyphs import _glyph_cells

    blocks = (BLOCKS.replace('"Hand and arm movement", "Timing with the speech", "Smoothness", "Body posture", "Facial expression"',
                            '"手部", "时机", "流畅度", "姿势", "表情"')
              .replace('"Bad", "Poor", "Fair", "Good", "Excellent"', '"很差", "较差", "一般", "较好", "很好"')
              .replace("In this part you compare two figures at a time.", "这一部分每次比较两个人物。"))
    path = write_paradigm_study(tmp_path / "zh", blocks)
    path.write_text('language = "zh"\n' + path.read_text())
    design = load_design(path)
    # the font is chosen for the blocks' texts too (validate says so when none has their characters)
    assert {"很", "般"} <= needed_chars(participant_texts(design))   # in no built-in text: only the anchors
    if design_fallback_font(design)[0] is None:  # pragma: no cover - the CI installs fonts-wqy-microhei
        pytest.skip("no CJK font installed (apt install fonts-wqy-microhei)")
    db = ResultsDB(tmp_path / "zh.sqlite", design)
    bot = UIBot(design, db, "Z1", "careful", 2, size=(1280, 720))
    try:
        assert bot.run() == 0
        drawn = set(bot.app.ui.drawn)
        assert bot.app.ui.cut_off == []
    finally:
        bot.close()
    for key in ("pref.equal", "rating.unset", "block.title", "instructions.how_pref", "instructions.how_rating"):
        assert any(design.text(key, n=5, first="A", last="B") in s for s in drawn), key
    assert "这一部分每次比较两个人物。" in drawn and "很好" in drawn
    chars = sorted({c for s in drawn for c in s if c.isprintable() and not c.isspace()})
    cells, none = _glyph_cells(design, db, chars, monkeypatch)
    db.close()
    assert none.max() > 100
    missing = [c for c, cell in zip(chars, cells) if cell.max() < 100 or np.abs(cell - none).mean() < 2.0]
    assert missing == [], "".join(missing)
