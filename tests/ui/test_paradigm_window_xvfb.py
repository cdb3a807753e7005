"""The pairwise, mismatch and rating screens in the REAL participant window (GLFW under Xvfb), driven by xdotool.

The participant plays the same script as the offscreen test (fixtures.paradigm_studies.SCRIPT: keys, clicks
and a click on a slider at a value's point) and the database must store exactly what the offscreen path
stores for it (SCRIPT_STORED). Screenshots of each paradigm's screen at 1280x720 are checked for the chosen
answer (green box, a slider's handle) in the X server's own pixels.
"""
from __future__ import annotations

import numpy as np
import pytest

from fixtures.paradigm_studies import SCRIPT, SCRIPT_STORED, paradigm_study  # noqa: F401
from test_paradigm_screens import stored
from test_window_xvfb import window_driver

pytestmark = [pytest.mark.display, pytest.mark.gl]


def test_real_window_answers_each_paradigm_with_keyboard_and_mouse(xvfb_display, paradigm_study, tmp_path):
    from studyapp.ui.screens.ranking_panel import FILLED_COLOR
    from studyapp.ui.screens.rating_panel import GRAB_COLOR

    design, db = paradigm_study
    with window_driver(design, db, "W1", tmp_path, size=(1280, 720)) as (d, runner):
        app = d.app
        d.until(lambda: "consent" in app.ui.rects)
        d.frames(2)
        d.click("consent")
        d.until(lambda: app.screen_key() == "instructions")
        d.frames(3)
        d.key("Return")
        d.until(lambda: app.screen_key() == "env_check")
        d.frames(3)
        d.click("continue")
        missing = []
        shots = {}
        for trial, parts in SCRIPT.items():
            if "block" in parts:
                d.until(lambda: app.screen_key() == "trials:block")
                d.frames(3)
                shots[f"block{trial}"] = d.screenshot(f"block{trial}")
                run(d, parts["block"], missing)
            d.until(lambda: app.screen_key() == "trials:ready")
            d.frames(3)
            d.click("play")
            d.until(lambda: app.screen_key() == "trials:answering", 30)
            d.frames(3)
            actions = parts["answer"]
            run(d, actions[:-1], missing)
            d.frames(3)
            shots[trial] = (d.screenshot(f"{app.session.current_trial().paradigm}{trial}"), dict(app.ui.rects))
            run(d, actions[-1:], missing)
            d.until(lambda t=trial: t in {r["trial_index"] for r in db.trials("W1")}, 10)
        d.until(lambda: app.session.finished or app.screen_key() == "questionnaire", 10)
    assert stored(db, "W1") == SCRIPT_STORED          # what the offscreen path stores for the same input
    assert missing == [([("diversity", 2)], [("diversity", 2)], False)]
    green = np.array(FILLED_COLOR[:3]) * 255
    rgb, rects = shots[0]                              # pairwise after key 4: "Slightly B" chosen
    x0, y0, x1, y1 = rects[("option", "realism", 1)]
    assert np.abs(rgb[int(y1) - 6, int(x0) + 8].astype(int) - green).max() <= 3
    x0, y0, x1, y1 = rects[("option", "realism", -2)]
    assert np.abs(rgb[int(y1) - 6, int(x0) + 8].astype(int) - green).max() > 40
    rgb, rects = shots[3]                              # rating: every slider set, each shows its handle
    for key in (("slider", c, s) for c in ("realism", "diversity") for s in range(3)):
        x0, y0, x1, y1 = (int(v) for v in rects[key])
        handle = np.abs(rgb[y0:y1, x0:x1].astype(int) - np.array(GRAB_COLOR[:3]) * 255).max(axis=2) < 30
        assert handle.sum() > 50, key


def run(d, actions, missing) -> None:
    """Play script actions in the window: X key events, clicks, a click at a slider value's point."""
    from studyapp.bots.ui_driver import slider_point

    for action in actions:
        if action[0] == "key":
            d.key(action[1])
        elif action[0] == "click":
            d.click(action[1])
        elif action[0] == "slider":
            x, y = slider_point(d.app.ui.rects[action[1]], action[2])
            d.xdo("mousemove", "--window", d.wid, int(round(x)), int(round(y)))
            d.frames(2)
            d.xdo("click", "1")
            d.frames(4)
        else:
            view = d.app.trial_view()
            missing.append((action[1], view.answer.missing(), view.can_submit()))
