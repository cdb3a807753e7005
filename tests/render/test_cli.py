"""`studyapp view --offscreen` and `studyapp render` through the real command line."""
from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import pytest

from render_helpers import SAMPLES
from studyapp.cli import main
from studyapp.resources import demo_design

pytestmark = pytest.mark.gl


def test_view_offscreen_writes_a_frame(tmp_path, capsys):
    out = tmp_path / "frame.png"
    with pytest.warns(UserWarning, match="tongueOut"):  # BEAT's face data has 51 of the 52 shapes
        rc = main(["view", str(SAMPLES / "beat75_diffsheg_output_excerpt.bvh"), "--fps", "15",
                   "--face", str(SAMPLES / "beat_face51_diffsheg_gt_excerpt.json"),
                   "--offscreen", "--out", str(out), "--size", "240x180", "--time", "0.1"])
    assert rc == 0 and out.is_file()
    img = mpimg.imread(out)
    assert img.shape[:2] == (180, 240)
    rgb = img[..., :3]
    # a figure in the middle, backdrop at the edges
    assert np.abs(rgb[60:160, 100:140] - rgb[5, 5]).sum(-1).max() > 0.3


def test_view_reports_a_bad_motion_file(tmp_path, capsys):
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    rc = main(["view", str(bad), "--offscreen", "--out", str(tmp_path / "x.png")])
    assert rc == 2
    assert "broken.bvh" in capsys.readouterr().err


def test_render_a_participants_trial_still(tmp_path):
    out = tmp_path / "trial.png"
    rc = main(["render", str(demo_design()), "--participant", "P01", "--trial", "0", "--time", "0.5",
               "--out", str(out), "--size", "384x216"])
    assert rc == 0
    img = mpimg.imread(out)[..., :3]
    assert img.shape[:2] == (216, 384)
    # three figures: every third differs from its own backdrop corner
    for x0 in (0, 128, 256):
        third = img[:, x0:x0 + 128]
        assert np.abs(third - third[-1:, :1]).sum(-1).max() > 0.3


def test_render_needs_time_for_png_and_checks_trial(tmp_path, capsys):
    assert main(["render", str(demo_design()), "--participant", "P01", "--trial", "0",
                 "--out", str(tmp_path / "t.png")]) == 2
    assert "--time" in capsys.readouterr().err
    assert main(["render", str(demo_design()), "--participant", "P01", "--trial", "999", "--time", "0",
                 "--out", str(tmp_path / "t.png")]) == 2
    assert "999" in capsys.readouterr().err


def test_view_takes_an_avatar_bone_map(tmp_path, capsys):
    robot = SAMPLES / "avatars" / "RobotExpressive.glb"
    motion = str(SAMPLES / "beat75_diffsheg_output_excerpt.bvh")
    assert main(["view", motion, "--fps", "15", "--avatar", str(robot), "--offscreen",
                 "--out", str(tmp_path / "no.png")]) != 0
    err = capsys.readouterr().err
    assert "RobotExpressive.glb: not a humanoid avatar" in err and "Traceback" not in err
    pairs = ("Abdomen=Spine,Torso=Chest,UpperArm.L=LeftUpperArm,LowerArm.L=LeftLowerArm,Palm2.L=LeftHand,"
             "UpperArm.R=RightUpperArm,LowerArm.R=RightLowerArm,Palm2.R=RightHand,UpperLeg.L=LeftUpperLeg,"
             "LowerLeg.L=LeftLowerLeg,Foot.L=LeftFoot,UpperLeg.R=RightUpperLeg,LowerLeg.R=RightLowerLeg,Foot.R=RightFoot")
    out = tmp_path / "robot.png"
    assert main(["view", motion, "--fps", "15", "--avatar", str(robot), "--avatar-bone-map", pairs,
                 "--offscreen", "--out", str(out), "--size", "240x180"]) == 0
    rgb = mpimg.imread(out)[..., :3]
    assert np.abs(rgb[40:160, 80:160] - rgb[5, 5]).sum(-1).max() > 0.3  # the robot is drawn


def test_view_of_an_smplx_file_opens_the_mouth_by_its_jaw(tmp_path, capsys):
    """No --face: an SMPL-X motion's jaw drives jawOpen. The same body with the jaw shut and opened 25 degrees
    differs only around the face."""
    images = []
    for name, jaw_deg in (("shut", 0.0), ("open", 25.0)):
        poses = np.zeros((2, 165))
        poses[:, 22 * 3] = np.radians(jaw_deg)
        path = tmp_path / f"{name}.npz"
        np.savez(path, poses=poses, trans=np.zeros((2, 3)), mocap_frame_rate=np.int32(30))
        out = tmp_path / f"{name}.png"
        assert main(["view", str(path), "--offscreen", "--out", str(out), "--size", "320x240"]) == 0
        images.append(mpimg.imread(out)[..., :3])
    diff = np.abs(images[0] - images[1]).sum(-1) > 0.05
    assert diff.sum() > 10, "the mouth did not move"
    rows, cols = np.nonzero(diff)
    # the built-in avatar's face is in the upper part of the frame, in the middle
    assert rows.max() < 240 * 0.45 and abs(cols.mean() - 160) < 30, (rows.min(), rows.max(), cols.mean())


def test_view_takes_a_body_model_and_names_a_wrong_one(tmp_path, capsys):
    from studyapp.motion.smpl import builtin_rest_joints

    motion = tmp_path / "m.npz"
    np.savez(motion, poses=np.zeros((2, 156)), trans=np.zeros((2, 3)), mocap_framerate=np.float64(30))
    wrong = tmp_path / "SMPLX_TEST.npz"  # an SMPL-X model for an SMPL-H file
    np.savez(wrong, J_regressor=np.eye(55), v_template=builtin_rest_joints("smplx"), shapedirs=np.zeros((55, 3, 4)))
    out = tmp_path / "x.png"
    assert main(["view", str(motion), "--body-model", str(wrong), "--offscreen", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "SMPLX_TEST.npz" in err and "J_regressor" in err and "SMPL-H" in err
    right = tmp_path / "SMPLH_TEST.npz"
    np.savez(right, J_regressor=np.eye(52), v_template=builtin_rest_joints("smplh"), shapedirs=np.zeros((52, 3, 4)))
    assert main(["view", str(motion), "--body-model", str(right), "--offscreen", "--out", str(out),
                 "--size", "160x120"]) == 0
    assert out.is_file()
