"""Real characters from public files on the avatar side: bone maps, facing, rigid parts, refusals.

The motion is a real BEAT file (DiffSHEG output) held in its rest pose with the left arm raised above the
head, so where the hand must be is known without the code under test: above the head, on the figure's
left side, which is the right of the picture when the figure faces the camera (seen from behind it would
be on the left).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from render_helpers import RELAXED, SAMPLES, posed, project, skin_cpu
from studyapp.errors import InputError
from studyapp.motion.bvh import read_bvh
from studyapp.motion.skeleton import Motion
from studyapp.render.pose import prepare_slot, skinning_palettes

AVATARS = SAMPLES / "avatars"

ROBOT_MAP = {
    "Abdomen": "Spine", "Torso": "Chest",
    "Shoulder.L": "LeftShoulder", "UpperArm.L": "LeftUpperArm", "LowerArm.L": "LeftLowerArm", "Palm2.L": "LeftHand",
    "Shoulder.R": "RightShoulder", "UpperArm.R": "RightUpperArm", "LowerArm.R": "RightLowerArm", "Palm2.R": "RightHand",
    "UpperLeg.L": "LeftUpperLeg", "LowerLeg.L": "LeftLowerLeg", "Foot.L": "LeftFoot",
    "UpperLeg.R": "RightUpperLeg", "LowerLeg.R": "RightLowerLeg", "Foot.R": "RightFoot",
}
CESIUM_MAP = {
    "Skeleton_torso_joint_1": "Hips", "Skeleton_torso_joint_2": "Spine", "torso_joint_3": "Chest",
    "Skeleton_neck_joint_1": "Neck", "Skeleton_neck_joint_2": "Head",
    "Skeleton_arm_joint_L__4_": "LeftUpperArm", "Skeleton_arm_joint_L__3_": "LeftLowerArm",
    "Skeleton_arm_joint_L__2_": "LeftHand",
    "Skeleton_arm_joint_R": "RightUpperArm", "Skeleton_arm_joint_R__2_": "RightLowerArm",
    "Skeleton_arm_joint_R__3_": "RightHand",
    "leg_joint_L_1": "LeftUpperLeg", "leg_joint_L_2": "LeftLowerLeg", "leg_joint_L_3": "LeftFoot",
    "leg_joint_R_1": "RightUpperLeg", "leg_joint_R_2": "RightLowerLeg", "leg_joint_R_3": "RightFoot",
}


def _fk_positions(skeleton, rotations, root_translation):
    """World joint positions of one frame, written here with scipy (BVH: zero rotations = offsets pose)."""
    n = skeleton.n_joints
    rot = [None] * n
    pos = np.zeros((n, 3))
    for j in range(n):
        r = Rotation.from_quat(rotations[j])
        p = skeleton.parents[j]
        if p < 0:
            rot[j], pos[j] = r, root_translation
        else:
            rot[j] = rot[p] * r
            pos[j] = pos[p] + rot[p].apply(skeleton.offsets[j])
    return pos


def beat_left_arm_up() -> Motion:
    """The BEAT sample's skeleton and hips, rest pose, left arm turned 80 degrees up, right arm 60 down."""
    src = read_bvh(SAMPLES / "beat75_diffsheg_output_excerpt.bvh", fps=15)
    m = Motion.rest(src.skeleton, n_frames=2, fps=15.0)
    m.translations[:] = src.translations[:1]
    for name, deg in (("LeftArm", 80), ("RightArm", 60)):
        j = src.skeleton.index(name)
        m.rotations[:, j] = Rotation.from_rotvec([0, 0, np.radians(deg)]).as_quat()
    return Motion(m.skeleton, m.fps, m.rotations, m.translations, source=src.source)


def test_the_beat_test_motion_puts_the_left_hand_above_the_head_on_the_left():
    m = beat_left_arm_up()
    sk = m.skeleton
    pos = _fk_positions(sk, m.rotations[0], m.translations[0, 0])
    hand, head, rhand = pos[sk.index("LeftHand")], pos[sk.index("Head")], pos[sk.index("RightHand")]
    # BEAT's left side is +X like the built-in avatar's; the hand ends above the head, the other one low
    assert hand[1] > head[1] and hand[0] > head[0] and rhand[1] < head[1]


def _render(renderer, avatar, motion, size=(360, 360), camera=None):
    from studyapp.render.context import OffscreenTarget
    from studyapp.render.scene import make_scene

    slot = prepare_slot(avatar, motion, None)
    scene = make_scene([slot], avatar)
    if camera is not None:  # the same view for pictures that are compared pixel by pixel
        scene.camera = camera
    target = OffscreenTarget(renderer.ctx, size)
    renderer.draw_trial(scene, 0.0, target.fbo)
    img = target.read_rgb().astype(int)
    target.release()
    return img, slot, scene


def _joint(avatar, bone_map, bone):
    names = [j for j, b in (bone_map or {}).items() if b == bone] or [bone]
    return avatar.skeleton.index(names[0])


@pytest.mark.gl
@pytest.mark.parametrize("file,bone_map", [("RobotExpressive.glb", ROBOT_MAP), ("CesiumMan.glb", CESIUM_MAP),
                                           ("cryptovoxels_vrm0.vrm", None)])
def test_real_character_faces_the_camera_and_raises_the_hand_the_motion_raises(renderer, file, bone_map, tmp_path):
    import matplotlib.image as mpimg

    from studyapp.render.scene import load_avatar

    avatar = load_avatar(AVATARS / file, bone_map)
    motion = beat_left_arm_up()
    img, slot, scene = _render(renderer, avatar, motion)
    rest_img, _, _ = _render(renderer, avatar, Motion.rest(motion.skeleton, 2, 15.0), camera=scene.camera)
    mpimg.imsave(tmp_path / "raised.png", img.astype(np.uint8))  # kept for a look when the test fails
    hand_j, head_j = _joint(avatar, bone_map, "LeftHand"), _joint(avatar, bone_map, "Head")
    hand, head = slot.joint_positions[0, hand_j], slot.joint_positions[0, head_j]
    assert hand[1] > head[1]  # above the head, as in the source
    h, w = img.shape[:2]
    (hx, hy), (kx, ky) = project(scene.camera, np.array([hand, head], float), (0, 0, w, h), h)
    # facing the camera: the figure's left hand is on the right of the picture
    assert hx > kx + 0.03 * w and hy < ky
    # the hand is drawn there now, and was not at rest
    r, c = int(round(hy)), int(round(hx))
    win = (slice(max(r - 4, 0), r + 5), slice(max(c - 4, 0), c + 5))
    changed = np.abs(img[win] - rest_img[win]).sum(-1) > 40
    assert changed.mean() > 0.3, f"hand not drawn at ({c}, {r}); see {tmp_path / 'raised.png'}"
    # and the picture's upper right holds more of the changed figure than its upper left (the raised arm)
    diff = np.abs(img - rest_img).sum(-1) > 40
    top = diff[: int(ky)]
    assert top[:, int(kx):].sum() > 3 * top[:, : int(kx)].sum()


def _turned_180(avatar):
    """The built-in avatar rebuilt facing -Z (geometry, skeleton root and binds turned about +Y)."""
    from studyapp.motion.fk import rest_global_transforms
    from studyapp.motion.skeleton import Skeleton
    from studyapp.render.avatar import Avatar

    turn = Rotation.from_euler("y", 180, degrees=True)
    sk = avatar.skeleton
    offsets = sk.offsets.copy()
    rest_q = sk.rest_rotations.copy()
    for r in np.flatnonzero(sk.parents < 0):
        offsets[r] = turn.apply(offsets[r])
        rest_q[r] = (turn * Rotation.from_quat(rest_q[r])).as_quat()
    sk2 = Skeleton(names=sk.names, parents=sk.parents, offsets=offsets, unit_scale=1.0, rest_rotations=rest_q)
    return Avatar(skeleton=sk2, vertices=turn.apply(avatar.vertices), normals=turn.apply(avatar.normals),
                  indices=avatar.indices, colors=avatar.colors, joints=avatar.joints, weights=avatar.weights,
                  inverse_bind=np.linalg.inv(rest_global_transforms(sk2)), morph_deltas=turn.apply(
                      avatar.morph_deltas.reshape(-1, 3)).reshape(avatar.morph_deltas.shape),
                  material=avatar.material, name="turned")


@pytest.mark.gl
def test_character_facing_minus_z_is_turned_to_face_the_camera(renderer, avatar, tmp_path):
    from studyapp.render.gltf import export_glb, load_gltf

    turned = _turned_180(avatar)
    # as stored, the turned figure's left hip is on -X: it faces -Z (the three.js Soldier's case)
    sk = turned.skeleton
    assert turned.vertices[:, 2].min() < -0.1  # the nose now points to -Z
    path = export_glb(turned, tmp_path / "soldier_like.glb")
    loaded = load_gltf(path)
    assert any("turned" in n and "-Z" in n for n in loaded.notes)
    motion = beat_left_arm_up()
    want, _, _ = _render(renderer, avatar, motion)
    got, _, _ = _render(renderer, loaded, motion)
    as_stored, _, _ = _render(renderer, turned, motion)  # what showing it unturned would give
    # the loaded character renders as the built-in one does, face towards the camera; unturned it would not
    assert np.abs(got - want).mean() < 1.0
    assert np.abs(as_stored - want).mean() > 3 * max(np.abs(got - want).mean(), 0.5)
    # the nose (the built-in head's most forward vertex) is nearest the camera again
    nose = int(np.argmax(avatar.vertices[:, 2] * (avatar.vertices[:, 1] > 1.4)))
    assert loaded.vertices[nose, 2] == pytest.approx(avatar.vertices[nose, 2], abs=1e-4)
    assert sk.n_joints == loaded.skeleton.n_joints


def test_vrm1_rigid_parts_move_with_their_bone():
    from studyapp.render.gltf import load_gltf

    av = load_gltf(AVATARS / "VRMC_vrm_expressions_isBinary_Overrides.vrm")
    assert "Head" in av.skeleton.names and av.skeleton.n_joints == 22  # the humanoid bones, not one joint
    head = av.skeleton.index("Head")
    # every vertex of this file hangs (rigidly, through non-joint nodes) from the head
    assert (av.joints[:, 0] == head).all() and np.allclose(av.weights[:, 0], 1)
    rest = skin_cpu(av, skinning_palettes(av, Motion.rest(av.skeleton, 1))[0])
    assert np.allclose(rest, av.vertices, atol=1e-6)
    motion = posed(av, {"Head": (0, 0, 30)})
    moved = skin_cpu(av, skinning_palettes(av, motion)[0])
    # independently: a rigid turn of 30 degrees about the head joint's local Z (world Z: the rest is unrotated)
    from studyapp.motion.fk import rest_joint_positions

    pivot = rest_joint_positions(av.skeleton)[head]
    want = Rotation.from_rotvec([0, 0, np.radians(30)]).apply(av.vertices - pivot) + pivot
    assert np.abs(moved - av.vertices).max() > 0.05
    assert np.allclose(moved, want, atol=1e-5)


@pytest.mark.gl
def test_vrm1_props_render_and_follow_the_head(renderer):
    from studyapp.render.scene import load_avatar

    av = load_avatar(AVATARS / "VRMC_vrm_expressions_isBinary_Overrides.vrm")
    img, _, scene = _render(renderer, av, Motion.rest(av.skeleton, 2, 15.0))
    tilted, _, _ = _render(renderer, av, posed(av, {"Head": (0, 0, 30)}, n_frames=2), camera=scene.camera)
    green = (img[..., 1] > 150) & (img[..., 0] < 120) & (img[..., 2] < 120)  # the 'Validation Window' quad
    assert green.sum() > 500
    assert (np.abs(tilted - img).sum(-1) > 60).mean() > 0.01


def _glb_node_positions(path) -> dict[str, np.ndarray]:
    """World positions of a GLB's nodes by name, read here from its JSON chunk (TRS only, scipy rotations)."""
    import json
    import struct

    raw = path.read_bytes()
    length = struct.unpack_from("<I", raw, 12)[0]
    nodes = json.loads(raw[20:20 + length])["nodes"]
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}

    def world(i):
        n = nodes[i]
        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat(n.get("rotation", [0, 0, 0, 1])).as_matrix() * n.get("scale", [1, 1, 1])
        m[:3, 3] = n.get("translation", [0, 0, 0])
        return m if i not in parent else world(parent[i]) @ m

    return {n.get("name", str(i)): world(i)[:3, 3] for i, n in enumerate(nodes)}


def test_fox_is_refused_as_not_humanoid_in_one_line_even_with_its_legs_mapped(tmp_path, capsys):
    """A four-legged figure is refused as such, with or without a bone map: mapped by name, its legs made it
    'humanoid' and human motion rendered the fox stood on end."""
    from studyapp.cli import main
    from studyapp.render.scene import load_avatar

    pos = _glb_node_positions(AVATARS / "Fox.glb")
    up = pos["b_Head_05"] - pos["b_Hip_01"]
    lean = np.degrees(np.arccos(up[1] / np.linalg.norm(up)))
    assert 60 < lean < 85  # the fox's spine runs along its body, not up
    legs = {"b_LeftLeg01_015": "LeftUpperLeg", "b_LeftLeg02_016": "LeftLowerLeg", "b_LeftFoot01_017": "LeftFoot",
            "b_RightLeg01_019": "RightUpperLeg", "b_RightLeg02_020": "RightLowerLeg", "b_RightFoot01_021": "RightFoot"}
    for bone_map in (None, legs):
        with pytest.raises(InputError) as err:
            load_avatar(AVATARS / "Fox.glb", bone_map)
        text = str(err.value)
        assert "Fox.glb: not a humanoid avatar: its rest pose does not stand upright" in text and "\n" not in text
        assert f"hips to head {lean:.0f} degrees from up" in text and "use a humanoid avatar" in text
    out = tmp_path / "fox.png"
    code = main(["view", str(SAMPLES / "motion" / "lafan1_walk1_subject1_excerpt.bvh"), "--avatar",
                 str(AVATARS / "Fox.glb"), "--avatar-bone-map", ",".join(f"{j}={b}" for j, b in legs.items()),
                 "--offscreen", "--out", str(out)])
    err_lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("error:")]
    assert code != 0 and not out.exists() and len(err_lines) == 1 and "not stand upright" in err_lines[0]


def test_avatar_bone_map_is_kept_and_used_for_retargeting():
    from studyapp.render.scene import load_avatar

    av = load_avatar(AVATARS / "RobotExpressive.glb", ROBOT_MAP)
    assert av.bone_map["UpperArm.L"] == "LeftUpperArm" and av.source.endswith("RobotExpressive.glb")
    with pytest.raises(InputError, match=r"RobotExpressive.glb.*not a humanoid avatar.*LeftHand"):
        load_avatar(AVATARS / "RobotExpressive.glb")
    with pytest.raises(InputError, match=r"RobotExpressive.glb, \[avatar.bone_map\] Tail: joint 'Tail' is not"):
        load_avatar(AVATARS / "RobotExpressive.glb", {**ROBOT_MAP, "Tail": "UpperChest"})
    # without the map's legs the retargeted pose differs: the map reaches the retargeting
    slot = prepare_slot(av, beat_left_arm_up(), None)
    up = slot.joint_positions[0, av.skeleton.index("Palm2.L")]
    assert up[1] > slot.joint_positions[0, av.skeleton.index("Head")][1]


def test_relaxed_pose_helper_still_applies_to_the_loaded_vrm0():
    # VRM 0 bones get Unity names, so the test helpers written for the built-in avatar pose it too
    from studyapp.render.gltf import load_gltf

    av = load_gltf(AVATARS / "cryptovoxels_vrm0.vrm")
    assert av.bone_map == {}
    m = posed(av, RELAXED)
    assert np.isfinite(skinning_palettes(av, m)).all()
    assert any("turned" in n for n in av.notes)


def test_file_without_skin_or_vrm_gets_its_skeleton_from_the_mesh_ancestors(tmp_path):
    import json

    from test_gltf import bar_gltf, write_gltf
    from studyapp.render.gltf import load_gltf

    gltf, data = bar_gltf()
    g = json.loads(json.dumps(gltf))
    del g["skins"]
    del g["nodes"][3]["skin"]
    g["nodes"][2]["children"] = [3]  # the mesh hangs from Tip, 0.2 m above Root
    g["scenes"][0]["nodes"] = [0]
    av = load_gltf(write_gltf(tmp_path, g, data))
    assert av.skeleton.names == ("Armature", "Root", "Tip")
    assert (av.joints[:, 0] == av.skeleton.index("Tip")).all()
    # the mesh sits 0.2 m higher than in the skinned file (its node is under Tip) and turns with Root
    plain = load_gltf(write_gltf(tmp_path, *bar_gltf(), "plain.gltf"))
    assert np.allclose(av.vertices, plain.vertices + [0, 0.2, 0], atol=1e-6)
    moved = skin_cpu(av, skinning_palettes(av, posed(av, {"Root": (90, 0, 0)}))[0])
    want = Rotation.from_rotvec([np.pi / 2, 0, 0]).apply(av.vertices)  # Root sits at the origin
    assert np.allclose(moved, want, atol=1e-5)


def test_trial_scene_builder_passes_the_design_bone_map_to_the_avatar():
    from types import SimpleNamespace

    from studyapp.render.scene import build_trial_scene

    m = beat_left_arm_up()
    media = SimpleNamespace(motions=(m, m, m), face=None, avatar=str(AVATARS / "RobotExpressive.glb"),
                            avatar_bone_map=dict(ROBOT_MAP), labels=("A", "B", "C"), name_maps=({}, {}, {}),
                            duration_s=m.duration)  # what scene.TrialSource declares
    scene = build_trial_scene(None, media)
    av = scene.avatars[0]
    assert av.bone_map["Palm2.L"] == "LeftHand"
    hand, head = av.skeleton.index("Palm2.L"), av.skeleton.index("Head")
    for slot in scene.slots:
        assert slot.joint_positions[0, hand, 1] > slot.joint_positions[0, head, 1]


def _mixamo_named(avatar, prefix: str = "mixamorig:"):
    """The built-in avatar under Mixamo's bone names (an Xbot-like character), nothing else changed."""
    from studyapp.motion.skeleton import Skeleton
    from studyapp.render.avatar import Avatar

    parts = {"Chest": "Spine1", "UpperChest": "Spine2", "UpperArm": "Arm", "LowerArm": "ForeArm",
             "UpperLeg": "UpLeg", "LowerLeg": "Leg", "Toes": "ToeBase"}
    fingers = {"Thumb": "Thumb", "Index": "Index", "Middle": "Middle", "Ring": "Ring", "Little": "Pinky"}

    def rename(n: str) -> str:
        for f, mf in fingers.items():
            for k, ph in enumerate(("Proximal", "Intermediate", "Distal"), start=1):
                for side in ("Left", "Right"):
                    if n == f"{side}{f}{ph}":
                        return f"{prefix}{side}Hand{mf}{k}"
        for a, b in parts.items():
            if n.endswith(a):
                return prefix + n[: -len(a)] + b
        return prefix + n

    sk = avatar.skeleton
    sk2 = Skeleton(tuple(rename(n) for n in sk.names), sk.parents, sk.offsets, unit_scale=1.0,
                   rest_rotations=sk.rest_rotations)
    return Avatar(skeleton=sk2, vertices=avatar.vertices, normals=avatar.normals, indices=avatar.indices,
                  colors=avatar.colors, joints=avatar.joints, weights=avatar.weights, inverse_bind=avatar.inverse_bind,
                  morph_deltas=avatar.morph_deltas, material=avatar.material, name="xbot-like")


@pytest.mark.gl
def test_mixamo_named_character_is_recognised_without_a_map_and_plays_as_the_builtin(renderer, avatar, tmp_path):
    """An Xbot-like character (``mixamorig:`` bones, any prefix number) needs no [avatar.bone_map]."""
    from studyapp.render.gltf import export_glb
    from studyapp.render.scene import load_avatar

    path = export_glb(_mixamo_named(avatar, "mixamorig7:"), tmp_path / "xbot_like.glb")
    loaded = load_avatar(str(path))
    assert "mixamorig7:LeftForeArm" in loaded.skeleton.names and not loaded.bone_map
    motion = beat_left_arm_up()
    want, _, scene = _render(renderer, avatar, motion)
    got, _, _ = _render(renderer, loaded, motion, camera=scene.camera)
    rest, _, _ = _render(renderer, loaded, Motion.rest(motion.skeleton, 2, 15.0), camera=scene.camera)
    assert np.abs(got - want).mean() < 1.0                       # the same picture: every bone found
    assert np.abs(rest - want).mean() > 3 * max(np.abs(got - want).mean(), 0.5)  # and the motion shows
