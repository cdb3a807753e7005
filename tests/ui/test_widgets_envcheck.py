"""Text recording, leak detection, UI scaling and the environment verdict (no GL needed)."""
import pytest

from studyapp.ui.envcheck import EnvReport, evaluate, verdict
from studyapp.ui.layer import ui_scale
from studyapp.ui.widgets import Painter, visible_label


def test_visible_label_strips_imgui_ids():
    assert visible_label("Next##trial") == "Next"
    assert visible_label("###hidden") == ""
    assert visible_label("Play") == "Play"


def test_leaks_match_whole_words_case_insensitively():
    p = Painter()
    for s in ("A figure moved", "The CaMN result", "clip synced?"):
        p.record(s)
    leaks = p.leaks(["camn", "a", "sync", "diffsheg"])
    assert ("camn", "The CaMN result") in leaks
    assert ("a", "A figure moved") in leaks      # a one-letter id does match a standalone "A"
    assert not any(sec == "sync" for sec, _ in leaks)  # "synced" is not the id "sync"
    assert not any(sec == "diffsheg" for sec, _ in leaks)


@pytest.mark.parametrize("size,content,expected", [
    ((1280, 720), 1.0, 1.0), ((3840, 2160), 1.0, 3.0), ((1920, 1080), 1.0, 1.5),
    ((1280, 720), 2.0, 2.0), ((2560, 720), 1.0, 1.0),
])
def test_ui_scale(size, content, expected):
    assert ui_scale(size, content) == pytest.approx(expected)


def test_ui_scale_narrow_window_limited_by_width():
    # a portrait-ish window must not get text scaled by its height alone
    assert ui_scale((1280, 1440)) < 1440 / 720


def _report(**kw):
    base = dict(gl_renderer="x", gl_version_code=450, display=":0", display_size=(1920, 1080), refresh_hz=60.0,
                audio_device="Speakers", audio_latency_ms=30.0, render_fps=55.0)
    base.update(kw)
    return EnvReport(**base)


def test_verdict_passes_on_a_good_machine():
    checks = evaluate(_report())
    assert {c.status for c in checks} == {"pass"}
    assert verdict(checks) == (True, "This computer can run the study.")


@pytest.mark.parametrize("kw,name,status", [
    (dict(gl_version_code=300), "OpenGL", "fail"),
    (dict(gl_version_code=None), "OpenGL", "fail"),
    (dict(audio_device=None), "Audio", "fail"),
    (dict(audio_latency_ms=400.0), "Audio", "warn"),
    (dict(render_fps=10.0), "Rendering", "fail"),
    (dict(refresh_hz=30.0), "Display", "warn"),
    (dict(display=None, refresh_hz=None), "Display", "warn"),
])
def test_each_problem_is_named(kw, name, status):
    checks = {c.name: c for c in evaluate(_report(**kw))}
    assert checks[name].status == status
    ok, summary = verdict(list(checks.values()))
    assert ok == (status != "fail")
    if status == "fail":
        assert name in summary


def test_zero_hz_refresh_reads_as_unknown_not_choppy():
    """GLFW reports 0 Hz where the display does not say (Xvfb, some VMs): that is "unknown", not a
    0 Hz display that would make motion choppy."""
    checks = {c.name: c for c in evaluate(_report(refresh_hz=0.0))}
    assert checks["Display"].status == "warn"
    assert checks["Display"].detail == "refresh rate unknown"
    assert "0 Hz" not in checks["Display"].detail


def test_display_facts_turns_zero_hz_into_none(monkeypatch):
    import types

    import glfw

    from studyapp.ui.envcheck import display_facts

    mode = types.SimpleNamespace(size=types.SimpleNamespace(width=1280, height=720), refresh_rate=0)
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr(glfw, "init", lambda: True)
    monkeypatch.setattr(glfw, "get_primary_monitor", lambda: object())
    monkeypatch.setattr(glfw, "get_video_mode", lambda mon: mode)
    monkeypatch.setattr(glfw, "get_monitor_content_scale", lambda mon: (1.0, 1.0))
    assert display_facts() == (":99", (1280, 720), None, 1.0)
