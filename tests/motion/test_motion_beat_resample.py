"""BEAT skeleton in code vs the real sample, upper-body motion, resampling and trimming."""
from __future__ import annotations

import numpy as np
import pytest

from motion_helpers import BEAT_SAMPLE
from studyapp.errors import InputError
from studyapp.motion.beat import BEAT_JOINTS, BEAT_UPPER_BODY, beat_motion_from_upper_body, beat_skeleton
from studyapp.motion.bvh import read_bvh
from studyapp.motion.fk import joint_positions
from studyapp.motion.resample import check_duration, resample, trim
from studyapp.motion.rotations import euler_to_quat, quat_to_matrix
from studyapp.motion.skeleton import Motion


def test_beat_skeleton_equals_sample_hierarchy():
    sample = read_bvh(BEAT_SAMPLE).skeleton
    sk = beat_skeleton()
    assert sk.names == sample.names == BEAT_JOINTS and len(BEAT_JOINTS) == 75
    np.testing.assert_array_equal(sk.parents, sample.parents)
    np.testing.assert_allclose(sk.offsets, sample.offsets, atol=1e-6)
    assert sk.channels == sample.channels
    assert sorted(sk.end_sites) == sorted(sample.end_sites)


def test_upper_body_is_beats_47_joint_list():
    assert len(BEAT_UPPER_BODY) == 47 == len(set(BEAT_UPPER_BODY))
    assert BEAT_UPPER_BODY[:7] == ("Spine", "Neck", "Neck1", "RightShoulder", "RightArm", "RightForeArm", "RightHand")
    assert BEAT_UPPER_BODY[25] == "LeftShoulder"
    assert not any(n.endswith("4") or "Leg" in n or n in ("Hips", "Head") for n in BEAT_UPPER_BODY)


def test_motion_from_upper_body_drives_only_those_joints():
    f = 4
    rot = np.tile([0.0, 0, 0, 1], (f, 47, 1))
    arm = BEAT_UPPER_BODY.index("RightArm")
    rot[:, arm] = euler_to_quat([0.0, 0.0, 90.0], "XYZ")
    m = beat_motion_from_upper_body(rot, fps=15, root=(0.0, 100.0, 0.0))
    assert m.rotations.shape == (f, 75, 4) and m.fps == 15
    np.testing.assert_allclose(m.translations[:, 0], [[0, 100, 0]] * f)
    pos = joint_positions(m)
    sk = m.skeleton
    # arm turned 90 degrees about Z: the forearm, lying along -X at rest, now hangs along -Y
    d = pos[0, sk.index("RightForeArm")] - pos[0, sk.index("RightArm")]
    np.testing.assert_allclose(d, [0.0, -29.35075, 0.0], atol=1e-4)
    untouched = [j for j, n in enumerate(sk.names) if n not in BEAT_UPPER_BODY]
    np.testing.assert_allclose(m.rotations[:, untouched], np.tile([0.0, 0, 0, 1], (f, len(untouched), 1)))
    with pytest.raises(ValueError):
        beat_motion_from_upper_body(np.zeros((3, 46, 4)))


def _turning(fps: float, seconds: float) -> Motion:
    sk = beat_skeleton()
    n = int(round(seconds * fps))
    t = np.arange(n) / fps
    m = Motion.rest(sk, n_frames=n, fps=fps)
    m.rotations[:, 1] = euler_to_quat(np.stack([np.zeros(n), np.zeros(n), 60.0 * t], axis=1), "XYZ")
    m.translations[:, 0, 0] = 10.0 * t
    return m


def test_resample_keeps_duration_and_interpolates():
    m = _turning(15, 2.0)
    up = resample(m, 120)
    assert up.n_frames == 240 and up.duration == pytest.approx(2.0)
    # at t = 1/30 s (between two 15 fps frames) the spine has turned 2 degrees and hips moved 1/3
    expect = quat_to_matrix(euler_to_quat([0.0, 0.0, 2.0], "XYZ"))
    np.testing.assert_allclose(quat_to_matrix(up.rotations[4, 1]), expect, atol=1e-12)
    assert up.translations[4, 0, 0] == pytest.approx(10.0 / 30)
    down = resample(_turning(120, 2.0), 15)
    assert down.n_frames == 30
    np.testing.assert_allclose(down.translations[:, 0, 0], 10.0 * np.arange(30) / 15, atol=1e-12)


def test_trim_and_duration_check():
    m = _turning(30, 2.0)
    part = trim(m, 0.5, 1.5)
    assert part.n_frames == 30
    assert part.translations[0, 0, 0] == pytest.approx(5.0)
    check_duration(m, 2.02, 0.05, "clip")
    m.source = "clip.bvh"
    with pytest.raises(InputError) as err:
        check_duration(m, 3.0, 0.05, "motion of clip 1")
    assert err.value.path == "clip.bvh" and "2.000 s" in err.value.problem and "motion of clip 1" in err.value.problem
