"""`studyapp convert SRC OUT.bvh --avatar builtin`: the motion as it plays on the avatar, as a BVH a user
opens in Blender. Checked with forward kinematics written here (scipy), against the study's own path."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from studyapp.cli import main
from studyapp.motion.bvh import read_bvh
from studyapp.motion.rest_frame import zero_at_rest
from studyapp.motion.rotations import quat_normalize
from studyapp.motion.skeleton import Motion, Skeleton
from studyapp.render.avatar import build_default_avatar
from studyapp.render.pose import to_avatar_skeleton

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples" / "motion"


def world_positions(motion: Motion, rest: bool = False) -> np.ndarray:
    sk = motion.skeleton
    if rest:
        quats = np.broadcast_to(sk.rest_rotations, (1,) + sk.rest_rotations.shape)
        trans = sk.offsets[None]
    else:
        quats, trans = motion.rotations, motion.translations
    f = quats.shape[0]
    rot = np.empty((f, sk.n_joints, 3, 3))
    pos = np.empty((f, sk.n_joints, 3))
    for j in range(sk.n_joints):
        local = Rotation.from_quat(quats[:, j]).as_matrix()
        p = int(sk.parents[j])
        if p < 0:
            rot[:, j], pos[:, j] = local, trans[:, j]
        else:
            rot[:, j] = rot[:, p] @ local
            pos[:, j] = pos[:, p] + np.einsum("fij,fj->fi", rot[:, p], trans[:, j])
    return pos


@pytest.mark.parametrize("name", ["bandai1_guide_normal_001.bvh", "zeggs_067_Speech_2_x_1_0_excerpt.bvh"])
def test_convert_onto_the_builtin_avatar_plays_what_the_study_plays(tmp_path, name, capsys):
    out = tmp_path / "on_avatar.bvh"
    assert main(["convert", str(SAMPLES / name), str(out), "--avatar", "builtin"]) == 0
    written = read_bvh(out)
    avatar = build_default_avatar()
    played = to_avatar_skeleton(avatar, read_bvh(SAMPLES / name))
    # every joint where the study puts it, every frame (6 decimals in metres)
    np.testing.assert_allclose(world_positions(written), world_positions(played), atol=2e-5)
    names = written.skeleton.names
    for bone in ("Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperArm", "LeftLowerArm", "LeftHand",
                 "RightUpperLeg", "RightLowerLeg", "RightFoot"):
        assert bone in names
    # its zero pose is the avatar's rest pose: Y up, facing +Z (the figure's left at +X)
    zero = world_positions(Motion.rest(written.skeleton, 1, 30.0))[0]
    rest = world_positions(Motion.rest(avatar.skeleton, 1, 30.0), rest=True)[0]
    np.testing.assert_allclose(zero, rest, atol=2e-5)
    assert zero[names.index("Head"), 1] > zero[names.index("Hips"), 1] + 0.4
    assert zero[names.index("LeftUpperArm"), 0] > zero[names.index("RightUpperArm"), 0] + 0.2


def test_zero_at_rest_keeps_every_world_position_of_a_rig_with_rest_rotations():
    rng = np.random.default_rng(3)
    n = 6
    rest = Rotation.random(n, random_state=4).as_quat()
    sk = Skeleton(tuple(f"j{k}" for k in range(n)), np.array([-1, 0, 1, 2, 1, 4]), rng.normal(size=(n, 3)),
                  rest_rotations=rest)
    rot = quat_normalize(rng.normal(size=(5, n, 4)))
    trans = np.broadcast_to(sk.offsets, (5, n, 3)).copy()
    trans[:, 0] += rng.normal(size=(5, 3))
    m = Motion(sk, 30.0, rot, trans)
    flat = zero_at_rest(m)
    np.testing.assert_allclose(world_positions(flat), world_positions(m), atol=1e-9)
    np.testing.assert_allclose(world_positions(Motion.rest(flat.skeleton, 1, 30.0))[0],
                               world_positions(Motion.rest(sk, 1, 30.0), rest=True)[0], atol=1e-9)
