"""The built-in avatar: a humanoid skeleton, sane skin weights and 52 ARKit morphs that move the right parts."""
from __future__ import annotations


import numpy as np

from studyapp.face.arkit import ARKIT_NAMES
from studyapp.motion.fk import rest_joint_positions
from studyapp.render.avatar import MAT_EYE, build_default_avatar, default_skeleton, vertex_normals


def test_skeleton_is_humanoid_tpose_in_metres():
    sk = default_skeleton()
    for name in ("Hips", "Spine", "Chest", "UpperChest", "Neck", "Head", "LeftShoulder", "LeftUpperArm",
                 "LeftLowerArm", "LeftHand", "RightHand", "LeftUpperLeg", "RightFoot"):
        assert name in sk.names
    for side in ("Left", "Right"):
        for f in ("Thumb", "Index", "Middle", "Ring", "Little"):
            for seg in ("Proximal", "Intermediate", "Distal"):
                assert f"{side}{f}{seg}" in sk.names
    assert all(sk.parents[j] < j for j in range(1, sk.n_joints))
    pos = rest_joint_positions(sk)
    # T-pose: shoulder, elbow and wrist at one height, left arm along +X
    arm = pos[[sk.index(n) for n in ("LeftUpperArm", "LeftLowerArm", "LeftHand")]]
    assert np.ptp(arm[:, 1]) < 1e-9 and np.all(np.diff(arm[:, 0]) > 0.2)
    assert 1.5 < pos[sk.index("Head")][1] < 1.7  # metres


def test_mesh_size_weights_and_bounds(avatar):
    assert 10_000 <= avatar.n_vertices <= 25_000
    assert np.allclose(avatar.weights.sum(1), 1.0, atol=1e-5)
    assert (avatar.weights >= 0).all()
    lo, hi = avatar.bounds()
    assert 1.70 < hi[1] < 1.85 and lo[1] > -0.01  # ~1.76 m tall, standing on y = 0
    assert abs(hi[0] + lo[0]) < 0.01  # symmetric T-pose
    n = np.linalg.norm(avatar.normals, axis=1)
    assert np.allclose(n, 1.0, atol=1e-3)


def test_skin_weights_follow_the_limbs(avatar):
    sk = avatar.skeleton
    v = avatar.vertices
    main = avatar.joints[np.arange(len(v)), avatar.weights.argmax(1)]
    # a vertex at the fingertip of the left index finger belongs to the distal bone
    tip = sk.index("LeftIndexDistal")
    near_tip = np.flatnonzero(main == tip)
    assert len(near_tip) > 20 and v[near_tip, 0].min() > 0.8
    # the elbow blends upper and lower arm smoothly: both have weight on vertices around the joint
    elbow_x = rest_joint_positions(sk)[sk.index("LeftLowerArm")][0]
    ring = np.flatnonzero((np.abs(v[:, 0] - elbow_x) < 0.01) & (v[:, 1] > 1.3))
    ua, la = sk.index("LeftUpperArm"), sk.index("LeftLowerArm")
    w_ua = (avatar.weights[ring] * (avatar.joints[ring] == ua)).sum(1)
    w_la = (avatar.weights[ring] * (avatar.joints[ring] == la)).sum(1)
    assert np.all(w_ua > 0.2) and np.all(w_la > 0.2)


def test_all_52_arkit_morphs_exist_and_move_something(avatar):
    assert avatar.morph_names == ARKIT_NAMES
    size = np.abs(avatar.morph_deltas).max(axis=(1, 2))
    assert (size > 5e-4).all(), [n for n, s in zip(ARKIT_NAMES, size) if s <= 5e-4]
    # the big ones are big
    for name in ("jawOpen", "eyeBlinkLeft", "mouthSmileLeft", "browInnerUp"):
        assert size[ARKIT_NAMES.index(name)] > 0.005, name


def test_morphs_only_touch_the_head(avatar):
    head = avatar.skeleton.index("Head")
    moved = np.abs(avatar.morph_deltas).max(axis=(0, 2)) > 0
    owner = avatar.joints[np.arange(avatar.n_vertices), avatar.weights.argmax(1)]
    assert set(np.unique(owner[moved])) <= {head, avatar.skeleton.index("Neck")}


def test_jaw_open_drops_the_chin_and_blinks_close_the_lids(avatar):
    v = avatar.vertices
    d = avatar.morph_deltas[ARKIT_NAMES.index("jawOpen")]
    head_y = rest_joint_positions(avatar.skeleton)[avatar.skeleton.index("Head")][1]
    owner = avatar.joints[np.arange(len(v)), avatar.weights.argmax(1)]
    on_head = owner == avatar.skeleton.index("Head")
    chin = np.flatnonzero(on_head & (np.abs(v[:, 0]) < 0.01) & (v[:, 2] > 0.05) & (v[:, 1] < head_y + 0.01))
    assert len(chin) and d[chin, 1].mean() < -0.015  # the chin drops by centimetres
    forehead = np.flatnonzero((np.abs(v[:, 0]) < 0.02) & (v[:, 1] > head_y + 0.13) & (v[:, 2] > 0.05))
    assert len(forehead) and np.abs(d[forehead]).max() == 0
    # blink: the left upper lid's lowest point goes below the eye centre, the right lid stays
    eye = np.flatnonzero(avatar.material == MAT_EYE)
    left_eye = eye[v[eye, 0] > 0]
    eye_centre_y = v[left_eye, 1].mean()
    blink = avatar.morph_deltas[ARKIT_NAMES.index("eyeBlinkLeft")]
    lid = np.flatnonzero(np.abs(blink).max(1) > 0)
    assert (v[lid, 0] > 0).all()
    assert (v[lid, 1] + blink[lid, 1]).min() < eye_centre_y - 0.005
    # smiles are mirror images of each other
    sl = avatar.morph_deltas[ARKIT_NAMES.index("mouthSmileLeft")]
    sr = avatar.morph_deltas[ARKIT_NAMES.index("mouthSmileRight")]
    assert np.isclose(np.abs(sl).sum(), np.abs(sr).sum(), rtol=0.05)
    assert v[np.abs(sl).max(1) > 1e-3, 0].mean() > 0 > v[np.abs(sr).max(1) > 1e-3, 0].mean()


def test_build_is_cached_and_read_only():
    a = build_default_avatar()
    b = build_default_avatar()
    assert a is b
    assert not a.vertices.flags.writeable


def test_vertex_normals_of_a_cube_face_point_outwards():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    n = vertex_normals(v, f)
    assert np.allclose(n, [0, 0, 1])
