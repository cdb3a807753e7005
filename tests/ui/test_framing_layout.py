"""Figures large enough to judge gestures, and text that fits, in the real participant screens.

The scripted participant (:class:`~studyapp.bots.ui_driver.UIBot`) drives the real UI offscreen; the checks look at
what it drew: where the 3D view is, the hand's pixels in it, and every string's rectangle.
"""
from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from fixtures.ui_steps import until_screen
from studyapp.bots.ui_driver import UIBot

pytestmark = pytest.mark.gl

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
ZEGGS = SAMPLES / "zeggs_067_Speech_2_x_1_0_excerpt.bvh"


def _gesture_study(tmp_path: Path, framing: str | None = None):
    """The synthetic tiny study with every motion file replaced by a real co-speech gesture clip (ZEGGS)."""
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB
    from fixtures.synthetic import write_synthetic_study

    path = write_synthetic_study(tmp_path / "study", n_stimuli=1, seconds=10.0, practice=False)
    motions = sorted(path.parent.rglob("*.bvh"))
    assert motions
    for m in motions:
        shutil.copyfile(ZEGGS, m)
    if framing is not None:
        path.write_text(path.read_text() + f'\n[display]\nframing = "{framing}"\n')
    design = load_design(path)
    return design, ResultsDB(tmp_path / "results.sqlite", design)


def _until(bot: UIBot, screen: str, limit: int = 200) -> None:
    until_screen(bot, screen, limit)


def _hand_joints(avatar, side: str) -> list[int]:
    sk = avatar.skeleton
    hand = sk.index(f"{side}Hand")
    out = [hand]
    for j in range(sk.n_joints):
        if sk.parents[j] in out:
            out.append(j)
    return out


def _project(view_proj: np.ndarray, pts: np.ndarray, viewport: tuple[int, int, int, int], height: int) -> np.ndarray:
    """Pixel (column, row from the top) of world points; ``viewport`` is GL's (x, y from the bottom, w, h)."""
    x, y, w, h = viewport
    clip = np.c_[pts, np.ones(len(pts))] @ view_proj.T
    ndc = clip[:, :2] / clip[:, 3:4]
    return np.c_[x + (ndc[:, 0] + 1) / 2 * w, height - (y + (ndc[:, 1] + 1) / 2 * h)]


def _skin(avatar, palette: np.ndarray) -> np.ndarray:
    """CPU linear blend skinning of every bind-pose vertex (written here, not taken from the renderer)."""
    v = np.c_[avatar.vertices.astype(np.float64), np.ones(avatar.n_vertices)]
    out = np.zeros((avatar.n_vertices, 3))
    for k in range(4):
        m = palette.astype(np.float64)[avatar.joints[:, k]]
        out += avatar.weights[:, k:k + 1] * np.einsum("vab,vb->va", m[:, :3], v)
    return out


def test_hands_are_large_enough_to_judge_in_the_ranking_layout(tmp_path):
    """1280x720, three slots, ranking panel open, upper-body framing (the default), a real gesture clip:
    each hand of the middle figure is at least 25 px across, measured on the rendered image (its pixels
    found by drawing the frame again with that hand collapsed to the wrist) and from the camera matrices
    and the hand's skinned vertices, which must agree."""
    from studyapp.render.context import OffscreenTarget
    from studyapp.render.renderer import Renderer, slot_viewports

    design, db = _gesture_study(tmp_path)
    assert design.display.framing == "upper-body"
    W, H = 1280, 720
    bot = UIBot(design, db, "P1", "ordered", 3, size=(W, H))
    try:
        _until(bot, "trials:ranking")
        scene, t, (rx, ry, rw, rh) = bot.app._scene_req
        shot = bot.target.read_rgb()
        # the 3D view keeps most of the window while the panel is open
        assert rh >= 0.5 * H, rh
        gl_view = (int(rx), int(H - ry - rh), int(rw), int(rh))
        vp = slot_viewports(gl_view, 3)[1]
        avatar = scene.avatars[1]
        slot = scene.slots[1]
        palette, weights = slot.frame_at(t)
        view_proj = scene.camera.view_proj(vp[2] / vp[3])
        renderer = Renderer(bot.ctx, samples=0)  # no anti-aliasing: only the hand's own pixels change
        target = OffscreenTarget(bot.ctx, (W, H))
        try:
            renderer.draw_trial(scene, t, target.fbo, gl_view)
            full = target.read_rgb()
            # what the participant saw is this frame, but for anti-aliased edges (the UI draws only outside)
            y0, y1 = int(ry), int(ry + rh)
            assert (np.abs(full[y0:y1].astype(int) - shot[y0:y1].astype(int)).sum(-1) > 24).mean() < 0.01
            sizes = []
            for side in ("Left", "Right"):
                joints = _hand_joints(avatar, side)
                owner = avatar.joints[np.arange(avatar.n_vertices), avatar.weights.argmax(1)]
                skinned = _skin(avatar, palette)
                px = _project(view_proj, skinned[np.isin(owner, joints)], vp, H)
                ext = px.max(0) - px.min(0)  # the hand: vertices it carries most
                touched = (np.isin(avatar.joints, joints) & (avatar.weights > 0)).any(1)
                px = _project(view_proj, skinned[touched], vp, H)
                ext_wrist = px.max(0) - px.min(0)  # and the wrist's skin, which moves a little with it
                # the hand collapsed onto its wrist: the pixels that change are the hand's
                pal = palette.copy()
                wrist = pal[joints[0]] @ np.linalg.inv(avatar.inverse_bind[joints[0]])
                for j in joints:
                    pal[j] = 0.0
                    pal[j][:, 3] = wrist[:, 3]
                # one frame holding this instant (the floor shadow follows the joints: keep them)
                hidden = replace(slot, palettes=pal[None], face_weights=weights[None],
                                 joint_positions=slot.joints_at(t)[None].astype(np.float32))
                scene_h = type(scene)(slots=(scene.slots[0], hidden, scene.slots[2]), avatars=scene.avatars,
                                      labels=scene.labels, camera=scene.camera, duration=scene.duration)
                renderer.draw_trial(scene_h, t, target.fbo, gl_view)
                diff = np.abs(full.astype(int) - target.read_rgb().astype(int)).sum(-1) > 24
                # the hand is the largest changed blob (forearm vertices with a little wrist weight move
                # a pixel here and there along the arm's edge)
                labels, n = ndimage.label(diff)
                assert n >= 1, f"{side} hand: no pixels"
                blob = labels == 1 + int(np.argmax(ndimage.sum(diff, labels, range(1, n + 1))))
                rows, cols = np.nonzero(blob)
                assert len(rows) > 50, f"{side} hand: {len(rows)} pixels"
                seen = np.array([cols.max() - cols.min() + 1, rows.max() - rows.min() + 1], float)
                # image and projection agree (to a pixel or two of rasterisation)
                assert np.all(seen >= ext - 3) and np.all(seen <= ext_wrist + 3), (side, seen, ext, ext_wrist)
                sizes.append(seen)
                assert max(seen) >= 25, f"{side} hand only {seen} px across"
            print("hand pixels (w, h):", [s.tolist() for s in sizes], "3D view height", rh)
        finally:
            target.release()
            renderer.release()
    finally:
        bot.close()
        db.close()


def _screens_run(tmp_path: Path, size: tuple[int, int], *, allow_ties: bool = False, extra_toml: str = "",
                 out_dir: Path | None = None):
    """A scripted participant through every screen at ``size``; returns (screens seen, cut-off strings)."""
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB
    from fixtures.synthetic import write_synthetic_study

    path = write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0, practice=False, questionnaire=True,
                                 allow_ties=allow_ties)
    if extra_toml:
        path.write_text(path.read_text() + extra_toml)
    design = load_design(path)
    db = ResultsDB(tmp_path / "r.sqlite", design)
    bot = UIBot(design, db, "P1", "ordered", 1, size=size, out_dir=out_dir)
    screens = []
    orig = bot.frame

    def frame() -> None:
        orig()
        key = bot.app.screen_key()
        if not screens or screens[-1] != key:
            screens.append(key)

    bot.frame = frame
    try:
        assert bot.run() == 0
        return screens, list(bot.app.ui.cut_off)
    finally:
        bot.close()
        db.close()


#: A Likert item whose anchors are too long for one row with the points (they must wrap, not be cut).
LONG_ANCHORS = """
[[questionnaire]]
id = "long"
kind = "likert"
text = "The three figures were easy to tell apart."
points = 7
anchors = ["Strongly disagree with every single word of this statement",
           "Strongly agree with every single word of this statement"]
"""


@pytest.mark.parametrize("size,ties", [((1280, 720), False), ((1280, 720), True), ((1920, 1080), False),
                                       ((3840, 2160), False)])
def test_no_text_is_cut_off_on_any_screen(tmp_path, size, ties):
    """Every string of every screen (welcome to done, the trial in all its states) lies inside what its
    window shows: not past a side, not below a bottom that cannot be scrolled to (Painter.cut_off)."""
    screens, cut = _screens_run(tmp_path, size, allow_ties=ties, extra_toml=LONG_ANCHORS)
    for screen in ("welcome", "instructions", "env_check", "trials:ready", "trials:playing", "trials:ranking",
                   "trials:ranked", "questionnaire", "done"):
        assert screen in screens, (screen, screens)
    assert cut == [], sorted(set(cut))[:10]


def test_the_cut_off_check_finds_text_that_does_not_fit(tmp_path, monkeypatch):
    """The check itself, on a page drawn for the purpose: a line too long for its window, and wrapped text
    taller than a window with no scrollbar, are reported; text that fits and a scrolling page are not."""
    from imgui_bundle import imgui

    from studyapp.ui.screens import welcome
    from studyapp.ui.screens.common import PAGE_FLAGS

    long_line = "An unwrapped line " * 30
    tall = "Wrapped text that goes on. " * 200

    def draw(app):
        s = app.scale
        imgui.set_next_window_pos((20 * s, 20 * s))
        imgui.set_next_window_size((400 * s, 200 * s))
        imgui.begin("##cramped", None, PAGE_FLAGS)  # no scrollbar
        app.ui.text("Fits.")
        app.ui.text(long_line)
        app.ui.wrapped(tall)
        imgui.end()
        imgui.set_next_window_pos((500 * s, 20 * s))
        imgui.set_next_window_size((400 * s, 200 * s))
        imgui.begin("##scrolling", None, imgui.WindowFlags_.no_decoration & ~imgui.WindowFlags_.no_scrollbar)
        app.ui.wrapped("Scrolls: " + tall)
        imgui.end()

    monkeypatch.setattr(welcome, "draw", draw)
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB
    from fixtures.synthetic import write_synthetic_study

    design = load_design(write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0))
    db = ResultsDB(tmp_path / "r.sqlite", design)
    bot = UIBot(design, db, "P1", "ordered", 1, size=(1280, 720))
    try:
        for _ in range(4):  # past the frames a new window needs to settle
            bot.frame()
        texts = {t for t, _ in bot.app.ui.cut_off}
    finally:
        bot.close()
        db.close()
    assert long_line in texts and tall in texts
    assert "Fits." not in texts and "Scrolls: " + tall not in texts


def test_seven_questions_scroll_instead_of_being_cut_off(tmp_path):
    """More questions than the panel's share of the window holds: the rows scroll instead of being cut
    off (the last ones start below the window), the 3D view keeps its share, and a participant who scrolls
    (the scripted one uses the mouse wheel) answers them all."""
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB
    from fixtures.synthetic import write_synthetic_study

    path = write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0, practice=False)
    path.write_text(path.read_text() + "".join(
        f'\n[[criteria]]\nid = "c{i}"\nlabel = "Question {i}"\nquestion = "Which motion is best on point {i}?"\n'
        f'explanation = "What to look for on this point, in a sentence long enough to wrap onto a second line."\n'
        for i in range(7)))
    design = load_design(path)
    db = ResultsDB(tmp_path / "r.sqlite", design)
    bot = UIBot(design, db, "P1", "ordered", 1, size=(1280, 720))
    try:
        _until(bot, "trials:ranking")
        for _ in range(3):
            bot.frame()
        rh = bot.app._scene_req[2][3]
        last = bot.app.ui.rects[("crit", "c6")]
        assert bot.app.ui.cut_off == [], bot.app.ui.cut_off[:5]
        assert bot.run() == 0
        assert bot.app.ui.cut_off == [], bot.app.ui.cut_off[:5]
        answered = {r["criterion"] for r in db.responses("P1")}
    finally:
        bot.close()
        db.close()
    assert rh >= 0.38 * 720
    assert last[1] > 720  # the last question starts below the window: reached by scrolling
    assert answered == {f"c{i}" for i in range(7)}
