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


def draw(app: ScreenApp) -> None:
    ui = app.ui
    t = app.design.text
    texts = app.design.texts
    page_begin(app, "env_check")
    ui.heading(t("env.title"), 2.0)
    ui.text("")
    report = app.env_report
    if report is None:
        ui.wrapped(t("env.measuring"))
        app.request_env_check()
        page_end()
        return
    checks = evaluate(report)
    ok = not any(c.status == "fail" for c in checks)
    summary = plain_verdict(checks, texts)
    s = app.scale
    if imgui.begin_table("##checks", 3, imgui.TableFlags_.row_bg | imgui.TableFlags_.borders_inner_h):
        imgui.table_setup_column("what", imgui.TableColumnFlags_.width_fixed, 140 * s)
        imgui.table_setup_column("status", imgui.TableColumnFlags_.width_fixed, 100 * s)
        imgui.table_setup_column("detail", imgui.TableColumnFlags_.width_stretch)
        for c in checks:
            imgui.table_next_row()
            imgui.table_next_column()
            name, sentence = plain(c, texts)
            ui.text(name)
            imgui.table_next_column()
            ui.text(t(f"env.{c.status}"), color=_STATUS_COLOR[c.status])
            imgui.table_next_column()
            ui.wrapped(sentence)
        imgui.end_table()
    imgui.spacing()
    ui.wrapped(summary)
    imgui.spacing()
    ui.heading(t("env.sound_title"), 1.3)
    ui.wrapped(t("env.sound_text"))
    # T: the keyboard-only way to the sound check (the page has no other use for letters)
    if ui.button(t("env.sound_button"), key="test_sound", size=(240 * s, 0)) or app.key_pressed(imgui.Key.t):
        app.play_test_sound()
    if app.test_sound_played:
        imgui.same_line()
        ui.muted(t("env.sound_played"))
    label = t("page.continue" if ok else "env.continue_anyway")
    if not ok:
        ui.text("")
        ui.wrapped(t("env.tell"))
    if primary_row(app, label, "continue", hint=t("page.press_enter")):
        app.session.record_env_check(app.env_info())
    page_end()
