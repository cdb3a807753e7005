"""Forward kinematics against hand-computed poses and a per-frame reference loop."""
from __future__ import annotations

import threading

import numpy as np

from studyapp.motion import fk
from studyapp.motion.beat import beat_skeleton
from studyapp.motion.rotations import euler_to_quat, quat_normalize, quat_to_matrix
from studyapp.motion.skeleton import Motion, Skeleton


def chain() -> Skeleton:
    return Skeleton(("root", "a", "b"), np.array([-1, 0, 1]), np.array([[0, 0, 0], [0, 1.0, 0], [0, 2.0, 0]]))


def test_two_bone_chain_by_hand():
    sk = chain()
    rot = np.tile([0.0, 0, 0, 1], (1, 3, 1))
    rot[0, 1] = euler_to_quat([90.0, 0, 0], "ZXY")  # joint a turns +90 about Z: +Y -> -X
    trans = np.broadcast_to(sk.offsets, (1, 3, 3)).copy()
    trans[0, 0] = [5.0, 0, 0]
    pos = fk.joint_positions(Motion(sk, 30, rot, trans))[0]
    np.testing.assert_allclose(pos, [[5, 0, 0], [5, 1, 0], [3, 1, 0]], atol=1e-12)
    g = fk.forward_kinematics(Motion(sk, 30, rot, trans))[0]
    np.testing.assert_allclose(g[2, 3], [0, 0, 0, 1])
    np.testing.assert_allclose(g[2, :3, :3], quat_to_matrix(rot[0, 1]), atol=1e-12)


def test_matches_per_frame_reference_on_beat():
    sk = beat_skeleton()
    rng = np.random.default_rng(3)
    rot = quat_normalize(rng.normal(size=(6, sk.n_joints, 4)))
    trans = np.broadcast_to(sk.offsets, (6, sk.n_joints, 3)).copy()
    trans[:, 0] = rng.normal(size=(6, 3)) * 10
    got = fk.forward_kinematics(Motion(sk, 15, rot, trans))
    for f in range(6):
        ref = np.zeros((sk.n_joints, 4, 4))
        for j in range(sk.n_joints):
            local = np.eye(4)
            local[:3, :3] = quat_to_matrix(rot[f, j])
            local[:3, 3] = trans[f, j]
            p = sk.parents[j]
            ref[j] = local if p < 0 else ref[p] @ local
        np.testing.assert_allclose(got[f], ref, atol=1e-9)
    np.testing.assert_allclose(fk.joint_positions(Motion(sk, 15, rot, trans)), got[..., :3, 3], atol=1e-12)


def test_rest_transforms_respect_rest_rotations_and_height():
    sk = chain()
    assert fk.figure_height(sk) == 3.0
    rest = np.tile([0.0, 0, 0, 1], (3, 1))
    rest[0] = euler_to_quat([0.0, 0, 90.0], "XYZ")  # root turned: chain lies along -X
    sk2 = Skeleton(sk.names, sk.parents, sk.offsets, rest_rotations=rest)
    np.testing.assert_allclose(fk.rest_joint_positions(sk2)[2], [-3, 0, 0], atol=1e-12)
    assert abs(fk.figure_height(sk2)) < 1e-12
    # BEAT is ~180 cm from toe to head end site
    assert 170 < fk.figure_height(beat_skeleton()) < 190


def test_unit_guess():
    assert fk.guess_unit_scale(181.5) == 0.01
    assert fk.guess_unit_scale(1.75) == 1.0
    assert fk.guess_unit_scale(63.0) is None


def _reference_transforms(sk: Skeleton, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """Float64, one joint at a time over all frames with plain 4x4 products (no levels, no blocks)."""
    f = rot.shape[0]
    local = np.zeros((f, sk.n_joints, 4, 4))
    local[..., :3, :3] = quat_to_matrix(rot)
    local[..., :3, 3] = trans
    local[..., 3, 3] = 1.0
    ref = np.empty_like(local)
    for j, p in enumerate(sk.parents):
        ref[:, j] = local[:, j] if p < 0 else ref[:, p] @ local[:, j]
    return ref


def test_float32_agrees_with_the_float64_reference_within_the_documented_tolerance():
    """700 frames cross the frame blocks (256) twice; BEAT-like angles (tens of degrees), hips moving by metres."""
    sk = beat_skeleton()
    rng = np.random.default_rng(5)
    f = 700
    rot = euler_to_quat(rng.normal(scale=30.0, size=(f, sk.n_joints, 3)), "XYZ")
    trans = np.broadcast_to(sk.offsets, (f, sk.n_joints, 3)).copy()
    trans[:, 0] += rng.normal(scale=100.0, size=(f, 3))
    ref = _reference_transforms(sk, rot, trans)
    got64 = fk.forward_kinematics(Motion(sk, 120, rot, trans))
    got32 = fk.forward_kinematics(Motion(sk, 120, rot, trans), dtype=np.float32)
    assert got64.dtype == np.float64 and got32.dtype == np.float32
    np.testing.assert_allclose(got64, ref, rtol=0, atol=1e-9)
    height = fk.figure_height(sk)
    pos_err = np.abs(got32[..., :3, 3] - ref[..., :3, 3]).max()
    rot_err = np.abs(got32[..., :3, :3] - ref[..., :3, :3]).max()
    assert pos_err <= fk.FLOAT32_TOLERANCE * height, pos_err / height
    assert rot_err <= fk.FLOAT32_TOLERANCE, rot_err
    np.testing.assert_array_equal(got32[..., 3, :], np.broadcast_to([0, 0, 0, 1], (f, sk.n_joints, 4)))


def test_any_forest_and_any_frame_count_matches_the_reference():
    """Random depth-first forests (several roots, fans, chains: every kind of level walk) at frame counts
    around the frame block, float64 and float32, transforms and positions."""
    rng = np.random.default_rng(11)
    for trial in range(12):
        j = int(rng.integers(1, 40))
        # mostly near parents (chains, fans), sometimes any earlier joint or a new root (-1)
        parents = np.array([-1] + [int(rng.integers(-1, k)) if rng.random() < 0.1
                                   else int(rng.integers(max(0, k - 3), k)) for k in range(1, j)])
        sk = Skeleton(tuple(f"j{k}" for k in range(j)), parents, rng.normal(size=(j, 3)))
        b = fk._FRAME_BLOCK
        f = int(rng.choice([0, 1, 2, b - 1, b, b + 1, 2 * b + 7]))
        rot = quat_normalize(rng.normal(size=(f, j, 4)))
        trans = rng.normal(size=(f, j, 3))
        ref = _reference_transforms(sk, rot, trans)
        got = fk.global_transforms(sk, rot, trans)
        assert got.shape == (f, j, 4, 4) and got.flags.c_contiguous
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9, err_msg=f"{trial}: {parents.tolist()}, {f} frames")
        np.testing.assert_allclose(fk.global_transforms(sk, rot, trans, np.float32), ref, rtol=0, atol=1e-4)
        np.testing.assert_allclose(fk.joint_positions(Motion(sk, 30, rot, trans)), ref[..., :3, 3], rtol=0, atol=1e-9)


def test_float32_on_real_beat_motion_is_within_a_hundredth_of_a_millimetre():
    """A real BEAT file (DiffSHEG output, centimetres, 75 joints 15 levels deep) and the ZEGGS capture
    (75 joints, 300 frames): float32 joint positions within 1e-3 file units (10 micrometres) of float64.

    Invisible: a figure 180 units tall drawn 600 pixels tall makes 1e-3 units 1/300 of a pixel, and the
    GPU skins every vertex in float32 anyway.
    """
    from motion_helpers import SAMPLES
    from studyapp.motion.bvh import read_bvh

    for path in (SAMPLES / "beat75_diffsheg_output_excerpt.bvh",
                 SAMPLES / "motion" / "zeggs_067_Speech_2_x_1_0_excerpt.bvh"):
        m = read_bvh(path)
        ref = _reference_transforms(m.skeleton, m.rotations, m.translations)
        got32 = fk.forward_kinematics(m, dtype=np.float32)
        np.testing.assert_allclose(fk.forward_kinematics(m), ref, rtol=0, atol=1e-9)
        height = fk.figure_height(m)
        assert 100 < height < 250  # centimetres: 1e-3 units is 10 micrometres
        err = np.abs(got32[..., :3, 3] - ref[..., :3, 3]).max()
        assert err <= 1e-3, (path.name, err)
        assert np.abs(got32[..., :3, :3] - ref[..., :3, :3]).max() <= 1e-5


def test_long_motions_split_over_threads_give_the_single_thread_result_bit_for_bit(monkeypatch):
    """Long motions are worked in frame ranges on several threads: every split (2-4 parts, ranges ending
    mid-block) writes exactly what one thread writes, in both precisions, and matches the reference."""
    sk = beat_skeleton()
    rng = np.random.default_rng(3)
    f = 4 * fk._PARALLEL_MIN_FRAMES + 37
    rot = quat_normalize(rng.normal(size=(f, sk.n_joints, 4)))
    trans = rng.normal(size=(f, sk.n_joints, 3))
    ref = _reference_transforms(sk, rot, trans)
    monkeypatch.setattr(fk, "THREADS", 1)
    assert fk._split(f) == [(0, f)]
    one = {dt: fk.global_transforms(sk, rot, trans, dt) for dt in (np.float64, np.float32)}
    for threads in (2, 3, 4):
        monkeypatch.setattr(fk, "THREADS", threads)
        parts = fk._split(f)
        assert len(parts) == threads and parts[0][0] == 0 and parts[-1][1] == f
        assert all(b == c for (_, b), (c, _) in zip(parts, parts[1:]))
        seen: set[str] = set()
        real_fill = fk._fill
        monkeypatch.setattr(fk, "_fill", lambda *a: (seen.add(threading.current_thread().name), real_fill(*a)))
        for dt in (np.float64, np.float32):
            got = fk.global_transforms(sk, rot, trans, dt)
            np.testing.assert_array_equal(got, one[dt])
        monkeypatch.setattr(fk, "_fill", real_fill)
        assert "studyapp-fk" in seen  # the parts really ran on other threads
    np.testing.assert_allclose(one[np.float64], ref, rtol=0, atol=1e-9)
