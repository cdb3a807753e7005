"""The window path under Xvfb: the same renderer draws into a GLFW window, and `studyapp view` runs."""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from render_helpers import SAMPLES

pytestmark = [pytest.mark.gl, pytest.mark.display]


def screenshot(display: str, window: str = "root") -> np.ndarray:
    """A window (or the whole X screen) as (H, W, 3) uint8, via ImageMagick's import (PPM: trivial to parse)."""
    raw = subprocess.run(["/usr/bin/import", "-display", display, "-window", window, "ppm:-"],
                         capture_output=True, check=True, timeout=30).stdout
    parts = raw.split(maxsplit=4)
    w, h = int(parts[1]), int(parts[2])
    return np.frombuffer(parts[4][-w * h * 3:], np.uint8).reshape(h, w, 3)


WINDOW_SCRIPT = """
import json, sys, time
import glfw
import numpy as np
sys.path.insert(0, sys.argv[2])
from render_helpers import RELAXED, posed
from studyapp.render.avatar import build_default_avatar
from studyapp.render.context import Window
from studyapp.render.pose import prepare_slot
from studyapp.render.renderer import Renderer
from studyapp.render.scene import make_scene

avatar = build_default_avatar()
win = Window((480, 270), vsync=False)
sizes = []
win.on_framebuffer_size(lambda w, h: sizes.append((w, h)))
renderer = Renderer(win.ctx)
slot = prepare_slot(avatar, posed(avatar, RELAXED, 2), None)
scene = make_scene([slot] * 3, avatar, labels=("A", "B", "C"))
win.use()
renderer.draw_trial(scene, 0.0, win.fbo)
np.save(sys.argv[1], win.read_rgb())
info = {"fb": win.framebuffer_size, "title": glfw.get_window_title(win.handle)}
win.swap_buffers()
glfw.set_window_size(win.handle, 400, 300)
for _ in range(100):
    win.poll_events()
    if sizes:
        break
    time.sleep(0.02)
info["resized"] = sizes[-1] if sizes else None
info["fb_after"] = win.framebuffer_size
renderer.release()
win.close()
print(json.dumps(info))
"""


def test_window_draws_the_trial(xvfb_display, tmp_path):
    # A separate process: GLX (the window) and EGL (the other tests' headless context) in one process
    # is not something every Mesa build survives.
    out = tmp_path / "window.npy"
    run = subprocess.run([sys.executable, "-c", WINDOW_SCRIPT, str(out), str(Path(__file__).parent)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    info = json.loads(run.stdout.strip().splitlines()[-1])
    assert info["fb"] == [480, 270] and info["title"] == "studyapp"
    assert info["resized"] == [400, 300] == info["fb_after"]
    img = np.load(out)
    background = img[5, 5].astype(int)
    fig = np.abs(img.astype(int) - background).sum(-1) > 60
    for x0 in (0, 160, 320):
        assert fig[:, x0 + 40: x0 + 120].sum() > 200  # a figure in each third


@pytest.mark.slow
def test_view_command_opens_a_window_and_closes_on_escape(xvfb_display):
    proc = subprocess.Popen(
        [sys.executable, "-m", "studyapp.cli", "view", str(SAMPLES / "beat75_diffsheg_output_excerpt.bvh"),
         "--fps", "15", "--face", str(SAMPLES / "livelinkface_S07-001_excerpt.csv"), "--size", "320x240"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        win_id = ""
        deadline = time.time() + 60
        while not win_id and time.time() < deadline and proc.poll() is None:
            time.sleep(0.3)
            # this process's window: a window of an earlier test on the same display may still be listed
            win_id = subprocess.run(["xdotool", "search", "--pid", str(proc.pid), "--name", "^studyapp$"],
                                    capture_output=True, text=True).stdout.split()
            win_id = win_id[0] if win_id else ""
        assert win_id, f"no window appeared: {proc.stderr.read() if proc.poll() is not None else ''}"
        # the window opens before the motion is loaded: wait for the first drawn frame
        spread = 0
        while spread <= 100 and time.time() < deadline + 30:
            shot = screenshot(xvfb_display, win_id)
            assert shot.shape[:2] == (240, 320)
            spread = np.ptp(shot.astype(int).sum(-1))
            time.sleep(0.3)
        assert spread > 100  # a figure on the backdrop, not a flat colour
        assert proc.poll() is None, f"view closed by itself ({proc.returncode}): {proc.stderr.read()[-2000:]}"
        # Escape to whatever window the process shows now (found again: the id read before can be stale on a
        # loaded X server), until it closes
        for _ in range(40):
            ids = subprocess.run(["xdotool", "search", "--pid", str(proc.pid), "--name", "^studyapp$"],
                                 capture_output=True, text=True).stdout.split()
            for w in ids:
                subprocess.run(["xdotool", "key", "--window", w, "Escape"], capture_output=True)
            try:
                proc.wait(0.5)
                break
            except subprocess.TimeoutExpired:
                continue
        assert proc.wait(20) == 0, proc.stderr.read()[-2000:]
    finally:
        if proc.poll() is None:
            proc.kill()
