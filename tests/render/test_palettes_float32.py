"""Skinning palettes in float32 against the float64 computation, on real characters with real motion.

The renderer builds every trial's palettes in float32 (forward kinematics and the inverse bind product);
this checks that nothing a participant could see changed: for the built-in avatar and the sample glTF/VRM
characters, playing the demo's motion and real BEAT, ZEGGS, CMU and Mixamo captures, every palette entry
stays within ``PALETTE_FLOAT32_TOLERANCE`` (metres for the translations) of the float64 palette, and a
rendered frame of the demo differs by one colour level on a few hundred of 921,600 pixels and in at most
a few silhouette pixels.

The float64 reference here is the product written out independently: forward kinematics one joint at a
time with scipy rotations (no levels, no blocks), then ``@`` the inverse bind matrices in float64.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from render_helpers import SAMPLES
from studyapp.motion.bvh import read_bvh
from studyapp.render.pose import PALETTE_FLOAT32_TOLERANCE, prepare_slot, resample_motion, skinning_palettes, \
    to_avatar_skeleton
from studyapp.resources import designs_dir

AVATARS = SAMPLES / "avatars"
MOTIONS = SAMPLES / "motion"
DEMO_MOTION = designs_dir() / "demo" / "motion" / "synced" / "clip01.bvh"
ROBOT_MAP = {
    "Abdomen": "Spine", "Torso": "Chest",
    "Shoulder.L": "LeftShoulder", "UpperArm.L": "LeftUpperArm", "LowerArm.L": "LeftLowerArm", "Palm2.L": "LeftHand",
    "Shoulder.R": "RightShoulder", "UpperArm.R": "RightUpperArm", "LowerArm.R": "RightLowerArm", "Palm2.R": "RightHand",
    "UpperLeg.L": "LeftUpperLeg", "LowerLeg.L": "LeftLowerLeg", "Foot.L": "LeftFoot",
    "UpperLeg.R": "RightUpperLeg", "LowerLeg.R": "RightLowerLeg", "Foot.R": "RightFoot",
}


def _reference_palettes(avatar, motion) -> np.ndarray:
    """float64 world transforms joint by joint (scipy quaternions), times float64 inverse binds."""
    sk = avatar.skeleton
    f, j = motion.rotations.shape[:2]
    world = np.zeros((f, j, 4, 4))
    world[..., 3, 3] = 1.0
    for k in range(j):
        local = np.zeros((f, 4, 4))
        local[:, :3, :3] = Rotation.from_quat(motion.rotations[:, k]).as_matrix()
        local[:, :3, 3] = motion.translations[:, k]
        local[:, 3, 3] = 1.0
        p = sk.parents[k]
        world[:, k] = local if p < 0 else world[:, p] @ local
    return world @ avatar.inverse_bind.astype(np.float64)


def _trial_motion(avatar, path, bone_map=None):
    """What prepare_slot feeds forward kinematics: the motion on the avatar's skeleton, at 60 fps."""
    motion = read_bvh(path)
    return resample_motion(to_avatar_skeleton(avatar, motion), 60.0)


def _load(file, bone_map):
    from studyapp.render.scene import load_avatar

    return load_avatar(AVATARS / file, bone_map)


CASES = [("builtin", None, DEMO_MOTION), ("builtin", None, SAMPLES / "beat75_diffsheg_output_excerpt.bvh"),
         ("builtin", None, MOTIONS / "zeggs_067_Speech_2_x_1_0_excerpt.bvh"),
         ("builtin", None, MOTIONS / "cmu_01_01_excerpt.bvh"),
         ("RobotExpressive.glb", ROBOT_MAP, MOTIONS / "mixamo_Joe_SalsaDancing6_excerpt.bvh"),
         ("RobotExpressive.glb", ROBOT_MAP, DEMO_MOTION),
         ("cryptovoxels_vrm0.vrm", None, MOTIONS / "zeggs_067_Speech_2_x_1_0_excerpt.bvh"),
         ("cryptovoxels_vrm0.vrm", None, DEMO_MOTION)]


@pytest.mark.parametrize("file,bone_map,motion_path", CASES, ids=[f"{a}-{c.stem}" for a, _, c in CASES])
def test_float32_palettes_match_float64_on_real_characters_and_motion(avatar, file, bone_map, motion_path):
    av = avatar if file == "builtin" else _load(file, bone_map)
    motion = _trial_motion(av, motion_path)
    assert motion.n_frames >= 2
    got = skinning_palettes(av, motion)
    ref = _reference_palettes(av, motion)
    assert got.dtype == np.float32 and got.shape == ref.shape and got.flags.c_contiguous
    rot_err = np.abs(got[..., :3, :3] - ref[..., :3, :3]).max()
    pos_err = np.abs(got[..., :3, 3] - ref[..., :3, 3]).max()
    # printed with -s: the figures behind PALETTE_FLOAT32_TOLERANCE's docstring
    print(f"{file} {motion_path.stem}: {motion.n_frames} frames, rotation {rot_err:.2e}, translation {pos_err:.2e} m")
    assert rot_err <= PALETTE_FLOAT32_TOLERANCE and pos_err <= PALETTE_FLOAT32_TOLERANCE
    np.testing.assert_array_equal(got[..., 3, :], np.broadcast_to([0, 0, 0, 1], got.shape[:2] + (4,)))


def test_prepare_slot_palettes_and_joints_are_the_float32_path(avatar):
    """The slot a trial plays holds exactly what skinning_palettes gives, and joints within the tolerance."""
    motion = read_bvh(DEMO_MOTION)
    slot = prepare_slot(avatar, motion, None)
    body = resample_motion(to_avatar_skeleton(avatar, motion), 60.0)
    np.testing.assert_array_equal(slot.palettes, skinning_palettes(avatar, body))
    ref = _reference_palettes(avatar, body)
    world = ref @ np.linalg.inv(avatar.inverse_bind.astype(np.float64))
    assert slot.joint_positions.dtype == np.float32
    assert np.abs(slot.joint_positions - world[..., :3, 3]).max() <= PALETTE_FLOAT32_TOLERANCE


@pytest.mark.gl
def test_demo_frames_render_the_same_from_float32_and_float64_palettes(renderer, avatar):
    """Three slots of the demo's motion, drawn at 1280x720 from float32 palettes and from the float64
    reference (rounded once for the GPU), with the same camera: the same picture."""
    import dataclasses

    from studyapp.render.context import OffscreenTarget
    from studyapp.render.scene import make_scene

    motion = read_bvh(DEMO_MOTION)
    fast = prepare_slot(avatar, motion, None)
    body = resample_motion(to_avatar_skeleton(avatar, motion), 60.0)
    ref = _reference_palettes(avatar, body)
    world = ref @ np.linalg.inv(avatar.inverse_bind.astype(np.float64))
    exact = dataclasses.replace(fast, palettes=ref.astype(np.float32),
                                joint_positions=world[..., :3, 3].astype(np.float32))
    scenes = [make_scene([s, s, s], avatar, labels=("A", "B", "C")) for s in (fast, exact)]
    scenes[1].camera = scenes[0].camera
    target = OffscreenTarget(renderer.ctx, (1280, 720))
    try:
        for t in (0.5, 3.25, 7.0):
            imgs = []
            for scene in scenes:
                renderer.draw_trial(scene, t, target.fbo)
                imgs.append(target.read_rgb().astype(int))
            diff = np.abs(imgs[0] - imgs[1]).max(-1)
            figure = (np.abs(imgs[1] - imgs[1][0, 0]).max(-1) > 0).mean()
            assert figure > 0.05, "nothing drawn"
            flipped = np.count_nonzero(diff > 2)
            print(f"t={t}: {np.count_nonzero(diff)} of {diff.size} pixels differ, {flipped} by more than 2 levels")
            # The last bit of a colour on at most a few hundred pixels (of 921,600), and a few silhouette pixels
            # whose centre lies within a micrometre of an edge may fall on the other side: nothing moves.
            assert np.count_nonzero(diff) <= 500 and flipped <= 10, (t, np.count_nonzero(diff), flipped)
    finally:
        target.release()


def test_a_trial_runs_forward_kinematics_in_float32_only(avatar, monkeypatch):
    """Loading a slot never asks for a float64 (F, J, 4, 4) array: every forward kinematics call made while
    preparing a trial (floor placement, palettes) is float32."""
    from studyapp.motion import fk
    from studyapp.render import pose

    calls = []

    def spy(skeleton, rotations, translations, dtype=np.float64):
        calls.append((np.dtype(dtype), len(rotations)))
        return fk.global_transforms(skeleton, rotations, translations, dtype)

    monkeypatch.setattr(pose, "global_transforms", spy)
    slot = pose.prepare_slot(avatar, read_bvh(MOTIONS / "zeggs_067_Speech_2_x_1_0_excerpt.bvh"), None)
    assert slot.palettes.dtype == np.float32 and slot.n_frames == 600
    big = [c for c in calls if c[1] > 1]
    assert big and all(dt == np.float32 for dt, _ in big), calls
