"""Offscreen EGL rendering: real pixels from the real renderer."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from render_helpers import RELAXED, posed, project, skin_cpu
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.render.context import OffscreenTarget
from studyapp.render.pose import prepare_slot
from studyapp.render.renderer import Renderer, slot_viewports
from studyapp.render.scene import make_scene

pytestmark = pytest.mark.gl


def face_with(**weights) -> FaceAnimation:
    w = np.zeros((2, 52), np.float32)
    for k, v in weights.items():
        w[:, ARKIT_NAMES.index(k)] = v
    return FaceAnimation(w, 30.0)


def render(renderer, scene, size, t=0.0, figures=True):
    target = OffscreenTarget(renderer.ctx, size)
    try:
        renderer.draw_trial(scene, t, target.fbo, figures=figures)
        return target.read_rgb()
    finally:
        target.release()


def changed(a, b, tol=12):
    return np.abs(a.astype(int) - b.astype(int)).sum(-1) > tol


@pytest.fixture(scope="module")
def relaxed_slot(avatar):
    return prepare_slot(avatar, posed(avatar, RELAXED, 2), face_with())


def test_three_figures_in_three_thirds(renderer, avatar, relaxed_slot):
    scene = make_scene([relaxed_slot] * 3, avatar, labels=None)
    img = render(renderer, scene, (1280, 720))
    empty = render(renderer, scene, (1280, 720), figures=False)
    fig = changed(img, empty)
    for i, (x, _, w, _) in enumerate(slot_viewports((0, 0, 1280, 720), 3)):
        third = fig[:, x:x + w]
        labels, n = ndimage.label(third)
        sizes = ndimage.sum(third, labels, range(1, n + 1))
        biggest = sizes.max()
        # one connected figure holds (nearly) all of the slot's figure pixels
        assert biggest > 0.03 * third.size, f"slot {i}: figure too small ({biggest} px)"
        assert biggest > 0.97 * third.sum(), f"slot {i}: figure is in pieces"
        cols = np.flatnonzero(third.any(0))
        # the figure is centred in its third and leaves background columns on both sides
        assert cols.min() > 0.05 * w and cols.max() < 0.95 * w
        assert abs((cols.min() + cols.max()) / 2 - w / 2) < 0.05 * w
    # columns between the figures are pure background
    for edge in (427, 853):
        assert not fig[:, edge - 3:edge + 3].any()
    # the same pose looks the same in every slot (left and right slots are both 427 px wide)
    a, b = img[:, 0:427], img[:, 853:1280]
    # (edge pixels may differ a little: the rasteriser snaps to different pixel offsets)
    d = np.abs(a.astype(int) - b.astype(int)).max(-1)
    assert (d > 2).mean() < 0.002 and d.mean() < 0.1


def test_same_frame_twice_is_identical(renderer, avatar, relaxed_slot):
    scene = make_scene([relaxed_slot] * 3, avatar, labels=("A", "B", "C"))
    one = render(renderer, scene, (480, 270), t=0.01)
    two = render(renderer, scene, (480, 270), t=0.01)
    assert np.array_equal(one, two)


def test_rotating_an_arm_changes_only_the_arm_region(renderer, avatar, relaxed_slot):
    lifted = dict(RELAXED, LeftUpperArm=(0, 0, -30))
    slot2 = prepare_slot(avatar, posed(avatar, lifted, 2), face_with())
    size = (640, 360)
    base = make_scene([relaxed_slot] * 3, avatar)
    moved = make_scene([relaxed_slot, slot2, relaxed_slot], avatar)
    moved.camera = base.camera
    a = render(renderer, base, size)
    b = render(renderer, moved, size)
    diff = changed(a, b)
    vps = slot_viewports((0, 0, *size), 3)
    assert not diff[:, : vps[1][0]].any() and not diff[:, vps[2][0]:].any(), "other slots changed"
    assert diff.sum() > 300
    # every changed pixel lies where the left arm (shoulder to fingertips) is in either pose
    sk = avatar.skeleton
    arm_joints = [sk.index(n) for n in sk.names if n.startswith("Left") and "Leg" not in n and "Foot" not in n and "Toes" not in n]
    # the arm region: every vertex the arm's joints influence at all (the shoulder blends into the chest)
    arm = (np.isin(avatar.joints, arm_joints) & (avatar.weights > 0)).any(1)
    boxes = []
    for slot in (relaxed_slot, slot2):
        pts = project(base.camera, skin_cpu(avatar, slot.palettes[0])[arm], vps[1], size[1])
        boxes.append((pts.min(0) - 4, pts.max(0) + 4))
    rows, cols = np.nonzero(diff)
    inside = np.zeros(len(rows), bool)
    for lo, hi in boxes:
        inside |= (cols >= lo[0]) & (cols <= hi[0]) & (rows >= lo[1]) & (rows <= hi[1])
    assert inside.all(), f"{(~inside).sum()} changed pixels outside the arm"
    # and the arm's new place is on the avatar's left = the viewer's right of the slot centre
    centre = vps[1][0] + vps[1][2] / 2
    assert cols.mean() > centre


def test_jaw_open_changes_the_mouth_and_only_the_face(renderer, avatar):
    size = (480, 540)
    closed = prepare_slot(avatar, posed(avatar, RELAXED, 2), face_with())
    open_ = prepare_slot(avatar, posed(avatar, RELAXED, 2), face_with(jawOpen=1.0))
    scene_a = make_scene([closed], avatar)
    scene_b = make_scene([open_], avatar)
    scene_b.camera = scene_a.camera
    a = render(renderer, scene_a, size)
    b = render(renderer, scene_b, size)
    diff = changed(a, b)
    assert diff.sum() > 20
    head = avatar.skeleton.index("Head")
    owner = avatar.joints[np.arange(avatar.n_vertices), avatar.weights.argmax(1)]
    jaw = np.zeros(52)
    jaw[ARKIT_NAMES.index("jawOpen")] = 1.0
    head_pts = np.concatenate([
        project(scene_a.camera, skin_cpu(avatar, closed.palettes[0], w)[owner == head], (0, 0, *size), size[1])
        for w in (None, jaw)])
    lo, hi = head_pts.min(0) - 2, head_pts.max(0) + 2
    rows, cols = np.nonzero(diff)
    assert ((cols >= lo[0]) & (cols <= hi[0]) & (rows >= lo[1]) & (rows <= hi[1])).all()
    # the change sits in the lower half of the face (the mouth), and the open mouth is darker
    assert rows.mean() > (lo[1] + hi[1]) / 2
    assert b[diff].mean() < a[diff].mean()


def test_viewport_offset_and_window_sized_target_match(renderer, avatar, relaxed_slot):
    scene = make_scene([relaxed_slot] * 3, avatar, labels=("A", "B", "C"))
    direct = render(renderer, scene, (300, 200))
    big = OffscreenTarget(renderer.ctx, (400, 300))
    big.clear((1.0, 0.0, 1.0))
    renderer.draw_trial(scene, 0.0, big.fbo, viewport=(50, 60, 300, 200))
    img = big.read_rgb()
    big.release()
    # (x=50, y=60) counts from the bottom; the image is top-row first
    inset = img[300 - 60 - 200: 300 - 60, 50:350]
    assert np.abs(inset.astype(int) - direct.astype(int)).max() <= 1
    assert (img[0, 0] == [255, 0, 255]).all()  # outside the viewport untouched


def test_labels_are_drawn_and_neutral(renderer, avatar, relaxed_slot):
    plain = make_scene([relaxed_slot] * 3, avatar, labels=None)
    labelled = make_scene([relaxed_slot] * 3, avatar, labels=("A", "B", "C"))
    # labels make room for themselves (a higher frame); compare with the same camera
    assert labelled.camera.target[1] > plain.camera.target[1]
    labelled.camera = plain.camera
    a = render(renderer, plain, (480, 270))
    b = render(renderer, labelled, (480, 270))
    diff = changed(a, b)
    rows = np.nonzero(diff)[0]
    assert diff.sum() > 30 and rows.max() < 270 * 0.15  # small text near the top
    for x, _, w, _ in slot_viewports((0, 0, 480, 270), 3):
        assert diff[:, x:x + w].any()


@pytest.mark.parametrize("aa", ["msaa", "fxaa"])
def test_antialiasing_smooths_edges(gl_ctx, avatar, relaxed_slot, aa):
    from studyapp.render.renderer import Renderer, is_software_renderer

    scene = make_scene([relaxed_slot] * 3, avatar)
    smooth_renderer = Renderer(gl_ctx, samples=4, software_aa=aa)
    if aa == "fxaa" and not is_software_renderer(gl_ctx):
        assert smooth_renderer.antialiasing == "msaa"  # GPUs always get the MSAA they asked for
    else:
        assert smooth_renderer.antialiasing == aa
    aliased = render(Renderer(gl_ctx, samples=0), scene, (320, 180))
    smooth = render(smooth_renderer, scene, (320, 180))
    # anti-aliasing blends silhouettes into the backdrop: more distinct colours, same picture
    n_a = len(np.unique(aliased.reshape(-1, 3), axis=0))
    n_s = len(np.unique(smooth.reshape(-1, 3), axis=0))
    assert n_s > n_a * 1.1
    assert np.abs(aliased.astype(int) - smooth.astype(int)).mean() < 3


def test_back_face_culling_hides_nothing_of_the_builtin_avatar(renderer, avatar, relaxed_slot):
    # the built-in avatar is drawn with culling; every surface must face outwards for that to be invisible
    import dataclasses

    from studyapp.render.camera import Camera

    two_sided = dataclasses.replace(avatar, double_sided=True)
    renderer = Renderer(renderer.ctx, lighting="pixel")  # as a double-sided avatar is always lit
    for camera in (Camera(eye=np.array([0.0, 1.2, 3.2]), target=np.array([0.0, 1.2, 0.0]), fov_y=35),  # body
                   Camera(eye=np.array([0.25, 1.7, 0.7]), target=np.array([0.0, 1.64, 0.0]), fov_y=22)):  # face
        closed = make_scene([relaxed_slot], avatar)
        both = make_scene([relaxed_slot], two_sided)
        closed.camera = both.camera = camera
        a = render(renderer, closed, (300, 300))
        b = render(renderer, both, (300, 300))
        assert changed(a, b).sum() <= 20  # a few pixels where parts interpenetrate; inward eyes alone give 35-400


def test_bone_palette_holds_more_than_128_joints(renderer, avatar):
    # Rigs like BEAT's (75 joints) plus face and finger bones run past 128: the palette must reach them.
    # Append 200 joints at the hips and skin the whole mesh to the very last one (index 251): turning that
    # joint a quarter turn about the vertical axis must show the T-posed figure from the side.
    import dataclasses

    from studyapp.motion.fk import rest_global_transforms
    from studyapp.motion.skeleton import Skeleton
    from studyapp.render.camera import Camera

    sk = avatar.skeleton
    n_extra = 200
    big = Skeleton(names=sk.names + tuple(f"Extra{i}" for i in range(n_extra)),
                   parents=np.concatenate([sk.parents, np.zeros(n_extra, int)]),
                   offsets=np.concatenate([sk.offsets, np.zeros((n_extra, 3))]), end_sites=sk.end_sites, unit_scale=1.0)
    last = big.n_joints - 1
    assert last > 128
    joints = np.zeros_like(avatar.joints)
    joints[:, 0] = last
    weights = np.zeros_like(avatar.weights)
    weights[:, 0] = 1.0
    rigged = dataclasses.replace(avatar, skeleton=big, joints=joints, weights=weights,
                                 inverse_bind=np.linalg.inv(rest_global_transforms(big)))
    camera = Camera(eye=np.array([0.0, 1.0, 5.0]), target=np.array([0.0, 1.0, 0.0]), fov_y=30)
    widths = []
    for turn in (0, 90):
        slot = prepare_slot(rigged, posed(rigged, {f"Extra{n_extra - 1}": (0, turn, 0)}, 2), None)
        scene = make_scene([slot], rigged)
        empty = make_scene([slot], rigged)
        scene.camera = empty.camera = camera
        fig = changed(render(renderer, scene, (320, 240)), render(renderer, empty, (320, 240), figures=False))
        cols = np.flatnonzero(fig.any(0))
        widths.append(cols.max() - cols.min() if len(cols) else 0)
    front, side = widths
    # T-pose: ~1.5 m fingertip to fingertip; from the side ~0.3 m
    assert front > 100 and side < 0.4 * front, widths
