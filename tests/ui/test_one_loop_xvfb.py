"""The participant window (GLFW under Xvfb, driven with xdotool) and the offscreen path (the scripted
participant on EGL) play the same trial through the same frame loop: same duration, same frames, and
the same figure in each slot at the same media time.

Both run on a virtual media clock that the loop moves by 1/30 s per frame, so the two paths can be
compared frame for frame (on a wall or audio clock the frames shown depend on the machine's speed).
"""
from __future__ import annotations

import contextlib

import numpy as np
import pytest

from test_window_xvfb import Driver, release_egl_context, thirds_with_figures

pytestmark = [pytest.mark.display, pytest.mark.gl]

FPS = 30.0
SIZE = (960, 540)
#: Media times (in frames of 1/FPS) whose pictures are compared between the two paths.
PICKED = (15, 45, 75)


@contextlib.contextmanager
def virtual_window(design, db, participant, tmp_path):
    """The participant's window on a virtual clock stepped 1/FPS per frame by the loop's timer."""
    from studyapp.audio.clock import SilentClock
    from studyapp.render.loop import VirtualTimer
    from studyapp.study.session import Session
    from studyapp.ui.app import WindowRunner

    session = Session(design, db, participant)
    clock = SilentClock(virtual=True, reason="test")
    restore_egl = release_egl_context()
    try:
        runner = WindowRunner(design, session, clock, size=SIZE, timer=VirtualTimer(FPS, clocks=[clock]))
    except Exception as exc:
        restore_egl()
        session.close()
        pytest.skip(f"no GLX window under Xvfb: {exc}")
    try:
        yield Driver(runner, tmp_path), runner
    finally:
        runner.close()
        session.close()
        restore_egl()


def _scene_rect(app):
    from studyapp.ui.screens.trial import layout

    x, y, w, h = (int(round(v)) for v in layout(app, app._view)["scene"])
    return x, y, w, h


class PlayWatcher:
    """After each frame: keeps the picture of the picked frames of the current play."""

    def __init__(self, app, loop):
        self.app, self.loop = app, loop
        self.shots: dict[int, np.ndarray] = {}
        self.rect = None

    def __call__(self):
        view = self.app._view
        rec = None if view is None else view.recorder
        if rec is None or not view.in_play or not rec.drawn_s:
            return
        k = int(round(rec.drawn_s[-1] * FPS))  # the frame just shown showed media time k / FPS
        if k in PICKED and k not in self.shots:
            self.rect = _scene_rect(self.app)
            x, y, w, h = self.rect
            self.shots[k] = self.loop.last_rgb[y:y + h, x:x + w].copy()


def _play_in_window(design, db, tmp_path):
    with virtual_window(design, db, "C1", tmp_path) as (d, runner):
        app = d.app
        runner.capture = True
        watch = PlayWatcher(app, runner.loop)
        d.to_practice()
        d.frames(3)
        d.click("play")                             # an X click starts the play
        def step():
            d.frames(1)
            watch()
        watch()
        while app._view.in_play:
            step()
        view = app._view
        return {"plan": view.plan, "duration": view.duration_s, "scene_duration": view.scene.duration,
                "drawn": list(view.recorder.drawn_s), "stats": view.recorder.stats(), "shots": watch.shots,
                "rect": watch.rect}


def _play_offscreen(design, db):
    from studyapp.bots.ui_driver import UIBot

    bot = UIBot(design, db, "C1", "ordered", 1, size=SIZE, fps=FPS, frames_per_play=None)
    try:
        bot.loop.capture = True
        watch = PlayWatcher(bot.app, bot.loop)
        for _ in range(2000):
            bot.step()
            watch()
            view = bot.app._view
            if view is not None and view.watched:
                break
        view = bot.app._view
        assert view is not None and view.watched, bot.app.screen_key()
        return {"plan": view.plan, "duration": view.duration_s, "scene_duration": view.scene.duration,
                "drawn": list(view.recorder.drawn_s), "stats": view.recorder.stats(), "shots": watch.shots,
                "rect": watch.rect}
    finally:
        bot.close()


def test_window_and_offscreen_play_the_same_trial(xvfb_display, tiny_study, tmp_path):
    from studyapp.study.storage import ResultsDB

    design, db = tiny_study
    win = _play_in_window(design, db, tmp_path)
    db2 = ResultsDB(tmp_path / "offscreen.sqlite", design)
    try:
        off = _play_offscreen(design, db2)
    finally:
        db2.close()

    # the same trial: practice clip, same models in the same slots
    assert win["plan"] == off["plan"] and win["plan"].is_practice
    # the same duration, taken from the trial's scene, and both played it to its end
    assert win["duration"] == off["duration"] == win["scene_duration"] == pytest.approx(3.0, abs=0.05)
    for played in (win, off):
        # the Play click is seen while the frame is built, after its media time was taken: the first
        # frame counted shows the clip's second frame, in both paths
        assert played["drawn"][0] == pytest.approx(1.0 / FPS)
        assert played["drawn"][-1] == pytest.approx(played["duration"], abs=1.0 / FPS + 1e-9)
        assert np.all(np.diff(played["drawn"]) == pytest.approx(1.0 / FPS))   # every frame, none skipped
    # the same frames shown, as stored with the trial: one per 1/30 s of the clip
    assert win["stats"]["frames_shown"] == off["stats"]["frames_shown"] == len(win["drawn"])
    assert abs(win["stats"]["frames_shown"] - win["duration"] * FPS) <= 1
    assert win["stats"]["dropped_frames"] == off["stats"]["dropped_frames"] == 0
    assert np.allclose(win["drawn"], off["drawn"], atol=1e-9)

    # the same figure in each slot at the same media time, pixel for pixel within a tolerance
    assert win["rect"] == off["rect"]
    assert sorted(win["shots"]) == sorted(off["shots"]) == sorted(PICKED)
    for k in PICKED:
        a, b = win["shots"][k].astype(int), off["shots"][k].astype(int)
        assert all(c > 500 for c in thirds_with_figures(win["shots"][k], 0, a.shape[0])), k  # a figure each
        for third in range(3):
            sl = slice(third * a.shape[1] // 3, (third + 1) * a.shape[1] // 3)
            diff = np.abs(a[:, sl] - b[:, sl]).sum(-1)
            assert diff.mean() < 3.0 and (diff > 60).mean() < 0.005, (k, third, diff.mean(), (diff > 60).mean())
    # ... and the comparison does tell frames apart: other media times differ in the moving slots
    a, b = win["shots"][PICKED[0]].astype(int), off["shots"][PICKED[1]].astype(int)
    assert (np.abs(a - b).sum(-1) > 60).mean() > 0.005
