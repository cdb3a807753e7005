"""The reference model: deterministic, shipped copies up to date, fast to build, plausible on the avatar."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import onnx

from studyapp.audio.wav import AudioClip
from studyapp.face.animation import FaceAnimation
from studyapp.models import contract as C
from studyapp.models.live import generate, stimulus_inputs, to_beat_motion
from studyapp.models.reference import build_reference_model, shipped_reference_model
from studyapp.models.runner import StreamingGestureModel
from studyapp.motion import rotations as R
from studyapp.motion.beat import BEAT_UPPER_BODY
from studyapp.motion.fk import joint_positions

from live_model_helpers import SR, speech_like

ROOT = Path(__file__).resolve().parents[2]


def test_build_is_deterministic_and_shipped_copies_are_current(ref_model: Path, tmp_path: Path) -> None:
    fresh = ref_model.read_bytes()
    assert build_reference_model(tmp_path / "again.onnx").read_bytes() == fresh
    for shipped in (shipped_reference_model(), ROOT / "study_designs" / "models" / "reference_gesture.onnx"):
        assert shipped.read_bytes() == fresh, f"{shipped} is stale: run python -m studyapp.models.reference {shipped}"


def test_module_command_writes_a_valid_model(tmp_path: Path) -> None:
    out = tmp_path / "sub" / "ref.onnx"
    done = subprocess.run([sys.executable, "-m", "studyapp.models.reference", str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    model = onnx.load(out)
    onnx.checker.check_model(model, full_check=True)
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta[C.META_FPS] == "15" and meta[C.META_ROTATION] == "6d" and meta[C.META_WINDOW] == "8"
    assert meta[C.META_FEATURES] == "log_mel:64,energy,f0"
    assert meta[C.META_JOINTS].split(",") == list(BEAT_UPPER_BODY)
    assert "untrained" in meta["studyapp.description"].lower()
    ops = {n.op_type for n in model.graph.node}
    assert {"Conv", "LSTM", "Gemm", "Tanh"} <= ops


def test_motion_is_small_and_stays_humanlike(ref_model: Path) -> None:
    model = StreamingGestureModel(ref_model)
    rng = np.random.default_rng(3)
    face = FaceAnimation(rng.uniform(0, 1, (240, 52)).astype(np.float32), 30.0, head_rotation=rng.normal(0, 0.1, (240, 3)))
    inputs = stimulus_inputs(model.spec, AudioClip(speech_like(8.0), SR), face)
    out = generate(model, inputs)
    q = R.sixd_to_quat(out)
    angle = np.degrees(2 * np.arccos(np.clip(np.abs(q[..., 3]), 0, 1)))
    names = model.spec.joints
    non_arm = [i for i, n in enumerate(names) if n not in ("RightArm", "LeftArm", "RightForeArm", "LeftForeArm")]
    assert angle[:, non_arm].max() < 45  # small deviations from rest everywhere but the lowered arms
    pos = joint_positions(to_beat_motion(out, model.spec, 15.0))
    sk = to_beat_motion(out[:1], model.spec, 15.0).skeleton
    for side in ("Right", "Left"):
        hand, shoulder = pos[:, sk.index(f"{side}Hand")], pos[:, sk.index(f"{side}Arm")]
        assert np.all(hand[:, 1] < shoulder[:, 1] - 30)  # arms hang down (cm), not a T-pose
        forward = hand[:, 2] - shoulder[:, 2]
        assert forward.mean() > 0 and forward.min() > -10  # elbows bent forward, hands never far behind
        travel = np.linalg.norm(np.diff(hand, axis=0), axis=1)
        assert hand.std(axis=0).max() > 1.0 and travel.max() < 10.0  # visible movement, no jumps (cm per frame)
