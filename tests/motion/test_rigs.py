"""Rig recognition without a map: the namings researchers' files use, fuzzy word matching, and the help a
user gets when a map is needed (`inspect` shows the mapping, `--name-map-template` writes the TOML)."""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from studyapp.cli import main
from studyapp.motion.bvh import read_bvh
from studyapp.motion.humanoid import REQUIRED_BONES
from studyapp.motion.rigs import detect_name_map, recognise_rig
from studyapp.motion.skeleton import Skeleton

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


def chain_skeleton(spec: list[tuple[str, str | None]]) -> Skeleton:
    names = [n for n, _ in spec]
    parents = [-1 if p is None else names.index(p) for _, p in spec]
    return Skeleton(tuple(names), np.array(parents), np.zeros((len(names), 3)))


def _limbs(prefix_l: str, prefix_r: str, parts: dict[str, str], parent_of: dict[str, str], spine_top: str, hips: str):
    spec = []
    for pre in (prefix_l, prefix_r):
        for key in ("Shoulder", "UpperArm", "LowerArm", "Hand"):
            par = {"Shoulder": spine_top, "UpperArm": "Shoulder", "LowerArm": "UpperArm", "Hand": "LowerArm"}[key]
            spec.append((parts[key].format(s=pre), spine_top if par == spine_top else parts[par].format(s=pre)))
        for key in ("UpperLeg", "LowerLeg", "Foot"):
            par = {"UpperLeg": hips, "LowerLeg": "UpperLeg", "Foot": "LowerLeg"}[key]
            spec.append((parts[key].format(s=pre), hips if par == hips else parts[par].format(s=pre)))
    return spec


DAZ = [("hip", None), ("abdomen", "hip"), ("chest", "abdomen"), ("neck", "chest"), ("head", "neck")] + _limbs(
    "l", "r", {"Shoulder": "{s}Collar", "UpperArm": "{s}Shldr", "LowerArm": "{s}ForeArm", "Hand": "{s}Hand",
               "UpperLeg": "{s}Thigh", "LowerLeg": "{s}Shin", "Foot": "{s}Foot"}, {}, "chest", "hip")
SMPL = [("pelvis", None), ("spine1", "pelvis"), ("spine2", "spine1"), ("spine3", "spine2"), ("neck", "spine3"),
        ("head", "neck")] + _limbs(
    "left", "right", {"Shoulder": "{s}_collar", "UpperArm": "{s}_shoulder", "LowerArm": "{s}_elbow",
                      "Hand": "{s}_wrist", "UpperLeg": "{s}_hip", "LowerLeg": "{s}_knee", "Foot": "{s}_ankle"},
    {}, "spine3", "pelvis")
BLENDER = [("root", None), ("pelvis", "root"), ("spine", "pelvis"), ("spine.001", "spine"), ("spine.002", "spine.001"),
           ("neck", "spine.002"), ("head", "neck")] + _limbs(
    "L", "R", {"Shoulder": "shoulder.{s}", "UpperArm": "upper_arm.{s}", "LowerArm": "forearm.{s}",
               "Hand": "hand.{s}", "UpperLeg": "thigh.{s}", "LowerLeg": "shin.{s}", "Foot": "foot.{s}"},
    {}, "spine.002", "pelvis")
BIPED = [("Bip01", None), ("Bip01 Pelvis", "Bip01"), ("Bip01 Spine", "Bip01 Pelvis"), ("Bip01 Spine1", "Bip01 Spine"),
         ("Bip01 Neck", "Bip01 Spine1"), ("Bip01 Head", "Bip01 Neck")] + _limbs(
    "Bip01 L", "Bip01 R", {"Shoulder": "{s} Clavicle", "UpperArm": "{s} UpperArm", "LowerArm": "{s} Forearm",
                           "Hand": "{s} Hand", "UpperLeg": "{s} Thigh", "LowerLeg": "{s} Calf", "Foot": "{s} Foot"},
    {}, "Bip01 Spine1", "Bip01 Pelvis")


@pytest.mark.parametrize("spec,rig", [(DAZ, "daz"), (SMPL, "smpl"), (BLENDER, None), (BIPED, None)])
def test_namings_map_every_required_bone_to_the_right_joint(spec, rig):
    sk = chain_skeleton(spec)
    name, mapping = recognise_rig(sk)
    if rig is not None:
        assert name == rig
    by_bone = {b: j for j, b in mapping.items()}
    assert set(REQUIRED_BONES) <= set(by_bone), sorted(set(REQUIRED_BONES) - set(by_bone))
    left_arm = next(n for n, _ in spec[len(spec) - 14 + 1:][:1])  # the left upper arm of _limbs' order
    assert by_bone["LeftUpperArm"] == left_arm
    assert "l" in by_bone["LeftLowerLeg"].lower() and by_bone["RightHand"] != by_bone["LeftHand"]
    assert by_bone["Head"].lower().endswith("head")


@pytest.mark.parametrize("file,rig", [
    ("motion/bandai1_guide_normal_001.bvh", "bandai"), ("motion/cmu_01_01_excerpt.bvh", "cmu"),
    ("motion/lafan1_walk1_subject1_excerpt.bvh", "lafan1"), ("motion/mixamo_Joe_SalsaDancing6_excerpt.bvh", "mixamo"),
    ("motion/zeggs_067_Speech_2_x_1_0_excerpt.bvh", "beat"), ("beat75_diffsheg_output_excerpt.bvh", "beat"),
])
def test_sample_rigs_are_recognised(file, rig):
    name, mapping = recognise_rig(read_bvh(SAMPLES / file).skeleton)
    assert name == rig
    assert set(REQUIRED_BONES) <= set(mapping.values())


def test_inspect_prints_the_mapping_and_writes_a_template(capsys, tmp_path):
    assert main(["inspect", str(SAMPLES / "motion" / "bandai1_guide_normal_001.bvh")]) == 0
    out = capsys.readouterr().out
    assert "rig                bandai" in out or "bandai" in out.split("rig", 1)[1].splitlines()[0]
    assert "LeftUpperArm: UpperArm_L" in out and "not a standing figure" in out
    # a rig nothing recognises: the template names every joint, fills what it found, lists the rest
    with open(SAMPLES / "motion" / "lafan1_walk1_subject1_excerpt.bvh", newline="") as f:
        src = f.read()  # CRLF kept: the file is written back as it came
    odd = src
    for k, joint in enumerate(["LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm", "RightHand"]):
        odd = odd.replace(f"JOINT {joint}\r", f"JOINT Bone{k:02d}\r")
    path = tmp_path / "odd.bvh"
    with open(path, "w", newline="") as f:
        f.write(odd)
    assert odd != src
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "LeftUpperArm" in out.split("missing bones", 1)[1].splitlines()[0]
    assert "--name-map-template" in out
    assert main(["inspect", str(path), "--name-map-template"]) == 0
    text = capsys.readouterr().out
    table = tomllib.loads(text)["conditions"]["name_map"]
    assert table["Hips"] == "Hips" and table["LeftUpLeg"] == "LeftUpperLeg"
    assert "# Bone00" in text and "still missing (required): LeftUpperArm" in text
    # filled in by hand, the map makes the rig retargetable
    filled = text.replace('# Bone00 = ""', 'Bone00 = "LeftUpperArm"').replace('# Bone01 = ""', 'Bone01 = "LeftLowerArm"')
    filled = filled.replace('# Bone02 = ""', 'Bone02 = "LeftHand"').replace('# Bone03 = ""', 'Bone03 = "RightUpperArm"')
    filled = filled.replace('# Bone04 = ""', 'Bone04 = "RightLowerArm"').replace('# Bone05 = ""', 'Bone05 = "RightHand"')
    from studyapp.motion.retarget import retarget
    from studyapp.render.avatar import build_default_avatar

    name_map = tomllib.loads(filled)["conditions"]["name_map"]
    out_motion = retarget(read_bvh(path), build_default_avatar().skeleton, name_map=name_map)
    assert np.isfinite(out_motion.rotations).all()


def test_detect_keeps_builtin_names_over_fuzzy_guesses():
    # BEAT's Spine2 has no humanoid counterpart and must stay unmapped (its rotation is composed upward)
    from studyapp.motion.beat import beat_skeleton

    m = detect_name_map(beat_skeleton())
    assert "Spine2" not in m and m["Spine3"] == "UpperChest"
