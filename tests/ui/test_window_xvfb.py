"""The REAL participant window (GLFW + Mesa GLX) under Xvfb, driven by xdotool like a participant.

The test starts its own Xvfb display, opens the window through :class:`studyapp.ui.app.WindowRunner`,
clicks, drags and types with xdotool (X events -> GLFW callbacks -> ui/input.py -> ImGui), takes
screenshots of the X screen with ImageMagick's ``import`` and checks what they show.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import time

import numpy as np
import pytest

pytestmark = [pytest.mark.display, pytest.mark.gl]


def _need(tool: str) -> str:
    path = shutil.which(tool) or (f"/usr/bin/{tool}" if os.path.exists(f"/usr/bin/{tool}") else None)
    if path is None:
        pytest.skip(f"{tool} is not installed")
    return path


class Driver:
    """Runs frames of the window and sends X input with xdotool."""

    def __init__(self, runner, tmp_path):
        self.runner = runner
        self.app = runner.app
        self.tmp = tmp_path
        self.xdotool = _need("xdotool")
        # /usr/bin/import: the `convert`/`import` first on PATH may be a stand-in (see DOMAIN.md)
        self.imp = "/usr/bin/import" if os.path.exists("/usr/bin/import") else _need("import")
        self.wid = None
        for _ in range(50):
            self.frames(2)
            out = subprocess.run([self.xdotool, "search", "--name", "^studyapp$"], capture_output=True, text=True)
            if out.stdout.strip():
                self.wid = out.stdout.split()[0]
                break
        assert self.wid, "xdotool cannot find the window titled 'studyapp'"

    def frames(self, n: int = 3) -> None:
        for _ in range(n):
            assert self.runner.step()
            time.sleep(0.01)  # let the X server deliver queued events before the next poll

    def to_practice(self) -> None:
        """From the welcome page to the first practice clip, as a participant clicks and types through."""
        app = self.app
        self.until(lambda: "consent" in app.ui.rects)
        self.frames(2)
        self.click("consent")
        self.until(lambda: app.screen_key() == "instructions")
        self.frames(3)
        self.key("Return")
        self.until(lambda: app.screen_key() == "env_check")
        self.frames(3)
        self.click("continue")
        self.until(lambda: app.screen_key() == "practice:ready")

    def until(self, pred, limit_s: float = 30.0) -> None:
        t_end = time.monotonic() + limit_s
        while not pred():
            assert time.monotonic() < t_end, f"timed out on screen {self.app.screen_key()!r}"
            self.frames(1)

    def xdo(self, *args) -> None:
        subprocess.run([self.xdotool, *map(str, args)], check=True, timeout=10)

    def center(self, key):
        x0, y0, x1, y1 = self.app.ui.rects[key]
        return int((x0 + x1) / 2), int((y0 + y1) / 2)

    def click(self, key) -> None:
        x, y = self.center(key)
        self.xdo("mousemove", "--window", self.wid, x, y)
        self.frames(2)
        self.xdo("click", "1")
        self.frames(4)

    def drag(self, src, dst) -> None:
        (ax, ay), (bx, by) = self.center(src), self.center(dst)
        self.xdo("mousemove", "--window", self.wid, ax, ay)
        self.frames(2)
        self.xdo("mousedown", "1")
        self.frames(2)
        for f in (0.1, 0.4, 0.8, 1.0):
            self.xdo("mousemove", "--window", self.wid, int(ax + (bx - ax) * f), int(ay + (by - ay) * f))
            self.frames(2)
        self.xdo("mouseup", "1")
        self.frames(4)

    def key(self, name: str) -> None:
        self.xdo("key", "--window", self.wid, name)
        self.frames(4)

    def screenshot(self, name: str) -> np.ndarray:
        import matplotlib.image as mimage

        self.frames(2)
        path = self.tmp / f"{name}.png"
        subprocess.run([self.imp, "-window", "root", str(path)], check=True, timeout=30)
        img = mimage.imread(str(path))[..., :3]
        img = (img * 255).astype(np.uint8) if img.dtype != np.uint8 else img
        geo = subprocess.run([self.xdotool, "getwindowgeometry", self.wid], capture_output=True, text=True).stdout
        pos = geo.split("Position:")[1].split()[0].split(",")
        x, y = int(pos[0]), int(pos[1])
        w, h = self.app.fb_size
        return img[y:y + h, x:x + w]


def release_egl_context():
    """Un-bind the EGL context earlier tests left current on this thread; returns a function that
    binds it again.

    Mesa refuses glXMakeCurrent (X error BadAccess, which Xlib turns into exit(1)) while an EGL context
    is current in the same thread; a participant's process never has one, the test process does.
    """
    import ctypes

    try:
        egl = ctypes.CDLL("libEGL.so.1")
    except OSError:
        return lambda: None
    for name in ("eglGetCurrentDisplay", "eglGetCurrentContext"):
        getattr(egl, name).restype = ctypes.c_void_p
    egl.eglGetCurrentSurface.restype = ctypes.c_void_p
    egl.eglGetCurrentSurface.argtypes = [ctypes.c_int]
    egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
    dpy, ctx = egl.eglGetCurrentDisplay(), egl.eglGetCurrentContext()
    if not dpy:
        return lambda: None
    draw, read = egl.eglGetCurrentSurface(0x3059), egl.eglGetCurrentSurface(0x305A)  # EGL_DRAW, EGL_READ
    egl.eglMakeCurrent(dpy, None, None, None)
    return lambda: egl.eglMakeCurrent(dpy, draw, read, ctx)


def thirds_with_figures(img: np.ndarray, top: int, bottom: int) -> list[int]:
    """Dark (figure) pixels in each third of the rows top..bottom of a light background."""
    dark = img[top:bottom].astype(int).sum(axis=2) < 250
    w = dark.shape[1]
    return [int(dark[:, k * w // 3:(k + 1) * w // 3].sum()) for k in range(3)]


@contextlib.contextmanager
def window_driver(design, db, participant: str, tmp_path, size=(1280, 720)):
    """A real GLFW window running a fresh session, with its :class:`Driver`; skips when Xvfb offers no GLX."""
    from studyapp.audio.clock import SilentClock
    from studyapp.study.session import Session
    from studyapp.ui.app import WindowRunner

    session = Session(design, db, participant)
    restore_egl = release_egl_context()
    try:
        runner = WindowRunner(design, session, SilentClock(), size=size)
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


def test_real_window_full_ranking_with_xdotool(xvfb_display, tiny_study, tmp_path, secrets_of):
    from studyapp.ui.widgets import Painter

    design, db = tiny_study
    with window_driver(design, db, "W1", tmp_path, size=(1280, 720)) as (d, runner):
        app = d.app
        d.until(lambda: "consent" in app.ui.rects)
        d.frames(2)
        d.click("consent")                       # xdotool click -> GLFW mouse callbacks
        d.until(lambda: app.screen_key() == "instructions")
        d.frames(3)
        d.key("Return")                          # keyboard path: Enter continues
        d.until(lambda: app.screen_key() == "env_check")
        d.frames(3)
        d.click("continue")
        d.until(lambda: app.screen_key() == "practice:ready")
        d.frames(3)
        d.click("play")
        d.until(lambda: app.screen_key() == "practice:playing", 10)
        d.key("space")                           # Space pauses (so the screenshot sees the playing layout)
        assert app.screen_key() == "practice:paused", app.screen_key()
        shot = d.screenshot("trial_playing")
        h = shot.shape[0]
        counts = thirds_with_figures(shot, int(0.1 * h), int(0.85 * h))
        assert all(c > 500 for c in counts), counts
        d.key("space")                           # ... and resumes
        d.until(lambda: app.screen_key() == "practice:ranking", 30)
        d.frames(3)
        shot = d.screenshot("trial_ranking")
        assert np.median(shot[int(0.6 * h):].astype(int).sum(axis=2)) < 200  # the dark ranking panel
        assert all(c > 100 for c in thirds_with_figures(shot, int(0.08 * h), int(0.45 * h)))
        crits = [c.id for c in design.criteria]
        # 1st question by dragging: right figure best, then left, then middle
        for place, slot in enumerate((2, 0, 1)):
            d.drag(("chip", crits[0], slot), ("place", crits[0], place))
        # 2nd by clicking in order best -> worst
        for slot in (1, 2, 0):
            d.click(("chip", crits[1], slot))
        # 3rd with the keyboard: choose the question, then 3, 1, 2
        d.click(("crit", crits[2]))
        for k in ("3", "1", "2"):
            d.key(k)
        d.frames(3)
        assert app.screen_key() == "practice:ranked", app.screen_key()
        shot = d.screenshot("trial_ranked")
        d.click("next")
        d.until(lambda: db.trials("W1"), 10)
        ranks = {(r["criterion"], r["slot"]): r["rank"] for r in db.responses("W1")}
        assert [ranks[(crits[0], s)] for s in range(3)] == [2, 3, 1]
        assert [ranks[(crits[1], s)] for s in range(3)] == [3, 1, 2]
        assert [ranks[(crits[2], s)] for s in range(3)] == [2, 3, 1]
        trial = db.trials("W1")[0]
        assert trial["frames_shown"] > 0 and trial["worst_av_offset_ms"] is not None
        p = Painter()
        for s in app.ui.drawn:
            p.record(s)
        assert p.leaks(secrets_of(design)) == []


def test_real_window_ties_with_mouse_and_equals_key(xvfb_display, tied_study, tmp_path):
    """With ties allowed: a click on the ">" between two boxes and the "=" key (X key event -> GLFW char
    callback) enter ties, and the session stores them as average ranks."""
    design, db = tied_study
    with window_driver(design, db, "W2", tmp_path, size=(1280, 720)) as (d, runner):
        app = d.app
        d.to_practice()
        d.frames(3)
        d.click("play")
        d.until(lambda: app.screen_key() == "practice:ranking", 30)
        d.frames(3)
        crits = [c.id for c in design.criteria]
        for slot in (0, 1, 2):                   # 1st question: left, middle, right...
            d.click(("chip", crits[0], slot))
        d.click(("tie", crits[0], 1))            # ... with middle = right
        d.click(("crit", crits[1]))              # 2nd: middle = right, then left
        for k in ("2", "equal", "3", "1"):
            d.key(k)
        for k in ("1", "2", "3"):                # 3rd: no tie
            d.key(k)
        d.frames(3)
        assert app.screen_key() == "practice:ranked", app.screen_key()
        assert app.trial_view().ranking.ties == {crits[0]: [False, True], crits[1]: [True, False],
                                                 crits[2]: [False, False]}
        d.click("next")
        d.until(lambda: db.trials("W2"), 10)
        ranks = {(r["criterion"], r["slot"]): r["rank"] for r in db.responses("W2")}
        assert [ranks[(crits[0], s)] for s in range(3)] == [1.0, 2.5, 2.5]
        assert [ranks[(crits[1], s)] for s in range(3)] == [3.0, 1.5, 1.5]
        assert [ranks[(crits[2], s)] for s in range(3)] == [1.0, 2.0, 3.0]


def test_f11_switches_fullscreen_and_back(xvfb_display, tiny_study, tmp_path):
    """F11 (an X key event) makes the window fill the 1280x800 screen, the UI lays itself out for the new
    framebuffer, and a second F11 restores the window's own size."""
    design, db = tiny_study
    with window_driver(design, db, "W3", tmp_path, size=(960, 540)) as (d, runner):
        app = d.app
        d.until(lambda: "consent" in app.ui.rects)
        assert app.fb_size == (960, 540) and not runner.window.is_fullscreen
        d.key("F11")
        d.until(lambda: app.fb_size == (1280, 800), 10)
        assert runner.window.is_fullscreen
        d.frames(3)
        x0, y0, x1, y1 = app.ui.rects["consent"]
        assert y1 <= 800 and y0 > 540  # the footer button moved down to the bottom of the larger window
        assert app.screen_key() == "welcome"  # F11 is not Enter: still on the consent page
        d.key("F11")
        d.until(lambda: app.fb_size == (960, 540), 10)
        assert not runner.window.is_fullscreen


def test_participant_window_asks_to_open_maximized(xvfb_display, tiny_study, monkeypatch):
    """run_window opens the participant's window with GLFW's MAXIMIZED hint (Xvfb has no window manager
    to act on it, so the test checks the request; F11 full screen is tested above)."""
    import glfw

    from studyapp.render.context import Window
    from studyapp.ui import app as app_mod

    from studyapp.render.context import ContextError

    hints = []
    real_hint = glfw.window_hint
    monkeypatch.setattr(glfw, "window_hint", lambda h, v: (hints.append((h, v)), real_hint(h, v))[1])
    # no window is made (a second GL window in one process upsets GLX): the hints given are what counts
    monkeypatch.setattr(glfw, "create_window", lambda *a: None)
    for maximized in (True, False):
        hints.clear()
        with pytest.raises(ContextError):
            Window((320, 200), visible=False, maximized=maximized)
        assert (glfw.MAXIMIZED, glfw.TRUE if maximized else glfw.FALSE) in hints

    made = {}

    class Runner:  # stands in for the window: records how run_window asks for it
        def __init__(self, *args, **kwargs):
            made.update(kwargs)

        def run(self):
            pass

        def close(self):
            pass

    monkeypatch.setattr(app_mod, "WindowRunner", Runner)
    design, db = tiny_study
    assert app_mod.run_window(design, db, "M1") == 1  # closed before the end
    assert made.get("maximized") is True


@pytest.mark.audio
def test_window_takes_the_audio_output_started_before_it_without_waiting_for_it(xvfb_display, tiny_study, capsys):
    """`studyapp run` starts the output before the design loads; the window opens and draws meanwhile, then
    plays on that very output (its process), and the process ends with the session."""
    import multiprocessing

    from studyapp.audio.playback import AudioPlayer, PendingClock
    from studyapp.study.session import Session
    from studyapp.ui.app import WindowRunner

    if not os.environ.get("PULSE_SERVER"):
        pytest.skip("no sound server (.ci/test starts a null sink): no output to open")
    design, db = tiny_study
    pending = PendingClock(None)
    child = pending.player._proc
    session = Session(design, db, "A1")
    restore_egl = release_egl_context()
    try:
        try:
            runner = WindowRunner(design, session, pending, size=(640, 360))
        except Exception as exc:
            pytest.skip(f"no GLX window under Xvfb: {exc}")
        try:
            deadline = time.monotonic() + 20
            while runner.app._pending_audio is not None and time.monotonic() < deadline:
                runner.step()                  # taken after the first flip that finds it open
            clock = runner.app.clock
            assert isinstance(clock, AudioPlayer) and clock is pending.player and clock._proc is child
            assert child.is_alive() and clock.wait_until_flowing(6.0)  # open, the device takes its samples
            assert f"audio output: {clock.device_name} " in capsys.readouterr().out
        finally:
            runner.close()
    finally:
        pending.close()
        session.close()
        restore_egl()
    assert not child.is_alive() and multiprocessing.active_children() == []
