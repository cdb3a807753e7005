"""Framing: what the shared camera shows (upper body / full body / a head), checked on rendered pixels and
against projections of the skinned mesh computed here."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from render_helpers import RELAXED, posed, project, skin_cpu
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.motion.skeleton import Motion, Skeleton
from studyapp.render.avatar import Avatar
from studyapp.render.context import OffscreenTarget
from studyapp.render.pose import prepare_slot
from studyapp.render.renderer import slot_viewports
from studyapp.render.scene import make_scene

pytestmark = pytest.mark.gl

ZEGGS = Path(__file__).resolve().parents[1] / "data" / "samples" / "zeggs_067_Speech_2_x_1_0_excerpt.bvh"


def render(renderer, scene, size, t=0.0, figures=True, viewport=None):
    target = OffscreenTarget(renderer.ctx, size)
    try:
        renderer.draw_trial(scene, t, target.fbo, viewport, figures=figures)
        return target.read_rgb()
    finally:
        target.release()


def figure_mask(renderer, scene, size, t):
    """Pixels where the figures are: the frame against the same frame drawn without figures."""
    a = render(renderer, scene, size, t)
    b = render(renderer, scene, size, t, figures=False)
    return np.abs(a.astype(int) - b.astype(int)).sum(-1) > 12


def walking(avatar, seconds=3.0, fps=30.0, metres=(2.4, 1.2)):
    """The relaxed pose carried across the floor: the hips travel ``metres`` (x, z) at constant speed,
    bobbing 3 cm twice a second as in a walk."""
    n = int(seconds * fps)
    m = posed(avatar, RELAXED, n, fps)
    s = np.linspace(0, 1, n)
    m.translations[:, 0, 0] += metres[0] * s
    m.translations[:, 0, 2] += metres[1] * s
    m.translations[:, 0, 1] += 0.03 * np.sin(2 * np.pi * 2 * s * seconds)
    return m


def test_full_body_walking_clip_keeps_head_and_feet_in_frame_at_full_size(renderer, avatar):
    size = (1280, 720)
    walk = prepare_slot(avatar, walking(avatar), None)
    still = prepare_slot(avatar, posed(avatar, RELAXED, 2), None)
    scene = make_scene([walk] * 3, avatar, labels=("A", "B", "C"), framing="full-body")
    still_scene = make_scene([still] * 3, avatar, labels=("A", "B", "C"), framing="full-body")
    x, _, w, h = vp = slot_viewports((0, 0, *size), 3)[1]
    heights = []
    for t in (0.0, 1.5, 2.95):
        fig = figure_mask(renderer, scene, size, t)[:, x:x + w]
        rows, cols = np.nonzero(fig)
        # head and feet inside the frame, with room to spare (the floor shadow counts as figure too)
        assert rows.min() > 0.02 * h and rows.max() < 0.98 * h, (t, rows.min(), rows.max())
        # the figure stays in the middle of its slot while it walks
        assert abs((cols.min() + cols.max()) / 2 - w / 2) < 0.06 * w, t
        heights.append(rows.max() - rows.min())
        # independently: the skinned mesh's head top and soles project inside the slot
        pts = project(scene.camera, skin_cpu(avatar, scene.slots[1].frame_at(t)[0]), vp, size[1])
        assert pts[:, 1].min() > 0 and pts[:, 1].max() < h and pts[:, 0].min() > x and pts[:, 0].max() < x + w
    # walking does not shrink the figure: about as tall as the same pose standing still (the frame only
    # makes room for the 3 cm bob of the hips); fitting the 2.7 m walk instead would make it a third smaller
    labels, n = ndimage.label(figure_mask(renderer, still_scene, size, 0.0)[:, x:x + w])
    rows = np.flatnonzero((labels == 1 + int(np.argmax(ndimage.sum(labels > 0, labels, range(1, n + 1))))).any(1))
    assert np.ptp(heights) <= 3 and np.mean(heights) >= 0.95 * np.ptp(rows), (heights, np.ptp(rows))


def test_upper_body_shows_the_hips_up_and_every_hand_position(renderer, avatar):
    """A real gesture clip: over the whole clip both hands (every vertex) and the head top stay inside the
    slot, the hips are in frame, the feet are not, and the figure is larger than with full-body framing."""
    from studyapp.motion.io import load_motion

    slot = prepare_slot(avatar, load_motion(ZEGGS), None)
    upper = make_scene([slot] * 3, avatar, labels=("A", "B", "C"))  # upper-body is the default
    full = make_scene([slot] * 3, avatar, labels=("A", "B", "C"), framing="full-body")
    sk = avatar.skeleton
    hands = [j for j, n in enumerate(sk.names) if n.startswith(("Left", "Right")) and
             any(k in n for k in ("Hand", "Thumb", "Index", "Middle", "Ring", "Little"))]
    owner = avatar.joints[np.arange(avatar.n_vertices), avatar.weights.argmax(1)]
    hand_v = np.isin(owner, hands)
    feet = np.isin(owner, [sk.index(n) for n in ("LeftFoot", "RightFoot", "LeftToes", "RightToes")])
    for size in ((1280, 720), (1280, 383)):  # the playing and the ranking layouts' 3D views
        x, _, w, h = vp = slot_viewports((0, 0, *size), 3)[1]
        for t in np.linspace(0, slot.duration - 0.05, 25):
            v = skin_cpu(avatar, slot.frame_at(t)[0])
            pts = project(upper.camera, v, vp, size[1])
            hp = pts[hand_v]
            assert hp[:, 0].min() > x and hp[:, 0].max() < x + w and hp[:, 1].min() > 0 and hp[:, 1].max() < h, t
            assert pts[:, 1].min() > 0  # head top
            hips = project(upper.camera, slot.joints_at(t)[[sk.index("Hips")]], vp, size[1])[0]
            assert 0 < hips[1] < h
            if size[1] < 500:  # a wide view: the height decides, and the legs are left out
                assert pts[feet][:, 1].min() > h
        # the same pixels on screen: the upper-body figure is drawn larger than the full-body one
        tall = [np.ptp(np.flatnonzero(figure_mask(renderer, sc, size, 2.0)[:, x:x + w].any(0))) for sc in (upper, full)]
        assert tall[0] > tall[1] or size[1] > 500, tall


def _head_only(avatar) -> Avatar:
    """The built-in avatar's head alone, on a one-joint skeleton: like an ARKit face model (no body)."""
    sk = avatar.skeleton
    head = sk.index("Head")
    keep_j = [head] + [j for j in range(sk.n_joints) if sk.parents[j] == head]
    keep_v = np.isin(avatar.joints, keep_j).all(1) | (avatar.weights * ~np.isin(avatar.joints, keep_j) == 0).all(1)
    tri = avatar.indices[keep_v[avatar.indices].all(1)]
    new_v = -np.ones(avatar.n_vertices, int)
    new_v[keep_v] = np.arange(keep_v.sum())
    remap = {j: i for i, j in enumerate(keep_j)}
    joints = np.vectorize(lambda j: remap.get(int(j), 0))(avatar.joints[keep_v])
    weights = np.where(np.isin(avatar.joints[keep_v], keep_j), avatar.weights[keep_v], 0)
    world = np.linalg.inv(avatar.inverse_bind[keep_j].astype(np.float64))[:, :3, 3]
    offsets = world - np.r_[[np.zeros(3)], np.repeat(world[:1], len(keep_j) - 1, 0)]
    skel = Skeleton(names=tuple(sk.names[j] for j in keep_j), parents=np.array([-1] + [0] * (len(keep_j) - 1)),
                    offsets=offsets)
    return Avatar(skeleton=skel, vertices=avatar.vertices[keep_v], normals=avatar.normals[keep_v],
                  indices=new_v[tri], colors=avatar.colors[keep_v], joints=joints, weights=weights,
                  inverse_bind=avatar.inverse_bind[keep_j], morph_names=avatar.morph_names,
                  morph_deltas=avatar.morph_deltas[:, keep_v], material=avatar.material[keep_v])


def test_a_head_only_avatar_is_framed_whole_mouth_and_chin_included(renderer, avatar):
    head = _head_only(avatar)
    assert head.skeleton.n_joints >= 1 and head.n_vertices > 1000
    w = np.zeros((2, 52), np.float32)
    w[:, ARKIT_NAMES.index("jawOpen")] = 1.0
    slot = prepare_slot(head, Motion.rest(head.skeleton, 2), FaceAnimation(w, 30.0))
    size = (480, 540)
    for framing in ("upper-body", "full-body"):
        scene = make_scene([slot], head, framing=framing)
        fig = figure_mask(renderer, scene, size, 0.0)
        labels, n = ndimage.label(fig)
        rows, cols = np.nonzero(fig)
        # the whole head inside the frame, not touching an edge, and filling most of the frame's height
        assert rows.min() > 2 and rows.max() < size[1] - 3 and cols.min() > 2 and cols.max() < size[0] - 3
        assert np.ptp(rows) > 0.6 * size[1], np.ptp(rows)
        # independently: the open jaw's lowest vertex (the chin) projects inside, above the bottom edge
        v = skin_cpu(head, slot.palettes[0], slot.face_weights[0])
        pts = project(scene.camera, v, (0, 0, *size), size[1])
        assert pts[:, 1].max() < size[1] - 2 and pts[:, 1].min() > 2
