"""build_trial_scene: one avatar and one retarget map per slot, the trial's duration from its timeline."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from studyapp.motion.bvh import write_bvh
from studyapp.motion.io import load_motion
from studyapp.render.scene import SlotError, build_trial_scene

SAMPLES = Path(__file__).parents[1] / "data" / "samples"
VRM = SAMPLES / "avatars" / "cryptovoxels_vrm0.vrm"


@dataclass
class Media:  # a scene.TrialSource
    motions: tuple
    avatar: object = "builtin"
    name_maps: tuple = ({}, {}, {})
    face: object = None
    labels: tuple | None = ("A", "B", "C")
    duration_s: float = 0.5
    avatar_bone_map: dict = field(default_factory=dict)


def test_one_avatar_per_slot_shared_when_the_same_file() -> None:
    m = load_motion(SAMPLES / "beat75_diffsheg_output_excerpt.bvh", fps=15.0)
    scene = build_trial_scene(None, Media((m, m, m), avatar=(str(VRM), "builtin", str(VRM))))
    left, middle, right = scene.avatars
    assert left is right and left is not middle                      # one object per file: shared GPU buffers
    assert left.skeleton.n_joints != middle.skeleton.n_joints         # and really two avatars
    assert [s.palettes.shape[1] for s in scene.slots] == [a.skeleton.n_joints for a in scene.avatars]
    assert scene.duration == 0.5                                      # the timeline's, not the motion's 0.2 s


def test_each_slot_uses_its_own_name_map(tmp_path: Path) -> None:
    """A rig with renamed arms works in the slot whose map names them, and the error of a slot without the
    map names that slot and its file (the window used to get one map for all slots, or None)."""
    src = (SAMPLES / "motion" / "cmu_01_01_excerpt.bvh").read_text()
    renamed = tmp_path / "renamed.bvh"
    names = {"LeftArm": "L_humerus", "LeftForeArm": "L_radius", "LeftHand": "L_wrist",
             "RightArm": "R_humerus", "RightForeArm": "R_radius", "RightHand": "R_wrist"}
    for old, new in names.items():
        src = src.replace(f"JOINT {old}\n", f"JOINT {new}\n")
    renamed.write_text(src)
    plain, odd = load_motion(SAMPLES / "motion" / "cmu_01_01_excerpt.bvh"), load_motion(renamed)
    assert set(names.values()) <= set(odd.skeleton.names)
    bones = {"LeftArm": "LeftUpperArm", "LeftForeArm": "LeftLowerArm", "LeftHand": "LeftHand",
             "RightArm": "RightUpperArm", "RightForeArm": "RightLowerArm", "RightHand": "RightHand"}
    arms = {names[k]: v for k, v in bones.items()}
    scene = build_trial_scene(None, Media((plain, odd, plain), name_maps=({}, arms, {})))
    # the renamed rig, mapped, poses its arms as the original does
    np.testing.assert_allclose(scene.slots[1].joint_positions, scene.slots[0].joint_positions, atol=1e-4)
    with pytest.raises(SlotError) as err:  # the renamed rig with no map: its own slot and file are named
        build_trial_scene(None, Media((plain, plain, odd)))
    assert err.value.slot == 2 and str(renamed) in str(err.value)
    with pytest.raises(SlotError) as err:  # a map for the renamed rig given to another slot is that slot's error
        build_trial_scene(None, Media((plain, odd, odd), name_maps=(arms, arms, arms)))
    assert err.value.slot == 0 and "L_humerus" in str(err.value)
