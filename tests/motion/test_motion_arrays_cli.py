"""Rotation arrays, the motion NPZ format, load_motion dispatch and the inspect / convert commands."""
from __future__ import annotations

import argparse
import json
import wave

import numpy as np
import pytest

from motion_helpers import BEAT_SAMPLE, MIXAMO_SAMPLE, PYBVH_SAMPLE, SAMPLES, SMALL_BVH, write
from studyapp.errors import InputError
from studyapp.cli import motion as motion_cli
from studyapp.motion.arrays import load_motion_npz, load_rotation_array, save_motion_npz
from studyapp.motion.beat import BEAT_UPPER_BODY
from studyapp.motion.bvh import read_bvh, read_bvh_channels
from studyapp.motion.fk import figure_height, joint_positions
from studyapp.motion.io import load_motion, summarize_motion
from studyapp.motion.rotations import (
    axis_angle_to_quat,
    euler_to_quat,
    quat_to_matrix,
    quat_to_sixd,
    quat_to_sixd_rows,
)


def _mats(q):
    return quat_to_matrix(q)


@pytest.fixture()
def upper_rotations():
    rng = np.random.default_rng(7)
    aa = rng.normal(scale=0.4, size=(12, 47, 3))
    return aa, axis_angle_to_quat(aa)


def test_axis_angle_47_flat_maps_onto_beat_upper_body(tmp_path, upper_rotations):
    aa, q = upper_rotations
    np.save(tmp_path / "diffsheg.npy", aa.reshape(12, 141)[None])  # (1, F, 141) batch output
    m = load_rotation_array(tmp_path / "diffsheg.npy", "beat", "axis_angle", fps=15)
    sk = m.skeleton
    assert m.n_frames == 12 and sk.n_joints == 75 and m.fps == 15
    idx = [sk.index(n) for n in BEAT_UPPER_BODY]
    np.testing.assert_allclose(_mats(m.rotations[:, idx]), _mats(q), atol=1e-12)
    np.testing.assert_allclose(m.rotations[:, sk.index("RightUpLeg")], np.tile([0.0, 0, 0, 1], (12, 1)))


def test_sixd_and_template_motion_first_frame(tmp_path, upper_rotations):
    _, q = upper_rotations
    template = read_bvh(BEAT_SAMPLE, fps=15)
    np.savez(tmp_path / "fcg.npz", poses=quat_to_sixd(q), other=np.zeros(3))
    m = load_rotation_array(tmp_path / "fcg.npz", template, "sixd", fps=15, key="poses")
    sk = m.skeleton
    np.testing.assert_allclose(_mats(m.rotations[:, sk.index("LeftHand")]), _mats(q[:, BEAT_UPPER_BODY.index("LeftHand")]), atol=1e-9)
    # undriven joints hold the template's first frame, not the rest pose
    np.testing.assert_allclose(m.rotations[:, 0], np.tile(template.rotations[0, 0], (12, 1)))
    np.testing.assert_allclose(m.translations[:, 0], np.tile(template.translations[0, 0], (12, 1)))


def _pytorch3d_rows(motion):
    """Every joint of every frame as PyTorch3D's matrix_to_rotation_6d writes it, flattened (F, J*6)."""
    m = quat_to_matrix(motion.rotations)
    return m[..., :2, :].reshape(motion.n_frames, -1)


def test_sixd_rows_npy_reproduces_bvh_world_positions(tmp_path):
    bvh = read_bvh(BEAT_SAMPLE, fps=15)
    rows = _pytorch3d_rows(bvh)
    assert rows.shape == (3, 75 * 6)
    np.testing.assert_allclose(rows.reshape(3, 75, 6), quat_to_sixd_rows(bvh.rotations), atol=0)
    np.save(tmp_path / "emage.npy", rows)
    m = load_rotation_array(tmp_path / "emage.npy", BEAT_SAMPLE, "sixd_rows", fps=15)
    want = joint_positions(bvh)
    np.testing.assert_allclose(joint_positions(m), want, atol=1e-9 * figure_height(bvh.skeleton))
    # the same file read as Zhou columns plays every joint's inverse rotation: far off, not a rounding error
    wrong = joint_positions(load_rotation_array(tmp_path / "emage.npy", BEAT_SAMPLE, "sixd", fps=15))
    assert np.abs(wrong - want).max() > 0.05 * figure_height(bvh.skeleton)


def test_convert_and_inspect_sixd_rows(tmp_path, capsys):
    bvh = read_bvh(BEAT_SAMPLE, fps=15)
    np.save(tmp_path / "emage.npy", _pytorch3d_rows(bvh))
    out = tmp_path / "emage.bvh"
    assert run_cli(["convert", str(tmp_path / "emage.npy"), str(out), "--template", str(BEAT_SAMPLE),
                    "--representation", "sixd_rows", "--fps", "15"]) == 0
    np.testing.assert_allclose(joint_positions(read_bvh(out)), joint_positions(bvh), atol=1e-4)
    capsys.readouterr()
    assert run_cli(["inspect", str(tmp_path / "emage.npy"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["arrays"]["array"]["fits"] == ["euler", "axis_angle", "sixd", "sixd_rows", "matrix"]  # 450 columns
    (note,) = [w for w in s["warnings"] if "6D" in w]
    assert "sixd_rows" in note and "[R00,R01,R02,R10,R11,R12]" in note and "[R00,R10,R20,R01,R11,R21]" in note
    with pytest.raises(SystemExit):
        run_cli(["convert", str(tmp_path / "emage.npy"), str(out), "--representation", "sixd_cols"])
    assert "sixd_rows" in capsys.readouterr().err


def test_convert_help_explains_both_sixd_layouts(capsys):
    with pytest.raises(SystemExit):
        run_cli(["convert", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "sixd = Zhou et al. first two columns [R00,R10,R20,R01,R11,R21]" in help_text
    assert "sixd_rows = first two rows [R00,R01,R02,R10,R11,R12] (PyTorch3D matrix_to_rotation_6d" in help_text


def test_euler_uses_template_order_and_explicit_joints(tmp_path):
    mix = read_bvh(MIXAMO_SAMPLE)
    joints = ["mixamorig:LeftArm", "mixamorig:Head"]
    ang = np.array([[[10.0, 20.0, 30.0], [5.0, -5.0, 0.0]]] * 3)
    np.save(tmp_path / "camn.npy", ang)
    m = load_rotation_array(tmp_path / "camn.npy", mix, "euler", fps=30, joints=joints)
    j = mix.skeleton.index("mixamorig:LeftArm")
    np.testing.assert_allclose(_mats(m.rotations[0, j]), _mats(euler_to_quat([10.0, 20.0, 30.0], "ZYX")), atol=1e-12)
    m2 = load_rotation_array(tmp_path / "camn.npy", mix, "euler", fps=30, joints=joints, order="XYZ")
    np.testing.assert_allclose(_mats(m2.rotations[0, j]), _mats(euler_to_quat([10.0, 20.0, 30.0], "XYZ")), atol=1e-12)


def test_root_key_matrix_and_wxyz(tmp_path, upper_rotations):
    _, q = upper_rotations
    root = np.stack([np.linspace(0, 10, 12), np.full(12, 95.0), np.zeros(12)], axis=1)
    np.savez(tmp_path / "m.npz", rotations=quat_to_matrix(q), trans=root)
    m = load_rotation_array(tmp_path / "m.npz", "beat", "matrix", fps=15, root_key="trans")
    np.testing.assert_allclose(m.translations[:, 0], root)
    np.testing.assert_allclose(_mats(m.rotations[:, m.skeleton.index("RightHand")]), _mats(q[:, BEAT_UPPER_BODY.index("RightHand")]), atol=1e-9)
    np.save(tmp_path / "w.npy", q[..., [3, 0, 1, 2]])
    m2 = load_rotation_array(tmp_path / "w.npy", "beat", "quat_wxyz", fps=15)
    np.testing.assert_allclose(_mats(m2.rotations[:, m2.skeleton.index("Neck")]), _mats(q[:, 1]), atol=1e-12)
    np.savez(tmp_path / "bad_root.npz", rotations=quat_to_matrix(q), trans=root[:5])
    with pytest.raises(InputError, match="root translation must be"):
        load_rotation_array(tmp_path / "bad_root.npz", "beat", "matrix", fps=15, root_key="trans")


@pytest.mark.parametrize(
    "array,rep,kw,pattern",
    [
        (np.zeros((5, 47, 4)), "axis_angle", {}, "4 numbers per joint"),
        (np.zeros((5, 100)), "axis_angle", {}, "not a multiple of 3"),
        (np.zeros((5, 10, 3)), "axis_angle", {}, "10 joints"),
        (np.zeros((0, 47, 3)), "axis_angle", {}, "no frames"),
        (np.full((2, 47, 3), np.nan), "axis_angle", {}, "non-finite"),
        (np.zeros((2, 1, 3)), "axis_angle", {"joints": ["NoSuchJoint"]}, "NoSuchJoint"),
        (np.zeros((2, 47, 6)), "sixd", {}, "cannot read as sixd: 6D rotation has a zero first column"),
        (np.zeros((2, 47, 6)), "sixd_rows", {}, "cannot read as sixd_rows: 6D rotation has a zero first row"),
        (np.zeros((2, 47 * 4)), "sixd_rows", {}, "not a multiple of 6"),
    ],
)
def test_array_errors_name_file_and_shape(tmp_path, array, rep, kw, pattern):
    p = tmp_path / "bad.npy"
    np.save(p, array)
    with pytest.raises(InputError, match=pattern) as err:
        load_rotation_array(p, "beat", rep, fps=15, **kw)
    assert err.value.path == str(p)


def test_npz_without_rotation_key_lists_keys(tmp_path):
    np.savez(tmp_path / "x.npz", a=np.zeros((2, 3)), b=np.zeros(2))
    with pytest.raises(InputError, match="a, b"):
        load_rotation_array(tmp_path / "x.npz", "beat", "axis_angle", fps=15)


def test_save_motion_npz_contents_and_reload(tmp_path):
    m = read_bvh(PYBVH_SAMPLE)
    save_motion_npz(m, tmp_path / "m.npz")
    z = np.load(tmp_path / "m.npz")
    assert str(z["quaternion_order"]) == "xyzw" and float(z["fps"]) == 120.0
    assert list(z["joints"]) == list(m.skeleton.names)
    np.testing.assert_allclose(z["rotations"], m.rotations)
    np.testing.assert_allclose(z["positions"], joint_positions(m))
    np.testing.assert_array_equal(z["parents"], m.skeleton.parents)
    back = load_motion(tmp_path / "m.npz")
    np.testing.assert_allclose(joint_positions(back), joint_positions(m), atol=1e-9)
    assert back.skeleton.channels == m.skeleton.channels
    assert sorted(back.skeleton.end_sites) == sorted(m.skeleton.end_sites)
    assert load_motion_npz(tmp_path / "m.npz", fps=30).fps == 30


def test_load_motion_dispatch_errors(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros((3, 141)))
    with pytest.raises(InputError, match="template"):
        load_motion(tmp_path / "a.npy")
    with pytest.raises(InputError, match="fps"):
        load_motion(tmp_path / "a.npy", template="beat", representation="axis_angle")
    (tmp_path / "a.fbx").write_text("x")
    with pytest.raises(InputError, match="unsupported"):
        load_motion(tmp_path / "a.fbx")
    with pytest.raises(InputError, match="not found"):
        load_motion(tmp_path / "missing.bvh")
    assert load_motion(tmp_path / "a.npy", template="beat", representation="axis_angle", fps=15).n_frames == 3


def test_summarize_samples():
    s = summarize_motion(BEAT_SAMPLE, fps=15)
    assert s["joints"] == 75 and s["frames"] == 3 and s["fps"] == 15 and s["unit_guess"] == "cm"
    assert s["rotation_orders"] == {"XYZ": 75} and s["position_channels"] == ["Hips"]
    assert 1.7 < s["height_m"] < 1.9
    assert summarize_motion(PYBVH_SAMPLE)["unit_guess"] == "unknown"


def test_summary_reports_header_disagreement(tmp_path):
    s = summarize_motion(write(tmp_path, SMALL_BVH.replace("Frames: 2", "Frames: 5")))
    assert s["frames"] == 2 and s["header_frames"] == 5
    header = [w for w in s["warnings"] if "Frames:" in w]
    assert len(header) == 1 and "Frames: 5" in header[0]
    # a two-joint skeleton is no humanoid: the other warning says a study would need a name_map
    assert s["missing_bones"] and any("name_map" in w for w in s["warnings"])


# --- CLI --------------------------------------------------------------------------------------


def run_cli(argv):
    parser = argparse.ArgumentParser(prog="studyapp")
    motion_cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args)


def test_inspect_text_and_json(capsys):
    assert run_cli(["inspect", str(MIXAMO_SAMPLE)]) == 0
    out = capsys.readouterr().out
    assert "joints" in out and "55" in out and "ZYX" in out and "cm" in out
    assert run_cli(["inspect", str(BEAT_SAMPLE), "--fps", "15", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["kind"] == "motion" and data["fps"] == 15 and data["joints"] == 75


def test_inspect_face_and_wav(tmp_path, capsys):
    assert run_cli(["inspect", str(SAMPLES / "beat_face51_diffsheg_gt_excerpt.json"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["kind"] == "face"
    wav = tmp_path / "tone.wav"
    with wave.open(str(wav), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(16000)
        w.writeframes((np.sin(np.arange(16000) / 10) * 10000).astype("<i2").tobytes())
    assert run_cli(["inspect", str(wav), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["kind"] == "audio"


def test_convert_bvh_order_and_fps(tmp_path):
    out = tmp_path / "zxy.bvh"
    assert run_cli(["convert", str(MIXAMO_SAMPLE), str(out), "--order", "zxy"]) == 0
    a, b = read_bvh(MIXAMO_SAMPLE), read_bvh(out)
    assert b.skeleton.rotation_order(3) == "ZXY"
    np.testing.assert_allclose(joint_positions(b), joint_positions(a), atol=1e-4 * figure_height(a.skeleton))
    src = write(tmp_path, SMALL_BVH, "small.bvh")
    assert run_cli(["convert", str(src), str(tmp_path / "60.bvh"), "--fps", "60"]) == 0
    d = read_bvh_channels(tmp_path / "60.bvh")
    assert d.n_frames == 4 and abs(d.frame_time - 1 / 60) < 1e-9
    np.testing.assert_allclose(d.channels[1, :3], [1.25, 90.5, 2.25], atol=1e-6)
    assert run_cli(["convert", str(BEAT_SAMPLE), str(tmp_path / "b15.bvh"), "--in-fps", "15"]) == 0
    assert read_bvh(tmp_path / "b15.bvh").fps == 15


def test_convert_array_to_bvh_and_bvh_to_npz(tmp_path, upper_rotations):
    aa, q = upper_rotations
    np.save(tmp_path / "diffsheg.npy", aa)
    out = tmp_path / "diffsheg.bvh"
    assert run_cli(["convert", str(tmp_path / "diffsheg.npy"), str(out), "--template", str(BEAT_SAMPLE),
                    "--representation", "axis_angle", "--fps", "15"]) == 0
    m = read_bvh(out)
    assert m.fps == 15 and m.n_frames == 12 and m.skeleton.n_joints == 75
    idx = [m.skeleton.index(n) for n in BEAT_UPPER_BODY]
    np.testing.assert_allclose(_mats(m.rotations[:, idx]), _mats(q), atol=1e-5)
    assert run_cli(["convert", str(out), str(tmp_path / "m.npz")]) == 0
    z = np.load(tmp_path / "m.npz")
    np.testing.assert_allclose(z["positions"], joint_positions(m), atol=1e-9)
    assert run_cli(["convert", str(tmp_path / "m.npz"), str(tmp_path / "back.bvh")]) == 0
    back = read_bvh(tmp_path / "back.bvh")
    assert back.fps == 15 and len(back.skeleton.end_sites) == 13
    np.testing.assert_allclose(joint_positions(back), joint_positions(m), atol=1e-4)


def test_convert_errors(tmp_path):
    with pytest.raises(InputError, match="template"):
        run_cli(["convert", str(tmp_path / "x.npy"), str(tmp_path / "y.bvh")]) if np.save(tmp_path / "x.npy", np.zeros((2, 6))) is None else None
    with pytest.raises(InputError, match=".bvh or .npz"):
        run_cli(["convert", str(BEAT_SAMPLE), str(tmp_path / "y.fbx")])
    with pytest.raises(InputError, match="permutation"):
        run_cli(["convert", str(BEAT_SAMPLE), str(tmp_path / "y.bvh"), "--order", "XXY"])


def test_convert_bad_template_is_one_line_naming_it(tmp_path, capsys, upper_rotations):
    """A missing, unreadable or wrong kind of --template: exit code 2 and one line naming the template."""
    from studyapp.cli import main

    np.save(tmp_path / "rot.npy", upper_rotations[0])
    (tmp_path / "notes.txt").write_text("hello")
    (tmp_path / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    np.save(tmp_path / "plain.npy", np.zeros((2, 6)))
    (tmp_path / "folder.bvh").mkdir()
    out = tmp_path / "out.bvh"
    cases = {
        str(tmp_path / "nosuch"): "template file not found",
        str(tmp_path / "nosuch.bvh"): "template file not found",
        str(tmp_path / "notes.txt"): "template is not a BVH file (.txt)",
        str(tmp_path / "broken.bvh"): "template is not a readable BVH file",
        str(tmp_path / "plain.npy"): "template is a .npy array, which holds no skeleton",
        str(tmp_path / "folder.bvh"): "template is a folder, not a BVH file",
    }
    for template, problem in cases.items():
        capsys.readouterr()
        rc = main(["convert", str(tmp_path / "rot.npy"), str(out), "--template", template,
                   "--representation", "axis_angle", "--fps", "15"])
        err = capsys.readouterr().err
        assert rc == 2, (template, err)
        assert err.startswith(f"error: {template}") and problem in err, err
        assert err.count("\n") == 1 and "Traceback" not in err, err
        assert not out.exists()
    # a good template of each kind still converts
    assert main(["convert", str(tmp_path / "rot.npy"), str(out), "--template", "beat",
                 "--representation", "axis_angle", "--fps", "15"]) == 0
    assert main(["convert", str(out), str(tmp_path / "m.npz")]) == 0
    assert main(["convert", str(tmp_path / "rot.npy"), str(tmp_path / "again.bvh"), "--template",
                 str(tmp_path / "m.npz"), "--representation", "axis_angle", "--fps", "15"]) == 0
    assert read_bvh(tmp_path / "again.bvh").n_frames == 12


def test_convert_refuses_non_positive_frame_rates(tmp_path, capsys):
    """A negative or zero --fps / --in-fps is one error line naming the option, not a traceback."""
    from studyapp.cli import main

    for option, value in (("--fps", "-3"), ("--fps", "0"), ("--in-fps", "nan")):
        capsys.readouterr()
        assert main(["convert", str(BEAT_SAMPLE), str(tmp_path / "o.bvh"), option, value]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: {option}: frame rate must be a positive number"), err
        assert "Traceback" not in err and not (tmp_path / "o.bvh").exists()


def test_files_that_are_not_numpy_are_named_as_such(tmp_path):
    """np.load takes any non-NumPy file for a pickle; the message must say what the file really is."""
    (tmp_path / "text.npy").write_text("hello")
    (tmp_path / "motion.npz").write_bytes(BEAT_SAMPLE.read_bytes())
    (tmp_path / "empty.npz").write_bytes(b"")
    for name, problem in (("text.npy", "not a NumPy .npy/.npz file (it starts with b'hello')"),
                          ("motion.npz", "not a NumPy .npy/.npz file (it starts with b'HIERARCH')"),
                          ("empty.npz", "file is empty")):
        for call in (lambda p: load_motion(p, template="beat", representation="axis_angle", fps=15),
                     lambda p: load_motion(p), summarize_motion):
            with pytest.raises(InputError) as err:
                call(tmp_path / name)
            assert err.value.path == str(tmp_path / name) and problem in err.value.problem, err.value
            assert "pickle" not in str(err.value)


def test_unused_root_array_is_reported_not_guessed(tmp_path, upper_rotations, capsys):
    aa, _ = upper_rotations
    root = np.tile([0.0, 1.0, 0.0], (aa.shape[0], 1))  # metres: applying it to a cm skeleton would be wrong
    np.savez(tmp_path / "out.npz", poses=aa, trans=root)
    template = read_bvh(BEAT_SAMPLE)
    with pytest.warns(UserWarning, match="'trans' looks like a \\(12, 3\\) root translation but is not used"):
        m = load_rotation_array(tmp_path / "out.npz", template, "axis_angle", fps=15)
    np.testing.assert_allclose(m.translations[:, 0], np.tile(template.translations[0, 0], (12, 1)))
    # on the command line the same note is one "warning:" line, and the file is still written
    assert run_cli(["convert", str(tmp_path / "out.npz"), str(tmp_path / "o.bvh"), "--template", "beat",
                    "--representation", "axis_angle", "--fps", "15"]) == 0
    err = capsys.readouterr().err
    assert err.startswith("warning: ") and "--root-key trans" in err and err.count("\n") == 1, err
    assert (tmp_path / "o.bvh").exists()


def test_convert_reports_header_disagreement_as_a_warning_line(tmp_path, capsys):
    src = write(tmp_path, SMALL_BVH.replace("Frames: 2", "Frames: 5"), "five.bvh")
    assert run_cli(["convert", str(src), str(tmp_path / "o.bvh")]) == 0
    err = capsys.readouterr().err
    assert err == f"warning: {src}: header says Frames: 5 but the file has 2 data lines; using the data lines\n"
    assert read_bvh_channels(tmp_path / "o.bvh").header_frames == 2


def test_inspect_face_arrays(tmp_path, capsys):
    """Face NPZ (weights + names) is face data; a bare (F, 52) NPY becomes face data once --fps is given."""
    from studyapp.face.arkit import ARKIT_NAMES

    w = np.random.default_rng(3).uniform(0, 0.5, size=(10, 52))
    np.savez(tmp_path / "face.npz", weights=w[:, :51], names=np.array(ARKIT_NAMES[:51]), fps=np.float64(30))
    np.save(tmp_path / "face.npy", w)
    assert run_cli(["inspect", str(tmp_path / "face.npz"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["kind"] == "face" and s["frames"] == 10 and s["fps"] == 30 and s["missing"] == ["tongueOut"]
    assert run_cli(["inspect", str(tmp_path / "face.npy"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["kind"] == "motion" and any("pass --fps" in x for x in s["warnings"])
    assert run_cli(["inspect", str(tmp_path / "face.npy"), "--fps", "60", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["kind"] == "face" and s["fps"] == 60 and abs(s["duration"] - 10 / 60) < 1e-9
    # a rotation array is still a rotation array
    np.save(tmp_path / "rot.npy", np.zeros((4, 47 * 3)))
    assert run_cli(["inspect", str(tmp_path / "rot.npy"), "--fps", "15", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["kind"] == "motion" and s["arrays"]["array"]["shape"] == [4, 141] and not s["warnings"]
