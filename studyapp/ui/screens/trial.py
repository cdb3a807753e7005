"""A trial: the figures play with the sound; Play / Pause / Replay; the answer panel below.

Layout (framebuffer pixels, top to bottom): the 3D view (the renderer draws the trial's avatars there, two
to four side by side) and the control panel: one row with where the participant is ("Clip 3 of 8", amber for
practice clips) and the transport, then the answers once the clip has been watched: the panel of the
trial's paradigm (:data:`PANELS`: ranking, preference or rating sliders).

Before the first trial of a block that has its own instructions (``Session.block_instructions()``), that
page is shown instead (:mod:`studyapp.ui.screens.block_intro`), once. Nothing sits above the figures, so they
keep as much of the window's height as the panel leaves (the camera frames them for the view's shape).
Attention-check trials look exactly like the others.
"""
from __future__ import annotations

from types import ModuleType
from typing import TYPE_CHECKING

from imgui_bundle import imgui

from studyapp.study.design.texts import EN as EN_TEXTS
from studyapp.ui.screens import block_intro, preference_panel, ranking_panel, rating_panel
from studyapp.ui.screens.common import PAGE_FLAGS

if TYPE_CHECKING:
    from studyapp.ui.seams import ScreenApp
    from studyapp.ui.trial import TrialView

CONTROLS_PX = 68.0
PRACTICE_COLOR = (1.0, 0.80, 0.35, 1.0)
PRACTICE_NOTE = EN_TEXTS["trial.practice_note"]  # English; participants read design.text(...)
#: The answer panel of each paradigm: ``height(app, view)``, ``draw(app, view)``, ``next_button(app, view)``.
PANELS = {"rank": ranking_panel, "pairwise": preference_panel, "mismatch": preference_panel,
          "rating": rating_panel}


def panel_of(view: TrialView) -> ModuleType:
    """The answer panel of the trial's paradigm (a module of :data:`PANELS`)."""
    return PANELS.get(view.paradigm, ranking_panel)


def _fmt(t: float) -> str:
    t = max(0.0, t)
    return f"{int(t // 60)}:{int(t % 60):02d}"


def layout(app: ScreenApp, view: TrialView) -> dict[str, tuple[float, float, float, float]]:
    """Pixel rectangles (x, y, w, h; y down) of the 3D view and the panel below it."""
    w, h = app.fb_size
    s = app.scale
    panel = CONTROLS_PX * s
    if view.ranking_open():
        panel += panel_of(view).height(app, view)
    panel = min(panel, 0.62 * h)
    return {"scene": (0, 0, w, h - panel), "panel": (0, h - panel, w, panel)}


def draw(app: ScreenApp) -> None:
    if block_intro.pending(app):
        block_intro.draw(app)
        return
    s = app.scale
    view = app.trial_view()
    if view is None or not view.loaded:
        _loading(app)
        return
    view.update()
    _keys(app, view)
    rects = layout(app, view)

    # -- the 3D view: drawn by the renderer before the UI ------------------------------------------
    t = view.media_time(app.now)
    # Only frames drawn while the sound runs count for sync (before the device starts, both show 0).
    view.drawn_media_s = t if view.in_play and view.clock.started else None
    app.request_scene(view.scene, t, rects["scene"])

    # -- panel: transport + ranking -------------------------------------------------------------
    x, y, w, h = rects["panel"]
    imgui.set_next_window_pos((x, y))
    imgui.set_next_window_size((w, h))
    imgui.push_style_var(imgui.StyleVar_.window_padding, imgui.ImVec2(20 * s, 10 * s))
    imgui.begin("##panel", None, PAGE_FLAGS)
    imgui.pop_style_var()
    _progress(app, view)
    _transport(app, view, t)
    if view.ranking_open():
        # the rows scroll when a design has more questions than the panel's share of the window holds
        imgui.begin_child("##ranks", imgui.ImVec2(0, 0))
        panel_of(view).draw(app, view)
        imgui.end_child()
    imgui.end()


def _progress(app: ScreenApp, view: TrialView) -> None:
    """Where the participant is ("Clip 3 of 8"), at the start of the transport row; amber for practice."""
    s = app.scale
    row = imgui.get_cursor_pos()
    imgui.set_cursor_pos(imgui.ImVec2(row.x, row.y + 9 * s))  # centred on the 44 px buttons
    if view.plan.is_practice:
        imgui.push_style_color(imgui.Col_.text, imgui.ImVec4(*PRACTICE_COLOR))
    app.ui.heading(app.session.progress_label(), 1.25, key="progress")
    if view.plan.is_practice:
        imgui.pop_style_color()
        app.ui.tooltip(app.design.text("trial.practice_note"))
    # the transport starts a new line at the row's top (a same_line here would put it 9 px lower)
    end_x = imgui.get_item_rect_max().x - imgui.get_window_pos().x
    imgui.set_cursor_pos(imgui.ImVec2(end_x + 24 * s, row.y))


def _loading(app: ScreenApp) -> None:
    from studyapp.ui.screens.common import page_begin, page_end

    page_begin(app, "loading")
    app.ui.heading(app.session.progress_label(), 1.4)
    app.ui.wrapped(app.design.text("trial.loading"))
    page_end()
    app.request_trial_load()


def _transport(app: ScreenApp, view: TrialView, t: float) -> None:
    ui = app.ui
    s = app.scale
    tx = app.design.text
    state = view.state
    bw = 150 * s
    bh = 44 * s
    if state == "ready":
        if ui.button(tx("trial.play"), key="play", size=(bw, bh), primary=True, enabled=view.can_play()):
            view.play()
    elif state == "playing":
        if ui.button(tx("trial.pause"), key="pause", size=(bw, bh)):
            view.toggle_pause()
    elif state == "paused":
        if ui.button(tx("trial.resume"), key="resume", size=(bw, bh), primary=True):
            view.toggle_pause()
    else:
        if ui.button(tx("trial.replay"), key="replay", size=(bw, bh), enabled=view.can_play()):
            view.play()
    if view.in_play and view.watched:
        imgui.same_line()
        if ui.button(tx("trial.stop"), key="stop", size=(110 * s, bh)):
            view.stop()
    imgui.same_line(0, 20 * s)
    frac = 0.0 if view.duration_s <= 0 else min(1.0, t / view.duration_s)
    imgui.set_cursor_pos_y(imgui.get_cursor_pos_y() + 10 * s)
    imgui.progress_bar(frac, imgui.ImVec2(200 * s, 24 * s), f"{_fmt(t)} / {_fmt(view.duration_s)}")
    if view.ranking_open():
        panel_of(view).next_button(app, view)
    else:
        imgui.same_line(0, 20 * s)
        imgui.set_cursor_pos_y(imgui.get_cursor_pos_y() + 2 * s)
        status = _status_text(app, view, state)
        ui.muted(f"{tx('trial.practice_note')} {status}" if view.plan.is_practice and state == "ready" else status)


def _status_text(app: ScreenApp, view: TrialView, state: str) -> str:
    t = app.design.text
    if state == "ready":
        return t("trial.ready")
    if state == "paused":
        return t("trial.paused")
    if state == "playing" and not view.ranking_open():
        return t("trial.watch")
    if state == "playing":
        return t("trial.replaying")
    rank = view.paradigm == "rank"
    if not view.app.session.can_play():
        return t("trial.rank_now" if rank else "trial.answer_now")
    return t("trial.rank_replay" if rank else "trial.answer_replay")


def _keys(app: ScreenApp, view: TrialView) -> None:
    if app.key_pressed("space"):
        if view.state == "ready":
            view.play()
        else:
            view.toggle_pause()
    if app.key_pressed("enter") and view.state == "ready":
        view.play()
