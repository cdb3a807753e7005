"""Environment check: graphics, display, audio output (+ a sound check) before the first clip.

Runs :func:`studyapp.ui.envcheck.gather` -- the same measurement as ``studyapp doctor`` -- with the
app's own GL context and audio clock, shows the results in plain words (:func:`~studyapp.ui.envcheck.plain`:
no renderer names or frame rates), and stores the full measurement with the session.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.ui.envcheck import evaluate, plain, plain_verdict
from studyapp.ui.screens.common import page_begin, page_end, primary_row

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp

_STATUS_COLOR = {"pass": (0.45, 0.85, 0.55, 1.0), "warn": (1.0, 0.80, 0.35, 1.0), "fail": (1.0, 0.45, 0.42, 1.0)}
_STATUS_WORD = {"pass": "OK", "warn": "Check", "fail": "Problem"}


def draw(app: ScreenApp) -> None:
    ui = app.ui
    page_begin(app, "env_check")
    ui.heading("Checking your computer", 2.0)
    ui.text("")
    report = app.env_report
    if report is None:
        ui.wrapped("Measuring graphics speed and audio output; this takes a moment...")
        app.request_env_check()
        page_end()
        return
    checks = evaluate(report)
    ok = not any(c.status == "fail" for c in checks)
    summary = plain_verdict(checks)
    s = app.scale
    if imgui.begin_table("##checks", 3, imgui.TableFlags_.row_bg | imgui.TableFlags_.borders_inner_h):
        imgui.table_setup_column("what", imgui.TableColumnFlags_.width_fixed, 140 * s)
        imgui.table_setup_column("status", imgui.TableColumnFlags_.width_fixed, 100 * s)
        imgui.table_setup_column("detail", imgui.TableColumnFlags_.width_stretch)
        for c in checks:
            imgui.table_next_row()
            imgui.table_next_column()
            name, sentence = plain(c)
            ui.text(name)
            imgui.table_next_column()
            ui.text(_STATUS_WORD[c.status], color=_STATUS_COLOR[c.status])
            imgui.table_next_column()
            ui.wrapped(sentence)
        imgui.end_table()
    imgui.spacing()
    ui.wrapped(summary)
    imgui.spacing()
    ui.heading("Sound check", 1.3)
    ui.wrapped("Put on your headphones and press the button: you should hear a short beep. Adjust the volume "
               "so it is comfortable. The clips use the same output.")
    # T: the keyboard-only way to the sound check (the page has no other use for letters)
    if ui.button("Play test sound (T)", key="test_sound", size=(240 * s, 0)) or app.key_pressed(imgui.Key.t):
        app.play_test_sound()
    if app.test_sound_played:
        imgui.same_line()
        ui.muted("Played. If you heard nothing, check the volume or tell the experimenter.")
    label = "Continue" if ok else "Continue anyway"
    if not ok:
        ui.text("")
        ui.wrapped("Please tell the experimenter before you continue.")
    if primary_row(app, label, "continue", hint="or press Enter"):
        app.session.record_env_check(app.env_info())
    page_end()
