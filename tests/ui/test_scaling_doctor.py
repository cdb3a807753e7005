"""UI scaling with the framebuffer (720p vs 4K) and the `studyapp doctor` command."""
import json
import subprocess
import sys

import numpy as np
import pytest


@pytest.mark.gl
def test_welcome_screen_scales_from_720p_to_4k(gl_ctx, tiny_study):
    from studyapp.audio.clock import SilentClock
    from studyapp.render.context import OffscreenTarget
    from studyapp.study.session import Session
    from studyapp.ui.app import StudyApp

    design, db = tiny_study
    session = Session(design, db, "S1")
    app = StudyApp(design, session, gl_ctx, SilentClock(virtual=True), bench_frames=0)
    rects, images = {}, {}
    try:
        for size in ((1280, 720), (3840, 2160)):
            target = OffscreenTarget(gl_ctx, size)
            for k in range(3):  # a new ImGui window is hidden on its first frame
                app.frame(target.fbo, size, k / 60.0)
            rects[size] = app.ui.rects["consent"]
            images[size] = target.read_rgb()
            target.release()
    finally:
        app.shutdown()
        session.close()
    small, big = rects[(1280, 720)], rects[(3840, 2160)]
    assert (big[2] - big[0]) / (small[2] - small[0]) == pytest.approx(3.0, rel=0.02)
    assert (big[3] - big[1]) / (small[3] - small[1]) == pytest.approx(3.0, rel=0.02)
    # the same layout, three times larger: text pixels cover the same share of the screen
    share = [np.mean(images[s].sum(axis=2) > 400) for s in images]
    assert share[0] > 0.005 and share[1] == pytest.approx(share[0], rel=0.35)
    assert session.state.value == "welcome"  # drawing alone never advances the study


def test_doctor_json_reports_and_decides(tmp_path):
    out = subprocess.run([sys.executable, "-m", "studyapp.cli", "doctor", "--json", "--frames", "3"],
                         capture_output=True, text=True, timeout=240)
    report = json.loads(out.stdout)
    for key in ("gl_renderer", "gl_version", "display", "audio_devices", "audio_latency_ms", "render_fps",
                "checks", "ok", "verdict"):
        assert key in report
    names = [c["name"] for c in report["checks"]]
    assert names == ["OpenGL", "Display", "Audio", "Rendering"]
    assert out.returncode == (0 if report["ok"] else 1)
    if report["gl_renderer"]:
        assert report["render_fps"] is None or report["render_fps"] > 0
    if not report["audio_device"]:
        assert any(c["name"] == "Audio" and c["status"] == "fail" for c in report["checks"])
        assert "cannot run" in report["verdict"]


def test_doctor_text_output():
    out = subprocess.run([sys.executable, "-m", "studyapp.cli", "doctor", "--frames", "0"],
                         capture_output=True, text=True, timeout=240)
    assert "studyapp doctor" in out.stdout and "OpenGL" in out.stdout and "Audio outputs" in out.stdout
    assert out.stdout.strip().splitlines()[-1].startswith("This computer")
