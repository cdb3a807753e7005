"""Small things a participant notices (issue 18, item 7), checked in what the real screens draw offscreen.

* the number keys pick a figure, not a rank, and the screen says so (the hint and a key on each chip);
* hovering a rank box does not make it look filled or selected (pixels);
* the computer check speaks plainly (no renderer names, frame rates or API names), while the session's
  record keeps the technical facts;
* hard line breaks in a design's instructions do not show: the paragraph flows to the window's width;
* the hint beside "Next clip" stays on one line at full screen (a second line ran into the first question).
"""
from __future__ import annotations

import json
import re
import sqlite3

import numpy as np
import pytest

from fixtures.ui_steps import until_screen
from studyapp.bots.ui_driver import UIBot

pytestmark = pytest.mark.gl


def _until(bot: UIBot, screen: str, limit: int = 300) -> None:
    until_screen(bot, screen, limit)


def _study(tmp_path, extra: str = "", instructions: str | None = None):
    from fixtures.synthetic import write_synthetic_study
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB

    path = write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0, practice=False)
    text = path.read_text()
    if instructions is not None:
        text = re.sub(r'(?m)^instructions\s*=\s*(""".*?"""|".*?")', lambda _m: "instructions = " + json.dumps(instructions),
                      text, count=1, flags=re.S)
        assert json.dumps(instructions) in text
    path.write_text(text + extra)
    design = load_design(path)
    return design, ResultsDB(tmp_path / "r.sqlite", design)


def test_keys_pick_figures_and_the_ranking_screen_says_so(tmp_path):
    from studyapp.ui.screens.ranking_panel import keys_line

    design, db = _study(tmp_path)
    bot = UIBot(design, db, "P1", "ordered", 1, size=(1280, 720))
    try:
        _until(bot, "instructions")
        drawn = " ".join(bot.app.ui.frame_strings)
        assert "1 = A, 2 = B, 3 = C puts that figure in the next free box" in drawn
        _until(bot, "trials:ranking")
        strings = bot.app.ui.frame_strings
        assert keys_line(("A", "B", "C")) in strings  # beside "Next clip" until a figure is placed
        assert {"key 1", "key 2", "key 3"} <= set(strings)
        # and the keys do what the line says: 2 then 3 then 1 puts B best, C second, A last
        from studyapp.ui.input import digit_key

        for d in (2, 3, 1):
            bot.app.input.tap(digit_key(d))
            bot.frame()
            bot.frame()
        crit = design.criteria[0].id
        assert bot.app.trial_view().ranking.order[crit] == [1, 2, 0]
    finally:
        bot.close()
        db.close()


def _mean_rgb(rgb: np.ndarray, rect, inset: float = 5.0) -> np.ndarray:
    """Mean colour of the left strip of ``rect`` (inside its border, beside its centred text)."""
    x0, y0, x1, y1 = (int(round(v)) for v in rect)
    return rgb[y0 + int(inset) + 8:y1 - int(inset) - 8, x0 + int(inset):x0 + int(inset) + 8].reshape(-1, 3).mean(0)


def test_hovering_a_rank_box_does_not_make_it_look_filled(tmp_path):
    design, db = _study(tmp_path)
    bot = UIBot(design, db, "P1", "ordered", 1, size=(1280, 720))
    try:
        _until(bot, "trials:ranking")
        crit = design.criteria[0].id
        box = bot.app.ui.rects[("place", crit, 1)]
        bot.app.input.mouse_move(5, 5)
        for _ in range(3):
            bot.frame()
        plain = _mean_rgb(bot.target.read_rgb(), box)
        bot.app.input.mouse_move((box[0] + box[2]) / 2, (box[1] + box[3]) / 2)
        for _ in range(3):
            bot.frame()
        hovered = _mean_rgb(bot.target.read_rgb(), box)
        # fill one box to see what "filled" looks like
        bot.app.input.mouse_move(5, 5)
        bot.app.trial_view().ranking.click(crit, 0)
        for _ in range(3):
            bot.frame()
        filled = _mean_rgb(bot.target.read_rgb(), bot.app.ui.rects[("place", crit, 0)])
    finally:
        bot.close()
        db.close()
    print("plain", plain, "hovered", hovered, "filled", filled)
    assert np.abs(hovered - plain).max() <= 16, (plain, hovered)      # a slight lift, same hue
    assert np.abs(hovered - filled).max() >= 40, (hovered, filled)    # never mistaken for a filled box
    assert hovered[2] - hovered[0] < 30                               # not the blue of a selected control


def test_computer_check_speaks_plainly_and_the_record_keeps_the_facts(tmp_path):
    design, db = _study(tmp_path)
    bot = UIBot(design, db, "P1", "ordered", 1, size=(1280, 720))
    try:
        _until(bot, "env_check")
        for _ in range(4):
            bot.frame()
        drawn = " ".join(bot.app.ui.frame_strings)
        renderer = bot.app.env_report.gl_renderer
        assert renderer and renderer not in drawn
        for jargon in ("OpenGL", "fps", "llvmpipe", "offscreen", "latency", "avatars", "Rendering"):
            assert jargon not in drawn, jargon
        assert "Graphics" in drawn and "Sound" in drawn
        _until(bot, "trials:ready")
    finally:
        bot.close()
        db.close()
    con = sqlite3.connect(tmp_path / "r.sqlite")
    try:
        cells = " ".join(str(v) for row in con.execute("SELECT * FROM sessions") for v in row)
    finally:
        con.close()
    assert renderer in cells and "fps" in cells  # the experimenter's record keeps the details


def test_hard_line_breaks_in_instructions_do_not_show(tmp_path):
    text = ("Watch each clip to the end, with the sound on. Then put the three\nfigures in order on each"
            " question. There are no right\nor wrong answers.\n\nSteps:\n- watch\n- rank")
    design, db = _study(tmp_path, instructions=text)
    bot = UIBot(design, db, "P1", "ordered", 1, size=(1280, 720))
    try:
        _until(bot, "instructions")
        strings = bot.app.ui.frame_strings
    finally:
        bot.close()
        db.close()
    assert ("Watch each clip to the end, with the sound on. Then put the three figures in order on each"
            " question. There are no right or wrong answers.") in strings
    assert "Steps:\n- watch\n- rank" in strings


@pytest.mark.parametrize("size", [(1920, 1080), (2560, 1440)])
def test_next_clip_hint_stays_on_one_line_at_full_screen(tmp_path, size):
    """A practice trial's wide "Practice clip 1 of 1" left the hint two lines, the second over a question."""
    from fixtures.synthetic import write_synthetic_study
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB
    from studyapp.ui.screens import ranking_panel

    path = write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0, practice=True)
    design = load_design(path)
    db = ResultsDB(tmp_path / "r.sqlite", design)
    bot = UIBot(design, db, "P1", "ordered", 1, size=size)
    heights = []
    orig = bot.app.ui.muted

    def muted(s, *, wrap_x=0.0, size=1.0):
        orig(s, wrap_x=wrap_x, size=size)
        if s.startswith("Drag or click"):
            from imgui_bundle import imgui
            heights.append((imgui.get_item_rect_max().y - imgui.get_item_rect_min().y, imgui.get_text_line_height()))

    bot.app.ui.muted = muted
    try:
        _until(bot, "practice:ranking")
    finally:
        bot.close()
        db.close()
    assert heights
    h, line = heights[-1]
    assert h < 1.2 * line, (h, line)  # two lines at the smallest size would be 1.4 lines
    assert ranking_panel.keys_line(("A", "B", "C")).startswith("Drag or click")
