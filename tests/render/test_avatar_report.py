"""``studyapp inspect`` on avatars: the joints, humanoid bones, ARKit coverage, facing, extensions, problems."""
from __future__ import annotations

import json

import pytest

from render_helpers import SAMPLES
from test_gltf import bar_gltf, write_gltf
from studyapp.cli import main
from studyapp.render.avatar_report import summarize_avatar

AVATARS = SAMPLES / "avatars"


def _inspect(capsys, path, *extra) -> str:
    assert main(["inspect", str(path), *extra]) == 0
    return capsys.readouterr().out


def _line(out: str, key: str) -> str:
    return next(line for line in out.splitlines() if line.startswith(key + " "))[len(key):].strip()


def test_inspect_fox_lists_joints_and_says_it_is_not_humanoid(capsys):
    out = _inspect(capsys, AVATARS / "Fox.glb")
    assert _line(out, "kind") == "avatar" and _line(out, "format") == "GLB"
    assert "b_LeftUpperArm_09" in _line(out, "joints") and "b_RightFoot02_022" in _line(out, "joints")
    assert _line(out, "joint count") == "24"
    # no bone map can make a four-legged figure humanoid, so none is suggested
    assert _line(out, "problems").startswith("not a humanoid avatar: its rest pose does not stand upright")
    assert "give [avatar.bone_map] entries" not in _line(out, "problems")


def test_inspect_vrm0_reports_its_humanoid_map_and_facing(capsys):
    out = _inspect(capsys, AVATARS / "cryptovoxels_vrm0.vrm")
    assert _line(out, "format") == "VRM 0.x"
    assert _line(out, "facing in file") == "-Z" and _line(out, "facing shown").startswith("+Z")
    assert "LeftLowerArm: LeftLowerArm (Left elbow)" in _line(out, "humanoid map")
    assert _line(out, "humanoid missing") == "-" and _line(out, "humanoid from") == "the file's VRM humanoid"
    assert "VRM" in _line(out, "extensions used")
    assert _line(out, "arkit coverage") == "0/52"


def test_inspect_json_with_a_bone_map_and_arkit_coverage(tmp_path, avatar):
    from studyapp.render.gltf import export_glb

    path = export_glb(avatar, tmp_path / "builtin.glb")
    report = summarize_avatar(path)
    assert report["arkit_coverage"] == "52/52" and report["facing_in_file"] == "+Z" and report["problems"] == []
    assert report["humanoid_map"]["LeftUpperArm"] == "LeftUpperArm" and report["joint_count"] == 52
    robot = summarize_avatar(AVATARS / "RobotExpressive.glb", {"UpperArm.L": "LeftUpperArm", "Tail": "Spine"})
    assert robot["humanoid_map"]["LeftUpperArm"] == "UpperArm.L"
    assert any(p.startswith("[avatar.bone_map] Tail: joint 'Tail' is not in the avatar") for p in robot["problems"])
    assert robot["morph_targets"] == ["Angry", "Surprised", "Sad"] and robot["arkit_coverage"] == "0/52"


def test_inspect_json_names_partial_arkit_sets_and_extensions(tmp_path, capsys):
    gltf, data = bar_gltf(extra={"extensionsUsed": ["KHR_materials_unlit"]})
    out = json.loads(_inspect(capsys, write_gltf(tmp_path, gltf, data, "bar.glb", "glb"), "--json"))
    assert out["arkit_coverage"] == "1/52" and "eyeBlinkLeft" in out["arkit_missing"]
    assert out["morph_targets"] == ["AK_17_JawOpen", "wiggle"]
    assert out["extensions_used"] == ["KHR_materials_unlit"]
    assert out["facing_in_file"].startswith("not measured")


@pytest.mark.parametrize("ext", ["KHR_draco_mesh_compression", "KHR_texture_basisu"])
def test_inspect_reports_unreadable_extensions_without_failing(tmp_path, capsys, ext):
    gltf, data = bar_gltf(extra={"extensionsUsed": [ext], "extensionsRequired": [ext]})
    out = _inspect(capsys, write_gltf(tmp_path, gltf, data))
    assert ext in _line(out, "extensions required")
    assert ext in _line(out, "problems") and "re-export" in _line(out, "problems")


def test_inspect_refuses_a_web_page_with_one_line(tmp_path, capsys):
    page = tmp_path / "model.vrm"
    page.write_text("<!DOCTYPE html><html></html>")
    assert main(["inspect", str(page)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a GLB file (starts with '<!DOCTYPE'" in err[0] and "Traceback" not in err[0]


def test_inspect_counts_arkit_shapes_given_by_vrm_expressions(tmp_path):
    gltf, data = bar_gltf(vrm="1")
    gltf["extensions"]["VRMC_vrm"]["expressions"] = {"custom": {
        "mouthSmileLeft": {"morphTargetBinds": [{"node": 3, "index": 1, "weight": 1.0}]}}}
    report = summarize_avatar(write_gltf(tmp_path, gltf, data, "bar.vrm", "glb"))
    assert report["arkit_coverage"] == "2/52" and report["arkit_from_vrm_expressions"] == ["mouthSmileLeft"]
