"""An SMPL-X condition's jaw reaches its figure's face in a trial whose stimulus has no face file (the
smplx_example design with the BEAT2 SMPL-X sample as its SMPL-X model output); with a face file, every figure
shows the stimulus's face.

``jawOpen`` is recomputed here from the file's ``poses`` with scipy (joint 22: how far the jaw's forward
axis, +z, drops below the horizontal, 25 degrees = 1) and compared with what each slot's animation sends to
the avatar's morph targets.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from studyapp.face.arkit import ARKIT_NAMES
from studyapp.render.scene import build_trial_scene
from studyapp.resources import designs_dir
from studyapp.study.design import load_design
from studyapp.study.schedule import participant_schedule
from studyapp.study.stimuli import clear_cache, load_trial_media

BEAT2 = Path(__file__).resolve().parents[1] / "data" / "samples" / "motion" / "beat2_smplx_2_scott_0_1_1_excerpt.npz"


def _jaw_open(poses: np.ndarray) -> np.ndarray:
    fwd = Rotation.from_rotvec(poses[:, 66:69]).apply([0.0, 0.0, 1.0])
    return np.clip(np.degrees(np.arcsin(np.clip(-fwd[:, 1], -1, 1))) / 25.0, 0.0, 1.0)


def _design(root: Path, with_faces: bool):
    src = designs_dir()
    shutil.copytree(src / "demo", root / "demo")
    shutil.copytree(src / "smplx_example", root / "smplx_example")
    for clip in ("clip01", "clip03"):  # the SMPL-X condition plays BEAT2's file (10 s at 30 fps)
        shutil.copy(BEAT2, root / "smplx_example" / "smplx" / f"{clip}.npz")
    text = (src / "smplx_example.toml").read_text()
    for clip in ("clip01", "clip03"):
        line = f'face = "demo/face/{clip}.csv"'
        text = text.replace(line, (line if with_faces else "") + "\nduration_s = 9.0")
    (root / "design.toml").write_text(text)
    clear_cache()
    return load_design(root / "design.toml")


def _trial(design):
    plan = next(p for p in participant_schedule(design, "P01", row=0) if "emage_like" in p.slots)
    media = load_trial_media(design, plan)
    return plan, media, build_trial_scene(None, media)


def test_without_a_face_file_the_smplx_figure_opens_its_jaw_as_its_file_says(tmp_path):
    plan, media, scene = _trial(_design(tmp_path, with_faces=False))
    want = _jaw_open(np.load(BEAT2)["poses"].astype(np.float64))
    assert want.max() > 0.1  # BEAT2's fitted jaws open a few degrees
    jaw = scene.avatars[0].morph_names.index("jawOpen")
    for i, cid in enumerate(plan.slots):
        slot = scene.slots[i]
        times = np.arange(slot.n_frames) / slot.fps
        expect = np.interp(times, np.arange(len(want)) / 30.0, want) if cid == "emage_like" else 0.0
        np.testing.assert_allclose(slot.face_weights[:, jaw], expect, atol=2e-3, err_msg=cid)
        others = np.delete(slot.face_weights, jaw, axis=1)
        assert not others.any(), cid  # nothing else moves in a face no file gives


def test_with_a_face_file_every_figure_shows_the_stimulus_face(tmp_path):
    plan, media, scene = _trial(_design(tmp_path, with_faces=True))
    assert media.slot_faces == ()
    names = scene.avatars[0].morph_names
    cols = [ARKIT_NAMES.index(n) for n in names]
    for slot in scene.slots:
        times = np.arange(slot.n_frames) / slot.fps
        np.testing.assert_allclose(slot.face_weights, media.face.sample(times)[:, cols], atol=1e-5)
