"""SMPL, SMPL-H and SMPL-X files read as they come, played on the built-in avatar.

Every check of where a limb points uses forward kinematics written here with scipy, either on the avatar
motion studyapp makes or straight from the file's axis-angle numbers (the SMPL chain: a joint's world
rotation is its parent's times its own axis-angle, rest frames aligned with the world), never studyapp's FK.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motion_helpers import scipy_fk
from studyapp.cli import main
from studyapp.errors import InputError
from studyapp.motion.bvh import read_bvh
from studyapp.motion.io import load_motion, summarize_motion
from studyapp.motion.smpl import builtin_rest_joints, parents, recognise_smpl
from studyapp.render.avatar import build_default_avatar
from studyapp.render.pose import to_avatar_skeleton

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples" / "motion"
BEAT2 = SAMPLES / "beat2_smplx_2_scott_0_1_1_excerpt.npz"
SMPL_PARENTS_22 = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19]  # samples README
L_SHOULDER, L_ELBOW, L_WRIST, R_SHOULDER, R_ELBOW, R_WRIST = 16, 18, 20, 17, 19, 21


world = scipy_fk  # forward kinematics written apart from studyapp.motion.fk


def smpl_world_rotations(poses: np.ndarray) -> np.ndarray:
    """``(F, 22, 3, 3)`` world rotations of the 22 body joints, straight from ``(F, J*3)`` axis-angle."""
    aa = poses.reshape(len(poses), -1, 3)
    g = np.empty((len(poses), 22, 3, 3))
    for j, p in enumerate(SMPL_PARENTS_22):
        local = Rotation.from_rotvec(aa[:, j]).as_matrix()
        g[:, j] = local if p < 0 else g[:, p] @ local
    return g


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def angle(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(unit(a) * unit(b), -1), -1.0, 1.0)))


def yaw_free_error(d_src: np.ndarray, d_t: np.ndarray) -> float:
    """Largest angle between source and avatar directions once the one best turn about +y (the file faces
    +z, the avatar wherever it faces) is taken out; the turn is searched in 1 degree steps."""
    return min(angle(d_src @ Rotation.from_rotvec([0, a, 0]).as_matrix().T, d_t).max()
               for a in np.radians(np.arange(0.0, 360.0, 1.0)))


def write_smplx(path: Path, poses: np.ndarray, trans=None, **extra) -> Path:
    f = len(poses)
    np.savez(path, poses=poses.astype(np.float32), trans=np.zeros((f, 3)) if trans is None else trans,
             betas=np.zeros(300, np.float32), expressions=np.zeros((f, 100)), mocap_frame_rate=np.int32(30),
             model=np.array("smplx2020"), gender=np.array("neutral"), **extra)
    return path


def on_avatar(path: Path, **kw):
    avatar = build_default_avatar()
    motion = load_motion(path, **kw)
    played = to_avatar_skeleton(avatar, motion)
    rot, pos = world(played)
    names = avatar.skeleton.names
    return motion, played, rot, pos, names.index


def avatar_axes(pos, idx):
    """The avatar's own up, left and forward at its first frame (from its hips, head and upper arms)."""
    up = unit(pos[0, idx("Head")] - pos[0, idx("Hips")])
    left = pos[0, idx("LeftUpperArm")] - pos[0, idx("RightUpperArm")]
    left = unit(left - up * np.dot(left, up))
    return up, left, np.cross(left, up)


# -- the synthetic SMPL-X poses of the issue ----------------------------------------------------------------


@pytest.mark.parametrize("degrees, expect_up, expect_left", [(0.0, 0.0, 1.0), (90.0, 1.0, 0.0),
                                                              (-60.0, -np.sin(np.radians(60)), np.cos(np.radians(60)))])
def test_left_shoulder_about_z_lands_on_the_builtin_avatar(tmp_path, degrees, expect_up, expect_left):
    poses = np.zeros((3, 165))
    poses[:, L_SHOULDER * 3 + 2] = np.radians(degrees)  # rotation about +z: the +x arm turns up for positive angles
    _, _, _, pos, idx = on_avatar(write_smplx(tmp_path / "pose.npz", poses))
    up, left, _ = avatar_axes(pos, idx)
    world_up = np.array([0.0, 1.0, 0.0])
    assert angle(up, world_up) < 5.0  # stands upright
    expected = expect_up * world_up + expect_left * left
    for a, b in (("LeftUpperArm", "LeftLowerArm"), ("LeftLowerArm", "LeftHand")):
        d = pos[:, idx(b)] - pos[:, idx(a)]
        assert angle(d, expected).max() < 3.0, (degrees, a, d[0])
    # the right arm stays level, pointing to the figure's right
    for a, b in (("RightUpperArm", "RightLowerArm"), ("RightLowerArm", "RightHand")):
        d = pos[:, idx(b)] - pos[:, idx(a)]
        assert angle(d, -left).max() < 3.0


def test_zero_pose_is_a_t_pose_with_level_arms_and_feet_on_the_floor(tmp_path):
    _, _, _, pos, idx = on_avatar(write_smplx(tmp_path / "zero.npz", np.zeros((2, 165))))
    avatar = build_default_avatar()
    _, rest = world(type(to_avatar_skeleton(avatar, load_motion(tmp_path / "zero.npz")))
                    .rest(avatar.skeleton, 1, 30.0))
    for side in ("Left", "Right"):
        arm = pos[0, idx(f"{side}Hand")] - pos[0, idx(f"{side}UpperArm")]
        assert abs(arm[1]) / np.linalg.norm(arm) < np.sin(np.radians(3.0))
    # the figure stands where the avatar stands at rest: feet at their rest height
    for foot in ("LeftFoot", "RightFoot"):
        assert abs(pos[0, idx(foot), 1] - rest[0, idx(foot), 1]) < 0.02


# -- real and data-set files ---------------------------------------------------------------------------------


def test_beat2_excerpt_plays_upright_with_the_arms_where_the_file_puts_them():
    raw = np.load(BEAT2)
    g = smpl_world_rotations(np.asarray(raw["poses"], np.float64))
    # the SMPL rest frame puts the left arm along +x, the right along -x
    src = {"LeftUpperArm": g[:, L_SHOULDER] @ [1.0, 0, 0], "LeftLowerArm": g[:, L_ELBOW] @ [1.0, 0, 0],
           "RightUpperArm": g[:, R_SHOULDER] @ [-1.0, 0, 0], "RightLowerArm": g[:, R_ELBOW] @ [-1.0, 0, 0]}
    motion, _, _, pos, idx = on_avatar(BEAT2)
    assert motion.n_frames == 300 and motion.fps == 30.0
    spine = pos[:, idx("Head")] - pos[:, idx("Hips")]
    assert angle(spine, [0.0, 1.0, 0.0]).max() < 25.0  # upright in every frame
    child = {"LeftUpperArm": "LeftLowerArm", "LeftLowerArm": "LeftHand", "RightUpperArm": "RightLowerArm",
             "RightLowerArm": "RightHand"}
    err = yaw_free_error(np.stack(list(src.values()), 1),
                         np.stack([pos[:, idx(child[b])] - pos[:, idx(b)] for b in src], 1))
    assert err < 8.0, f"arms off by up to {err:.1f} degrees"
    # and the arms really move in this clip (a test of a still figure proves little)
    assert angle(src["LeftLowerArm"], src["LeftLowerArm"][:1]).max() > 20.0


def _amass_smplh(path: Path, frames: int = 40) -> tuple[Path, np.ndarray, np.ndarray]:
    """An AMASS-style SMPL-H file: Z-up (root +90 degrees about x), 60 fps, walking 1 m along +y (forward in
    Z-up), left arm swinging between -70 and +30 degrees about z."""
    t = np.linspace(0.0, 1.0, frames)
    poses = np.zeros((frames, 156))
    poses[:, 0] = np.pi / 2
    poses[:, L_SHOULDER * 3 + 2] = np.radians(-20 + 50 * np.sin(2 * np.pi * t))
    poses[:, L_ELBOW * 3 + 1] = np.radians(40 * t)  # the forearm bends forward-ish about y
    trans = np.stack([0.1 * t, 1.0 * t, 0.9 + 0.02 * np.sin(4 * np.pi * t)], axis=1)
    np.savez(path, poses=poses, trans=trans, betas=np.zeros(16), gender=np.array("male"),
             mocap_framerate=np.float64(60.0), dmpls=np.zeros((frames, 8)))
    return path, poses, trans


def test_amass_smplh_file_is_stood_upright_with_root_motion_kept(tmp_path):
    path, poses, trans = _amass_smplh(tmp_path / "amass.npz")
    assert recognise_smpl(path) == "smplh"
    motion, played, _, pos, idx = on_avatar(path)
    assert motion.fps == 60.0 and motion.skeleton.n_joints == 52
    spine = pos[:, idx("Head")] - pos[:, idx("Hips")]
    assert angle(spine, [0.0, 1.0, 0.0]).max() < 5.0
    # root motion: the source's pelvis travels as trans does, turned from Z-up to Y-up (z -> y, y -> -z)
    _, src_pos = world(motion)
    travel = src_pos[:, 0] - src_pos[0, 0]
    z_to_y = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    np.testing.assert_allclose(travel, (trans - trans[0]) @ z_to_y.T, atol=1e-9)
    # on the avatar the hips travel as far (scaled by hip heights) and bob as much, and no more
    hips = pos[:, idx("Hips")]
    assert 0.5 < np.linalg.norm(hips[-1, [0, 2]] - hips[0, [0, 2]]) < 1.5
    assert np.ptp(hips[:, 1]) < 0.06
    # the arms: world directions from the file's own numbers, stood upright, then the one yaw between rigs
    g = np.einsum("ij,fkjl->fkil", z_to_y, smpl_world_rotations(poses))
    d_src = g[:, L_ELBOW] @ [1.0, 0, 0]
    d_t = pos[:, idx("LeftHand")] - pos[:, idx("LeftLowerArm")]
    assert yaw_free_error(d_src, d_t) < 4.0


def test_feet_stay_on_the_floor_whatever_floor_the_file_uses(tmp_path):
    poses = np.zeros((2, 165))
    a = load_motion(write_smplx(tmp_path / "a.npz", poses, trans=np.full((2, 3), [0.0, 1.29, 0.0])))
    b = load_motion(write_smplx(tmp_path / "b.npz", poses, trans=np.zeros((2, 3))))
    _, pa = world(a)
    _, pb = world(b)
    np.testing.assert_allclose(pa, pb, atol=1e-9)
    ankles = [7, 8]
    assert abs(pa[:, ankles, 1].min() - builtin_rest_joints("smplx")[ankles, 1].min()) < 1e-9
    # a foot pitched down (toes lower) does not sink the figure: the ankles stay where they stand at rest
    pointed = poses.copy()
    pointed[:, 7 * 3] = pointed[:, 8 * 3] = np.radians(40)  # ankles about x: toes (+z) turn down
    _, pc = world(load_motion(write_smplx(tmp_path / "c.npz", pointed)))
    np.testing.assert_allclose(pc[:, :10], pa[:, :10], atol=1e-9)  # pelvis .. ankles, spine: unchanged
    assert pc[0, 10, 1] < pa[0, 10, 1] - 0.02  # the toes are lower


# -- recognition ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("width, family, joints", [(72, "smpl", 24), (156, "smplh", 52), (165, "smplx", 55)])
def test_each_family_is_recognised_by_the_width_of_poses(tmp_path, width, family, joints):
    p = tmp_path / "m.npz"
    np.savez(p, poses=np.zeros((5, width)), trans=np.zeros((5, 3)), mocap_framerate=np.float64(120))
    assert recognise_smpl(p) == family
    m = load_motion(p)
    assert (m.skeleton.n_joints, m.n_frames, m.fps) == (joints, 5, 120.0)
    assert m.skeleton.parents.tolist()[:22] == SMPL_PARENTS_22
    assert m.skeleton.parents.tolist() == parents(family).tolist()


def test_amass_split_keys_make_one_pose(tmp_path):
    f = 4
    body = np.zeros((f, 63))
    body[:, (L_SHOULDER - 1) * 3 + 2] = np.radians(90)  # pose_body starts at joint 1
    p = tmp_path / "split.npz"
    np.savez(p, root_orient=np.zeros((f, 3)), pose_body=body, pose_hand=np.zeros((f, 90)), trans=np.zeros((f, 3)),
             betas=np.zeros(16), mocap_framerate=np.float64(30))
    assert recognise_smpl(p) == "smplh"
    m = load_motion(p)
    rot = Rotation.from_quat(m.rotations[0, L_SHOULDER])
    np.testing.assert_allclose(rot.as_rotvec(), [0, 0, np.radians(90)], atol=1e-9)


def test_talkshow_npy_layout(tmp_path):
    a = np.zeros((6, 265))
    a[:, 0] = 0.3                                 # jaw about x (mouth opens)
    a[:, 9:12] = [np.pi, 0, 0]                    # TalkSHOW's global orient: the figure upside down (camera space)
    a[:, 12 + (L_SHOULDER - 1) * 3 + 2] = np.radians(90)
    p = tmp_path / "talkshow.npy"
    np.save(p, a)
    assert recognise_smpl(p) == "smplx"
    m = load_motion(p)
    assert m.fps == 30.0 and m.skeleton.n_joints == 55
    np.testing.assert_allclose(Rotation.from_quat(m.rotations[0, 22]).as_rotvec(), [0.3, 0, 0], atol=1e-9)
    _, pos = world(m)
    assert pos[0, 15, 1] > pos[0, 0, 1] + 0.4    # stood upright: head above pelvis
    s = summarize_motion(p)
    assert s["family"] == "SMPL-X" and s["up_axis"].startswith("-Y")
    assert any("30 fps" in w for w in s["warnings"])


def test_a_template_on_an_smpl_file_is_refused_with_the_reason(tmp_path, capsys):
    assert main(["convert", str(BEAT2), str(tmp_path / "x.bvh"), "--template", "beat",
                 "--representation", "axis_angle", "--in-fps", "30"]) == 2
    err = capsys.readouterr().err
    assert "SMPL-X file carries its own skeleton" in err and "drop the template" in err and str(BEAT2) in err


def test_other_arrays_are_not_taken_for_smpl(tmp_path):
    np.savez(tmp_path / "rot.npz", poses=np.zeros((5, 47 * 6)))
    np.save(tmp_path / "rot.npy", np.zeros((5, 165)))
    assert recognise_smpl(tmp_path / "rot.npz") is None
    assert recognise_smpl(tmp_path / "rot.npy") is None
    with pytest.raises(InputError, match="template"):
        load_motion(tmp_path / "rot.npz")


def test_pickled_extras_are_skipped_not_fatal(tmp_path):
    p = tmp_path / "extras.npz"
    np.savez(p, poses=np.zeros((3, 165)), trans=np.zeros((3, 3)), mocap_frame_rate=np.int32(30),
             gender=np.array({"gender": "neutral"}, dtype=object))  # some pipelines store a dict like this
    assert recognise_smpl(p) == "smplx"
    assert load_motion(p).n_frames == 3


def test_a_file_with_no_frame_rate_names_the_keys(tmp_path):
    p = tmp_path / "nofps.npz"
    np.savez(p, poses=np.zeros((3, 165)))
    with pytest.raises(InputError, match="mocap_frame_rate") as e:
        load_motion(p)
    assert str(p) in str(e.value)
    assert load_motion(p, fps=25).fps == 25.0


def test_inspect_names_family_joints_fps_up_axis_and_face(tmp_path, capsys):
    path, _, _ = _amass_smplh(tmp_path / "amass.npz")
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "SMPL-H" in out and "+Z (stood upright)" in out
    s = summarize_motion(BEAT2)
    assert (s["family"], s["joints"], s["fps"], s["up_axis"]) == ("SMPL-X", 55, 30.0, "+Y")
    assert any("jaw" in f for f in s["face_parameters"]) and any("100 FLAME" in f for f in s["face_parameters"])


# -- the user's body model -----------------------------------------------------------------------------------


def _synthetic_body_model(path: Path, rest: np.ndarray, n_dirs: int = 3) -> Path:
    """Two vertices per joint at ``rest +- 1 cm`` in x; ``J_regressor`` averages each pair; shape direction k
    moves every vertex by ``(k + 1) * 0.01`` along y and (for k = 0) stretches y by 10 %."""
    j = len(rest)
    verts = np.repeat(rest, 2, axis=0) + np.tile([[0.01, 0, 0], [-0.01, 0, 0]], (j, 1))
    reg = np.zeros((j, 2 * j))
    reg[np.arange(j), 2 * np.arange(j)] = 0.5
    reg[np.arange(j), 2 * np.arange(j) + 1] = 0.5
    dirs = np.zeros((2 * j, 3, n_dirs))
    for k in range(n_dirs):
        dirs[:, 1, k] = (k + 1) * 0.01
    dirs[:, 1, 0] += 0.1 * verts[:, 1]
    kin = np.stack([np.where(parents("smplx") < 0, 2**32 - 1, parents("smplx")), np.arange(j)]).astype(np.uint32)
    np.savez(path, J_regressor=reg, v_template=verts, shapedirs=dirs, kintree_table=kin,
             f=np.zeros((1, 3), np.uint32))
    return path


def test_body_model_file_gives_the_rest_joints_shaped_by_betas(tmp_path):
    rest = builtin_rest_joints("smplx") * 0.8 - [0.0, 0.3, 0.0]  # a smaller figure in template space
    model = _synthetic_body_model(tmp_path / "SMPLX_TEST.npz", rest)
    betas = np.zeros(300)
    betas[:2] = [1.0, 2.0]
    f = 2
    np.savez(tmp_path / "m.npz", poses=np.zeros((f, 165)), trans=np.zeros((f, 3)), betas=betas,
             mocap_frame_rate=np.int32(30))
    m = load_motion(tmp_path / "m.npz", body_model=model)
    expected = rest.copy()
    expected[:, 1] = rest[:, 1] * 1.1 + 0.01 + 0.02 * 2  # beta0: +1 cm and +10 %; beta1: 2 x 2 cm
    _, pos = world(m)
    # rest offsets are the model's; the whole figure is set on the floor, so compare relative to the pelvis
    np.testing.assert_allclose(pos[0] - pos[0, 0], expected - expected[0], atol=1e-9)
    builtin = load_motion(tmp_path / "m.npz")
    assert not np.allclose(world(builtin)[1][0] - world(builtin)[1][0, 0], pos[0] - pos[0, 0], atol=1e-3)


def test_a_body_model_of_another_family_is_refused_by_key(tmp_path):
    model = _synthetic_body_model(tmp_path / "SMPLX_TEST.npz", builtin_rest_joints("smplx"))
    np.savez(tmp_path / "h.npz", poses=np.zeros((2, 156)), mocap_framerate=np.float64(30))
    with pytest.raises(InputError, match="J_regressor") as e:
        load_motion(tmp_path / "h.npz", body_model=model)
    assert "SMPLX_TEST.npz" in str(e.value) and "SMPL-H" in str(e.value)
    np.savez(tmp_path / "junk.npz", a=np.zeros(3))
    with pytest.raises(InputError, match="missing J_regressor"):
        load_motion(tmp_path / "h.npz", body_model=tmp_path / "junk.npz")


# -- conversion ----------------------------------------------------------------------------------------------


def test_convert_smplx_onto_the_builtin_avatar_writes_the_pose(tmp_path, capsys):
    poses = np.zeros((4, 165))
    poses[:, L_SHOULDER * 3 + 2] = np.radians(-60)
    src = write_smplx(tmp_path / "down60.npz", poses)
    out = tmp_path / "on_avatar.bvh"
    assert main(["convert", str(src), str(out), "--avatar", "builtin"]) == 0
    written = read_bvh(out)
    assert written.n_frames == 4 and written.fps == 30.0
    _, pos = world(written)
    idx = written.skeleton.names.index
    arm = pos[:, idx("LeftHand")] - pos[:, idx("LeftUpperArm")]
    # 60 degrees below the horizontal (the BVH is in centimetres or metres: only the direction counts)
    elevation = np.degrees(np.arcsin(arm[:, 1] / np.linalg.norm(arm, axis=-1)))
    np.testing.assert_allclose(elevation, -60.0, atol=3.0)


# -- the example design's files ------------------------------------------------------------------------------


def _written_as(family: str, bvh: Path) -> dict[str, np.ndarray]:
    """A demo BVH as an SMPL pipeline writes it (how study_designs/smplx_example was made, see its README)."""
    from studyapp.motion.retarget import retarget
    from studyapp.motion.rotations import quat_multiply, quat_rotate, quat_to_axis_angle
    from studyapp.motion.smpl import smpl_skeleton

    m = load_motion(bvh)
    sk = smpl_skeleton(family)
    r = retarget(m, sk)
    q = r.rotations.copy()
    root = r.translations[:, 0]
    if family == "smplh":  # AMASS: Z-up, the root turned +90 degrees about x and trans with it
        y_to_z = np.broadcast_to([np.sin(np.pi / 4), 0.0, 0.0, np.cos(np.pi / 4)], (r.n_frames, 4))
        q[:, 0] = quat_multiply(y_to_z, q[:, 0])
        trans = quat_rotate(y_to_z, root) - quat_rotate(y_to_z[0], sk.offsets[0])
    else:
        trans = root - sk.offsets[0]
    return {"poses": quat_to_axis_angle(q).reshape(r.n_frames, -1), "trans": trans}


@pytest.mark.parametrize("family, source", [("smplx", "synced"), ("smplh", "lagged")])
def test_the_example_designs_smpl_files_play_the_demo_motion_they_were_written_from(family, source):
    """study_designs/smplx_example.toml uses the demo's motion written as SMPL-X (BEAT2 keys) and as SMPL-H
    (AMASS: Z-up); they are what their README says, and on the avatar each plays as the demo BVH does."""
    from studyapp.resources import designs_dir

    bvh = designs_dir() / "demo" / "motion" / source / "clip01.bvh"
    smpl_path = designs_dir() / "smplx_example" / family / "clip01.npz"
    assert recognise_smpl(smpl_path) == family
    shipped = np.load(smpl_path)
    again = _written_as(family, bvh)
    np.testing.assert_allclose(shipped["poses"], again["poses"], atol=2e-4)
    np.testing.assert_allclose(shipped["trans"], again["trans"], atol=2e-4)
    _, _, _, p_smpl, idx = on_avatar(smpl_path)
    _, _, _, p_bvh, _ = on_avatar(bvh)
    limbs = [("LeftUpperArm", "LeftLowerArm"), ("LeftLowerArm", "LeftHand"), ("RightUpperArm", "RightLowerArm"),
             ("RightLowerArm", "RightHand"), ("Hips", "Head")]
    d_smpl = np.stack([p_smpl[:, idx(b)] - p_smpl[:, idx(a)] for a, b in limbs], 1)
    d_bvh = np.stack([p_bvh[:, idx(b)] - p_bvh[:, idx(a)] for a, b in limbs], 1)
    assert angle(d_smpl, d_bvh).max() < 4.0
    assert angle(d_bvh[:, 1], d_bvh[:1, 1]).max() > 15.0  # the forearms do move in this clip


def test_convert_to_bvh_keeps_every_joint_where_it_was(tmp_path, capsys):
    """SMPL's joint order is parent-first but not depth-first (both hips come before either knee); the BVH
    lists joints depth-first and its channel columns must follow that listing."""
    out = tmp_path / "beat2.bvh"
    assert main(["convert", str(BEAT2), str(out)]) == 0
    written = read_bvh(out)
    src = load_motion(BEAT2)
    assert written.skeleton.names != src.skeleton.names  # reordered, so the test means something
    order = [written.skeleton.names.index(n) for n in src.skeleton.names]
    _, p_written = world(written)
    _, p_src = world(src)
    np.testing.assert_allclose(p_written[:, order], p_src, atol=1e-5)
