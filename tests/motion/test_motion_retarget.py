"""Retargeting by humanoid names: identity, other rigs, A-pose and turned rest poses, name maps."""
from __future__ import annotations

import numpy as np
import pytest

from motion_helpers import BEAT_SAMPLE, MIXAMO_SAMPLE
from studyapp.errors import InputError
from studyapp.motion.beat import beat_skeleton
from studyapp.motion.bvh import read_bvh
from studyapp.motion.fk import forward_kinematics, joint_positions
from studyapp.motion.humanoid import HUMANOID_BONES, HUMANOID_PARENT, MIXAMO_MAP, REQUIRED_BONES, VRM0_MAP, VRM1_MAP
from studyapp.motion.retarget import detect_name_map, retarget
from studyapp.motion.rotations import euler_to_quat, quat_normalize
from studyapp.motion.skeleton import Motion, Skeleton


def unity_skeleton() -> Skeleton:
    rng = np.random.default_rng(5)
    names = list(HUMANOID_BONES)
    parents = [-1 if HUMANOID_PARENT[n] is None else names.index(HUMANOID_PARENT[n]) for n in names]
    offsets = rng.normal(size=(len(names), 3)) + [0.0, 5.0, 0.0]
    for side, sign in (("Left", 1.0), ("Right", -1.0)):  # give it a left and a right so facing is defined
        offsets[names.index(f"{side}UpperLeg")] = [sign * 10.0, -5.0, 0.0]
        offsets[names.index(f"{side}Shoulder")] = [sign * 8.0, 2.0, 0.0]
    return Skeleton(tuple(names), np.array(parents), offsets)


def arm_raise(frames: int = 10) -> Motion:
    """BEAT skeleton raising the right arm from T-pose to straight up, hips drifting along +X."""
    sk = beat_skeleton()
    m = Motion.rest(sk, n_frames=frames, fps=15)
    ang = np.zeros((frames, 3))
    ang[:, 2] = np.linspace(0.0, -90.0, frames)
    m.rotations[:, sk.index("RightArm")] = euler_to_quat(ang, "XYZ")
    m.translations[:, 0, 0] = np.linspace(0.0, 20.0, frames)
    return m


def test_detect_name_maps():
    beat = detect_name_map(beat_skeleton())
    assert beat["RightHandPinky1"] == "RightLittleProximal"
    # Neck + Neck1 -> Neck: the upper joint takes the bone, Neck's rotation is composed into it
    assert beat["Neck1"] == "Neck" and "Neck" not in beat and "Spine2" not in beat
    sk = beat_skeleton()
    no_neck1 = sk.subset([j for j, n in enumerate(sk.names) if n != "Neck1"])
    assert detect_name_map(no_neck1)["Neck"] == "Neck"
    mix = detect_name_map(read_bvh(MIXAMO_SAMPLE).skeleton)
    assert mix["mixamorig:Spine2"] == "UpperChest" and mix["mixamorig:LeftForeArm"] == "LeftLowerArm"
    assert set(REQUIRED_BONES) <= set(mix.values())
    for table, key, bone in ((VRM0_MAP, "J_Bip_L_UpperArm", "LeftUpperArm"), (VRM1_MAP, "leftThumbMetacarpal", "LeftThumbProximal")):
        sk = Skeleton(tuple(table), np.array([-1] + [0] * (len(table) - 1)), np.zeros((len(table), 3)))
        assert detect_name_map(sk)[key] == bone
    # case-insensitive
    upper = Skeleton(tuple(k.upper() for k in MIXAMO_MAP), np.array([-1] + [0] * (len(MIXAMO_MAP) - 1)), np.zeros((len(MIXAMO_MAP), 3)))
    assert detect_name_map(upper)["MIXAMORIG:HIPS"] == "Hips"


def test_identity_retarget_reproduces_world_positions_when_all_joints_map():
    sk = unity_skeleton()
    rng = np.random.default_rng(2)
    rot = quat_normalize(rng.normal(size=(5, sk.n_joints, 4)))
    trans = np.broadcast_to(sk.offsets, (5, sk.n_joints, 3)).copy()
    trans[:, 0] += rng.normal(size=(5, 3))
    src = Motion(sk, 30, rot, trans)
    copy = Skeleton(sk.names, sk.parents, sk.offsets.copy())
    out = retarget(src, copy)
    np.testing.assert_allclose(joint_positions(out), joint_positions(src), atol=1e-9)


def test_beat_onto_itself():
    src = read_bvh(BEAT_SAMPLE, fps=15)
    out = retarget(src, beat_skeleton())
    g_s, g_t = forward_kinematics(src), forward_kinematics(out)
    mapped = [src.skeleton.index(j) for j in detect_name_map(src.skeleton)]
    # every mapped joint ends up with the source's world orientation
    np.testing.assert_allclose(g_t[:, mapped, :3, :3], g_s[:, mapped, :3, :3], atol=1e-9)
    # and when the joints without a humanoid counterpart hold still, positions match everywhere
    still = [j for j in range(75) if j not in mapped]
    src.rotations[:, still] = [0.0, 0.0, 0.0, 1.0]
    out = retarget(src, beat_skeleton())
    np.testing.assert_allclose(joint_positions(out), joint_positions(src), atol=1e-9)
    assert out.fps == 15 and out.n_frames == src.n_frames


def _arm_direction(m: Motion, shoulder: str, hand: str) -> np.ndarray:
    p = joint_positions(m)
    d = p[:, m.skeleton.index(hand)] - p[:, m.skeleton.index(shoulder)]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_beat_to_mixamo_hands_follow():
    src = arm_raise()
    mix = read_bvh(MIXAMO_SAMPLE).skeleton
    out = retarget(src, mix)
    assert out.skeleton is mix and out.n_frames == 10
    d_s = _arm_direction(src, "RightArm", "RightHand")
    d_t = _arm_direction(out, "mixamorig:RightArm", "mixamorig:RightHand")
    assert np.all(np.sum(d_s * d_t, axis=1) > 0.995)
    # the right hand rises from shoulder height to above the head
    p = joint_positions(out)
    hand, shoulder = p[:, mix.index("mixamorig:RightHand"), 1], p[:, mix.index("mixamorig:RightArm"), 1]
    assert abs(hand[0] - shoulder[0]) < 3 and hand[-1] - shoulder[-1] > 40
    assert np.all(np.diff(hand) > 0)
    # hips move by the source displacement scaled by hip height ratio (both cm, similar size)
    hips = p[:, 0]
    assert 15 < hips[-1, 0] - hips[0, 0] < 25


def test_a_pose_target_with_rest_rotations_and_unit_change():
    sk = beat_skeleton()
    rest = np.tile([0.0, 0, 0, 1], (sk.n_joints, 1))
    # glTF-like rig in metres whose arms hang 45 degrees down in the bind pose
    rest[sk.index("RightArm")] = euler_to_quat([0.0, 0.0, 45.0], "XYZ")
    rest[sk.index("LeftArm")] = euler_to_quat([0.0, 0.0, -45.0], "XYZ")
    target = Skeleton(sk.names, sk.parents, sk.offsets * 0.01, sk.channels, unit_scale=1.0, rest_rotations=rest)
    src = arm_raise()
    out = retarget(src, target)
    d_s = _arm_direction(src, "RightArm", "RightHand")
    d_t = _arm_direction(out, "RightArm", "RightHand")
    np.testing.assert_allclose(d_t, d_s, atol=1e-9)
    # rest pose of the source (T-pose) shows as a T-pose on the A-pose rig
    np.testing.assert_allclose(d_t[0], [-1.0, 0.0, 0.0], atol=1e-6)
    # hips drift 20 cm in the source -> 0.2 m on the target
    p = joint_positions(out)
    assert p[-1, 0, 0] - p[0, 0, 0] == pytest.approx(0.2, rel=1e-6)
    # joints the target cannot map keep their rest local rotation
    np.testing.assert_allclose(out.rotations[:, sk.index("Spine2")], np.tile([0.0, 0, 0, 1], (10, 1)))


def test_target_facing_minus_z():
    sk = beat_skeleton()
    rest = np.tile([0.0, 0, 0, 1], (sk.n_joints, 1))
    rest[0] = euler_to_quat([0.0, 180.0, 0.0], "XYZ")  # VRM 0.x style: the whole rig faces -Z
    target = Skeleton(sk.names, sk.parents, sk.offsets, sk.channels, rest_rotations=rest)
    src = Motion.rest(sk, n_frames=2, fps=15)
    # right arm swings forward (+Z for the BEAT source) in frame 1
    src.rotations[1, sk.index("RightArm")] = euler_to_quat([0.0, 90.0, 0.0], "XYZ")
    d_s = _arm_direction(src, "RightArm", "RightHand")
    assert d_s[1, 2] > 0.99
    out = retarget(src, target)
    d_t = _arm_direction(out, "RightArm", "RightHand")
    assert d_t[1, 2] < -0.99  # forward for the turned rig
    # the source moving along +X (its left) moves the turned target along -X (its left)
    src.translations[1, 0] = [10.0, 0, 0]
    assert joint_positions(retarget(src, target))[1, 0, 0] == pytest.approx(-10.0)


def test_partial_name_map_overrides_builtin_and_missing_bones_are_listed():
    sk = beat_skeleton()
    # names no rule can read (neither a built-in map nor the fuzzy word matching)
    names = tuple({"RightForeArm": "Bone_017", "LeftUpLeg": "Bone_042"}.get(n, n) for n in sk.names)
    odd = Skeleton(names, sk.parents, sk.offsets, sk.channels)
    src = Motion(odd, 15, arm_raise().rotations, arm_raise().translations)
    with pytest.raises(InputError) as err:
        retarget(src, beat_skeleton())
    assert "RightLowerArm" in err.value.problem and "LeftUpperLeg" in err.value.problem
    assert "Bone_017" in err.value.problem and "name_map" in err.value.problem  # the file's joints are listed
    out = retarget(src, beat_skeleton(), name_map={"Bone_017": "RightLowerArm", "Bone_042": "LeftUpperLeg"})
    np.testing.assert_allclose(
        _arm_direction(out, "RightArm", "RightHand"), _arm_direction(arm_raise(), "RightArm", "RightHand"), atol=1e-9
    )
    # an override can also re-point a bone the built-in map already had (Spine2 instead of Spine1)
    out2 = retarget(arm_raise(), beat_skeleton(), name_map={"Spine2": "Chest"})
    assert np.isfinite(out2.rotations).all()
    with pytest.raises(InputError, match="not a humanoid bone"):
        retarget(arm_raise(), beat_skeleton(), name_map={"Spine2": "Ribcage"})
    with pytest.raises(InputError, match="NoSuchJoint"):
        retarget(arm_raise(), beat_skeleton(), name_map={"NoSuchJoint": "Chest"})


def test_rest_frames_are_measured_once_per_rig_and_change_no_result(monkeypatch):
    """A trial's three slots share a source rig and an avatar: the second retarget onto it reuses the rest-pose
    frames (fewer bone_axes calls) and gives the same arrays as a fresh computation, bit for bit."""
    import importlib

    rt = importlib.import_module("studyapp.motion.retarget")
    target = read_bvh(MIXAMO_SAMPLE).skeleton
    a = read_bvh(BEAT_SAMPLE, fps=15)
    rng = np.random.default_rng(11)
    other = read_bvh(BEAT_SAMPLE, fps=15).skeleton  # another file of the same rig: another object
    assert other is not a.skeleton
    b = Motion(other, a.fps, quat_normalize(a.rotations + rng.normal(scale=0.05, size=a.rotations.shape)),
               a.translations + rng.normal(size=a.translations.shape))
    calls = []
    real = rt.bone_axes
    monkeypatch.setattr(rt, "bone_axes", lambda *args, **kw: calls.append(1) or real(*args, **kw))

    rt._REST_CACHE.clear()
    fresh_b = retarget(b, target)  # rest frames measured for b's rig and the target
    rt._REST_CACHE.clear()
    first_a = retarget(a, target)
    n_first = len(calls)
    again_b = retarget(b, target)  # both rigs' rest frames reused (a different skeleton object, same rig)
    assert len(calls) - n_first < n_first
    np.testing.assert_array_equal(again_b.rotations, fresh_b.rotations)
    np.testing.assert_array_equal(again_b.translations, fresh_b.translations)
    np.testing.assert_array_equal(retarget(a, target).rotations, first_a.rotations)
