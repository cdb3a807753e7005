"""Palettes, retargeting into slots, interpolation and the face's head rotation."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from render_helpers import RELAXED, SAMPLES, posed, skin_cpu
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.motion.bvh import read_bvh
from studyapp.motion.skeleton import Motion
from studyapp.render.pose import prepare_slot, resample_motion, skinning_palettes


def test_rest_pose_palettes_are_identity(avatar):
    pal = skinning_palettes(avatar, Motion.rest(avatar.skeleton, 3))
    assert pal.shape == (3, avatar.skeleton.n_joints, 4, 4) and pal.dtype == np.float32
    assert np.allclose(pal, np.eye(4), atol=1e-6)


def test_rotating_the_upper_arm_moves_the_left_arm_only(avatar):
    sk = avatar.skeleton
    pal = skinning_palettes(avatar, posed(avatar, {"LeftUpperArm": (0, 0, -90)}))[0]
    moved = np.linalg.norm(skin_cpu(avatar, pal) - avatar.vertices, axis=1) > 1e-4
    owner = avatar.joints[np.arange(avatar.n_vertices), avatar.weights.argmax(1)]
    left_arm = {sk.index(n) for n in sk.names if n.startswith("Left") and not any(k in n for k in ("Leg", "Foot", "Toes"))}
    assert moved.sum() > 1000
    assert set(np.unique(owner[moved])) <= left_arm | {sk.index("UpperChest"), sk.index("Chest")}
    # the hand hangs down: the middle fingertip is now below the shoulder by about the arm's length
    tip = sk.index("LeftMiddleDistal")
    assert (pal[tip] @ np.r_[avatar.vertices[owner == tip].mean(0), 1])[1] < 1.415 - 0.6


def test_resample_uses_slerp_between_frames(avatar):
    j = avatar.skeleton.index("LeftLowerArm")
    m = Motion.rest(avatar.skeleton, 2, fps=15.0)
    m.rotations[1, j] = Rotation.from_rotvec([0, 1.2, 0]).as_quat()
    up = resample_motion(m, 60.0)
    assert up.n_frames == 8 and up.fps == 60.0
    expected = Slerp([0, 1], Rotation.from_quat(m.rotations[:, j]))([0.25, 0.5, 0.75]).as_quat()
    got = up.rotations[1:4, j]
    assert np.allclose(np.abs((got * expected).sum(-1)), 1.0, atol=1e-9)


def test_frame_at_blends_neighbouring_frames(avatar):
    slot = prepare_slot(avatar, posed(avatar, RELAXED, 4, fps=30.0), None, playback_fps=30.0)
    p0, _ = slot.frame_at(0.0)
    mid, _ = slot.frame_at(0.5 / 30)
    assert np.allclose(mid, (slot.palettes[0] + slot.palettes[1]) / 2, atol=1e-6)
    late, _ = slot.frame_at(99.0)  # past the end: hold the last frame
    assert np.array_equal(late, slot.palettes[-1])


def test_face_weights_follow_the_avatar_morph_order_and_time(avatar):
    w = np.zeros((3, 52), np.float32)
    w[:, ARKIT_NAMES.index("jawOpen")] = [0.0, 1.0, 0.0]
    face = FaceAnimation(w, 10.0)
    slot = prepare_slot(avatar, Motion.rest(avatar.skeleton, 3, fps=10.0), face, playback_fps=20.0)
    jaw = avatar.morph_names.index("jawOpen")
    assert slot.face_weights.shape == (6, 52)
    assert np.allclose(slot.face_weights[:, jaw], [0, 0.5, 1.0, 0.5, 0, 0])
    assert np.isclose(slot.frame_at(0.125)[1][jaw], 0.75)


def test_face_head_rotation_turns_the_head(avatar):
    w = np.zeros((2, 52), np.float32)
    yaw = np.radians(30)
    face = FaceAnimation(w, 30.0, head_rotation=np.array([[yaw, 0, 0], [yaw, 0, 0]]))
    still = prepare_slot(avatar, Motion.rest(avatar.skeleton, 2), None)
    turned = prepare_slot(avatar, Motion.rest(avatar.skeleton, 2), face)
    head = avatar.skeleton.index("Head")
    assert np.allclose(still.palettes[0, head], np.eye(4), atol=1e-6)
    r = turned.palettes[0, head][:3, :3]
    assert np.isclose(np.degrees(np.arccos(r[0, 0])), 30, atol=0.01) and np.isclose(r[1, 1], 1, atol=1e-6)
    assert np.allclose(turned.palettes[0, avatar.skeleton.index("Neck")], np.eye(4), atol=1e-6)


def test_beat_bvh_retargets_onto_the_avatar_centred_in_metres(avatar):
    motion = read_bvh(SAMPLES / "beat75_diffsheg_output_excerpt.bvh", fps=15)
    slot = prepare_slot(avatar, motion, None)
    assert np.isfinite(slot.palettes).all()
    assert slot.duration == pytest.approx(3 / 15)
    hips = slot.joint_positions[:, 0]
    assert np.allclose(hips[0, [0, 2]], 0, atol=1e-6)  # starts centred
    head = slot.joint_positions[:, avatar.skeleton.index("Head")]
    assert 1.3 < head[:, 1].min() and head[:, 1].max() < 1.8  # metres, standing
    # the model's motion is not the rest pose: the arms are posed
    assert not np.allclose(slot.palettes[0, avatar.skeleton.index("LeftUpperArm")], np.eye(4), atol=0.05)


def test_framing_keeps_every_hand_position_of_every_slot_in_view(avatar):
    from render_helpers import project
    from studyapp.render.renderer import slot_viewports
    from studyapp.render.scene import make_scene

    # one calm slot and one with wide, high gestures: the shared camera must fit both
    n = 30
    calm = posed(avatar, RELAXED, n)
    wide = posed(avatar, RELAXED, n)
    sk = avatar.skeleton
    angles = np.linspace(-72, 40, n)  # the left arm sweeps from the side to above the shoulder
    for f, a in enumerate(angles):
        j = sk.index("LeftUpperArm")
        wide.rotations[f, j] = Rotation.from_rotvec(np.radians([0, 0, a])).as_quat()
    slots = [prepare_slot(avatar, m, None) for m in (calm, wide, calm)]
    scene = make_scene(slots, avatar, labels=("A", "B", "C"))
    tips = [sk.index(n) for n in sk.names if n.endswith("Distal")] + [sk.index("Head")]
    vps = slot_viewports((0, 0, 1280, 720), 3)
    for slot, vp in zip(slots, vps):
        pts = project(scene.camera, slot.joint_positions[:, tips].reshape(-1, 3), vp, 720)
        assert (pts[:, 0] > vp[0]).all() and (pts[:, 0] < vp[0] + vp[2]).all()
        assert (pts[:, 1] > 0.09 * 720).all() and (pts[:, 1] < 720).all()  # below the label band
