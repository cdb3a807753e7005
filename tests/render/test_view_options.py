"""`studyapp view` takes every option a design condition has, and they mean what they mean in a design.

Each check renders through the real command line (``view --offscreen``, the same frame loop and scene
path as the window) and compares pixels with a reference rendered from a file that needs no options.
"""
from __future__ import annotations

import re

import matplotlib.image as mpimg
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from render_helpers import SAMPLES
from studyapp.cli import main

pytestmark = pytest.mark.gl

BEAT = SAMPLES / "beat75_diffsheg_output_excerpt.bvh"  # BEAT rig, header says 120 fps over 15 fps data
ZEGGS = SAMPLES / "motion" / "zeggs_067_Speech_2_x_1_0_excerpt.bvh"  # 10 s of speech gestures at 30 fps
SIZE = "240x320"


def _view(tmp_path, name, *args, time: float = 2.0) -> np.ndarray:
    out = tmp_path / f"{name}.png"
    rc = main(["view", *map(str, args), "--offscreen", "--out", str(out), "--size", SIZE, "--time", str(time)])
    assert rc == 0 and out.is_file()
    return (mpimg.imread(out)[..., :3] * 255).round().astype(int)


def _dark(img: np.ndarray) -> int:
    """Dark pixels (the figure's trousers and hair; the backdrop is light grey)."""
    return int((img.sum(-1) < 250).sum())


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    """Share of pixels that clearly differ between two renders."""
    return float((np.abs(a - b).sum(-1) > 60).mean())


def _bvh_rotations(path, fps):
    from studyapp.motion.bvh import read_bvh

    return read_bvh(path, fps=fps)


def _rooted(src, dst) -> None:
    """``src`` with the root held at its first frame's position (an array has rotations only)."""
    text = src.read_text()
    assert re.search(r"ROOT \S+\s*\{\s*OFFSET[^\n]*\n\s*CHANNELS 6 Xposition Yposition Zposition", text)
    head, motion = text.split("Frame Time:")
    lines = motion.splitlines()
    first = lines[1].split()[:3]
    lines[1:] = [" ".join(first + ln.split()[3:]) for ln in lines[1:] if ln.strip()]
    dst.write_text(head + "Frame Time:" + "\n".join(lines) + "\n")


def test_view_array_with_template_representation_and_fps(tmp_path, capsys):
    """A (frames, joints, 3) axis-angle array of a ZEGGS file's own rotations, read with --template (the
    BVH), --representation axis_angle and --fps 30, shows the pose the BVH itself shows."""
    still_root = tmp_path / "zeggs_still_root.bvh"
    _rooted(ZEGGS, still_root)
    motion = _bvh_rotations(still_root, None)
    rotvec = Rotation.from_quat(motion.rotations.reshape(-1, 4)).as_rotvec().reshape(*motion.rotations.shape[:2], 3)
    arr = tmp_path / "model_output.npy"
    np.save(arr, rotvec.astype(np.float32))

    ref = _view(tmp_path, "bvh", still_root)
    got = _view(tmp_path, "array", arr, "--template", ZEGGS, "--representation", "axis_angle", "--fps", "30")
    assert _dark(ref) > 2000  # a figure is drawn
    # the same pose, pixel for pixel, but for a few where the sleeve and the hand meet at equal depth (the
    # float32 array's last bits decide which one is drawn there)
    assert (np.abs(got - ref).max(-1) > 2).sum() <= 5

    # The options are used, not ignored: the same numbers read as Euler degrees are another (near-rest)
    # pose, and --fps 15 plays the array at half speed (frame 30 at 2 s, as the BVH read at 15 fps).
    wrong = _view(tmp_path, "euler", arr, "--template", ZEGGS, "--representation", "euler", "--fps", "30")
    assert _changed(wrong, ref) > 0.05
    slow = _view(tmp_path, "slow", arr, "--template", ZEGGS, "--representation", "axis_angle", "--fps", "15")
    half = _view(tmp_path, "half", still_root, "--fps", "15")
    assert np.abs(slow - half).max() <= 2 and _changed(slow, ref) > 0.01


def test_view_array_options_are_checked_like_a_design(tmp_path, capsys):
    arr = tmp_path / "out.npy"
    np.save(arr, np.zeros((4, 75, 3), np.float32))
    assert main(["view", str(arr), "--representation", "axis_angle", "--fps", "15",
                 "--offscreen", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "out.npy" in err and "--template" in err and "template BVH" in err
    assert main(["view", str(arr), "--template", str(BEAT), "--representation", "6d", "--fps", "15",
                 "--offscreen", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "--representation" in err and "ambiguous" in err and "sixd_rows" in err
    # an array setting on a BVH is refused, as in a design
    assert main(["view", str(BEAT), "--radians", "--offscreen", "--out", str(tmp_path / "x.png")]) == 2
    assert "--degrees" in capsys.readouterr().err
    # the file itself is the positional argument: the message names no option that `view` lacks
    design = tmp_path / "demo.toml"
    design.write_text("[study]\n")
    assert main(["view", str(design), "--offscreen", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "demo.toml" in err and ".bvh" in err and "--motion" not in err and "pattern" not in err


def _renamed_copy(src, dst) -> dict[str, str]:
    """``src`` with every joint renamed ``J000``, ``J001``, ... (no rig or fuzzy matcher knows these);
    returns new name -> old name."""
    names: list[str] = []

    def rename(m):
        names.append(m.group(2))
        return f"{m.group(1)} J{len(names) - 1:03d}"

    dst.write_text(re.sub(r"^(\s*(?:ROOT|JOINT))\s+(\S+)", rename, src.read_text(), flags=re.M))
    return {f"J{k:03d}": old for k, old in enumerate(names)}


def test_view_name_map_on_a_renamed_rig(tmp_path, capsys):
    from studyapp.motion.rigs import detect_name_map

    renamed = tmp_path / "renamed.bvh"
    new_to_old = _renamed_copy(BEAT, renamed)
    # without a map the rig is unknown: one message naming the file and listing its joints
    assert main(["view", str(renamed), "--fps", "15", "--offscreen", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "renamed.bvh" in err and "J000" in err and "name_map" in err

    # the map the original joint names are recognised with, spelled with the new names
    old_map = detect_name_map(_bvh_rotations(BEAT, 15.0).skeleton)
    new_map = {new: old_map[old] for new, old in new_to_old.items() if old in old_map}
    assert len(new_map) >= 15

    ref = _view(tmp_path, "original", BEAT, "--fps", "15")
    pairs = [a for new, bone in new_map.items() for a in ("--name-map", f"{new}={bone}")]
    by_pairs = _view(tmp_path, "pairs", renamed, "--fps", "15", *pairs)
    assert _dark(ref) > 2000
    assert np.abs(by_pairs - ref).max() <= 2  # the same figure, the same pose

    # the same map as a TOML file in the layout `inspect --name-map-template` writes
    toml = tmp_path / "map.toml"
    toml.write_text("[conditions.name_map]\n" + "".join(f'{k} = "{v}"\n' for k, v in new_map.items()))
    by_file = _view(tmp_path, "file", renamed, "--fps", "15", "--name-map", toml)
    assert np.abs(by_file - ref).max() <= 2

    bad = tmp_path / "bad.toml"
    bad.write_text("[name_map]\nJ000 = 3\n")
    assert main(["view", str(renamed), "--name-map", str(bad), "--offscreen", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "bad.toml, line 2" in err and "J000" in err


def test_view_plays_studyapps_own_motion_npz_without_array_options(tmp_path):
    """A motion NPZ written by studyapp (``convert``, bundles) carries its skeleton and frame rate."""
    from studyapp.motion.arrays import save_motion_npz

    npz = tmp_path / "converted.npz"
    save_motion_npz(_bvh_rotations(BEAT, 15.0), npz)
    assert np.abs(_view(tmp_path, "npz", npz) - _view(tmp_path, "bvh", BEAT, "--fps", "15")).max() <= 2
